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
//! **Lossy links.** A message the link lost reaches the center as a silence. Every center here
//! has a loss-aware option beside the published one (`link_loss` = p, [`loss_aware`]), which
//! reads "nothing arrived" as a silence or a loss; absent (or 0) the published update runs,
//! bit for bit.
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
pub mod loss_aware;
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
use crate::linalg::fixed;
use crate::linalg::{cholesky_into, spd_inverse_into, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::{LinearSensor, MeasurementModel};
use crate::scheme::{Feedback, SchemeError, System};

/// What one sensor contributes to a step's update at the fusion center. Borrowed: the inbox
/// and the center's buffers hold the vectors, so that building it allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Evidence<'a> {
    /// Nothing (silence read as no measurement, or not scheduled).
    Nothing,
    /// A received measurement with the sensor's own noise R.
    Measurement(&'a Vector),
    /// A silence read as the pseudo-measurement `z` with effective noise `r` (>= R).
    Pseudo { z: &'a Vector, r: &'a Matrix },
}

/// Fuses one step's evidence (one entry per sensor, in sensor order) into the prediction
/// `pred`: [`Fusion`]'s update in a work space of its own (a center keeps one [`Fusion`]
/// instead, which allocates nothing per step).
pub fn fuse(
    system: &System,
    pred: &Gaussian,
    evidence: &[Evidence<'_>],
) -> Result<Gaussian, SchemeError> {
    let mut fusion = Fusion::new(system);
    fusion.start(pred)?;
    for (i, ev) in evidence.iter().enumerate() {
        fusion.add(system, i, *ev)?;
    }
    let mut out = pred.clone();
    fusion.finish(&mut out)?;
    Ok(out)
}

/// The fusion of one step, sensor by sensor, in buffers sized once: in information form (one
/// sum per step, the same operations as [`crate::scheme::centralized::CentralizedKf`], so
/// all-send runs agree bit for bit) when every sensor is linear, else by sequential EKF
/// updates linearized at the running estimate (that path allocates).
///
/// The linear path performs the operations of `Information::from_gaussian`, `add_measurement`
/// per measurement, `Y += sym(H^T R'^{-1} H)` and `y += H^T R'^{-1} z` per silence (R'^{-1}
/// by `spd_inverse`) and `to_gaussian`, in the same order, hence the same bits. The parts
/// `H^T R'^{-1}` and `sym(H^T R'^{-1} H)` of a silence are kept per sensor and computed again
/// only when R' changes (bit for bit): the stochastic triggers' and send-on-delta's R' are
/// fixed, so theirs are computed once; the innovation trigger's follows P^- every step.
///
/// A step is [`start`](Self::start), [`add`](Self::add) per sensor, [`finish`](Self::finish).
#[derive(Debug, Clone)]
pub struct Fusion {
    /// Every sensor linear (the information form).
    linear: bool,
    /// Y and y of the step.
    info: Information,
    /// The Cholesky factors of P^- and of Y are computed in this storage.
    factor: Matrix,
    /// H^T R^{-1} z.
    tmp: Vector,
    /// Per linear sensor, the information parts of its last silence.
    silences: Vec<SilenceParts>,
    /// The running estimate of the EKF path.
    running: Option<Gaussian>,
}

/// `sym(H^T R'^{-1} H)` and `H^T R'^{-1}` of a silence with effective noise R', with the R'
/// they were computed from.
#[derive(Debug, Clone)]
struct SilenceParts {
    /// R' of the parts below, valid when `computed`.
    r: Matrix,
    /// Whether the parts are those of `r` (false before the first silence and after a
    /// failed inverse).
    computed: bool,
    /// R'^{-1}, and the storage its Cholesky factor is computed in.
    r_inv: Matrix,
    factor: Matrix,
    /// H^T, copied once (a transpose is exact).
    ht: Matrix,
    /// H^T R'^{-1} (n x m).
    ht_rinv: Matrix,
    /// sym(H^T R'^{-1} H) (n x n).
    info: Matrix,
}

impl SilenceParts {
    fn new(sensor: &LinearSensor) -> Self {
        let (m, n) = (sensor.meas_dim(), sensor.state_dim());
        Self {
            r: Matrix::zeros(m, m),
            computed: false,
            r_inv: Matrix::zeros(m, m),
            factor: Matrix::zeros(m, m),
            ht: sensor.h().transpose(),
            ht_rinv: Matrix::zeros(n, m),
            info: Matrix::zeros(n, n),
        }
    }

    /// The parts for `r`: `R'^{-1} = spd_inverse(R')`, then `H^T R'^{-1}` and
    /// `(H^T R'^{-1}) H` as nalgebra's products (`fixed::gemm` is their kernel), symmetrized.
    /// Kept when `r` is the R' of the last call, bit for bit (the same operations would give
    /// the same parts).
    fn update(&mut self, sensor: &LinearSensor, r: &Matrix) -> Result<(), SchemeError> {
        let same = self.r.shape() == r.shape()
            && self
                .r
                .iter()
                .zip(r.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if self.computed && same {
            return Ok(());
        }
        self.computed = false;
        spd_inverse_into(r, &mut self.r_inv, &mut self.factor).map_err(|source| {
            SchemeError::Matrix {
                what: "effective noise of a silence",
                source,
            }
        })?;
        fixed::gemm(&mut self.ht_rinv, &self.ht, &self.r_inv);
        fixed::gemm(&mut self.info, &self.ht_rinv, sensor.h());
        symmetrize(&mut self.info);
        if self.r.shape() == r.shape() {
            self.r.copy_from(r);
        } else {
            self.r = r.clone();
        }
        self.computed = true;
        Ok(())
    }
}

impl Fusion {
    /// Buffers for `system`'s state and sensors.
    pub fn new(system: &System) -> Self {
        let n = system.prior.dim();
        let linear = system.sensors.iter().all(|s| s.as_linear().is_some());
        let silences = if linear {
            let parts = |s: &std::sync::Arc<dyn MeasurementModel>| {
                SilenceParts::new(s.as_linear().expect("checked linear"))
            };
            system.sensors.iter().map(parts).collect()
        } else {
            Vec::new()
        };
        Self {
            linear,
            info: Information {
                matrix: Matrix::zeros(n, n),
                vector: Vector::zeros(n),
            },
            factor: Matrix::zeros(n, n),
            tmp: Vector::zeros(n),
            silences,
            running: None,
        }
    }

    /// Starts a step from the prediction `pred`: `Information::from_gaussian` (y = P^{-1} x by
    /// the Cholesky solve, Y = P^{-1} symmetrized) in the buffers, or the EKF's running
    /// estimate.
    pub fn start(&mut self, pred: &Gaussian) -> Result<(), SchemeError> {
        if !self.linear {
            self.running = Some(pred.clone());
            return Ok(());
        }
        let chol =
            cholesky_into(&pred.cov, &mut self.factor).map_err(|source| FilterError::Matrix {
                what: "covariance",
                source,
            })?;
        let info = &mut self.info;
        info.vector.copy_from(&pred.mean);
        fixed::chol_solve(&chol, &mut info.vector);
        info.matrix.fill_with_identity();
        fixed::chol_solve_matrix(&chol, &mut info.matrix);
        self.factor = chol.unpack_dirty();
        symmetrize(&mut info.matrix);
        Ok(())
    }

    /// Adds the evidence of sensor `i` (sensors in order, after [`start`](Self::start)).
    pub fn add(
        &mut self,
        system: &System,
        i: usize,
        evidence: Evidence<'_>,
    ) -> Result<(), SchemeError> {
        if !self.linear {
            let sensor = system.sensors[i].as_ref();
            let e = self.running.take().expect("started");
            self.running = Some(match evidence {
                Evidence::Nothing => e,
                Evidence::Measurement(z) => kf::update(sensor, e, z)?,
                Evidence::Pseudo { z, r } => update_with_noise(sensor, e, z, r)?,
            });
            return Ok(());
        }
        let sensor = system.sensors[i].as_linear().expect("checked linear");
        let (matrix, ht_rinv, z) = match evidence {
            Evidence::Nothing => return Ok(()),
            // Information::add_measurement: Y += H^T R^{-1} H, y += H^T R^{-1} z.
            Evidence::Measurement(z) => {
                kf::check_measurement(sensor, z)?;
                (sensor.information(), sensor.ht_rinv(), z)
            }
            // Y += sym(H^T R'^{-1} H), y += H^T R'^{-1} z.
            Evidence::Pseudo { z, r } => {
                kf::check_measurement(sensor, z)?;
                let parts = &mut self.silences[i];
                parts.update(sensor, r)?;
                (&parts.info, &parts.ht_rinv, z)
            }
        };
        fixed::add_assign(self.info.matrix.as_mut_slice(), matrix.as_slice());
        fixed::gemv(&mut self.tmp, ht_rinv, z);
        fixed::add_assign(self.info.vector.as_mut_slice(), self.tmp.as_slice());
        Ok(())
    }

    /// A whole step on the measurements that arrived in `inbox` and nothing else (a silence
    /// adds nothing): [`start`](Self::start), [`add`](Self::add) of each sensor in order,
    /// [`finish`](Self::finish) into `out`. The loss-aware centers then update on each
    /// silence's mixture.
    pub fn fuse_received(
        &mut self,
        system: &System,
        pred: &Gaussian,
        inbox: &[Received],
        out: &mut Gaussian,
    ) -> Result<(), SchemeError> {
        self.start(pred)?;
        for (i, msg) in inbox.iter().enumerate() {
            let evidence = match received_measurement(i, msg)? {
                Some(z) => Evidence::Measurement(z),
                None => Evidence::Nothing,
            };
            self.add(system, i, evidence)?;
        }
        self.finish(out)
    }

    /// Ends the step: the fused estimate into `out` (sized for the state; `to_gaussian` in
    /// the buffers for the information form).
    pub fn finish(&mut self, out: &mut Gaussian) -> Result<(), SchemeError> {
        if !self.linear {
            *out = self.running.take().expect("started");
            return Ok(());
        }
        self.info.to_gaussian_into(out, &mut self.factor)?;
        Ok(())
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
