//! Tests of Geng et al.'s schemes; each can fail.
use super::bounds::{psd_margin, theorem4, theorem5, BoundStep, UpperVarphi};
use super::center::{federated_fusion, reset};
use super::*;
use crate::engine::runner;
use crate::filter::tobit;
use crate::filter::{kf, Gaussian};
use crate::link::Received;
use crate::metrics::results;
use crate::model::presets;
use crate::scenario::build;
use crate::scenario::builtin;
use crate::scheme::FusionCenter;

fn oscillator_system(with_bias: bool) -> Arc<System> {
    let exp = build::load(builtin::get("geng-oscillator").unwrap(), "geng-oscillator").unwrap();
    if with_bias {
        return exp.system.clone();
    }
    // Two states, no bias: the rotation alone, sensors on x1 and x2.
    let transition =
        presets::rotation_oscillator(0.052 * std::f64::consts::PI, 1.0, 0.0025).unwrap();
    let s = |row: Vec<f64>| {
        Arc::new(
            LinearSensor::new(
                crate::linalg::matrix_from_rows(&[row]),
                Matrix::from_element(1, 1, 0.6),
            )
            .unwrap(),
        ) as Arc<dyn MeasurementModel>
    };
    Arc::new(System {
        transition,
        sensors: vec![s(vec![1.0, 0.0]), s(vec![0.0, 1.0])],
        prior: Gaussian::new(
            Vector::from_vec(vec![5.0, 0.0]),
            Matrix::identity(2, 2) * 0.1,
        ),
    })
}

fn model(system: &Arc<System>, tau: Option<f64>, fusion: Fusion) -> Arc<FtkfModel> {
    model_r(system, tau, fusion, None)
}

fn model_r(
    system: &Arc<System>,
    tau: Option<f64>,
    fusion: Fusion,
    noise_var: Option<f64>,
) -> Arc<FtkfModel> {
    let thr = match tau {
        Some(t) => Thresholds::new(-t, t).unwrap(),
        None => Thresholds::none(),
    };
    FederatedTobitScheme::new(
        system.clone(),
        vec![thr; system.n_sensors()],
        noise_var.map(|r| vec![r; system.n_sensors()]),
        None,
        fusion,
        None,
        TobitOptions::default(),
    )
    .unwrap()
    .model()
    .clone()
}

/// Round-robin inbox of step k from the true readings.
fn inbox(k: usize, z: &[Vector]) -> Vec<Received> {
    let p = z.len();
    (0..p)
        .map(|i| {
            if crate::network::Schedule::RoundRobin.allows(k, i, p) {
                Received::Measurement(z[i].clone())
            } else {
                Received::NotScheduled
            }
        })
        .collect()
}

fn readings(system: &System, steps: usize, seed: u64) -> Vec<Vec<Vector>> {
    use rand::SeedableRng;
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
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

/// Thresholds at +-infinity and no bias: the local Tobit KF is the Kalman filter (on the
/// readings of its sensor's scheduled steps), and so is the federated FTKF (on all).
#[test]
fn without_censoring_and_bias_the_local_tobit_kf_is_the_kf() {
    let sys = oscillator_system(false);
    let z = readings(&sys, 60, 7);
    for m in 0..2 {
        let mut c = FtkfCenter::new(model(&sys, None, Fusion::Local(m)), false);
        let mut e = sys.prior.clone();
        for k in 1..=60 {
            let inb = inbox(k, &z[k - 1]);
            c.step(k, &inb).unwrap();
            e = kf::predict(&sys.transition, &e);
            if let Received::Measurement(zz) = &inb[m] {
                e = kf::update(sys.sensors[m].as_ref(), e, zz).unwrap();
            }
            assert!((&c.estimate().mean - &e.mean).amax() < 1e-12, "k {k}");
            assert!((&c.estimate().cov - &e.cov).amax() < 1e-12, "k {k}");
        }
    }
    let mut c = FtkfCenter::new(model(&sys, None, Fusion::Federated), false);
    let mut central = crate::scheme::centralized::CentralizedKf::new(sys.clone());
    for k in 1..=60 {
        let inb = inbox(k, &z[k - 1]);
        c.step(k, &inb).unwrap();
        central.step(k, &inb).unwrap();
        assert!((&c.estimate().mean - &central.estimate().mean).amax() < 1e-10);
        assert!((&c.estimate().cov - &central.estimate().cov).amax() < 1e-10);
    }
}

/// Federated fusion (26) of p locals reset (27) from one estimate with epsilon = 1/p returns
/// that estimate; with a wrong coefficient it does not.
#[test]
fn federated_fusion_of_identical_locals_returns_the_estimate() {
    let g = Gaussian::new(
        Vector::from_vec(vec![1.0, -2.0, 0.5]),
        crate::linalg::matrix_from_rows(&[
            vec![0.4, 0.1, 0.0],
            vec![0.1, 0.3, 0.02],
            vec![0.0, 0.02, 0.2],
        ]),
    );
    for p in [1usize, 2, 3, 5] {
        let locals: Vec<Gaussian> = (0..p).map(|_| reset(&g, 1.0 / p as f64)).collect();
        let f = federated_fusion(&locals).unwrap();
        assert!((&f.mean - &g.mean).amax() < 1e-13);
        assert!((&f.cov - &g.cov).amax() < 1e-13);
    }
    let f = federated_fusion(&[reset(&g, 0.5), reset(&g, 0.25)]).unwrap();
    assert!((&f.cov - &g.cov).amax() > 1e-2);
}

/// With the reset (27) the federated FTKF-DB is one Tobit KF updating with the scheduled
/// sensor, whatever the sharing coefficients.
#[test]
fn federated_equals_the_centralized_tobit_kf() {
    let sys = oscillator_system(true);
    let z = readings(&sys, 100, 11);
    let thr = Thresholds::new(-1.0, 1.0).unwrap();
    for sharing in [vec![0.5, 0.5], vec![0.2, 0.8]] {
        let m = FederatedTobitScheme::new(
            sys.clone(),
            vec![thr; 2],
            None,
            Some(sharing),
            Fusion::Federated,
            None,
            TobitOptions::default(),
        )
        .unwrap();
        let mut c = FtkfCenter::new(m.model().clone(), false);
        let mut e = sys.prior.clone();
        let mut censored = 0;
        for k in 1..=100 {
            let inb = inbox(k, &z[k - 1]);
            c.step(k, &inb).unwrap();
            e = kf::predict(&sys.transition, &e);
            for (i, r) in inb.iter().enumerate() {
                if let Received::Measurement(zz) = r {
                    let y = thr.censor(zz[0]);
                    censored += usize::from(y != zz[0]);
                    let h = sys.sensors[i].as_linear().unwrap().h().clone();
                    e = tobit::update(e, &h, 0.06, y, 0.0, &thr, &Default::default())
                        .unwrap()
                        .0;
                }
            }
            let tol = 1e-8 * (1.0 + e.mean.amax());
            assert!((&c.estimate().mean - &e.mean).amax() < tol, "k {k}");
            assert!((&c.estimate().cov - &e.cov).amax() < 1e-8 * (1.0 + e.cov.amax()));
        }
        assert!(
            censored > 20,
            "the test must exercise censoring ({censored})"
        );
    }
}

/// The bias-blind FTKF reports the bias's open-loop prior and a filter on x alone.
#[test]
fn bias_blind_ftkf_keeps_the_bias_prior() {
    let sys = oscillator_system(true);
    let z = readings(&sys, 10, 3);
    let m = FederatedTobitScheme::new(
        sys.clone(),
        vec![Thresholds::none(); 2],
        None,
        None,
        Fusion::Federated,
        Some(vec![2]),
        TobitOptions::default(),
    )
    .unwrap();
    let mut c = FtkfCenter::new(m.model().clone(), false);
    for k in 1..=10 {
        c.step(k, &inbox(k, &z[k - 1])).unwrap();
        let e = c.estimate();
        assert_eq!(e.mean[2], 0.0);
        assert!((e.cov[(2, 2)] - (0.1 + 0.25 * k as f64)).abs() < 1e-12);
        assert_eq!((e.cov[(0, 2)], e.cov[(1, 2)]), (0.0, 0.0));
    }
}

fn bound_steps(
    model: &FtkfModel,
    m: usize,
    records: &[Vec<super::LocalRecord>],
    fused: bool,
) -> Vec<BoundStep> {
    records
        .iter()
        .map(|step| {
            // The fused filter updates with whichever sensor was scheduled.
            let (i, rec) = if fused {
                step.iter()
                    .enumerate()
                    .find(|(_, r)| r.scheduled)
                    .unwrap_or((m, &step[m]))
            } else {
                (m, &step[0])
            };
            BoundStep {
                h: rec.scheduled.then(|| model.sensors[i].0.clone()),
                r: model.sensors[i].1,
                alpha: rec.alpha,
                beta: rec.beta,
                theta_l: rec.theta_l,
            }
        })
        .collect()
}

/// Smallest margins `(P^- - P^l, P^u - P^-)` over the run, relative (>= -1e-9: holds).
fn theorem4_margins(
    sys: &Arc<System>,
    tau: f64,
    fusion: Fusion,
    seed: u64,
    varphi: UpperVarphi,
) -> (f64, f64) {
    // The paper's R = 0.6 (the scenario's sensors are measured at 0.06 plus added noise).
    let model = model_r(sys, Some(tau), fusion, Some(0.6));
    let z: Vec<Vec<Vector>> = readings(sys, 100, seed)
        .into_iter()
        .map(|zk| {
            zk.into_iter()
                .map(|z| z.map(|v| v + 0.54f64.sqrt() * hashed_normal(v)))
                .collect()
        })
        .collect();
    let mut c = FtkfCenter::new(model.clone(), true);
    for k in 1..=100 {
        c.step(k, &inbox(k, &z[k - 1])).unwrap();
    }
    let recs = c.records.clone().unwrap();
    let m = match fusion {
        Fusion::Local(m) => m,
        _ => 0,
    };
    let steps = bound_steps(&model, m, &recs, !matches!(fusion, Fusion::Local(_)));
    let preds = &c.fused_pred;
    let b = theorem4(
        &model.transition,
        &preds[0],
        &steps[..steps.len() - 1],
        varphi,
    );
    let mut worst = (f64::INFINITY, f64::INFINITY);
    for (k, p) in preds.iter().enumerate() {
        worst.0 = worst.0.min(psd_margin(p, &b[k].lower));
        worst.1 = worst.1.min(psd_margin(&b[k].upper, p));
    }
    worst
}

/// Theorem 4 along runs of the built-in oscillator at the paper's R = 0.6 (property test over
/// 10 seeds x 3 filters x 3 regions x 2 readings), for each local filter alone and for the
/// fused filter (the reset loop is one Tobit KF; the bounds are applied to it with the
/// scheduled sensor's probabilities), in the PSD order. Without censoring both bounds must
/// hold on every step; under censoring the test counts the runs where the printed theorem
/// fails (see docs/reproductions.md) and asserts the failure found.
#[test]
fn theorem4_bounds_along_built_in_runs() {
    let sys = oscillator_system(true);
    let tol = -1e-9;
    let mut fails = std::collections::BTreeMap::new();
    for seed in 0..10u64 {
        for fusion in [Fusion::Local(0), Fusion::Local(1), Fusion::Federated] {
            // Thresholds far outside the signal: alpha = beta = 0, the bounds are the KF's.
            let (lo, up) = theorem4_margins(&sys, 1e6, fusion, seed, UpperVarphi::Lemma1);
            assert!(
                lo >= tol && up >= tol,
                "no censoring, {fusion:?}, seed {seed}: {lo} {up}"
            );
            for tau in [5.0, 1.0, 0.5] {
                for varphi in [UpperVarphi::Lemma1, UpperVarphi::Printed] {
                    let (lo, up) = theorem4_margins(&sys, tau, fusion, seed, varphi);
                    let e = fails
                        .entry(format!("tau={tau} {varphi:?}"))
                        .or_insert((0usize, 0usize, 0usize));
                    e.0 += 1;
                    e.1 += usize::from(lo < tol);
                    e.2 += usize::from(up < tol);
                }
            }
        }
    }
    eprintln!("runs, lower-bound violations, upper-bound violations: {fails:?}");
    // Finding: under censoring the printed Theorem 4 fails (both bounds, both readings of
    // varphi) in most runs — at R = 0.6 and tau = 1 or 0.5 in every run. The Tobit update's
    // effective noise R (1 + varphi) / (1 - alpha - beta)^2 can fall below what the bounds
    // assume. Asserted so that a fix (or a regression) is noticed.
    for (key, v) in &fails {
        assert!(
            v.1 > 0 && v.2 > 0,
            "{key}: the printed bounds held in every run: {v:?}"
        );
    }
    assert_eq!(fails["tau=1 Lemma1"], (30, 30, 30));
}

/// Theorem 5 as printed, from the standalone local bounds, against the fused prediction
/// covariance of the federated run (reported, and the no-censoring case asserted).
#[test]
fn theorem5_without_censoring_bounds_the_fused_prediction() {
    let sys = oscillator_system(true);
    let z = readings(&sys, 60, 5);
    let mut locals = Vec::new();
    for m in 0..2 {
        let model = model(&sys, Some(1e6), Fusion::Local(m));
        let mut c = FtkfCenter::new(model.clone(), true);
        for k in 1..=60 {
            c.step(k, &inbox(k, &z[k - 1])).unwrap();
        }
        let steps = bound_steps(&model, m, c.records.as_ref().unwrap(), false);
        locals.push(theorem4(
            &model.transition,
            &c.fused_pred[0],
            &steps[..59],
            UpperVarphi::Lemma1,
        ));
    }
    let fmodel = model(&sys, Some(1e6), Fusion::Federated);
    let mut c = FtkfCenter::new(fmodel, true);
    for k in 1..=60 {
        c.step(k, &inbox(k, &z[k - 1])).unwrap();
    }
    for (k, p) in c.fused_pred.iter().enumerate().skip(1) {
        let b = theorem5(&[&locals[0][k], &locals[1][k]]).unwrap();
        // The fused filter uses both sensors, each local only one: the printed fused lower
        // bound [sum (P^l_m)^{-1}]^{-1} is below the fused covariance.
        assert!(psd_margin(p, &b.lower) >= -1e-9, "k {k}");
    }
}

/// No scheme's average error falls below the information bound (the KF with the uncensored
/// readings on the same schedule) by more than Monte Carlo error: paired differences over the
/// same trials, at each noise variance, 300 trials of the built-in scenario.
#[test]
fn no_scheme_beats_the_information_bound() {
    let mut exp = build::load(builtin::get("geng-oscillator").unwrap(), "geng-oscillator").unwrap();
    exp.trials = 300;
    let sums = runner::run(&exp, runner::RunOptions { threads: 0 }, &|_| {}).unwrap();
    let summary = results::summarize(&exp, &sums);
    let nv = |s: &results::SchemeSummary| {
        s.params
            .get("noise_var")
            .map(|v| format!("{v:?}"))
            .unwrap_or_default()
    };
    let bounds: Vec<_> = summary
        .schemes
        .iter()
        .filter(|s| s.kind == "round-robin-kf")
        .collect();
    assert_eq!(bounds.len(), 3);
    let mut checked = 0;
    for s in summary
        .schemes
        .iter()
        .filter(|s| s.kind != "round-robin-kf")
    {
        let b = bounds
            .iter()
            .find(|b| nv(b) == nv(s))
            .expect("a bound at every R");
        for col in 0..s.per_trial[0].len() {
            let d: Vec<f64> = s
                .per_trial
                .iter()
                .zip(&b.per_trial)
                .map(|(x, y)| x[col] - y[col])
                .collect();
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let se = (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
            assert!(
                mean > -3.0 * se,
                "{} {:?} column {col}: {mean} below the bound by more than 3 se ({se})",
                s.name,
                s.params
            );
            checked += 1;
        }
    }
    assert!(checked >= 4 * 15);
}

/// Without censoring (geng-tracking's thresholds lie far outside the signal) FTKF-DB is the
/// information bound: the same estimates on the same readings.
#[test]
fn uncensored_ftkf_db_equals_the_bound_on_the_tracking_example() {
    let mut exp = build::load(builtin::get("geng-tracking").unwrap(), "geng-tracking").unwrap();
    exp.trials = 20;
    let sums = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    let summary = results::summarize(&exp, &sums);
    let get = |label: &str| summary.schemes.iter().find(|s| s.name == label).unwrap();
    let (a, b) = (get("FTKF-DB"), get("Information bound"));
    for (x, y) in a.per_trial.iter().zip(&b.per_trial) {
        assert!((x[0] - y[0]).abs() < 1e-8 * y[0].max(1.0));
    }
    assert_eq!(a.bits_per_step, 32.0);
}

/// The noise override is common to all variants and has the requested variance.
#[test]
fn hashed_noise_is_standard_normal() {
    let n = 200_000;
    let (mut s1, mut s2) = (0.0, 0.0);
    for i in 0..n {
        let v = hashed_normal(i as f64 * 0.001 - 3.0);
        s1 += v;
        s2 += v * v;
    }
    let (m, var) = (s1 / n as f64, s2 / n as f64 - (s1 / n as f64).powi(2));
    assert!(m.abs() < 0.01 && (var - 1.0).abs() < 0.01, "{m} {var}");
    assert_eq!(hashed_normal(1.25), hashed_normal(1.25));
}
