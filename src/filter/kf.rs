//! Kalman filter in covariance form. The update takes the Jacobian from the sensor model, so the
//! same code is the KF for a linear sensor and the EKF for a nonlinear one (linearized at the
//! predicted mean).
use super::{FilterError, Gaussian};
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::model::{LinearTransition, MeasurementModel};

/// Prediction step: mean F x, covariance F P F^T + Q (Dormann et al., eq. (2) with N = 1).
pub fn predict(model: &LinearTransition, est: &Gaussian) -> Gaussian {
    Gaussian {
        mean: model.f() * &est.mean,
        cov: predict_cov(model, &est.cov),
    }
}

/// The covariance half of [`predict`]: `F P F^T + Q`, symmetrized.
pub fn predict_cov(model: &LinearTransition, cov: &Matrix) -> Matrix {
    // The products in the exact fixed-size gemm (`F * cov`, then `* F^T`), then `+ Q`.
    let n = cov.nrows();
    let mut fp = Matrix::zeros(n, cov.ncols());
    crate::linalg::fixed::gemm(&mut fp, model.f(), cov);
    let mut out = Matrix::zeros(n, n);
    crate::linalg::fixed::gemm(&mut out, &fp, &model.f().transpose());
    crate::linalg::fixed::add_assign(out.as_mut_slice(), model.q().as_slice());
    symmetrize(&mut out);
    out
}

/// Buffers for [`predict_into`], sized at construction so a step allocates nothing.
#[derive(Debug, Clone)]
pub struct PredictWork {
    /// `F P`.
    fp: Matrix,
    /// `F^T`, copied per step (a transpose is exact).
    ft: Matrix,
}

impl PredictWork {
    /// Buffers for an n-dimensional state.
    pub fn new(n: usize) -> Self {
        Self {
            fp: Matrix::zeros(n, n),
            ft: Matrix::zeros(n, n),
        }
    }
}

/// [`predict`] into `out` through `work`: the same operations (`F x` as gemv, `F P` and
/// `(F P) F^T` in the exact fixed-size gemm, `+ Q`, symmetrized) in the same order, hence the
/// same bits, without a temporary.
pub fn predict_into(
    model: &LinearTransition,
    est: &Gaussian,
    out: &mut Gaussian,
    work: &mut PredictWork,
) {
    crate::linalg::fixed::gemv(&mut out.mean, model.f(), &est.mean);
    crate::linalg::fixed::gemm(&mut work.fp, model.f(), &est.cov);
    work.ft.tr_copy_from(model.f());
    crate::linalg::fixed::gemm(&mut out.cov, &work.fp, &work.ft);
    crate::linalg::fixed::add_assign(out.cov.as_mut_slice(), model.q().as_slice());
    symmetrize(&mut out.cov);
}

/// Innovation nu = z - h(x), its covariance S = H P H^T + R and the Jacobian H used.
#[derive(Debug, Clone)]
pub struct Innovation {
    pub nu: Vector,
    pub s: Matrix,
    pub h: Matrix,
}

/// Innovation of `z` against the prediction `est` (the NIS censoring rule, the Tobit and the
/// quantized updates all start from it).
pub fn innovation(
    sensor: &dyn MeasurementModel,
    est: &Gaussian,
    z: &Vector,
) -> Result<Innovation, FilterError> {
    check_measurement(sensor, z)?;
    let h = sensor.jacobian(&est.mean);
    let nu = z - sensor.predict(&est.mean);
    let mut s = &h * &est.cov * h.transpose() + sensor.noise_cov();
    symmetrize(&mut s);
    Ok(Innovation { nu, s, h })
}

/// Reject measurements of the wrong size or with NaN/inf components: a silent wrong answer is
/// worse than an error.
pub fn check_measurement(sensor: &dyn MeasurementModel, z: &Vector) -> Result<(), FilterError> {
    if z.len() != sensor.meas_dim() {
        return Err(FilterError::MeasurementDimension {
            expected: sensor.meas_dim(),
            got: z.len(),
        });
    }
    if z.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFiniteMeasurement(
            z.iter().copied().collect(),
        ));
    }
    Ok(())
}

/// Kalman gain K = P H^T S^{-1}.
pub fn gain(est: &Gaussian, inn: &Innovation) -> Result<Matrix, FilterError> {
    let chol = cholesky(&inn.s).map_err(|source| FilterError::Matrix {
        what: "innovation covariance S",
        source,
    })?;
    // K^T = S^{-1} H P (S and P symmetric).
    let kt = chol.solve(&(&inn.h * &est.cov));
    Ok(kt.transpose())
}

/// Measurement update in Joseph form, (I - K H) P (I - K H)^T + K R K^T, symmetrized: it stays
/// positive definite under rounding where the short form I - K H can lose definiteness.
pub fn update(
    sensor: &dyn MeasurementModel,
    est: Gaussian,
    z: &Vector,
) -> Result<Gaussian, FilterError> {
    let inn = innovation(sensor, &est, z)?;
    let k = gain(&est, &inn)?;
    let mean = &est.mean + &k * &inn.nu;
    let n = est.dim();
    let i_kh = Matrix::identity(n, n) - &k * &inn.h;
    let mut cov = &i_kh * &est.cov * i_kh.transpose() + &k * sensor.noise_cov() * k.transpose();
    symmetrize(&mut cov);
    Ok(Gaussian { mean, cov })
}

/// The covariance half of [`update`], linearized at `x_ref` instead of the predicted mean:
/// `H` = the sensor's Jacobian at `x_ref`, `S = H P H^T + R`, the gain `K = P H^T S^{-1}` and
/// the Joseph-form `(I - K H) P (I - K H)^T + K R K^T`, symmetrized. Returns
/// `(P_{k|k}, K, S)`.
///
/// This is a local filter's update when only the covariance is wanted (the mean is formed by
/// the caller, `x_ref + K nu`): Zheng et al.'s (2014) sensors linearize an EKF at the fed-back estimate
/// (Remark 3), and the data-independent covariance sequence of a linear sensor
/// (`scheme::censored_pf::local_plan`) is this recursion with any `x_ref`. At `x_ref` = the
/// predicted mean it performs the operations of [`update`] in the same order: its covariance
/// is the same bits.
pub fn update_cov(
    sensor: &dyn MeasurementModel,
    p_pred: &Matrix,
    x_ref: &Vector,
) -> Result<(Matrix, Matrix, Matrix), FilterError> {
    let h = sensor.jacobian(x_ref);
    let mut s = &h * p_pred * h.transpose() + sensor.noise_cov();
    symmetrize(&mut s);
    let chol = cholesky(&s).map_err(|source| FilterError::Matrix {
        what: "local innovation covariance",
        source,
    })?;
    let gain = chol.solve(&(&h * p_pred)).transpose();
    let n = p_pred.nrows();
    let i_kh = Matrix::identity(n, n) - &gain * &h;
    let mut p = &i_kh * p_pred * i_kh.transpose() + &gain * sensor.noise_cov() * gain.transpose();
    symmetrize(&mut p);
    Ok((p, gain, s))
}

/// One full KF step: predict with `model`, then update with each available measurement in
/// turn (sequential updates equal the joint update for independent sensor noises).
pub fn step(
    model: &LinearTransition,
    est: &Gaussian,
    measurements: &[(&dyn MeasurementModel, &Vector)],
) -> Result<Gaussian, FilterError> {
    let mut e = predict(model, est);
    for (sensor, z) in measurements {
        e = update(*sensor, e, z)?;
    }
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::matrix_from_rows;
    use crate::model::LinearSensor;

    fn scalar(f: f64, q: f64) -> LinearTransition {
        LinearTransition::new(Matrix::from_element(1, 1, f), Matrix::from_element(1, 1, q)).unwrap()
    }

    #[test]
    fn scalar_update_by_hand() {
        // Prior N(0, 4), z = 2 with r = 1: K = 4/5, mean 1.6, variance 4/5.
        let s = LinearSensor::new(
            Matrix::from_element(1, 1, 1.0),
            Matrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        let e = Gaussian::new(
            Vector::from_element(1, 0.0),
            Matrix::from_element(1, 1, 4.0),
        );
        let u = update(&s, e, &Vector::from_element(1, 2.0)).unwrap();
        assert!((u.mean[0] - 1.6).abs() < 1e-15);
        assert!((u.cov[(0, 0)] - 0.8).abs() < 1e-15);
    }

    #[test]
    fn scalar_kf_converges_to_closed_form_steady_state() {
        // x' = a x + w (q), z = x + v (r). Steady-state prediction variance p solves
        // p = a^2 p r / (p + r) + q, i.e. p^2 + p (r - a^2 r - q) - q r = 0.
        let (a, q, r) = (0.9_f64, 0.5_f64, 2.0_f64);
        let b = r - a * a * r - q;
        let p_pred = (-b + (b * b + 4.0 * q * r).sqrt()) / 2.0;
        let p_filt = p_pred * r / (p_pred + r);
        let model = scalar(a, q);
        let s = LinearSensor::new(
            Matrix::from_element(1, 1, 1.0),
            Matrix::from_element(1, 1, r),
        )
        .unwrap();
        let mut e = Gaussian::new(
            Vector::from_element(1, 0.0),
            Matrix::from_element(1, 1, 100.0),
        );
        for _ in 0..200 {
            let z = Vector::from_element(1, 0.3);
            e = step(&model, &e, &[(&s, &z)]).unwrap();
        }
        assert!(
            (e.cov[(0, 0)] - p_filt).abs() < 1e-12,
            "{} vs {}",
            e.cov[(0, 0)],
            p_filt
        );
    }

    #[test]
    fn rejects_bad_measurements() {
        let s = LinearSensor::new(
            matrix_from_rows(&[vec![1.0, 0.0]]),
            Matrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        let e = Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2));
        let nan = Vector::from_element(1, f64::NAN);
        assert!(matches!(
            update(&s, e.clone(), &nan),
            Err(FilterError::NonFiniteMeasurement(_))
        ));
        let two = Vector::zeros(2);
        assert!(matches!(
            update(&s, e, &two),
            Err(FilterError::MeasurementDimension {
                expected: 1,
                got: 2
            })
        ));
    }
}
