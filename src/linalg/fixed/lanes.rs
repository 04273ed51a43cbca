//! The fixed kernels on [`WIDTH`] independent problems at once (the trials of a lockstep
//! batch): each number is a [`Lanes`] array, one problem per lane, and every lane goes through
//! exactly the operations of the scalar kernel it mirrors, in the same order, so every lane's
//! bits are the scalar kernel's bits on that lane's data.
//!
//! Why: a trial's Cholesky solves are chains of dependent divisions, and a scalar division
//! takes the divider for as long as a vector one. Laid out across trials, the lanes of a chain
//! divide by the same diagonal at once (one `vdivpd` for four trials with AVX2), which is where
//! the batched Kalman Monte Carlo spent its time.
#![allow(clippy::needless_range_loop)]

/// Problems per lane array: four doubles fill an AVX2 register.
pub const WIDTH: usize = 4;

/// One number of every lane.
pub type Lanes = [f64; WIDTH];

/// `a x` for an R x C column-major `a` shared by the lanes: [`super::mat_vec`] per lane.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn mat_vec<const R: usize, const C: usize>(a: &[f64], x: &[Lanes; C]) -> [Lanes; R] {
    let a = &a[..R * C];
    let mut acc = [[0.0; WIDTH]; R];
    for r in 0..R {
        for l in 0..WIDTH {
            acc[r][l] = a[r] * x[0][l];
        }
    }
    for j in 1..C {
        let col = &a[j * R..(j + 1) * R];
        for r in 0..R {
            for l in 0..WIDTH {
                acc[r][l] = col[r] * x[j][l] + acc[r][l];
            }
        }
    }
    acc
}

/// `a x` for a column-major `a` of R rows and `x.len()` columns (a sensor's H^T R^{-1}) shared
/// by the lanes: [`super::mat_vec_cols_by`] per lane (with its map already applied to `x`).
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn mat_vec_cols<const R: usize>(a: &[f64], x: &[Lanes]) -> [Lanes; R] {
    let mut acc = [[0.0; WIDTH]; R];
    let Some((x0, rest)) = x.split_first() else {
        return acc;
    };
    let a = &a[..R * x.len()];
    for r in 0..R {
        for l in 0..WIDTH {
            acc[r][l] = a[r] * x0[l];
        }
    }
    for (j, xj) in rest.iter().enumerate() {
        let col = &a[(j + 1) * R..(j + 2) * R];
        for r in 0..R {
            for l in 0..WIDTH {
                acc[r][l] = col[r] * xj[l] + acc[r][l];
            }
        }
    }
    acc
}

/// Forward substitution with the lower triangle of the column-major N x N `l` shared by the
/// lanes: the scalar forward substitution (`lower_solve_fixed`) per lane. False at a zero diagonal, which the lanes
/// share, so every lane stops where the scalar kernel stops.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn lower_solve<const N: usize>(l: &[f64], b: &mut [Lanes; N]) -> bool {
    let l = &l[..N * N];
    for i in 0..N {
        let d = l[i * N + i];
        if d == 0.0 {
            return false;
        }
        let mut coeff = [0.0; WIDTH];
        for w in 0..WIDTH {
            coeff[w] = b[i][w] / d;
        }
        b[i] = coeff;
        for j in i + 1..N {
            let lij = l[i * N + j];
            for w in 0..WIDTH {
                b[j][w] = -coeff[w] * lij + b[j][w];
            }
        }
    }
    true
}

/// `b <- P^{-1} b` with the dirty Cholesky factor `l` of P shared by the lanes:
/// [`super::chol_solve_array`] per lane (its forward substitution's result ignored, as there).
#[inline(always)]
pub fn chol_solve<const N: usize>(l: &[f64], b: &mut [Lanes; N]) {
    let l = &l[..N * N];
    lower_solve::<N>(l, b);
    for i in (0..N).rev() {
        let mut dot = [0.0; WIDTH];
        for j in i + 1..N {
            let lij = l[i * N + j];
            for w in 0..WIDTH {
                dot[w] += lij * b[j][w];
            }
        }
        let d = l[i * N + i];
        for w in 0..WIDTH {
            b[i][w] = (b[i][w] - dot[w]) / d;
        }
    }
}

/// `e^T P^{-1} e` per lane from the factor of [`super::nees_factor`]:
/// [`super::mahalanobis_sq_factored`] per lane (`None` at a zero diagonal, for every lane).
#[inline(always)]
pub fn mahalanobis_sq_factored<const N: usize>(e: &[Lanes; N], factor: &[f64]) -> Option<Lanes> {
    let mut w = *e;
    if !lower_solve::<N>(factor, &mut w) {
        return None;
    }
    let mut s = [0.0; WIDTH];
    for v in w {
        for l in 0..WIDTH {
            s[l] += v[l] * v[l];
        }
    }
    Some(s)
}

/// Rows `x[..]` of up to [`WIDTH`] problems as lanes: lane l is `rows[l]`, and the lanes past
/// the rows repeat the first (work that is thrown away, on numbers that cannot fault).
#[inline(always)]
pub fn gather<const N: usize>(rows: &[[f64; N]]) -> [Lanes; N] {
    let first = rows.first().copied().unwrap_or([0.0; N]);
    let mut out = [[0.0; WIDTH]; N];
    for l in 0..WIDTH {
        let row = rows.get(l).unwrap_or(&first);
        for c in 0..N {
            out[c][l] = row[c];
        }
    }
    out
}

/// The inverse of [`gather`]: row l of `rows` from lane l, for the rows there are.
#[inline(always)]
pub fn scatter<const N: usize>(lanes: &[Lanes; N], rows: &mut [[f64; N]]) {
    for (l, row) in rows.iter_mut().enumerate().take(WIDTH) {
        for c in 0..N {
            row[c] = lanes[c][l];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A random column-major lower-triangular factor with a positive diagonal and garbage in
    /// the strict upper triangle (a dirty factor), and random lanes of every sign and scale.
    fn problem<const N: usize>(
        rng: &mut rand_xoshiro::Xoshiro256PlusPlus,
    ) -> (Vec<f64>, [Lanes; N]) {
        let mut l = vec![0.0; N * N];
        for c in 0..N {
            for r in 0..N {
                let v: f64 = rng.random_range(-3.0..3.0);
                l[c * N + r] = if r == c { v.abs() + 0.1 } else { v };
            }
        }
        let scale =
            |rng: &mut rand_xoshiro::Xoshiro256PlusPlus| 10f64.powi(rng.random_range(-8..8));
        let b = std::array::from_fn(|_| {
            std::array::from_fn(|_| rng.random_range(-1.0..1.0) * scale(rng))
        });
        (l, b)
    }

    fn lane<const N: usize>(b: &[Lanes; N], l: usize) -> [f64; N] {
        std::array::from_fn(|c| b[c][l])
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    fn check<const N: usize>(seed: u64) {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
        for _ in 0..200 {
            let (l, b) = problem::<N>(&mut rng);
            let mut solved = b;
            chol_solve::<N>(&l, &mut solved);
            let prod: [Lanes; N] = mat_vec::<N, N>(&l, &b);
            let cols: [Lanes; N] = mat_vec_cols::<N>(&l, &b);
            let nees = mahalanobis_sq_factored::<N>(&b, &l).expect("positive diagonal");
            for w in 0..WIDTH {
                let mut one = lane(&b, w);
                super::super::chol_solve_array::<N>(&l, &mut one);
                assert!(same_bits(&one, &lane(&solved, w)), "chol_solve, lane {w}");
                let p: [f64; N] = super::super::mat_vec::<N, N>(&l, &lane(&b, w));
                assert!(same_bits(&p, &lane(&prod, w)), "mat_vec, lane {w}");
                let q: [f64; N] = super::super::mat_vec_cols_by::<N>(&l, &lane(&b, w), |x| x);
                assert!(same_bits(&q, &lane(&cols, w)), "mat_vec_cols, lane {w}");
                let m = super::super::mahalanobis_sq_factored(&lane(&b, w), &l).expect("dims");
                assert_eq!(m.to_bits(), nees[w].to_bits(), "mahalanobis, lane {w}");
            }
        }
    }

    #[test]
    fn every_lane_is_the_scalar_kernel_bit_for_bit() {
        check::<1>(1);
        check::<2>(2);
        check::<3>(3);
        check::<4>(4);
        check::<5>(5);
        check::<6>(6);
    }

    #[test]
    fn a_zero_diagonal_stops_every_lane_where_the_scalar_kernel_stops() {
        let l = [2.0, 1.0, 0.0, 0.0]; // column-major 2 x 2, L11 = 0
        let b: [Lanes; 2] = [[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]];
        assert!(mahalanobis_sq_factored::<2>(&b, &l).is_none());
        let mut solved = b;
        chol_solve::<2>(&l, &mut solved);
        for w in 0..WIDTH {
            let mut one = lane(&b, w);
            super::super::chol_solve_array::<2>(&l, &mut one);
            assert!(same_bits(&one, &lane(&solved, w)), "lane {w}");
        }
    }

    #[test]
    fn gather_pads_with_the_first_row_and_scatter_writes_only_the_rows() {
        let rows = [[1.0, 2.0], [3.0, 4.0]];
        let lanes = gather(&rows);
        assert_eq!(lanes, [[1.0, 3.0, 1.0, 1.0], [2.0, 4.0, 2.0, 2.0]]);
        let mut back = [[0.0; 2]; 2];
        scatter(&lanes, &mut back);
        assert_eq!(back, rows);
    }
}
