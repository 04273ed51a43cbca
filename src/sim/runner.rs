//! The Monte Carlo runner: the only time loop of the library. Per trial, truth and every
//! sensor's measurements are drawn once from a stream seeded by (seed, trial); every scheme then
//! processes the same data with coin flips from a stream of its own (common random numbers).
//! Trials run in parallel in fixed blocks whose sums are merged in block order, so results are
//! bit-identical for any number of threads.
use super::build::Experiment;
use super::metrics::Sums;
use crate::linalg::Vector;
use crate::network;
use crate::scheme::SchemeError;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Trials per block. Fixed (not derived from the thread count) so that the summation order,
/// and hence every bit of the result, is the same for 1 or many threads.
const BLOCK: usize = 4;

/// Stream 0 of a trial draws truth and measurements; stream 1 + v is variant v's coins.
pub fn trial_rng(seed: u64, trial: u64, stream: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(trial_seed(seed, trial, stream))
}

fn trial_seed(seed: u64, trial: u64, stream: u64) -> u64 {
    splitmix64(splitmix64(splitmix64(seed) ^ trial) ^ stream)
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A run that failed, with where.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("scheme {label} (variant {variant}), trial {trial}, step {k}: {source}")]
    Scheme {
        label: String,
        variant: usize,
        trial: usize,
        k: usize,
        source: SchemeError,
    },
    #[error("scheme {label}, trial {trial}, step {k}: fused covariance is not positive definite ({source})")]
    Covariance {
        label: String,
        trial: usize,
        k: usize,
        source: crate::linalg::LinalgError,
    },
    #[error("could not start the thread pool: {0}")]
    Pool(String),
}

/// Truth and measurements of one trial.
pub struct TrialData {
    /// x_1..x_T.
    pub truth: Vec<Vector>,
    /// z_k^i for k = 1..T, i = 1..N.
    pub measurements: Vec<Vec<Vector>>,
}

/// Draws x_0 from the prior, then x_k and every z_k^i, all from one stream.
pub fn draw_trial(exp: &Experiment, trial: usize) -> TrialData {
    let sys = &exp.system;
    let mut rng = trial_rng(exp.seed, trial as u64, 0);
    let x0 = &exp.initial_truth;
    let x0_sqrt = crate::model::transition::psd_sqrt(&x0.cov).expect("validated initial truth");
    let n0 = Vector::from_fn(sys.state_dim(), |_, _| {
        rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng)
    });
    let mut x = &x0.mean + x0_sqrt * n0;
    let mut truth = Vec::with_capacity(exp.steps);
    let mut measurements = Vec::with_capacity(exp.steps);
    for _ in 0..exp.steps {
        x = sys.transition.sample_next(&x, &mut rng);
        measurements.push(sys.sensors.iter().map(|s| s.sample(&x, &mut rng)).collect());
        truth.push(x.clone());
    }
    TrialData {
        truth,
        measurements,
    }
}

/// Runs one trial of every variant, adding into `sums` (one per variant).
fn run_trial(exp: &Experiment, trial: usize, sums: &mut [Sums]) -> Result<(), RunError> {
    let data = draw_trial(exp, trial);
    let n_sensors = exp.system.n_sensors();
    let mut inbox = Vec::with_capacity(n_sensors);
    let mut transmissions = Vec::with_capacity(n_sensors);
    for (v, variant) in exp.variants.iter().enumerate() {
        let label = &exp.curves[variant.curve].label;
        let scheme_err = |k: usize, source: SchemeError| RunError::Scheme {
            label: label.clone(),
            variant: v,
            trial,
            k,
            source,
        };
        let mut rng = trial_rng(exp.seed, trial as u64, 1 + v as u64);
        // The fusion center's own stream (particle filters) is independent of the sensors'.
        let center_seed =
            splitmix64(trial_seed(exp.seed, trial as u64, 1 + v as u64) ^ 0xC3A5_C85C_97CB_3127);
        let mut inst = variant
            .scheme
            .build_with_seed(center_seed)
            .map_err(|e| scheme_err(0, e))?;
        let schedule = variant.scheme.schedule();
        let mut obs = sums[v].trial(&exp.groups, exp.steady_from);
        // What the fusion center tells the sensors before the first measurement.
        let mut feedback = inst.center.feedback();
        for k in 1..=exp.steps {
            transmissions.clear();
            for (i, node) in inst.sensors.iter_mut().enumerate() {
                let t = if schedule.allows(k, i, n_sensors) {
                    node.step(k, &data.measurements[k - 1][i], feedback.as_ref(), &mut rng)
                        .map_err(|e| scheme_err(k, e))?
                } else {
                    crate::link::Transmission::Silent
                };
                transmissions.push(t);
            }
            let mut traffic = network::deliver(transmissions.drain(..), &mut inbox);
            traffic.downlink_bits = feedback.as_ref().map_or(0, |f| f.bits(n_sensors));
            if schedule != network::Schedule::All {
                for (i, r) in inbox.iter_mut().enumerate() {
                    if !schedule.allows(k, i, n_sensors) {
                        *r = crate::link::Received::NotScheduled;
                    }
                }
            }
            inst.center.step(k, &inbox).map_err(|e| scheme_err(k, e))?;
            feedback = inst.center.feedback();
            obs.record(k, &data.truth[k - 1], inst.center.estimate(), traffic)
                .map_err(|source| RunError::Covariance {
                    label: label.clone(),
                    trial,
                    k,
                    source,
                })?;
            obs.record_ess(k, inst.center.ess());
        }
        obs.finish();
    }
    Ok(())
}

/// Options of a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunOptions {
    /// Worker threads (0: rayon's default, one per core).
    pub threads: usize,
}

/// Runs every trial of every variant and returns the merged sums, one per variant.
/// `progress` is called with the number of finished trials.
pub fn run(
    exp: &Experiment,
    opts: RunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<Sums>, RunError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| RunError::Pool(e.to_string()))?;
    let n_blocks = exp.trials.div_ceil(BLOCK);
    let done = AtomicUsize::new(0);
    let empty = || -> Vec<Sums> {
        exp.variants
            .iter()
            .map(|_| Sums::new(exp.groups.len(), exp.steps, exp.system.state_dim()))
            .collect()
    };
    let blocks: Result<Vec<Vec<Sums>>, RunError> = pool.install(|| {
        (0..n_blocks)
            .into_par_iter()
            .map(|b| {
                let mut sums = empty();
                for trial in b * BLOCK..((b + 1) * BLOCK).min(exp.trials) {
                    run_trial(exp, trial, &mut sums)?;
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                }
                Ok(sums)
            })
            .collect()
    });
    let mut total = empty();
    for block in blocks? {
        for (t, b) in total.iter_mut().zip(&block) {
            t.merge(b);
        }
    }
    Ok(total)
}
