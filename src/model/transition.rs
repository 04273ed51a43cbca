//! Linear-Gaussian transition x_{k+1} = F x_k + w_k, w_k ~ N(0, Q).
use super::ModelError;
use crate::linalg::{check_spd, cholesky, Matrix, Vector};
use rand::RngCore;
use rand_distr::{Distribution, StandardNormal};

/// Linear-Gaussian motion model. Built only through [`LinearTransition::new`], which checks that
/// `F` is square, `Q` matches it and is symmetric positive semi-definite, so filters never
/// re-check in their hot loops.
#[derive(Debug, Clone)]
pub struct LinearTransition {
    f: Matrix,
    q: Matrix,
    /// Lower-triangular square root of `Q` for sampling; zero rows where `Q` is singular.
    q_sqrt: Matrix,
}

impl LinearTransition {
    /// Validates the dimensions and that `Q` is a covariance (positive semi-definite is allowed:
    /// some models put no noise on a component).
    pub fn new(f: Matrix, q: Matrix) -> Result<Self, ModelError> {
        let n = f.nrows();
        if f.ncols() != n {
            return Err(ModelError::Dimension {
                what: "transition matrix F",
                expected: "a square matrix".into(),
                got: format!("{}x{}", f.nrows(), f.ncols()),
            });
        }
        if q.nrows() != n || q.ncols() != n {
            return Err(ModelError::Dimension {
                what: "process noise Q",
                expected: format!("{n}x{n} like F"),
                got: format!("{}x{}", q.nrows(), q.ncols()),
            });
        }
        if f.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Covariance {
                what: "transition matrix F",
                source: crate::linalg::LinalgError::NonFinite,
            });
        }
        let q_sqrt = psd_sqrt(&q).map_err(|source| ModelError::Covariance {
            what: "process noise Q",
            source,
        })?;
        Ok(Self { f, q, q_sqrt })
    }

    /// State dimension.
    pub fn dim(&self) -> usize {
        self.f.nrows()
    }

    /// The transition matrix `F`.
    pub fn f(&self) -> &Matrix {
        &self.f
    }

    /// The process noise covariance `Q`.
    pub fn q(&self) -> &Matrix {
        &self.q
    }

    /// Noise-free propagation `F x`.
    pub fn propagate(&self, x: &Vector) -> Vector {
        &self.f * x
    }

    /// Lower square root of Q (w_k = Q^{1/2} n, n standard normal).
    pub fn q_sqrt(&self) -> &Matrix {
        &self.q_sqrt
    }

    /// Draw `x_{k+1} = F x_k + w_k`.
    pub fn sample_next(&self, x: &Vector, rng: &mut dyn RngCore) -> Vector {
        let w = Vector::from_fn(self.dim(), |_, _| StandardNormal.sample(rng));
        &self.f * x + &self.q_sqrt * w
    }
}

/// Square root `L` with `L L^T = A` of a positive semi-definite matrix: Cholesky when `A` is
/// definite, otherwise a symmetric eigen-decomposition (Q of a model may be singular).
pub fn psd_sqrt(a: &Matrix) -> Result<Matrix, crate::linalg::LinalgError> {
    // Cholesky reads one triangle only: an asymmetric matrix would be sampled from that
    // triangle while filters use it as given.
    crate::linalg::check_symmetric(a)?;
    if let Ok(chol) = cholesky(a) {
        return Ok(chol.l());
    }
    // Semi-definite: accept only if the symmetric check passes apart from definiteness.
    match check_spd(a) {
        Err(crate::linalg::LinalgError::NotPositiveDefinite) | Ok(()) => {}
        Err(e) => return Err(e),
    }
    let eig = a.clone().symmetric_eigen();
    let scale = eig.eigenvalues.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if eig.eigenvalues.iter().any(|&l| l < -1e-12 * scale.max(1.0)) {
        return Err(crate::linalg::LinalgError::NotPositiveDefinite);
    }
    let sqrt_l = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    Ok(&eig.eigenvectors * Matrix::from_diagonal(&sqrt_l))
}
