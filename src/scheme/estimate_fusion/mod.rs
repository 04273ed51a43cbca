//! Estimate fusion: every sensor runs a local KF/EKF on its own measurements and sends its
//! state estimate; the center fuses the estimates by covariance intersection (consistent
//! whatever the correlations) or by the naive information sum (which ignores that the local
//! errors are correlated through the common process noise and the common prior, and is
//! overconfident for it). See [`ci`] for the fusion rules.
//!
//! **Send rule** (knob `delta`): the center holds a copy (x̃_i, P̃_i) of each sensor's last
//! estimate, predicted forward (x̃ ← F x̃, P̃ ← F P̃ F^T + Q) at every step the sensor is
//! silent; the sensor mirrors that copy and sends when its estimate has moved away from it,
//! `(x_i - x̃_i)^T P_i^{-1} (x_i - x̃_i) > delta²`. `delta = 0` (default) sends every step.
//! A sensor that has never sent is held at the prior predicted forward, which is what its
//! local KF started from.
//!
//! **What is sent and counted.** x_i as n reals (32 bits each, [`Message::Estimate`]). For a
//! linear sensor P_i is a deterministic function of the model (the local Riccati recursion
//! does not depend on the data), so the center runs that recursion itself and P_i is not
//! sent. For a nonlinear sensor P_i depends on the data (the EKF linearizes at the estimate),
//! so the message carries x_i followed by P_i's n(n+1)/2 distinct entries (the upper
//! triangle, row by row): n + n(n+1)/2 reals.
//!
//! Sensor side and fusion side are separate types:
//!
//! ```
//! use hushfuse::filter::Gaussian;
//! use hushfuse::linalg::{Matrix, Vector};
//! use hushfuse::link::Received;
//! use hushfuse::model::{presets, LinearSensor, MeasurementModel};
//! use hushfuse::scheme::estimate_fusion::*;
//! use hushfuse::scheme::{FusionCenter, SensorNode, System};
//! use rand::SeedableRng;
//! use std::sync::Arc;
//!
//! let h = Matrix::from_row_slice(1, 2, &[1.0, 0.0]);
//! let sensors: Vec<Arc<dyn MeasurementModel>> = (0..2)
//!     .map(|_| {
//!         let s = LinearSensor::new(h.clone(), Matrix::from_element(1, 1, 1.0)).unwrap();
//!         Arc::new(s) as Arc<dyn MeasurementModel>
//!     })
//!     .collect();
//! let system = Arc::new(System {
//!     transition: presets::constant_velocity_1d(1.0, 0.1).unwrap(),
//!     sensors,
//!     prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2)),
//! });
//! let mut nodes: Vec<LocalKfSensor> =
//!     (0..2).map(|i| LocalKfSensor::new(system.clone(), i, 0.0).unwrap()).collect();
//! let mut center = EstimateFusionCenter::new(system.clone(), FusionRule::CovarianceIntersection);
//! let mut coins = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
//! for k in 1..=5 {
//!     let z = Vector::from_element(1, k as f64);
//!     let inbox: Vec<Received> = nodes
//!         .iter_mut()
//!         .map(|n| n.step(k, &z, None, &mut coins).map(Received::from))
//!         .collect::<Result<_, _>>()?;
//!     center.step(k, &inbox)?;
//! }
//! // Two identical sensors: CI cannot beat one of them (it does not know they are independent).
//! let local = nodes[0].estimate();
//! assert!(center.estimate().cov[(0, 0)] >= local.cov[(0, 0)] - 1e-9);
//! # Ok::<(), hushfuse::scheme::SchemeError>(())
//! ```
pub mod ci;
pub mod params;
#[cfg(test)]
mod tests;

use crate::filter::{kf, Gaussian};
use crate::linalg::{mahalanobis_sq, Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::scheme::{
    Feedback, FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System,
};
use rand::RngCore;
use std::sync::Arc;

/// How the center fuses the sensors' estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionRule {
    /// Covariance intersection with the trace-minimizing weights ([`ci::covariance_intersection`]).
    CovarianceIntersection,
    /// The naive information sum ([`ci::naive_sum`]).
    NaiveSum,
}

/// Whether sensor `i`'s covariance must travel (nonlinear sensors; module doc).
fn sends_covariance(system: &System, i: usize) -> bool {
    system.sensors[i].as_linear().is_none()
}

/// x followed by the upper triangle of P, row by row.
pub fn pack(est: &Gaussian) -> Vector {
    let n = est.dim();
    let mut v = Vec::with_capacity(n + n * (n + 1) / 2);
    v.extend(est.mean.iter());
    for i in 0..n {
        for j in i..n {
            v.push(est.cov[(i, j)]);
        }
    }
    Vector::from_vec(v)
}

/// The inverse of [`pack`] for a state of dimension `n`.
pub fn unpack(v: &Vector, n: usize) -> Option<Gaussian> {
    if v.len() != n + n * (n + 1) / 2 {
        return None;
    }
    let mean = v.rows(0, n).into_owned();
    let mut cov = Matrix::zeros(n, n);
    let mut t = n;
    for i in 0..n {
        for j in i..n {
            cov[(i, j)] = v[t];
            cov[(j, i)] = v[t];
            t += 1;
        }
    }
    Some(Gaussian::new(mean, cov))
}

/// Sensor side: a local KF/EKF on the sensor's own measurements and the send rule.
#[derive(Debug, Clone)]
pub struct LocalKfSensor {
    system: Arc<System>,
    index: usize,
    delta: f64,
    est: Gaussian,
    /// The center's copy of this sensor's estimate, mirrored.
    copy: Gaussian,
    /// The last step this node was called at (0: none yet).
    last_k: usize,
}

impl LocalKfSensor {
    /// Sensor `index` of `system`, event threshold `delta` >= 0 (0: send every step).
    pub fn new(system: Arc<System>, index: usize, delta: f64) -> Result<Self, SchemeError> {
        let delta = nonnegative_delta(delta)?;
        let est = system.prior.clone();
        Ok(Self {
            copy: est.clone(),
            est,
            system,
            index,
            delta,
            last_k: 0,
        })
    }

    /// The local estimate after the last step.
    pub fn estimate(&self) -> &Gaussian {
        &self.est
    }
}

impl SensorNode for LocalKfSensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        _feedback: Option<&Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        let model = &self.system.transition;
        let sensor = self.system.sensors[self.index].as_ref();
        // Steps this node was not called at (no reading: not scheduled) pass in time for
        // the local filter and the mirrored copy alike, as the center's copy and replica do.
        for _ in self.last_k + 1..k {
            self.est = kf::predict(model, &self.est);
            self.copy = kf::predict(model, &self.copy);
        }
        self.last_k = k;
        self.est = kf::step(model, &self.est, &[(sensor, z)])?;
        self.copy = kf::predict(model, &self.copy);
        let d = &self.est.mean - &self.copy.mean;
        let moved = mahalanobis_sq(&d, &self.est.cov).map_err(|source| SchemeError::Matrix {
            what: "local covariance",
            source,
        })?;
        if moved > self.delta * self.delta || (self.delta == 0.0 && moved == 0.0) {
            self.copy = self.est.clone();
            let payload = if sends_covariance(&self.system, self.index) {
                pack(&self.est)
            } else {
                self.est.mean.clone()
            };
            Ok(Transmission::Send(Message::Estimate(payload)))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Fusion side: holds a copy of every sensor's estimate (replicating the local covariance
/// recursions of linear sensors) and fuses the copies by the rule.
#[derive(Debug, Clone)]
pub struct EstimateFusionCenter {
    system: Arc<System>,
    rule: FusionRule,
    /// Replicas of the linear sensors' local posterior covariances (`None`: nonlinear).
    replicas: Vec<Option<Matrix>>,
    copies: Vec<Gaussian>,
    weights: Vec<f64>,
    est: Gaussian,
}

impl EstimateFusionCenter {
    pub fn new(system: Arc<System>, rule: FusionRule) -> Self {
        let n = system.n_sensors();
        let prior = system.prior.clone();
        Self {
            replicas: (0..n)
                .map(|i| (!sends_covariance(&system, i)).then(|| prior.cov.clone()))
                .collect(),
            copies: vec![prior.clone(); n],
            weights: vec![1.0 / n.max(1) as f64; n],
            est: prior,
            system,
            rule,
        }
    }

    /// The weights of the last fusion (CI: the trace-minimizing ω; naive: all 1).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The center's copies of the sensors' estimates after the last step.
    pub fn copies(&self) -> &[Gaussian] {
        &self.copies
    }
}

impl FusionCenter for EstimateFusionCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        if inbox.len() != self.system.n_sensors() {
            return Err(SchemeError::Unsupported(format!(
                "inbox has {} entries for {} sensors",
                inbox.len(),
                self.system.n_sensors()
            )));
        }
        let model = &self.system.transition;
        let n = self.system.state_dim();
        for (i, msg) in inbox.iter().enumerate() {
            // The local Riccati recursion, by the very operations the sensor's KF performs
            // (its covariance does not depend on the mean for a linear sensor); a sensor that
            // was not scheduled (no reading) only predicted.
            if let Some(p) = &self.replicas[i] {
                let pred_cov = kf::predict_cov(model, p);
                self.replicas[i] = Some(if matches!(msg, Received::NotScheduled) {
                    pred_cov
                } else {
                    let sensor = self.system.sensors[i].as_ref();
                    let zero = Vector::zeros(n);
                    let z = sensor.predict(&zero);
                    kf::update(sensor, Gaussian::new(zero, pred_cov), &z)?.cov
                });
            }
            self.copies[i] = match msg {
                Received::Estimate(v) => match &self.replicas[i] {
                    Some(p) if v.len() == n => Gaussian::new(v.clone(), p.clone()),
                    None => unpack(v, n).ok_or_else(|| SchemeError::Protocol {
                        sensor: i,
                        message: format!(
                            "expected an estimate and its covariance ({} reals), got {}",
                            n + n * (n + 1) / 2,
                            v.len()
                        ),
                    })?,
                    Some(_) => {
                        return Err(SchemeError::Protocol {
                            sensor: i,
                            message: format!("expected an estimate of {n} reals, got {}", v.len()),
                        })
                    }
                },
                Received::Silent | Received::NotScheduled => kf::predict(model, &self.copies[i]),
                other => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("estimate fusion expects estimates, got {other:?}"),
                    })
                }
            };
        }
        self.est = match self.rule {
            FusionRule::CovarianceIntersection => {
                let (g, w) = ci::covariance_intersection(&self.copies)?;
                self.weights = w;
                g
            }
            FusionRule::NaiveSum => {
                self.weights = vec![1.0; self.copies.len()];
                ci::naive_sum(&self.copies)?
            }
        };
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
}

fn nonnegative_delta(delta: f64) -> Result<f64, SchemeError> {
    if delta.is_finite() && delta >= 0.0 {
        Ok(delta)
    } else {
        Err(SchemeError::Invalid {
            field: "delta",
            message: format!("expected a finite number >= 0, got {delta}"),
        })
    }
}

/// Local KFs sending estimates, fused by CI or the naive sum.
#[derive(Debug, Clone)]
pub struct EstimateFusionScheme {
    system: Arc<System>,
    rule: FusionRule,
    delta: f64,
}

impl EstimateFusionScheme {
    /// `delta` >= 0: the event threshold of the send rule (0: every step).
    pub fn new(system: Arc<System>, rule: FusionRule, delta: f64) -> Result<Self, SchemeError> {
        Ok(Self {
            system,
            rule,
            delta: nonnegative_delta(delta)?,
        })
    }
}

impl Scheme for EstimateFusionScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = (0..self.system.n_sensors())
            .map(|i| {
                LocalKfSensor::new(self.system.clone(), i, self.delta)
                    .map(|s| Box::new(s) as Box<dyn SensorNode>)
            })
            .collect::<Result<_, _>>()?;
        Ok(SchemeInstance {
            sensors,
            center: Box::new(EstimateFusionCenter::new(self.system.clone(), self.rule)),
        })
    }
}
