//! Motion and sensor models, as small capability traits so that each filter asks only for what
//! it uses: a Kalman filter needs a [`LinearTransition`] and a [`MeasurementModel`]'s Jacobian;
//! the extended Kalman filter is the same update with the Jacobian evaluated at the prediction.
pub mod nonlinear;
pub mod presets;
pub mod sensor;
pub mod transition;

pub use nonlinear::{Placement, RangeSensor, RssSensor};
pub use sensor::{LinearSensor, MeasurementModel};
pub use transition::LinearTransition;

/// Why a model could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("{what}: expected {expected}, got {got}")]
    Dimension {
        what: &'static str,
        expected: String,
        got: String,
    },
    #[error("{what}: {source}")]
    Covariance {
        what: &'static str,
        source: crate::linalg::LinalgError,
    },
    #[error("{what} must be finite and positive, got {value}")]
    Parameter { what: &'static str, value: f64 },
}

/// Test support: a linear sensor that hides its linearity (`as_linear()` is `None`), so
/// filters take their nonlinear (EKF) paths on a model whose exact answer is known.
#[cfg(test)]
#[derive(Debug)]
pub(crate) struct Opaque(pub LinearSensor);

#[cfg(test)]
impl MeasurementModel for Opaque {
    fn state_dim(&self) -> usize {
        self.0.state_dim()
    }
    fn meas_dim(&self) -> usize {
        self.0.meas_dim()
    }
    fn predict(&self, x: &crate::linalg::Vector) -> crate::linalg::Vector {
        self.0.predict(x)
    }
    fn jacobian(&self, x: &crate::linalg::Vector) -> crate::linalg::Matrix {
        self.0.jacobian(x)
    }
    fn noise_cov(&self) -> &crate::linalg::Matrix {
        self.0.noise_cov()
    }
    fn noise_sqrt(&self) -> &crate::linalg::Matrix {
        self.0.noise_sqrt()
    }
}
