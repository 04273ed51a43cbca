//! Tests of [`super`] (the summary of a run's sums).
use super::*;
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::network::Traffic;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// A consistent 2-D filter over 1000 trials (error ~ N(0, I), covariance I), except that one
/// trial in a thousand claims a covariance 1e-12 I at every step (NEES ~ 1e12).
fn synthetic(collapsed: bool) -> (Sums, Vec<f64>) {
    let (trials, steps, n) = (1000, 50, 2);
    let mut sums = Sums::new(1, steps, n);
    let groups = vec![("all".to_string(), vec![0, 1])];
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
    let truth = Vector::zeros(n);
    for t in 0..trials {
        let mut obs = sums.trial(&groups, 11);
        let scale = if collapsed && t == 500 { 1e-12 } else { 1.0 };
        for k in 1..=steps {
            let mean = Vector::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
            let est = Gaussian::new(mean, Matrix::identity(n, n) * scale);
            obs.record(k, &truth, &est, Traffic::default()).unwrap();
        }
        obs.finish();
    }
    let anees: Vec<f64> = (0..steps)
        .map(|k| sums.at(k, Layout::NEES) / trials as f64 / n as f64)
        .collect();
    (sums, anees)
}

/// One trial that collapses before the steady state (at step 2 of 50) carries the printed
/// ANEES (every step) but no steady-state value: flagged all the same (it printed ANEES 10.0
/// unmarked at 20,000 trials).
#[test]
fn a_trial_collapsed_before_the_steady_state_is_flagged() {
    let (n, trials, steps) = (2, 1000, 50);
    let mut sums = Sums::new(1, steps, n);
    let groups = vec![("all".to_string(), vec![0, 1])];
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(9);
    let truth = Vector::zeros(n);
    for t in 0..trials {
        let mut obs = sums.trial(&groups, 11);
        for k in 1..=steps {
            let scale = if t == 3 && k == 2 { 1e-12 } else { 1.0 };
            let mean = Vector::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
            let est = Gaussian::new(mean, Matrix::identity(n, n) * scale);
            obs.record(k, &truth, &est, Traffic::default()).unwrap();
        }
        obs.finish();
    }
    let anees: Vec<f64> = (0..steps)
        .map(|k| sums.at(k, Layout::NEES) / trials as f64 / n as f64)
        .collect();
    let c = consistency(n, trials, 11, &sums, &anees);
    let mean = anees.iter().sum::<f64>() / steps as f64;
    assert!(mean > 100.0, "the printed ANEES is ruined: {mean}");
    assert!(c.mean_dominated && c.top_trials_share > 0.99, "{c:?}");
    // Without the collapse: not flagged.
    let (good, good_anees) = synthetic(false);
    assert!(!consistency(2, 1000, 11, &good, &good_anees).mean_dominated);
}

#[test]
fn one_collapsed_trial_in_a_thousand_is_flagged_while_median_and_coverage_stay_sane() {
    let (good, good_anees) = synthetic(false);
    let (bad, bad_anees) = synthetic(true);
    let cg = consistency(2, 1000, 11, &good, &good_anees);
    let cb = consistency(2, 1000, 11, &bad, &bad_anees);
    assert!(!cg.mean_dominated, "{cg:?}");
    assert!(cb.mean_dominated, "{cb:?}");
    assert!(cb.top_trials_share > 0.99);
    // The mean is ruined...
    let mean_bad = bad_anees.iter().sum::<f64>() / bad_anees.len() as f64;
    assert!(mean_bad > 1e8, "{mean_bad}");
    // ...the median and the coverage are not: chi2_2 median / 2 = ln 2.
    let expected = std::f64::consts::LN_2;
    assert!((cg.median_nees_expected - expected).abs() < 1e-9);
    for c in [&cg, &cb] {
        assert!((c.median_nees / expected - 1.0).abs() < 0.02, "{c:?}");
    }
    let cov = |s: &Sums| {
        (0..50)
            .map(|k| s.at(k, Layout::NEES_COVERED_95))
            .sum::<f64>()
            / 50e3
    };
    assert!((cov(&good) - 0.95).abs() < 0.005, "{}", cov(&good));
    assert!((cov(&bad) - cov(&good)).abs() < 0.002);
    // The collapsed trial is the one that diverged.
    assert_eq!(good.diverged, 0);
    assert_eq!(bad.diverged, 1);
    // A consistent filter's per-step ANEES lies in the chi-square interval most of the time.
    assert!(cg.anees_steps_in_interval > 0.8, "{cg:?}");
    assert_eq!(cb.anees_steps_in_interval, 0.0);
}

#[test]
fn an_overflowed_sum_of_squares_gives_no_standard_error() {
    let mut t = crate::metrics::TrialStat::default();
    for v in [1e300, 2e300, 3e300] {
        t.sum += v;
        t.sum_sq += v * v;
    }
    let (mean, se) = t.mean_se(3);
    assert!((mean / 2e300 - 1.0).abs() < 1e-12);
    assert!(se.is_nan());
}
