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
//!
//! On a link that loses packets ([`Losses`]) the sensors are unchanged (they never learn of a
//! loss) and the center's view of each sensor ([`CenterView`]) counts the steps since its last
//! estimate *arrived*: Algorithm 2 then extrapolates from that estimate (the replica entry of
//! that step, shared as above), and Algorithm 1 — whose sensors never omit twice, so a second
//! missing step is a loss — takes the center's loss fallback ([`super::loss`], the center's own
//! function on the estimate that arrived, which [`Signals`] keeps).
use super::center::{canonical_silence, loss_fallback, DkfCenter};
use super::loss::{self, Streak};
use super::replica::Replicas;
use super::sensor::Trigger;
use super::signals::Signals;
use super::{DistributedKfScheme, Fusion};
use crate::filter::Gaussian;
use crate::linalg::fixed;
use crate::linalg::{Matrix, Vector};
use crate::link::Message;
use crate::network::Traffic;
use crate::scheme::fast_path::{BatchSink, FastTrialError, Losses, TrialCache};
use crate::scheme::SchemeError;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;
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
    losses: Option<&Losses>,
    coins: &mut [Xoshiro256PlusPlus],
    cache: &mut TrialCache,
    sink: &mut dyn BatchSink,
) -> Option<Result<(), FastTrialError>> {
    let plan = &scheme.plan;
    let losses = losses.filter(|l| l.any(steps));
    // A lost estimate with a singular A: the generic center's plain extrapolation.
    if losses.is_some() && plan.a_inv().is_none() {
        return None;
    }
    let key = (Arc::as_ptr(plan) as usize, measurements.as_ptr() as usize);
    // Whether the trial is covered depends on the plan and the data only (the key), so it is
    // checked once per trial too.
    let track: &mut Option<Track> = cache.get_or_insert_with(key, || {
        covered(scheme, measurements, steps)
            .then(|| {
                let sys = &scheme.system;
                let (n, ns) = (sys.state_dim(), sys.n_sensors());
                Track {
                    signals: Signals::compute(scheme, measurements, steps),
                    replicas: Replicas::new(n, ns, steps),
                    means: Means::new(n, ns, steps),
                }
            })
            // An estimate beyond the single range arrives non-finite, which the generic
            // center rejects at its step.
            .filter(|t| t.signals.xbar_e.iter().all(|v| v.is_finite()))
    });
    let track = track.as_mut()?;
    Some(match losses {
        None => run_variant::<false>(scheme, track, steps, None, coins, sink),
        Some(_) => run_variant::<true>(scheme, track, steps, losses, coins, sink),
    })
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

/// Where a variant's sensor stands: consecutive silent steps before the current one (every
/// sensor is scheduled at every step), and for Algorithm 2 its replica's entry at the current
/// step.
#[derive(Clone, Copy, Default)]
struct SensorState {
    silent_steps: usize,
    entry: u32,
}

/// What the center holds of a sensor (DkfCenter's per-sensor state): consecutive steps without
/// its estimate, the current one included (the sensor's own count on an ideal link), the
/// replica entry of its last estimate to arrive (Algorithm 2, missing twice or more), and
/// whether it is under the loss fallback (Algorithm 1, missing twice or more: a loss; its
/// streak is in [`Fallback::streaks`]).
#[derive(Clone, Copy, Default)]
struct CenterView {
    missing: usize,
    entry: u32,
    fallback: bool,
}

/// A sensor and the center's view of it.
#[derive(Clone, Copy, Default)]
struct Node {
    sensor: SensorState,
    center: CenterView,
}

/// The loss fallback's work space: per sensor its streak and its term (C̄^p_k)^{-1} x̃^{pp,i}_k
/// of (11), the step's summed second moments, and the number of sensors under it this step.
struct Fallback {
    streaks: Vec<Option<Streak>>,
    terms: Vec<f64>,
    moment: Matrix,
    count: usize,
    /// x̄^{e,i}_s of the streak being started; the common prior's mean for s = 0.
    received: Vector,
    prior: Vector,
    contribution: Vector,
    tmp: Vector,
}

/// One variant's trial; `LOSSY`: whether `losses` is `Some` (on an ideal link the center's view
/// of every sensor is the sensor's own, which the compiler then knows).
fn run_variant<const LOSSY: bool>(
    scheme: &DistributedKfScheme,
    track: &mut Track,
    steps: usize,
    losses: Option<&Losses>,
    coins: &mut [Xoshiro256PlusPlus],
    sink: &mut dyn BatchSink,
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
    let bounded = matches!(scheme.fusion, Fusion::Bounded { .. });
    let message = Message::Estimate(Vector::zeros(n));
    let (msg_bits, msg_frame_bits) = (message.bits(), message.frame_bits());
    let mut nodes = vec![Node::default(); ns];
    let mut fallback = Fallback {
        streaks: vec![None; ns],
        terms: vec![0.0; ns * n],
        moment: Matrix::zeros(n, n),
        count: 0,
        received: Vector::zeros(n),
        prior: sys.prior.mean.clone(),
        contribution: Vector::zeros(n),
        tmp: Vector::zeros(n),
    };
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
        let mut lost = 0u64;
        let mut senders = 0u128;
        fallback.count = 0;
        for (i, (node, rng)) in nodes.iter_mut().zip(coins.iter_mut()).enumerate() {
            let Node {
                sensor: st,
                center: cv,
            } = node;
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
            if send {
                st.silent_steps = 0;
                messages += 1;
                senders |= crate::network::sensor_bit(i);
            } else {
                st.silent_steps += 1;
            }
            // The link: a lost estimate is a silence at the center.
            let arrived = send && !(LOSSY && losses.is_some_and(|l| l.lost(i, k)));
            lost += u64::from(send && !arrived);
            // The center's bookkeeping (DkfCenter::step).
            if arrived {
                cv.missing = 0;
                if cv.fallback {
                    cv.fallback = false;
                    fallback.streaks[i] = None;
                }
                continue;
            }
            cv.missing += 1;
            silent |= 1 << i;
            if bounded {
                // Algorithm 2's replica of the center's held estimate (the sensor's own
                // entry when the center holds what the sensor believes it holds).
                cv.entry = if !LOSSY || cv.missing == st.silent_steps {
                    st.entry
                } else if cv.missing == 1 {
                    replicas
                        .after_send(plan, signals, i, k - 1)
                        .map_err(err(k))?
                } else {
                    replicas
                        .advance(plan, signals, cv.entry, i, k)
                        .map_err(err(k))?
                };
            }
            if cv.missing >= 2 {
                match &scheme.fusion {
                    Fusion::OmittedEstimates => {
                        fallback
                            .add(plan, &scheme.fusion, signals, cv, (i, k))
                            .map_err(err(k))?;
                    }
                    Fusion::Bounded { .. } => inexact += 1,
                }
            }
        }
        let factor = if fallback.count > 0 {
            fallback
                .fuse(center, signals, replicas, &nodes, (k, p), silent, &mut est)
                .map_err(err(k))?;
            None
        } else {
            fuse(
                center, signals, replicas, means, &nodes, k, p, silent, inexact, &mut est,
            )
            .map_err(err(k))?
        };
        let traffic = Traffic {
            messages,
            bits: messages * msg_bits,
            frame_bits: messages * msg_frame_bits,
            lost,
            senders,
            scheduled: crate::network::all_sensors(ns),
            ..Traffic::default()
        };
        sink.step(0, k, &est, factor, traffic)
            .map_err(|source| FastTrialError::Sink { k, source })?;
    }
    Ok(())
}

impl Fallback {
    /// Sensor i's estimate is missing at k for the second time or more under Algorithm 1 (a
    /// loss): the center's loss fallback, its term of (11) into `terms`, its moment summed.
    #[cold]
    #[inline(never)]
    fn add(
        &mut self,
        plan: &super::plan::GlobalizedPlan,
        fusion: &Fusion,
        signals: &Signals,
        cv: &mut CenterView,
        (i, k): (usize, usize),
    ) -> Result<(), SchemeError> {
        if self.count == 0 {
            self.moment.fill(0.0);
        }
        let s = k - cv.missing;
        let streak = &mut self.streaks[i];
        if streak.is_none() {
            // x̄^{e,i}_s, as it arrived.
            if s == 0 {
                self.received.copy_from(&self.prior);
            } else {
                let x = signals.at(&signals.xbar_e, s, i);
                self.received.copy_from_slice(x);
            }
        }
        let out = (&mut self.contribution, &mut self.moment);
        loss_fallback(plan, fusion, streak, (i, s, k), &self.received, out)?;
        cv.fallback = true;
        let m = plan.at(k)?;
        crate::linalg::fixed::gemv(&mut self.tmp, &m.cbar_p_inv, &self.contribution);
        let n = self.tmp.len();
        self.terms[i * n..(i + 1) * n].copy_from_slice(self.tmp.as_slice());
        self.count += 1;
        Ok(())
    }

    /// The center's step k with `count` sensors under the loss fallback: (11) in sensor order,
    /// solved with (10)'s factor of the silence set, the covariance inflated
    /// ([`loss::inflate`]), as DkfCenter::step does.
    #[allow(clippy::too_many_arguments)]
    fn fuse(
        &self,
        center: &DkfCenter,
        signals: &Signals,
        replicas: &Replicas,
        view: &[Node],
        (k, p): (usize, usize),
        silent: u64,
        est: &mut Gaussian,
    ) -> Result<(), SchemeError> {
        let fused = center.fused_covariance(p, canonical_silence(&center.class, silent), 0)?;
        information_sum(
            signals,
            replicas,
            &self.terms,
            view,
            k,
            est.mean.as_mut_slice(),
        );
        fixed::chol_solve(&fused.chol, &mut est.mean);
        let m = center.plan().at(k)?;
        est.cov = loss::inflate(&fused.cov, &m.cbar_p_inv, &self.moment, self.count);
        Ok(())
    }
}

/// The center's step k (DkfCenter::step) when no sensor is under the loss fallback: (11)'s
/// information vector in sensor order, solved with (10)'s Cholesky factor, and the fused
/// covariance, into `est`. Returns the NEES factor of `est.cov` (`fixed::nees_factor`) when the
/// covariance is a copy of a memoized one that keeps it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn fuse<'c>(
    center: &'c DkfCenter,
    signals: &Signals,
    replicas: &Replicas,
    means: &mut Means,
    view: &[Node],
    k: usize,
    p: usize,
    silent: u64,
    inexact: usize,
    est: &mut Gaussian,
) -> Result<Option<&'c [f64]>, SchemeError> {
    let Some(dense) = center.dense_memo() else {
        let fused =
            center.fused_covariance(p, canonical_silence(&center.class, silent), inexact)?;
        information_sum(signals, replicas, &[], view, k, est.mean.as_mut_slice());
        fixed::chol_solve(&fused.chol, &mut est.mean);
        est.cov.as_mut_slice().copy_from_slice(fused.cov.as_slice());
        return Ok(None);
    };
    let set = dense.canonical(center, silent);
    let base = dense.base(center, p, set)?;
    match means.get(k, silent).filter(|_| inexact == 0) {
        Some(mean) => est.mean.copy_from_slice(mean),
        None => {
            information_sum(signals, replicas, &[], view, k, est.mean.as_mut_slice());
            fixed::chol_solve(&base.chol, &mut est.mean);
            if inexact == 0 {
                means.put(k, silent, est.mean.as_slice());
            }
        }
    }
    dense.covariance_into(center, p, set, base, inexact, &mut est.cov)
}

/// (11): Σ_i of (C̄^e_k)^{-1} x̄^{e,i}_k for a sensor whose estimate arrived, (C̄^p_k)^{-1}
/// x̄^{p,i}_k for one whose estimate of k - 1 did, (C̄^p_k)^{-1} x̃^{pp,i}_k (Algorithm 2) or
/// the loss fallback's term in `fallback` for one missing longer; from zero, in sensor order,
/// each `+=` as nalgebra's (element by element) — in fixed size for dimensions 1..=6.
fn information_sum(
    signals: &Signals,
    replicas: &Replicas,
    fallback: &[f64],
    view: &[Node],
    k: usize,
    out: &mut [f64],
) {
    let terms = Terms {
        signals,
        replicas,
        fallback,
        k,
    };
    match out.len() {
        1 => sum_fixed::<1>(&terms, view, out),
        2 => sum_fixed::<2>(&terms, view, out),
        3 => sum_fixed::<3>(&terms, view, out),
        4 => sum_fixed::<4>(&terms, view, out),
        5 => sum_fixed::<5>(&terms, view, out),
        6 => sum_fixed::<6>(&terms, view, out),
        _ => {
            out.fill(0.0);
            for (i, node) in view.iter().enumerate() {
                fixed::add_assign(out, terms.of(&node.center, i));
            }
        }
    }
}

/// Where the sensors' terms of (11) at step k are (see [`information_sum`]).
struct Terms<'a> {
    signals: &'a Signals,
    replicas: &'a Replicas,
    /// The loss fallback's terms, `n` per sensor (read only for a sensor under it).
    fallback: &'a [f64],
    k: usize,
}

impl<'a> Terms<'a> {
    /// Sensor i's term.
    #[inline(always)]
    fn of(&self, cv: &CenterView, i: usize) -> &'a [f64] {
        let (signals, k) = (self.signals, self.k);
        match cv.missing {
            0 => signals.at(&signals.info_sent, k, i),
            1 => signals.at(&signals.info_omitted, k, i),
            _ if cv.fallback => &self.fallback[i * signals.n..(i + 1) * signals.n],
            _ => self.replicas.info(cv.entry),
        }
    }
}

#[inline(always)]
fn sum_fixed<const N: usize>(terms: &Terms, view: &[Node], out: &mut [f64]) {
    let mut acc = [0.0; N];
    for (i, node) in view.iter().enumerate() {
        let term: &[f64; N] = terms.of(&node.center, i).try_into().expect("N entries");
        for j in 0..N {
            acc[j] += term[j];
        }
    }
    out.copy_from_slice(&acc);
}
