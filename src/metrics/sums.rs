//! Metrics as mergeable sums: per time step and per trial, so that runs split across threads,
//! processes or machines merge exactly (in a fixed order, for bit-identical results).
use crate::filter::Gaussian;
use crate::linalg::{mahalanobis_sq, Vector};
use crate::network::Traffic;
use multiversion::multiversion;

/// Layout of one step's row of sums: one squared error per state group, then the fixed fields.
#[derive(Debug, Clone, Copy)]
pub struct Layout {
    pub groups: usize,
}

impl Layout {
    pub const TOTAL_SE: usize = 0;
    pub const NEES: usize = 1;
    pub const TRACE: usize = 2;
    pub const MESSAGES: usize = 3;
    pub const BITS: usize = 4;
    pub const FRAME_BITS: usize = 5;
    pub const DOWNLINK_BITS: usize = 6;
    /// Steps whose fused covariance was not positive definite (a collapsed particle cloud).
    pub const DEGENERATE: usize = 7;
    /// Steps whose NEES was below the 99% quantile of chi-square with n degrees of freedom
    /// (a robust consistency check: 0.99 of the steps for a consistent filter, whatever a
    /// few collapsed particle clouds do to the mean NEES).
    pub const NEES_COVERED: usize = 8;
    /// Effective sample size of the particle weights (particle-filter centers only).
    pub const ESS: usize = 9;
    /// Steps whose NEES was below the 95% quantile of chi-square with n degrees of freedom.
    pub const NEES_COVERED_95: usize = 10;
    pub const FIXED: usize = 11;

    /// Entries per step.
    pub fn width(&self) -> usize {
        self.groups + Self::FIXED
    }
    /// Index of group g's squared error.
    pub fn group(&self, g: usize) -> usize {
        Self::FIXED + g
    }
}

/// Row widths (groups + fixed fields) whose step values and trial sums are kept on the stack.
const STACK_WIDTH: usize = 16;

/// A row of zeros of a given length, on the stack up to [`STACK_WIDTH`]: a trial's running
/// sums without a heap allocation per trial.
enum Row {
    Stack([f64; STACK_WIDTH], usize),
    Heap(Vec<f64>),
}

impl Row {
    fn zeros(len: usize) -> Self {
        if len <= STACK_WIDTH {
            Row::Stack([0.0; STACK_WIDTH], len)
        } else {
            Row::Heap(vec![0.0; len])
        }
    }
}

impl std::ops::Deref for Row {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        match self {
            Row::Stack(a, n) => &a[..*n],
            Row::Heap(v) => v,
        }
    }
}

impl std::ops::DerefMut for Row {
    fn deref_mut(&mut self) -> &mut [f64] {
        match self {
            Row::Stack(a, n) => &mut a[..*n],
            Row::Heap(v) => v,
        }
    }
}

/// Per-trial steady-state quantities whose spread across trials gives standard errors.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrialStat {
    pub sum: f64,
    pub sum_sq: f64,
}

impl TrialStat {
    fn add(&mut self, v: f64) {
        self.sum += v;
        self.sum_sq += v * v;
    }
    fn merge(&mut self, o: &TrialStat) {
        self.sum += o.sum;
        self.sum_sq += o.sum_sq;
    }
    /// Mean and standard error of the mean over `n` trials.
    pub fn mean_se(&self, n: usize) -> (f64, f64) {
        let nf = n as f64;
        let mean = self.sum / nf;
        if n < 2 {
            return (mean, f64::NAN);
        }
        let var = (self.sum_sq - nf * mean * mean) / (nf - 1.0);
        // An overflowed sum of squares gives no standard error: NaN (reported as not finite),
        // never a reassuring 0 beside a mean of 1e300.
        if !var.is_finite() || !mean.is_finite() {
            return (mean, f64::NAN);
        }
        (mean, (var.max(0.0) / nf).sqrt())
    }
}

/// The divergence rule: a trial has diverged when its NEES exceeds the chi-square(n) 99.9%
/// quantile for this many consecutive steps, or when any step's squared error or NEES is not
/// finite. A consistent filter does so with probability about 1e-30 per window of steps.
pub const DIVERGENCE_RUN: usize = 10;
/// Upper tail probability of the divergence threshold (the 99.9% quantile).
pub const DIVERGENCE_TAIL: f64 = 1e-3;

/// A fixed log-spaced histogram of steady-state NEES / n: exact counts that merge by addition,
/// from which the median is read by interpolating inside the bin that holds it (50 bins per
/// decade from 1e-4 to 1e12; a few tenths of a percent for a smooth distribution).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct NeesHistogram {
    /// Bin 0: below 1e-4; bin BINS + 1: at or above 1e12, or not finite.
    pub counts: Vec<u64>,
    /// Bins lo..hi hold every nonzero count (a block's few hundred values touch a fraction of
    /// the 802 bins, and merging and clearing visit only these). Not stored: a histogram read
    /// from a file is taken as touching every bin.
    #[serde(skip, default = "NeesHistogram::every_bin")]
    touched: (usize, usize),
}

/// Equal counts (which bins were touched is bookkeeping).
impl PartialEq for NeesHistogram {
    fn eq(&self, other: &Self) -> bool {
        self.counts == other.counts
    }
}

impl NeesHistogram {
    const LO: f64 = -4.0;
    const PER_DECADE: f64 = 50.0;
    const BINS: usize = 800;

    fn new() -> Self {
        Self {
            counts: vec![0; Self::BINS + 2],
            touched: (0, 0),
        }
    }

    fn every_bin() -> (usize, usize) {
        (0, Self::BINS + 2)
    }

    /// Widens the touched range to hold bins lo..hi.
    fn touch(&mut self, lo: usize, hi: usize) {
        let (a, b) = self.touched;
        self.touched = if a == b {
            (lo, hi)
        } else {
            (a.min(lo), b.max(hi))
        };
    }

    #[cfg(test)]
    fn add(&mut self, v: f64) {
        let b = Self::bin(v);
        self.counts[b] += 1;
        self.touch(b, b + 1);
    }

    /// Adds `v / divisor` for every `v` of `values` (the table looked up and the touched
    /// range widened once for all).
    fn add_divided(&mut self, values: &[f64], divisor: f64) {
        let (lo, hi) = count_divided(&mut self.counts, log_table(), values, divisor);
        if lo < hi {
            self.touch(lo, hi);
        }
    }

    /// Back to no counts, keeping the allocation.
    fn clear(&mut self) {
        let (lo, hi) = self.touched;
        self.counts[lo..hi].fill(0);
        self.touched = (0, 0);
    }

    /// The bin of `v`: 0 below 1e-4 (and for v <= 0), `BINS + 1` at or above 1e12 (and for
    /// anything not finite), else `1 + floor((log10 v - LO) * PER_DECADE)` with the library's
    /// log10. That log10 costs more than the rest of a step's bookkeeping, so the bin is first
    /// read from a cheap approximation of t = (log10 v - LO) * PER_DECADE that is within
    /// [`APPROX_T_ERROR`] of it; only when t is that close to a bin edge (a few in a million
    /// values) is the library's log10 called. Either way the bin is the one `exact_bin` gives.
    #[cfg(test)]
    fn bin(v: f64) -> usize {
        Self::bin_in(log_table(), v)
    }

    /// [`NeesHistogram::bin`] with the table of [`approx_t`] at hand.
    #[inline(always)]
    fn bin_in(table: &LogTable, v: f64) -> usize {
        if let Some(t) = approx_t_in(table, v) {
            if (0.0..Self::BINS as f64).contains(&t) {
                // t's integer part i by truncation (t >= 0; no call into libm), and its
                // fraction t - i exactly (Sterbenz). A fraction at least APPROX_T_ERROR from
                // both edges puts the exact t in [i, i + 1) too: bin 1 + i.
                let i = t as i32;
                let frac = t - f64::from(i);
                if (APPROX_T_ERROR..1.0 - APPROX_T_ERROR).contains(&frac) {
                    return 1 + i as usize;
                }
            } else if t + APPROX_T_ERROR < 0.0 {
                return 0;
            } else if t - APPROX_T_ERROR >= Self::BINS as f64 {
                return Self::BINS + 1;
            }
        }
        Self::exact_bin(v)
    }

    /// The bin by the definition (see [`NeesHistogram::bin`]).
    fn exact_bin(v: f64) -> usize {
        if !v.is_finite() {
            Self::BINS + 1
        } else if v <= 0.0 {
            0
        } else {
            let t = (v.log10() - Self::LO) * Self::PER_DECADE;
            if t < 0.0 {
                0
            } else if t >= Self::BINS as f64 {
                Self::BINS + 1
            } else {
                1 + t as usize
            }
        }
    }

    fn merge(&mut self, o: &NeesHistogram) {
        let (lo, hi) = o.touched;
        let hi = hi.min(o.counts.len()).min(self.counts.len());
        if lo >= hi {
            return;
        }
        for (a, b) in self.counts[lo..hi].iter_mut().zip(&o.counts[lo..hi]) {
            *a += b;
        }
        self.touch(lo, hi);
    }

    /// Number of values added.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// The median, interpolated log-linearly inside the bin that holds it; `None` when empty,
    /// the bin edge when it lies in the underflow or overflow bin (infinite for overflow).
    pub fn median(&self) -> Option<f64> {
        let total = self.total();
        if total == 0 {
            return None;
        }
        let half = total as f64 / 2.0;
        let mut acc = 0.0;
        for (b, &c) in self.counts.iter().enumerate() {
            let next = acc + c as f64;
            if next >= half && c > 0 {
                if b == 0 {
                    return Some(10f64.powf(Self::LO));
                }
                if b == Self::BINS + 1 {
                    return Some(f64::INFINITY);
                }
                let frac = (half - acc) / c as f64;
                return Some(10f64.powf(Self::LO + (b as f64 - 1.0 + frac) / Self::PER_DECADE));
            }
            acc = next;
        }
        None
    }
}

/// [`NeesHistogram::add_divided`]'s counting: the bin of every `v / divisor` counted, and the
/// range of bins counted in (empty: `lo >= hi`). Compiled also for AVX2 and picked at run
/// time: the same IEEE operations (no FMA contraction), hence the same bins.
#[multiversion(targets("x86_64+avx2"))]
fn count_divided(
    counts: &mut [u64],
    table: &LogTable,
    values: &[f64],
    divisor: f64,
) -> (usize, usize) {
    let (mut lo, mut hi) = (usize::MAX, 0);
    for &v in values {
        let b = NeesHistogram::bin_in(table, v / divisor);
        counts[b] += 1;
        lo = lo.min(b);
        hi = hi.max(b + 1);
    }
    (lo, hi)
}

/// The chi-square(n) 99%, 95% and 99.9% quantiles that NEES is compared with: computed once
/// per state dimension for the whole process (an iterative inversion, once per trial and
/// variant before), the same numbers.
fn nees_bounds(n: usize) -> [f64; 3] {
    use std::sync::OnceLock;
    const CACHED: usize = 32;
    static BOUNDS: [OnceLock<[f64; 3]>; CACHED] = [const { OnceLock::new() }; CACHED];
    let compute = || {
        let q =
            |tail: f64| crate::stats::chi2::upper_quantile(n as f64, tail).unwrap_or(f64::INFINITY);
        [q(0.01), q(0.05), q(DIVERGENCE_TAIL)]
    };
    match BOUNDS.get(n) {
        Some(cell) => *cell.get_or_init(compute),
        None => compute(),
    }
}

/// A bound on |approx_t(v) - t(v)|, where t(v) = (log10 v - LO) * PER_DECADE as
/// [`NeesHistogram::exact_bin`] computes it. The approximation's own error is below 1e-8 (see
/// [`approx_t`]); the library's log10 and the two roundings of t add a few 1e-13 at most.
const APPROX_T_ERROR: f64 = 1e-6;

/// Entries of the table of log10 over the leading mantissa bits.
const LOG_TABLE_BITS: u32 = 8;

/// Per leading-mantissa cell: 1/c and log10(c) of its centre c (see [`log_table`]).
type LogTable = [[f64; 2]; 1 << LOG_TABLE_BITS];

/// Per leading-mantissa cell i (mantissa m in [1 + i/256, 1 + (i+1)/256)): the cell's centre
/// c, 1/c and log10(c).
fn log_table() -> &'static LogTable {
    use std::sync::OnceLock;
    static TABLE: OnceLock<LogTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        let cells = (1u32 << LOG_TABLE_BITS) as f64;
        std::array::from_fn(|i| {
            let c = 1.0 + (i as f64 + 0.5) / cells;
            [1.0 / c, c.log10()]
        })
    })
}

/// (log10 v - LO) * PER_DECADE within 1e-8, for a positive normal v (`None` otherwise):
/// v = 2^e m with m in [1, 2); log10 v = e log10 2 + log10 c + log10(m / c) for the centre c
/// of m's table cell, the last term by three terms of the series of ln(1 + d) / ln 10 with
/// |d| < 1/512 (the first omitted term is below 1e-11, times 50 per decade below 1e-9; the
/// rounding of a dozen operations on numbers below 1000 adds about 1e-13).
#[cfg(test)]
fn approx_t(v: f64) -> Option<f64> {
    approx_t_in(log_table(), v)
}

/// [`approx_t`] with its table at hand.
#[inline(always)]
fn approx_t_in(table: &LogTable, v: f64) -> Option<f64> {
    if !(v.is_normal() && v > 0.0) {
        return None;
    }
    let bits = v.to_bits();
    let e = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let cell = ((bits >> (52 - LOG_TABLE_BITS)) & ((1 << LOG_TABLE_BITS) - 1)) as usize;
    let m = f64::from_bits((bits & ((1u64 << 52) - 1)) | (1023u64 << 52));
    let [inv_c, log_c] = table[cell];
    let d = m * inv_c - 1.0;
    let ln1p = d * (1.0 - d * (0.5 - d * (1.0 / 3.0)));
    let log10 = e as f64 * std::f64::consts::LOG10_2 + log_c + ln1p * std::f64::consts::LOG10_E;
    Some((log10 - NeesHistogram::LO) * NeesHistogram::PER_DECADE)
}

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
        let layout = sums.layout();
        let w = layout.width();
        let total: f64 = err.iter().map(|e| e * e).sum();
        let flag = |b: bool| f64::from(u8::from(b));
        // This step's value of every field, at its layout index. ESS is left at +0, which adds
        // nothing to any of its sums (they start at +0 and only ever add ESS values >= 0); it
        // is recorded by `record_ess`.
        let mut stack = [0.0; STACK_WIDTH];
        let mut heap;
        let vals: &mut [f64] = if w <= STACK_WIDTH {
            &mut stack[..w]
        } else {
            heap = vec![0.0; w];
            &mut heap
        };
        let [messages, bits, frame_bits, downlink_bits] = counts;
        vals[Layout::TOTAL_SE] = total;
        vals[Layout::NEES] = nees;
        vals[Layout::TRACE] = trace;
        vals[Layout::MESSAGES] = messages;
        vals[Layout::BITS] = bits;
        vals[Layout::FRAME_BITS] = frame_bits;
        vals[Layout::DOWNLINK_BITS] = downlink_bits;
        vals[Layout::DEGENERATE] = flag(degenerate);
        vals[Layout::NEES_COVERED] = flag(nees <= self.nees_bound);
        vals[Layout::NEES_COVERED_95] = flag(nees <= self.nees_bound_95);
        let steady = k >= self.steady_from;
        for (g, (_, idx)) in self.groups.iter().enumerate() {
            let se = idx.iter().map(|&j| err[j] * err[j]).sum::<f64>();
            vals[layout.group(g)] = se;
            if steady {
                self.group_acc[g] += se;
            }
        }
        // Every per-(trial, step) value goes into the sum, the sum of squares and this
        // trial's whole-run sum.
        let row = &mut sums.per_step[(k - 1) * w..k * w];
        let row_sq = &mut sums.per_step_sq[(k - 1) * w..k * w];
        let run = &mut self.run_acc[..w];
        for f in 0..w {
            let v = vals[f];
            row[f] += v;
            row_sq[f] += v * v;
            run[f] += v;
        }
        // Divergence: a run of NEES beyond the 99.9% quantile, or anything not finite.
        if !(total.is_finite() && nees.is_finite()) {
            self.diverged = true;
        }
        if nees > self.divergence_bound || nees.is_nan() {
            self.run += 1;
            if self.run >= DIVERGENCE_RUN {
                self.diverged = true;
            }
        } else {
            self.run = 0;
        }
        if steady {
            if self.pending == PENDING_NEES {
                self.flush_nees(sums);
            }
            self.pending_nees[self.pending] = nees;
            self.pending += 1;
            self.acc[0] += total;
            self.acc[1] += trace;
            self.acc[2] += nees;
            self.acc[3] += messages;
            self.count += 1;
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

    /// [`TrialState::record_ess`].
    pub fn record_ess(&mut self, k: usize, ess: Option<f64>) {
        self.state.record_ess(self.sums, k, ess);
    }

    /// Closes the trial.
    pub fn finish(self) {
        self.state.finish(self.sums);
    }
}

/// Records step `k` of the trials of a batch run in lockstep whose estimates share one
/// covariance: trial j (state `states[j]`, truth `truths[j][k - 1]`) has the mean
/// `means[j * n..(j + 1) * n]`; `shared` holds the covariance (its mean is work space),
/// `factor` its Cholesky factor. The same numbers as [`TrialState::record_factored`] of
/// each trial in order; what no trial changes (the trace, the traffic's counts) is read
/// once per step.
/// Compiled also for AVX2 and picked at run time: the same IEEE operations (no FMA
/// contraction), so the same sums on every x86-64 machine.
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx2"))]
pub fn record_shared(
    states: &mut [TrialState],
    sums: &mut Sums,
    k: usize,
    truths: &[&[Vector]],
    means: &[f64],
    shared: &mut Gaussian,
    factor: Option<&[f64]>,
    traffic: Traffic,
) -> Result<(), crate::linalg::LinalgError> {
    /// Trials whose errors and NEES are computed before any is accumulated: their
    /// Cholesky solves (two dependent divisions each) then overlap.
    const GROUP: usize = 4;
    let n = shared.mean.len();
    let trace = trace(&shared.cov);
    let counts = traffic_counts(traffic);
    let trials = states.iter_mut().zip(truths).zip(means.chunks_exact(n));
    let mut trials = trials.peekable();
    while trials.peek().is_some() {
        let group: [_; GROUP] = std::array::from_fn(|_| trials.next());
        let mut errs = [[0.0; STACK_WIDTH]; GROUP];
        let mut nees = [None; GROUP];
        for ((trial, err), nees) in group.iter().zip(&mut errs).zip(&mut nees) {
            let Some(((_, truth), mean)) = trial else {
                break;
            };
            let truth = &truth[k - 1];
            assert_eq!(truth.len(), n, "record: truth and estimate dimensions");
            if let Some(f) = factor.filter(|_| n <= STACK_WIDTH) {
                let err = &mut err[..n];
                for ((e, m), t) in err.iter_mut().zip(*mean).zip(truth.as_slice()) {
                    *e = m - t;
                }
                *nees = crate::linalg::fixed::mahalanobis_sq_factored(err, f);
            }
        }
        for ((trial, err), nees) in group.into_iter().zip(&errs).zip(nees) {
            let Some(((state, truth), mean)) = trial else {
                break;
            };
            match nees {
                Some(nees) => state.accumulate(sums, k, &err[..n], nees, false, trace, counts),
                // Not factored: the general record (which also reports what is wrong).
                None => {
                    shared.mean.as_mut_slice().copy_from_slice(mean);
                    state.record_inner(sums, k, &truth[k - 1], shared, factor, traffic)?;
                }
            }
        }
    }
    Ok(())
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

/// [`mahalanobis_sq`] with the factorization done in `buf` and the solve in `white`: the same
/// checks (square, finite), the same Cholesky factorization of a copy of `p` and the same
/// triangular solve, hence the same number, without allocating.
fn nees_buffered(
    e: &[f64],
    p: &crate::linalg::Matrix,
    white: &mut Vector,
    buf: &mut Option<crate::linalg::Matrix>,
) -> Result<f64, crate::linalg::LinalgError> {
    use crate::linalg::LinalgError;
    if p.nrows() != p.ncols() {
        return Err(LinalgError::NotSquare {
            rows: p.nrows(),
            cols: p.ncols(),
        });
    }
    if p.as_slice().iter().any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    // Dimensions 1..=6: the same factorization, solve and sum in fixed-size buffers.
    if let Some(r) = crate::linalg::fixed::mahalanobis_sq_small_slice(e, p) {
        return r.ok_or(LinalgError::NotPositiveDefinite);
    }
    let mut m = match buf.take() {
        Some(m) if m.shape() == p.shape() => m,
        _ => crate::linalg::Matrix::zeros(p.nrows(), p.ncols()),
    };
    m.copy_from(p);
    let chol = nalgebra::Cholesky::new(m).ok_or(LinalgError::NotPositiveDefinite)?;
    if white.len() != e.len() {
        *white = Vector::zeros(e.len());
    }
    white.as_mut_slice().copy_from_slice(e);
    // Only the lower triangle is read: the dirty factor solves as `chol.l()` does.
    let solved = chol.l_dirty().solve_lower_triangular_mut(white);
    *buf = Some(chol.unpack_dirty());
    if !solved {
        return Err(LinalgError::NotPositiveDefinite);
    }
    Ok(white.norm_squared())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Matrix;

    #[test]
    fn histograms_merge_and_clear_only_what_they_touched_with_the_counts_of_a_full_pass() {
        let fill = |values: &[f64]| {
            let mut h = NeesHistogram::new();
            values.iter().for_each(|&v| h.add(v));
            h
        };
        let a = fill(&[1e-3, 0.5, 0.5, 2.0]);
        let b = fill(&[1e6, 3.0, f64::NAN, 1e-9]);
        // Values added divided, all at once: the counts and the touched range of one by one.
        let mut d = NeesHistogram::new();
        d.add_divided(&[2e-3, 1.0, 1.0, 4.0], 2.0);
        assert_eq!((&d.counts, d.touched), (&a.counts, a.touched));
        d.add_divided(&[], 2.0);
        assert_eq!(d.touched, a.touched);
        let mut m = NeesHistogram::new();
        m.merge(&a);
        m.merge(&b);
        let full: Vec<u64> = a.counts.iter().zip(&b.counts).map(|(x, y)| x + y).collect();
        assert_eq!(m.counts, full);
        assert_eq!(m.total(), 8);
        // One read back from a file touches every bin.
        let back: NeesHistogram =
            serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
        assert_eq!(back.touched, NeesHistogram::every_bin());
        let mut twice = back.clone();
        twice.merge(&back);
        assert_eq!(twice.total(), 16);
        twice.clear();
        assert_eq!(twice, NeesHistogram::new());
        m.clear();
        assert_eq!(m.counts, NeesHistogram::new().counts);
    }

    #[test]
    fn the_fast_histogram_bin_is_the_bin_of_the_library_log10() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
        let mut worst: f64 = 0.0;
        let mut check = |v: f64| {
            assert_eq!(
                NeesHistogram::bin(v),
                NeesHistogram::exact_bin(v),
                "value {v:e}"
            );
            if let Some(t) = approx_t(v) {
                let exact = (v.log10() - NeesHistogram::LO) * NeesHistogram::PER_DECADE;
                worst = worst.max((t - exact).abs());
            }
        };
        // Log-uniform over 1e-8 .. 1e16 (beyond both ends of the histogram).
        for _ in 0..400_000 {
            let v = 10f64.powf(rng.random_range(-8.0..16.0));
            check(v);
        }
        // Every bin edge and its floating-point neighbours, where the cheap value cannot
        // decide and the library's log10 must.
        for b in 0..=NeesHistogram::BINS + 1 {
            let edge = 10f64.powf(NeesHistogram::LO + b as f64 / NeesHistogram::PER_DECADE);
            let mut v = edge;
            for _ in 0..4 {
                v = v.next_down();
            }
            for _ in 0..9 {
                check(v);
                v = v.next_up();
            }
        }
        // Around the margin: t a few APPROX_T_ERROR from every edge, where the fast path
        // starts or stops deciding.
        for b in 0..=NeesHistogram::BINS + 1 {
            for d in [-3.0, -1.0, -0.5, 0.5, 1.0, 3.0] {
                let t = b as f64 + d * APPROX_T_ERROR;
                check(10f64.powf(NeesHistogram::LO + t / NeesHistogram::PER_DECADE));
            }
        }
        for v in [
            0.0,
            -0.0,
            -1.0,
            f64::MIN_POSITIVE,
            f64::MIN_POSITIVE / 4.0,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            1.0,
            1e-4,
            1e12,
        ] {
            check(v);
        }
        assert!(worst < 1e-8, "approximation error {worst:e}");
        assert!(worst < APPROX_T_ERROR / 100.0);
    }

    #[test]
    fn records_hand_computed_errors_and_merges() {
        let groups = vec![("a".to_string(), vec![0]), ("b".to_string(), vec![1])];
        let mut s = Sums::new(2, 2, 2);
        let truth = Vector::from_vec(vec![1.0, 2.0]);
        let est = Gaussian::new(
            Vector::from_vec(vec![2.0, 4.0]),
            Matrix::from_diagonal(&Vector::from_vec(vec![1.0, 4.0])),
        );
        let mut t = s.trial(&groups, 2);
        let traffic = Traffic {
            messages: 3,
            bits: 96,
            frame_bits: 400,
            downlink_bits: 64,
        };
        t.record(1, &truth, &est, traffic).unwrap();
        t.record(2, &truth, &est, traffic).unwrap();
        t.finish();
        let l = s.layout();
        assert_eq!(s.at(0, l.group(0)), 1.0);
        assert_eq!(s.at(0, l.group(1)), 4.0);
        assert_eq!(s.at(1, Layout::TOTAL_SE), 5.0);
        assert_eq!(s.at(1, Layout::NEES), 2.0); // 1/1 + 4/4
        assert_eq!(s.at(1, Layout::TRACE), 5.0);
        assert_eq!(s.at(1, Layout::BITS), 96.0);
        assert_eq!(s.at(1, Layout::FRAME_BITS), 400.0);
        assert_eq!(s.at(1, Layout::DOWNLINK_BITS), 64.0);
        assert_eq!(s.steady_mse.sum, 5.0);
        assert_eq!(s.per_trial, vec![5.0, 1.0, 4.0]);
        assert_eq!(
            s.per_trial_rows().collect::<Vec<_>>(),
            vec![&[5.0, 1.0, 4.0][..]]
        );
        let mut m = s.clone();
        m.merge(&s);
        assert_eq!(m.trials, 2);
        // Cleared sums are new sums.
        let mut cleared = m.clone();
        cleared.clear();
        assert_eq!(cleared, Sums::new(2, 2, 2));
        assert_eq!(m.at(1, Layout::TOTAL_SE), 10.0);
        let (mean, se) = m.steady_mse.mean_se(2);
        assert_eq!((mean, se), (5.0, 0.0));
    }

    #[test]
    fn second_moments_and_whole_run_averages_give_hand_computed_standard_errors() {
        // One 1-D state, 3 trials x 2 steps; the estimate is off by e(t, k), covariance 1.
        let groups = vec![("x".to_string(), vec![0])];
        let errors = [[1.0, 2.0], [2.0, 0.0], [3.0, 1.0]];
        let mut s = Sums::new(1, 2, 1);
        let truth = Vector::from_vec(vec![0.0]);
        for (t, e) in errors.iter().enumerate() {
            let mut obs = s.trial(&groups, 1);
            for (k, &e) in e.iter().enumerate() {
                let est = Gaussian::new(Vector::from_vec(vec![e]), Matrix::identity(1, 1));
                let traffic = Traffic {
                    messages: t as _,
                    bits: 8 * k as u64,
                    ..Traffic::default()
                };
                obs.record(k + 1, &truth, &est, traffic).unwrap();
            }
            obs.finish();
        }
        // Step 1 squared errors 1, 4, 9: mean 14/3, sample variance (98 - 196/3) / 2 = 49/3,
        // se sqrt(49/9) = 7/3.
        let (m, se) = s.mean_se_at(0, Layout::TOTAL_SE);
        assert!((m - 14.0 / 3.0).abs() < 1e-12);
        assert!((se - 7.0 / 3.0).abs() < 1e-12, "{se}");
        // Per-trial time averages of the squared error: 2.5, 2, 5 -> mean 19/6; sample
        // variance (35.25 - 361/12) / 2 = 31/12, se sqrt(31/36).
        let (m, se) = s.whole_run[Layout::TOTAL_SE].mean_se(3);
        assert!((m - 19.0 / 6.0).abs() < 1e-12);
        assert!((se - (31.0f64 / 36.0).sqrt()).abs() < 1e-12, "{se}");
        // Messages: trial t sends t per step; whole-run averages 0, 1, 2 -> se 1 / sqrt(3).
        let (m, se) = s.whole_run[Layout::MESSAGES].mean_se(3);
        assert_eq!(m, 1.0);
        assert!((se - 1.0 / 3f64.sqrt()).abs() < 1e-12);
        // Bits are 0 at step 1 and 8 at step 2 in every trial: no spread at either step.
        assert_eq!(s.mean_se_at(1, Layout::BITS), (8.0, 0.0));
        // Merging two halves gives the same second moments as one pass.
        let mut m2 = Sums::new(1, 2, 1);
        m2.merge(&s);
        assert_eq!(m2.per_step_sq, s.per_step_sq);
        assert_eq!(m2.whole_run, s.whole_run);
    }
}
