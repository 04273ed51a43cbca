//! Kalman filter in information form: Y = P^{-1}, y = P^{-1} x. Fusing independent sensors is
//! a sum (seed 004 Section II, centralized fusion; seed 003 eq. (9), (12)), which is why
//! fusion centers use this form.
use super::{FilterError, Gaussian};
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::model::LinearSensor;

/// Information matrix and vector of a Gaussian.
#[derive(Debug, Clone, PartialEq)]
pub struct Information {
    /// Information matrix Y = P^{-1}.
    pub matrix: Matrix,
    /// Information vector y = P^{-1} x.
    pub vector: Vector,
}

impl Information {
    /// Converts a covariance-form estimate.
    pub fn from_gaussian(g: &Gaussian) -> Result<Self, FilterError> {
        let chol = cholesky(&g.cov).map_err(|source| FilterError::Matrix {
            what: "covariance",
            source,
        })?;
        let vector = chol.solve(&g.mean);
        let mut matrix = chol.inverse();
        symmetrize(&mut matrix);
        Ok(Self { matrix, vector })
    }

    /// Back to covariance form.
    pub fn to_gaussian(&self) -> Result<Gaussian, FilterError> {
        let chol = cholesky(&self.matrix).map_err(|source| FilterError::Matrix {
            what: "information matrix",
            source,
        })?;
        let mean = chol.solve(&self.vector);
        let mut cov = chol.inverse();
        symmetrize(&mut cov);
        Ok(Gaussian { mean, cov })
    }

    /// Adds one linear measurement: Y += H^T R^{-1} H, y += H^T R^{-1} z
    /// (seed 004, centralized filtering step).
    pub fn add_measurement(
        &mut self,
        sensor: &LinearSensor,
        z: &Vector,
    ) -> Result<(), FilterError> {
        crate::filter::kf::check_measurement(sensor, z)?;
        self.matrix += sensor.information();
        self.vector += sensor.ht_rinv() * z;
        Ok(())
    }
}

/// Information-form update of a prediction with any subset of linear sensors' measurements.
pub fn update(
    prediction: &Gaussian,
    measurements: &[(&LinearSensor, &Vector)],
) -> Result<Gaussian, FilterError> {
    let mut info = Information::from_gaussian(prediction)?;
    for (sensor, z) in measurements {
        info.add_measurement(sensor, z)?;
    }
    info.to_gaussian()
}

/// `Y^{-1}` and `Y^{-1} y` from information parts held separately (used by the fusion
/// centers, which build Y and y by sums).
pub fn solve(matrix: &Matrix, vector: &Vector) -> Result<Gaussian, FilterError> {
    Information {
        matrix: matrix.clone(),
        vector: vector.clone(),
    }
    .to_gaussian()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::kf;
    use crate::linalg::{matrix_from_rows, relative_difference};
    use crate::model::presets;
    use proptest::prelude::*;

    proptest! {
        /// Information form equals covariance form (Joseph update) for random priors and
        /// measurements of a 2-D constant-velocity state.
        #[test]
        fn information_equals_covariance_form(
            m in proptest::collection::vec(-10.0f64..10.0, 4),
            diag in proptest::collection::vec(0.1f64..10.0, 4),
            z1 in proptest::collection::vec(-10.0f64..10.0, 2),
            z2 in -10.0f64..10.0,
        ) {
            let model = presets::constant_velocity_2d(0.5, 1.0).unwrap();
            let prior = Gaussian::new(
                Vector::from_vec(m),
                Matrix::from_diagonal(&Vector::from_vec(diag)),
            );
            let pred = kf::predict(&model, &prior);
            let pos = LinearSensor::new(
                matrix_from_rows(&[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]]),
                matrix_from_rows(&[vec![2.0, 0.5], vec![0.5, 1.0]]),
            ).unwrap();
            let vel = LinearSensor::new(
                matrix_from_rows(&[vec![0.0, 1.0, 0.0, 1.0]]),
                Matrix::from_element(1, 1, 0.3),
            ).unwrap();
            let z1 = Vector::from_vec(z1);
            let z2 = Vector::from_element(1, z2);
            let cov_form = kf::update(&vel, kf::update(&pos, pred.clone(), &z1).unwrap(), &z2).unwrap();
            let info_form = update(&pred, &[(&pos, &z1), (&vel, &z2)]).unwrap();
            prop_assert!(relative_difference(&cov_form.cov, &info_form.cov) < 1e-10);
            let dm = (&cov_form.mean - &info_form.mean).amax() / cov_form.mean.amax().max(1.0);
            prop_assert!(dm < 1e-10, "mean differs by {dm}");
        }
    }
}
