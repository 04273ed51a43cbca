//! Sensor node of the globalized distributed KF (seed 004): runs the globalized local filter
//! (eq. (2) and the local filtering step of Section II), a standard KF beside it for the event
//! tests, and a replica of what the fusion center holds about it, so it can decide whether the
//! center's extrapolation is still good enough.
use super::plan::GlobalizedPlan;
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
    fn every_other_step(&self) -> bool {
        matches!(self, Trigger::Random { .. } | Trigger::Event { .. })
    }
}

/// One sensor of the globalized distributed KF.
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
    /// Replica of the center: last sent globalized estimate, predicted since (x̄^{pp,i}).
    held: Vector,
    /// Debiasing matrix of the last sent estimate, predicted since (Δ^{pp,i}).
    held_delta: Matrix,
    /// Standard KF estimate at the last transmission, predicted since (x̂^{pp,i}).
    kf_held: Vector,
    /// Consecutive silent steps before the current one.
    silent_steps: usize,
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
        Self {
            plan,
            index,
            sensor,
            trigger,
            xbar: prior_mean.clone(),
            kf: prior_mean.clone(),
            held: prior_mean.clone(),
            held_delta: Matrix::identity(n, n),
            kf_held: prior_mean,
            silent_steps: 0,
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

impl SensorNode for DkfSensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        _feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        check_measurement(self.sensor.as_ref(), z)?;
        let m = self.plan.at(k)?;
        let a = self.plan.a();
        let i = self.index;
        // Globalized prediction (2) and local filtering step (Section II).
        let xbar_p = a * &self.xbar;
        self.xbar = &m.prediction_weight * &xbar_p + &m.measurement_weight[i] * z;
        // Standard KF beside it.
        let kf_p = a * &self.kf;
        let correction = &m.kf_gain[i] * (z - self.sensor.predict(&kf_p));
        self.kf = &kf_p + &correction;
        // Replica of the center's extrapolation.
        self.held = a * &self.held;
        self.kf_held = a * &self.kf_held;
        let bounded = matches!(self.trigger, Trigger::Bounded { .. });
        if bounded {
            let a_inv = self.plan.a_inv().ok_or_else(|| {
                SchemeError::Unsupported("Algorithm 2 needs an invertible system matrix".into())
            })?;
            self.held_delta = a * &self.held_delta * a_inv;
        }

        let u: f64 = rng.random();
        let must_send = self.trigger.every_other_step() && self.silent_steps >= 1;
        let send = must_send
            || match &self.trigger {
                Trigger::Always => true,
                Trigger::Random { send_probability } => u < *send_probability,
                Trigger::Event { alpha } => correction.norm() > *alpha,
                Trigger::Bounded { alpha, b_inv } => {
                    let d =
                        debiased_difference(&m.delta_p[i], &self.held_delta, &self.held, &xbar_p)?;
                    (&self.kf_held - &self.kf).norm() > *alpha || d.dot(&(b_inv * &d)) > 1.0
                }
            };
        if send {
            self.held.copy_from(&self.xbar);
            self.kf_held.copy_from(&self.kf);
            if bounded {
                self.held_delta.copy_from(&m.delta_e[i]);
            }
            self.silent_steps = 0;
            Ok(Transmission::Send(Message::Estimate(self.xbar.clone())))
        } else {
            self.silent_steps += 1;
            Ok(Transmission::Silent)
        }
    }
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

/// d̃^i_k = x̃^{pp,i}_k - x̄^{p,i}_k (Section IV).
fn debiased_difference(
    delta_p: &Matrix,
    delta_pp: &Matrix,
    held: &Vector,
    xbar_p: &Vector,
) -> Result<Vector, SchemeError> {
    Ok(debiased_extrapolation(delta_p, delta_pp, held)? - xbar_p)
}
