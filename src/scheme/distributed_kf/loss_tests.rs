//! The center's fallback for estimates missing twice or more in a row ([`super::loss`]).
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::model::{presets, LinearSensor, LinearTransition, MeasurementModel};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

fn scalar_system(a: f64, q: f64, r: f64, m0: f64, p0: f64) -> Arc<System> {
    let one = |v: f64| Matrix::from_element(1, 1, v);
    Arc::new(System {
        transition: LinearTransition::new(one(a), one(q)).unwrap(),
        sensors: vec![Arc::new(LinearSensor::new(one(1.0), one(r)).unwrap())],
        prior: Gaussian::new(Vector::from_element(1, m0), one(p0)),
    })
}

#[test]
fn one_sensor_lost_from_the_start_leaves_the_pure_prediction() {
    // One sensor (the globalized filter is then the standard KF, Δ = 1). Nothing arrives:
    // step 1 is Algorithm 1's exact omission (the prediction a m0, a^2 p0 + q); from step 2
    // the fallback must give the prediction of the prior too, by hand:
    // k = 2: a^2 m0 and a^2 (a^2 p0 + q) + q; k = 3: a^3 m0 and a^2 P_2 + q.
    let (a, q, r, m0, p0) = (1.2, 0.5, 2.0, 1.5, 3.0);
    let system = scalar_system(a, q, r, m0, p0);
    let scheme = DistributedKfScheme::full_rate(system, 4).unwrap();
    let mut inst = scheme.build().unwrap();
    let (mut mean, mut var) = (m0, p0);
    for k in 1..=4 {
        inst.center.step(k, &[Received::Silent]).unwrap();
        mean *= a;
        var = a * a * var + q;
        let est = inst.center.estimate();
        assert!(
            (est.mean[0] - mean).abs() < 1e-12 * mean.abs(),
            "step {k}: {} vs {mean}",
            est.mean[0]
        );
        assert!(
            (est.cov[(0, 0)] - var).abs() < 1e-12 * var,
            "step {k}: {} vs {var}",
            est.cov[(0, 0)]
        );
    }
    // And by the hand values themselves at k = 2 (1.2^2 (1.2^2 3 + 0.5) + 0.5 = 7.4408).
    let mut inst = scheme.build().unwrap();
    inst.center.step(1, &[Received::Silent]).unwrap();
    inst.center.step(2, &[Received::Silent]).unwrap();
    assert!((inst.center.estimate().cov[(0, 0)] - 7.4408).abs() < 1e-12);
    assert!((inst.center.estimate().mean[0] - 2.16).abs() < 1e-12);
}

#[test]
fn one_sensor_lost_after_an_arrival_is_the_prediction_of_what_arrived() {
    // Sent at 1 (arrived), lost at 2 and 3: the center holds x̄_1 (the KF estimate of step 1,
    // variance P_1) and at k = 3 must give a^2 x̄_1 and a^2 (a^2 P_1 + q) + q.
    let (a, q, r, m0, p0) = (0.9, 0.3, 1.0, -0.5, 2.0);
    let system = scalar_system(a, q, r, m0, p0);
    let scheme = DistributedKfScheme::full_rate(system, 3).unwrap();
    let mut inst = scheme.build().unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    let z = Vector::from_element(1, 0.7);
    let Transmission::Send(Message::Estimate(x1)) =
        inst.sensors[0].step(1, &z, None, &mut rng).unwrap()
    else {
        panic!("full rate sends")
    };
    inst.center
        .step(1, &[Received::Estimate(x1.clone())])
        .unwrap();
    let p1 = inst.center.estimate().cov[(0, 0)];
    let pp = a * a * p0 + q;
    assert!((p1 - pp * r / (pp + r)).abs() < 1e-12);
    inst.center.step(2, &[Received::Silent]).unwrap();
    inst.center.step(3, &[Received::Silent]).unwrap();
    let est = inst.center.estimate();
    let want = a * a * (a * a * p1 + q) + q;
    assert!(
        (est.cov[(0, 0)] - want).abs() < 1e-12 * want,
        "{} vs {want}",
        est.cov[(0, 0)]
    );
    assert!((est.mean[0] - a * a * x1[0]).abs() < 1e-12);
}

/// Section V's system (as in `tests.rs`).
fn dormann_system() -> Arc<System> {
    let transition = presets::near_constant_acceleration_2d(0.25, 1.0).unwrap();
    let pick = |a: usize, b: usize| {
        let mut h = Matrix::zeros(2, 6);
        h[(0, a)] = 1.0;
        h[(1, b)] = 1.0;
        Arc::new(LinearSensor::new(h, Matrix::identity(2, 2)).unwrap()) as Arc<dyn MeasurementModel>
    };
    let sensors = vec![
        pick(0, 3),
        pick(0, 3),
        pick(1, 4),
        pick(1, 4),
        pick(2, 5),
        pick(2, 5),
    ];
    let prior = Gaussian::new(
        Vector::from_vec(vec![1.0, 0.5, 0.1, -2.0, 0.3, 0.0]),
        Matrix::from_diagonal(&Vector::from_vec(vec![4.0, 1.0, 0.5, 4.0, 1.0, 0.5])),
    );
    Arc::new(System {
        transition,
        sensors,
        prior,
    })
}

/// Mean NEES at step `at` of the loss-aware center and of the naive one (the same mean with
/// (10)'s covariance, uninflated) over `runs` trials, in which the sensors in `lost` miss
/// their estimates at steps `from..=at` and every other estimate arrives.
fn mean_nees(lost: &[usize], from: usize, at: usize, runs: usize, seed: u64) -> (f64, f64, f64) {
    let system = dormann_system();
    let scheme = DistributedKfScheme::full_rate(system.clone(), at).unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let chol = crate::linalg::cholesky(&system.prior.cov).unwrap();
    let (mut aware, mut aware2, mut naive) = (0.0, 0.0, 0.0);
    for _ in 0..runs {
        let mut inst = scheme.build().unwrap();
        let normals = Vector::from_fn(6, |_, _| rng.sample::<f64, _>(StandardNormal));
        let mut x = &system.prior.mean + chol.l() * normals;
        for k in 1..=at {
            x = system.transition.sample_next(&x, &mut rng);
            let inbox: Vec<Received> = (0..6)
                .map(|i| {
                    let z = system.sensors[i].sample(&x, &mut rng);
                    let t = inst.sensors[i].step(k, &z, None, &mut rng).unwrap();
                    match t {
                        Transmission::Send(m) if !(lost.contains(&i) && k >= from) => {
                            Transmission::Send(m).into()
                        }
                        _ => Received::Silent,
                    }
                })
                .collect();
            inst.center.step(k, &inbox).unwrap();
        }
        let est = inst.center.estimate();
        let e = &x - &est.mean;
        let nees = crate::linalg::mahalanobis_sq(&e, &est.cov).unwrap();
        aware += nees;
        aware2 += nees * nees;
        // The naive center: (10)'s covariance of the same silence set, uninflated.
        let silent: u64 = lost.iter().map(|&i| 1u64 << i).sum();
        let center = DkfCenter::new(
            scheme.plan().clone(),
            system.sensors.clone(),
            system.prior.clone(),
            Fusion::OmittedEstimates,
        );
        let p = scheme.plan().index(at).unwrap();
        let base = center.fused_covariance(p, silent, 0).unwrap();
        naive += crate::linalg::mahalanobis_sq(&e, &base.cov).unwrap();
    }
    let n = runs as f64;
    let mean = aware / n;
    let se = ((aware2 / n - mean * mean) / n).sqrt();
    (mean, se, naive / n)
}

#[test]
fn one_lost_sensor_gives_a_consistent_estimate_and_the_naive_one_does_not() {
    // One sensor lost over steps 3..=8 of Section V's system, every other estimate arriving:
    // the missing pattern does not depend on the data and L = 1, so the fallback's covariance
    // is the error covariance itself and the mean NEES is n = 6, to within 4 Monte Carlo
    // standard errors (from the sample). Position, velocity and acceleration sensors.
    for (lost, seed) in [(0usize, 11u64), (2, 12), (4, 13)] {
        let (mean, se, naive) = mean_nees(&[lost], 3, 8, 3000, seed);
        eprintln!("sensor {lost} lost over 3..=8: mean NEES {mean:.3} ± {se:.3}, naive {naive:.3}");
        assert!(
            (mean - 6.0).abs() < 4.0 * se,
            "sensor {lost}: mean NEES {mean} ± {se}"
        );
        assert!(
            naive > 6.0 + 10.0 * se,
            "sensor {lost}: the naive center's mean NEES {naive} should be far above 6"
        );
    }
}

#[test]
fn two_lost_sensors_give_a_conservative_estimate() {
    // L = 2: E[D D^T] <= 2 (S^1 + S^2), so the mean NEES may sit below n, not above.
    let (mean, se, naive) = mean_nees(&[0, 2], 2, 7, 3000, 21);
    eprintln!("sensors 0, 2 lost over 2..=7: mean NEES {mean:.3} ± {se:.3}, naive {naive:.3}");
    assert!(mean < 6.0 + 4.0 * se, "mean NEES {mean} ± {se}");
    assert!(naive > 6.0 + 10.0 * se, "naive {naive}");
}
