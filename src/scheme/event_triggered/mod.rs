//! Baselines of event-based estimation: a sensor sends its raw measurement only when an event
//! fires, and the fusion center's Kalman filter reads the silences too.
//!
//! - [`innovation`]: deterministic innovation trigger `||F_k^T (z_k - C x̂_k^-)||_∞ > δ` with
//!   the Gaussian approximation of the truncated innovation on silence (Wu, Jia, Johansson,
//!   Shi, "Event-based sensor data scheduling: trade-off between communication rate and
//!   estimation quality", IEEE TAC 58(4), 2013, Section III and Theorem 2).
//! - [`stochastic`]: stochastic triggers, open loop on `z_k` and closed loop on the innovation,
//!   whose silences keep the posterior Gaussian so that the center's filter is the exact MMSE
//!   estimator (Han, Mo, Wu, Weerakkody, Sinopoli, Shi, "Stochastic event-triggered sensor
//!   schedule for remote state estimation", IEEE TAC 60(10), 2015, Theorems 1 and 2).
//! - [`send_on_delta`]: send `z_k` when it moved by more than δ (in every component) since the
//!   last one sent; silence is ignored or read as a bounded, uniform measurement error.
//!
//! Every scheme has one bandwidth knob (δ, τ, δ) and sends less as it grows; at knob 0 each
//! sends every measurement and equals the all-send centralized KF
//! ([`crate::scheme::centralized::CentralizedKf`]) bit for bit.
//!
//! **Multi-sensor form.** The papers treat one sensor. Here every sensor triggers against the
//! same fused prediction x̂_k^- (fed back where the trigger needs it), and the center fuses all
//! sensors of a step at once in information form: a received z_i counts as a measurement with
//! noise R_i, a silence as a *pseudo-measurement* with an effective noise (the exact
//! silence likelihood for the stochastic triggers; the Gaussian approximation for the
//! deterministic ones). Given x_k the sensors' noises and coins are independent, so the
//! product of these per-sensor likelihoods is the joint one.
//!
//! **Bits.** A sent measurement costs 32 bits per component (uplink payload). Feedback, where
//! a trigger needs the fused prediction, is counted as downlink by the runner (see
//! [`crate::scheme::Feedback::bits`]).
//!
//! Sensor side and fusion side are separate types; a scheme builds a matched set:
//!
//! ```
//! use hushfuse::filter::Gaussian;
//! use hushfuse::linalg::{Matrix, Vector};
//! use hushfuse::link::Received;
//! use hushfuse::model::{presets, LinearSensor, MeasurementModel};
//! use hushfuse::scheme::event_triggered::stochastic::*;
//! use hushfuse::scheme::{FusionCenter, SensorNode, System};
//! use rand::SeedableRng;
//! use std::sync::Arc;
//!
//! let h = Matrix::from_row_slice(1, 2, &[1.0, 0.0]);
//! let sensor = LinearSensor::new(h, Matrix::from_element(1, 1, 1.0)).unwrap();
//! let system = Arc::new(System {
//!     transition: presets::constant_velocity_1d(1.0, 0.1).unwrap(),
//!     sensors: vec![Arc::new(sensor) as Arc<dyn MeasurementModel>],
//!     prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2)),
//! });
//! // Closed loop, Y = R^{-1} / tau^2 with tau = 1: silent with probability exp(-nu^2 / 2).
//! let trigger = StochasticTrigger::with_tau(&system, TriggerLoop::Closed, 1.0)?;
//! let mut node = StochasticTriggerSensor::new(system.clone(), 0, trigger.clone());
//! let mut center = StochasticTriggerCenter::new(system.clone(), trigger);
//! let mut coins = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
//! for k in 1..=10 {
//!     let z = Vector::from_element(1, 0.1 * k as f64);
//!     let fb = center.feedback(); // the fused prediction x̂_k^-
//!     let t = node.step(k, &z, fb.as_ref(), &mut coins)?;
//!     center.step(k, &[Received::from(t)])?;
//! }
//! assert!(center.estimate().cov[(0, 0)] < 1.0);
//! # Ok::<(), hushfuse::scheme::SchemeError>(())
//! ```
pub mod innovation;
pub mod params;
pub mod send_on_delta;
pub mod stochastic;
#[cfg(test)]
mod tests;

pub use innovation::{InnovationTriggerCenter, InnovationTriggerScheme, InnovationTriggerSensor};
pub use send_on_delta::{SendOnDeltaCenter, SendOnDeltaScheme, SendOnDeltaSensor, SilenceModel};
pub use stochastic::{
    StochasticTrigger, StochasticTriggerCenter, StochasticTriggerScheme, StochasticTriggerSensor,
    TriggerLoop,
};

use crate::filter::information::Information;
use crate::filter::{kf, FilterError, Gaussian};
use crate::linalg::{spd_inverse, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::MeasurementModel;
use crate::scheme::{Feedback, SchemeError, System};

/// What one sensor contributes to a step's update at the fusion center.
#[derive(Debug, Clone, PartialEq)]
pub enum Evidence {
    /// Nothing (silence read as no measurement, or not scheduled).
    Nothing,
    /// A received measurement with the sensor's own noise R.
    Measurement(Vector),
    /// A silence read as the pseudo-measurement `z` with effective noise `r` (>= R).
    Pseudo { z: Vector, r: Matrix },
}

/// Fuses one step's evidence into the prediction `pred`: in information form (one sum per
/// step, the same operations as [`crate::scheme::centralized::CentralizedKf`], so all-send
/// runs agree bit for bit) when every sensor is linear, else by sequential EKF updates
/// linearized at the running estimate.
pub fn fuse(
    system: &System,
    pred: Gaussian,
    evidence: &[Evidence],
) -> Result<Gaussian, SchemeError> {
    let all_linear = system.sensors.iter().all(|s| s.as_linear().is_some());
    if all_linear {
        let mut info = Information::from_gaussian(&pred)?;
        for (i, ev) in evidence.iter().enumerate() {
            let sensor = system.sensors[i].as_linear().expect("checked linear");
            match ev {
                Evidence::Nothing => {}
                Evidence::Measurement(z) => info.add_measurement(sensor, z)?,
                Evidence::Pseudo { z, r } => {
                    kf::check_measurement(sensor, z)?;
                    let r_inv = spd_inverse(r).map_err(|source| SchemeError::Matrix {
                        what: "effective noise of a silence",
                        source,
                    })?;
                    let ht_rinv = sensor.h().transpose() * r_inv;
                    let mut add = &ht_rinv * sensor.h();
                    symmetrize(&mut add);
                    info.matrix += add;
                    info.vector += ht_rinv * z;
                }
            }
        }
        Ok(info.to_gaussian()?)
    } else {
        let mut e = pred;
        for (i, ev) in evidence.iter().enumerate() {
            let sensor = system.sensors[i].as_ref();
            e = match ev {
                Evidence::Nothing => e,
                Evidence::Measurement(z) => kf::update(sensor, e, z)?,
                Evidence::Pseudo { z, r } => update_with_noise(sensor, e, z, r)?,
            };
        }
        Ok(e)
    }
}

/// A KF/EKF update (Joseph form) of `est` with `z`, taking the measurement noise to be `r`
/// instead of the sensor's R.
pub fn update_with_noise(
    sensor: &dyn MeasurementModel,
    est: Gaussian,
    z: &Vector,
    r: &Matrix,
) -> Result<Gaussian, FilterError> {
    let mut inn = kf::innovation(sensor, &est, z)?;
    inn.s += r - sensor.noise_cov();
    symmetrize(&mut inn.s);
    let k = kf::gain(&est, &inn)?;
    let mean = &est.mean + &k * &inn.nu;
    let n = est.dim();
    let i_kh = Matrix::identity(n, n) - &k * &inn.h;
    let mut cov = &i_kh * &est.cov * i_kh.transpose() + &k * r * k.transpose();
    symmetrize(&mut cov);
    Ok(Gaussian { mean, cov })
}

/// The fused prediction a feedback carries: `(mean, cov)`, or a protocol error naming the
/// sensor.
fn prediction_feedback(
    sensor: usize,
    feedback: Option<&Feedback>,
    need_cov: bool,
) -> Result<(&Vector, Option<&Matrix>), SchemeError> {
    match feedback {
        Some(Feedback::Prediction { mean, cov }) if !need_cov || cov.is_some() => {
            Ok((mean, cov.as_ref()))
        }
        other => Err(SchemeError::Protocol {
            sensor,
            message: format!(
                "expected the fused prediction{} as feedback, got {other:?}",
                if need_cov { " with its covariance" } else { "" }
            ),
        }),
    }
}

/// The measurement a sensor sent, `None` for silence / not scheduled, or a protocol error.
fn received_measurement(i: usize, msg: &Received) -> Result<Option<&Vector>, SchemeError> {
    match msg {
        Received::Measurement(z) => Ok(Some(z)),
        Received::Silent | Received::NotScheduled => Ok(None),
        other => Err(SchemeError::Protocol {
            sensor: i,
            message: format!("expected a measurement or silence, got {other:?}"),
        }),
    }
}

/// Checks that the inbox has one entry per sensor.
fn check_inbox(system: &System, inbox: &[Received]) -> Result<(), SchemeError> {
    if inbox.len() != system.n_sensors() {
        return Err(SchemeError::Unsupported(format!(
            "inbox has {} entries for {} sensors",
            inbox.len(),
            system.n_sensors()
        )));
    }
    Ok(())
}

/// A threshold parameter: finite and >= 0.
fn nonnegative(field: &'static str, v: f64) -> Result<f64, SchemeError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(SchemeError::Invalid {
            field,
            message: format!("expected a finite number >= 0, got {v}"),
        })
    }
}
