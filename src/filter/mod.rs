//! Filters as step functions: each takes the model by reference and the estimate by value and
//! returns the next estimate; only the simulator owns a time loop.
pub mod information;
pub mod kf;
pub mod particle;
pub mod tobit;

use crate::linalg::{LinalgError, Matrix, Vector};

/// A Gaussian estimate: mean and covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Gaussian {
    pub mean: Vector,
    pub cov: Matrix,
}

impl Gaussian {
    pub fn new(mean: Vector, cov: Matrix) -> Self {
        Self { mean, cov }
    }
    /// State dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }
}

/// Why a filter step failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    #[error("{what}: {source}")]
    Matrix {
        what: &'static str,
        source: LinalgError,
    },
    #[error("measurement has {got} components, sensor expects {expected}")]
    MeasurementDimension { expected: usize, got: usize },
    #[error("measurement is not finite: {0:?}")]
    NonFiniteMeasurement(Vec<f64>),
}
