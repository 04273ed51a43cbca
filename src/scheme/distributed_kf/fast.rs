//! The fast trial of Dormann et al.'s schemes: the same sensors and fusion center as
//! [`super::DkfSensor`] and [`super::DkfCenter`], run without the generic loop.
//!
//! Most of a sensor's work does not depend on the variant: the globalized local filter
//! x̄^{e,i}_k (Section II) and the standard local KF beside it are functions of the measurements
//! only, and so are the fusion center's terms of (11) for an estimate that arrives
//! ((C̄^e_k)^{-1} x̄^{e,i}_k) and for one sent at k-1 and omitted at k ((C̄^p_k)^{-1} A x̄^{e,i}_{k-1},
//! since the center's held estimate is then exactly the sensor's prediction). A trial computes
//! them once in its [`Signals`], shared by every variant of the plan (a sweep of rates, alphas
//! and bounds). Algorithm 2's replicas of the center — what test (13) and the center's
//! debiased term of a sensor silent for two steps or more need — depend on the data and on
//! (sensor, last transmission, step) only, and are shared per trial too ([`Replicas`]); so are
//! the fused means of steps whose silent sensors all sent at k-1 ([`Means`]), and the fused
//! covariances are shared by every trial ([`super::center::DenseMemo`]). A variant then only draws its
//! coins, runs its trigger and looks its step up. Every number is computed by the operations
//! the generic path performs, on the same operands, so it is the same bit for bit.
use super::center::{canonical_silence, DkfCenter};
use super::replica::Replicas;
use super::sensor::Trigger;
use super::signals::Signals;
use super::{DistributedKfScheme, Fusion};
use crate::filter::Gaussian;
use crate::linalg::fixed;
use crate::linalg::Vector;
use crate::link::Message;
use crate::network::Traffic;
use crate::scheme::fast_path::{FastTrialError, StepSink, TrialCache};
use crate::scheme::SchemeError;
use rand::{Rng, RngCore};
use std::sync::Arc;

/// Fused means of one trial for steps without inexact extrapolations, by (k, silence set).
/// Such a mean is (10)-(11) solved with the sensors' exact terms of [`Signals`] — summed in
/// sensor order from zero — and the Cholesky factor of (k's plan step, the set): a function of
/// the data, k and the set only, the same for every variant (of either algorithm) that has
/// that set at k. Dense: up to 2^[`MEAN_MEMO_SENSORS`] sets per step.
struct Means {
    n: usize,
    sets: usize,
    /// The entry of (k, set) at `(k - 1) * sets + set`, or `NONE`.
    slot: Vec<u32>,
    values: Vec<f64>,
}

const MEAN_MEMO_SENSORS: usize = 8;
const NONE: u32 = u32::MAX;

impl Means {
    fn new(n: usize, sensors: usize, steps: usize) -> Self {
        let sets = if sensors <= MEAN_MEMO_SENSORS {
            1 << sensors
        } else {
            0
        };
        Self {
            n,
            sets,
            slot: vec![NONE; steps * sets],
            values: Vec::new(),
        }
    }

    fn get(&self, k: usize, silent: u64) -> Option<&[f64]> {
        let e = *self.slot.get((k - 1) * self.sets + silent as usize)?;
        (e != NONE).then(|| &self.values[e as usize * self.n..(e as usize + 1) * self.n])
    }

    fn put(&mut self, k: usize, silent: u64, mean: &[f64]) {
        if let Some(slot) = self.slot.get_mut((k - 1) * self.sets + silent as usize) {
            *slot = (self.values.len() / self.n) as u32;
            self.values.extend_from_slice(mean);
        }
    }
}

/// What a trial's variants share: the signals, Algorithm 2's replicas and the fused means.
pub(super) struct Track {
    signals: Signals,
    replicas: Replicas,
    means: Means,
}

/// The fast trial; `None` when the data or the system is outside what it covers (the generic
/// loop then reports whatever is wrong, at the step it is wrong).
pub(super) fn run(
    scheme: &DistributedKfScheme,
    measurements: &[Vec<Vector>],
    steps: usize,
    rng: &mut dyn RngCore,
    cache: &mut TrialCache,
    sink: &mut dyn StepSink,
) -> Option<Result<(), FastTrialError>> {
    let plan = &scheme.plan;
    let key = (Arc::as_ptr(plan) as usize, measurements.as_ptr() as usize);
    // Whether the trial is covered depends on the plan and the data only (the key), so it is
    // checked once per trial too.
    let track: &mut Option<Track> = cache.get_or_insert_with(key, || {
        covered(scheme, measurements, steps).then(|| {
            let sys = &scheme.system;
            let (n, ns) = (sys.state_dim(), sys.n_sensors());
            Track {
                signals: Signals::compute(scheme, measurements, steps),
                replicas: Replicas::new(n, ns, steps),
                means: Means::new(n, ns, steps),
            }
        })
    });
    Some(run_variant(scheme, track.as_mut()?, steps, rng, sink))
}

/// Whether the fast trial covers these data: finite measurements of the right sizes for every
/// step, a plan that reaches the last step, and silence sets that fit a bit set.
fn covered(scheme: &DistributedKfScheme, measurements: &[Vec<Vector>], steps: usize) -> bool {
    let plan = &scheme.plan;
    let sys = &scheme.system;
    let ns = sys.n_sensors();
    ns <= 64
        && measurements.len() >= steps
        && plan.at(steps).is_ok()
        && plan.index(steps).is_ok()
        && measurements[..steps].iter().all(|zs| {
            zs.len() == ns
                && zs
                    .iter()
                    .zip(&sys.sensors)
                    .all(|(z, s)| z.len() == s.meas_dim() && z.iter().all(|v| v.is_finite()))
        })
}

/// Where a variant's sensor stands: consecutive silent steps before the current one (the
/// center's count after a silent step is this plus one: every sensor is scheduled at every
/// step), and for Algorithm 2 its replica's entry at the current step.
#[derive(Clone, Copy, Default)]
struct SensorState {
    silent_steps: usize,
    entry: u32,
}

fn run_variant(
    scheme: &DistributedKfScheme,
    track: &mut Track,
    steps: usize,
    rng: &mut dyn RngCore,
    sink: &mut dyn StepSink,
) -> Result<(), FastTrialError> {
    let Track {
        signals,
        replicas,
        means,
    } = track;
    let plan = &scheme.plan;
    let sys = &scheme.system;
    let center = &scheme.proto;
    let n = sys.state_dim();
    let ns = sys.n_sensors();
    let every_other = scheme.trigger.every_other_step();
    let message = Message::Estimate(Vector::zeros(n));
    let (msg_bits, msg_frame_bits) = (message.bits(), message.frame_bits());
    let mut state = vec![SensorState::default(); ns];
    let mut est = Gaussian::new(Vector::zeros(n), sys.prior.cov.clone());
    let mut tmp = vec![0.0; n];
    let bound = match &scheme.trigger {
        Trigger::Bounded { b_inv, .. } => replicas.bound(b_inv),
        _ => 0,
    };
    let err = |k: usize| move |source: SchemeError| FastTrialError::Scheme { k, source };
    for k in 1..=steps {
        let p = plan.index(k).map_err(err(k))?;
        let mut silent = 0u64;
        let mut inexact = 0usize;
        let mut messages = 0u64;
        for (i, st) in state.iter_mut().enumerate() {
            // The sensor (DkfSensor::step): its trigger, with Algorithm 2's replica of the
            // center at this step.
            let u: f64 = rng.random();
            let must_send = every_other && st.silent_steps >= 1;
            let send = must_send
                || match &scheme.trigger {
                    Trigger::Always => true,
                    Trigger::Random { send_probability } => u < *send_probability,
                    Trigger::Event { alpha } => signals.correction_norm[(k - 1) * ns + i] > *alpha,
                    Trigger::Bounded { alpha, .. } => {
                        st.entry = if st.silent_steps == 0 {
                            replicas.after_send(plan, signals, i, k - 1)
                        } else {
                            replicas.advance(plan, signals, st.entry, i, k)
                        }
                        .map_err(err(k))?;
                        replicas.test_13(st.entry, *alpha, bound, &mut tmp)
                    }
                };
            // The center's bookkeeping (DkfCenter::step).
            if send {
                st.silent_steps = 0;
                messages += 1;
            } else {
                st.silent_steps += 1;
                silent |= 1 << i;
                if st.silent_steps >= 2 {
                    match &scheme.fusion {
                        Fusion::OmittedEstimates => {
                            return Err(err(k)(SchemeError::Protocol {
                                sensor: i,
                                // Unreachable: Algorithm 1's sensors never omit twice and
                                // the fast trial runs on a lossless link only.
                                message: format!(
                                    "silent for {} steps on a lossless link; Algorithm 1's \
                                     sensors send at least every other step",
                                    st.silent_steps
                                ),
                            }));
                        }
                        Fusion::Bounded { .. } => inexact += 1,
                    }
                }
            }
        }
        let factor = fuse(
            center, signals, replicas, means, &state, k, p, silent, inexact, &mut est,
        )
        .map_err(err(k))?;
        let traffic = Traffic {
            messages,
            bits: messages * msg_bits,
            frame_bits: messages * msg_frame_bits,
            ..Traffic::default()
        };
        match factor {
            Some(f) => sink.step_factored(k, &est, f, traffic),
            None => sink.step(k, &est, traffic),
        }
        .map_err(|source| FastTrialError::Sink { k, source })?;
    }
    Ok(())
}

/// The center's step k (DkfCenter::step): (11)'s information vector in sensor order, solved
/// with (10)'s Cholesky factor, and the fused covariance, into `est`. Returns the NEES factor
/// of `est.cov` (`fixed::nees_factor`) when the covariance is a copy of a memoized one that
/// keeps it.
#[allow(clippy::too_many_arguments)]
fn fuse<'c>(
    center: &'c DkfCenter,
    signals: &Signals,
    replicas: &Replicas,
    means: &mut Means,
    state: &[SensorState],
    k: usize,
    p: usize,
    silent: u64,
    inexact: usize,
    est: &mut Gaussian,
) -> Result<Option<&'c [f64]>, SchemeError> {
    let Some(dense) = center.dense_memo() else {
        let fused =
            center.fused_covariance(p, canonical_silence(&center.class, silent), inexact)?;
        information_sum(signals, replicas, state, k, est.mean.as_mut_slice());
        fixed::chol_solve(&fused.chol, &mut est.mean);
        est.cov.as_mut_slice().copy_from_slice(fused.cov.as_slice());
        return Ok(None);
    };
    let set = dense.canonical(center, silent);
    let base = dense.base(center, p, set)?;
    match means.get(k, silent).filter(|_| inexact == 0) {
        Some(mean) => est.mean.copy_from_slice(mean),
        None => {
            information_sum(signals, replicas, state, k, est.mean.as_mut_slice());
            fixed::chol_solve(&base.chol, &mut est.mean);
            if inexact == 0 {
                means.put(k, silent, est.mean.as_slice());
            }
        }
    }
    dense.covariance_into(center, p, set, base, inexact, &mut est.cov)
}

/// (11): Σ_i of (C̄^e_k)^{-1} x̄^{e,i}_k for a sensor that sent, (C̄^p_k)^{-1} x̄^{p,i}_k for one
/// that sent at k - 1, (C̄^p_k)^{-1} x̃^{pp,i}_k (Algorithm 2) for one silent longer; from zero,
/// in sensor order, each `+=` as nalgebra's (element by element) — in fixed size for
/// dimensions 1..=6.
fn information_sum(
    signals: &Signals,
    replicas: &Replicas,
    state: &[SensorState],
    k: usize,
    out: &mut [f64],
) {
    match out.len() {
        1 => sum_fixed::<1>(signals, replicas, state, k, out),
        2 => sum_fixed::<2>(signals, replicas, state, k, out),
        3 => sum_fixed::<3>(signals, replicas, state, k, out),
        4 => sum_fixed::<4>(signals, replicas, state, k, out),
        5 => sum_fixed::<5>(signals, replicas, state, k, out),
        6 => sum_fixed::<6>(signals, replicas, state, k, out),
        _ => {
            out.fill(0.0);
            for (i, st) in state.iter().enumerate() {
                fixed::add_assign(out, information_term(signals, replicas, st, k, i));
            }
        }
    }
}

/// Sensor i's term of (11) (see [`information_sum`]).
#[inline(always)]
fn information_term<'a>(
    signals: &'a Signals,
    replicas: &'a Replicas,
    st: &SensorState,
    k: usize,
    i: usize,
) -> &'a [f64] {
    match st.silent_steps {
        0 => signals.at(&signals.info_sent, k, i),
        1 => signals.at(&signals.info_omitted, k, i),
        _ => replicas.info(st.entry),
    }
}

#[inline(always)]
fn sum_fixed<const N: usize>(
    signals: &Signals,
    replicas: &Replicas,
    state: &[SensorState],
    k: usize,
    out: &mut [f64],
) {
    let mut acc = [0.0; N];
    for (i, st) in state.iter().enumerate() {
        let term: &[f64; N] = information_term(signals, replicas, st, k, i)
            .try_into()
            .expect("N entries");
        for j in 0..N {
            acc[j] += term[j];
        }
    }
    out.copy_from_slice(&acc);
}
