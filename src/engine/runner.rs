//! The Monte Carlo runner: the only time loop of the library. Per trial, truth and every
//! sensor's measurements are drawn once from a stream seeded by (seed, trial); every scheme then
//! processes the same data with coin flips from a stream of its own (common random numbers).
//! Trials run in parallel in fixed blocks whose sums are merged in block order, so results are
//! bit-identical for any number of threads.
use crate::linalg::quad::F64x4;
use crate::linalg::Vector;
use crate::metrics::{QuadTrials, Sums, TrialFailure};
use crate::network;
use crate::scenario::experiment::Experiment;
pub use crate::scenario::limits::{WINDOW_MAX_BYTES, WINDOW_PER_THREAD};
use crate::scheme::SchemeError;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Trials per block. Fixed (not derived from the thread count) so that the summation order,
/// and hence every bit of the result, is the same for 1 or many threads.
const BLOCK: usize = 4;

/// The window grows (doubling) while a window takes less than this: each window ends in a
/// barrier of the thread pool (tens of microseconds), which cost the 5000 short trials of the
/// peers' KF Monte Carlo 40% of their time at two blocks per thread.
const WINDOW_MIN_SECONDS: f64 = 0.025;

/// Blocks per window at most, whatever the size of a block's sums: a window is also what a
/// Ctrl-C drops, so it stays short in time too (it only grows while it is under
/// [`WINDOW_MIN_SECONDS`]).
const WINDOW_MAX_BLOCKS: usize = 1024;

use crate::engine::trial::{
    run_trial, LoopBuffers, LoopError, Observer, ObserverError, StepOutput, TrialSpec,
};
use crate::stats::seeding::coin_stream;
pub use crate::stats::seeding::{center_seed, trial_rng};

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
    /// A variant's trial failed (recorded in its sums, see [`first_failure`]).
    #[error("trial {trial}: {message}")]
    Failed {
        label: String,
        trial: usize,
        k: usize,
        message: String,
    },
}

use crate::scenario::draw::Drawer;
pub use crate::scenario::draw::{draw_trial, TrialData};

/// What a worker task keeps from block to block: trial buffers (one per trial of a block
/// when the variants run blocks in lockstep, else one) and the variants' work space.
struct Worker<'e> {
    drawers: Vec<Drawer>,
    /// A block drawn side by side ([`run_quad_block`]) and its trials' running sums (`None`
    /// inside: the rows do not fit [`QuadTrials`]).
    quad: crate::scenario::draw::QuadData,
    lanes: Option<Option<QuadTrials>>,
    scratch: LoopBuffers,
    /// The trial states of a lockstep batch, restarted for each variant of each block.
    states: Vec<crate::metrics::TrialState<'e>>,
}

impl<'e> Worker<'e> {
    fn new(exp: &Experiment) -> Self {
        Self {
            drawers: vec![Drawer::new(exp)],
            quad: Default::default(),
            lanes: None,
            scratch: LoopBuffers::new(exp.system.n_sensors()),
            states: Vec::new(),
        }
    }
}

/// A [`Worker`] borrowed from a pool and returned to it when dropped.
struct PooledWorker<'a, 'e> {
    worker: Option<Worker<'e>>,
    pool: &'a std::sync::Mutex<Vec<Worker<'e>>>,
}

impl<'a, 'e> PooledWorker<'a, 'e> {
    fn take(pool: &'a std::sync::Mutex<Vec<Worker<'e>>>, exp: &Experiment) -> Self {
        let worker = pool
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .pop()
            .unwrap_or_else(|| Worker::new(exp));
        Self {
            worker: Some(worker),
            pool,
        }
    }

    fn get(&mut self) -> &mut Worker<'e> {
        self.worker.as_mut().expect("present until dropped")
    }
}

impl Drop for PooledWorker<'_, '_> {
    fn drop(&mut self) {
        if let Some(w) = self.worker.take() {
            self.pool.lock().unwrap_or_else(|e| e.into_inner()).push(w);
        }
    }
}

/// Runs the trials of one block, adding into `sums` (one per variant): one trial at a time,
/// every variant on its data (the variants of a trial share work through its cache), or, when
/// every variant runs batches ([`crate::scheme::fast_path::LockstepFastPath::batches`]), all
/// the block's trials drawn first and each variant run on them in lockstep. `on_trial` is
/// called after each trial (after the block, for a batch); `stop` is checked before each trial
/// (before the block) and ends the block early with `Ok(false)`.
fn run_block<'e>(
    exp: &'e Experiment,
    trials: std::ops::Range<usize>,
    sums: &mut [Sums],
    worker: &mut Worker<'e>,
    stop: &dyn Fn() -> bool,
    on_trial: &dyn Fn(usize),
) -> Result<bool, RunError> {
    let batch = (2..=BLOCK).contains(&trials.len())
        // The one rule of the fast paths (`link_layer::route`): a batch needs ideal links and
        // singles for every variant.
        && exp.variants.iter().all(|v| {
            crate::engine::link_layer::route(exp, v, true) == crate::engine::link_layer::Route::FastIdeal
                && v.scheme.fast_path().is_some_and(|f| f.batches())
        });
    if !batch {
        for trial in trials {
            if stop() {
                return Ok(false);
            }
            let drawer = &mut worker.drawers[0];
            drawer.draw(exp, trial);
            run_trial_with(exp, trial, &drawer.data, sums, &mut worker.scratch)?;
            note_readings(exp, &drawer.peaks, sums);
            on_trial(1);
        }
        return Ok(true);
    }
    if stop() {
        return Ok(false);
    }
    let n = trials.len();
    if n == F64x4::LANES
        && exp
            .variants
            .iter()
            .all(|v| v.scheme.fast_path().is_some_and(|f| f.quads()))
        && worker.drawers[0].start_quad(exp, trials.start, &mut worker.quad)
    {
        run_quad_block(exp, trials, sums, worker)?;
        on_trial(n);
        return Ok(true);
    }
    while worker.drawers.len() < n {
        worker.drawers.push(Drawer::new(exp));
    }
    for (d, trial) in worker.drawers.iter_mut().zip(trials.clone()) {
        d.draw(exp, trial);
    }
    let drawn = &worker.drawers[..n];
    // The block's trials in arrays of BLOCK (nothing allocated per block).
    let mut measurements: [&[Vec<Vector>]; BLOCK] = [&[]; BLOCK];
    let mut truths: [&[Vector]; BLOCK] = [&[]; BLOCK];
    for ((m, t), d) in measurements.iter_mut().zip(&mut truths).zip(drawn) {
        *m = d.data.measurements.as_slice();
        *t = d.data.truth.as_slice();
    }
    let measurements = &measurements[..n];
    for (v, s) in sums.iter_mut().enumerate().take(exp.variants.len()) {
        let scheme = &exp.variants[v].scheme;
        while worker.states.len() < n {
            worker
                .states
                .push(s.trial_state(&exp.groups, exp.steady_from));
        }
        let states = &mut worker.states[..n];
        states.iter_mut().for_each(|state| state.restart(s));
        let mut recorder = BatchRecorder {
            security: exp.security,
            states,
            truths: &truths[..n],
            sums: s,
        };
        // Every variant batches, so each has a fast path (one virtual call per block).
        let outcome = scheme.fast_path().and_then(|fast| {
            fast.run_batch_fast(
                measurements,
                exp.steps,
                worker.scratch.batch_cache(),
                &mut recorder,
            )
        });
        match outcome {
            Some(Ok(())) => recorder.finish(),
            // Not for this data, or failed: one trial at a time from this block's start (the
            // block's sums of this variant hold this block's trials only), which reports the
            // error as the one-at-a-time loop does.
            other => {
                if other.is_some() {
                    recorder.sums.clear();
                }
                for (d, trial) in drawn.iter().zip(trials.clone()) {
                    run_variant(exp, trial, v, &d.data, recorder.sums, &mut worker.scratch)?;
                }
            }
        }
    }
    for d in drawn {
        note_readings(exp, &d.peaks, sums);
    }
    on_trial(n);
    Ok(true)
}

/// [`run_block`] for a block of four trials drawn side by side, a step at a time (started by
/// [`Drawer::start_quad`]), and run by every variant's [`LockstepFastPath::run_quad_fast`],
/// recorded by [`QuadTrials`]. A variant that declines the block, or whose fast path or
/// recording fails, runs the block's trials one at a time from the block's start (the numbers
/// of the batch, or the failure the one-at-a-time loop reports).
///
/// [`LockstepFastPath::run_quad_fast`]: crate::scheme::fast_path::LockstepFastPath::run_quad_fast
fn run_quad_block<'e>(
    exp: &'e Experiment,
    trials: std::ops::Range<usize>,
    sums: &mut [Sums],
    worker: &mut Worker<'e>,
) -> Result<(), RunError> {
    let Worker {
        drawers,
        quad,
        lanes,
        states,
        scratch,
    } = worker;
    let mut drawn = false;
    for (v, s) in sums.iter_mut().enumerate().take(exp.variants.len()) {
        let outcome = exp.variants[v].scheme.fast_path().and_then(|fast| {
            let lanes = lanes
                .get_or_insert_with(|| QuadTrials::new(s, exp.steady_from))
                .as_mut()?;
            lanes.restart(s, exp.steady_from);
            let mut run = QuadRun {
                exp,
                drawer: &drawers[0],
                quad,
                sums: s,
                lanes,
            };
            let outcome = fast.run_quad_fast(&mut run, exp.steps);
            if let Some(Ok(())) = outcome {
                while states.len() < F64x4::LANES {
                    states.push(s.trial_state(&exp.groups, exp.steady_from));
                }
                lanes.close(s, &mut states[..F64x4::LANES]);
            }
            outcome
        });
        if let Some(Ok(())) = outcome {
            continue;
        }
        // One trial at a time (after clearing what a failed block recorded).
        if outcome.is_some() {
            s.clear();
        }
        if !drawn {
            while drawers.len() < trials.len() {
                drawers.push(Drawer::new(exp));
            }
            for (d, trial) in drawers.iter_mut().zip(trials.clone()) {
                d.draw(exp, trial);
            }
            drawn = true;
        }
        for (d, trial) in drawers.iter().zip(trials.clone()) {
            run_variant(exp, trial, v, &d.data, s, scratch)?;
        }
    }
    // Every step drawn (a variant may have stopped early), for the peaks of every reading.
    while quad.drawn < exp.steps {
        drawers[0].draw_quad_step(exp, quad);
    }
    note_readings(exp, &quad.peaks, sums);
    Ok(())
}

/// A block of four trials run side by side ([`crate::scheme::fast_path::QuadBlock`]): the steps
/// drawn as the fast path asks for them, each step's estimates recorded into the variant's
/// block sums ([`QuadTrials::record`]).
struct QuadRun<'a> {
    exp: &'a Experiment,
    drawer: &'a Drawer,
    quad: &'a mut crate::scenario::draw::QuadData,
    sums: &'a mut Sums,
    lanes: &'a mut QuadTrials,
}

impl crate::scheme::fast_path::QuadBlock for QuadRun<'_> {
    fn shape(&self) -> (usize, usize) {
        (self.quad.n, self.quad.sensors)
    }

    fn readings(&mut self, k: usize) -> &[F64x4] {
        while self.quad.drawn < k.min(self.exp.steps) {
            self.drawer.draw_quad_step(self.exp, self.quad);
        }
        let s = self.quad.sensors;
        &self.quad.readings[(k - 1) * s..k * s]
    }

    fn step_quad(
        &mut self,
        k: usize,
        means: &[F64x4],
        cov: &crate::linalg::Matrix,
        factor: Option<&[f64]>,
        mut traffic: network::Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        traffic.secure(&self.exp.security, traffic.star_frames());
        let n = self.quad.n;
        let truth = &self.quad.truth[(k - 1) * n..k * n];
        let groups = &self.exp.groups;
        let recorded = self
            .lanes
            .record(self.sums, groups, k, truth, means, cov, factor, traffic);
        // Not side by side (no usable factor): the runner reruns the trials one at a time.
        recorded
            .then_some(())
            .ok_or(crate::linalg::LinalgError::NotPositiveDefinite)
    }
}

/// One trial's largest readings (`peaks`, [`Drawer::peaks`]) into every variant's sums
/// ([`crate::metrics::Sums::reading_peaks`], for [`crate::metrics::precision`]); nothing when
/// the scenario sends doubles, whose rounding is never coarse.
fn note_readings(exp: &Experiment, peaks: &[f64], sums: &mut [Sums]) {
    if !exp.reals.is_f32() {
        return;
    }
    for s in sums.iter_mut().take(exp.variants.len()) {
        s.merge_peaks(peaks);
    }
}

/// The sink of a batch: one trial state per trial of the block, all adding into the
/// variant's block sums in trial order at every step.
struct BatchRecorder<'a, 'e> {
    /// What securing the frames adds to each step's traffic (the fast paths price none).
    security: crate::link::security::SecuritySpec,
    sums: &'a mut Sums,
    states: &'a mut [crate::metrics::TrialState<'e>],
    truths: &'a [&'a [Vector]],
}

impl BatchRecorder<'_, '_> {
    /// Closes the trials, in trial order.
    fn finish(self) {
        for state in self.states.iter_mut() {
            state.close(self.sums);
        }
    }
}

impl crate::scheme::fast_path::BatchSink for BatchRecorder<'_, '_> {
    fn step(
        &mut self,
        j: usize,
        k: usize,
        estimate: &crate::filter::Gaussian,
        factor: Option<&[f64]>,
        mut traffic: network::Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        traffic.secure(&self.security, traffic.star_frames());
        let (state, truth) = (&mut self.states[j], &self.truths[j][k - 1]);
        match factor {
            Some(f) => state.record_factored(self.sums, k, truth, estimate, f, traffic)?,
            None => state.record(self.sums, k, truth, estimate, traffic)?,
        }
        state.record_ess(self.sums, k, None);
        Ok(())
    }

    fn step_shared(
        &mut self,
        k: usize,
        means: &[f64],
        shared: &mut crate::filter::Gaussian,
        factor: Option<&[f64]>,
        mut traffic: network::Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        traffic.secure(&self.security, traffic.star_frames());
        // No ESS to record (`record_ess` of `None` adds nothing).
        crate::metrics::record_shared(
            self.states,
            self.sums,
            k,
            self.truths,
            means,
            shared,
            factor,
            traffic,
        )
    }
}

/// Runs one trial of every variant on the given truth and measurements (drawn by
/// [`draw_trial`], or recorded), adding into `sums` (one per variant). Variant v's coins come
/// from stream 1 + v of `trial`, as in [`run`].
pub fn run_trial_on(
    exp: &Experiment,
    trial: usize,
    data: &TrialData,
    sums: &mut [Sums],
) -> Result<(), RunError> {
    run_trial_with(
        exp,
        trial,
        data,
        sums,
        &mut LoopBuffers::new(exp.system.n_sensors()),
    )
}

/// [`run_trial_on`] in the given work space.
fn run_trial_with(
    exp: &Experiment,
    trial: usize,
    data: &TrialData,
    sums: &mut [Sums],
    scratch: &mut LoopBuffers,
) -> Result<(), RunError> {
    for (v, s) in sums.iter_mut().enumerate().take(exp.variants.len()) {
        run_variant(exp, trial, v, data, s, scratch)?;
    }
    Ok(())
}

/// The metrics of one variant's trial as an engine [`Observer`]: every fused step into its
/// trial's sums, and the sink of the scheme's fast path (no links needed).
struct SumsObserver<'a, 'b> {
    /// What securing the frames adds to a fast path's traffic (the loop's steps have it).
    security: crate::link::security::SecuritySpec,
    obs: &'b mut crate::metrics::TrialObserver<'a>,
    truth: &'b [Vector],
}

impl Observer for SumsObserver<'_, '_> {
    fn needs_links(&self) -> bool {
        false
    }

    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError> {
        self.obs
            .record(s.k, &self.truth[s.k - 1], s.estimate, s.traffic)
            .map_err(ObserverError::Covariance)?;
        self.obs.record_ess(s.k, s.ess);
        self.obs.record_nodes(s.k, s.nodes);
        Ok(())
    }

    fn fast_sink(&mut self) -> Option<&mut dyn crate::scheme::fast_path::BatchSink> {
        Some(self)
    }
}

impl crate::scheme::fast_path::BatchSink for SumsObserver<'_, '_> {
    /// A fast trial reports as trial 0 of a batch of one.
    fn step(
        &mut self,
        _j: usize,
        k: usize,
        estimate: &crate::filter::Gaussian,
        factor: Option<&[f64]>,
        mut traffic: network::Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        traffic.secure(&self.security, traffic.star_frames());
        let truth = &self.truth[k - 1];
        match factor {
            Some(f) => self.obs.record_factored(k, truth, estimate, f, traffic)?,
            None => self.obs.record(k, truth, estimate, traffic)?,
        }
        self.obs.record_ess(k, None);
        Ok(())
    }
}

/// Runs variant `v` over one trial's data (the engine's loop), adding into its `sums`.
fn run_variant(
    exp: &Experiment,
    trial: usize,
    v: usize,
    data: &TrialData,
    sums: &mut Sums,
    scratch: &mut LoopBuffers,
) -> Result<(), RunError> {
    if let Some(peers) = exp.variants[v].scheme.peers() {
        crate::engine::peers::run_variant(exp, trial, v, peers, data, sums);
        return Ok(());
    }
    let label = &exp.curves[exp.variants[v].curve].label;
    let mut obs = sums.trial(&exp.groups, exp.steady_from);
    let spec = TrialSpec {
        trial,
        variant: v,
        stream: coin_stream(v),
        available: None,
    };
    let mut observer = SumsObserver {
        security: exp.security,
        obs: &mut obs,
        truth: &data.truth,
    };
    match run_trial(exp, &data.measurements, spec, scratch, &mut observer) {
        Ok(()) => obs.finish(),
        // A failed trial makes the variant a failed row (the first failure, by trial), not
        // the end of the run: the other variants finish. What the trial recorded before it
        // failed stays in these sums, which are then not reported.
        Err(e) => {
            let step = match &e {
                LoopError::Scheme { k, .. }
                | LoopError::Covariance { k, .. }
                | LoopError::Observer { k, .. }
                | LoopError::Input { k, .. } => *k,
            };
            sums.record_failure(TrialFailure {
                trial,
                step,
                message: e.describe(label),
            });
        }
    }
    Ok(())
}

/// The first failure of any variant of a run, as the error the run stopped with before failed
/// variants became failed rows (for callers that need every variant to succeed: calibration).
pub fn first_failure(exp: &Experiment, sums: &[Sums]) -> Option<RunError> {
    sums.iter().enumerate().find_map(|(v, s)| {
        s.failure.as_ref().map(|f| RunError::Failed {
            label: exp.curves[exp.variants[v].curve].label.clone(),
            trial: f.trial,
            k: f.step,
            message: f.message.clone(),
        })
    })
}

/// Options of a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunOptions {
    /// Worker threads (0: rayon's default, one per core).
    pub threads: usize,
}

/// Number of fixed trial blocks of a run of `trials` trials: the unit of checkpoints and shards.
pub fn n_blocks(trials: usize) -> usize {
    trials.div_ceil(BLOCK)
}

/// Trials of block `b` (the last block may be short).
/// (Saturating: a block number past the run, even near `usize::MAX`, gives an empty range at
/// the end, never an overflow.)
pub fn block_trials(b: usize, trials: usize) -> std::ops::Range<usize> {
    b.saturating_mul(BLOCK).min(trials)..b.saturating_add(1).saturating_mul(BLOCK).min(trials)
}

/// Per-variant sums with nothing added: where every fold of blocks starts.
pub fn empty_sums(exp: &Experiment) -> Vec<Sums> {
    exp.variants
        .iter()
        .map(|_| Sums::new(exp.groups.len(), exp.steps, exp.system.state_dim()))
        .collect()
}

/// Adds one block's sums into a running total (the fold of [`run`], in block order).
pub fn fold_block(total: &mut [Sums], block: &[Sums]) {
    for (t, b) in total.iter_mut().zip(block) {
        t.merge(b);
    }
}

/// Receives each finished window of [`run_windows`]: its first block and the blocks' sums.
pub type WindowSink<'a> = dyn FnMut(usize, &mut Vec<Vec<Sums>>) -> Result<(), RunError> + 'a;

/// How [`run_windows`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Completion {
    /// Every block of the range ran.
    Done,
    /// The stop flag was raised: the blocks delivered so far are complete; the window in
    /// flight was dropped.
    Stopped,
}

/// Runs the blocks of `blocks` a window at a time in parallel and hands each finished window's
/// per-block sums (in block order, starting at block `first`) to `on_window`, which folds
/// them or takes them out of the vector; what it leaves there is cleared and reused for later
/// blocks (fresh sums cost an allocation and page faults per block). `stop` is
/// checked before every trial: once raised, the window in flight is dropped and the run
/// returns [`Completion::Stopped`]. `progress` is called with the number of trials finished
/// in this call.
/// Most worker threads a run starts: eight per core. More only cost the time of creating them
/// (minutes for 10^5, during which the process does not see Ctrl-C); results do not depend
/// on the count.
pub fn max_threads() -> usize {
    8 * std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

pub fn run_windows(
    exp: &Experiment,
    opts: RunOptions,
    blocks: std::ops::Range<usize>,
    stop: Option<&std::sync::atomic::AtomicBool>,
    progress: &(dyn Fn(usize) + Sync),
    on_window: &mut WindowSink<'_>,
) -> Result<Completion, RunError> {
    // One thread: the blocks run on the caller's thread, without a pool to hand every
    // window to and back (a thread wake-up each way); the same blocks in the same order.
    let pool = if opts.threads == 1 {
        None
    } else {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(opts.threads.min(max_threads()))
            .build()
            .map_err(|e| RunError::Pool(e.to_string()))?;
        Some(pool)
    };
    let threads = pool
        .as_ref()
        .map_or(1, rayon::ThreadPool::current_num_threads);
    let done = AtomicUsize::new(0);
    let stopped = || stop.is_some_and(|s| s.load(Ordering::Relaxed));
    // Blocks run in parallel a window at a time and are handed over in block order as each
    // window finishes: memory stays flat in the number of trials (at most `window` blocks'
    // sums are alive), and the summation order is the one of a sequential run.
    let min_window = WINDOW_PER_THREAD * threads.max(1);
    let block_bytes = empty_sums(exp).iter().map(Sums::heap_bytes).sum::<usize>()
        + BLOCK * exp.variants.len() * Sums::per_trial_bytes(exp.groups.len());
    let max_window = (WINDOW_MAX_BYTES / block_bytes.max(1))
        .min(WINDOW_MAX_BLOCKS)
        .max(min_window);
    let mut window = min_window;
    let workers = std::sync::Mutex::new(Vec::new());
    // Block sums left by `on_window`, cleared, for the next blocks.
    let spare: std::sync::Mutex<Vec<Vec<Sums>>> = std::sync::Mutex::new(Vec::new());
    let fresh_sums = || {
        let reused = spare.lock().unwrap_or_else(|e| e.into_inner()).pop();
        reused.unwrap_or_else(|| empty_sums(exp))
    };
    let mut start = blocks.start;
    while start < blocks.end {
        let began = std::time::Instant::now();
        if stopped() {
            return Ok(Completion::Stopped);
        }
        let end = (start + window).min(blocks.end);
        let block = block_runner(|worker, b: usize| {
            let mut sums = fresh_sums();
            let finished = run_block(
                exp,
                block_trials(b, exp.trials),
                &mut sums,
                worker,
                &stopped,
                &|n| progress(done.fetch_add(n, Ordering::Relaxed) + n),
            )?;
            Ok(finished.then_some(sums))
        });
        let window_sums: Result<Vec<Option<Vec<Sums>>>, RunError> = match &pool {
            Some(pool) => pool.install(|| {
                (start..end)
                    .into_par_iter()
                    // One drawer (trial buffers) per worker task, not per block, recycled
                    // from window to window.
                    .map_init(
                        || PooledWorker::take(&workers, exp),
                        |worker, b| block(worker.get(), b),
                    )
                    .collect()
            }),
            None => {
                let mut worker = PooledWorker::take(&workers, exp);
                (start..end).map(|b| block(worker.get(), b)).collect()
            }
        };
        let Some(mut window_sums) = window_sums?.into_iter().collect::<Option<Vec<_>>>() else {
            return Ok(Completion::Stopped);
        };
        on_window(start, &mut window_sums)?;
        let mut spare = spare.lock().unwrap_or_else(|e| e.into_inner());
        for mut block in window_sums {
            block.iter_mut().for_each(Sums::clear);
            spare.push(block);
        }
        drop(spare);
        start = end;
        if began.elapsed().as_secs_f64() < WINDOW_MIN_SECONDS {
            window = (2 * window).min(max_window);
        }
    }
    Ok(Completion::Done)
}

/// Gives a closure that runs block `b` with a worker the signature that takes a worker of
/// any borrow (for the pool's tasks and the caller's own thread alike).
fn block_runner<'e, F>(f: F) -> F
where
    F: Fn(&mut Worker<'e>, usize) -> Result<Option<Vec<Sums>>, RunError>,
{
    f
}

/// Runs every trial of every variant and returns the merged sums, one per variant.
/// `progress` is called with the number of finished trials.
pub fn run(
    exp: &Experiment,
    opts: RunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<Sums>, RunError> {
    run_maybe_until(exp, opts, progress, None)
}

/// [`run`] that stops between trials once `stop` is raised (Python's Ctrl-C): the sums are then
/// those of the blocks finished, not the run's.
pub fn run_until(
    exp: &Experiment,
    opts: RunOptions,
    progress: &(dyn Fn(usize) + Sync),
    stop: &std::sync::atomic::AtomicBool,
) -> Result<Vec<Sums>, RunError> {
    run_maybe_until(exp, opts, progress, Some(stop))
}

fn run_maybe_until(
    exp: &Experiment,
    opts: RunOptions,
    progress: &(dyn Fn(usize) + Sync),
    stop: Option<&std::sync::atomic::AtomicBool>,
) -> Result<Vec<Sums>, RunError> {
    let mut total = empty_sums(exp);
    run_windows(
        exp,
        opts,
        0..n_blocks(exp.trials),
        stop,
        progress,
        &mut |_, blocks| {
            for block in blocks.iter() {
                fold_block(&mut total, block);
            }
            Ok(())
        },
    )?;
    Ok(total)
}
