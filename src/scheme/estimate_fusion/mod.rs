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

use crate::filter::{kf, FilterError, Gaussian};
use crate::linalg::fixed;
use crate::linalg::{cholesky_into, mahalanobis_sq, symmetrize, Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::model::{LinearSensor, LinearTransition, MeasurementModel};
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
    let mut g = Gaussian::new(Vector::zeros(n), Matrix::zeros(n, n));
    unpack_into(v, n, &mut g).then_some(g)
}

/// [`unpack`] into `out` (of dimension `n`); `false`, leaving `out` as it was, when `v` has the
/// wrong length.
pub fn unpack_into(v: &Vector, n: usize, out: &mut Gaussian) -> bool {
    if v.len() != n + n * (n + 1) / 2 {
        return false;
    }
    out.mean.copy_from(&v.rows(0, n));
    let mut t = n;
    for i in 0..n {
        for j in i..n {
            out.cov[(i, j)] = v[t];
            out.cov[(j, i)] = v[t];
            t += 1;
        }
    }
    true
}

/// Buffers of [`update_linear`] for a linear sensor (m readings) on an n-dimensional state.
#[derive(Debug, Clone)]
struct LinearUpdateWork {
    /// `H^T` (n x m), copied once (a transpose is exact).
    ht: Matrix,
    /// `H x^-`, then the innovation `nu = z - H x^-` (m).
    hx: Vector,
    nu: Vector,
    /// `H P^-` (m x n), `S` (m x m) and the storage of its Cholesky factor.
    hp: Matrix,
    s: Matrix,
    factor: Matrix,
    /// `K^T = S^{-1} H P^-` (m x n), `K` (n x m), `K nu` (n).
    kt: Matrix,
    k: Matrix,
    knu: Vector,
    /// `I - K H`, its transpose, `(I - K H) P^-` (n x n).
    i_kh: Matrix,
    i_kh_t: Matrix,
    prod: Matrix,
    /// `K R` (n x m), `K R K^T` (n x n).
    kr: Matrix,
    krk: Matrix,
}

impl LinearUpdateWork {
    fn new(sensor: &LinearSensor) -> Self {
        let (m, n) = (sensor.h().nrows(), sensor.h().ncols());
        Self {
            ht: sensor.h().transpose(),
            hx: Vector::zeros(m),
            nu: Vector::zeros(m),
            hp: Matrix::zeros(m, n),
            s: Matrix::zeros(m, m),
            factor: Matrix::zeros(m, m),
            kt: Matrix::zeros(m, n),
            k: Matrix::zeros(n, m),
            knu: Vector::zeros(n),
            i_kh: Matrix::zeros(n, n),
            i_kh_t: Matrix::zeros(n, n),
            prod: Matrix::zeros(n, n),
            kr: Matrix::zeros(n, m),
            krk: Matrix::zeros(n, n),
        }
    }
}

/// [`kf::update`] of `est` with a linear sensor's reading `z`, in place through `w`: the same
/// checks, products (nalgebra's gemm and gemv, as `a * b` computes them, through the `fixed`
/// kernels that are those bit for bit), Cholesky factor and solves (`kf::gain`'s
/// `chol.solve(H P^-)` as `fixed::chol_solve_matrix`), the Joseph form
/// `(I - K H) P^- (I - K H)^T + K R K^T` and the symmetrization, in the same order, hence the
/// same bits, without allocating. On an error `est` may be partly updated (the
/// step fails).
fn update_linear(
    sensor: &LinearSensor,
    est: &mut Gaussian,
    z: &Vector,
    w: &mut LinearUpdateWork,
) -> Result<(), FilterError> {
    kf::check_measurement(sensor, z)?;
    let (h, r) = (sensor.h(), sensor.noise_cov());
    // kf::innovation: nu = z - H x^-, S = H P^- H^T + R symmetrized.
    fixed::gemv(&mut w.hx, h, &est.mean);
    for ((nu, zi), hx) in w.nu.iter_mut().zip(z.iter()).zip(w.hx.iter()) {
        *nu = zi - hx;
    }
    fixed::gemm(&mut w.hp, h, &est.cov);
    fixed::gemm(&mut w.s, &w.hp, &w.ht);
    fixed::add_assign(w.s.as_mut_slice(), r.as_slice());
    symmetrize(&mut w.s);
    // kf::gain: K^T = S^{-1} (H P^-).
    let chol = cholesky_into(&w.s, &mut w.factor).map_err(|source| FilterError::Matrix {
        what: "innovation covariance S",
        source,
    })?;
    w.kt.copy_from(&w.hp);
    fixed::chol_solve_matrix(&chol, &mut w.kt);
    w.factor = chol.unpack_dirty();
    w.k.tr_copy_from(&w.kt);
    // x = x^- + K nu.
    fixed::gemv(&mut w.knu, &w.k, &w.nu);
    fixed::add_assign(est.mean.as_mut_slice(), w.knu.as_slice());
    // I - K H.
    fixed::gemm(&mut w.i_kh, &w.k, h);
    let n = est.mean.len();
    for j in 0..n {
        for i in 0..n {
            let id = if i == j { 1.0 } else { 0.0 };
            w.i_kh[(i, j)] = id - w.i_kh[(i, j)];
        }
    }
    // ((I - K H) P^-) (I - K H)^T + (K R) K^T, symmetrized.
    fixed::gemm(&mut w.prod, &w.i_kh, &est.cov);
    w.i_kh_t.tr_copy_from(&w.i_kh);
    fixed::gemm(&mut est.cov, &w.prod, &w.i_kh_t);
    fixed::gemm(&mut w.kr, &w.k, r);
    fixed::gemm(&mut w.krk, &w.kr, &w.kt);
    fixed::add_assign(est.cov.as_mut_slice(), w.krk.as_slice());
    symmetrize(&mut est.cov);
    Ok(())
}

/// `kf::predict` of `est`, through `pred` (swapped in) and `work`: `predict_into`'s
/// operations are `predict`'s.
fn predict_in_place(
    model: &LinearTransition,
    est: &mut Gaussian,
    pred: &mut Gaussian,
    work: &mut kf::PredictWork,
) {
    kf::predict_into(model, est, pred, work);
    std::mem::swap(est, pred);
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
    /// Buffers of the step (a linear sensor's step allocates only its message).
    work: SensorWork,
}

#[derive(Debug, Clone)]
struct SensorWork {
    predict: kf::PredictWork,
    /// A prediction, swapped with the estimate it replaces.
    pred: Gaussian,
    /// `None` for a nonlinear sensor (the EKF step allocates).
    update: Option<LinearUpdateWork>,
    /// `x_i - x̃_i`.
    d: Vector,
}

impl LocalKfSensor {
    /// Sensor `index` of `system`, event threshold `delta` >= 0 (0: send every step).
    pub fn new(system: Arc<System>, index: usize, delta: f64) -> Result<Self, SchemeError> {
        let delta = nonnegative_delta(delta)?;
        let est = system.prior.clone();
        let work = SensorWork {
            predict: kf::PredictWork::new(est.dim()),
            pred: est.clone(),
            update: system.sensors[index].as_linear().map(LinearUpdateWork::new),
            d: Vector::zeros(est.dim()),
        };
        Ok(Self {
            copy: est.clone(),
            est,
            system,
            index,
            delta,
            last_k: 0,
            work,
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
        let w = &mut self.work;
        // Steps this node was not called at (no reading: not scheduled) pass in time for
        // the local filter and the mirrored copy alike, as the center's copy and replica do.
        for _ in self.last_k + 1..k {
            predict_in_place(model, &mut self.est, &mut w.pred, &mut w.predict);
            predict_in_place(model, &mut self.copy, &mut w.pred, &mut w.predict);
        }
        self.last_k = k;
        // kf::step: the prediction, then the update with the reading.
        match (&mut w.update, sensor.as_linear()) {
            (Some(u), Some(lin)) => {
                kf::predict_into(model, &self.est, &mut w.pred, &mut w.predict);
                update_linear(lin, &mut w.pred, z, u)?;
                std::mem::swap(&mut self.est, &mut w.pred);
            }
            _ => self.est = kf::step(model, &self.est, &[(sensor, z)])?,
        }
        predict_in_place(model, &mut self.copy, &mut w.pred, &mut w.predict);
        for ((d, x), c) in
            w.d.iter_mut()
                .zip(self.est.mean.iter())
                .zip(self.copy.mean.iter())
        {
            *d = x - c;
        }
        let moved = mahalanobis_sq(&w.d, &self.est.cov).map_err(|source| SchemeError::Matrix {
            what: "local covariance",
            source,
        })?;
        if moved > self.delta * self.delta || (self.delta == 0.0 && moved == 0.0) {
            self.copy.mean.copy_from(&self.est.mean);
            self.copy.cov.copy_from(&self.est.cov);
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
    /// Buffers of the step (a step allocates nothing).
    work: CenterWork,
}

#[derive(Debug, Clone)]
struct CenterWork {
    predict: kf::PredictWork,
    /// A prediction (swapped with the copy it replaces), or a replica's zero-mean update.
    pred: Gaussian,
    /// `F^T`, copied once (a transpose is exact), and `F P` of a replica's prediction.
    ft: Matrix,
    fp: Matrix,
    /// Per linear sensor: its update buffers and the reading `H 0` its replica updates with.
    updates: Vec<Option<(LinearUpdateWork, Vector)>>,
    fusion: ci::FusionWork,
}

impl EstimateFusionCenter {
    pub fn new(system: Arc<System>, rule: FusionRule) -> Self {
        let n = system.n_sensors();
        let prior = system.prior.clone();
        let dim = prior.dim();
        let work = CenterWork {
            predict: kf::PredictWork::new(dim),
            pred: prior.clone(),
            ft: system.transition.f().transpose(),
            fp: Matrix::zeros(dim, dim),
            updates: system
                .sensors
                .iter()
                .map(|s| {
                    s.as_linear()
                        .map(|l| (LinearUpdateWork::new(l), l.predict(&Vector::zeros(dim))))
                })
                .collect(),
            fusion: ci::FusionWork::new(n, dim),
        };
        Self {
            replicas: (0..n)
                .map(|i| (!sends_covariance(&system, i)).then(|| prior.cov.clone()))
                .collect(),
            copies: vec![prior.clone(); n],
            weights: vec![1.0 / n.max(1) as f64; n],
            est: prior,
            system,
            rule,
            work,
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
        let w = &mut self.work;
        for (i, msg) in inbox.iter().enumerate() {
            // The local Riccati recursion, by the very operations the sensor's KF performs
            // (its covariance does not depend on the mean for a linear sensor): kf::predict_cov,
            // then kf::update of (0, P^-) with the reading H 0; a sensor that was not scheduled
            // (no reading) only predicted.
            if let (Some(p), Some((u, z0))) = (&mut self.replicas[i], &mut w.updates[i]) {
                fixed::gemm(&mut w.fp, model.f(), p);
                fixed::gemm(&mut w.pred.cov, &w.fp, &w.ft);
                fixed::add_assign(w.pred.cov.as_mut_slice(), model.q().as_slice());
                symmetrize(&mut w.pred.cov);
                if !matches!(msg, Received::NotScheduled) {
                    let sensor = self.system.sensors[i].as_linear().expect("a replica's");
                    w.pred.mean.fill(0.0);
                    update_linear(sensor, &mut w.pred, z0, u)?;
                }
                std::mem::swap(p, &mut w.pred.cov);
            }
            let copy = &mut self.copies[i];
            match msg {
                Received::Estimate(v) => match &self.replicas[i] {
                    Some(p) if v.len() == n => {
                        copy.mean.copy_from(v);
                        copy.cov.copy_from(p);
                    }
                    None => {
                        if !unpack_into(v, n, copy) {
                            return Err(SchemeError::Protocol {
                                sensor: i,
                                message: format!(
                                    "expected an estimate and its covariance ({} reals), got {}",
                                    n + n * (n + 1) / 2,
                                    v.len()
                                ),
                            });
                        }
                    }
                    Some(_) => {
                        return Err(SchemeError::Protocol {
                            sensor: i,
                            message: format!("expected an estimate of {n} reals, got {}", v.len()),
                        })
                    }
                },
                Received::Silent | Received::NotScheduled => {
                    predict_in_place(model, copy, &mut w.pred, &mut w.predict)
                }
                other => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("estimate fusion expects estimates, got {other:?}"),
                    })
                }
            }
        }
        match self.rule {
            FusionRule::CovarianceIntersection => {
                ci::covariance_intersection_into(&self.copies, &mut self.est, &mut w.fusion)?;
                self.weights.copy_from_slice(w.fusion.weights());
            }
            FusionRule::NaiveSum => {
                self.weights.fill(1.0);
                ci::naive_sum_into(&self.copies, &mut self.est, &mut w.fusion)?;
            }
        }
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
