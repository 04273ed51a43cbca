//! Properties of Zheng et al.'s (2014) censoring sensors and particle-filter fusion center.
use super::censoring::nis_threshold;
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{matrix_from_rows, Matrix, Vector};
use crate::link::{Received, Transmission};
use crate::model::{presets, LinearSensor, MeasurementModel};
use crate::scheme::SensorNode;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

fn system(n_sensors: usize) -> Arc<System> {
    let transition = presets::constant_velocity_1d_discrete(1.0, 4.0).unwrap();
    let sensors = (0..n_sensors)
        .map(|_| {
            Arc::new(
                LinearSensor::new(
                    matrix_from_rows(&[vec![1.0, 0.0]]),
                    Matrix::from_element(1, 1, 1.0),
                )
                .unwrap(),
            ) as Arc<dyn MeasurementModel>
        })
        .collect();
    Arc::new(System {
        transition,
        sensors,
        prior: Gaussian::new(Vector::from_vec(vec![0.0, 10.0]), Matrix::identity(2, 2)),
    })
}

fn options(fusion: Fusion) -> PfOptions {
    PfOptions {
        particles: 500,
        fusion,
        resampling: crate::filter::particle::Resampling::Systematic,
        resample_policy: crate::filter::particle::ResamplePolicy::Always,
        band: BandMethod::Exact,
        prop3_samples: 50,
        link_loss: 0.0,
    }
}

fn protocol(rule: SendRule, feedback: FeedbackMode) -> Protocol {
    Protocol::new(rule, feedback).unwrap()
}

/// Runs one trial of `scheme` on data from `seed`; returns the fused estimates per step.
fn run(scheme: &CensoredPfScheme, sys: &System, seed: u64, steps: usize) -> Vec<Gaussian> {
    let mut data_rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut coin_rng = Xoshiro256PlusPlus::seed_from_u64(seed + 1);
    let mut inst = scheme.build_with_seed(seed + 2).unwrap();
    let mut x = sys.prior.mean.clone();
    let mut fb = inst.center.feedback();
    let mut out = Vec::new();
    for k in 1..=steps {
        x = sys.transition.sample_next(&x, &mut data_rng);
        let inbox: Vec<Received> = inst
            .sensors
            .iter_mut()
            .zip(&sys.sensors)
            .map(|(node, s)| {
                let z = s.sample(&x, &mut data_rng);
                node.step(k, &z, fb.as_ref(), &mut coin_rng).unwrap().into()
            })
            .collect();
        inst.center.step(k, &inbox).unwrap();
        fb = inst.center.feedback();
        out.push(inst.center.estimate().clone());
    }
    out
}

/// With l = N the threshold is 0, every sensor sends, and CFwMD, CFoMD and all-send weight
/// the particles identically (the same estimates, bit for bit).
#[test]
fn everything_sent_makes_all_fusions_identical() {
    let sys = system(3);
    let eta = nis_threshold(1, 3.0, 3).unwrap();
    assert_eq!(eta, 0.0);
    let full = CensoredPfScheme::new(
        sys.clone(),
        protocol(SendRule::Nis { eta }, FeedbackMode::Prediction),
        options(Fusion::Full),
    )
    .unwrap();
    let simple = CensoredPfScheme::new(
        sys.clone(),
        protocol(SendRule::Nis { eta }, FeedbackMode::Prediction),
        options(Fusion::Simple),
    )
    .unwrap();
    let all = CensoredPfScheme::new(
        sys.clone(),
        protocol(SendRule::All, FeedbackMode::Prediction),
        options(Fusion::Simple),
    )
    .unwrap();
    let a = run(&full, &sys, 5, 15);
    let b = run(&simple, &sys, 5, 15);
    let c = run(&all, &sys, 5, 15);
    assert_eq!(a, b);
    assert_eq!(a, c);
}

/// Non-feedback sensors censor against their own KF, whose innovations are N(0, s) and white:
/// the fraction of sends is Binomial(n, l/N), so it must lie within 4 standard errors of l/N.
#[test]
fn censoring_rate_matches_l_over_n_without_feedback() {
    let sys = system(4);
    for l in [1.0, 2.0, 3.0] {
        let eta = nis_threshold(1, l, 4).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(l as u64);
        let mut sends = 0usize;
        let mut total = 0usize;
        for _trial in 0..200 {
            let mut x = sys.prior.mean.clone()
                + crate::model::transition::psd_sqrt(&sys.prior.cov).unwrap()
                    * Vector::from_fn(2, |_, _| {
                        rand_distr::Distribution::<f64>::sample(
                            &rand_distr::StandardNormal,
                            &mut rng,
                        )
                    });
            let mut node = CensoringSensor::new(
                0,
                sys.sensors[0].clone(),
                Arc::new(sys.transition.clone()),
                sys.prior.clone(),
                protocol(SendRule::Nis { eta }, FeedbackMode::None),
            );
            for k in 1..=50 {
                x = sys.transition.sample_next(&x, &mut rng);
                let z = sys.sensors[0].sample(&x, &mut rng);
                if let Transmission::Send(_) = node.step(k, &z, None, &mut rng).unwrap() {
                    sends += 1;
                }
                total += 1;
            }
        }
        let p = l / 4.0;
        let rate = sends as f64 / total as f64;
        let se = (p * (1.0 - p) / total as f64).sqrt();
        assert!(
            (rate - p).abs() < 4.0 * se,
            "l = {l}: rate {rate} vs {p} (se {se})"
        );
    }
}

/// Theorem 1: the KL rule (24) with the threshold mapped from eta makes the same decisions as
/// the NIS rule (4), measurement by measurement.
#[test]
fn kl_rule_decides_like_nis() {
    let sys = system(1);
    let eta = nis_threshold(1, 0.5, 1).unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
    let mut nis_node = CensoringSensor::new(
        0,
        sys.sensors[0].clone(),
        Arc::new(sys.transition.clone()),
        sys.prior.clone(),
        protocol(SendRule::Nis { eta }, FeedbackMode::None),
    );
    let mut kl_node = CensoringSensor::new(
        0,
        sys.sensors[0].clone(),
        Arc::new(sys.transition.clone()),
        sys.prior.clone(),
        protocol(SendRule::KlDivergence { eta }, FeedbackMode::None),
    );
    let mut x = sys.prior.mean.clone();
    let (mut sent, mut silent) = (0, 0);
    for k in 1..=2000 {
        x = sys.transition.sample_next(&x, &mut rng);
        let z = sys.sensors[0].sample(&x, &mut rng);
        let a = nis_node.step(k, &z, None, &mut rng).unwrap();
        let b = kl_node.step(k, &z, None, &mut rng).unwrap();
        assert_eq!(a, b, "step {k}: NIS {:?}", nis_node.last_decision());
        if matches!(a, Transmission::Send(_)) {
            sent += 1
        } else {
            silent += 1
        }
    }
    assert!(
        sent > 100 && silent > 100,
        "both decisions must occur: {sent} sent, {silent} silent"
    );
}

/// Under censoring with feedback the full likelihood beats ignoring the silences: over the
/// same trials CFwMD's position MSE is below CFoMD's by more than 3 standard errors of the
/// paired difference.
#[test]
fn silence_is_informative_with_feedback() {
    let sys = system(2);
    let eta = nis_threshold(1, 1.0, 2).unwrap();
    let full = CensoredPfScheme::new(
        sys.clone(),
        protocol(SendRule::Nis { eta }, FeedbackMode::Prediction),
        options(Fusion::Full),
    )
    .unwrap();
    let simple = CensoredPfScheme::new(
        sys.clone(),
        protocol(SendRule::Nis { eta }, FeedbackMode::Prediction),
        options(Fusion::Simple),
    )
    .unwrap();
    let mut diffs = Vec::new();
    for seed in 0..150u64 {
        let truth_err = |est: &[Gaussian]| -> f64 {
            // Same data seed, so the truth is the same; recompute it.
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed * 10);
            let mut x = sys.prior.mean.clone();
            est.iter()
                .map(|e| {
                    x = sys.transition.sample_next(&x, &mut rng);
                    for s in &sys.sensors {
                        let _ = s.sample(&x, &mut rng);
                    }
                    (e.mean[0] - x[0]).powi(2)
                })
                .sum::<f64>()
        };
        let a = truth_err(&run(&full, &sys, seed * 10, 20));
        let b = truth_err(&run(&simple, &sys, seed * 10, 20));
        diffs.push(a - b);
    }
    let n = diffs.len() as f64;
    let mean = diffs.iter().sum::<f64>() / n;
    let se = (diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    assert!(mean < -3.0 * se, "CFwMD - CFoMD = {mean} ± {se}");
}

#[test]
fn bad_configurations_are_errors() {
    let sys = system(2);
    assert!(nis_threshold(1, 3.0, 2).is_err());
    let nis = protocol(SendRule::Nis { eta: 0.4 }, FeedbackMode::Prediction);
    let mut o = options(Fusion::Full);
    o.particles = 0;
    assert!(matches!(
        CensoredPfScheme::new(sys.clone(), nis, o),
        Err(SchemeError::Invalid {
            field: "particles",
            ..
        })
    ));
    let mut o = options(Fusion::Full);
    o.prop3_samples = 0;
    assert!(matches!(
        CensoredPfScheme::new(sys.clone(), nis, o),
        Err(SchemeError::Invalid {
            field: "prop3_samples",
            ..
        })
    ));
    // The KL rule censors against the local prediction: feedback is refused.
    assert!(matches!(
        Protocol::new(
            SendRule::KlDivergence { eta: 0.4 },
            FeedbackMode::Prediction
        ),
        Err(SchemeError::Invalid {
            field: "feedback",
            ..
        })
    ));
    assert!(Protocol::new(SendRule::Nis { eta: f64::NAN }, FeedbackMode::None).is_err());
    // l outside (0, N], and `l` with all-send.
    for l in [0.0, 2.5, f64::INFINITY] {
        assert!(Protocol::for_target(Policy::Nis, Some(l), FeedbackMode::None, &sys).is_err());
    }
    assert!(Protocol::for_target(Policy::All, Some(1.0), FeedbackMode::None, &sys).is_err());
    assert!(Protocol::for_target(Policy::Random, None, FeedbackMode::None, &sys).is_err());
    // CFwMD-exact needs censoring without feedback.
    assert!(CensoredPfScheme::new(
        sys,
        protocol(SendRule::All, FeedbackMode::None),
        options(Fusion::Exact)
    )
    .is_err());
}

/// The sensors and the fusion center take eta and the feedback mode from one protocol, which
/// `for_target` derives from l: eta is the chi-square quantile of eq. (8) for l / N.
#[test]
fn protocol_for_target_derives_eta_once() {
    let sys = system(2);
    let p = Protocol::for_target(Policy::Nis, Some(1.0), FeedbackMode::Prediction, &sys).unwrap();
    assert_eq!(p.eta(), Some(nis_threshold(1, 1.0, 2).unwrap()));
    assert_eq!(p.feedback(), FeedbackMode::Prediction);
    let r = Protocol::for_target(Policy::Random, Some(0.5), FeedbackMode::None, &sys).unwrap();
    assert_eq!(r.rule(), SendRule::Random { p: 0.25 });
    assert_eq!(r.eta(), None);
}

/// The shared local-covariance plan is a speed-up only: with and without it, every feedback
/// mode and fusion gives the same estimates bit for bit, and a planned instance refuses to
/// run past an unconverged horizon.
#[test]
fn local_plan_changes_no_number() {
    let sys = system(3);
    let eta = nis_threshold(1, 1.0, 3).unwrap();
    for feedback in [
        FeedbackMode::None,
        FeedbackMode::Prediction,
        FeedbackMode::PredictionAndCovariance,
    ] {
        for fusion in [Fusion::Full, Fusion::Simple] {
            let o = options(fusion);
            let plain =
                CensoredPfScheme::new(sys.clone(), protocol(SendRule::Nis { eta }, feedback), o)
                    .unwrap();
            let planned = plain.clone().with_horizon(30).unwrap();
            assert_eq!(
                run(&plain, &sys, 11, 30),
                run(&planned, &sys, 11, 30),
                "{feedback:?} {fusion:?}"
            );
        }
    }
    let o = options(Fusion::Full);
    let nis = protocol(SendRule::Nis { eta }, FeedbackMode::Prediction);
    let short = CensoredPfScheme::new(sys.clone(), nis, o)
        .unwrap()
        .with_horizon(2)
        .unwrap();
    let mut inst = short.build_with_seed(1).unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let z = Vector::from_vec(vec![0.5]);
    let fb = inst.center.feedback();
    assert!(inst.sensors[0].step(2, &z, fb.as_ref(), &mut rng).is_ok());
    assert!(matches!(
        inst.sensors[0].step(3, &z, fb.as_ref(), &mut rng),
        Err(SchemeError::HorizonExceeded { k: 3, horizon: 2 })
    ));
    let inbox = vec![Received::Silent; 3];
    assert!(matches!(
        inst.center.step(3, &inbox),
        Err(SchemeError::HorizonExceeded { k: 3, horizon: 2 })
    ));
}

/// A corrupt message is refused with an error, and the fusion center stays usable: the next
/// step with a valid inbox runs (library users may drop a bad packet and go on).
#[test]
fn center_recovers_after_a_refused_message() {
    let sys = system(2);
    let eta = nis_threshold(1, 1.0, 2).unwrap();
    for planned in [false, true] {
        let o = options(Fusion::Full);
        let nis = protocol(SendRule::Nis { eta }, FeedbackMode::Prediction);
        let mut scheme = CensoredPfScheme::new(sys.clone(), nis, o).unwrap();
        if planned {
            scheme = scheme.with_horizon(5).unwrap();
        }
        let mut inst = scheme.build_with_seed(4).unwrap();
        let bad = vec![
            Received::Measurement(Vector::from_vec(vec![f64::NAN])),
            Received::Silent,
        ];
        assert!(matches!(
            inst.center.step(1, &bad),
            Err(SchemeError::Protocol { sensor: 0, .. })
        ));
        let good = vec![
            Received::Measurement(Vector::from_vec(vec![10.0])),
            Received::Silent,
        ];
        for k in 2..=5 {
            inst.center.step(k, &good).unwrap();
            let est = inst.center.estimate();
            assert!(
                est.mean.iter().all(|v| v.is_finite()),
                "planned {planned}, k {k}"
            );
        }
    }
}
