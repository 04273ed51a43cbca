//! Covariance intersection and the naive sum: hand-computed fusions, the weight search, and
//! the statistical PSD order against the true error covariance.
use super::ci::{covariance_intersection, covariance_intersection_with, naive_sum};
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{cholesky, Matrix, Vector};
use crate::link::{Received, Transmission};
use crate::model::{presets, LinearSensor, MeasurementModel};
use crate::scheme::registry::{self, BuildContext};
use crate::scheme::{FusionCenter, SchemeError, SensorNode, System};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

fn diag(v: &[f64]) -> Matrix {
    Matrix::from_diagonal(&Vector::from_row_slice(v))
}

fn gaussian(mean: &[f64], cov: Matrix) -> Gaussian {
    Gaussian::new(Vector::from_row_slice(mean), cov)
}

/// P1 = diag(1, 4), P2 = diag(4, 1): by symmetry omega = 1/2, P^-1 = diag(0.625, 0.625),
/// P = 1.6 I; x = P (0.5 P1^-1 x1 + 0.5 P2^-1 x2) = 1.6 (0.125, 0.5) = (0.2, 0.8) for
/// x1 = 0, x2 = (1, 1). The naive sum: P = diag(0.8, 0.8), x = 0.8 (0.25, 1) = (0.2, 0.8).
#[test]
fn two_estimates_by_hand() {
    let a = gaussian(&[0.0, 0.0], diag(&[1.0, 4.0]));
    let b = gaussian(&[1.0, 1.0], diag(&[4.0, 1.0]));
    let (ci, w) = covariance_intersection(&[a.clone(), b.clone()]).unwrap();
    // tr P is flat at its minimum, so omega is found to ~sqrt(eps); P's entries (not flat
    // in omega) follow to ~1e-7.
    assert!((w[0] - 0.5).abs() < 1e-7, "{w:?}");
    assert!((&ci.cov - Matrix::identity(2, 2) * 1.6).amax() < 1e-6);
    assert!((&ci.mean - Vector::from_vec(vec![0.2, 0.8])).amax() < 1e-6);
    let naive = naive_sum(&[a, b]).unwrap();
    assert!((&naive.cov - Matrix::identity(2, 2) * 0.8).amax() < 1e-14);
    assert!((&naive.mean - Vector::from_vec(vec![0.2, 0.8])).amax() < 1e-14);
    // One estimate better in every direction takes all the weight.
    let good = gaussian(&[0.0, 0.0], diag(&[1.0, 1.0]));
    let bad = gaussian(&[5.0, 5.0], diag(&[3.0, 2.0]));
    let (g, w) = covariance_intersection(&[bad, good]).unwrap();
    assert!(w[1] > 1.0 - 1e-9, "{w:?}");
    assert!((g.cov[(0, 0)] - 1.0).abs() < 1e-8);
}

/// The weight search for more than two estimates finds the minimum of tr P over the simplex
/// (compared with a fine grid).
#[test]
fn ci_weights_minimize_the_trace() {
    let rot = |t: f64, s1: f64, s2: f64| {
        let r = Matrix::from_row_slice(2, 2, &[t.cos(), -t.sin(), t.sin(), t.cos()]);
        &r * diag(&[s1, s2]) * r.transpose()
    };
    let est = vec![
        gaussian(&[0.0, 0.0], rot(0.0, 1.0, 6.0)),
        gaussian(&[1.0, 0.0], rot(1.0, 1.5, 5.0)),
        gaussian(&[0.0, 1.0], rot(2.2, 0.8, 7.0)),
    ];
    let (fused, w) = covariance_intersection(&est).unwrap();
    assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12 && w.iter().all(|&x| x >= 0.0));
    let mut best = f64::INFINITY;
    let n = 200;
    for i in 0..=n {
        for j in 0..=(n - i) {
            let w = [
                i as f64 / n as f64,
                j as f64 / n as f64,
                (n - i - j) as f64 / n as f64,
            ];
            if let Ok(g) = covariance_intersection_with(&est, &w) {
                best = best.min(g.cov.trace());
            }
        }
    }
    assert!(
        fused.cov.trace() <= best + 1e-6,
        "{} vs grid {best}",
        fused.cov.trace()
    );
}

/// Two position sensors on a 1-D constant-velocity target with strong process noise: their
/// local KF errors are strongly correlated (common process noise, common prior).
fn correlated_system() -> Arc<System> {
    let h = Matrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let sensors = [1.0, 2.0]
        .iter()
        .map(|&r| {
            Arc::new(LinearSensor::new(h.clone(), Matrix::from_element(1, 1, r)).unwrap())
                as Arc<dyn MeasurementModel>
        })
        .collect();
    Arc::new(System {
        transition: presets::constant_velocity_1d(1.0, 2.0).unwrap(),
        sensors,
        prior: Gaussian::new(Vector::from_vec(vec![0.0, 1.0]), diag(&[4.0, 1.0])),
    })
}

/// Largest eigenvalue of L^{-1} S L^{-T} for P = L L^T: <= 1 iff S <= P (PSD order).
fn whitened_max_eig(p: &Matrix, s: &Matrix) -> f64 {
    let l = cholesky(p).unwrap().l();
    let li = l.clone().try_inverse().unwrap();
    let w = &li * s * li.transpose();
    w.symmetric_eigenvalues().max()
}

/// Covariance intersection's P is never below the true error covariance; the naive sum's
/// is. P is deterministic here (linear sensors, every step sent), the true covariance is
/// estimated from M trials: u^T S u has relative standard error sqrt(2/M), so the tests use
/// 1 +- 4 sqrt(2/M) (M = 3000: 1 +- 0.10), at several steps.
#[test]
fn ci_is_never_below_the_true_error_covariance_and_the_naive_sum_is() {
    let system = correlated_system();
    let (trials, steps) = (3000, 12);
    let at = [1, 4, 12];
    let mut s_ci = vec![Matrix::zeros(2, 2); at.len()];
    let mut s_naive = vec![Matrix::zeros(2, 2); at.len()];
    let mut p_ci = vec![Matrix::zeros(2, 2); at.len()];
    let mut p_naive = vec![Matrix::zeros(2, 2); at.len()];
    let sqrt = crate::model::transition::psd_sqrt(&system.prior.cov).unwrap();
    for t in 0..trials {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(77_000 + t as u64);
        let n0 = Vector::from_fn(2, |_, _| {
            rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng)
        });
        let mut x = &system.prior.mean + &sqrt * n0;
        let mut nodes: Vec<LocalKfSensor> = (0..2)
            .map(|i| LocalKfSensor::new(system.clone(), i, 0.0).unwrap())
            .collect();
        let mut ci = EstimateFusionCenter::new(system.clone(), FusionRule::CovarianceIntersection);
        let mut naive = EstimateFusionCenter::new(system.clone(), FusionRule::NaiveSum);
        for k in 1..=steps {
            x = system.transition.sample_next(&x, &mut rng);
            let inbox: Vec<Received> = nodes
                .iter_mut()
                .enumerate()
                .map(|(i, n)| {
                    let z = system.sensors[i].sample(&x, &mut rng);
                    Received::from(n.step(k, &z, None, &mut rng).unwrap())
                })
                .collect();
            ci.step(k, &inbox).unwrap();
            naive.step(k, &inbox).unwrap();
            if let Some(j) = at.iter().position(|&a| a == k) {
                let e = &x - &ci.estimate().mean;
                s_ci[j] += &e * e.transpose() / trials as f64;
                let e = &x - &naive.estimate().mean;
                s_naive[j] += &e * e.transpose() / trials as f64;
                if t == 0 {
                    p_ci[j] = ci.estimate().cov.clone();
                    p_naive[j] = naive.estimate().cov.clone();
                } else {
                    assert_eq!(p_ci[j], ci.estimate().cov, "deterministic P");
                }
            }
        }
    }
    let tol = 4.0 * (2.0 / trials as f64).sqrt();
    for j in 0..at.len() {
        let l_ci = whitened_max_eig(&p_ci[j], &s_ci[j]);
        let l_naive = whitened_max_eig(&p_naive[j], &s_naive[j]);
        eprintln!(
            "step {}: lambda_max CI {l_ci:.3}, naive {l_naive:.3}",
            at[j]
        );
        assert!(
            l_ci < 1.0 + tol,
            "step {}: CI below the true covariance ({l_ci})",
            at[j]
        );
        assert!(
            l_naive > 1.0 + tol,
            "step {}: naive sum not overconfident ({l_naive})",
            at[j]
        );
    }
}

/// The center's replica of a linear sensor's local covariance is the sensor's, bit for bit,
/// so only x travels; with an event threshold the rate falls as delta grows.
#[test]
fn replica_covariance_and_send_rate() {
    let system = correlated_system();
    let rate = |delta: f64| {
        let mut sent = 0;
        for t in 0..30 {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(t);
            let mut x = system.prior.mean.clone();
            let mut nodes: Vec<LocalKfSensor> = (0..2)
                .map(|i| LocalKfSensor::new(system.clone(), i, delta).unwrap())
                .collect();
            let mut c =
                EstimateFusionCenter::new(system.clone(), FusionRule::CovarianceIntersection);
            for k in 1..=30 {
                x = system.transition.sample_next(&x, &mut rng);
                let mut inbox = Vec::new();
                for (i, n) in nodes.iter_mut().enumerate() {
                    let z = system.sensors[i].sample(&x, &mut rng);
                    let tx = n.step(k, &z, None, &mut rng).unwrap();
                    if let Transmission::Send(m) = &tx {
                        assert_eq!(m.bits(), 2 * 32, "x only: P is replicated");
                        sent += 1;
                    }
                    inbox.push(Received::from(tx));
                }
                c.step(k, &inbox).unwrap();
                for (i, n) in nodes.iter().enumerate() {
                    if inbox[i] != Received::Silent {
                        assert_eq!(c.copies()[i].cov, n.estimate().cov);
                        // The copy is the estimate as it arrived: singles.
                        let sent = n.estimate().mean.map(crate::link::as_sent);
                        assert_eq!(c.copies()[i].mean, sent);
                    }
                }
            }
        }
        sent as f64 / (30.0 * 30.0 * 2.0)
    };
    let rates: Vec<f64> = [0.0, 0.5, 1.0, 2.0, 4.0].iter().map(|&d| rate(d)).collect();
    assert_eq!(rates[0], 1.0);
    assert!(rates.windows(2).all(|w| w[1] < w[0]), "{rates:?}");
}

/// A sensor with no reading for a few steps (not scheduled: its node is not called) passes
/// them in time: after the gap its estimate, and the center's replica of its covariance, are
/// those of a filter that predicted across the gap.
#[test]
fn a_gap_without_readings_is_predicted_across_by_node_and_center() {
    let system = correlated_system();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let mut node = LocalKfSensor::new(system.clone(), 0, 0.0).unwrap();
    let mut reference = system.prior.clone();
    let mut c = EstimateFusionCenter::new(system.clone(), FusionRule::CovarianceIntersection);
    let mut x = system.prior.mean.clone();
    let gap = 4..8;
    for k in 1..=10 {
        x = system.transition.sample_next(&x, &mut rng);
        let z = system.sensors[0].sample(&x, &mut rng);
        let mut inbox = vec![Received::NotScheduled, Received::NotScheduled];
        if gap.contains(&k) {
            reference = kf::predict(&system.transition, &reference);
        } else {
            reference = kf::step(
                &system.transition,
                &reference,
                &[(system.sensors[0].as_ref(), &z)],
            )
            .unwrap();
            inbox[0] = Received::from(node.step(k, &z, None, &mut rng).unwrap());
        }
        c.step(k, &inbox).unwrap();
        if !gap.contains(&k) {
            assert_eq!(node.estimate().mean, reference.mean, "step {k}");
            assert_eq!(node.estimate().cov, reference.cov, "step {k}");
            assert_eq!(c.copies()[0].cov, reference.cov, "center replica, step {k}");
        }
    }
}

// A linear sensor that hides its linearity: its covariance must travel.
use crate::model::Opaque;

#[test]
fn nonlinear_sensors_send_their_covariance() {
    let linear = correlated_system();
    let opaque = Arc::new(System {
        transition: linear.transition.clone(),
        sensors: linear
            .sensors
            .iter()
            .map(|s| Arc::new(Opaque(s.as_linear().unwrap().clone())) as Arc<dyn MeasurementModel>)
            .collect(),
        prior: linear.prior.clone(),
    });
    let g = gaussian(
        &[1.0, 2.0],
        Matrix::from_row_slice(2, 2, &[3.0, 0.5, 0.5, 2.0]),
    );
    assert_eq!(pack(&g).as_slice(), &[1.0, 2.0, 3.0, 0.5, 2.0]);
    assert_eq!(unpack(&pack(&g), 2).unwrap(), g);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let mut a = LocalKfSensor::new(opaque.clone(), 0, 0.0).unwrap();
    let mut b = LocalKfSensor::new(opaque.clone(), 1, 0.0).unwrap();
    let mut c_opaque = EstimateFusionCenter::new(opaque.clone(), FusionRule::NaiveSum);
    let mut c_linear = EstimateFusionCenter::new(linear.clone(), FusionRule::NaiveSum);
    let mut la = LocalKfSensor::new(linear.clone(), 0, 0.0).unwrap();
    let mut lb = LocalKfSensor::new(linear.clone(), 1, 0.0).unwrap();
    for k in 1..=10 {
        let z = Vector::from_element(1, k as f64);
        let ta = a.step(k, &z, None, &mut rng).unwrap();
        let Transmission::Send(m) = &ta else {
            panic!("delta = 0 sends")
        };
        assert_eq!(m.bits(), (2 + 3) * 32, "x and the 3 distinct entries of P");
        let tb = b.step(k, &z, None, &mut rng).unwrap();
        c_opaque.step(k, &[ta.into(), tb.into()]).unwrap();
        let inbox = [
            la.step(k, &z, None, &mut rng).unwrap().into(),
            lb.step(k, &z, None, &mut rng).unwrap().into(),
        ];
        c_linear.step(k, &inbox).unwrap();
        // The opaque sensors' P crosses the network as singles (`link::as_sent`, relative
        // error at most 2^-24 per entry) while the linear center computes P itself: equal to
        // single precision, no longer to double.
        let d_cov = (&c_opaque.estimate().cov - &c_linear.estimate().cov).amax();
        let d_mean = (&c_opaque.estimate().mean - &c_linear.estimate().mean).amax();
        assert!(
            d_cov < 1e-6 && d_mean < 1e-6,
            "step {k}: {d_cov:e}, {d_mean:e}"
        );
    }
    // A bare x where x and P are expected is a protocol error.
    let err = c_opaque
        .step(
            11,
            &[Received::Estimate(Vector::zeros(2)), Received::Silent],
        )
        .unwrap_err();
    assert!(matches!(err, SchemeError::Protocol { sensor: 0, .. }));
}

#[test]
fn params_and_validation() {
    let system = correlated_system();
    assert!(matches!(
        EstimateFusionScheme::new(system.clone(), FusionRule::NaiveSum, -1.0),
        Err(SchemeError::Invalid { field: "delta", .. })
    ));
    let cx = BuildContext {
        system: &system,
        steps: 10,
        link_loss: None,
    };
    for kind in ["ci-fusion", "naive-fusion"] {
        let entry = registry::find(kind).unwrap();
        assert_eq!(entry.knob.map(|k| k.name), Some("delta"));
        assert!(
            (entry.build)(toml::Table::new(), &cx).is_ok(),
            "delta defaults to 0"
        );
        let t: toml::Table = toml::from_str("delta = -1.0").unwrap();
        assert_eq!(
            (entry.build)(t, &cx).unwrap_err().field.as_deref(),
            Some("delta")
        );
        let t: toml::Table = toml::from_str("omega = 0.5").unwrap();
        assert_eq!(
            (entry.build)(t, &cx).unwrap_err().field.as_deref(),
            Some("omega")
        );
    }
}

/// The allocating forms the in-place ones replaced, kept as the reference they must
/// reproduce bit for bit.
mod reference {
    use crate::filter::information::Information;
    use crate::filter::{FilterError, Gaussian};
    use crate::linalg::{cholesky, Matrix, Vector};

    fn weighted(infos: &[Information], w: &[f64]) -> Information {
        let n = infos[0].vector.len();
        let mut matrix = Matrix::zeros(n, n);
        let mut vector = Vector::zeros(n);
        for (info, &wi) in infos.iter().zip(w) {
            if wi > 0.0 {
                matrix += &info.matrix * wi;
                vector += &info.vector * wi;
            }
        }
        Information { matrix, vector }
    }

    fn trace_of(infos: &[Information], w: &[f64]) -> f64 {
        match cholesky(&weighted(infos, w).matrix) {
            Ok(c) => c.inverse().trace(),
            Err(_) => f64::INFINITY,
        }
    }

    fn ci_weights_of(infos: &[Information]) -> Vec<f64> {
        let m = infos.len();
        match m {
            0 => vec![],
            1 => vec![1.0],
            2 => {
                let f = |a: f64| trace_of(infos, &[a, 1.0 - a]);
                let g = 0.5 * (5f64.sqrt() - 1.0);
                let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
                let mut c = hi - g * (hi - lo);
                let mut d = lo + g * (hi - lo);
                let (mut fc, mut fd) = (f(c), f(d));
                for _ in 0..60 {
                    if fc < fd {
                        hi = d;
                        d = c;
                        fd = fc;
                        c = hi - g * (hi - lo);
                        fc = f(c);
                    } else {
                        lo = c;
                        c = d;
                        fc = fd;
                        d = lo + g * (hi - lo);
                        fd = f(d);
                    }
                }
                let mid = 0.5 * (lo + hi);
                let best = [(f(mid), mid), (f(0.0), 0.0), (f(1.0), 1.0)]
                    .into_iter()
                    .fold((f64::INFINITY, mid), |a, b| if b.0 < a.0 { b } else { a })
                    .1;
                vec![best, 1.0 - best]
            }
            _ => {
                let mut w = vec![1.0 / m as f64; m];
                let mut value = trace_of(infos, &w);
                let mut eta = 1.0;
                for _ in 0..100 {
                    let Ok(c) = cholesky(&weighted(infos, &w).matrix) else {
                        break;
                    };
                    let p = c.inverse();
                    let grad: Vec<f64> = infos
                        .iter()
                        .map(|info| -(&p * &info.matrix * &p).trace())
                        .collect();
                    let scale = grad.iter().fold(0.0_f64, |a, g| a.max(g.abs()));
                    if scale.is_nan() || scale <= 0.0 {
                        break;
                    }
                    let mut improved = false;
                    while eta > 1e-8 {
                        let mut trial: Vec<f64> = w
                            .iter()
                            .zip(&grad)
                            .map(|(wi, gi)| wi * (-eta * gi / scale).exp())
                            .collect();
                        let sum: f64 = trial.iter().sum();
                        trial.iter_mut().for_each(|t| *t /= sum);
                        let v = trace_of(infos, &trial);
                        if v < value {
                            let gain = value - v;
                            w = trial;
                            value = v;
                            improved = gain > 1e-13 * value;
                            eta = (eta * 2.0).min(8.0);
                            break;
                        }
                        eta *= 0.5;
                    }
                    if !improved {
                        break;
                    }
                }
                w
            }
        }
    }

    pub fn covariance_intersection(
        estimates: &[Gaussian],
    ) -> Result<(Gaussian, Vec<f64>), FilterError> {
        let infos: Vec<Information> = estimates
            .iter()
            .map(Information::from_gaussian)
            .collect::<Result<_, _>>()?;
        let w = ci_weights_of(&infos);
        Ok((weighted(&infos, &w).to_gaussian()?, w))
    }

    pub fn naive_sum(estimates: &[Gaussian]) -> Result<Gaussian, FilterError> {
        let infos: Vec<Information> = estimates
            .iter()
            .map(Information::from_gaussian)
            .collect::<Result<_, _>>()?;
        weighted(&infos, &vec![1.0; infos.len()]).to_gaussian()
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn random_spd(rng: &mut Xoshiro256PlusPlus, n: usize, ridge: f64) -> Matrix {
    use rand::Rng;
    let b = Matrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
    let mut a = &b * b.transpose() + Matrix::identity(n, n) * ridge;
    crate::linalg::symmetrize(&mut a);
    a
}

/// The in-place fusion rules (one `FusionWork` reused throughout) reproduce the allocating
/// forms bit for bit: weights, mean and covariance, for 1..=5 estimates of dimensions 1..=7
/// (the golden section at two, the exponentiated gradient above), some nearly singular.
#[test]
fn in_place_fusion_is_the_allocating_fusion_bit_for_bit() {
    use rand::Rng;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(21);
    for trial in 0..300 {
        let (m, n) = (1 + trial % 5, 1 + (trial / 5) % 7);
        let est: Vec<Gaussian> = (0..m)
            .map(|_| {
                let ridge = if rng.random_bool(0.2) { 1e-9 } else { 0.05 };
                Gaussian::new(
                    Vector::from_fn(n, |_, _| rng.random_range(-3.0..3.0)),
                    random_spd(&mut rng, n, ridge),
                )
            })
            .collect();
        let mut work = ci::FusionWork::new(m, n);
        let mut out = Gaussian::new(Vector::zeros(n), Matrix::zeros(n, n));
        for _ in 0..2 {
            let (want, w) = reference::covariance_intersection(&est).unwrap();
            ci::covariance_intersection_into(&est, &mut out, &mut work).unwrap();
            assert_eq!(bits(&w), bits(work.weights()), "m {m} n {n}");
            assert_eq!(bits(want.mean.as_slice()), bits(out.mean.as_slice()));
            assert_eq!(bits(want.cov.as_slice()), bits(out.cov.as_slice()));
            let want = reference::naive_sum(&est).unwrap();
            ci::naive_sum_into(&est, &mut out, &mut work).unwrap();
            assert_eq!(bits(want.mean.as_slice()), bits(out.mean.as_slice()));
            assert_eq!(bits(want.cov.as_slice()), bits(out.cov.as_slice()));
        }
    }
}

/// `update_linear` is `kf::update` bit for bit (mean and covariance) on random priors and
/// linear sensors of 1..=3 readings on states of dimensions 1..=7, with reused buffers.
#[test]
fn update_linear_is_the_kf_update_bit_for_bit() {
    use rand::Rng;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(8);
    for trial in 0..300 {
        let (m, n) = (1 + trial % 3, 1 + (trial / 3) % 7);
        let h = Matrix::from_fn(m, n, |_, _| rng.random_range(-1.0..1.0));
        let sensor = LinearSensor::new(h, random_spd(&mut rng, m, 0.1)).unwrap();
        let mut work = LinearUpdateWork::new(&sensor);
        for _ in 0..2 {
            let prior = Gaussian::new(
                Vector::from_fn(n, |_, _| rng.random_range(-3.0..3.0)),
                random_spd(&mut rng, n, 0.05),
            );
            let z = Vector::from_fn(m, |_, _| rng.random_range(-3.0..3.0));
            let want = kf::update(&sensor, prior.clone(), &z).unwrap();
            let mut got = prior;
            update_linear(&sensor, &mut got, &z, &mut work).unwrap();
            assert_eq!(
                bits(want.mean.as_slice()),
                bits(got.mean.as_slice()),
                "m {m} n {n}"
            );
            assert_eq!(
                bits(want.cov.as_slice()),
                bits(got.cov.as_slice()),
                "m {m} n {n}"
            );
        }
    }
}
