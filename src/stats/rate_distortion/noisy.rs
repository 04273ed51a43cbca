//! The vector floor with a noisy linear sensor set `z = H x + v`, `v ~ N(0, V)`: the all-data
//! Kalman filter's steady-state error plus the fully observed floor of its estimate process
//! (see the parent module's doc for why the two add).
use super::{sdp, FloorError};
use crate::linalg::{check_symmetric, cholesky, spd_inverse, symmetrize, Matrix};

/// Steady state of the Kalman filter that receives every measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanSteadyState {
    /// Prediction (prior) covariance `M = A P Aᵀ + W`.
    pub prior: Matrix,
    /// Filtered (posterior) covariance `P = M − M Hᵀ (H M Hᵀ + V)⁻¹ H M`: the all-data error.
    pub posterior: Matrix,
}

impl KalmanSteadyState {
    /// Covariance of the estimate's driving term `K ν` (gain times innovation):
    /// `K S Kᵀ = M Hᵀ S⁻¹ H M = M − P`.
    pub fn estimate_noise(&self) -> Matrix {
        let mut n = &self.prior - &self.posterior;
        symmetrize(&mut n);
        n
    }
}

/// Iterates the Riccati recursion from `M = W` until the prior stops changing (relative change
/// below 1e-13).
///
/// With more reading rows than states (`m > n`) each step is taken in information form,
/// `P = (M⁻¹ + Hᵀ V⁻¹ H)⁻¹` with `Hᵀ V⁻¹ H` formed once, which inverts n × n matrices where the
/// innovation form `P = M − M Hᵀ (H M Hᵀ + V)⁻¹ H M` inverts the m × m `S`: for a network of
/// hundreds of sensors the floor then costs milliseconds, not a second. The two are the same
/// matrix; they differ in the last digits.
///
/// Errors: [`FloorError::Invalid`] for mismatched shapes, non-finite entries, `W` or `V` not
/// symmetric positive definite, and for a recursion that has not settled after 100 000 steps
/// or blows up (an undetectable unstable mode).
pub fn kalman_steady_state(
    a: &Matrix,
    w: &Matrix,
    h: &Matrix,
    v: &Matrix,
) -> Result<KalmanSteadyState, FloorError> {
    check_sensor(a, w, h, v)?;
    let information = if h.nrows() > a.nrows() {
        Some(sensor_information(h, v)?)
    } else {
        None
    };
    let mut prior = w.clone();
    for _ in 0..100_000 {
        let mut posterior = match &information {
            None => {
                let s = h * &prior * h.transpose() + v;
                let s_inv = spd_inverse(&s).map_err(|e| FloorError::Invalid(format!("S: {e}")))?;
                let gain = &prior * h.transpose() * s_inv;
                &prior - &gain * h * &prior
            }
            Some(u) => {
                let inverse = |m: &Matrix, what: &str| {
                    spd_inverse(m).map_err(|e| FloorError::Invalid(format!("{what}: {e}")))
                };
                inverse(&(inverse(&prior, "M")? + u), "M⁻¹ + Hᵀ V⁻¹ H")?
            }
        };
        symmetrize(&mut posterior);
        let mut next = a * &posterior * a.transpose() + w;
        symmetrize(&mut next);
        if next.iter().any(|x| !x.is_finite()) || next.norm() > 1e300 {
            break;
        }
        let change = (&next - &prior).norm() / next.norm();
        prior = next;
        if change < 1e-13 {
            return Ok(KalmanSteadyState { prior, posterior });
        }
    }
    Err(FloorError::Invalid(
        "the Kalman Riccati recursion has no steady state (undetectable unstable mode?)".into(),
    ))
}

/// `Hᵀ V⁻¹ H`, symmetric, from the Cholesky factor of `V` (checked positive definite by
/// [`check_sensor`]).
fn sensor_information(h: &Matrix, v: &Matrix) -> Result<Matrix, FloorError> {
    let factor = nalgebra::Cholesky::new(v.clone())
        .ok_or_else(|| FloorError::Invalid("V: not positive definite".into()))?;
    let mut u = h.transpose() * factor.solve(h);
    symmetrize(&mut u);
    Ok(u)
}

/// The smallest steady-state mean squared error any causal scheme reaches at `rate` bits per
/// step when the encoder sees `z = H x + v`: `trace(P_kf) + floor_mse(A, M − P_kf, rate)`.
///
/// Errors: those of [`kalman_steady_state`] and [`sdp::floor_mse`]; in particular
/// [`FloorError::Invalid`] when the estimate's driving covariance `M − P_kf` is singular, which
/// happens when `H` has fewer independent rows than the state has components (the program
/// needs that covariance invertible; that case is left out).
pub fn floor_mse_noisy(
    a: &Matrix,
    w: &Matrix,
    h: &Matrix,
    v: &Matrix,
    rate: f64,
) -> Result<f64, FloorError> {
    let kf = kalman_steady_state(a, w, h, v)?;
    let floor = sdp::floor_mse(a, &kf.estimate_noise(), rate)?;
    Ok(kf.posterior.trace() + floor)
}

fn check_sensor(a: &Matrix, w: &Matrix, h: &Matrix, v: &Matrix) -> Result<(), FloorError> {
    let (n, m) = (a.nrows(), h.nrows());
    let shapes_ok = n > 0
        && a.ncols() == n
        && w.shape() == (n, n)
        && h.ncols() == n
        && m > 0
        && v.shape() == (m, m);
    if !shapes_ok {
        return Err(FloorError::Invalid(format!(
            "shapes: A {:?}, W {:?}, H {:?}, V {:?}",
            a.shape(),
            w.shape(),
            h.shape(),
            v.shape()
        )));
    }
    if [a, w, h, v]
        .iter()
        .any(|x| x.iter().any(|e| !e.is_finite()))
    {
        return Err(FloorError::Invalid(
            "non-finite entry in A, W, H or V".into(),
        ));
    }
    for (name, x) in [("W", w), ("V", v)] {
        check_symmetric(x).map_err(|e| FloorError::Invalid(format!("{name}: {e}")))?;
        cholesky(x).map_err(|e| FloorError::Invalid(format!("{name}: {e}")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::rate_distortion::scalar;

    fn m1(x: f64) -> Matrix {
        Matrix::from_element(1, 1, x)
    }

    #[test]
    fn scalar_kalman_agrees_with_closed_form() {
        for &(a, w, h, v) in &[(1.2, 1.0, 1.0, 0.5), (0.9, 0.1, 2.0, 3.0)] {
            let kf = kalman_steady_state(&m1(a), &m1(w), &m1(h), &m1(v)).unwrap();
            let closed = scalar::kalman(a, w, h, v).unwrap();
            assert!((kf.prior[(0, 0)] - closed.prior).abs() < 1e-10 * closed.prior);
            assert!((kf.posterior[(0, 0)] - closed.posterior).abs() < 1e-10 * closed.prior);
        }
    }

    /// The information form (more reading rows than states) and the innovation form (the same
    /// system read by one row at the summed precision) reach the same steady state: two
    /// position sensors of variances 1 and 4 on a constant-velocity target are one of variance
    /// 0.8. Tolerance: the recursion stops at a relative change of 1e-13.
    #[test]
    fn information_form_agrees_with_the_innovation_form() {
        let a = Matrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]);
        let w = Matrix::from_row_slice(2, 2, &[0.25, 0.5, 0.5, 1.0]) * 0.1
            + Matrix::identity(2, 2) * 1e-3;
        let rows = Matrix::from_row_slice(3, 2, &[1.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        let v3 = Matrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.0, 4.0, 1.0]));
        let many = kalman_steady_state(&a, &w, &rows, &v3).unwrap();
        let one = kalman_steady_state(&a, &w, &Matrix::from_row_slice(1, 2, &[1.0, 0.0]), &m1(0.8))
            .unwrap();
        for (x, y) in [(&many.prior, &one.prior), (&many.posterior, &one.posterior)] {
            assert!((x - y).amax() < 1e-11 * y.amax(), "{x} vs {y}");
        }
    }

    #[test]
    fn undetectable_unstable_mode_is_an_error() {
        let a = Matrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.1, 0.5]));
        let h = Matrix::from_row_slice(1, 2, &[0.0, 1.0]);
        let r = kalman_steady_state(&a, &Matrix::identity(2, 2), &h, &m1(1.0));
        assert!(matches!(r, Err(FloorError::Invalid(_))), "{r:?}");
    }
}
