//! Small dense linear-algebra helpers shared by every filter: symmetrization, SPD checks and
//! Cholesky-based inverses with errors instead of panics.
pub mod fixed;
pub mod quad;
mod types;

use nalgebra::{Cholesky, Dyn};
pub use types::{Matrix, Vector};

/// Why a matrix was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinalgError {
    #[error("matrix is not square ({rows}x{cols})")]
    NotSquare { rows: usize, cols: usize },
    #[error("matrix is not symmetric (|A - A^T| = {asymmetry:.3e} at entry ({row}, {col}))")]
    NotSymmetric {
        asymmetry: f64,
        row: usize,
        col: usize,
    },
    #[error("matrix is not positive definite (Cholesky factorization failed)")]
    NotPositiveDefinite,
    #[error("matrix has a non-finite entry")]
    NonFinite,
}

/// Replace `a` by `(a + a^T) / 2`; updates lose symmetry to rounding, and a covariance that
/// drifts from symmetric eventually fails its Cholesky factorization.
pub fn symmetrize(a: &mut Matrix) {
    let n = a.nrows();
    if a.ncols() != n {
        // Non-square: the indexing form (which panics out of range, as it always did).
        for i in 0..n {
            for j in (i + 1)..n {
                let m = 0.5 * (a[(i, j)] + a[(j, i)]);
                a[(i, j)] = m;
                a[(j, i)] = m;
            }
        }
        return;
    }
    // Column-major: (i, j) at j * n + i.
    let s = a.as_mut_slice();
    for i in 0..n {
        for j in (i + 1)..n {
            let m = 0.5 * (s[j * n + i] + s[i * n + j]);
            s[j * n + i] = m;
            s[i * n + j] = m;
        }
    }
}

/// Cholesky factor of a symmetric positive definite matrix, or an error saying why not.
/// Dimensions 1..=6 factor in fixed size (the same operations, bit for bit).
pub fn cholesky(a: &Matrix) -> Result<Cholesky<f64, Dyn>, LinalgError> {
    // In storage of its own: the copy of `a` is the one allocation.
    cholesky_into(a, &mut Matrix::zeros(0, 0))
}

/// Inverse of a symmetric positive definite matrix through its Cholesky factor, symmetrized.
pub fn spd_inverse(a: &Matrix) -> Result<Matrix, LinalgError> {
    // `Cholesky::inverse`: the identity solved in place (fixed size for n <= 6).
    let chol = cholesky(a)?;
    let mut inv = Matrix::identity(a.nrows(), a.ncols());
    fixed::chol_solve_matrix(&chol, &mut inv);
    symmetrize(&mut inv);
    Ok(inv)
}

/// Check that `a` is square and finite (the first checks of [`cholesky`] and
/// [`check_symmetric`]).
fn check_square_finite(a: &Matrix) -> Result<(), LinalgError> {
    if a.nrows() != a.ncols() {
        return Err(LinalgError::NotSquare {
            rows: a.nrows(),
            cols: a.ncols(),
        });
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    Ok(())
}

/// Check that `a` is square, finite and symmetric to a relative tolerance of 1e-9.
pub fn check_symmetric(a: &Matrix) -> Result<(), LinalgError> {
    check_square_finite(a)?;
    let scale = a
        .iter()
        .fold(0.0_f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    for i in 0..a.nrows() {
        for j in (i + 1)..a.ncols() {
            let d = (a[(i, j)] - a[(j, i)]).abs();
            if d > 1e-9 * scale {
                return Err(LinalgError::NotSymmetric {
                    asymmetry: d,
                    row: i,
                    col: j,
                });
            }
        }
    }
    Ok(())
}

/// Check that `a` is a covariance: square, finite, symmetric to a relative tolerance of 1e-9,
/// and positive definite.
pub fn check_spd(a: &Matrix) -> Result<(), LinalgError> {
    check_symmetric(a)?;
    cholesky(a).map(|_| ())
}

/// Normalized estimation error squared `e^T P^{-1} e` through the Cholesky factor of `P`.
pub fn mahalanobis_sq(e: &Vector, p: &Matrix) -> Result<f64, LinalgError> {
    if p.nrows() == p.ncols() && p.iter().all(|v| v.is_finite()) {
        // The checks of `cholesky` passed: the fixed-size path for n <= 6.
        if let Some(r) = fixed::mahalanobis_sq_small(e, p) {
            return r.ok_or(LinalgError::NotPositiveDefinite);
        }
    }
    let chol = cholesky(p)?;
    let y = chol
        .l()
        .solve_lower_triangular(e)
        .ok_or(LinalgError::NotPositiveDefinite)?;
    Ok(y.norm_squared())
}

/// Matrix from rows, as scenario files and tests write them.
pub fn matrix_from_rows(rows: &[Vec<f64>]) -> Matrix {
    let r = rows.len();
    let c = rows.first().map_or(0, Vec::len);
    Matrix::from_fn(r, c, |i, j| rows[i][j])
}

/// Largest absolute entry of `a - b` relative to the largest absolute entry of `b` (or 1).
pub fn relative_difference(a: &Matrix, b: &Matrix) -> f64 {
    let scale = b.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    (a - b).iter().fold(0.0_f64, |m, v| m.max(v.abs())) / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_of_hand_computed_matrix() {
        // [[4, 2], [2, 3]]^{-1} = 1/8 [[3, -2], [-2, 4]]
        let a = matrix_from_rows(&[vec![4.0, 2.0], vec![2.0, 3.0]]);
        let inv = spd_inverse(&a).unwrap();
        let expected = matrix_from_rows(&[vec![0.375, -0.25], vec![-0.25, 0.5]]);
        assert!(relative_difference(&inv, &expected) < 1e-15);
    }

    #[test]
    fn rejects_non_spd_and_asymmetric() {
        let indefinite = matrix_from_rows(&[vec![1.0, 2.0], vec![2.0, 1.0]]);
        assert_eq!(
            check_spd(&indefinite),
            Err(LinalgError::NotPositiveDefinite)
        );
        let asym = matrix_from_rows(&[vec![1.0, 0.5], vec![0.0, 1.0]]);
        assert!(matches!(
            check_spd(&asym),
            Err(LinalgError::NotSymmetric { .. })
        ));
        let nan = matrix_from_rows(&[vec![f64::NAN, 0.0], vec![0.0, 1.0]]);
        assert_eq!(check_spd(&nan), Err(LinalgError::NonFinite));
    }

    #[test]
    fn mahalanobis_matches_hand_value() {
        // e = (1, 1), P = diag(1, 4): 1 + 1/4
        let p = Matrix::from_diagonal(&Vector::from_vec(vec![1.0, 4.0]));
        let e = Vector::from_vec(vec![1.0, 1.0]);
        assert!((mahalanobis_sq(&e, &p).unwrap() - 1.25).abs() < 1e-15);
    }

    #[test]
    fn in_place_inverse_is_spd_inverse_bit_for_bit() {
        // Dimensions with the fixed-size kernels (2, 6) and nalgebra's own path (7), in
        // buffers of the wrong shape and reused; and the same errors.
        let mut buf = Matrix::zeros(0, 0);
        let mut out = Matrix::zeros(1, 3);
        for n in [2usize, 6, 7, 2] {
            let b = Matrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 5) as f64 * 0.37 - 0.6);
            let a = &b * b.transpose() + Matrix::identity(n, n) * 0.1;
            spd_inverse_into(&a, &mut out, &mut buf).unwrap();
            let expected = spd_inverse(&a).unwrap();
            let bits = |m: &Matrix| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&expected), "n = {n}");
            assert_eq!(buf.shape(), (n, n), "the factor's storage is kept");
        }
        let indefinite = matrix_from_rows(&[vec![1.0, 2.0], vec![2.0, 1.0]]);
        let nan = matrix_from_rows(&[vec![f64::NAN, 0.0], vec![0.0, 1.0]]);
        let wide = Matrix::zeros(2, 3);
        for bad in [indefinite, nan, wide] {
            assert_eq!(
                spd_inverse_into(&bad, &mut out, &mut buf),
                spd_inverse(&bad).map(|_| ())
            );
        }
    }
}

/// [`cholesky`] of `a` computed in the storage of `storage` (which it takes; the caller puts
/// the factor back with `unpack_dirty`, and it is resized to `a`'s shape if it differs, so only
/// a first call allocates): the same checks and the same factorization (`fixed::cholesky`)
/// without the copy `cholesky` allocates. On failure `storage` is left empty (the
/// next call sizes it again).
pub fn cholesky_into(a: &Matrix, storage: &mut Matrix) -> Result<Cholesky<f64, Dyn>, LinalgError> {
    check_square_finite(a)?;
    let mut m = std::mem::replace(storage, Matrix::zeros(0, 0));
    if m.shape() != a.shape() {
        m = Matrix::zeros(a.nrows(), a.ncols());
    }
    m.copy_from(a);
    fixed::cholesky(m).ok_or(LinalgError::NotPositiveDefinite)
}

/// [`spd_inverse`] of `a` into `out` (resized to `a`'s shape if it differs), factoring in the
/// storage of `factor` ([`cholesky_into`]): the same checks, factorization, solves of the
/// identity and symmetrization, hence the same bits, without allocating.
pub fn spd_inverse_into(
    a: &Matrix,
    out: &mut Matrix,
    factor: &mut Matrix,
) -> Result<(), LinalgError> {
    let chol = cholesky_into(a, factor)?;
    if out.shape() != a.shape() {
        *out = Matrix::zeros(a.nrows(), a.ncols());
    }
    out.fill_with_identity();
    fixed::chol_solve_matrix(&chol, out);
    *factor = chol.unpack_dirty();
    symmetrize(out);
    Ok(())
}

/// [`spd_inverse_into`] for n <= 6 on the stack: the same checks, then the factorization and
/// the solves of `fixed::cholesky_square` and `fixed::chol_inverse_sym_square` (tested bit for
/// bit against `cholesky`, `chol_solve_matrix` and `symmetrize`), without touching a factor's
/// matrix; other sizes take [`spd_inverse_into`].
pub fn spd_inverse_small_into(
    a: &Matrix,
    out: &mut Matrix,
    factor: &mut Matrix,
) -> Result<(), LinalgError> {
    fn square<const N: usize>(a: &[f64], out: &mut [f64]) -> bool {
        let mut m = [0.0f64; 36];
        m[..N * N].copy_from_slice(&a[..N * N]);
        if !fixed::cholesky_square::<N>(&mut m) {
            return false;
        }
        fixed::chol_inverse_sym_square::<N>(&m, out);
        true
    }
    let n = a.nrows();
    if n != a.ncols() || !(1..=6).contains(&n) {
        return spd_inverse_into(a, out, factor);
    }
    check_square_finite(a)?;
    if out.shape() != a.shape() {
        *out = Matrix::zeros(n, n);
    }
    let (a, o) = (a.as_slice(), out.as_mut_slice());
    let ok = match n {
        1 => square::<1>(a, o),
        2 => square::<2>(a, o),
        3 => square::<3>(a, o),
        4 => square::<4>(a, o),
        5 => square::<5>(a, o),
        _ => square::<6>(a, o),
    };
    if ok {
        Ok(())
    } else {
        Err(LinalgError::NotPositiveDefinite)
    }
}

#[cfg(test)]
mod in_place_tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// `cholesky_into` is `cholesky` and `spd_inverse_into` (and `spd_inverse_small_into`) is
    /// `spd_inverse`, bit for bit, on
    /// random SPD matrices of dimensions 1..=9 (the fixed-size kernels and nalgebra's dynamic path), with reused buffers of a
    /// different size at first, and refuses what `spd_inverse` refuses.
    #[test]
    fn spd_inverse_into_is_spd_inverse_bit_for_bit() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(17);
        let (mut out, mut factor) = (Matrix::zeros(2, 3), Matrix::zeros(0, 0));
        for trial in 0..400 {
            let n = 1 + trial % 9;
            let b = Matrix::from_fn(n, n, |_, _| rng.random_range(-2.0..2.0));
            let mut a = &b * b.transpose() + Matrix::identity(n, n) * rng.random_range(1e-6..1.0);
            symmetrize(&mut a);
            let want = spd_inverse(&a).unwrap();
            let chol = cholesky_into(&a, &mut factor).unwrap();
            assert_eq!(chol.l_dirty(), cholesky(&a).unwrap().l_dirty(), "n {n}");
            factor = chol.unpack_dirty();
            spd_inverse_into(&a, &mut out, &mut factor).unwrap();
            let mut small = Matrix::zeros(1, 1);
            spd_inverse_small_into(&a, &mut small, &mut factor).unwrap();
            let bits = |m: &Matrix| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&small), bits(&out), "spd_inverse_small_into, n {n}");
            assert_eq!(
                want.as_slice()
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
                out.as_slice()
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
                "n {n}"
            );
        }
        let indefinite = matrix_from_rows(&[vec![1.0, 2.0], vec![2.0, 1.0]]);
        assert_eq!(
            spd_inverse_into(&indefinite, &mut out, &mut factor),
            Err(LinalgError::NotPositiveDefinite)
        );
        let nan = matrix_from_rows(&[vec![f64::NAN, 0.0], vec![0.0, 1.0]]);
        assert_eq!(
            spd_inverse_into(&nan, &mut out, &mut factor),
            Err(LinalgError::NonFinite)
        );
        for bad in [&indefinite, &nan] {
            assert_eq!(
                spd_inverse_small_into(bad, &mut out, &mut factor),
                spd_inverse_into(bad, &mut out, &mut factor)
            );
        }
    }
}
