//! Recording the four trials of a runner block side by side (lane j of an [`F64x4`]: trial j),
//! when their estimates share one covariance (the all-data KF's lockstep block): each step's
//! errors, NEES (two divisions per state component, by the shared factor's diagonal, one
//! instruction for the four trials), step values and running sums are made for the four at
//! once. The numbers are those of recording each trial alone ([`TrialState::record_factored`]):
//! every lane runs that path's operations in its order, and the step's sums add the four
//! trials' values in trial order.
use super::{
    nees_bounds, trace, traffic_counts, Layout, Sums, TrialState, DIVERGENCE_RUN, STACK_WIDTH,
};
use crate::linalg::quad::{F64x4, Real};
use crate::linalg::Matrix;
use crate::network::Traffic;
use multiversion::multiversion;

/// Trials recorded side by side: the lanes of an [`F64x4`].
const QUAD: usize = F64x4::LANES;

/// What four [`TrialState`]s carry from step to step, in lanes (lane j: trial j of the block).
pub struct QuadTrials {
    steady_from: usize,
    /// chi^2_n 99%, 95% and 99.9% quantiles ([`nees_bounds`]).
    bounds: [f64; 3],
    /// Each trial's sums over all steps, per field of the row.
    run_acc: [F64x4; STACK_WIDTH],
    /// Steady-state sums: total squared error, trace, NEES, messages.
    acc: [F64x4; 4],
    /// Steady-state squared error per group.
    group_acc: [F64x4; STACK_WIDTH - Layout::FIXED],
    /// Current run of steps above the divergence bound, and whether the trial diverged.
    run: [usize; QUAD],
    diverged: [bool; QUAD],
    /// Steady-state steps recorded.
    count: usize,
    /// Every steady-state NEES of the four trials, for the histogram at the end.
    nees: Vec<f64>,
    /// The traffic of the last steps recorded and how many trial-steps had it, not yet in
    /// [`Sums::sensors`] (integer counts: adding them a run of steps at a time changes
    /// nothing).
    senders: Option<(Traffic, u64)>,
}

impl QuadTrials {
    /// The state of four new trials adding into `sums`; `None` when a row does not fit the
    /// stack (16 fields): those record one trial at a time.
    pub fn new(sums: &Sums, steady_from: usize) -> Option<Self> {
        if sums.layout().width() > STACK_WIDTH {
            return None;
        }
        Some(Self {
            steady_from,
            bounds: nees_bounds(sums.state_dim),
            run_acc: [F64x4::ZERO; STACK_WIDTH],
            acc: [F64x4::ZERO; 4],
            group_acc: [F64x4::ZERO; STACK_WIDTH - Layout::FIXED],
            run: [0; QUAD],
            diverged: [false; QUAD],
            count: 0,
            nees: Vec::new(),
            senders: None,
        })
    }

    /// Back to four new trials of `sums` (as [`QuadTrials::new`] makes them), keeping the
    /// buffer.
    pub fn restart(&mut self, sums: &Sums, steady_from: usize) {
        let nees = std::mem::take(&mut self.nees);
        if let Some(fresh) = Self::new(sums, steady_from) {
            *self = fresh;
        }
        self.nees = nees;
        self.nees.clear();
    }

    /// Records step `k` of the four trials: truths `truth[c]` and means `means[c]` (component
    /// c, lane j: trial j), the shared covariance `cov` with its NEES factor `factor`
    /// ([`crate::linalg::fixed::nees_factor`]) and the step's traffic. False, with nothing
    /// recorded, when the factor is missing, has a zero diagonal or the state is wider than 6:
    /// then the trials must be recorded one at a time from their start.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &mut self,
        sums: &mut Sums,
        groups: &[(String, Vec<usize>)],
        k: usize,
        truth: &[F64x4],
        means: &[F64x4],
        cov: &Matrix,
        factor: Option<&[f64]>,
        traffic: Traffic,
    ) -> bool {
        let n = means.len();
        let Some(factor) = factor.filter(|f| f.len() == n * n && truth.len() == n) else {
            return false;
        };
        if (0..n).any(|i| factor[i * n + i] == 0.0) {
            return false;
        }
        let step = StepShared {
            k,
            trace: trace(cov),
            counts: traffic_counts(traffic),
            factor,
        };
        let done = match n {
            1 => record_step::<1>(self, sums, groups, &step, truth, means),
            2 => record_step::<2>(self, sums, groups, &step, truth, means),
            3 => record_step::<3>(self, sums, groups, &step, truth, means),
            4 => record_step::<4>(self, sums, groups, &step, truth, means),
            5 => record_step::<5>(self, sums, groups, &step, truth, means),
            6 => record_step::<6>(self, sums, groups, &step, truth, means),
            _ => false,
        };
        if done {
            match &mut self.senders {
                Some((last, count)) if *last == traffic => *count += QUAD as u64,
                pending => {
                    if let Some((last, count)) = pending.take() {
                        sums.add_senders(&last, count);
                    }
                    *pending = Some((traffic, QUAD as u64));
                }
            }
        }
        done
    }

    /// Closes the four trials in trial order, through `states` (four trial states of `sums`,
    /// restarted here): each is given its lane's running sums and closed as a trial recorded
    /// alone closes. The steady-state NEES go into the histogram together (its counts are
    /// integers: the order they are added in changes nothing).
    pub fn close(&mut self, sums: &mut Sums, states: &mut [TrialState]) {
        if let Some((last, count)) = self.senders.take() {
            sums.add_senders(&last, count);
        }
        let n = sums.state_dim.max(1) as f64;
        sums.nees_hist.add_divided(&self.nees, n);
        for (j, state) in states.iter_mut().enumerate().take(QUAD) {
            state.restart(sums);
            for (run, lanes) in state.run_acc.iter_mut().zip(&self.run_acc) {
                *run = lanes.0[j];
            }
            for (acc, lanes) in state.group_acc.iter_mut().zip(&self.group_acc) {
                *acc = lanes.0[j];
            }
            state.acc = self.acc.map(|lanes| lanes.0[j]);
            state.count = self.count;
            state.diverged = self.diverged[j];
            state.run = self.run[j];
            state.close(sums);
        }
    }
}

/// What the four trials of a step share: the step, the covariance's trace and NEES factor, the
/// traffic's counts.
struct StepShared<'f> {
    k: usize,
    trace: f64,
    counts: [f64; 4],
    factor: &'f [f64],
}

/// [`QuadTrials::record`] for state dimension N. Compiled also for AVX2 and picked at run
/// time: the same IEEE operations (no FMA contraction), so the same sums on every x86-64
/// machine.
#[multiversion(targets("x86_64+avx2"))]
fn record_step<const N: usize>(
    q: &mut QuadTrials,
    sums: &mut Sums,
    groups: &[(String, Vec<usize>)],
    step: &StepShared,
    truth: &[F64x4],
    means: &[F64x4],
) -> bool {
    let layout = sums.layout();
    let w = layout.width();
    if groups.len() != layout.groups {
        return false;
    }
    let k = step.k;
    let e: [F64x4; N] = std::array::from_fn(|c| means[c] - truth[c]);
    let Some(nees) = crate::linalg::fixed::mahalanobis_factored_array(e, step.factor) else {
        return false;
    };
    let total = squares(&e, 0..N);
    let [bound, bound_95, divergence_bound] = q.bounds;
    let [messages, bits, frame_bits, downlink_bits] = step.counts;
    let mut vals = [F64x4::ZERO; STACK_WIDTH];
    vals[Layout::TOTAL_SE] = total;
    vals[Layout::NEES] = nees;
    vals[Layout::TRACE] = F64x4::splat(step.trace);
    vals[Layout::MESSAGES] = F64x4::splat(messages);
    vals[Layout::BITS] = F64x4::splat(bits);
    vals[Layout::FRAME_BITS] = F64x4::splat(frame_bits);
    vals[Layout::DOWNLINK_BITS] = F64x4::splat(downlink_bits);
    // DEGENERATE: never (the factor exists); ESS: none (+0 adds nothing to its sums).
    vals[Layout::NEES_COVERED] = nees.flag_le(bound);
    vals[Layout::NEES_COVERED_95] = nees.flag_le(bound_95);
    let steady = k >= q.steady_from;
    for (g, (_, idx)) in groups.iter().enumerate() {
        let se = squares(&e, idx.iter().copied());
        vals[layout.group(g)] = se;
        if steady {
            q.group_acc[g] = q.group_acc[g] + se;
        }
    }
    for (run, v) in q.run_acc.iter_mut().zip(&vals) {
        *run = *run + *v;
    }
    // Divergence, lane by lane: a run of NEES beyond the 99.9% quantile, or anything not
    // finite.
    for j in 0..QUAD {
        let (t, v) = (total.0[j], nees.0[j]);
        if !(t.is_finite() && v.is_finite()) {
            q.diverged[j] = true;
        }
        if v > divergence_bound || v.is_nan() {
            q.run[j] += 1;
            if q.run[j] >= DIVERGENCE_RUN {
                q.diverged[j] = true;
            }
        } else {
            q.run[j] = 0;
        }
    }
    if steady {
        q.nees.extend_from_slice(&nees.0);
        q.acc[0] = q.acc[0] + total;
        q.acc[1] = q.acc[1] + vals[Layout::TRACE];
        q.acc[2] = q.acc[2] + nees;
        q.acc[3] = q.acc[3] + vals[Layout::MESSAGES];
        q.count += 1;
    }
    // The step's sums: each field's four values added in trial order.
    let row = &mut sums.per_step[(k - 1) * w..k * w];
    let row_sq = &mut sums.per_step_sq[(k - 1) * w..k * w];
    for ((r, s), v) in row.iter_mut().zip(row_sq.iter_mut()).zip(&vals) {
        let sq = *v * *v;
        let (mut a, mut b) = (*r, *s);
        for j in 0..QUAD {
            a += v.0[j];
            b += sq.0[j];
        }
        (*r, *s) = (a, b);
    }
    true
}

/// The squared errors of the components `idx` summed as `Iterator::sum` sums f64: a fold
/// from its neutral element, in order.
#[inline(always)]
fn squares<const N: usize>(e: &[F64x4; N], idx: impl Iterator<Item = usize>) -> F64x4 {
    let neutral = F64x4::splat(std::iter::empty::<f64>().sum::<f64>());
    idx.fold(neutral, |s, c| s + e[c] * e[c])
}
