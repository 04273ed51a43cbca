//! Recording the trials of a lockstep batch whose estimates share one covariance (the fast
//! paths of the linear schemes): the same numbers as one trial at a time, with what no trial
//! changes read once per step.
use super::{
    trace, traffic_counts, Layout, Row, StepValues, Sums, TrialState, DIVERGENCE_RUN, PENDING_NEES,
    STACK_WIDTH,
};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::network::Traffic;
use multiversion::multiversion;

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
    let n = shared.mean.len();
    let trace = trace(&shared.cov);
    let counts = traffic_counts(traffic);
    sums.add_senders(&traffic, states.len().min(truths.len()) as u64);
    if let Some(f) = factor.filter(|f| f.len() == n * n) {
        let step = Step {
            k,
            trace,
            counts,
            factor: f,
        };
        let done = match n {
            1 => record_groups::<1>(states, sums, &step, truths, means),
            2 => record_groups::<2>(states, sums, &step, truths, means),
            3 => record_groups::<3>(states, sums, &step, truths, means),
            4 => record_groups::<4>(states, sums, &step, truths, means),
            5 => record_groups::<5>(states, sums, &step, truths, means),
            6 => record_groups::<6>(states, sums, &step, truths, means),
            _ => false,
        };
        if done {
            return Ok(());
        }
    }
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

/// What the trials of a step share: the step, the covariance's trace and factor, the traffic's
/// counts.
struct Step<'f> {
    k: usize,
    trace: f64,
    counts: [f64; 4],
    factor: &'f [f64],
}

/// Trials per group: of [`record_groups`], and of the general path of [`record_shared`], whose
/// groups' errors and NEES are computed before any is accumulated (their Cholesky solves, two
/// dependent divisions each, then overlap).
const GROUP: usize = 4;

/// [`record_shared`] for state dimension N when every field of a step fits on the stack: the
/// trials in groups of [`GROUP`], each trial's error, NEES (from the shared factor) and step
/// values as [`TrialState::accumulate`] makes them, then the step's sums and sums of squares
/// added field by field, trial after trial, in whole registers (the same additions in the same
/// order as one trial at a time). False, with nothing recorded, when the factor has a zero
/// diagonal (no NEES from it) or the row is too wide: the caller then records the general way.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn record_groups<const N: usize>(
    states: &mut [TrialState],
    sums: &mut Sums,
    step: &Step,
    truths: &[&[Vector]],
    means: &[f64],
) -> bool {
    let w = sums.layout().width();
    if w > STACK_WIDTH || (0..N).any(|i| step.factor[i * N + i] == 0.0) {
        return false;
    }
    let k = step.k;
    let trials = states.len().min(truths.len()).min(means.len() / N);
    let (states, truths) = (&mut states[..trials], &truths[..trials]);
    let groups = states.chunks_mut(GROUP).zip(truths.chunks(GROUP));
    for (g, (states, truths)) in groups.enumerate() {
        let means = &means[g * GROUP * N..];
        let mut vals = [[0.0; STACK_WIDTH]; GROUP];
        for (j, (state, vals)) in states.iter_mut().zip(&mut vals).enumerate() {
            let truth = truths[j][k - 1].as_slice();
            assert_eq!(truth.len(), N, "record: truth and estimate dimensions");
            let e: [f64; N] = std::array::from_fn(|c| means[j * N + c] - truth[c]);
            let Some(nees) = crate::linalg::fixed::mahalanobis_sq_factored(&e, step.factor) else {
                unreachable!("the factor's diagonal was checked");
            };
            let values = state.error_step(&e, nees, false, step.trace);
            let group_se = |idx: &[usize]| idx.iter().map(|&j| e[j] * e[j]).sum::<f64>();
            state.step_values(sums, k, &values, group_se, step.counts, vals);
        }
        // The step's row on the stack, full width (whole registers; the entries past `w`
        // add zeros and are not written back), each trial's values added in trial order.
        let row = &mut sums.per_step[(k - 1) * w..k * w];
        let row_sq = &mut sums.per_step_sq[(k - 1) * w..k * w];
        let (mut r, mut q) = ([0.0; STACK_WIDTH], [0.0; STACK_WIDTH]);
        r[..w].copy_from_slice(row);
        q[..w].copy_from_slice(row_sq);
        for vals in &vals[..states.len()] {
            for f in 0..STACK_WIDTH {
                r[f] += vals[f];
                q[f] += vals[f] * vals[f];
            }
        }
        row.copy_from_slice(&r[..w]);
        row_sq.copy_from_slice(&q[..w]);
    }
    true
}

impl TrialState<'_> {
    /// [`TrialState::accumulate_step`] except the additions into the step's sums and sums of
    /// squares: step `k`'s value of every field is left in `vals` (zero on entry, the row's
    /// width or [`STACK_WIDTH`], past the width left zero) for the caller to add, and goes
    /// into this trial's running sums. A batch adds its trials' values into the step's sums
    /// together ([`record_shared`]).
    #[inline(always)]
    pub(super) fn step_values(
        &mut self,
        sums: &mut Sums,
        k: usize,
        step: &StepValues,
        group_se: impl Fn(&[usize]) -> f64,
        counts: [f64; 4],
        vals: &mut [f64],
    ) {
        let layout = sums.layout();
        let StepValues {
            total,
            nees,
            degenerate,
            covered,
            trace,
        } = *step;
        // ESS is left at +0, which adds nothing to any of its sums (they start at +0 and only
        // ever add ESS values >= 0); it is recorded by `record_ess`.
        let [messages, bits, frame_bits, downlink_bits] = counts;
        vals[Layout::TOTAL_SE] = total;
        vals[Layout::NEES] = nees;
        vals[Layout::TRACE] = trace;
        vals[Layout::MESSAGES] = messages;
        vals[Layout::BITS] = bits;
        vals[Layout::FRAME_BITS] = frame_bits;
        vals[Layout::DOWNLINK_BITS] = downlink_bits;
        vals[Layout::DEGENERATE] = degenerate;
        vals[Layout::NEES_COVERED] = covered[0];
        vals[Layout::NEES_COVERED_95] = covered[1];
        let steady = k >= self.steady_from;
        for (g, (_, idx)) in self.groups.iter().enumerate() {
            let se = group_se(idx);
            vals[layout.group(g)] = se;
            if steady {
                self.group_acc[g] += se;
            }
        }
        // This trial's whole-run sums: in whole registers when the row is on the stack (its
        // entries past the width add zeros to zeros).
        match (
            &mut self.run_acc,
            <&mut [f64; STACK_WIDTH]>::try_from(&mut *vals),
        ) {
            (Row::Stack(run, _), Ok(vals)) => {
                for f in 0..STACK_WIDTH {
                    run[f] += vals[f];
                }
            }
            (run, _) => {
                for (run, v) in run.iter_mut().zip(vals.iter()) {
                    *run += v;
                }
            }
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
}
