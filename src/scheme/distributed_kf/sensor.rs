//! Sensor node of the globalized distributed KF (Dormann et al.): runs the globalized local filter
//! (eq. (2) and the local filtering step of Section II), a standard KF beside it for the event
//! tests, and a replica of what the fusion center holds about it, so it can decide whether the
//! center's extrapolation is still good enough.
use super::plan::{GlobalizedPlan, PredictedDelta};
use crate::filter::kf::check_measurement;
use crate::linalg::{Matrix, Vector};
use crate::link::{Message, Transmission};
use crate::model::MeasurementModel;
use crate::scheme::{Feedback, SchemeError, SensorNode};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// When a sensor sends its globalized estimate.
#[derive(Debug, Clone, PartialEq)]
pub enum Trigger {
    /// Every step (the original globalized DKF of Section II).
    Always,
    /// Algorithm 1 with random communication: a sensor that was silent at k-1 must send;
    /// otherwise it sends with probability `send_probability`.
    Random { send_probability: f64 },
    /// Algorithm 1 with the event-based test (12): send when ||K^i_k (z^i_k - H^i x̂^{p,i}_k)||
    /// of the standard local KF exceeds `alpha`; a sensor silent at k-1 must send.
    Event { alpha: f64 },
    /// Algorithm 2's test (13): send when ||x̂^{pp,i}_k - x̂^{e,i}_k|| > alpha (standard KF,
    /// predicted since the last transmission) or when d̃ d̃^T ≤ B fails, i.e.
    /// d̃^T B^{-1} d̃ > 1 (for SPD B the two are equivalent by the Schur complement).
    Bounded { alpha: f64, b_inv: Matrix },
}

impl Trigger {
    /// Send probability of Algorithm 1's random communication that yields the average rate
    /// `rate` in [0.5, 1]: with forced sends after a silent step, the fraction of sending steps
    /// is 1 / (2 - p), so p = 2 - 1/rate.
    pub fn random_for_rate(rate: f64) -> Self {
        Trigger::Random {
            send_probability: (2.0 - 1.0 / rate).clamp(0.0, 1.0),
        }
    }

    /// Whether this trigger enforces Algorithm 1's "every other step" rule.
    pub(crate) fn every_other_step(&self) -> bool {
        matches!(self, Trigger::Random { .. } | Trigger::Event { .. })
    }
}

/// One sensor of the globalized distributed KF.
///
/// A step allocates nothing but the message it sends: every matrix it needs is in the shared
/// plan, the vectors live in buffers of the node, and each product is the same gemv the
/// expression form `a * &x` runs, so the numbers are those of the textbook form bit for bit.
#[derive(Debug, Clone)]
pub struct DkfSensor {
    plan: Arc<GlobalizedPlan>,
    index: usize,
    sensor: Arc<dyn MeasurementModel>,
    trigger: Trigger,
    /// Globalized estimate x̄^{e,i}_k.
    xbar: Vector,
    /// Standard local KF estimate x̂^{e,i}_k.
    kf: Vector,
    /// Replica of the center: last sent globalized estimate as the center received it (a
    /// single per component, [`crate::link::as_sent`]: the rounding is deterministic, so the
    /// sensor knows it), predicted since (x̄^{pp,i}).
    held: Vector,
    /// Debiasing matrix of the last sent estimate, predicted since (Δ^{pp,i}): a link of the
    /// plan's shared chain ([`GlobalizedPlan::delta_head`]); `None` when A is singular.
    held_delta: Option<Arc<PredictedDelta>>,
    /// Standard KF estimate at the last transmission, predicted since (x̂^{pp,i}).
    kf_held: Vector,
    /// Consecutive silent steps before the current one.
    silent_steps: usize,
    /// Work space: x̄^{p,i}_k, and state- and measurement-sized temporaries.
    xbar_p: Vector,
    tmp: Vector,
    tmp2: Vector,
    zbuf: Vector,
    zbuf2: Vector,
}

impl DkfSensor {
    /// Sensor `index` of the plan's system, starting from the common prior mean.
    pub fn new(
        plan: Arc<GlobalizedPlan>,
        index: usize,
        sensor: Arc<dyn MeasurementModel>,
        prior_mean: Vector,
        trigger: Trigger,
    ) -> Self {
        let n = prior_mean.len();
        let m = sensor.meas_dim();
        Self {
            held_delta: plan.delta_head(index, 0),
            plan,
            index,
            sensor,
            trigger,
            xbar: prior_mean.clone(),
            kf: prior_mean.clone(),
            held: prior_mean.clone(),
            kf_held: prior_mean,
            silent_steps: 0,
            xbar_p: Vector::zeros(n),
            tmp: Vector::zeros(n),
            tmp2: Vector::zeros(n),
            zbuf: Vector::zeros(m),
            zbuf2: Vector::zeros(m),
        }
    }

    /// The globalized estimate x̄^{e,i} after the last step.
    pub fn globalized_estimate(&self) -> &Vector {
        &self.xbar
    }

    /// The standard local KF estimate after the last step.
    pub fn local_kf_estimate(&self) -> &Vector {
        &self.kf
    }
}

/// `x <- a x` through the buffer `tmp` (the same gemv as `a * &x`).
pub(crate) fn predict_in_place(a: &Matrix, x: &mut Vector, tmp: &mut Vector) {
    crate::linalg::fixed::gemv(tmp, a, x);
    std::mem::swap(x, tmp);
}

impl SensorNode for DkfSensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        _feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        check_measurement(self.sensor.as_ref(), z)?;
        let p = self.plan.index(k)?;
        let m = self.plan.at(k)?;
        let a = self.plan.a();
        let i = self.index;
        // Globalized prediction (2) and local filtering step (Section II):
        // x̄^e = C̄^e (C̄^p)^{-1} x̄^p + C̄^e H^T R^{-1} z.
        crate::linalg::fixed::gemv(&mut self.xbar_p, a, &self.xbar);
        crate::linalg::fixed::gemv(&mut self.xbar, &m.prediction_weight, &self.xbar_p);
        crate::linalg::fixed::gemv(&mut self.tmp, &m.measurement_weight[i], z);
        self.xbar += &self.tmp;
        // Standard KF beside it: x̂^e = x̂^p + K (z - h(x̂^p)); `kf` holds x̂^p, `tmp2` the
        // correction.
        predict_in_place(a, &mut self.kf, &mut self.tmp);
        match self.sensor.as_linear() {
            Some(lin) => crate::linalg::fixed::gemv(&mut self.zbuf2, lin.h(), &self.kf),
            None => self.zbuf2.copy_from(&self.sensor.predict(&self.kf)),
        }
        self.zbuf.copy_from(z);
        self.zbuf -= &self.zbuf2;
        crate::linalg::fixed::gemv(&mut self.tmp2, &m.kf_gain[i], &self.zbuf);
        self.kf += &self.tmp2;
        // Replica of the center's extrapolation.
        predict_in_place(a, &mut self.held, &mut self.tmp);
        predict_in_place(a, &mut self.kf_held, &mut self.tmp);
        let bounded = matches!(self.trigger, Trigger::Bounded { .. });
        if bounded {
            if self.plan.a_inv().is_none() {
                return Err(SchemeError::Unsupported(
                    "Algorithm 2 needs an invertible system matrix".into(),
                ));
            }
            let next = self.held_delta.as_ref().map(|d| d.next(&self.plan));
            self.held_delta = next;
        }

        let u: f64 = rng.random();
        let must_send = self.trigger.every_other_step() && self.silent_steps >= 1;
        let send = must_send
            || match &self.trigger {
                Trigger::Always => true,
                Trigger::Random { send_probability } => u < *send_probability,
                Trigger::Event { alpha } => self.tmp2.norm() > *alpha,
                Trigger::Bounded { alpha, b_inv } => {
                    let pd = self.held_delta.as_ref().expect("checked invertible");
                    // d̃ = x̃^{pp} - x̄^p, into `tmp`.
                    debiased_extrapolation_into(
                        &m.delta_p[i],
                        pd,
                        self.held.as_slice(),
                        &mut self.tmp2,
                        &mut self.tmp,
                    )?;
                    self.tmp -= &self.xbar_p;
                    // kf_held - kf, into `tmp2`.
                    self.tmp2.copy_from(&self.kf_held);
                    self.tmp2 -= &self.kf;
                    let far = self.tmp2.norm() > *alpha;
                    far || {
                        crate::linalg::fixed::gemv(&mut self.tmp2, b_inv, &self.tmp);
                        self.tmp.dot(&self.tmp2) > 1.0
                    }
                }
            };
        if send {
            self.held.copy_from(&self.xbar);
            crate::link::round_as_sent(self.held.as_mut_slice());
            self.kf_held.copy_from(&self.kf);
            if bounded {
                self.held_delta = self.plan.delta_head(i, p);
            }
            self.silent_steps = 0;
            Ok(Transmission::Send(Message::Estimate(self.xbar.clone())))
        } else {
            self.silent_steps += 1;
            Ok(Transmission::Silent)
        }
    }
}

/// `out = Δ^{p,i}_k (Δ^{pp,i}_k)^{-1} x̄^{pp,i}_k` with the LU factors of Δ^{pp,i} given and
/// `work` as scratch: [`debiased_extrapolation`] without allocating, same operations (the
/// fixed-size LU solve is bit for bit nalgebra's). `held` is x̄^{pp,i}_k's entries.
pub fn debiased_extrapolation_into(
    delta_p: &Matrix,
    delta_pp: &PredictedDelta,
    held: &[f64],
    work: &mut Vector,
    out: &mut Vector,
) -> Result<(), SchemeError> {
    work.copy_from_slice(held);
    if !delta_pp.lu.solve(work) {
        return Err(SchemeError::Unsupported(
            "debiasing matrix Δ^pp is singular".into(),
        ));
    }
    crate::linalg::fixed::gemv(out, delta_p, work);
    Ok(())
}

/// x̃^{pp,i}_k = Δ^{p,i}_k (Δ^{pp,i}_k)^{-1} x̄^{pp,i}_k (Section IV).
pub fn debiased_extrapolation(
    delta_p: &Matrix,
    delta_pp: &Matrix,
    held: &Vector,
) -> Result<Vector, SchemeError> {
    let solved = delta_pp
        .clone()
        .lu()
        .solve(held)
        .ok_or_else(|| SchemeError::Unsupported("debiasing matrix Δ^pp is singular".into()))?;
    Ok(delta_p * solved)
}
