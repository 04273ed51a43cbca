//! One trial in detail, and per-step errors with their standard errors, for `report.html`; and
//! the loops that replay recorded measurements ([`crate::engine::replay`]). Both run the
//! engine's loop ([`crate::engine::trial`]): the same truths, measurements and coins as the
//! runner; a variant's coins come from its own stream, or from variant 0's for every variant
//! when each scheme ran alone, as calibrated arenas do.
use crate::engine::peers;
use crate::engine::runner::draw_trial;
use crate::engine::trial::{self, LoopBuffers, Observer, ObserverError, TrialSpec};
pub use crate::engine::trial::{Link, StepOutput};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::metrics::Sums;
use crate::scenario::build::Experiment;
use crate::stats::seeding::coin_stream;
/// One variant's trial: its fused estimates and what each sensor did.
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

/// Per variant: per-step RMSE and its standard error.
pub type RmseSe = Vec<(Vec<f64>, Vec<f64>)>;

/// Where a variant's coins come from and which readings exist.
#[derive(Debug, Clone, Copy)]
pub struct LoopOptions<'a> {
    /// Trial index of the coin streams (each variant's own stream of this trial, as in the
    /// runner).
    pub trial: usize,
    /// Every variant on variant 0's stream (schemes run alone, as calibrated arenas do).
    pub alone: bool,
    /// `available[k - 1][i]`: whether sensor i has a reading at step k. A sensor without one
    /// is not asked (its node does not step) and reaches the fusion center as
    /// [`crate::link::Received::NotScheduled`]. `None`: every reading exists.
    pub available: Option<&'a [Vec<bool>]>,
}

impl LoopOptions<'_> {
    /// The engine's description of variant `v`'s trial.
    fn spec(&self, v: usize) -> TrialSpec<'_> {
        TrialSpec {
            trial: self.trial,
            variant: v,
            stream: coin_stream(if self.alone { 0 } else { v }),
            available: self.available,
        }
    }
}

/// A closure as an engine observer: its error stops the loop with its words.
struct Calls<'f>(&'f mut dyn FnMut(&StepOutput) -> Result<(), String>);

impl Observer for Calls<'_> {
    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError> {
        (self.0)(s).map_err(ObserverError::Message)
    }
}

/// Runs variant `v` over `measurements` (`measurements[k - 1][i]`, read only where
/// available), calling `f` after every step; a scheme error or an error of `f` stops the loop.
/// With every reading available this is the runner's loop: the same coins, the same inbox,
/// the same traffic.
pub fn run_variant_with(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    v: usize,
    opts: LoopOptions,
    f: &mut dyn FnMut(&StepOutput) -> Result<(), String>,
) -> Result<(), String> {
    let label = &exp.curves[exp.variants[v].curve].label;
    if let Some(peers) = exp.variants[v].scheme.peers() {
        let sensors = exp.system.n_sensors();
        let at = (opts.trial, opts.available);
        return peers::run_steps(exp, v, peers, measurements, at, &mut |k, est, counts, _| {
            let (links, bits) = (
                peers::links(counts, sensors),
                peers::sensor_bits(counts, sensors),
            );
            f(&peer_step(k, est, counts, (&links, &bits)))
        })
        .map_err(|e| format!("scheme {label}: {e}"));
    }
    let mut buffers = LoopBuffers::new(exp.system.n_sensors());
    trial::run_trial(exp, measurements, opts.spec(v), &mut buffers, &mut Calls(f))
        .map_err(|e| e.describe(label))
}

/// A decentralized scheme's step as the engine's loop reports one: its first node's estimate,
/// each sensor node sent or silent with its payload bits, the network's traffic and counters.
fn peer_step<'a>(
    k: usize,
    estimates: &[&'a Gaussian],
    counts: &'a [crate::network::topology::tally::NodeCounts],
    (links, bits): (&'a [Link], &'a [u64]),
) -> StepOutput<'a> {
    StepOutput {
        k,
        estimate: estimates[0],
        links,
        bits,
        traffic: peers::traffic(counts),
        ess: None,
        nodes: counts,
    }
}

/// A trial's metrics beside a closure: every step into the sums, then to the closure.
struct SumsAndCalls<'a, 'b, 'f> {
    obs: crate::metrics::TrialObserver<'a>,
    truth: &'b [Vector],
    f: &'f mut dyn FnMut(&StepOutput) -> Result<(), String>,
}

impl Observer for SumsAndCalls<'_, '_, '_> {
    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError> {
        self.obs
            .record(s.k, &self.truth[s.k - 1], s.estimate, s.traffic)
            .map_err(ObserverError::Covariance)?;
        self.obs.record_ess(s.k, s.ess);
        self.obs.record_nodes(s.k, s.nodes);
        (self.f)(s).map_err(ObserverError::Message)
    }
}

/// [`run_variant_with`] adding the trial's metrics against `truth` into `sums`, as the runner
/// does.
pub fn run_variant_into(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    truth: &[Vector],
    v: usize,
    opts: LoopOptions,
    sums: &mut Sums,
    f: &mut dyn FnMut(&StepOutput) -> Result<(), String>,
) -> Result<(), String> {
    let label = &exp.curves[exp.variants[v].curve].label;
    if let Some(peers) = exp.variants[v].scheme.peers() {
        let sensors = exp.system.n_sensors();
        let mut obs = sums.trial(&exp.groups, exp.steady_from);
        let at = (opts.trial, opts.available);
        peers::run_steps(
            exp,
            v,
            peers,
            measurements,
            at,
            &mut |k, est, counts, factors| {
                peers::record(&mut obs, k, &truth[k - 1], (est, factors), counts)?;
                let (links, bits) = (
                    peers::links(counts, sensors),
                    peers::sensor_bits(counts, sensors),
                );
                f(&peer_step(k, est, counts, (&links, &bits)))
            },
        )
        .map_err(|e| format!("scheme {label}: {e}"))?;
        obs.finish();
        return Ok(());
    }
    let mut buffers = LoopBuffers::new(exp.system.n_sensors());
    let mut observer = SumsAndCalls {
        obs: sums.trial(&exp.groups, exp.steady_from),
        truth,
        f,
    };
    trial::run_trial(exp, measurements, opts.spec(v), &mut buffers, &mut observer)
        .map_err(|e| e.describe(label))?;
    observer.obs.finish();
    Ok(())
}

/// Called after every step with (k, truth, the estimates, what each sensor did): one estimate
/// for a center scheme, one per node for a decentralized scheme.
type EstimatesFn<'a> = &'a mut dyn FnMut(usize, &Vector, &[&Gaussian], &[Link]);

/// Variant `v` of `trial` on drawn data, calling `f` after every step. A decentralized
/// scheme's nodes run on its graph ([`crate::engine::peers`]); a sensor node that sent no frame
/// in a step shows as silent.
fn run_variant(
    exp: &Experiment,
    data: &crate::engine::runner::TrialData,
    v: usize,
    trial: usize,
    alone: bool,
    f: EstimatesFn,
) -> Result<(), String> {
    if let Some(peers) = exp.variants[v].scheme.peers() {
        let sensors = exp.system.n_sensors();
        let at = (trial, None);
        return peers::run_steps(
            exp,
            v,
            peers,
            &data.measurements,
            at,
            &mut |k, est, counts, _| {
                f(k, &data.truth[k - 1], est, &peers::links(counts, sensors));
                Ok(())
            },
        );
    }
    let opts = LoopOptions {
        trial,
        alone,
        available: None,
    };
    run_variant_with(exp, &data.measurements, v, opts, &mut |s| {
        f(s.k, &data.truth[s.k - 1], &[s.estimate], s.links);
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
        // A decentralized scheme's trial in detail is its first node's.
        run_variant(exp, &data, v, trial, alone, &mut |_, _, est, links| {
            vt.estimates.push(est[0].clone());
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
            // A decentralized scheme's error is the mean over its nodes, as its row's.
            run_variant(exp, &data, v, trial, alone, &mut |k, x, ests, _| {
                let e: f64 = ests
                    .iter()
                    .map(|est| {
                        indices
                            .iter()
                            .map(|&i| (x[i] - est.mean[i]).powi(2))
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    / ests.len() as f64;
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
