//! Metrics as mergeable sums: per time step and per trial, so that runs split across threads,
//! processes or machines merge exactly (in a fixed order, for bit-identical results).
//!
//! The row layout is in `row.rs`, the NEES histogram and bounds in `nees.rs`; this file holds
//! the sums of a variant, their recording during a trial and their merging.
mod estimators;
mod nees;
mod quad;
mod row;
mod shared;
#[cfg(test)]
mod tests;

use crate::filter::Gaussian;
use crate::linalg::{mahalanobis_sq, Vector};
use crate::network::Traffic;
pub use estimators::EstimatorStat;
use estimators::EstimatorState;
pub use nees::*;
pub use quad::QuadTrials;
pub use row::*;
pub use shared::record_shared;

/// Sums for one scheme variant.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sums {
    pub layout_groups: usize,
    /// State dimension (for the NEES bound).
    pub state_dim: usize,
    pub steps: usize,
    /// steps x width, row-major.
    pub per_step: Vec<f64>,
    /// Sums of squares of the same per-(trial, step) values, for per-step standard errors.
    pub per_step_sq: Vec<f64>,
    /// Per field of the layout: the per-trial average over all steps, whose spread across
    /// trials gives the standard error of every time-averaged mean in `summary.json`.
    pub whole_run: Vec<TrialStat>,
    pub trials: usize,
    /// Steady-state per-trial averages: total squared error, trace, NEES, messages per step.
    pub steady_mse: TrialStat,
    pub steady_trace: TrialStat,
    pub steady_nees: TrialStat,
    pub steady_messages: TrialStat,
    /// Per trial, in trial order: steady-state mean squared error, total then per group
    /// (`1 + groups` values a trial, one flat vector: no allocation per trial; see
    /// [`Sums::per_trial_rows`]). Kept so that two schemes can be compared by paired
    /// differences on the same trials.
    pub per_trial: Vec<f64>,
    /// Per trial, in trial order: steady-state mean NEES (to see whether a few trials dominate
    /// the mean).
    pub per_trial_nees: Vec<f64>,
    /// Trials that diverged (see [`DIVERGENCE_RUN`]).
    pub diverged: usize,
    /// Smallest ESS across trials per step (infinite where no particle filter reported one).
    pub ess_min: Vec<f64>,
    /// Whether the fusion center reported an ESS.
    pub has_ess: bool,
    /// Steady-state NEES / n of every (trial, step).
    pub nees_hist: NeesHistogram,
    /// Per step, summed over trials, the link's counters of [`LINK_COUNTERS`] (in that order):
    /// messages the link lost, messages it delivered late (fused on arrival), messages later
    /// than the horizon (dropped), feedback packets the downlink lost, and with ARQ the
    /// retransmissions, duplicates, acknowledgment frames and their bits. Empty until a link
    /// does any of this (an ideal link costs nothing here); integers, so the order of additions
    /// changes nothing.
    pub link: Vec<[u64; LINK_FIELDS]>,
    /// The first trial (in trial order) whose loop failed, if one did: the variant is then
    /// reported as failed and its numbers are not used. Merging keeps the lowest trial, so the
    /// failure reported does not depend on threads, checkpoints or shards.
    #[serde(default)]
    pub failure: Option<TrialFailure>,
    /// Per sensor i (bit i of [`Traffic::scheduled`] and [`Traffic::senders`]), summed over
    /// trials and steps: `[steps scheduled, steps it sent]`. Each sensor's send probability,
    /// whose entropy the entropy-coded rate `r_eff_per_step` charges. Integers (the order of
    /// additions changes nothing); as long as the highest sensor that was ever scheduled.
    /// (Always written: checkpoints are postcard, which has no optional fields.)
    #[serde(default)]
    pub sensors: Vec<[u64; 2]>,
    /// The largest |reading| of each measurement component (sensors in order, each sensor's
    /// components in order), over every trial and step: whether a single (32-bit) rounds the
    /// readings coarser than their noise ([`crate::metrics::precision`]). A maximum, so the
    /// order of merging changes nothing; empty until a trial is noted.
    #[serde(default)]
    pub reading_peaks: Vec<f64>,
    /// Over a multi-hop network: per node (sensors, relays, sink), its counters
    /// ([`crate::network::topology::tally::NODE_COUNTERS`]) summed over trials and steps.
    /// Integers; empty on a star.
    #[serde(default)]
    pub nodes: Vec<crate::network::topology::tally::NodeCounts>,
    /// Over a multi-hop network: per step, summed over trials, `[frames on air (every node's
    /// attempts), frames that carried what other nodes sent (forwards)]`: the hops of
    /// `per_step.csv`. Empty on a star.
    #[serde(default)]
    pub hops: Vec<[u64; 2]>,
    /// A decentralized scheme (every node estimates): per node, the spread across trials of its
    /// steady-state mean squared error and NEES ([`EstimatorStat`]). Empty for a scheme with one
    /// estimate (its center's).
    #[serde(default)]
    pub estimators: Vec<EstimatorStat>,
    /// A decentralized scheme: per trial, the steady-state mean over steps of the nodes'
    /// disagreement (1/M) Σᵢ ‖x̂ᵢ − x̄‖², x̄ the mean of the M nodes' estimates.
    #[serde(default)]
    pub disagreement: TrialStat,
}

/// Where and why a variant's trial failed.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrialFailure {
    pub trial: usize,
    /// The step (1-based; 0: building the scheme).
    pub step: usize,
    pub message: String,
}

/// Number of counters in a row of [`Sums::link`].
pub const LINK_FIELDS: usize = 8;

/// The names of the counters of a row of [`Sums::link`], in order (as in [`Traffic`]).
pub const LINK_COUNTERS: [&str; LINK_FIELDS] = [
    "lost",
    "late",
    "dropped_late",
    "downlink_lost",
    "retransmissions",
    "duplicates",
    "ack_frames",
    "ack_bits",
];

/// The link's counters of one step's traffic, in the order of [`LINK_COUNTERS`].
pub fn link_counts(t: &Traffic) -> [u64; LINK_FIELDS] {
    [
        t.lost,
        t.late,
        t.dropped_late,
        t.downlink_lost,
        t.retransmissions,
        t.duplicates,
        t.ack_frames,
        t.ack_bits,
    ]
}

/// Observer of one trial of one variant: accumulates into a [`Sums`] as the trial runs.
pub struct TrialObserver<'a> {
    sums: &'a mut Sums,
    state: TrialState<'a>,
}

/// What one trial of one variant carries from step to step (divergence run, steady-state
/// sums, work space), apart from the [`Sums`] it adds into: several trials of a batch can be
/// in flight on the same sums ([`TrialState::record`] takes them per call).
pub struct TrialState<'a> {
    groups: &'a [(String, Vec<usize>)],
    steady_from: usize,
    /// chi^2_n 99% quantile.
    nees_bound: f64,
    /// chi^2_n 95% quantile.
    nees_bound_95: f64,
    /// chi^2_n 99.9% quantile (divergence).
    divergence_bound: f64,
    /// Current run of consecutive steps above `divergence_bound`.
    run: usize,
    diverged: bool,
    acc: [f64; 4],
    group_acc: Row,
    /// This trial's per-field sums over all steps (for [`Sums::whole_run`]).
    run_acc: Row,
    count: usize,
    /// Work space, so that a step allocates nothing: the error (when it is too long for the
    /// stack), its whitened form and the matrix the NEES Cholesky factor is computed in
    /// (dimensions above 6).
    err: Vector,
    white: Vector,
    chol_buf: Option<crate::linalg::Matrix>,
    /// The last step's traffic and its counts as floats.
    traffic: (Traffic, [f64; 4]),
    /// Steady-state NEES values not yet in the histogram: binned [`PENDING_NEES`] at a time
    /// and at [`TrialState::finish`], in a loop of independent iterations, instead of each at
    /// the end of its step's chain NEES -> NEES / n -> log -> bin (the counts are integers:
    /// the order they are added in changes nothing).
    pending_nees: [f64; PENDING_NEES],
    pending: usize,
    /// A decentralized scheme's per-node running sums ([`TrialState::record_estimators`]).
    estimators: Option<Box<EstimatorState>>,
}

/// One step's values of a trial (of one estimator, or the mean over a network's estimators).
#[derive(Debug, Clone, Copy)]
struct StepValues {
    /// Squared error, all components.
    total: f64,
    nees: f64,
    /// 1 when the covariance was degenerate (the fraction of estimators whose was).
    degenerate: f64,
    /// 1 when the NEES was within its 99% and 95% bounds (the fraction of estimators).
    covered: [f64; 2],
    trace: f64,
}

/// Capacity of [`TrialState`]'s buffer of NEES values awaiting the histogram.
const PENDING_NEES: usize = 32;

impl Sums {
    pub fn new(groups: usize, steps: usize, state_dim: usize) -> Self {
        let layout = Layout { groups };
        Self {
            layout_groups: groups,
            state_dim,
            steps,
            per_step: vec![0.0; steps * layout.width()],
            per_step_sq: vec![0.0; steps * layout.width()],
            whole_run: vec![TrialStat::default(); layout.width()],
            trials: 0,
            steady_mse: TrialStat::default(),
            steady_trace: TrialStat::default(),
            steady_nees: TrialStat::default(),
            steady_messages: TrialStat::default(),
            per_trial: Vec::new(),
            per_trial_nees: Vec::new(),
            diverged: 0,
            ess_min: vec![f64::INFINITY; steps],
            has_ess: false,
            nees_hist: NeesHistogram::new(),
            link: Vec::new(),
            failure: None,
            sensors: Vec::new(),
            reading_peaks: Vec::new(),
            nodes: Vec::new(),
            hops: Vec::new(),
            estimators: Vec::new(),
            disagreement: TrialStat::default(),
        }
    }

    /// Adds step `k`'s (1-based) frames on air and forwards of one trial to [`Sums::hops`].
    fn add_hops(&mut self, k: usize, nodes: &[crate::network::topology::tally::NodeCounts]) {
        if self.hops.is_empty() {
            self.hops = vec![[0; 2]; self.steps];
        }
        for c in nodes {
            let (sent, _, forwarded) = crate::network::topology::tally::frames(c);
            self.hops[k - 1][0] += sent;
            self.hops[k - 1][1] += forwarded;
        }
    }

    /// Adds one step's counters of every node of a multi-hop network.
    pub fn add_nodes(&mut self, nodes: &[crate::network::topology::tally::NodeCounts]) {
        if self.nodes.len() < nodes.len() {
            self.nodes.resize(nodes.len(), Default::default());
        }
        for (a, b) in self.nodes.iter_mut().zip(nodes) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
    }

    /// Adds one step's scheduled and sending sensors of `trials` trials (one, or a lockstep
    /// batch sharing its traffic) to [`Sums::sensors`].
    fn add_senders(&mut self, t: &Traffic, trials: u64) {
        let all = t.scheduled | t.senders;
        if all == 0 {
            return;
        }
        let top = 128 - all.leading_zeros() as usize;
        if self.sensors.len() < top {
            self.sensors.resize(top, [0; 2]);
        }
        for (field, mut mask) in [(0, t.scheduled), (1, t.senders)] {
            while mask != 0 {
                self.sensors[mask.trailing_zeros() as usize][field] += trials;
                mask &= mask - 1;
            }
        }
    }

    /// Raises [`Sums::reading_peaks`] to `peaks` where they are larger (a NaN changes nothing).
    pub fn merge_peaks(&mut self, peaks: &[f64]) {
        if self.reading_peaks.len() < peaks.len() {
            self.reading_peaks.resize(peaks.len(), 0.0);
        }
        for (a, b) in self.reading_peaks.iter_mut().zip(peaks) {
            *a = a.max(*b);
        }
    }

    /// Records that a trial failed; of several, the lowest trial is kept.
    pub fn record_failure(&mut self, f: TrialFailure) {
        if self.failure.as_ref().is_none_or(|g| f.trial < g.trial) {
            self.failure = Some(f);
        }
    }

    /// Adds step `k`'s (1-based) link counts of one trial, `counts` from [`link_counts`].
    fn add_link(&mut self, k: usize, counts: [u64; LINK_FIELDS]) {
        if self.link.is_empty() {
            self.link = vec![[0; LINK_FIELDS]; self.steps];
        }
        for (a, b) in self.link[k - 1].iter_mut().zip(counts) {
            *a += b;
        }
    }

    /// Heap bytes of these sums before any trial is added (the per-step rows, the whole-run
    /// stats, the ESS minima and the NEES histogram).
    pub fn heap_bytes(&self) -> usize {
        8 * (self.per_step.len() + self.per_step_sq.len() + self.ess_min.len())
            + std::mem::size_of::<TrialStat>() * self.whole_run.len()
            + 8 * self.nees_hist.counts.len()
    }

    /// Heap bytes each trial adds (its row of [`Sums::per_trial`] and its steady NEES), with
    /// the allocator's header.
    pub fn per_trial_bytes(groups: usize) -> usize {
        8 * (1 + groups) + 16 + std::mem::size_of::<Vec<f64>>() + 8
    }

    pub fn layout(&self) -> Layout {
        Layout {
            groups: self.layout_groups,
        }
    }

    /// Starts observing one trial.
    pub fn trial<'a>(
        &'a mut self,
        groups: &'a [(String, Vec<usize>)],
        steady_from: usize,
    ) -> TrialObserver<'a> {
        let state = self.trial_state(groups, steady_from);
        TrialObserver { sums: self, state }
    }

    /// The state of a new trial that will add into these sums (see [`TrialState`]).
    pub fn trial_state<'a>(
        &self,
        groups: &'a [(String, Vec<usize>)],
        steady_from: usize,
    ) -> TrialState<'a> {
        let [nees_bound, nees_bound_95, divergence_bound] = nees_bounds(self.state_dim);
        let width = self.layout().width();
        TrialState {
            groups,
            steady_from,
            nees_bound,
            nees_bound_95,
            divergence_bound,
            run: 0,
            diverged: false,
            acc: [0.0; 4],
            group_acc: Row::zeros(groups.len()),
            run_acc: Row::zeros(width),
            count: 0,
            err: Vector::zeros(0),
            white: Vector::zeros(0),
            chol_buf: None,
            traffic: (Traffic::default(), [0.0; 4]),
            pending_nees: [0.0; PENDING_NEES],
            pending: 0,
            estimators: None,
        }
    }

    /// The per-trial rows of [`Sums::per_trial`], in trial order.
    pub fn per_trial_rows(&self) -> std::slice::ChunksExact<'_, f64> {
        self.per_trial.chunks_exact(1 + self.layout_groups)
    }

    /// Back to [`Sums::new`] of the same shape, keeping the allocations.
    pub fn clear(&mut self) {
        self.per_step.fill(0.0);
        self.per_step_sq.fill(0.0);
        self.whole_run.fill(TrialStat::default());
        self.trials = 0;
        self.steady_mse = TrialStat::default();
        self.steady_trace = TrialStat::default();
        self.steady_nees = TrialStat::default();
        self.steady_messages = TrialStat::default();
        self.per_trial.clear();
        self.per_trial_nees.clear();
        self.diverged = 0;
        self.ess_min.fill(f64::INFINITY);
        self.has_ess = false;
        self.nees_hist.clear();
        self.link.clear();
        self.failure = None;
        self.sensors.clear();
        self.reading_peaks.clear();
        self.nodes.clear();
        self.hops.clear();
        self.estimators.clear();
        self.disagreement = TrialStat::default();
    }

    /// Adds another block's sums (same shape).
    pub fn merge(&mut self, o: &Sums) {
        for (a, b) in self.per_step.iter_mut().zip(&o.per_step) {
            *a += b;
        }
        for (a, b) in self.per_step_sq.iter_mut().zip(&o.per_step_sq) {
            *a += b;
        }
        for (a, b) in self.whole_run.iter_mut().zip(&o.whole_run) {
            a.merge(b);
        }
        self.trials += o.trials;
        self.steady_mse.merge(&o.steady_mse);
        self.steady_trace.merge(&o.steady_trace);
        self.steady_nees.merge(&o.steady_nees);
        self.steady_messages.merge(&o.steady_messages);
        self.per_trial.extend_from_slice(&o.per_trial);
        self.per_trial_nees.extend_from_slice(&o.per_trial_nees);
        self.diverged += o.diverged;
        for (a, b) in self.ess_min.iter_mut().zip(&o.ess_min) {
            *a = a.min(*b);
        }
        self.has_ess |= o.has_ess;
        self.nees_hist.merge(&o.nees_hist);
        if let Some(f) = &o.failure {
            self.record_failure(f.clone());
        }
        if self.sensors.len() < o.sensors.len() {
            self.sensors.resize(o.sensors.len(), [0; 2]);
        }
        for (a, b) in self.sensors.iter_mut().zip(&o.sensors) {
            a[0] += b[0];
            a[1] += b[1];
        }
        self.merge_peaks(&o.reading_peaks);
        self.add_nodes(&o.nodes);
        if self.estimators.len() < o.estimators.len() {
            self.estimators
                .resize(o.estimators.len(), EstimatorStat::default());
        }
        for (a, b) in self.estimators.iter_mut().zip(&o.estimators) {
            a.mse.merge(&b.mse);
            a.nees.merge(&b.nees);
        }
        self.disagreement.merge(&o.disagreement);
        if !o.hops.is_empty() {
            if self.hops.is_empty() {
                self.hops = vec![[0; 2]; self.steps];
            }
            for (a, b) in self.hops.iter_mut().zip(&o.hops) {
                a[0] += b[0];
                a[1] += b[1];
            }
        }
        if !o.link.is_empty() {
            if self.link.is_empty() {
                self.link = vec![[0; LINK_FIELDS]; self.steps];
            }
            for (a, b) in self.link.iter_mut().zip(&o.link) {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
            }
        }
    }

    /// Sum of entry `field` at step index `s` (0-based).
    pub fn at(&self, s: usize, field: usize) -> f64 {
        self.per_step[s * self.layout().width() + field]
    }

    /// Mean over trials and its standard error of entry `field` at step index `s` (0-based).
    pub fn mean_se_at(&self, s: usize, field: usize) -> (f64, f64) {
        let i = s * self.layout().width() + field;
        TrialStat {
            sum: self.per_step[i],
            sum_sq: self.per_step_sq[i],
        }
        .mean_se(self.trials)
    }
}

impl TrialState<'_> {
    /// Records step `k` (1-based): truth, fused estimate and the traffic of the step.
    /// NEES needs a positive definite covariance; a scheme whose covariance is not is a
    /// defect that we report rather than hide.
    pub fn record(
        &mut self,
        sums: &mut Sums,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        sums.add_senders(&traffic, 1);
        self.record_inner(sums, k, truth, est, None, traffic)
    }

    /// [`TrialState::record`] with the Cholesky factor of the estimate's covariance from
    /// [`crate::linalg::fixed::nees_factor`] (the same factor record would compute, so the
    /// same NEES): a covariance shared by all trials is factored once, not once per trial.
    pub fn record_factored(
        &mut self,
        sums: &mut Sums,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        factor: &[f64],
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        sums.add_senders(&traffic, 1);
        self.record_inner(sums, k, truth, est, Some(factor), traffic)
    }

    fn record_inner(
        &mut self,
        sums: &mut Sums,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        factor: Option<&[f64]>,
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        let n = est.mean.len();
        assert_eq!(truth.len(), n, "record: truth and estimate dimensions");
        // err = mean - truth (nalgebra's `-`, element by element): on the stack up to
        // STACK_WIDTH components (no allocation per trial), else in the trial's buffer.
        let mut err_stack = [0.0; STACK_WIDTH];
        // The trial's buffer is taken (and put back below) only when the stack is too small.
        let mut err_heap = Vector::zeros(0);
        let err: &mut [f64] = if n <= STACK_WIDTH {
            &mut err_stack[..n]
        } else {
            err_heap = std::mem::replace(&mut self.err, err_heap);
            if err_heap.len() != n {
                err_heap = Vector::zeros(n);
            }
            err_heap.as_mut_slice()
        };
        for ((e, m), t) in err
            .iter_mut()
            .zip(est.mean.as_slice())
            .zip(truth.as_slice())
        {
            *e = m - t;
        }
        let err: &[f64] = err;
        let link = link_counts(&traffic);
        if link.iter().any(|&c| c > 0) {
            sums.add_link(k, link);
        }
        let recorded = self.nees(err, est, factor).map(|(nees, degenerate)| {
            // The traffic of a step is usually the last step's: its conversions are kept.
            if self.traffic.0 != traffic {
                self.traffic = (traffic, traffic_counts(traffic));
            }
            let counts = self.traffic.1;
            self.accumulate(sums, k, err, nees, degenerate, trace(&est.cov), counts);
        });
        if n > STACK_WIDTH {
            self.err = err_heap;
        }
        recorded
    }

    /// NEES of the error `err` of `est` (by `factor`, the factor of its covariance, when
    /// given), and whether the covariance was degenerate.
    fn nees(
        &mut self,
        err: &[f64],
        est: &Gaussian,
        factor: Option<&[f64]>,
    ) -> Result<(f64, bool), crate::linalg::LinalgError> {
        let factored = factor.and_then(|f| crate::linalg::fixed::mahalanobis_sq_factored(err, f));
        let nees_direct = match factored {
            Some(v) => Ok(v),
            None => nees_buffered(err, &est.cov, &mut self.white, &mut self.chol_buf),
        };
        // A particle cloud can collapse onto one particle: its covariance is then singular.
        // NEES is computed with a tiny relative jitter (so the claim of certainty shows as a
        // huge NEES) and the step is counted as degenerate; NaN/inf remain errors.
        match nees_direct {
            Ok(v) => Ok((v, false)),
            Err(crate::linalg::LinalgError::NotPositiveDefinite) => {
                let n = est.cov.nrows();
                let scale = (est.cov.trace().abs() / n as f64).max(1e-12);
                let jittered = &est.cov + crate::linalg::Matrix::identity(n, n) * (1e-9 * scale);
                Ok((
                    mahalanobis_sq(&Vector::from_column_slice(err), &jittered)?,
                    true,
                ))
            }
            Err(e) => Err(e),
        }
    }

    /// Adds step `k`'s values into the sums and this trial's running sums: the error `err`,
    /// its NEES, whether the covariance was degenerate, the covariance's trace and the
    /// traffic's counts as floats.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn accumulate(
        &mut self,
        sums: &mut Sums,
        k: usize,
        err: &[f64],
        nees: f64,
        degenerate: bool,
        trace: f64,
        counts: [f64; 4],
    ) {
        let step = self.error_step(err, nees, degenerate, trace);
        self.accumulate_step(
            sums,
            k,
            &step,
            |idx| idx.iter().map(|&j| err[j] * err[j]).sum::<f64>(),
            counts,
        );
    }

    /// The step values of one estimate: its error `err` (the squared error summed), its
    /// NEES and whether that is within the bounds, whether the covariance was degenerate, its
    /// trace.
    #[inline(always)]
    fn error_step(&self, err: &[f64], nees: f64, degenerate: bool, trace: f64) -> StepValues {
        let flag = |b: bool| f64::from(u8::from(b));
        StepValues {
            total: err.iter().map(|e| e * e).sum(),
            nees,
            degenerate: flag(degenerate),
            covered: [
                flag(nees <= self.nees_bound),
                flag(nees <= self.nees_bound_95),
            ],
            trace,
        }
    }

    /// Adds step `k`'s values (`step`; `group_se(idx)`: the squared error of the components
    /// `idx`) into the sums and this trial's running sums.
    #[inline(always)]
    fn accumulate_step(
        &mut self,
        sums: &mut Sums,
        k: usize,
        step: &StepValues,
        group_se: impl Fn(&[usize]) -> f64,
        counts: [f64; 4],
    ) {
        let w = sums.layout().width();
        let mut stack = [0.0; STACK_WIDTH];
        let mut heap;
        let vals: &mut [f64] = if w <= STACK_WIDTH {
            &mut stack
        } else {
            heap = vec![0.0; w];
            &mut heap
        };
        self.step_values(sums, k, step, group_se, counts, vals);
        // Every per-(trial, step) value goes into the sum and the sum of squares.
        let row = &mut sums.per_step[(k - 1) * w..k * w];
        let row_sq = &mut sums.per_step_sq[(k - 1) * w..k * w];
        for f in 0..w {
            let v = vals[f];
            row[f] += v;
            row_sq[f] += v * v;
        }
    }

    /// Records the fusion center's effective sample size after step `k` (1-based), if it has
    /// one (particle filters; see [`crate::scheme::FusionCenter::ess`]).
    pub fn record_ess(&mut self, sums: &mut Sums, k: usize, ess: Option<f64>) {
        let Some(ess) = ess else {
            return;
        };
        let w = sums.layout().width();
        sums.per_step[(k - 1) * w + Layout::ESS] += ess;
        sums.per_step_sq[(k - 1) * w + Layout::ESS] += ess * ess;
        self.run_acc[Layout::ESS] += ess;
        let m = &mut sums.ess_min[k - 1];
        *m = m.min(ess);
        sums.has_ess = true;
    }

    /// Adds the pending steady-state NEES / n values to the histogram.
    fn flush_nees(&mut self, sums: &mut Sums) {
        let n = sums.state_dim.max(1) as f64;
        sums.nees_hist
            .add_divided(&self.pending_nees[..self.pending], n);
        self.pending = 0;
    }

    /// Closes the trial: its steady-state averages, per-trial rows and histogram counts go
    /// into `sums` (a trial that is not finished adds only its per-step sums).
    pub fn finish(mut self, sums: &mut Sums) {
        self.close(sums);
    }

    /// Back to the state of a new trial of `sums` (as [`Sums::trial_state`] makes it, for
    /// the same groups and steady-state start), keeping this one's storage: a batch's trial
    /// states are reused from block to block instead of made (and moved) anew.
    pub fn restart(&mut self, sums: &Sums) {
        let [nees_bound, nees_bound_95, divergence_bound] = nees_bounds(sums.state_dim);
        self.nees_bound = nees_bound;
        self.nees_bound_95 = nees_bound_95;
        self.divergence_bound = divergence_bound;
        self.run = 0;
        self.diverged = false;
        self.acc = [0.0; 4];
        self.group_acc.fill(0.0);
        let width = sums.layout().width();
        if self.run_acc.len() == width {
            self.run_acc.fill(0.0);
        } else {
            self.run_acc = Row::zeros(width);
        }
        self.count = 0;
        self.pending = 0;
        if let Some(e) = &mut self.estimators {
            e.acc.clear();
            e.disagreement = 0.0;
        }
    }

    /// [`TrialState::finish`] in place (the state is then spent until
    /// [`TrialState::restart`]).
    pub fn close(&mut self, sums: &mut Sums) {
        self.flush_nees(sums);
        let c = self.count.max(1) as f64;
        sums.trials += 1;
        sums.steady_mse.add(self.acc[0] / c);
        sums.steady_trace.add(self.acc[1] / c);
        sums.steady_nees.add(self.acc[2] / c);
        sums.per_trial_nees.push(self.acc[2] / c);
        sums.diverged += usize::from(self.diverged);
        sums.steady_messages.add(self.acc[3] / c);
        sums.per_trial.push(self.acc[0] / c);
        sums.per_trial.extend(self.group_acc.iter().map(|v| v / c));
        let steps = sums.steps.max(1) as f64;
        for (stat, v) in sums.whole_run.iter_mut().zip(self.run_acc.iter()) {
            stat.add(v / steps);
        }
        if let Some(e) = &self.estimators {
            if sums.estimators.len() < e.acc.len() {
                sums.estimators
                    .resize(e.acc.len(), EstimatorStat::default());
            }
            for (stat, [se, nees]) in sums.estimators.iter_mut().zip(&e.acc) {
                stat.mse.add(se / c);
                stat.nees.add(nees / c);
            }
            sums.disagreement.add(e.disagreement / c);
        }
    }
}

impl TrialObserver<'_> {
    /// Records step `k` (1-based): truth, fused estimate and the traffic of the step
    /// ([`TrialState::record`]).
    pub fn record(
        &mut self,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        self.state.record(self.sums, k, truth, est, traffic)
    }

    /// [`TrialState::record_factored`].
    pub fn record_factored(
        &mut self,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        factor: &[f64],
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        self.state
            .record_factored(self.sums, k, truth, est, factor, traffic)
    }

    /// [`TrialState::record_estimators`].
    pub fn record_estimators(
        &mut self,
        k: usize,
        truth: &Vector,
        estimates: (&[&Gaussian], Option<&[f64]>),
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        self.state
            .record_estimators(self.sums, k, truth, estimates, traffic)
    }

    /// [`TrialState::record_ess`].
    pub fn record_ess(&mut self, k: usize, ess: Option<f64>) {
        self.state.record_ess(self.sums, k, ess);
    }

    /// [`Sums::add_nodes`] and the hops of step `k`: a step's counters of a multi-hop
    /// network's nodes (nothing on a star).
    pub fn record_nodes(
        &mut self,
        k: usize,
        nodes: &[crate::network::topology::tally::NodeCounts],
    ) {
        if !nodes.is_empty() {
            self.sums.add_nodes(nodes);
            self.sums.add_hops(k, nodes);
        }
    }

    /// Closes the trial.
    pub fn finish(self) {
        self.state.finish(self.sums);
    }
}

/// A step's traffic counts as the floats its fields add.
fn traffic_counts(traffic: Traffic) -> [f64; 4] {
    [
        traffic.messages as f64,
        traffic.bits as f64,
        traffic.frame_bits as f64,
        traffic.downlink_bits as f64,
    ]
}

/// `p.trace()` (the diagonal summed from +0 in order) on the slice of a square `p`.
fn trace(p: &crate::linalg::Matrix) -> f64 {
    let n = p.nrows();
    if p.ncols() != n {
        return p.trace(); // nalgebra's message for a non-square matrix
    }
    let s = p.as_slice();
    let mut t = 0.0;
    for i in 0..n {
        t += s[i * n + i];
    }
    t
}
