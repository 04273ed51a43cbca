//! Properties of the exact Tobit particle filter: the likelihood against hand-computed values
//! and in the deep tails, the filter against the round-robin Kalman filter (the information
//! bound) without censoring and with wide and narrow censoring regions, determinism, and the
//! scenario-file parameters.
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{mahalanobis_sq, matrix_from_rows, Matrix, Vector};
use crate::model::{LinearSensor, LinearTransition, MeasurementModel};
use crate::scheme::centralized::CentralizedKf;
use crate::scheme::registry::{self, BuildContext};
use rand::SeedableRng;

/// Geng et al., Section IV-A, as hushfuse carries it: xi = [x1, x2, b], F = [[A, B], [0, 1]],
/// Q = blockdiag(0.0025 I, Xi = 0.25), C1 = [1 0 0], C2 = [0 1 0], R = 0.6,
/// prior N([5, 0, 0], 0.1 I).
fn oscillator() -> Arc<System> {
    let w = 0.052 * std::f64::consts::PI;
    let (c, s) = (w.cos(), w.sin());
    let f = matrix_from_rows(&[vec![c, -s, 0.1], vec![s, c, 0.15], vec![0.0, 0.0, 1.0]]);
    let q = Matrix::from_diagonal(&Vector::from_vec(vec![0.0025, 0.0025, 0.25]));
    let sensor = |row: Vec<f64>| -> Arc<dyn MeasurementModel> {
        Arc::new(
            LinearSensor::new(matrix_from_rows(&[row]), Matrix::from_element(1, 1, 0.6)).unwrap(),
        )
    };
    Arc::new(System {
        transition: LinearTransition::new(f, q).unwrap(),
        sensors: vec![sensor(vec![1.0, 0.0, 0.0]), sensor(vec![0.0, 1.0, 0.0])],
        prior: Gaussian::new(
            Vector::from_vec(vec![5.0, 0.0, 0.0]),
            Matrix::identity(3, 3) * 0.1,
        ),
    })
}

/// One trial's truth and round-robin inboxes (uncensored raw z of the scheduled sensor).
struct Trial {
    truth: Vec<Vector>,
    inboxes: Vec<Vec<Received>>,
}

fn simulate(sys: &System, seed: u64, steps: usize) -> Trial {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let x0_sqrt = crate::model::transition::psd_sqrt(&sys.prior.cov).unwrap();
    let n0 = Vector::from_fn(sys.state_dim(), |_, _| {
        rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng)
    });
    let mut x = &sys.prior.mean + x0_sqrt * n0;
    let p = sys.n_sensors();
    let mut truth = Vec::with_capacity(steps);
    let mut inboxes = Vec::with_capacity(steps);
    for k in 1..=steps {
        x = sys.transition.sample_next(&x, &mut rng);
        let inbox = (0..p)
            .map(|i| {
                let z = sys.sensors[i].sample(&x, &mut rng);
                if Schedule::RoundRobin.allows(k, i, p) {
                    Received::Measurement(z)
                } else {
                    Received::NotScheduled
                }
            })
            .collect();
        truth.push(x.clone());
        inboxes.push(inbox);
    }
    Trial { truth, inboxes }
}

fn run(center: &mut dyn FusionCenter, trial: &Trial) -> Vec<Gaussian> {
    trial
        .inboxes
        .iter()
        .enumerate()
        .map(|(k, inbox)| {
            center.step(k + 1, inbox).unwrap();
            center.estimate().clone()
        })
        .collect()
}

fn pf(sys: &Arc<System>, tau: f64, particles: usize, seed: u64) -> TobitPfCenter {
    let p = sys.n_sensors();
    let options = TobitPfOptions {
        particles,
        ..TobitPfOptions::default()
    };
    TobitPfCenter::new(sys.clone(), &vec![-tau; p], &vec![tau; p], options, seed).unwrap()
}

fn mean_and_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

// ---------------------------------------------------------------------------------------------
// Censoring and likelihood

/// Eq. (6): the thresholds belong to the censored sides; infinite thresholds never censor.
#[test]
fn censor_follows_eq_6_at_and_beyond_the_thresholds() {
    assert_eq!(censor(-1.0, -1.0, 2.0), Censored::Left);
    assert_eq!(censor(-1.5, -1.0, 2.0), Censored::Left);
    assert_eq!(censor(2.0, -1.0, 2.0), Censored::Right);
    assert_eq!(censor(7.0, -1.0, 2.0), Censored::Right);
    assert_eq!(censor(0.3, -1.0, 2.0), Censored::Inside(0.3));
    assert_eq!(
        censor(-1.0 + 1e-15, -1.0, 2.0),
        Censored::Inside(-1.0 + 1e-15)
    );
    let inf = f64::INFINITY;
    assert_eq!(censor(-1e300, -inf, inf), Censored::Inside(-1e300));
    assert_eq!(censor(1e300, -inf, inf), Censored::Inside(1e300));
    assert_eq!(Censored::Left.value(-1.0, 2.0), -1.0);
    assert_eq!(Censored::Right.value(-1.0, 2.0), 2.0);
    assert_eq!(Censored::Inside(0.3).value(-1.0, 2.0), 0.3);
    assert!(Censored::Left.is_censored() && !Censored::Inside(0.0).is_censored());
}

/// The three likelihoods against values computed by hand (Python's `math.erfc`, an
/// independent implementation): mu = 0.3, R = 0.6, tau = (-1, 2), inside reading 0.7.
#[test]
fn log_likelihood_equals_hand_computed_values() {
    let (mu, sd) = (0.3, 0.6f64.sqrt());
    let cases = [
        (Censored::Left, -3.065_190_008_248_767), // ln Phi((-1 - 0.3) / sqrt 0.6)
        (Censored::Right, -4.262_084_078_313_92), // ln(1 - Phi((2 - 0.3) / sqrt 0.6))
        (Censored::Inside(0.7), -0.796_859_054_655_010_7), // ln N(0.7; 0.3, 0.6)
    ];
    for (reading, want) in cases {
        let got = log_likelihood(reading, mu, sd, -1.0, 2.0);
        assert!(
            (got - want).abs() <= 1e-13 * want.abs(),
            "{reading:?}: {got} vs {want}"
        );
        // The per-particle kernel gives the same numbers.
        let mut lw = vec![1.5; 70];
        add_log_likelihood(reading, sd, -1.0, 2.0, &[mu; 70], &mut lw);
        for l in lw {
            assert!((l - 1.5 - want).abs() <= 1e-13, "{reading:?}: {l}");
        }
    }
    // Left and right probabilities of one predicted measurement, plus the inside mass, sum to 1:
    // P(z <= -1) + P(z >= 2) + P(-1 < z < 2) with the band from `log_q_band`.
    let total = log_likelihood(Censored::Left, mu, sd, -1.0, 2.0).exp()
        + log_likelihood(Censored::Right, mu, sd, -1.0, 2.0).exp()
        + normal::log_q_band((-1.0 - mu) / sd, (2.0 - mu) / sd).exp();
    assert!((total - 1.0).abs() < 1e-14, "{total}");
}

/// The per-particle kernel equals the scalar function across the line, tails included.
#[test]
fn slice_kernel_matches_scalar_likelihood() {
    let sd = 0.7;
    let mu: Vec<f64> = (0..400).map(|i| -60.0 + 0.3 * i as f64).collect();
    for reading in [Censored::Left, Censored::Right, Censored::Inside(0.4)] {
        let mut lw = vec![0.0; mu.len()];
        add_log_likelihood(reading, sd, -2.0, 3.0, &mu, &mut lw);
        for (m, l) in mu.iter().zip(&lw) {
            let want = log_likelihood(reading, *m, sd, -2.0, 3.0);
            assert!(l.is_finite(), "{reading:?} at mu = {m}: {l}");
            assert!(
                (l - want).abs() <= 1e-12 * want.abs().max(1.0),
                "{reading:?} at mu = {m}: {l} vs {want}"
            );
        }
    }
}

/// |theta| = 40: the censoring probabilities are logs of numbers far below the smallest
/// double, and still finite and accurate (asymptotic series of the Mills ratio); on the other
/// side they are log 1 = 0 to within the double nearest it.
#[test]
fn deep_tails_are_finite_and_accurate() {
    let sd = 2.0;
    // theta = (tau - mu) / sd = -40 at the left threshold, +40 at the right one.
    let want = -804.608_442_013_753_7; // -x^2/2 - ln x - ln sqrt(2 pi) + ln(1 - 1/x^2 + ...)
    let left = log_likelihood(Censored::Left, 80.0, sd, 0.0, 100.0);
    let right = log_likelihood(Censored::Right, -80.0, sd, -100.0, 0.0);
    for got in [left, right] {
        assert!(got.is_finite() && (got - want).abs() < 1e-10, "{got}");
    }
    // The likely side: log(1 - 3.7e-350) rounds to 0 and must not become NaN or positive.
    let near_one = [
        log_likelihood(Censored::Left, -80.0, sd, 0.0, 100.0),
        log_likelihood(Censored::Right, 80.0, sd, -100.0, 0.0),
    ];
    for got in near_one {
        assert!(got.is_finite() && got <= 0.0 && got > -1e-300, "{got}");
    }
    // Far beyond: still finite (log Phi(-1e4) ~ -5e7).
    let far = log_likelihood(Censored::Left, 2e4, sd, 0.0, 1e5);
    assert!(far.is_finite() && far < -4.9e7, "{far}");
}

/// A reading censored 40 standard deviations beyond where every particle puts it: the
/// log-weights (~ -800) normalize, the estimate is finite and moves toward the threshold.
#[test]
fn filter_survives_a_reading_forty_sigma_in_the_tail() {
    let sensor: Arc<dyn MeasurementModel> = Arc::new(
        LinearSensor::new(
            matrix_from_rows(&[vec![1.0, 0.0]]),
            Matrix::from_element(1, 1, 1.0),
        )
        .unwrap(),
    );
    let sys = Arc::new(System {
        transition: LinearTransition::new(Matrix::identity(2, 2), Matrix::identity(2, 2) * 1e-4)
            .unwrap(),
        sensors: vec![sensor],
        prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2) * 0.01),
    });
    let mut center = TobitPfCenter::new(
        sys,
        &[-1.0],
        &[40.0],
        TobitPfOptions {
            particles: 3000,
            ..Default::default()
        },
        3,
    )
    .unwrap();
    center
        .step(1, &[Received::Measurement(Vector::from_element(1, 55.0))])
        .unwrap();
    assert_eq!(center.last_censored(), 1);
    let est = center.estimate();
    assert!(est.mean.iter().chain(est.cov.iter()).all(|v| v.is_finite()));
    // Weights ~ Q(40 - x) favour the largest x: the mean moves up by about a prior variance
    // times the inverse Mills ratio (~ 0.01 * 40 = 0.4, capped by the cloud's extent).
    assert!(est.mean[0] > 0.15, "{}", est.mean[0]);
    let ev = center.last_log_evidence();
    assert!(ev.is_finite() && ev < -700.0 && ev > -805.0, "{ev}");
}

// ---------------------------------------------------------------------------------------------
// Against the round-robin Kalman filter

/// With thresholds at +-infinity the model is linear-Gaussian and the exact filter is the
/// Kalman filter on the round-robin schedule: the PF's mean approaches it, with a squared
/// distance (in the KF's metric) that shrinks like 1/N.
#[test]
fn without_censoring_the_pf_approaches_the_round_robin_kf() {
    let sys = oscillator();
    let inf = f64::INFINITY;
    let trials: Vec<Trial> = (0..6).map(|s| simulate(&sys, 100 + s, 40)).collect();
    let distance = |particles: usize| -> (f64, f64) {
        let (mut d2, mut cov_rel, mut count) = (0.0, 0.0, 0.0);
        for (t, trial) in trials.iter().enumerate() {
            let mut kf = CentralizedKf::new(sys.clone());
            let kf_est = run(&mut kf, trial);
            for rep in 0..6u64 {
                let mut center = pf(&sys, inf, particles, 1000 * t as u64 + rep);
                let pf_est = run(&mut center, trial);
                for (a, b) in pf_est.iter().zip(&kf_est) {
                    d2 += mahalanobis_sq(&(&a.mean - &b.mean), &b.cov).unwrap();
                    cov_rel += crate::linalg::relative_difference(&a.cov, &b.cov);
                    count += 1.0;
                }
            }
        }
        (d2 / count, cov_rel / count)
    };
    let (d_small, c_small) = distance(250);
    let (d_large, c_large) = distance(4000);
    eprintln!(
        "E d^2: {d_small:.3e} (N = 250), {d_large:.3e} (N = 4000); \
         N d^2 / n: {:.2}, {:.2}; cov rel diff {c_small:.3}, {c_large:.3}",
        250.0 * d_small / 3.0,
        4000.0 * d_large / 3.0
    );
    // Monte Carlo error of a weighted mean: E d^2 = n c / N with an inflation c >= 1 from the
    // weights and the resampling history. Measured on these trials: c = 11.6, 13.5, 13.9, 14.7
    // at N = 250, 1000, 4000, 16000 (standard error ~15%): 1/N with no floor. Allow c < 40; a
    // wrong likelihood gives an O(1) distance that does not shrink.
    assert!(4000.0 * d_large / 3.0 < 40.0, "{d_large}");
    assert!(250.0 * d_small / 3.0 < 40.0, "{d_small}");
    // 16 times the particles: at least 6 times closer (1/N gives 16).
    assert!(d_large * 6.0 < d_small, "{d_small} -> {d_large}");
    assert!(c_large < 0.1 && c_large < c_small, "{c_small} -> {c_large}");
}

/// Per-trial MSE (all state components, averaged over steps) and NEES of a run.
fn scores(est: &[Gaussian], truth: &[Vector]) -> (f64, Vec<f64>) {
    let mut mse = 0.0;
    let mut nees = Vec::with_capacity(est.len());
    for (e, x) in est.iter().zip(truth) {
        let err = x - &e.mean;
        mse += err.norm_squared();
        nees.push(mahalanobis_sq(&err, &e.cov).unwrap());
    }
    (mse / est.len() as f64, nees)
}

struct Comparison {
    /// Paired per-trial MSE difference PF - KF: mean and standard error.
    diff: (f64, f64),
    kf_mse: f64,
    pf_mse: f64,
    /// PF mean NEES per state component, and the fraction of NEES below chi^2_3(0.95).
    anees: f64,
    coverage95: f64,
    censored_fraction: f64,
}

fn compare(tau: f64, trials: u64, steps: usize, particles: usize) -> Comparison {
    let sys = oscillator();
    let (mut diffs, mut kf_sum, mut pf_sum) = (Vec::new(), 0.0, 0.0);
    let (mut nees_all, mut censored, mut readings) = (Vec::new(), 0usize, 0usize);
    for t in 0..trials {
        let trial = simulate(&sys, 7_000 + t, steps);
        let mut kf = CentralizedKf::new(sys.clone());
        let (kf_mse, _) = scores(&run(&mut kf, &trial), &trial.truth);
        let mut center = pf(&sys, tau, particles, 9_000 + t);
        let mut est = Vec::with_capacity(steps);
        for (k, inbox) in trial.inboxes.iter().enumerate() {
            center.step(k + 1, inbox).unwrap();
            censored += center.last_censored();
            readings += 1;
            est.push(center.estimate().clone());
        }
        let (pf_mse, nees) = scores(&est, &trial.truth);
        assert!(pf_mse.is_finite());
        diffs.push(pf_mse - kf_mse);
        kf_sum += kf_mse;
        pf_sum += pf_mse;
        nees_all.extend(nees);
    }
    let chi2_3_95 = 7.814_727_903_251_178;
    let c = Comparison {
        diff: mean_and_se(&diffs),
        kf_mse: kf_sum / trials as f64,
        pf_mse: pf_sum / trials as f64,
        anees: nees_all.iter().sum::<f64>() / nees_all.len() as f64 / 3.0,
        coverage95: nees_all.iter().filter(|&&v| v < chi2_3_95).count() as f64
            / nees_all.len() as f64,
        censored_fraction: censored as f64 / readings as f64,
    };
    eprintln!(
        "tau = +-{tau}: MSE KF (bound) {:.4}, PF {:.4}, PF - KF {:.4} +- {:.4}; \
         ANEES {:.3}, NEES < chi2(0.95) {:.3}; censored {:.3}",
        c.kf_mse, c.pf_mse, c.diff.0, c.diff.1, c.anees, c.coverage95, c.censored_fraction
    );
    c
}

/// Wide censoring region (thresholds far outside the signal): the exact filter reaches the
/// information bound, the uncensored round-robin KF, within Monte Carlo error, and not below.
#[test]
fn wide_region_reaches_the_information_bound() {
    let c = compare(1000.0, 120, 60, 1000);
    assert_eq!(c.censored_fraction, 0.0);
    let (d, se) = c.diff;
    // Not below the bound (beyond 3 standard errors of the paired difference) ...
    assert!(d > -3.0 * se, "PF below the bound: {d} +- {se}");
    // ... and no further above it than Monte Carlo error of the PF itself (a few n/N of the
    // posterior variance, here < 2% of the MSE) plus 3 standard errors.
    assert!(
        d < 3.0 * se + 0.02 * c.kf_mse,
        "{d} +- {se} vs {}",
        c.kf_mse
    );
    assert!((0.85..1.2).contains(&c.anees), "{}", c.anees);
}

/// Narrow region (+-1, most readings censored): clearly worse than the bound, but finite and
/// consistent — the exact posterior's covariance covers its error (mean NEES = n in
/// expectation for the Bayes posterior).
#[test]
fn narrow_region_is_worse_than_the_bound_and_consistent() {
    let c = compare(1.0, 120, 60, 1000);
    assert!(c.censored_fraction > 0.5, "{}", c.censored_fraction);
    let (d, se) = c.diff;
    assert!(d > 5.0 * se && c.pf_mse > 1.5 * c.kf_mse, "{d} +- {se}");
    assert!(c.pf_mse.is_finite() && c.pf_mse < 100.0 * c.kf_mse);
    assert!((0.8..1.3).contains(&c.anees), "ANEES {}", c.anees);
    assert!((0.88..0.99).contains(&c.coverage95), "{}", c.coverage95);
}

// ---------------------------------------------------------------------------------------------
// Determinism, messages, scheme

/// Same seed and inboxes: bit-identical estimates; another seed: different ones.
#[test]
fn same_seed_same_bits() {
    let sys = oscillator();
    let trial = simulate(&sys, 5, 30);
    let scheme = TobitPfScheme::new(
        sys.clone(),
        &[-1.0, -1.0],
        &[1.0, 1.0],
        TobitPfOptions {
            particles: 300,
            resampling: Resampling::Residual,
            resample_policy: ResamplePolicy::EssBelow(0.5),
        },
    )
    .unwrap();
    let a = run(scheme.build_with_seed(42).unwrap().center.as_mut(), &trial);
    let b = run(scheme.build_with_seed(42).unwrap().center.as_mut(), &trial);
    let c = run(&mut scheme.center(43).unwrap(), &trial);
    let bits = |v: &[Gaussian]| -> Vec<u64> {
        v.iter()
            .flat_map(|g| g.mean.iter().chain(g.cov.iter()).map(|x| x.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_ne!(bits(&a), bits(&c));
}

/// Held values are not data: a step whose inbox holds only NotScheduled / Silent entries is a
/// pure prediction (the same as a center given nothing at all); corrupt or foreign messages
/// are refused before the cloud is touched.
#[test]
fn held_values_carry_no_information_and_bad_messages_are_refused() {
    let sys = oscillator();
    let mut a = pf(&sys, 1.0, 200, 8);
    let mut b = pf(&sys, 1.0, 200, 8);
    a.step(1, &[Received::NotScheduled, Received::NotScheduled])
        .unwrap();
    b.step(1, &[Received::Silent, Received::NotScheduled])
        .unwrap();
    assert_eq!(a.estimate(), b.estimate());
    assert_eq!(a.last_log_evidence(), 0.0);
    for bad in [
        vec![Received::Estimate(Vector::zeros(3)), Received::NotScheduled],
        vec![
            Received::Measurement(Vector::from_element(1, f64::NAN)),
            Received::NotScheduled,
        ],
        vec![
            Received::Measurement(Vector::zeros(2)),
            Received::NotScheduled,
        ],
        vec![Received::NotScheduled],
    ] {
        assert!(a.step(2, &bad).is_err(), "{bad:?}");
    }
    // The refusals left `a` where `b` is.
    let ok = [
        Received::NotScheduled,
        Received::Measurement(Vector::zeros(1)),
    ];
    a.step(2, &ok).unwrap();
    b.step(2, &ok).unwrap();
    assert_eq!(a.estimate(), b.estimate());
}

#[test]
fn scheme_is_round_robin_with_forwarding_sensors() {
    let sys = oscillator();
    let scheme = TobitPfScheme::new(sys, &[-5.0, -2.0], &[5.0, 3.0], Default::default()).unwrap();
    assert_eq!(scheme.schedule(), Schedule::RoundRobin);
    assert_eq!(scheme.thresholds(1), Some((-2.0, 3.0)));
    assert_eq!(scheme.thresholds(2), None);
    let inst = scheme.build_with_seed(1).unwrap();
    assert_eq!(inst.sensors.len(), 2);
    assert!(inst.center.feedback().is_none());
}

/// The constructor names the scenario-file field of what is wrong.
#[test]
fn constructor_validates_with_field_names() {
    let sys = oscillator();
    let field = |tau_l: &[f64], tau_r: &[f64], options: TobitPfOptions| -> Option<&'static str> {
        match TobitPfScheme::new(sys.clone(), tau_l, tau_r, options) {
            Err(SchemeError::Invalid { field, .. }) => Some(field),
            Err(e) => panic!("{e}"),
            Ok(_) => None,
        }
    };
    let d = TobitPfOptions::default();
    let inf = f64::INFINITY;
    assert_eq!(field(&[-1.0, -1.0], &[1.0, 1.0], d), None);
    assert_eq!(field(&[-inf, -1.0], &[inf, 1.0], d), None);
    assert_eq!(field(&[-1.0], &[1.0, 1.0], d), Some("tau_l"));
    assert_eq!(field(&[-1.0, -1.0], &[1.0, 1.0, 1.0], d), Some("tau_r"));
    assert_eq!(field(&[f64::NAN, -1.0], &[1.0, 1.0], d), Some("tau_l"));
    assert_eq!(field(&[-1.0, -1.0], &[1.0, f64::NAN], d), Some("tau_r"));
    assert_eq!(field(&[-1.0, 1.0], &[1.0, 1.0], d), Some("tau_r"));
    assert_eq!(field(&[inf, -1.0], &[inf, 1.0], d), Some("tau_r"));
    let with = |particles, resample_policy| TobitPfOptions {
        particles,
        resample_policy,
        ..d
    };
    let (l, r) = ([-1.0, -1.0], [1.0, 1.0]);
    assert_eq!(
        field(&l, &r, with(0, ResamplePolicy::Always)),
        Some("particles")
    );
    assert_eq!(
        field(&l, &r, with(MAX_PARTICLES + 1, ResamplePolicy::Always)),
        Some("particles")
    );
    assert_eq!(field(&l, &r, with(1, ResamplePolicy::Always)), None);
    assert_eq!(
        field(&l, &r, with(10, ResamplePolicy::EssBelow(1.5))),
        Some("ess_threshold")
    );
    // A vector sensor is not a Tobit sensor.
    let mut vector = (*sys).clone();
    vector.sensors[0] = Arc::new(
        LinearSensor::new(
            matrix_from_rows(&[vec![1.0, 0.0, 0.0], vec![0.0, 1.0, 0.0]]),
            Matrix::identity(2, 2),
        )
        .unwrap(),
    );
    assert!(matches!(
        TobitPfScheme::new(Arc::new(vector), &l, &r, d),
        Err(SchemeError::Unsupported(_))
    ));
}

fn build(text: &str) -> Result<Box<dyn Scheme>, registry::ParamError> {
    let sys = oscillator();
    let table: toml::Table = toml::from_str(text).unwrap();
    let cx = BuildContext {
        system: &sys,
        steps: 10,
        link_loss: None,
    };
    (registry::find("tobit-pf").expect("registered").build)(table, &cx)
}

/// Scenario-file parameters: a number applies to every sensor, a list gives one per sensor,
/// infinities and integers are accepted, and every error points at its field.
#[test]
fn params_parse_broadcast_and_point_at_fields() {
    let p: TobitPfParams =
        registry::parse(toml::from_str("tau_l = -5\ntau_r = 5.0").unwrap()).unwrap();
    assert_eq!(
        p.tau_l.as_ref().unwrap().expand("tau_l", 2).unwrap(),
        vec![-5.0, -5.0]
    );
    assert_eq!(p.particles, 2000);
    assert_eq!(p.options(), TobitPfOptions::default());
    let p: TobitPfParams = registry::parse(
        toml::from_str(
            "tau_l = [-inf, -1]\ntau_r = [inf, 2.5]\nparticles = 10\nresampling = \"residual\"\ness_threshold = 0.5",
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(
        p.tau_l.as_ref().unwrap().expand("tau_l", 2).unwrap(),
        vec![f64::NEG_INFINITY, -1.0]
    );
    assert_eq!(
        p.options(),
        TobitPfOptions {
            particles: 10,
            resampling: Resampling::Residual,
            resample_policy: ResamplePolicy::EssBelow(0.5),
        }
    );
    let s = build("tau_l = -5\ntau_r = [5, 6]").unwrap();
    assert_eq!(s.schedule(), Schedule::RoundRobin);

    let field = |text: &str| build(text).err().and_then(|e| e.field);
    assert_eq!(field("tau_l = [-5]\ntau_r = 5"), Some("tau_l".into()));
    assert_eq!(field("tau_l = -5\ntau_r = [5, 5, 5]"), Some("tau_r".into()));
    assert_eq!(field("tau_l = 5\ntau_r = 5"), Some("tau_r".into()));
    assert_eq!(field("tau_l = nan\ntau_r = 5"), Some("tau_l".into()));
    // A missing side is not censored; `tau` and a side together are refused.
    assert!(build("tau_r = 5").is_ok());
    assert_eq!(field("tau = -1"), Some("tau".into()));
    assert!(build("tau = 5\ntau_l = -5").is_err());
    assert_eq!(
        field("tau = 5\nnoise_var = 0.001"),
        Some("noise_var".into())
    );
    assert_eq!(
        field("tau_l = -5\ntau_r = 5\nparticles = 0"),
        Some("particles".into())
    );
    assert_eq!(
        field("tau_l = -5\ntau_r = 5\nparticles = 20000000"),
        Some("particles".into())
    );
    assert_eq!(
        field("tau_l = -5\ntau_r = 5\ness_threshold = 2"),
        Some("ess_threshold".into())
    );
    assert_eq!(
        field("tau_l = -5\ntau_r = 5\nsigma = 1"),
        Some("sigma".into())
    );
    assert_eq!(
        field("tau_l = -5\ntau_r = 5\nresampling = \"bogus\""),
        Some("resampling".into())
    );
}
