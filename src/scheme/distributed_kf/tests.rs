//! Exactness properties of Dormann et al.'s Section II and Algorithm 1.
use super::*;
use crate::filter::{information, kf, Gaussian};
use crate::linalg::{relative_difference, Matrix, Vector};
use crate::link::{Received, Transmission};
use crate::model::{presets, LinearSensor, MeasurementModel};
use crate::scheme::centralized::CentralizedKf;
use crate::scheme::FusionCenter;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Section V's system: NCA model, two position, two velocity, two acceleration sensors.
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

fn simulate(system: &System, steps: usize, seed: u64) -> Vec<Vec<Vector>> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut x = system.prior.mean.clone();
    (0..steps)
        .map(|_| {
            x = system.transition.sample_next(&x, &mut rng);
            system
                .sensors
                .iter()
                .map(|s| s.sample(&x, &mut rng))
                .collect()
        })
        .collect()
}

fn rel_vec(a: &Vector, b: &Vector) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}

/// Drives sensors and center with a prescribed send pattern, bypassing the trigger. Estimates
/// are delivered exactly (not as the singles of `link::as_sent`): the identities checked here
/// are the algorithm's (exact arithmetic up to rounding), not the wire's.
fn run_pattern(system: &Arc<System>, data: &[Vec<Vector>], pattern: &[Vec<bool>]) -> Vec<Gaussian> {
    let scheme =
        DistributedKfScheme::new(system.clone(), data.len(), Trigger::Always, None).unwrap();
    let mut inst = scheme.build().unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0);
    let mut out = Vec::new();
    for (k0, zs) in data.iter().enumerate() {
        let k = k0 + 1;
        let inbox: Vec<Received> = inst
            .sensors
            .iter_mut()
            .zip(zs)
            .zip(&pattern[k0])
            .map(
                |((s, z), &send)| match s.step(k, z, None, &mut rng).unwrap() {
                    Transmission::Send(crate::link::Message::Estimate(x)) if send => {
                        Received::Estimate(x)
                    }
                    _ => Received::Silent,
                },
            )
            .collect();
        inst.center.step(k, &inbox).unwrap();
        out.push(inst.center.estimate().clone());
    }
    out
}

#[test]
fn full_rate_globalized_dkf_equals_centralized_kf() {
    let system = dormann_system();
    let data = simulate(&system, 60, 7);
    let all = vec![vec![true; 6]; data.len()];
    let dkf = run_pattern(&system, &data, &all);
    let mut ckf = CentralizedKf::new(system.clone());
    for (k0, zs) in data.iter().enumerate() {
        let inbox: Vec<Received> = zs
            .iter()
            .map(|z| Received::Measurement(z.clone()))
            .collect();
        ckf.step(k0 + 1, &inbox).unwrap();
        let c = ckf.estimate();
        assert!(
            relative_difference(&dkf[k0].cov, &c.cov) < 1e-9,
            "step {k0}"
        );
        assert!(rel_vec(&dkf[k0].mean, &c.mean) < 1e-9, "step {k0}");
    }
}

proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 48,
        // A fixed seed: the same cases on every run and machine (CI included).
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0004),
        ..proptest::prelude::ProptestConfig::default()
    })]
    /// Algorithm 1 (eq. (10)-(11)) equals the centralized KF that received every measurement up
    /// to k-1 and the same subset at k, for random patterns with a transmission at least every
    /// other step.
    #[test]
    fn algorithm1_equals_centralized_kf_with_same_subset(seed in 0u64..10_000, steps in 2usize..40) {
        let system = dormann_system();
        let data = simulate(&system, steps, seed);
        let mut prng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x9e37);
        let mut pattern = Vec::new();
        let mut prev = vec![true; 6];
        for _ in 0..steps {
            let row: Vec<bool> = prev.iter().map(|&p| !p || prng.random::<bool>()).collect();
            prev = row.clone();
            pattern.push(row);
        }
        let dkf = run_pattern(&system, &data, &pattern);
        let mut full = system.prior.clone();
        for (k0, zs) in data.iter().enumerate() {
            let pred = kf::predict(&system.transition, &full);
            let lin: Vec<&LinearSensor> = system.sensors.iter().map(|s| s.as_linear().unwrap()).collect();
            let subset: Vec<(&LinearSensor, &Vector)> = lin.iter().zip(zs).zip(&pattern[k0])
                .filter(|(_, &s)| s).map(|((l, z), _)| (*l, z)).collect();
            let reference = information::update(&pred, &subset).unwrap();
            prop_assert!(relative_difference(&dkf[k0].cov, &reference.cov) < 1e-9);
            prop_assert!(rel_vec(&dkf[k0].mean, &reference.mean) < 1e-9,
                "step {}: {} vs {}", k0, dkf[k0].mean, reference.mean);
            let everything: Vec<(&LinearSensor, &Vector)> = lin.iter().copied().zip(zs).collect();
            full = information::update(&pred, &everything).unwrap();
        }
    }
}

#[test]
fn algorithm1_survives_estimates_missing_twice_in_a_row() {
    // Under the protocol only a loss makes an estimate miss twice: the center falls back
    // (see `loss`) instead of stopping.
    let system = dormann_system();
    let scheme = DistributedKfScheme::new(system.clone(), 5, Trigger::Always, None).unwrap();
    let mut inst = scheme.build().unwrap();
    let silent = vec![Received::Silent; 6];
    for k in 1..=5 {
        inst.center.step(k, &silent).unwrap();
        let est = inst.center.estimate();
        assert!(est.mean.iter().all(|v| v.is_finite()), "step {k}");
        crate::linalg::check_spd(&est.cov).unwrap();
    }
}

#[test]
fn random_rate_mapping_hits_the_target_rate() {
    // p = 2 - 1/r; the stationary sending fraction of the forced-send chain is 1/(2 - p).
    for &r in &[0.5, 0.6, 0.75, 0.9, 1.0] {
        let Trigger::Random {
            send_probability: p,
        } = Trigger::random_for_rate(r)
        else {
            unreachable!()
        };
        assert!((1.0 / (2.0 - p) - r).abs() < 1e-12);
    }
}

#[test]
fn debiasing_matrices_track_the_bias_of_globalized_estimates() {
    // Section IV: E(x̄^{e,i}_k) = Δ^{e,i}_k E(x_k). Check it without inverting Δ (which is
    // ill-conditioned for a sensor that sees only velocity): per component, the mean of
    // x̄ - Δ x over independent runs must be within 4 Monte Carlo standard errors of zero,
    // while the raw bias x̄ - x is many standard errors away from zero (so the test can fail).
    let system = dormann_system();
    let steps = 20;
    let scheme = DistributedKfScheme::new(system.clone(), steps, Trigger::Always, None).unwrap();
    let plan = scheme.plan().clone();
    let runs = 4000;
    for sensor_index in [0, 2, 4] {
        let delta = plan.at(steps).unwrap().delta_e[sensor_index].clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(99 + sensor_index as u64);
        let (mut s1, mut s2) = (Vector::zeros(6), Vector::zeros(6));
        let (mut r1, mut r2) = (Vector::zeros(6), Vector::zeros(6));
        for _ in 0..runs {
            let mut x = system.prior.mean.clone();
            let mut node = DkfSensor::new(
                plan.clone(),
                sensor_index,
                system.sensors[sensor_index].clone(),
                x.clone(),
                Trigger::Always,
            );
            for k in 1..=steps {
                x = system.transition.sample_next(&x, &mut rng);
                let z = system.sensors[sensor_index].sample(&x, &mut rng);
                crate::scheme::SensorNode::step(&mut node, k, &z, None, &mut rng).unwrap();
            }
            let d = node.globalized_estimate() - &delta * &x;
            let r = node.globalized_estimate() - &x;
            s1 += &d;
            s2 += d.component_mul(&d);
            r1 += &r;
            r2 += r.component_mul(&r);
        }
        let n = runs as f64;
        let z_scores = |s1: &Vector, s2: &Vector| -> Vector {
            Vector::from_fn(6, |j, _| {
                let mean = s1[j] / n;
                let var = (s2[j] / n - mean * mean).max(1e-300);
                mean / (var / n).sqrt()
            })
        };
        let debiased = z_scores(&s1, &s2);
        let raw = z_scores(&r1, &r2);
        assert!(
            debiased.amax() < 4.0,
            "sensor {sensor_index}: z = {debiased}"
        );
        assert!(
            raw.amax() > 10.0,
            "sensor {sensor_index}: raw bias z = {raw}"
        );
    }
}
