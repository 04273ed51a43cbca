//! One trial in detail, and per-step errors with their standard errors, for `report.html`.
//! The same loop as [`super::runner`] (the same truths, measurements and coins: a variant's
//! coins come from stream 1 + its index, or stream 1 for every variant when each scheme ran
//! alone, as calibrated arenas do); [`super::runner::run`] itself is untouched.
use super::build::Experiment;
use super::runner::{draw_trial, trial_rng};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::link::{Received, Transmission};
use crate::network;

/// What one sensor did at one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    Sent,
    Silent,
    NotScheduled,
}

/// One variant over one trial.
#[derive(Debug, Clone)]
pub struct VariantTrace {
    /// Fused estimate after step k (k = 1..T).
    pub estimates: Vec<Gaussian>,
    /// `links[k][i]`: sensor i at step k + 1.
    pub links: Vec<Vec<Link>>,
}

/// Truth and every variant of one trial.
#[derive(Debug, Clone)]
pub struct Trace {
    pub truth: Vec<Vector>,
    pub variants: Vec<VariantTrace>,
}

/// Called after every step with (k, truth, fused estimate, what each sensor did).
type StepFn<'a> = &'a mut dyn FnMut(usize, &Vector, &Gaussian, &[Link]);

/// Per variant: per-step RMSE and its standard error.
pub type RmseSe = Vec<(Vec<f64>, Vec<f64>)>;

/// Runs variant `v` over `trial`, calling `f(k, truth, estimate, links)` after every step.
fn run_variant(
    exp: &Experiment,
    data: &super::runner::TrialData,
    v: usize,
    trial: usize,
    alone: bool,
    f: StepFn,
) -> Result<(), String> {
    let n = exp.system.n_sensors();
    let stream = 1 + if alone { 0 } else { v as u64 };
    let mut rng = trial_rng(exp.seed, trial as u64, stream);
    let center_seed = super::runner::center_seed(exp.seed, trial as u64, stream);
    let variant = &exp.variants[v];
    let mut inst = variant
        .scheme
        .build_with_seed(center_seed)
        .map_err(|e| e.to_string())?;
    let schedule = variant.scheme.schedule();
    let mut feedback = inst.center.feedback();
    let mut inbox = Vec::with_capacity(n);
    let mut tx = Vec::with_capacity(n);
    let mut links = Vec::with_capacity(n);
    for k in 1..=exp.steps {
        tx.clear();
        links.clear();
        for (i, node) in inst.sensors.iter_mut().enumerate() {
            let t = if schedule.allows(k, i, n) {
                let t = node
                    .step(k, &data.measurements[k - 1][i], feedback.as_ref(), &mut rng)
                    .map_err(|e| e.to_string())?;
                links.push(if matches!(t, Transmission::Send(_)) {
                    Link::Sent
                } else {
                    Link::Silent
                });
                t
            } else {
                links.push(Link::NotScheduled);
                Transmission::Silent
            };
            tx.push(t);
        }
        network::deliver(tx.drain(..), &mut inbox);
        if schedule != network::Schedule::All {
            for (i, r) in inbox.iter_mut().enumerate() {
                if !schedule.allows(k, i, n) {
                    *r = Received::NotScheduled;
                }
            }
        }
        inst.center.step(k, &inbox).map_err(|e| e.to_string())?;
        feedback = inst.center.feedback();
        f(k, &data.truth[k - 1], inst.center.estimate(), &links);
    }
    Ok(())
}

/// Trial `trial` of every variant: estimates and who sent.
pub fn trace(exp: &Experiment, trial: usize, alone: bool) -> Result<Trace, String> {
    let data = draw_trial(exp, trial);
    let mut variants = Vec::new();
    for v in 0..exp.variants.len() {
        let mut vt = VariantTrace {
            estimates: Vec::with_capacity(exp.steps),
            links: Vec::with_capacity(exp.steps),
        };
        run_variant(exp, &data, v, trial, alone, &mut |_, _, est, links| {
            vt.estimates.push(est.clone());
            vt.links.push(links.to_vec());
        })?;
        variants.push(vt);
    }
    Ok(Trace {
        truth: data.truth,
        variants,
    })
}

/// Per variant, per step: RMSE of a group of state indices and its standard error (delta
/// method from the per-trial squared errors: se(RMSE) = se(MSE) / (2 RMSE)), over `trials`.
pub fn rmse_with_se(
    exp: &Experiment,
    indices: &[usize],
    trials: usize,
    alone: bool,
) -> Result<RmseSe, String> {
    let t = exp.steps;
    let mut s1 = vec![vec![0.0; t]; exp.variants.len()];
    let mut s2 = vec![vec![0.0; t]; exp.variants.len()];
    for trial in 0..trials {
        let data = draw_trial(exp, trial);
        for v in 0..exp.variants.len() {
            let (a, b) = (&mut s1[v], &mut s2[v]);
            run_variant(exp, &data, v, trial, alone, &mut |k, x, est, _| {
                let e: f64 = indices.iter().map(|&i| (x[i] - est.mean[i]).powi(2)).sum();
                a[k - 1] += e;
                b[k - 1] += e * e;
            })?;
        }
    }
    let n = trials as f64;
    Ok(s1
        .iter()
        .zip(&s2)
        .map(|(a, b)| {
            let mut r = Vec::with_capacity(t);
            let mut se = Vec::with_capacity(t);
            for k in 0..t {
                let m = a[k] / n;
                let var = if trials > 1 {
                    ((b[k] / n - m * m) * n / (n - 1.0)).max(0.0)
                } else {
                    0.0
                };
                let rm = m.sqrt();
                r.push(rm);
                se.push(if rm > 0.0 {
                    (var / n).sqrt() / (2.0 * rm)
                } else {
                    0.0
                });
            }
            (r, se)
        })
        .collect())
}
