//! Fixed-size kernels for the small dimensions of the linear-Gaussian schemes (state and
//! measurement dimensions up to 6), monomorphized per shape so the compiler unrolls them, with
//! the dynamic path kept for every other shape.
//!
//! They compute *exactly* what nalgebra's dynamic `gemv` (and hence `&a * &x`) computes: for
//! `y = A x` nalgebra runs one axpy per column, `y_r = A_r0 x_0`, then `y_r = A_rj x_j + y_r`
//! for j = 1, 2, ... — every product rounded on its own, the sums in column order, the product
//! the left operand. The kernels below perform the same operations in the same order (Rust
//! never fuses a multiply and an add), so every bit is the same; the property test in this
//! module checks it on random and special values.
use crate::linalg::{Matrix, Vector};

/// `y = a x`, bit for bit as `y.gemv(1.0, a, x, 0.0)`.
pub fn gemv(y: &mut Vector, a: &Matrix, x: &Vector) {
    let (r, c) = a.shape();
    assert!(
        x.len() == c && y.len() == r,
        "gemv: dimensions mismatch ({r}x{c} times {}, into {})",
        x.len(),
        y.len()
    );
    macro_rules! dispatch {
        ($(($rr:literal, $cc:literal)),*) => {
            match (r, c) {
                $(($rr, $cc) => gemv_fixed::<$rr, $cc>(y.as_mut_slice(), a.as_slice(), x.as_slice()),)*
                _ => y.gemv(1.0, a, x, 0.0),
            }
        };
    }
    dispatch!(
        (1, 1),
        (1, 2),
        (1, 3),
        (1, 4),
        (1, 5),
        (1, 6),
        (2, 1),
        (2, 2),
        (2, 3),
        (2, 4),
        (2, 5),
        (2, 6),
        (3, 1),
        (3, 2),
        (3, 3),
        (3, 4),
        (3, 5),
        (3, 6),
        (4, 1),
        (4, 2),
        (4, 3),
        (4, 4),
        (4, 5),
        (4, 6),
        (5, 1),
        (5, 2),
        (5, 3),
        (5, 4),
        (5, 5),
        (5, 6),
        (6, 1),
        (6, 2),
        (6, 3),
        (6, 4),
        (6, 5),
        (6, 6)
    );
}

/// `y = a x` for an R x C column-major `a`: nalgebra's operation order (see the module).
/// `acc = p + acc`, not `acc += p`: the product is the left operand, as in nalgebra's axpy,
/// which decides the payload when both are NaN.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn gemv_fixed<const R: usize, const C: usize>(y: &mut [f64], a: &[f64], x: &[f64]) {
    let (y, a, x): (&mut [f64; R], &[f64], &[f64; C]) = (
        y.try_into().expect("R rows"),
        &a[..R * C],
        x.try_into().expect("C columns"),
    );
    let mut acc = [0.0; R];
    for r in 0..R {
        acc[r] = a[r] * x[0];
    }
    for j in 1..C {
        let xj = x[j];
        let col = &a[j * R..(j + 1) * R];
        for r in 0..R {
            acc[r] = col[r] * xj + acc[r];
        }
    }
    *y = acc;
}

/// `x <- a x` through the buffer `tmp` (no allocation), bit for bit as `a * &x`.
pub fn mul_in_place(a: &Matrix, x: &mut Vector, tmp: &mut Vector) {
    gemv(tmp, a, x);
    std::mem::swap(x, tmp);
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn bits(v: &Vector) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        /// The fixed-size kernel equals the dynamic gemv (and `&a * &x`) bit for bit, for
        /// every shape up to 7 x 7 (7 takes the dynamic fallback), with values spanning many
        /// magnitudes, signed zeros and infinities.
        #[test]
        fn fixed_gemv_is_bit_identical(
            r in 1usize..=7,
            c in 1usize..=7,
            vals in proptest::collection::vec(
                prop_oneof![
                    8 => -1e3f64..1e3,
                    1 => (-300i32..300).prop_map(|e| 10f64.powi(e)),
                    1 => Just(-0.0f64),
                    1 => Just(0.0f64),
                    1 => Just(f64::INFINITY),
                ],
                56,
            ),
        ) {
            let a = Matrix::from_fn(r, c, |i, j| vals[(i * 7 + j) % 56]);
            let x = Vector::from_fn(c, |i, _| vals[(49 + i) % 56]);
            let mut fast = Vector::zeros(r);
            gemv(&mut fast, &a, &x);
            let mut dynamic = Vector::zeros(r);
            dynamic.gemv(1.0, &a, &x, 0.0);
            let expr = &a * &x;
            prop_assert_eq!(bits(&fast), bits(&dynamic));
            prop_assert_eq!(bits(&fast), bits(&expr));
        }
    }
}
