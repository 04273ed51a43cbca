//! Sensor models z = h(x) + v, v ~ N(0, R).
use super::ModelError;
use crate::linalg::{cholesky, Matrix, Vector};
use rand::RngCore;
use rand_distr::{Distribution, StandardNormal};
use std::fmt::Debug;

/// What every filter asks of a sensor: the predicted measurement, its Jacobian (the matrix
/// itself for a linear sensor, which makes the EKF update equal the KF update), and the noise.
pub trait MeasurementModel: Debug + Send + Sync {
    /// State dimension the sensor expects.
    fn state_dim(&self) -> usize;
    /// Measurement dimension.
    fn meas_dim(&self) -> usize;
    /// Noise-free measurement h(x).
    fn predict(&self, x: &Vector) -> Vector;
    /// Jacobian of h at x.
    fn jacobian(&self, x: &Vector) -> Matrix;
    /// Measurement noise covariance R.
    fn noise_cov(&self) -> &Matrix;
    /// Lower Cholesky factor of R, for sampling.
    fn noise_sqrt(&self) -> &Matrix;
    /// `Some(H)` when h(x) = H x; schemes that are exact only for linear sensors ask this.
    fn as_linear(&self) -> Option<&LinearSensor> {
        None
    }
    /// The sensor's planar position, for sensors that have one (used to activate the sensors
    /// nearest to the target).
    fn position(&self) -> Option<[f64; 2]> {
        None
    }
    /// State indices of the target position the sensor measures from, for placed sensors.
    fn target_indices(&self) -> Option<[usize; 2]> {
        None
    }
    /// h(x) for `n` states at once, for particle filters: `component(j)` is the j-th state
    /// component of every state (contiguous), and row r of h(x_p) goes to `out[r * n + p]`.
    /// The default goes state by state; the sensors here override it with loops over whole
    /// components that the compiler vectorizes.
    fn predict_many<'a>(&self, component: &dyn Fn(usize) -> &'a [f64], n: usize, out: &mut [f64]) {
        let d = self.state_dim();
        let mut x = Vector::zeros(d);
        for p in 0..n {
            for j in 0..d {
                x[j] = component(j)[p];
            }
            let z = self.predict(&x);
            for (r, v) in z.iter().enumerate() {
                out[r * n + p] = *v;
            }
        }
    }
    /// Draw z = h(x) + v.
    fn sample(&self, x: &Vector, rng: &mut dyn RngCore) -> Vector {
        let v = Vector::from_fn(self.meas_dim(), |_, _| StandardNormal.sample(rng));
        self.predict(x) + self.noise_sqrt() * v
    }
}

/// Linear sensor z = H x + v, v ~ N(0, R), with R positive definite.
#[derive(Debug, Clone)]
pub struct LinearSensor {
    h: Matrix,
    r: Matrix,
    r_sqrt: Matrix,
    r_inv: Matrix,
    /// H^T R^{-1}, used by every information-form update.
    ht_rinv: Matrix,
    /// H^T R^{-1} H, the information one measurement carries.
    info: Matrix,
}

impl LinearSensor {
    /// Validates `R` (symmetric positive definite) and that it matches `H`'s rows.
    pub fn new(h: Matrix, r: Matrix) -> Result<Self, ModelError> {
        if r.nrows() != h.nrows() || r.ncols() != h.nrows() {
            return Err(ModelError::Dimension {
                what: "measurement noise R",
                expected: format!("{m}x{m} (H has {m} rows)", m = h.nrows()),
                got: format!("{}x{}", r.nrows(), r.ncols()),
            });
        }
        if h.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Covariance {
                what: "measurement matrix H",
                source: crate::linalg::LinalgError::NonFinite,
            });
        }
        crate::linalg::check_spd(&r).map_err(|source| ModelError::Covariance {
            what: "measurement noise R",
            source,
        })?;
        let chol = cholesky(&r).map_err(|source| ModelError::Covariance {
            what: "measurement noise R",
            source,
        })?;
        let r_sqrt = chol.l();
        let mut r_inv = chol.inverse();
        crate::linalg::symmetrize(&mut r_inv);
        let ht_rinv = h.transpose() * &r_inv;
        let mut info = &ht_rinv * &h;
        crate::linalg::symmetrize(&mut info);
        Ok(Self {
            h,
            r,
            r_sqrt,
            r_inv,
            ht_rinv,
            info,
        })
    }

    /// The measurement matrix H.
    pub fn h(&self) -> &Matrix {
        &self.h
    }
    /// R^{-1}.
    pub fn r_inv(&self) -> &Matrix {
        &self.r_inv
    }
    /// H^T R^{-1}.
    pub fn ht_rinv(&self) -> &Matrix {
        &self.ht_rinv
    }
    /// H^T R^{-1} H.
    pub fn information(&self) -> &Matrix {
        &self.info
    }
}

impl MeasurementModel for LinearSensor {
    fn state_dim(&self) -> usize {
        self.h.ncols()
    }
    fn meas_dim(&self) -> usize {
        self.h.nrows()
    }
    fn predict(&self, x: &Vector) -> Vector {
        &self.h * x
    }
    fn jacobian(&self, _x: &Vector) -> Matrix {
        self.h.clone()
    }
    fn noise_cov(&self) -> &Matrix {
        &self.r
    }
    fn noise_sqrt(&self) -> &Matrix {
        &self.r_sqrt
    }
    fn as_linear(&self) -> Option<&LinearSensor> {
        Some(self)
    }
    fn predict_many<'a>(&self, component: &dyn Fn(usize) -> &'a [f64], n: usize, out: &mut [f64]) {
        for r in 0..self.h.nrows() {
            let row = &mut out[r * n..(r + 1) * n];
            row.fill(0.0);
            for j in 0..self.h.ncols() {
                let c = self.h[(r, j)];
                if c != 0.0 {
                    for (o, x) in row.iter_mut().zip(component(j)) {
                        *o += c * x;
                    }
                }
            }
        }
    }
}
