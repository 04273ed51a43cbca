//! The all-data centralized KF's mean recursion for a lockstep batch of trials: the scheduled
//! step's operations on each trial's mean, the covariance half shared.
use super::ScheduledStep;
use crate::linalg::quad::{F64x4, Real};
use crate::linalg::{Matrix, Vector};
use crate::link::as_sent;
use multiversion::multiversion;

/// Step `k` of the means `xs` of the batch's `trials` ([`scheduled_mean`] of each). Compiled
/// also for AVX2 and picked at run time: the same IEEE operations (no FMA contraction), so
/// the same bits on every x86-64 machine.
///
/// The trials stay one after the other (not across the lanes of a vector register): their
/// division chains then overlap in the out-of-order core with the recording around them,
/// where a lane layout, tried, cost 4% more time on the peers' KF Monte Carlo for the
/// transposes in and out of the registers.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn advance_means<const N: usize>(
    f: &[f64],
    linear: &[(usize, Matrix)],
    step: &ScheduledStep,
    xs: &mut [[f64; N]],
    trials: &[&[Vec<Vector>]],
    k: usize,
) {
    for (x, m) in xs.iter_mut().zip(trials) {
        *x = scheduled_mean(f, linear, step, x, m[k - 1].iter().map(|z| z.as_slice()));
    }
}

/// Step `k` of the four trials of a block drawn side by side: [`scheduled_mean`] on lanes
/// (lane j: trial j), `zs` the step's readings of the scalar sensors. The same operations
/// lane by lane, one division instruction for the four trials. Compiled also for AVX2.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn advance_quad<const N: usize>(
    f: &[f64],
    linear: &[(usize, Matrix)],
    step: &ScheduledStep,
    x: &[F64x4; N],
    zs: &[F64x4],
) -> [F64x4; N] {
    scheduled_mean(f, linear, step, x, zs.iter().map(std::slice::from_ref))
}

/// One scheduled step's mean ([`super::CentralizedKf::scheduled_step`]) on arrays (one
/// trial's numbers, or four trials' in lanes): from_gaussian's P^{-1} (F x) by the predicted
/// covariance's factor, plus H_i^T R_i^{-1} z_i of each sensor in sensor order
/// (add_measurement) as each arrives ([`as_sent`]), back by the fused factor (to_gaussian).
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn scheduled_mean<'z, const N: usize, T: Real + 'z>(
    f: &[f64],
    linear: &[(usize, Matrix)],
    step: &ScheduledStep,
    x: &[T; N],
    zs: impl IntoIterator<Item = &'z [T]>,
) -> [T; N] {
    use crate::linalg::fixed::{chol_solve_array, mat_vec, mat_vec_cols_by};
    let mut y: [T; N] = mat_vec(f, x);
    chol_solve_array(step.pred_chol.l_dirty().as_slice(), &mut y);
    for ((_, ht_rinv), z) in linear.iter().zip(zs) {
        let t: [T; N] = mat_vec_cols_by(ht_rinv.as_slice(), z, |v: T| v.each(as_sent));
        for (yi, ti) in y.iter_mut().zip(t) {
            *yi = *yi + ti;
        }
    }
    chol_solve_array(step.fused_chol.l_dirty().as_slice(), &mut y);
    y
}
