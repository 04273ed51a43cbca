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
use crate::linalg::quad::Real;
use crate::linalg::types::{Matrix, Vector};

/// `y = a x`, bit for bit as `y.gemv(1.0, a, x, 0.0)`.
pub fn gemv(y: &mut Vector, a: &Matrix, x: &Vector) {
    let (r, c) = a.shape();
    assert!(
        x.len() == c && y.len() == r,
        "gemv: dimensions mismatch ({r}x{c} times {}, into {})",
        x.len(),
        y.len()
    );
    // One index for the shape, so that the dispatch is a jump table, not 36 comparisons.
    let shape = if (1..=6).contains(&r) && (1..=6).contains(&c) {
        r * 8 + c
    } else {
        0
    };
    let (ys, as_, xs) = (y.as_mut_slice(), a.as_slice(), x.as_slice());
    match shape {
        9 => gemv_fixed::<1, 1, _>(ys, as_, xs),
        10 => gemv_fixed::<1, 2, _>(ys, as_, xs),
        11 => gemv_fixed::<1, 3, _>(ys, as_, xs),
        12 => gemv_fixed::<1, 4, _>(ys, as_, xs),
        13 => gemv_fixed::<1, 5, _>(ys, as_, xs),
        14 => gemv_fixed::<1, 6, _>(ys, as_, xs),
        17 => gemv_fixed::<2, 1, _>(ys, as_, xs),
        18 => gemv_fixed::<2, 2, _>(ys, as_, xs),
        19 => gemv_fixed::<2, 3, _>(ys, as_, xs),
        20 => gemv_fixed::<2, 4, _>(ys, as_, xs),
        21 => gemv_fixed::<2, 5, _>(ys, as_, xs),
        22 => gemv_fixed::<2, 6, _>(ys, as_, xs),
        25 => gemv_fixed::<3, 1, _>(ys, as_, xs),
        26 => gemv_fixed::<3, 2, _>(ys, as_, xs),
        27 => gemv_fixed::<3, 3, _>(ys, as_, xs),
        28 => gemv_fixed::<3, 4, _>(ys, as_, xs),
        29 => gemv_fixed::<3, 5, _>(ys, as_, xs),
        30 => gemv_fixed::<3, 6, _>(ys, as_, xs),
        33 => gemv_fixed::<4, 1, _>(ys, as_, xs),
        34 => gemv_fixed::<4, 2, _>(ys, as_, xs),
        35 => gemv_fixed::<4, 3, _>(ys, as_, xs),
        36 => gemv_fixed::<4, 4, _>(ys, as_, xs),
        37 => gemv_fixed::<4, 5, _>(ys, as_, xs),
        38 => gemv_fixed::<4, 6, _>(ys, as_, xs),
        41 => gemv_fixed::<5, 1, _>(ys, as_, xs),
        42 => gemv_fixed::<5, 2, _>(ys, as_, xs),
        43 => gemv_fixed::<5, 3, _>(ys, as_, xs),
        44 => gemv_fixed::<5, 4, _>(ys, as_, xs),
        45 => gemv_fixed::<5, 5, _>(ys, as_, xs),
        46 => gemv_fixed::<5, 6, _>(ys, as_, xs),
        49 => gemv_fixed::<6, 1, _>(ys, as_, xs),
        50 => gemv_fixed::<6, 2, _>(ys, as_, xs),
        51 => gemv_fixed::<6, 3, _>(ys, as_, xs),
        52 => gemv_fixed::<6, 4, _>(ys, as_, xs),
        53 => gemv_fixed::<6, 5, _>(ys, as_, xs),
        54 => gemv_fixed::<6, 6, _>(ys, as_, xs),
        _ => y.gemv(1.0, a, x, 0.0),
    }
}

/// `y = a x` for an R x C column-major `a`: nalgebra's operation order (see the module).
/// `acc = p + acc`, not `acc += p`: the product is the left operand, as in nalgebra's axpy,
/// which decides the payload when both are NaN.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn gemv_fixed<const R: usize, const C: usize, T: Real>(y: &mut [T], a: &[f64], x: &[T]) {
    let (y, a, x): (&mut [T; R], &[f64], &[T; C]) = (
        y.try_into().expect("R rows"),
        &a[..R * C],
        x.try_into().expect("C columns"),
    );
    let mut acc = [T::ZERO; R];
    for r in 0..R {
        acc[r] = T::scaled(a[r], x[0]);
    }
    for j in 1..C {
        let xj = x[j];
        let col = &a[j * R..(j + 1) * R];
        for r in 0..R {
            acc[r] = T::scaled(col[r], xj) + acc[r];
        }
    }
    *y = acc;
}

/// `a x` for an R x C column-major `a` on arrays: [`gemv`]'s operations (nalgebra's order),
/// for callers that keep their small vectors on the stack.
#[inline(always)]
pub fn mat_vec<const R: usize, const C: usize, T: Real>(a: &[f64], x: &[T; C]) -> [T; R] {
    let mut y = [T::ZERO; R];
    gemv_fixed::<R, C, T>(&mut y, a, x);
    y
}

/// `y = a x` for a column-major `a` of `y.len()` rows and C columns: [`gemv`]'s operations
/// with the row count known only at run time (a sensor's measurement dimension).
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn mat_vec_rows<const C: usize>(y: &mut [f64], a: &[f64], x: &[f64; C]) {
    let r = y.len();
    let a = &a[..r * C];
    for (i, yi) in y.iter_mut().enumerate() {
        let mut acc = a[i] * x[0];
        for j in 1..C {
            acc = a[j * r + i] * x[j] + acc;
        }
        *yi = acc;
    }
}

/// `a x` for a column-major `a` of R rows and `x.len()` columns (a sensor's H^T R^{-1}):
/// [`gemv`]'s operations with the column count known only at run time.
#[inline(always)]
pub fn mat_vec_cols<const R: usize>(a: &[f64], x: &[f64]) -> [f64; R] {
    mat_vec_cols_by(a, x, |v| v)
}

/// [`mat_vec_cols`] of `map` of each entry of `x` (a fast path's measurement as it arrives,
/// without a copy): the same operations on the mapped entries.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn mat_vec_cols_by<const R: usize, T: Real>(
    a: &[f64],
    x: &[T],
    map: impl Fn(T) -> T,
) -> [T; R] {
    let mut acc = [T::ZERO; R];
    let Some((&x0, rest)) = x.split_first() else {
        return acc;
    };
    let a = &a[..R * x.len()];
    let x0 = map(x0);
    for r in 0..R {
        acc[r] = T::scaled(a[r], x0);
    }
    for (j, &xj) in rest.iter().enumerate() {
        let xj = map(xj);
        let col = &a[(j + 1) * R..(j + 2) * R];
        for r in 0..R {
            acc[r] = T::scaled(col[r], xj) + acc[r];
        }
    }
    acc
}

/// `y = a x` for a column-major `a` of `y.len()` rows and `x.len()` columns, both known only
/// at run time: [`gemv`]'s operations, in a loop.
#[inline]
#[allow(clippy::assign_op_pattern)]
pub fn mat_vec_dyn(y: &mut [f64], a: &[f64], x: &[f64]) {
    let (r, c) = (y.len(), x.len());
    if c == 0 {
        y.fill(0.0);
        return;
    }
    let a = &a[..r * c];
    for (i, yi) in y.iter_mut().enumerate() {
        let mut acc = a[i] * x[0];
        for j in 1..c {
            acc = a[j * r + i] * x[j] + acc;
        }
        *yi = acc;
    }
}

/// `b <- P^{-1} b` with the (dirty) column-major Cholesky factor `l` of an N x N P:
/// [`chol_solve`]'s operations on an array.
#[inline(always)]
pub fn chol_solve_array<const N: usize, T: Real>(l: &[f64], b: &mut [T; N]) {
    chol_solve_fixed::<N, T>(l, b);
}

/// `x <- a x` through the buffer `tmp` (no allocation), bit for bit as `a * &x`.
pub fn mul_in_place(a: &Matrix, x: &mut Vector, tmp: &mut Vector) {
    gemv(tmp, a, x);
    std::mem::swap(x, tmp);
}

/// Runs `$body` with `N` bound to the dimension `$n` when it is 1..=6, else `$fallback`.
macro_rules! with_dim {
    ($n:expr, $body:ident ( $($arg:expr),* ), $fallback:expr) => {
        match $n {
            1 => $body::<1>($($arg),*),
            2 => $body::<2>($($arg),*),
            3 => $body::<3>($($arg),*),
            4 => $body::<4>($($arg),*),
            5 => $body::<5>($($arg),*),
            6 => $body::<6>($($arg),*),
            _ => $fallback,
        }
    };
}

/// `b <- P^{-1} b` with the Cholesky factor of P, bit for bit as nalgebra's
/// `Cholesky::solve_mut` on a vector: forward substitution with L (`b_i /= L_ii`, then
/// `b_j = -b_i L_ji + b_j` below), then back substitution with L^T (`b_i = (b_i - dot) / L_ii`,
/// the dot accumulated from +0 in row order, as nalgebra's dynamic `dotc` does below 8 terms).
pub fn chol_solve(chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>, b: &mut Vector) {
    let l = chol.l_dirty();
    assert_eq!(l.nrows(), b.len(), "chol_solve: dimensions mismatch");
    with_dim!(
        b.len(),
        chol_solve_f64(l.as_slice(), b.as_mut_slice()),
        chol.solve_mut(b)
    )
}

/// [`chol_solve_fixed`] on one trial's numbers (for `with_dim!`, which names N only).
#[inline(always)]
fn chol_solve_f64<const N: usize>(l: &[f64], b: &mut [f64]) {
    chol_solve_fixed::<N, f64>(l, b);
}

#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn chol_solve_fixed<const N: usize, T: Real>(l: &[f64], b: &mut [T]) {
    let (l, b): (&[f64], &mut [T; N]) = (&l[..N * N], b.try_into().expect("N rows"));
    lower_solve_fixed::<N, T>(l, b);
    for i in (0..N).rev() {
        let mut dot = T::ZERO;
        for j in i + 1..N {
            dot = dot + T::scaled(l[i * N + j], b[j]);
        }
        b[i] = (b[i] - dot).over(l[i * N + i]);
    }
}

/// Forward substitution with the lower triangle of the column-major N x N `l` (nalgebra's
/// `solve_lower_triangular_unchecked_mut` on a vector). Returns false at a zero diagonal
/// (as the checked version does; then `b` is partly solved).
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn lower_solve_fixed<const N: usize, T: Real>(l: &[f64], b: &mut [T; N]) -> bool {
    for i in 0..N {
        let d = l[i * N + i];
        if d == 0.0 {
            return false;
        }
        let coeff = b[i].over(d);
        b[i] = coeff;
        for j in i + 1..N {
            b[j] = (-coeff).times(l[i * N + j]) + b[j];
        }
    }
    true
}

/// nalgebra's `Cholesky::new` on a column-major N x N matrix, in place: for each column j,
/// `col_j[j..] = -L_jk col_k[j..] + col_j[j..]` for k < j, then the square root of the diagonal
/// (refused when zero, negative or NaN) and the division of the rest of the column by it. The
/// strict upper triangle is left as it was (nalgebra's "dirty" factor).
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn cholesky_fixed<const N: usize>(m: &mut [f64]) -> bool {
    let m = &mut m[..N * N];
    for j in 0..N {
        for k in 0..j {
            let factor = -m[k * N + j];
            for r in j..N {
                m[j * N + r] = factor * m[k * N + r] + m[j * N + r];
            }
        }
        let diag = m[j * N + j];
        // `is_zero` then `try_sqrt` (`v >= 0`): NaN and negatives fail.
        if diag == 0.0 || diag.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return false;
        }
        let denom = diag.sqrt();
        m[j * N + j] = denom;
        for r in j + 1..N {
            m[j * N + r] /= denom;
        }
    }
    true
}

/// `e^T P^{-1} e` as [`crate::linalg::mahalanobis_sq`] computes it for a finite square `p` of
/// dimension 1..=6 (nalgebra's Cholesky factorization, the checked forward substitution with
/// L and the squared norm summed from +0 in order), in fixed-size buffers. `None` for other
/// dimensions (the caller takes the dynamic path); `Some(None)` when P is not positive
/// definite.
pub fn mahalanobis_sq_small(e: &Vector, p: &Matrix) -> Option<Option<f64>> {
    mahalanobis_sq_small_slice(e.as_slice(), p)
}

/// [`mahalanobis_sq_small`] of an error held in a slice.
pub fn mahalanobis_sq_small_slice(e: &[f64], p: &Matrix) -> Option<Option<f64>> {
    let n = e.len();
    if p.nrows() != n || p.ncols() != n {
        return None;
    }
    with_dim!(n, mahalanobis_fixed(e, p.as_slice()), None)
}

#[inline(always)]
fn mahalanobis_fixed<const N: usize>(e: &[f64], p: &[f64]) -> Option<Option<f64>> {
    let mut m = [[0.0; N]; N];
    for (c, col) in m.iter_mut().enumerate() {
        col.copy_from_slice(&p[c * N..(c + 1) * N]);
    }
    let m = m.as_flattened_mut();
    if !cholesky_fixed::<N>(m) {
        return Some(None);
    }
    let mut w: [f64; N] = e.try_into().expect("N rows");
    if !lower_solve_fixed::<N, _>(m, &mut w) {
        return Some(None);
    }
    let mut s = 0.0;
    for v in w {
        s += v * v;
    }
    Some(Some(s))
}

/// The dirty Cholesky factor [`mahalanobis_sq_small`] computes from a finite square `p` of
/// dimension 1..=6 (column-major, strict upper triangle as in `p`); `None` for other
/// dimensions, for a non-finite `p` and when P is not positive definite.
pub fn nees_factor(p: &Matrix) -> Option<Vec<f64>> {
    let n = p.nrows();
    if !(1..=6).contains(&n) || p.ncols() != n || p.as_slice().iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut m = p.as_slice().to_vec();
    with_dim!(n, cholesky_fixed(&mut m), false).then_some(m)
}

/// `e^T P^{-1} e` from the factor of [`nees_factor`]: the forward substitution and the sum of
/// squares of [`mahalanobis_sq_small`], hence its number. `None` for dimensions it does not
/// cover (the factor of a positive definite P has no zero diagonal).
#[inline]
pub fn mahalanobis_sq_factored(e: &[f64], factor: &[f64]) -> Option<f64> {
    let n = e.len();
    if factor.len() != n * n {
        return None;
    }
    with_dim!(n, mahalanobis_from_factor(e, factor), None)
}

#[inline(always)]
fn mahalanobis_from_factor<const N: usize>(e: &[f64], l: &[f64]) -> Option<f64> {
    mahalanobis_factored_array::<N, f64>(e.try_into().ok()?, l)
}

/// [`mahalanobis_sq_factored`] of N numbers: one trial's error, or four trials' in lanes
/// ([`crate::linalg::quad::F64x4`]). `None` at a zero diagonal of the factor.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn mahalanobis_factored_array<const N: usize, T: Real>(e: [T; N], l: &[f64]) -> Option<T> {
    let mut w = e;
    if !lower_solve_fixed::<N, T>(&l[..N * N], &mut w) {
        return None;
    }
    let mut s = T::ZERO;
    for v in w {
        s = s + v * v;
    }
    Some(s)
}

/// An LU factorization (`A.clone().lu()`) ready to solve with: for dimensions 1..=6 the
/// packed factors (unit lower L below the diagonal, U on and above it) and the row
/// permutation as a gather, inline (no heap); nalgebra's own factorization otherwise.
// The small case is inline on purpose: one per memoized Δ^pp, and no heap block each.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum PackedLu {
    Fixed {
        n: usize,
        /// Column-major n x n (stride n): L strictly below the diagonal, U on and above.
        lu: [f64; 36],
        /// The permutation's swaps applied to the rows of b, as `out[i] = b[perm[i]]`.
        perm: [u8; 6],
    },
    Dynamic(Box<nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>>),
}

impl PackedLu {
    /// Takes the factorization `lu` (of a square matrix).
    pub fn new(lu: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>) -> Self {
        let l = lu.l();
        let n = l.nrows();
        if !(1..=6).contains(&n) || l.ncols() != n {
            return PackedLu::Dynamic(Box::new(lu));
        }
        let u = lu.u();
        let mut packed = [0.0; 36];
        for c in 0..n {
            for r in 0..n {
                packed[c * n + r] = if r > c { l[(r, c)] } else { u[(r, c)] };
            }
        }
        // Applying the swaps to the indices moves them as it would move b's entries.
        let mut idx = Vector::from_fn(n, |i, _| i as f64);
        lu.p().permute_rows(&mut idx);
        let mut perm = [0u8; 6];
        for (p, &v) in perm.iter_mut().zip(idx.iter()) {
            *p = v as u8;
        }
        PackedLu::Fixed {
            n,
            lu: packed,
            perm,
        }
    }

    /// `b <- A^{-1} b`, bit for bit as nalgebra's `LU::solve_mut` on a vector (row swaps,
    /// unit forward substitution `b_j = -b_i L_ji + b_j`, back substitution `b_i /= U_ii`,
    /// `b_j = -b_i U_ji + b_j` above). Returns false at a zero pivot, as `solve_mut` does.
    pub fn solve(&self, b: &mut Vector) -> bool {
        match self {
            PackedLu::Fixed { n, lu, perm } => {
                assert_eq!(b.len(), *n, "lu_solve: dimensions mismatch");
                with_dim!(
                    *n,
                    lu_solve_fixed(lu, perm, b.as_mut_slice()),
                    unreachable!("packed only for n <= 6")
                )
            }
            PackedLu::Dynamic(lu) => lu.solve_mut(b),
        }
    }
}

#[inline(always)]
#[allow(clippy::assign_op_pattern)]
fn lu_solve_fixed<const N: usize>(lu: &[f64], perm: &[u8], b: &mut [f64]) -> bool {
    let (lu, perm, b): (&[f64], &[u8], &mut [f64; N]) =
        (&lu[..N * N], &perm[..N], b.try_into().expect("N rows"));
    let src = *b;
    for i in 0..N {
        b[i] = src[usize::from(perm[i])];
    }
    // Unit lower triangle: nalgebra divides by the unit diagonal (exact) and never reads it.
    for i in 0..N - 1 {
        let coeff = b[i] / 1.0;
        for j in i + 1..N {
            b[j] = -coeff * lu[i * N + j] + b[j];
        }
    }
    for i in (0..N).rev() {
        let d = lu[i * N + i];
        if d == 0.0 {
            return false;
        }
        let coeff = b[i] / d;
        b[i] = coeff;
        for j in 0..i {
            b[j] = -coeff * lu[i * N + j] + b[j];
        }
    }
    true
}

/// `y = a b` for square n x n matrices, bit for bit as `y.gemm(1.0, a, b, 0.0)`: below 6
/// nalgebra runs one gemv per column of b (as [`gemv`]); from 6 on it calls matrixmultiply,
/// whose kernels on x86-64 with FMA (AVX2+FMA, AVX-512) accumulate each entry as a chain of
/// fused multiply-adds over k from +0 and scale by alpha = 1 (exact). That chain is emulated
/// at n = 6 when the CPU has those features; everything else takes nalgebra's own path.
pub fn gemm(y: &mut Matrix, a: &Matrix, b: &Matrix) {
    let n = a.nrows();
    let square = |m: &Matrix| m.nrows() == n && m.ncols() == n;
    if !(square(y) && square(a) && square(b)) {
        y.gemm(1.0, a, b, 0.0);
        return;
    }
    macro_rules! columns {
        ($nn:literal) => {{
            let (a, b) = (a.as_slice(), b.as_slice());
            for (j, col) in y.as_mut_slice().chunks_exact_mut($nn).enumerate() {
                gemv_fixed::<$nn, $nn, _>(col, a, &b[j * $nn..(j + 1) * $nn]);
            }
        }};
    }
    match n {
        1 => columns!(1),
        2 => columns!(2),
        3 => columns!(3),
        4 => columns!(4),
        5 => columns!(5),
        6 if matrixmultiply_uses_fma() => {
            // SAFETY: the CPU has FMA (checked just above).
            unsafe { gemm_fma_6(y.as_mut_slice(), a.as_slice(), b.as_slice()) }
        }
        _ => y.gemm(1.0, a, b, 0.0),
    }
}

/// Whether matrixmultiply's f64 kernel on this CPU is one of its FMA kernels.
fn matrixmultiply_uses_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("fma") && std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `y = a b`, 6 x 6 column-major: `y_ij = fma(a_i5, b_5j, ... fma(a_i0, b_0j, +0))`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "fma")]
unsafe fn gemm_fma_6(y: &mut [f64], a: &[f64], b: &[f64]) {
    const N: usize = 6;
    let (y, a, b) = (&mut y[..N * N], &a[..N * N], &b[..N * N]);
    for j in 0..N {
        let mut acc = [0.0f64; N];
        for k in 0..N {
            let bkj = b[j * N + k];
            for i in 0..N {
                acc[i] = a[k * N + i].mul_add(bkj, acc[i]);
            }
        }
        y[j * N..(j + 1) * N].copy_from_slice(&acc);
    }
}

#[cfg(not(target_arch = "x86_64"))]
unsafe fn gemm_fma_6(_: &mut [f64], _: &[f64], _: &[f64]) {
    unreachable!("only called when matrixmultiply_uses_fma")
}

/// `Cholesky::new(m)`, with the factorization in fixed size for dimensions 1..=6 (the same
/// operations, see `cholesky_fixed`).
pub fn cholesky(mut m: Matrix) -> Option<nalgebra::Cholesky<f64, nalgebra::Dyn>> {
    let n = m.nrows();
    if n != m.ncols() {
        return nalgebra::Cholesky::new(m);
    }
    let ok = with_dim!(n, cholesky_fixed(m.as_mut_slice()), {
        return nalgebra::Cholesky::new(m);
    });
    ok.then(|| nalgebra::Cholesky::pack_dirty(m))
}

/// `chol.solve_mut(b)` for a matrix b, column by column as [`chol_solve`] (nalgebra solves
/// every column forward and then every column backward; the columns are independent).
pub fn chol_solve_matrix(chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>, b: &mut Matrix) {
    let l = chol.l_dirty();
    let n = l.nrows();
    assert_eq!(n, b.nrows(), "chol_solve_matrix: dimensions mismatch");
    macro_rules! columns {
        ($nn:literal) => {{
            for col in b.as_mut_slice().chunks_exact_mut($nn) {
                chol_solve_fixed::<$nn, _>(l.as_slice(), col);
            }
        }};
    }
    match n {
        1 => columns!(1),
        2 => columns!(2),
        3 => columns!(3),
        4 => columns!(4),
        5 => columns!(5),
        6 => columns!(6),
        _ => chol.solve_mut(b),
    }
}

/// nalgebra's dot product of two dynamic vectors (`a.dot(b)`), bit for bit: eight partial
/// sums over blocks of eight, folded as (0+4), (1+5), (2+6), (3+7) into a sum from +0, then the
/// remaining terms one by one.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "dot: dimensions mismatch");
    let n = a.len();
    let mut acc = [0.0f64; 8];
    let mut i = 0;
    while n - i >= 8 {
        for (j, s) in acc.iter_mut().enumerate() {
            *s += a[i + j] * b[i + j];
        }
        i += 8;
    }
    let mut res = 0.0;
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for k in i..n {
        res += a[k] * b[k];
    }
    res
}

/// `v.norm()` of a dynamic vector, bit for bit: the square root of `0 + v.dot(v)`.
pub fn norm(v: &[f64]) -> f64 {
    let mut res = 0.0;
    res += dot(v, v);
    res.sqrt()
}

/// `a += b` element by element, as nalgebra's `+=` (`a_i + b_i`).
pub fn add_assign(a: &mut [f64], b: &[f64]) {
    assert_eq!(a.len(), b.len(), "add_assign: dimensions mismatch");
    for (x, y) in a.iter_mut().zip(b) {
        *x += y;
    }
}

/// `a -= b` element by element, as nalgebra's `-=` (`a_i - b_i`).
pub fn sub_assign(a: &mut [f64], b: &[f64]) {
    assert_eq!(a.len(), b.len(), "sub_assign: dimensions mismatch");
    for (x, y) in a.iter_mut().zip(b) {
        *x -= y;
    }
}

/// `y = a x` for a square `a`, on slices (vectors kept in flat buffers), bit for bit as
/// [`gemv`]: the same fixed-size kernel for dimensions 1..=6, nalgebra's gemv on views of the
/// slices otherwise (the same generic code as on owned vectors).
pub fn gemv_square(y: &mut [f64], a: &Matrix, x: &[f64]) {
    let n = a.nrows();
    assert!(
        a.ncols() == n && x.len() == n && y.len() == n,
        "gemv_square: dimensions mismatch ({n}x{} times {}, into {})",
        a.ncols(),
        x.len(),
        y.len()
    );
    with_dim!(n, gemv_fixed_square(y, a.as_slice(), x), {
        let x = nalgebra::DVectorView::from_slice(x, n);
        nalgebra::DVectorViewMut::from_slice(y, n).gemv(1.0, a, &x, 0.0)
    })
}

#[inline(always)]
fn gemv_fixed_square<const N: usize>(y: &mut [f64], a: &[f64], x: &[f64]) {
    gemv_fixed::<N, N, _>(y, a, x)
}

impl PackedLu {
    /// [`PackedLu::new`] without unpacking L and U into matrices of their own: nalgebra keeps
    /// both in one matrix (`lu_internal`: L strictly below the diagonal, U on and above it),
    /// which is the packed layout already. The same factors and permutation, bit for bit.
    pub fn from_packed(lu: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>) -> Self {
        let m = lu.lu_internal();
        let n = m.nrows();
        if !(1..=6).contains(&n) || m.ncols() != n {
            return PackedLu::Dynamic(Box::new(lu));
        }
        let mut packed = [0.0; 36];
        packed[..n * n].copy_from_slice(m.as_slice());
        let mut idx = Vector::from_fn(n, |i, _| i as f64);
        lu.p().permute_rows(&mut idx);
        let mut perm = [0u8; 6];
        for (p, &v) in perm.iter_mut().zip(idx.iter()) {
            *p = v as u8;
        }
        PackedLu::Fixed {
            n,
            lu: packed,
            perm,
        }
    }
}

/// `b <- L^{-1} b` with the lower triangle of a (dirty) Cholesky factor `l`, bit for bit as
/// nalgebra's checked `l.solve_lower_triangular_mut(b)` (and so as `chol.l()
/// .solve_lower_triangular(&b)`, which reads only the lower triangle): forward substitution,
/// `b_i /= L_ii`, then `b_j = -b_i L_ji + b_j` below. False at a zero diagonal. Fixed size for
/// dimensions 1..=6, nalgebra's own solve otherwise.
pub fn lower_solve(l: &Matrix, b: &mut Vector) -> bool {
    let n = b.len();
    assert!(
        l.nrows() == n && l.ncols() == n,
        "lower_solve: dimensions mismatch"
    );
    macro_rules! fixed {
        ($nn:literal) => {{
            let b: &mut [f64; $nn] = b.as_mut_slice().try_into().expect("n rows");
            lower_solve_fixed::<$nn, _>(l.as_slice(), b)
        }};
    }
    match n {
        1 => fixed!(1),
        2 => fixed!(2),
        3 => fixed!(3),
        4 => fixed!(4),
        5 => fixed!(5),
        6 => fixed!(6),
        _ => l.solve_lower_triangular_mut(b),
    }
}

// Square N x N kernels on flat column-major slices (`N * N` long, on the caller's stack):
// the operations of [`gemm`], [`cholesky`], `identity` + [`chol_solve_matrix`] and
// `linalg::symmetrize` on `Matrix`, for a filter that keeps its whole step in fixed size.
// Every operation of the reference is performed, so no shortcut depends on the values.

/// Whether [`gemm_square`] covers dimension `n` (as [`gemm`]'s own kernels do: below 6 always,
/// at 6 when the CPU has matrixmultiply's FMA kernel; nalgebra's path is taken otherwise).
pub fn gemm_square_covers(n: usize) -> bool {
    (1..6).contains(&n) || (n == 6 && matrixmultiply_uses_fma())
}

/// `y = a b` for N x N column-major slices, bit for bit as [`gemm`] on matrices. Panics
/// unless [`gemm_square_covers`]`(N)`.
#[inline(always)]
pub fn gemm_square<const N: usize>(y: &mut [f64], a: &[f64], b: &[f64]) {
    let (y, a, b) = (&mut y[..N * N], &a[..N * N], &b[..N * N]);
    if N < 6 {
        for (col, bj) in y.chunks_exact_mut(N).zip(b.chunks_exact(N)) {
            gemv_fixed::<N, N, _>(col, a, bj);
        }
    } else {
        assert!(
            N == 6 && matrixmultiply_uses_fma(),
            "gemm_square: not covered"
        );
        // SAFETY: the CPU has AVX2 and FMA (asserted just above).
        unsafe { gemm_fma_6_avx2(y, a, b) }
    }
}

/// `gemm_fma_6`'s chain `y_ij = fma(a_i5, b_5j, ... fma(a_i0, b_0j, +0))` with explicit
/// vectors: rows 0..4 of a column in one 256-bit register, rows 4..6 in one 128-bit register.
/// A vector FMA rounds each lane once, as `f64::mul_add` does, so the bits are the same.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn gemm_fma_6_avx2(y: &mut [f64], a: &[f64], b: &[f64]) {
    use std::arch::x86_64::*;
    const N: usize = 6;
    let (y, a, b) = (&mut y[..N * N], &a[..N * N], &b[..N * N]);
    for j in 0..N {
        let mut lo = _mm256_setzero_pd();
        let mut hi = _mm_setzero_pd();
        for k in 0..N {
            let col = &a[k * N..(k + 1) * N];
            let bkj = b[j * N + k];
            // SAFETY: `col` has 6 entries: loads of 0..4 and 4..6 stay inside it.
            let (al, ah) = unsafe {
                (
                    _mm256_loadu_pd(col.as_ptr()),
                    _mm_loadu_pd(col.as_ptr().add(4)),
                )
            };
            lo = _mm256_fmadd_pd(al, _mm256_set1_pd(bkj), lo);
            hi = _mm_fmadd_pd(ah, _mm_set1_pd(bkj), hi);
        }
        let out = &mut y[j * N..(j + 1) * N];
        // SAFETY: `out` has 6 entries: stores of 0..4 and 4..6 stay inside it.
        unsafe {
            _mm256_storeu_pd(out.as_mut_ptr(), lo);
            _mm_storeu_pd(out.as_mut_ptr().add(4), hi);
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
unsafe fn gemm_fma_6_avx2(_: &mut [f64], _: &[f64], _: &[f64]) {
    unreachable!("only called when matrixmultiply_uses_fma")
}

/// `Cholesky::new` in place on an N x N column-major slice: [`cholesky`]'s factorization
/// (dirty: the strict upper triangle is left as it was). False when not positive definite.
/// The operations of `cholesky_fixed`; its refusal `diag == 0 || !(diag > 0)` (nalgebra's
/// `is_zero` then `try_sqrt`) is written as the equivalent `!(diag > 0)`.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn cholesky_square<const N: usize>(m: &mut [f64]) -> bool {
    let m = &mut m[..N * N];
    for j in 0..N {
        for k in 0..j {
            let factor = -m[k * N + j];
            for r in j..N {
                m[j * N + r] = factor * m[k * N + r] + m[j * N + r];
            }
        }
        let diag = m[j * N + j];
        // NaN and every value <= 0 fail (the negated comparison is the point: NaN is not > 0).
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(diag > 0.0) {
            return false;
        }
        let denom = diag.sqrt();
        m[j * N + j] = denom;
        for r in j + 1..N {
            m[j * N + r] /= denom;
        }
    }
    true
}

/// sym(P^{-1}) from the dirty column-major factor `l` of P (N x N, as [`cholesky_square`]
/// accepts it: a positive diagonal), into `out`
/// (column-major): bit for bit what `identity`, [`chol_solve_matrix`] and `linalg::symmetrize`
/// compute — the forward and back substitution of each column e_c (the columns run side by
/// side, each with its own operations in their order), then `0.5 * (x_ij + x_ji)` for i < j.
#[inline(always)]
#[allow(clippy::assign_op_pattern)]
pub fn chol_inverse_sym_square<const N: usize>(l: &[f64], out: &mut [f64]) {
    let l = &l[..N * N];
    // x[r][c]: row r of the solutions, so the columns of one row are contiguous.
    let mut x = [[0.0f64; N]; N];
    for (i, row) in x.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    // Forward substitution with L (`lower_solve_fixed`, whose early exit at a zero diagonal
    // never happens here: an accepted factor's diagonal is a square root of a value > 0).
    for i in 0..N {
        let d = l[i * N + i];
        for v in x[i].iter_mut() {
            *v = *v / d;
        }
        for j in i + 1..N {
            let lji = l[i * N + j];
            let (head, tail) = x.split_at_mut(j);
            let (xi, xj) = (&head[i], &mut tail[0]);
            for c in 0..N {
                xj[c] = -xi[c] * lji + xj[c];
            }
        }
    }
    // Back substitution with L^T (`chol_solve_fixed`: the dot from +0 in row order).
    for i in (0..N).rev() {
        let mut dot = [0.0f64; N];
        for j in i + 1..N {
            let lji = l[i * N + j];
            for c in 0..N {
                dot[c] += lji * x[j][c];
            }
        }
        let d = l[i * N + i];
        for c in 0..N {
            x[i][c] = (x[i][c] - dot[c]) / d;
        }
    }
    // `symmetrize` of the column-major X (X_ij = x[i][j]): the diagonal as it is, and
    // 0.5 * (X_ij + X_ji) on both sides for i < j.
    let out = &mut out[..N * N];
    for i in 0..N {
        out[i * N + i] = x[i][i];
        for j in (i + 1)..N {
            let m = 0.5 * (x[i][j] + x[j][i]);
            out[j * N + i] = m;
            out[i * N + j] = m;
        }
    }
}

/// `linalg::symmetrize` on an N x N column-major slice: `0.5 * (a_ij + a_ji)` into both, for
/// i < j in the same order.
#[inline(always)]
pub fn symmetrize_square<const N: usize>(s: &mut [f64]) {
    let s = &mut s[..N * N];
    for i in 0..N {
        for j in (i + 1)..N {
            let m = 0.5 * (s[j * N + i] + s[i * N + j]);
            s[j * N + i] = m;
            s[i * N + j] = m;
        }
    }
}

/// Whether every entry is finite, as `s.iter().all(|v| v.is_finite())`, in four lanes that
/// vector units run side by side: `v * 0` is ±0 for a finite v and NaN for an infinite or
/// NaN one, so a lane's sum of them is zero exactly when all its entries are finite.
#[inline(always)]
pub fn all_finite(s: &[f64]) -> bool {
    let mut acc = [0.0f64; 4];
    let chunks = s.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a += v * 0.0;
        }
    }
    for (a, v) in acc.iter_mut().zip(rest) {
        *a += v * 0.0;
    }
    acc.iter().all(|&a| a == 0.0)
}

/// Whether the CPU has AVX2 and FMA: code compiled for them (`target_feature`) computes the
/// same numbers — Rust fuses no multiply and add — on wider vectors.
pub fn has_avx2_fma() -> bool {
    matrixmultiply_uses_fma()
}

#[cfg(test)]
mod lower_solve_tests;
#[cfg(test)]
mod square_tests;
#[cfg(test)]
mod tests;
