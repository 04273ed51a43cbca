//! The layout of the sums: one step's row ([`Layout`]: a squared error per state group, then
//! the fixed fields), the row buffer a trial's running sums live in, and the per-trial
//! statistic whose spread gives standard errors.
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
pub(super) const STACK_WIDTH: usize = 16;

/// A row of zeros of a given length, on the stack up to [`STACK_WIDTH`]: a trial's running
/// sums without a heap allocation per trial.
pub(super) enum Row {
    Stack([f64; STACK_WIDTH], usize),
    Heap(Vec<f64>),
}

impl Row {
    pub(super) fn zeros(len: usize) -> Self {
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
    pub(super) fn add(&mut self, v: f64) {
        self.sum += v;
        self.sum_sq += v * v;
    }
    pub(super) fn merge(&mut self, o: &TrialStat) {
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
