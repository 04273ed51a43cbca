//! Exactness, consistency and hand-computed steps of the event-triggered baselines.
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{mahalanobis_sq, Matrix, Vector};
use crate::link::{Received, Transmission};
use crate::model::{presets, LinearSensor, LinearTransition, MeasurementModel};
use crate::scheme::centralized::CentralizedKf;
use crate::scheme::registry::{self, BuildContext};
use crate::scheme::{FusionCenter, Scheme, SchemeError, SensorNode, System};
use crate::stats::truncated_normal::band_variance as truncated_variance;
use crate::stats::{chi2, normal};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

fn position_sensor(r: f64) -> Arc<dyn MeasurementModel> {
    Arc::new(
        LinearSensor::new(
            Matrix::from_row_slice(1, 2, &[1.0, 0.0]),
            Matrix::from_element(1, 1, r),
        )
        .unwrap(),
    )
}

/// 1-D constant velocity, four position sensors of different noise.
fn cv_system() -> Arc<System> {
    Arc::new(System {
        transition: presets::constant_velocity_1d(1.0, 0.5).unwrap(),
        sensors: [1.0, 2.0, 0.5, 4.0].map(position_sensor).to_vec(),
        prior: Gaussian::new(
            Vector::from_vec(vec![0.0, 1.0]),
            Matrix::from_diagonal(&Vector::from_vec(vec![10.0, 1.0])),
        ),
    })
}

/// A stable 2-D system (its measurements stay near zero, where the open-loop trigger is
/// silent), observed by a position and a velocity sensor.
fn stable_system() -> Arc<System> {
    let f = Matrix::from_row_slice(2, 2, &[0.95, 0.1, 0.0, 0.9]);
    let q = Matrix::identity(2, 2) * 0.2;
    let vel = Arc::new(
        LinearSensor::new(
            Matrix::from_row_slice(1, 2, &[0.0, 1.0]),
            Matrix::from_element(1, 1, 0.5),
        )
        .unwrap(),
    ) as Arc<dyn MeasurementModel>;
    Arc::new(System {
        transition: LinearTransition::new(f, q).unwrap(),
        sensors: vec![position_sensor(1.0), vel],
        prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2)),
    })
}

/// A scalar random walk x' = x + w (q = 1), prior N(0.5, 1), one sensor z = x + v (r = 1):
/// P^- = 2 and Z = 3 at the first step.
fn scalar_system() -> Arc<System> {
    Arc::new(System {
        transition: LinearTransition::new(
            Matrix::from_element(1, 1, 1.0),
            Matrix::from_element(1, 1, 1.0),
        )
        .unwrap(),
        sensors: vec![Arc::new(
            LinearSensor::new(
                Matrix::from_element(1, 1, 1.0),
                Matrix::from_element(1, 1, 1.0),
            )
            .unwrap(),
        ) as Arc<dyn MeasurementModel>],
        prior: Gaussian::new(
            Vector::from_element(1, 0.5),
            Matrix::from_element(1, 1, 1.0),
        ),
    })
}

struct Trial {
    truth: Vec<Vector>,
    z: Vec<Vec<Vector>>,
}

/// Truth from x_0 ~ prior, and every sensor's measurements.
fn simulate(system: &System, steps: usize, seed: u64) -> Trial {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let sqrt = crate::model::transition::psd_sqrt(&system.prior.cov).unwrap();
    let n0 = Vector::from_fn(system.state_dim(), |_, _| {
        rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng)
    });
    let mut x = &system.prior.mean + sqrt * n0;
    let (mut truth, mut z) = (Vec::new(), Vec::new());
    for _ in 0..steps {
        x = system.transition.sample_next(&x, &mut rng);
        z.push(
            system
                .sensors
                .iter()
                // Singles already, so a measurement crosses the network unchanged
                // (`link::as_sent`): the bit-for-bit checks compare the schemes, not the wire.
                .map(|s| s.sample(&x, &mut rng).map(crate::link::as_sent))
                .collect(),
        );
        truth.push(x.clone());
    }
    Trial { truth, z }
}

/// Runs a scheme on a trial like the runner does; returns the estimates and the number of
/// messages sent.
fn run(scheme: &dyn Scheme, trial: &Trial, coin_seed: u64) -> (Vec<Gaussian>, usize) {
    let mut inst = scheme.build().unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(coin_seed);
    let mut feedback = inst.center.feedback();
    let (mut out, mut sent) = (Vec::new(), 0);
    for (k0, zs) in trial.z.iter().enumerate() {
        let inbox: Vec<Received> = inst
            .sensors
            .iter_mut()
            .zip(zs)
            .map(|(s, z)| {
                let t = s.step(k0 + 1, z, feedback.as_ref(), &mut rng).unwrap();
                sent += matches!(t, Transmission::Send(_)) as usize;
                Received::from(t)
            })
            .collect();
        inst.center.step(k0 + 1, &inbox).unwrap();
        feedback = inst.center.feedback();
        out.push(inst.center.estimate().clone());
    }
    (out, sent)
}

fn all_send_kf(system: &Arc<System>, trial: &Trial) -> Vec<Gaussian> {
    let mut kf = CentralizedKf::new(system.clone());
    trial
        .z
        .iter()
        .enumerate()
        .map(|(k0, zs)| {
            let inbox: Vec<Received> = zs.iter().cloned().map(Received::Measurement).collect();
            kf.step(k0 + 1, &inbox).unwrap();
            kf.estimate().clone()
        })
        .collect()
}

fn schemes_at_zero(system: &Arc<System>) -> Vec<(&'static str, Box<dyn Scheme>)> {
    vec![
        (
            "innovation",
            Box::new(InnovationTriggerScheme::new(system.clone(), 0.0).unwrap()),
        ),
        (
            "open",
            Box::new(StochasticTriggerScheme::new(
                system.clone(),
                StochasticTrigger::with_tau(system, TriggerLoop::Open, 0.0).unwrap(),
            )),
        ),
        (
            "closed",
            Box::new(StochasticTriggerScheme::new(
                system.clone(),
                StochasticTrigger::with_tau(system, TriggerLoop::Closed, 0.0).unwrap(),
            )),
        ),
        (
            "sod-uniform",
            Box::new(SendOnDeltaScheme::new(system.clone(), 0.0, SilenceModel::Uniform).unwrap()),
        ),
        (
            "sod-ignore",
            Box::new(SendOnDeltaScheme::new(system.clone(), 0.0, SilenceModel::Ignore).unwrap()),
        ),
    ]
}

#[test]
fn zero_threshold_equals_the_all_send_kf_bit_for_bit() {
    let system = cv_system();
    for seed in 0..3 {
        let trial = simulate(&system, 40, seed);
        let reference = all_send_kf(&system, &trial);
        for (name, scheme) in schemes_at_zero(&system) {
            let (est, sent) = run(scheme.as_ref(), &trial, 100 + seed);
            assert_eq!(sent, 40 * 4, "{name}: every measurement is sent");
            for (k, (a, b)) in est.iter().zip(&reference).enumerate() {
                assert_eq!(a.mean, b.mean, "{name}, step {}", k + 1);
                assert_eq!(a.cov, b.cov, "{name}, step {}", k + 1);
            }
        }
    }
}

#[test]
fn truncated_variance_matches_quadrature_and_its_limits() {
    // Simpson's rule for E[x^2 | |x| <= d] of a standard normal.
    let by_quadrature = |d: f64| {
        let n = 2000;
        let h = 2.0 * d / n as f64;
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..=n {
            let x = -d + i as f64 * h;
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            num += w * x * x * normal::pdf(x);
            den += w * normal::pdf(x);
        }
        num / den
    };
    for d in [0.01, 0.3, 1.0, 2.0, 4.0] {
        let v = truncated_variance(d);
        assert!((v - by_quadrature(d)).abs() < 1e-10, "d = {d}: {v}");
    }
    assert_eq!(truncated_variance(0.0), 0.0);
    // The series and the closed form meet at 1e-3 (v' = 2 delta / 3 accounts for 1.3e-12
    // of the difference, the closed form's cancellation for ~1e-13).
    let (a, b) = (
        truncated_variance(0.999_999e-3),
        truncated_variance(1.000_001e-3),
    );
    assert!((b - a).abs() < 3e-12 && b > a, "{a} vs {b}");
    assert!((truncated_variance(40.0) - 1.0).abs() < 1e-15);
    // By hand: v(1) = 1 - 2 phi(1) / (1 - 2 Q(1)) = 1 - 0.4839414490 / 0.6826894921.
    assert!(
        (truncated_variance(1.0) - (1.0 - 0.483_941_449_038_286_7 / 0.682_689_492_137_085_9)).abs()
            < 1e-12
    );
}

/// One silent step of Wu et al.'s estimator with numbers: P^- = 2, Z = 3, delta = 1.
#[test]
fn innovation_trigger_single_step_by_hand() {
    let system = scalar_system();
    let mut sensor = InnovationTriggerSensor::new(system.clone(), 0, 1.0).unwrap();
    let mut center = InnovationTriggerCenter::new(system.clone(), 1.0).unwrap();
    let fb = center.feedback().unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0);
    // eps = (z - 0.5) / sqrt(3): silent at eps = 0.999, sends at 1.001.
    let z_at = |eps: f64| Vector::from_element(1, 0.5 + eps * 3f64.sqrt());
    assert_eq!(
        sensor.step(1, &z_at(0.999), Some(&fb), &mut rng).unwrap(),
        Transmission::Silent
    );
    assert!(matches!(
        sensor.step(1, &z_at(1.001), Some(&fb), &mut rng).unwrap(),
        Transmission::Send(_)
    ));
    assert!(matches!(
        sensor.step(1, &z_at(-1.001), Some(&fb), &mut rng).unwrap(),
        Transmission::Send(_)
    ));
    center.step(1, &[Received::Silent]).unwrap();
    // beta = 1 - v(1) = 0.4839414490 / 0.6826894921 = 0.708881; P = 2 - beta * 4 / 3.
    let beta = 0.483_941_449_038_286_7 / 0.682_689_492_137_085_9;
    let e = center.estimate();
    assert!((e.cov[(0, 0)] - (2.0 - beta * 4.0 / 3.0)).abs() < 1e-12);
    assert!(
        (e.mean[0] - 0.5).abs() < 1e-15,
        "a silence does not move the mean"
    );
    // Without feedback the sensor cannot trigger.
    assert!(matches!(
        sensor.step(2, &z_at(0.0), None, &mut rng),
        Err(SchemeError::Protocol { sensor: 0, .. })
    ));
}

/// One silent step of Han et al.'s estimators with numbers: P^- = 2, R = 1, tau = 1, so
/// R + Y^-1 = 2.
#[test]
fn stochastic_trigger_single_step_by_hand() {
    let system = scalar_system();
    let closed = StochasticTrigger::with_tau(&system, TriggerLoop::Closed, 1.0).unwrap();
    let open = StochasticTrigger::with_tau(&system, TriggerLoop::Open, 1.0).unwrap();
    assert!((closed.silence_noise(0).unwrap()[(0, 0)] - 2.0).abs() < 1e-15);
    let u = Vector::from_element(1, 1.0);
    assert!((closed.silence_probability(0, &u) - (-0.5f64).exp()).abs() < 1e-15);
    // Theorem 2 (closed loop): x = x^- = 0.5, P = 2 - 2 * 2 / (2 + 2) = 1.
    let mut c = StochasticTriggerCenter::new(system.clone(), closed);
    c.step(1, &[Received::Silent]).unwrap();
    assert!((c.estimate().mean[0] - 0.5).abs() < 1e-15);
    assert!((c.estimate().cov[(0, 0)] - 1.0).abs() < 1e-14);
    // Theorem 1 (open loop): x = 0.5 - 2 / 4 * 0.5 = 0.25, P = 1.
    let mut o = StochasticTriggerCenter::new(system.clone(), open.clone());
    assert!(o.feedback().is_none(), "open loop needs no feedback");
    o.step(1, &[Received::Silent]).unwrap();
    assert!((o.estimate().mean[0] - 0.25).abs() < 1e-14);
    assert!((o.estimate().cov[(0, 0)] - 1.0).abs() < 1e-14);
    // A matrix Y = R^-1 / tau^2 is the same trigger.
    let by_matrix =
        StochasticTrigger::with_matrix(&system, TriggerLoop::Open, Matrix::from_element(1, 1, 1.0))
            .unwrap();
    assert_eq!(by_matrix, open);
    // The sensor's coin: silent with probability exp(-z^2 / 2).
    let mut sensor = StochasticTriggerSensor::new(system.clone(), 0, by_matrix);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    let n = 20_000;
    let silent = (0..n)
        .filter(|_| sensor.step(1, &u, None, &mut rng).unwrap() == Transmission::Silent)
        .count() as f64
        / n as f64;
    let p = (-0.5f64).exp();
    assert!(
        (silent - p).abs() < 4.0 * (p * (1.0 - p) / n as f64).sqrt(),
        "{silent}"
    );
}

/// Send-on-delta with numbers: delta = 1.5, R = 1.
#[test]
fn send_on_delta_single_steps_by_hand() {
    let system = scalar_system();
    let mut s = SendOnDeltaSensor::new(1.5).unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0);
    let z = |v: f64| Vector::from_element(1, v);
    assert!(matches!(
        s.step(1, &z(1.0), None, &mut rng).unwrap(),
        Transmission::Send(_)
    ));
    assert_eq!(
        s.step(2, &z(2.4), None, &mut rng).unwrap(),
        Transmission::Silent
    );
    assert_eq!(
        s.step(3, &z(-0.4), None, &mut rng).unwrap(),
        Transmission::Silent
    );
    assert!(matches!(
        s.step(4, &z(2.6), None, &mut rng).unwrap(),
        Transmission::Send(_)
    ));
    let mut c = SendOnDeltaCenter::new(system.clone(), 1.5, SilenceModel::Uniform).unwrap();
    c.step(1, &[Received::Measurement(z(1.0))]).unwrap();
    // Step 1: P^- = 2, K = 2/3, x = 0.5 + 2/3 * 0.5, P = 2/3.
    let (x1, p1) = (0.5 + 2.0 / 3.0 * 0.5, 2.0 / 3.0);
    assert!((c.estimate().mean[0] - x1).abs() < 1e-14);
    assert!((c.estimate().cov[(0, 0)] - p1).abs() < 1e-14);
    // Step 2, silent: pseudo-measurement 1.0 with noise 1 + 1.5^2 / 3 = 1.75.
    c.step(2, &[Received::Silent]).unwrap();
    let pp = p1 + 1.0;
    let k = pp / (pp + 1.75);
    assert!((c.estimate().mean[0] - (x1 + k * (1.0 - x1))).abs() < 1e-14);
    assert!((c.estimate().cov[(0, 0)] - (1.0 - k) * pp).abs() < 1e-14);
    // Ignoring the silence is a bare prediction.
    let mut ig = SendOnDeltaCenter::new(system, 1.5, SilenceModel::Ignore).unwrap();
    ig.step(1, &[Received::Measurement(z(1.0))]).unwrap();
    ig.step(2, &[Received::Silent]).unwrap();
    assert!((ig.estimate().cov[(0, 0)] - pp).abs() < 1e-14);
    assert!((ig.estimate().mean[0] - x1).abs() < 1e-14);
}

/// Sum of NEES over trials at given steps, and messages per sensor and step.
fn nees_at(
    system: &Arc<System>,
    scheme: &dyn Scheme,
    trials: usize,
    steps: usize,
    at: &[usize],
) -> (Vec<f64>, f64) {
    let mut sums = vec![0.0; at.len()];
    let mut sent = 0;
    for t in 0..trials {
        let trial = simulate(system, steps, 10_000 + t as u64);
        let (est, s) = run(scheme, &trial, 20_000 + t as u64);
        sent += s;
        for (j, &k) in at.iter().enumerate() {
            let e = &trial.truth[k - 1] - &est[k - 1].mean;
            sums[j] += mahalanobis_sq(&e, &est[k - 1].cov).unwrap();
        }
    }
    let rate = sent as f64 / (trials * steps * system.n_sensors()) as f64;
    (sums, rate)
}

/// Theorems 1-2 make the stochastic-trigger KF exact, so its NEES summed over M trials at a
/// step is chi-square with M n degrees of freedom: check it at three steps against the
/// two-sided 99.9% interval.
#[test]
fn stochastic_trigger_filters_are_consistent() {
    let trials = 400;
    let at = [10, 20, 30];
    let cases: Vec<(Arc<System>, TriggerLoop, f64)> = vec![
        (cv_system(), TriggerLoop::Closed, 1.0),
        (cv_system(), TriggerLoop::Closed, 3.0),
        (stable_system(), TriggerLoop::Open, 1.0),
    ];
    for (system, kind, tau) in cases {
        let trigger = StochasticTrigger::with_tau(&system, kind, tau).unwrap();
        let scheme = StochasticTriggerScheme::new(system.clone(), trigger);
        let (sums, rate) = nees_at(&system, &scheme, trials, 30, &at);
        assert!(
            rate > 0.05 && rate < 0.95,
            "{kind:?} tau {tau}: rate {rate} tests nothing"
        );
        let dof = (trials * system.state_dim()) as f64;
        let lo = chi2::upper_quantile(dof, 0.9995).unwrap();
        let hi = chi2::upper_quantile(dof, 0.0005).unwrap();
        for (s, k) in sums.iter().zip(at) {
            assert!(
                *s > lo && *s < hi,
                "{kind:?} tau {tau}, step {k}: NEES sum {s} outside [{lo}, {hi}] (ANEES {})",
                s / trials as f64
            );
        }
    }
}

/// Wu et al.'s filter is an approximation: its ANEES is reported, not asserted.
#[test]
fn innovation_trigger_anees_is_reported() {
    let system = cv_system();
    for delta in [0.5, 1.0, 2.0] {
        let scheme = InnovationTriggerScheme::new(system.clone(), delta).unwrap();
        let (sums, rate) = nees_at(&system, &scheme, 200, 30, &[10, 20, 30]);
        let anees: Vec<f64> = sums.iter().map(|s| s / 200.0 / 2.0).collect();
        eprintln!(
            "innovation trigger delta {delta}: rate {rate:.3}, ANEES/n at k=10,20,30 {anees:.3?}"
        );
        assert!(anees.iter().all(|a| a.is_finite()));
    }
}

/// The send rate falls strictly as each knob grows (same data and coins for every value).
#[test]
fn send_rate_falls_as_the_knob_grows() {
    let cv = cv_system();
    let stable = stable_system();
    let knobs = [0.25, 0.5, 1.0, 2.0, 4.0];
    let rate_of = |system: &Arc<System>, make: &dyn Fn(f64) -> Box<dyn Scheme>, v: f64| {
        let scheme = make(v);
        (0..40)
            .map(|t| run(scheme.as_ref(), &simulate(system, 40, t), 500 + t).1)
            .sum::<usize>() as f64
            / (40 * 40 * system.n_sensors()) as f64
    };
    type Make<'a> = Box<dyn Fn(f64) -> Box<dyn Scheme> + 'a>;
    let cases: Vec<(&str, &Arc<System>, Make)> = vec![
        (
            "innovation",
            &cv,
            Box::new(|d| Box::new(InnovationTriggerScheme::new(cv.clone(), d).unwrap())),
        ),
        (
            "closed",
            &cv,
            Box::new(|t| {
                Box::new(StochasticTriggerScheme::new(
                    cv.clone(),
                    StochasticTrigger::with_tau(&cv, TriggerLoop::Closed, t).unwrap(),
                ))
            }),
        ),
        (
            "open",
            &stable,
            Box::new(|t| {
                Box::new(StochasticTriggerScheme::new(
                    stable.clone(),
                    StochasticTrigger::with_tau(&stable, TriggerLoop::Open, t).unwrap(),
                ))
            }),
        ),
        (
            "send-on-delta",
            &cv,
            Box::new(|d| {
                Box::new(SendOnDeltaScheme::new(cv.clone(), d, SilenceModel::Uniform).unwrap())
            }),
        ),
    ];
    for (name, system, make) in &cases {
        let rates: Vec<f64> = knobs.iter().map(|&v| rate_of(system, make, v)).collect();
        assert!(
            rates.windows(2).all(|w| w[1] < w[0]),
            "{name}: rates {rates:?} do not fall"
        );
        assert!(
            rates[0] > rates[4] + 0.1,
            "{name}: rates {rates:?} barely move"
        );
    }
}

#[test]
fn constructors_and_params_name_the_field() {
    let system = cv_system();
    let field = |e: SchemeError| match e {
        SchemeError::Invalid { field, .. } => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        field(InnovationTriggerScheme::new(system.clone(), -1.0).unwrap_err()),
        "delta"
    );
    assert_eq!(
        field(SendOnDeltaScheme::new(system.clone(), f64::NAN, SilenceModel::Ignore).unwrap_err()),
        "delta"
    );
    assert_eq!(
        field(StochasticTrigger::with_tau(&system, TriggerLoop::Open, -0.1).unwrap_err()),
        "tau"
    );
    let bad_y = Matrix::from_element(1, 1, -1.0);
    assert_eq!(
        field(StochasticTrigger::with_matrix(&system, TriggerLoop::Open, bad_y).unwrap_err()),
        "Y"
    );
    let y2 = Matrix::identity(2, 2);
    assert_eq!(
        field(StochasticTrigger::with_matrix(&system, TriggerLoop::Open, y2).unwrap_err()),
        "Y"
    );
    let cx = BuildContext {
        system: &system,
        steps: 10,
        link_loss: None,
    };
    let build = |kind: &str, toml_text: &str| {
        let table: toml::Table = toml::from_str(toml_text).unwrap();
        (registry::find(kind).unwrap().build)(table, &cx)
    };
    assert!(build("innovation-trigger-kf", "delta = 1.0").is_ok());
    assert!(build("stochastic-trigger-open", "tau = 1.0").is_ok());
    assert!(build("stochastic-trigger-closed", "Y = [[2.0]]").is_ok());
    assert!(build("send-on-delta", "delta = 1.0\nsilence = \"ignore\"").is_ok());
    let e = build("send-on-delta", "delta = 1.0\ndelat = 2").unwrap_err();
    assert_eq!(e.field.as_deref(), Some("delat"));
    let e = build("innovation-trigger-kf", "delta = -2.0").unwrap_err();
    assert_eq!(e.field.as_deref(), Some("delta"));
    let e = build("stochastic-trigger-closed", "tau = 1.0\nY = [[1.0]]").unwrap_err();
    assert!(e.message.contains("exactly one"), "{}", e.message);
    for kind in [
        "innovation-trigger-kf",
        "stochastic-trigger-open",
        "stochastic-trigger-closed",
        "send-on-delta",
    ] {
        assert!(
            registry::find(kind).unwrap().knob.is_some(),
            "{kind} declares its knob"
        );
    }
}

/// The fusion as the information-form expressions write it (nalgebra's products, a fresh
/// inverse of every R'): what [`Fusion`] must reproduce bit for bit.
fn fuse_by_expressions(system: &System, pred: &Gaussian, evidence: &[Evidence]) -> Gaussian {
    use crate::filter::information::Information;
    use crate::linalg::{spd_inverse, symmetrize};
    let mut info = Information::from_gaussian(pred).unwrap();
    for (i, ev) in evidence.iter().enumerate() {
        let sensor = system.sensors[i].as_linear().unwrap();
        match ev {
            Evidence::Nothing => {}
            Evidence::Measurement(z) => info.add_measurement(sensor, z).unwrap(),
            Evidence::Pseudo { z, r } => {
                let ht_rinv = sensor.h().transpose() * spd_inverse(r).unwrap();
                let mut add = &ht_rinv * sensor.h();
                symmetrize(&mut add);
                info.matrix += add;
                info.vector += ht_rinv * *z;
            }
        }
    }
    info.to_gaussian().unwrap()
}

/// [`Fusion`] in its buffers, across steps whose silence noises repeat (its kept parts) and
/// change, equals the expressions bit for bit.
#[test]
fn fusion_in_buffers_equals_the_expressions_bit_for_bit() {
    let system = cv_system();
    let mut fusion = Fusion::new(&system);
    let mut out = system.prior.clone();
    let bits = |g: &Gaussian| {
        let m = g.mean.iter().chain(g.cov.iter());
        m.map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    let z = |v: f64| Vector::from_element(1, v);
    let r = |v: f64| Matrix::from_element(1, 1, v);
    let (z1, z2, z3) = (z(0.3), z(-1.7), z(2.9));
    let (r1, r2) = (r(1.9), r(0.7));
    let mut pred = kf::predict(&system.transition, &system.prior);
    for (k, noise) in [&r1, &r1, &r2, &r1].into_iter().enumerate() {
        let evidence = [
            Evidence::Measurement(&z1),
            Evidence::Pseudo { z: &z2, r: noise },
            Evidence::Nothing,
            Evidence::Pseudo { z: &z3, r: &r2 },
        ];
        fusion.start(&pred).unwrap();
        for (i, ev) in evidence.iter().enumerate() {
            fusion.add(&system, i, *ev).unwrap();
        }
        fusion.finish(&mut out).unwrap();
        let expected = fuse_by_expressions(&system, &pred, &evidence);
        assert_eq!(bits(&out), bits(&expected), "step {k}");
        assert_eq!(
            bits(&fuse(&system, &pred, &evidence).unwrap()),
            bits(&expected)
        );
        pred = kf::predict(&system.transition, &out);
    }
}
