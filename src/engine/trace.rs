//! One trial in detail, and per-step errors with their standard errors, for `report.html`; and
//! the loop that replays recorded measurements ([`crate::engine::replay`]).
//! The same loop as [`crate::engine::runner`] (the same truths, measurements and coins: a variant's
//! coins come from stream 1 + its index, or stream 1 for every variant when each scheme ran
//! alone, as calibrated arenas do); [`crate::engine::runner::run`] itself is untouched.
use crate::engine::runner::{draw_trial, trial_rng};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::link::{Received, Transmission};
use crate::metrics::Sums;
use crate::network::{self, Traffic};
use crate::scenario::build::Experiment;

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

/// Everything one step of one variant produced.
#[derive(Debug)]
pub struct StepOutput<'a> {
    /// Step (1-based).
    pub k: usize,
    /// Fused estimate after the step.
    pub estimate: &'a Gaussian,
    /// What each sensor did.
    pub links: &'a [Link],
    /// Payload bits each sensor sent (0 when it did not send).
    pub bits: &'a [u64],
    /// The step's traffic, counted as the runner counts it (uplink by the network, downlink
    /// from the feedback the sensors were given before the step).
    pub traffic: Traffic,
    /// The fusion center's effective sample size (particle filters).
    pub ess: Option<f64>,
}

/// Where a variant's coins come from and which readings exist.
#[derive(Debug, Clone, Copy)]
pub struct LoopOptions<'a> {
    /// Trial index of the coin streams (stream 1 + v of this trial, as in the runner).
    pub trial: usize,
    /// Every variant on stream 1 (schemes run alone, as calibrated arenas do).
    pub alone: bool,
    /// `available[k - 1][i]`: whether sensor i has a reading at step k. A sensor without one
    /// is not asked (its node does not step) and reaches the fusion center as
    /// [`Received::NotScheduled`]. `None`: every reading exists.
    pub available: Option<&'a [Vec<bool>]>,
}

/// Runs variant `v` over `measurements` (`measurements[k - 1][i]`, read only where
/// available), calling `f` after every step; a scheme error or an error of `f` stops the loop.
/// With every reading available this is the runner's loop step for step: the same coins, the
/// same inbox, the same traffic.
pub fn run_variant_with(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    v: usize,
    opts: LoopOptions,
    f: &mut dyn FnMut(&StepOutput) -> Result<(), String>,
) -> Result<(), String> {
    let n = exp.system.n_sensors();
    let stream = 1 + if opts.alone { 0 } else { v as u64 };
    let trial = opts.trial as u64;
    let mut rng = trial_rng(exp.seed, trial, stream);
    let center_seed = crate::engine::runner::center_seed(exp.seed, trial, stream);
    let variant = &exp.variants[v];
    let label = &exp.curves[variant.curve].label;
    let err = |k: usize, e: &dyn std::fmt::Display| format!("scheme {label}, step {k}: {e}");
    let mut inst = variant
        .scheme
        .build_with_seed(center_seed)
        .map_err(|e| err(0, &e))?;
    let schedule = variant.scheme.schedule();
    let mut feedback = inst.center.feedback();
    let mut inbox = Vec::with_capacity(n);
    let mut tx = Vec::with_capacity(n);
    let mut links = Vec::with_capacity(n);
    let mut bits = Vec::with_capacity(n);
    for k in 1..=exp.steps {
        tx.clear();
        links.clear();
        bits.clear();
        let has = |i: usize| opts.available.is_none_or(|a| a[k - 1][i]);
        for (i, node) in inst.sensors.iter_mut().enumerate() {
            let t = if schedule.allows(k, i, n) && has(i) {
                let t = node
                    .step(k, &measurements[k - 1][i], feedback.as_ref(), &mut rng)
                    .map_err(|e| err(k, &e))?;
                match &t {
                    Transmission::Send(m) => {
                        links.push(Link::Sent);
                        bits.push(m.bits());
                    }
                    Transmission::Silent => {
                        links.push(Link::Silent);
                        bits.push(0);
                    }
                }
                t
            } else {
                links.push(Link::NotScheduled);
                bits.push(0);
                Transmission::Silent
            };
            tx.push(t);
        }
        let mut traffic = network::deliver(tx.drain(..), &mut inbox);
        traffic.downlink_bits = feedback.as_ref().map_or(0, |f| f.bits(n));
        if schedule != network::Schedule::All || opts.available.is_some() {
            for (i, r) in inbox.iter_mut().enumerate() {
                if !schedule.allows(k, i, n) || !has(i) {
                    *r = Received::NotScheduled;
                }
            }
        }
        inst.center.step(k, &inbox).map_err(|e| err(k, &e))?;
        feedback = inst.center.feedback();
        f(&StepOutput {
            k,
            estimate: inst.center.estimate(),
            links: &links,
            bits: &bits,
            traffic,
            ess: inst.center.ess(),
        })?;
    }
    Ok(())
}

/// Runs variant `v` over `measurements` and adds the trial into `sums` exactly as the runner
/// does (the same observer calls in the same order), calling `f` after every step too.
pub fn run_variant_into(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    truth: &[Vector],
    v: usize,
    opts: LoopOptions,
    sums: &mut Sums,
    f: &mut dyn FnMut(&StepOutput) -> Result<(), String>,
) -> Result<(), String> {
    let label = exp.curves[exp.variants[v].curve].label.clone();
    let mut obs = sums.trial(&exp.groups, exp.steady_from);
    run_variant_with(exp, measurements, v, opts, &mut |s| {
        obs.record(s.k, &truth[s.k - 1], s.estimate, s.traffic)
            .map_err(|e| {
                format!(
                    "scheme {label}, step {}: fused covariance is not positive definite ({e})",
                    s.k
                )
            })?;
        obs.record_ess(s.k, s.ess);
        f(s)
    })?;
    obs.finish();
    Ok(())
}

/// Runs variant `v` over `trial`, calling `f(k, truth, estimate, links)` after every step.
fn run_variant(
    exp: &Experiment,
    data: &crate::engine::runner::TrialData,
    v: usize,
    trial: usize,
    alone: bool,
    f: StepFn,
) -> Result<(), String> {
    let opts = LoopOptions {
        trial,
        alone,
        available: None,
    };
    run_variant_with(exp, &data.measurements, v, opts, &mut |s| {
        f(s.k, &data.truth[s.k - 1], s.estimate, s.links);
        Ok(())
    })
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
