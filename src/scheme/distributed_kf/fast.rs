//! The fast trial of seed 004's schemes: the same sensors and fusion center as
//! [`super::DkfSensor`] and [`super::DkfCenter`], run without the generic loop.
//!
//! Most of a sensor's work does not depend on the variant: the globalized local filter
//! x̄^{e,i}_k (Section II) and the standard local KF beside it are functions of the measurements
//! only, and so are the fusion center's terms of (11) for an estimate that arrives
//! ((C̄^e_k)^{-1} x̄^{e,i}_k) and for one sent at k-1 and omitted at k ((C̄^p_k)^{-1} A x̄^{e,i}_{k-1},
//! since the center's held estimate is then exactly the sensor's prediction). A trial computes
//! them once in a [`Track`] shared by every variant of the plan (a sweep of rates, alphas and
//! bounds); a variant then only draws its coins, runs its trigger, and — for Algorithm 2 — the
//! extrapolation of estimates silent for two steps or more, which the sensor's test (13) and
//! the center's debiased contribution share. Every number is computed by the operations the
//! generic path performs, on the same operands, so it is the same bit for bit.
use super::center::canonical_silence;
use super::plan::PredictedDelta;
use super::sensor::{debiased_extrapolation_into, predict_in_place, Trigger};
use super::{DistributedKfScheme, Fusion};
use crate::filter::{fixed, Gaussian};
use crate::linalg::Vector;
use crate::link::Message;
use crate::network::Traffic;
use crate::scheme::{FastTrialError, SchemeError, StepSink, TrialCache};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// The variant-independent part of one trial, per step k and sensor i (index
/// `(k - 1) * sensors + i`, each entry `n` long).
pub(super) struct Track {
    n: usize,
    sensors: usize,
    /// x̄^{p,i}_k = A x̄^{e,i}_{k-1}.
    xbar_p: Vec<f64>,
    /// x̄^{e,i}_k, the estimate a sensor sends.
    xbar: Vec<f64>,
    /// The standard local KF's prediction and estimate.
    kf_p: Vec<f64>,
    kf: Vec<f64>,
    /// ||K^i_k (z^i_k - H^i x̂^{p,i}_k)||, the norm of test (12); one per (k, i).
    correction_norm: Vec<f64>,
    /// (C̄^e_k)^{-1} x̄^{e,i}_k: (11)'s term of an estimate that arrived.
    info_sent: Vec<f64>,
    /// (C̄^p_k)^{-1} x̄^{p,i}_k: (11)'s term of an estimate sent at k-1 and omitted at k.
    info_omitted: Vec<f64>,
}

impl Track {
    fn at<'a>(&self, v: &'a [f64], k: usize, i: usize) -> &'a [f64] {
        let o = ((k - 1) * self.sensors + i) * self.n;
        &v[o..o + self.n]
    }

    /// The sensors' steps of [`super::DkfSensor::step`] that do not depend on the trigger,
    /// and the center's two data terms, in the same operations.
    fn compute(scheme: &DistributedKfScheme, measurements: &[Vec<Vector>], steps: usize) -> Self {
        let plan = &scheme.plan;
        let sys = &scheme.system;
        let n = sys.state_dim();
        let ns = sys.n_sensors();
        let len = steps * ns * n;
        let mut t = Track {
            n,
            sensors: ns,
            xbar_p: Vec::with_capacity(len),
            xbar: Vec::with_capacity(len),
            kf_p: Vec::with_capacity(len),
            kf: Vec::with_capacity(len),
            correction_norm: Vec::with_capacity(steps * ns),
            info_sent: Vec::with_capacity(len),
            info_omitted: Vec::with_capacity(len),
        };
        let a = plan.a();
        let mut xbar: Vec<Vector> = vec![sys.prior.mean.clone(); ns];
        let mut kf: Vec<Vector> = vec![sys.prior.mean.clone(); ns];
        let mut xbar_p = Vector::zeros(n);
        let mut tmp = Vector::zeros(n);
        let mut tmp2 = Vector::zeros(n);
        let mut zbuf: Vec<Vector> = sys
            .sensors
            .iter()
            .map(|s| Vector::zeros(s.meas_dim()))
            .collect();
        let mut zbuf2 = zbuf.clone();
        for (k, zs) in (1..=steps).zip(measurements) {
            let m = plan.at(k).expect("checked horizon");
            for (i, (s, z)) in sys.sensors.iter().zip(zs).enumerate() {
                let lin = s
                    .as_linear()
                    .expect("the plan exists only for linear sensors");
                let (xbar, kf) = (&mut xbar[i], &mut kf[i]);
                crate::filter::fixed::gemv(&mut xbar_p, a, xbar);
                crate::filter::fixed::gemv(xbar, &m.prediction_weight, &xbar_p);
                crate::filter::fixed::gemv(&mut tmp, &m.measurement_weight[i], z);
                fixed::add_assign(xbar.as_mut_slice(), tmp.as_slice());
                predict_in_place(a, kf, &mut tmp);
                t.kf_p.extend_from_slice(kf.as_slice());
                let (zbuf, zbuf2) = (&mut zbuf[i], &mut zbuf2[i]);
                crate::filter::fixed::gemv(zbuf2, lin.h(), kf);
                zbuf.copy_from_slice(z.as_slice());
                fixed::sub_assign(zbuf.as_mut_slice(), zbuf2.as_slice());
                crate::filter::fixed::gemv(&mut tmp2, &m.kf_gain[i], zbuf);
                fixed::add_assign(kf.as_mut_slice(), tmp2.as_slice());
                t.correction_norm.push(fixed::norm(tmp2.as_slice()));
                t.xbar_p.extend_from_slice(xbar_p.as_slice());
                t.xbar.extend_from_slice(xbar.as_slice());
                t.kf.extend_from_slice(kf.as_slice());
                crate::filter::fixed::gemv(&mut tmp, &m.cbar_e_inv, xbar);
                t.info_sent.extend_from_slice(tmp.as_slice());
                crate::filter::fixed::gemv(&mut tmp, &m.cbar_p_inv, &xbar_p);
                t.info_omitted.extend_from_slice(tmp.as_slice());
            }
        }
        t
    }
}

/// `v += w` as nalgebra's `+=` does it (element by element, `v_j + w_j`).
fn add(v: &mut Vector, w: &[f64]) {
    fixed::add_assign(v.as_mut_slice(), w);
}

/// Per-sensor state of Algorithm 2's replica of the center (the sensor's and the center's
/// copies are the same numbers, so one serves both).
struct Held {
    /// x̄^{pp,i}: the last sent estimate, predicted since.
    held: Vector,
    /// x̂^{pp,i}: the standard KF at the last transmission, predicted since.
    kf_held: Vector,
    /// Δ^{pp,i}.
    delta: Option<Arc<PredictedDelta>>,
    /// This step's debiased extrapolation x̃^{pp,i} (test (13) and the center's term).
    debiased: Vector,
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
    let sys = &scheme.system;
    let ns = sys.n_sensors();
    let covered = ns <= 64
        && measurements.len() >= steps
        && plan.at(steps).is_ok()
        && plan.index(steps).is_ok()
        && measurements[..steps].iter().all(|zs| {
            zs.len() == ns
                && zs
                    .iter()
                    .zip(&sys.sensors)
                    .all(|(z, s)| z.len() == s.meas_dim() && z.iter().all(|v| v.is_finite()))
        });
    if !covered {
        return None;
    }
    let key = (Arc::as_ptr(plan) as usize, measurements.as_ptr() as usize);
    let track: &Track =
        cache.get_or_insert_with(key, || Track::compute(scheme, measurements, steps));
    Some(run_variant(scheme, track, steps, rng, sink))
}

fn run_variant(
    scheme: &DistributedKfScheme,
    track: &Track,
    steps: usize,
    rng: &mut dyn RngCore,
    sink: &mut dyn StepSink,
) -> Result<(), FastTrialError> {
    let plan = &scheme.plan;
    let sys = &scheme.system;
    let center = &scheme.proto;
    let n = sys.state_dim();
    let ns = sys.n_sensors();
    let a = plan.a();
    let bounded = matches!(scheme.trigger, Trigger::Bounded { .. });
    let every_other = scheme.trigger.every_other_step();
    let message = Message::Estimate(Vector::zeros(n));
    let (msg_bits, msg_frame_bits) = (message.bits(), message.frame_bits());
    // Sensor i's consecutive silent steps before the current one (the center's count after
    // a silent step is this plus one: every sensor is scheduled at every step).
    let mut silent_steps = vec![0usize; ns];
    let mut held: Vec<Held> = if bounded {
        (0..ns)
            .map(|i| Held {
                held: sys.prior.mean.clone(),
                kf_held: sys.prior.mean.clone(),
                delta: plan.delta_head(i, 0),
                debiased: Vector::zeros(n),
            })
            .collect()
    } else {
        Vec::new()
    };
    let mut est = Gaussian::new(Vector::zeros(n), sys.prior.cov.clone());
    let (mut tmp, mut tmp2, mut work) = (Vector::zeros(n), Vector::zeros(n), Vector::zeros(n));
    let err = |k: usize| move |source: SchemeError| FastTrialError::Scheme { k, source };
    for k in 1..=steps {
        let p = plan.index(k).map_err(err(k))?;
        let m = plan.at(k).map_err(err(k))?;
        est.mean.fill(0.0);
        let mut silent = 0u64;
        let mut inexact = 0usize;
        let mut messages = 0u64;
        for i in 0..ns {
            let xbar_p = track.at(&track.xbar_p, k, i);
            let kf = track.at(&track.kf, k, i);
            // The sensor (DkfSensor::step): its replica of the center, then the trigger.
            if bounded {
                let h = &mut held[i];
                if silent_steps[i] == 0 {
                    // Sent at k-1: the prediction of what was sent is the sensor's own.
                    h.held.copy_from_slice(xbar_p);
                    h.kf_held.copy_from_slice(track.at(&track.kf_p, k, i));
                } else {
                    predict_in_place(a, &mut h.held, &mut tmp);
                    predict_in_place(a, &mut h.kf_held, &mut tmp);
                }
                h.delta = h.delta.as_ref().map(|d| d.next(plan));
            }
            let u: f64 = rng.random();
            let must_send = every_other && silent_steps[i] >= 1;
            let send = must_send
                || match &scheme.trigger {
                    Trigger::Always => true,
                    Trigger::Random { send_probability } => u < *send_probability,
                    Trigger::Event { alpha } => track.correction_norm[(k - 1) * ns + i] > *alpha,
                    Trigger::Bounded { alpha, b_inv } => {
                        let h = &mut held[i];
                        let pd = h.delta.as_ref().expect("A is invertible for Algorithm 2");
                        debiased_extrapolation_into(
                            &m.delta_p[i],
                            pd,
                            &h.held,
                            &mut work,
                            &mut h.debiased,
                        )
                        .map_err(err(k))?;
                        // d̃ = x̃^{pp} - x̄^p.
                        tmp.copy_from_slice(h.debiased.as_slice());
                        fixed::sub_assign(tmp.as_mut_slice(), xbar_p);
                        tmp2.copy_from_slice(h.kf_held.as_slice());
                        fixed::sub_assign(tmp2.as_mut_slice(), kf);
                        let far = fixed::norm(tmp2.as_slice()) > *alpha;
                        far || {
                            crate::filter::fixed::gemv(&mut tmp2, b_inv, &tmp);
                            fixed::dot(tmp.as_slice(), tmp2.as_slice()) > 1.0
                        }
                    }
                };
            // The center (DkfCenter::step): (11) in sensor order.
            if send {
                if bounded {
                    let h = &mut held[i];
                    h.held.copy_from_slice(track.at(&track.xbar, k, i));
                    h.kf_held.copy_from_slice(kf);
                    h.delta = plan.delta_head(i, p);
                }
                silent_steps[i] = 0;
                messages += 1;
                add(&mut est.mean, track.at(&track.info_sent, k, i));
            } else {
                silent_steps[i] += 1;
                silent |= 1 << i;
                if silent_steps[i] == 1 {
                    add(&mut est.mean, track.at(&track.info_omitted, k, i));
                } else {
                    match &scheme.fusion {
                        Fusion::OmittedEstimates => {
                            return Err(err(k)(SchemeError::Protocol {
                                sensor: i,
                                message: format!(
                                    "silent for {} steps; Algorithm 1 needs a \
                                     transmission at least every other step",
                                    silent_steps[i]
                                ),
                            }))
                        }
                        Fusion::Bounded { .. } => {
                            inexact += 1;
                            crate::filter::fixed::gemv(&mut tmp, &m.cbar_p_inv, &held[i].debiased);
                            add(&mut est.mean, tmp.as_slice());
                        }
                    }
                }
            }
        }
        let fused = center
            .fused_covariance(p, canonical_silence(&center.class, silent), inexact)
            .map_err(err(k))?;
        crate::filter::fixed::chol_solve(&fused.chol, &mut est.mean);
        est.cov.copy_from_slice(fused.cov.as_slice());
        let traffic = Traffic {
            messages,
            bits: messages * msg_bits,
            frame_bits: messages * msg_frame_bits,
            downlink_bits: 0,
        };
        sink.step(k, &est, traffic)
            .map_err(|source| FastTrialError::Sink { k, source })?;
    }
    Ok(())
}
