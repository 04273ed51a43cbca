//! Metrics as mergeable sums: per time step and per trial, so that runs split across threads,
//! processes or machines merge exactly (in a fixed order, for bit-identical results).
use crate::filter::Gaussian;
use crate::linalg::{mahalanobis_sq, Vector};
use crate::network::Traffic;

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
    const FIXED: usize = 9;

    /// Entries per step.
    pub fn width(&self) -> usize {
        self.groups + Self::FIXED
    }
    /// Index of group g's squared error.
    pub fn group(&self, g: usize) -> usize {
        Self::FIXED + g
    }
}

/// Per-trial steady-state quantities whose spread across trials gives standard errors.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
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
        let var = ((self.sum_sq - nf * mean * mean) / (nf - 1.0)).max(0.0);
        (mean, (var / nf).sqrt())
    }
}

/// Sums for one scheme variant.
#[derive(Debug, Clone, PartialEq)]
pub struct Sums {
    pub layout_groups: usize,
    /// State dimension (for the NEES bound).
    pub state_dim: usize,
    pub steps: usize,
    /// steps x width, row-major.
    pub per_step: Vec<f64>,
    pub trials: usize,
    /// Steady-state per-trial averages: total squared error, trace, NEES, messages per step.
    pub steady_mse: TrialStat,
    pub steady_trace: TrialStat,
    pub steady_nees: TrialStat,
    pub steady_messages: TrialStat,
    /// Per trial, in trial order: steady-state mean squared error, total then per group.
    /// Kept so that two schemes can be compared by paired differences on the same trials.
    pub per_trial: Vec<Vec<f64>>,
}

/// Observer of one trial of one variant: accumulates into a [`Sums`] as the trial runs.
pub struct TrialObserver<'a> {
    sums: &'a mut Sums,
    groups: &'a [(String, Vec<usize>)],
    steady_from: usize,
    /// chi^2_n 99% quantile.
    nees_bound: f64,
    acc: [f64; 4],
    group_acc: Vec<f64>,
    count: usize,
    /// Work space, so that a step allocates nothing: the error, its whitened form and the
    /// matrix the NEES Cholesky factor is computed in.
    err: Vector,
    white: Vector,
    chol_buf: Option<crate::linalg::Matrix>,
}

impl Sums {
    pub fn new(groups: usize, steps: usize, state_dim: usize) -> Self {
        let layout = Layout { groups };
        Self {
            layout_groups: groups,
            state_dim,
            steps,
            per_step: vec![0.0; steps * layout.width()],
            trials: 0,
            steady_mse: TrialStat::default(),
            steady_trace: TrialStat::default(),
            steady_nees: TrialStat::default(),
            steady_messages: TrialStat::default(),
            per_trial: Vec::new(),
        }
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
        let nees_bound = crate::stats::chi2::upper_quantile(self.state_dim as f64, 0.01)
            .unwrap_or(f64::INFINITY);
        TrialObserver {
            sums: self,
            groups,
            steady_from,
            nees_bound,
            acc: [0.0; 4],
            group_acc: vec![0.0; groups.len()],
            count: 0,
            err: Vector::zeros(0),
            white: Vector::zeros(0),
            chol_buf: None,
        }
    }

    /// Adds another block's sums (same shape).
    pub fn merge(&mut self, o: &Sums) {
        for (a, b) in self.per_step.iter_mut().zip(&o.per_step) {
            *a += b;
        }
        self.trials += o.trials;
        self.steady_mse.merge(&o.steady_mse);
        self.steady_trace.merge(&o.steady_trace);
        self.steady_nees.merge(&o.steady_nees);
        self.steady_messages.merge(&o.steady_messages);
        self.per_trial.extend(o.per_trial.iter().cloned());
    }

    /// Sum of entry `field` at step index `s` (0-based).
    pub fn at(&self, s: usize, field: usize) -> f64 {
        self.per_step[s * self.layout().width() + field]
    }
}

impl TrialObserver<'_> {
    /// Records step `k` (1-based): truth, fused estimate and the traffic of the step.
    /// NEES needs a positive definite covariance; a scheme whose covariance is not is a
    /// defect that we report rather than hide.
    pub fn record(
        &mut self,
        k: usize,
        truth: &Vector,
        est: &Gaussian,
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        let layout = self.sums.layout();
        let w = layout.width();
        // err = mean - truth, in the buffer.
        if self.err.len() != est.mean.len() {
            self.err = Vector::zeros(est.mean.len());
            self.white = Vector::zeros(est.mean.len());
        }
        self.err.copy_from(&est.mean);
        self.err -= truth;
        let nees_direct = nees_buffered(&self.err, &est.cov, &mut self.white, &mut self.chol_buf);
        let err = &self.err;
        let row = &mut self.sums.per_step[(k - 1) * w..k * w];
        let total: f64 = err.iter().map(|e| e * e).sum();
        let steady = k >= self.steady_from;
        for (g, (_, idx)) in self.groups.iter().enumerate() {
            let se = idx.iter().map(|&j| err[j] * err[j]).sum::<f64>();
            row[layout.group(g)] += se;
            if steady {
                self.group_acc[g] += se;
            }
        }
        // A particle cloud can collapse onto one particle: its covariance is then singular.
        // NEES is computed with a tiny relative jitter (so the claim of certainty shows as a
        // huge NEES) and the step is counted as degenerate; NaN/inf remain errors.
        let (nees, degenerate) = match nees_direct {
            Ok(v) => (v, false),
            Err(crate::linalg::LinalgError::NotPositiveDefinite) => {
                let n = est.cov.nrows();
                let scale = (est.cov.trace().abs() / n as f64).max(1e-12);
                let jittered = &est.cov + crate::linalg::Matrix::identity(n, n) * (1e-9 * scale);
                (mahalanobis_sq(err, &jittered)?, true)
            }
            Err(e) => return Err(e),
        };
        let trace = est.cov.trace();
        row[Layout::TOTAL_SE] += total;
        row[Layout::NEES] += nees;
        row[Layout::TRACE] += trace;
        row[Layout::MESSAGES] += traffic.messages as f64;
        row[Layout::BITS] += traffic.bits as f64;
        row[Layout::FRAME_BITS] += traffic.frame_bits as f64;
        row[Layout::DOWNLINK_BITS] += traffic.downlink_bits as f64;
        row[Layout::DEGENERATE] += f64::from(u8::from(degenerate));
        row[Layout::NEES_COVERED] += f64::from(u8::from(nees <= self.nees_bound));
        if steady {
            self.acc[0] += total;
            self.acc[1] += trace;
            self.acc[2] += nees;
            self.acc[3] += traffic.messages as f64;
            self.count += 1;
        }
        Ok(())
    }

    /// Closes the trial.
    pub fn finish(self) {
        let c = self.count.max(1) as f64;
        self.sums.trials += 1;
        self.sums.steady_mse.add(self.acc[0] / c);
        self.sums.steady_trace.add(self.acc[1] / c);
        self.sums.steady_nees.add(self.acc[2] / c);
        self.sums.steady_messages.add(self.acc[3] / c);
        let mut row = Vec::with_capacity(1 + self.group_acc.len());
        row.push(self.acc[0] / c);
        row.extend(self.group_acc.iter().map(|v| v / c));
        self.sums.per_trial.push(row);
    }
}

/// [`mahalanobis_sq`] with the factorization done in `buf` and the solve in `white`: the same
/// checks (square, finite), the same Cholesky factorization of a copy of `p` and the same
/// triangular solve, hence the same number, without allocating.
fn nees_buffered(
    e: &Vector,
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
    if p.iter().any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    let mut m = match buf.take() {
        Some(m) if m.shape() == p.shape() => m,
        _ => crate::linalg::Matrix::zeros(p.nrows(), p.ncols()),
    };
    m.copy_from(p);
    let chol = nalgebra::Cholesky::new(m).ok_or(LinalgError::NotPositiveDefinite)?;
    white.copy_from(e);
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
        assert_eq!(s.per_trial, vec![vec![5.0, 1.0, 4.0]]);
        let mut m = s.clone();
        m.merge(&s);
        assert_eq!(m.trials, 2);
        assert_eq!(m.at(1, Layout::TOTAL_SE), 10.0);
        let (mean, se) = m.steady_mse.mean_se(2);
        assert_eq!((mean, se), (5.0, 0.0));
    }
}
