//! Kalman filter in information form: Y = P^{-1}, y = P^{-1} x. Fusing independent sensors is
//! a sum (Dormann et al., Section II, centralized fusion; Zhang et al. (2016), eq. (9), (12)), which is why
//! fusion centers use this form.
use super::{FilterError, Gaussian};
use crate::linalg::{cholesky, symmetrize, LinalgError, Matrix, Vector};
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

    /// Converts a covariance-form estimate by inverting its covariance: `Y = P^{-1}` (from the
    /// Cholesky factor, symmetrized) and `y = Y x` as a product. [`from_gaussian`](Self::from_gaussian)
    /// forms `y` by a solve instead; the two agree to rounding, and this one is what Zhang et al.'s (2016)
    /// fusion center starts from in eq. (9) and (12) (`P^{-1}` and `P^{-1} x` of the prediction).
    pub fn from_inverted_covariance(g: &Gaussian) -> Result<Self, FilterError> {
        let chol = cholesky(&g.cov).map_err(|source| FilterError::Matrix {
            what: "predicted covariance",
            source,
        })?;
        let mut matrix = chol.inverse();
        symmetrize(&mut matrix);
        let vector = &matrix * &g.mean;
        Ok(Self { matrix, vector })
    }

    /// Adds the information of a rank-one covariance-form update of `prior`, made along the
    /// row `h` (a `1 x n` Jacobian): `P' = P - c g g^T` and `x' = x + b g`, `g = P h^T`. The
    /// update enters as `P'^{-1} - P^{-1}` and `P'^{-1} x' - P^{-1} x`, which Sherman-Morrison
    /// gives without inverting `P'`:
    ///
    /// ```text
    /// Y += h^T h c / (1 - c s),   y += h^T (c h x + b) / (1 - c s),   s = h P h^T.
    /// ```
    ///
    /// A scalar measurement `z` with noise variance `r` is `c = 1 / (s + r)`,
    /// `b = (z - h x) / (s + r)` (then `Y += h^T h / r`, `y += h^T z / r`); Zhang et al.'s (2016) quantized
    /// innovation (eq. (10), (13) with the (A24) denominator) is `c = eta / Delta^2`,
    /// `b = sigma / Delta`.
    ///
    /// Returns `false`, leaving `self` unchanged, when `1 - c s <= 0`: the update would remove
    /// at least the prior's whole variance along `g` (`P'` not positive definite).
    #[must_use]
    pub fn add_rank_one_update(&mut self, prior: &Gaussian, h: &Matrix, c: f64, b: f64) -> bool {
        let s = (h * &prior.cov * h.transpose())[(0, 0)];
        let denom = 1.0 - c * s;
        if denom <= 0.0 {
            return false;
        }
        let hx = (h * &prior.mean)[(0, 0)];
        self.matrix += h.transpose() * h * (c / denom);
        self.vector += h.transpose() * ((c * hx + b) / denom);
        true
    }

    /// [`add_rank_one_update`](Self::add_rank_one_update) without temporaries: the same
    /// operations in the same order (`s` and `h x` as nalgebra's gemm/gemv of a row, the outer
    /// product `h^T h` entry by entry as its gemv per column, `h_j h_i`, then the scaling and the
    /// sums), hence the same bits. Only a `1 x n` row; other shapes take the matrix products.
    #[must_use]
    #[allow(clippy::assign_op_pattern)]
    pub fn add_rank_one_update_in_place(
        &mut self,
        prior: &Gaussian,
        h: &Matrix,
        c: f64,
        b: f64,
    ) -> bool {
        let n = self.vector.len();
        if h.nrows() != 1 || h.ncols() != n || n == 0 {
            return self.add_rank_one_update(prior, h, c, b);
        }
        let s = h_p_ht(h, &prior.cov);
        let denom = 1.0 - c * s;
        if denom <= 0.0 {
            return false;
        }
        let mut hx = [0.0];
        crate::linalg::fixed::mat_vec_dyn(&mut hx, h.as_slice(), prior.mean.as_slice());
        let (hs, ks) = (h.as_slice(), c / denom);
        let m = self.matrix.as_mut_slice();
        for j in 0..n {
            for i in 0..n {
                m[j * n + i] = m[j * n + i] + (hs[j] * hs[i]) * ks;
            }
        }
        let kv = (c * hx[0] + b) / denom;
        for (v, hi) in self.vector.iter_mut().zip(hs) {
            *v = *v + hi * kv;
        }
        true
    }

    /// [`from_inverted_covariance`](Self::from_inverted_covariance) into `self` (sized for
    /// `g`), factoring in the buffer `factor`: the same factorization, solves and product, hence
    /// the same bits, without allocating.
    pub fn set_inverted_covariance(
        &mut self,
        g: &Gaussian,
        factor: &mut Matrix,
    ) -> Result<(), FilterError> {
        let chol = factor_in(factor, &g.cov, "predicted covariance")?;
        self.matrix.fill_with_identity();
        crate::linalg::fixed::chol_solve_matrix(&chol, &mut self.matrix);
        *factor = chol.unpack_dirty();
        symmetrize(&mut self.matrix);
        crate::linalg::fixed::gemv(&mut self.vector, &self.matrix, &g.mean);
        Ok(())
    }

    /// [`to_gaussian`](Self::to_gaussian) into `out` (sized for `self`), factoring in the
    /// buffer `factor`: the same bits, without allocating.
    pub fn to_gaussian_into(
        &self,
        out: &mut Gaussian,
        factor: &mut Matrix,
    ) -> Result<(), FilterError> {
        let chol = factor_in(factor, &self.matrix, "information matrix")?;
        out.mean.copy_from(&self.vector);
        crate::linalg::fixed::chol_solve(&chol, &mut out.mean);
        out.cov.fill_with_identity();
        crate::linalg::fixed::chol_solve_matrix(&chol, &mut out.cov);
        *factor = chol.unpack_dirty();
        symmetrize(&mut out.cov);
        Ok(())
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
    /// (Dormann et al., centralized filtering step).
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

/// [`cholesky`]'s factor of `a`, computed in the storage of `buf` (which it takes; the caller
/// puts the factor back with `unpack_dirty`): the same checks and the same factorization
/// (`fixed::cholesky`), without the copy `cholesky` allocates. On failure `buf` is left empty
/// (the step fails anyway).
fn factor_in(
    buf: &mut Matrix,
    a: &Matrix,
    what: &'static str,
) -> Result<nalgebra::Cholesky<f64, nalgebra::Dyn>, FilterError> {
    let err = |source| FilterError::Matrix { what, source };
    if a.nrows() != a.ncols() {
        return Err(err(LinalgError::NotSquare {
            rows: a.nrows(),
            cols: a.ncols(),
        }));
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(err(LinalgError::NonFinite));
    }
    let mut m = std::mem::replace(buf, Matrix::zeros(0, 0));
    if m.shape() != a.shape() {
        m = Matrix::zeros(a.nrows(), a.ncols());
    }
    m.copy_from(a);
    crate::linalg::fixed::cholesky(m).ok_or(err(LinalgError::NotPositiveDefinite))
}

/// `(h * p * h^T)[(0, 0)]` for a 1 x n row h, without the temporaries, in nalgebra's order:
/// `h p` column by column as gemv (`h_0 p_0j`, then `h_k p_kj + acc`), then `(h p) h^T` the
/// same way (`(hp)_0 h_0`, then `(hp)_k h_k + acc`). Other shapes take the matrix products.
#[allow(clippy::assign_op_pattern)]
pub fn h_p_ht(h: &Matrix, p: &Matrix) -> f64 {
    let n = h.ncols();
    if h.nrows() != 1 || n == 0 || p.nrows() != n || p.ncols() != n {
        return (h * p * h.transpose())[(0, 0)];
    }
    let (h, p) = (h.as_slice(), p.as_slice());
    let hp = |j: usize| {
        let col = &p[j * n..(j + 1) * n];
        let mut acc = h[0] * col[0];
        for (hk, ck) in h.iter().zip(col).skip(1) {
            acc = hk * ck + acc;
        }
        acc
    };
    let mut acc = hp(0) * h[0];
    for (k, hk) in h.iter().enumerate().skip(1) {
        acc = hp(k) * hk + acc;
    }
    acc
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

    /// A scalar measurement as a rank-one update (`c = 1 / (s + r)`, `b = (z - h x) / (s + r)`)
    /// adds the same information as `add_measurement`, and an update removing the whole
    /// variance along `g` is refused.
    #[test]
    fn rank_one_update_of_a_scalar_measurement_is_the_measurement() {
        let prior = Gaussian::new(
            Vector::from_vec(vec![1.0, -2.0]),
            matrix_from_rows(&[vec![4.0, 1.0], vec![1.0, 2.0]]),
        );
        let (h, r, z) = (matrix_from_rows(&[vec![0.6, 0.8]]), 0.5, 3.0);
        let sensor = LinearSensor::new(h.clone(), Matrix::from_element(1, 1, r)).unwrap();
        let mut want = Information::from_inverted_covariance(&prior).unwrap();
        want.add_measurement(&sensor, &Vector::from_element(1, z))
            .unwrap();
        let s = (&h * &prior.cov * h.transpose())[(0, 0)];
        let hx = (&h * &prior.mean)[(0, 0)];
        let mut got = Information::from_inverted_covariance(&prior).unwrap();
        assert!(got.add_rank_one_update(&prior, &h, 1.0 / (s + r), (z - hx) / (s + r)));
        assert!(relative_difference(&got.matrix, &want.matrix) < 1e-12);
        assert!((&got.vector - &want.vector).amax() < 1e-12 * want.vector.amax());
        let before = got.clone();
        assert!(!got.add_rank_one_update(&prior, &h, 1.0 / s, 0.0));
        assert_eq!(got, before);
        // The inverted-covariance form agrees with the solved one.
        let solved = Information::from_gaussian(&prior).unwrap();
        let inverted = Information::from_inverted_covariance(&prior).unwrap();
        assert!((&solved.vector - &inverted.vector).amax() < 1e-14);
        assert_eq!(solved.matrix, inverted.matrix);
    }

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
