//! Recording the trials of a lockstep batch whose estimates share one covariance (the fast
//! paths of the linear schemes): the same numbers as one trial at a time, with what no trial
//! changes read once per step.
use super::{trace, traffic_counts, Sums, TrialState, STACK_WIDTH};
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
    /// Trials whose errors and NEES are computed before any is accumulated: their
    /// Cholesky solves (two dependent divisions each) then overlap.
    const GROUP: usize = 4;
    let n = shared.mean.len();
    let trace = trace(&shared.cov);
    let counts = traffic_counts(traffic);
    sums.add_senders(&traffic, states.len().min(truths.len()) as u64);
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
