//! Motion-model presets. Each returns F and Q of a discretized continuous-time model.
use super::{LinearTransition, ModelError};
use crate::linalg::Matrix;

fn positive(what: &'static str, v: f64) -> Result<f64, ModelError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(ModelError::Parameter { what, value: v })
    }
}

/// Block-diagonal copy of `block` repeated `times` times.
fn block_diag(block: &Matrix, times: usize) -> Matrix {
    let b = block.nrows();
    let mut m = Matrix::zeros(b * times, b * times);
    for t in 0..times {
        m.view_mut((t * b, t * b), (b, b)).copy_from(block);
    }
    m
}

/// 1-D constant velocity, state (x, vx), continuous white-noise acceleration of intensity
/// `sigma2`: F = [[1, D], [0, 1]], Q = sigma2 [[D^3/3, D^2/2], [D^2/2, D]].
pub fn constant_velocity_1d(dt: f64, sigma2: f64) -> Result<LinearTransition, ModelError> {
    let d = positive("sampling interval dt", dt)?;
    let s = positive("noise intensity sigma2", sigma2)?;
    let f = Matrix::from_row_slice(2, 2, &[1.0, d, 0.0, 1.0]);
    let q = Matrix::from_row_slice(2, 2, &[d.powi(3) / 3.0, d * d / 2.0, d * d / 2.0, d]) * s;
    LinearTransition::new(f, q)
}

/// 1-D constant velocity with discrete white-noise acceleration (Zheng et al. (2014), Section VII):
/// Q = sigma2 [[D^4/4, D^3/2], [D^3/2, D^2]], rank one (the acceleration is constant over a
/// sampling interval).
pub fn constant_velocity_1d_discrete(dt: f64, sigma2: f64) -> Result<LinearTransition, ModelError> {
    let d = positive("sampling interval dt", dt)?;
    let s = positive("noise intensity sigma2", sigma2)?;
    let f = Matrix::from_row_slice(2, 2, &[1.0, d, 0.0, 1.0]);
    let q = Matrix::from_row_slice(
        2,
        2,
        &[d.powi(4) / 4.0, d.powi(3) / 2.0, d.powi(3) / 2.0, d * d],
    ) * s;
    LinearTransition::new(f, q)
}

/// 2-D constant velocity with discrete white-noise acceleration, state (x, vx, y, vy)
/// (Zheng et al. (2014), Section VII-C).
pub fn constant_velocity_2d_discrete(dt: f64, sigma2: f64) -> Result<LinearTransition, ModelError> {
    let one = constant_velocity_1d_discrete(dt, sigma2)?;
    LinearTransition::new(block_diag(one.f(), 2), block_diag(one.q(), 2))
}

/// 2-D constant velocity, state (x, vx, y, vy): two independent copies of the 1-D model.
pub fn constant_velocity_2d(dt: f64, sigma2: f64) -> Result<LinearTransition, ModelError> {
    let one = constant_velocity_1d(dt, sigma2)?;
    LinearTransition::new(block_diag(one.f(), 2), block_diag(one.q(), 2))
}

/// 2-D near-constant acceleration, state (x, vx, ax, y, vy, ay), continuous white-noise jerk of
/// intensity `sigma2` — Dormann et al., Section V. The printed system matrix has a typo in row 5
/// (`0 0 0 0 0 1`, which would make F singular and lose vy); we use the standard block
/// `[[1, D, D^2/2], [0, 1, D], [0, 0, 1]]` per axis, which is the one the printed noise matrix
/// `[[D^5/20, D^4/8, D^3/6], [D^4/8, D^3/3, D^2/2], [D^3/6, D^2/2, D]]` belongs to.
pub fn near_constant_acceleration_2d(dt: f64, sigma2: f64) -> Result<LinearTransition, ModelError> {
    let d = positive("sampling interval dt", dt)?;
    let s = positive("noise intensity sigma2", sigma2)?;
    let f = Matrix::from_row_slice(3, 3, &[1.0, d, d * d / 2.0, 0.0, 1.0, d, 0.0, 0.0, 1.0]);
    let q = Matrix::from_row_slice(
        3,
        3,
        &[
            d.powi(5) / 20.0,
            d.powi(4) / 8.0,
            d.powi(3) / 6.0,
            d.powi(4) / 8.0,
            d.powi(3) / 3.0,
            d * d / 2.0,
            d.powi(3) / 6.0,
            d * d / 2.0,
            d,
        ],
    ) * s;
    LinearTransition::new(block_diag(&f, 2), block_diag(&q, 2))
}

/// 2-D rotation oscillator, state (p1, p2): F rotates by the angle `omega * dt`,
/// Q = `q` I. A marginally stable model whose state never settles.
pub fn rotation_oscillator(omega: f64, dt: f64, q: f64) -> Result<LinearTransition, ModelError> {
    let d = positive("sampling interval dt", dt)?;
    let q = positive("process noise variance q", q)?;
    if !omega.is_finite() {
        return Err(ModelError::Parameter {
            what: "angular rate omega",
            value: omega,
        });
    }
    let (s, c) = (omega * d).sin_cos();
    let f = Matrix::from_row_slice(2, 2, &[c, s, -s, c]);
    LinearTransition::new(f, Matrix::identity(2, 2) * q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nca_matches_printed_noise_and_corrected_matrix() {
        let m = near_constant_acceleration_2d(0.25, 1.0).unwrap();
        let d: f64 = 0.25;
        // Row 5 (index 4) is vy' = vy + D ay, not the printed (0 0 0 0 0 1).
        assert_eq!(m.f()[(4, 4)], 1.0);
        assert_eq!(m.f()[(4, 5)], d);
        assert_eq!(m.f()[(3, 5)], d * d / 2.0);
        assert_eq!(m.q()[(0, 0)], d.powi(5) / 20.0);
        assert_eq!(m.q()[(4, 5)], d * d / 2.0);
        assert_eq!(m.q()[(5, 5)], d);
        assert_eq!(m.q()[(0, 3)], 0.0);
        assert!(m.f().clone().try_inverse().is_some());
    }

    #[test]
    fn cv_noise_is_hand_computed() {
        let m = constant_velocity_1d(2.0, 3.0).unwrap();
        assert_eq!(m.q()[(0, 0)], 3.0 * 8.0 / 3.0);
        assert_eq!(m.q()[(0, 1)], 3.0 * 2.0);
        assert_eq!(m.q()[(1, 1)], 6.0);
        assert!(constant_velocity_1d(0.0, 1.0).is_err());
        assert!(constant_velocity_2d(1.0, f64::NAN).is_err());
    }

    #[test]
    fn oscillator_preserves_norm_without_noise() {
        let m = rotation_oscillator(0.3, 0.5, 0.01).unwrap();
        let x = crate::linalg::Vector::from_vec(vec![3.0, 4.0]);
        assert!((m.propagate(&x).norm() - 5.0).abs() < 1e-12);
    }
}
