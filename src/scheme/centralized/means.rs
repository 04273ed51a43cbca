//! The all-data centralized KF's mean recursion for a lockstep batch of trials: the trials as
//! the lanes of [`crate::linalg::fixed::lanes`], the scheduled step's operations on each.
use super::ScheduledStep;
use crate::linalg::{Matrix, Vector};
use crate::link::as_sent;
use multiversion::multiversion;

/// Step `k` of the means `xs` of the batch's `trials` ([`scheduled_means`]). Compiled
/// also for AVX2 and picked at run time: the same IEEE operations (no FMA contraction), so
/// the same bits on every x86-64 machine.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn advance_means<const N: usize>(
    f: &[f64],
    linear: &[(usize, Matrix)],
    step: &ScheduledStep,
    xs: &mut [[f64; N]],
    trials: &[&[Vec<Vector>]],
    k: usize,
) {
    use crate::linalg::fixed::lanes::WIDTH;
    for (xs, trials) in xs.chunks_mut(WIDTH).zip(trials.chunks(WIDTH)) {
        scheduled_means(f, linear, step, xs, trials, k);
    }
}

/// One scheduled step's mean ([`super::CentralizedKf::scheduled_step`]) for up to
/// [`WIDTH`](crate::linalg::fixed::lanes::WIDTH) trials at once: from_gaussian's P^{-1} (F x)
/// by the predicted covariance's factor, plus H_i^T R_i^{-1} z_i of each sensor in sensor
/// order (add_measurement) as each arrives ([`crate::link::as_sent`]), back by the fused factor
/// (to_gaussian). One trial per lane ([`crate::linalg::fixed::lanes`]: each lane's operations
/// are the scalar kernels', so each trial's bits are its own step's), so that the trials'
/// divisions by the factors' shared diagonals go through the divider together.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn scheduled_means<const N: usize>(
    f: &[f64],
    linear: &[(usize, Matrix)],
    step: &ScheduledStep,
    xs: &mut [[f64; N]],
    trials: &[&[Vec<Vector>]],
    k: usize,
) {
    use crate::linalg::fixed::lanes::{self, Lanes, WIDTH};
    let x = lanes::gather(xs);
    let mut y: [Lanes; N] = lanes::mat_vec::<N, N>(f, &x);
    lanes::chol_solve::<N>(step.pred_chol.l_dirty().as_slice(), &mut y);
    // Each lane's readings of this step; the lanes past the batch's trials repeat the first.
    let mut rows: [&[Vector]; WIDTH] = [trials[0][k - 1].as_slice(); WIDTH];
    for (row, trial) in rows.iter_mut().zip(trials) {
        *row = trial[k - 1].as_slice();
    }
    let mut buf = [[0.0; WIDTH]; 8];
    let mut heap = Vec::new();
    for (i, (m, ht_rinv)) in linear.iter().enumerate() {
        // Sensor i's reading as it arrives, one trial per lane.
        let z: &mut [Lanes] = match buf.get_mut(..*m) {
            Some(z) => z,
            None => {
                heap.resize(*m, [0.0; WIDTH]);
                &mut heap
            }
        };
        for (l, row) in rows.iter().enumerate() {
            for (zj, v) in z.iter_mut().zip(row[i].as_slice()) {
                zj[l] = as_sent(*v);
            }
        }
        let t: [Lanes; N] = lanes::mat_vec_cols::<N>(ht_rinv.as_slice(), z);
        for (yc, tc) in y.iter_mut().zip(t) {
            for l in 0..WIDTH {
                yc[l] = yc[l] + tc[l];
            }
        }
    }
    lanes::chol_solve::<N>(step.fused_chol.l_dirty().as_slice(), &mut y);
    // Held in memory as lanes before the rows are written: otherwise the compiler fuses the
    // last divisions with the scatter and runs them one lane at a time.
    let y = std::hint::black_box(y);
    lanes::scatter(&y, xs);
}
