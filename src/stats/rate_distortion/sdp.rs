//! The vector floor of a fully observed Gauss–Markov source `x' = A x + w`, `w ~ N(0, W)`, by the
//! semidefinite program of Tanaka, Kim, Parrilo and Mitter, solved with Clarabel.
//!
//! With `P` the steady-state error covariance of the decoder's estimate and
//! `Π = (P⁻¹ + Aᵀ W⁻¹ A)⁻¹`, the rate `½ log det(A P Aᵀ + W) − ½ log det P` equals
//! `½ log det W − ½ log det Π` (determinant lemma), and `Π ⪯ (P⁻¹ + AᵀW⁻¹A)⁻¹
//! = P − P Aᵀ (A P Aᵀ + W)⁻¹ A P` is, by a Schur complement, the linear matrix inequality
//! `[[P − Π, P Aᵀ], [A P, A P Aᵀ + W]] ⪰ 0`. With `P ⪯ A P Aᵀ + W` (the estimate can only gain
//! from what it is sent) both the rate bound and the distortion bound are convex. `log det Π`
//! enters through `[[Π, Z], [Zᵀ, Diag Z]] ⪰ 0`, `Z` lower triangular, and
//! `t_i <= log Z_ii` (exponential cones): then `Σ t_i <= log det Π`, with equality reachable.
//!
//! Variables, in order: the upper triangles of `P` and `Π`, the lower triangle of `Z`, `t`.
use nalgebra::Schur;

use super::conic::{Affine, ConeProgram};
use super::FloorError;
use crate::linalg::{check_symmetric, cholesky, Matrix};

/// Smallest rate (bits per step) with a finite floor: `Σ max(0, log2|λ_i(A)|)` over the
/// eigenvalues of `A` (the data-rate theorem). At or below it the floor is infinite.
pub fn min_rate(a: &Matrix) -> f64 {
    Schur::new(a.clone())
        .complex_eigenvalues()
        .iter()
        .map(|l| l.norm().log2().max(0.0))
        .sum()
}

/// The smallest steady-state mean squared error `trace(P)` that any causal scheme reaches at
/// `rate` bits per step on the fully observed source `x' = A x + w`, `w ~ N(0, W)`.
///
/// Errors: [`FloorError::Invalid`] for shapes, non-finite entries or a `W` that is not
/// symmetric positive definite (with condition number at most 1e10); [`FloorError::RateTooLow`] at or below [`min_rate`] (or a
/// negative rate); [`FloorError::Solver`] when Clarabel does not report `Solved`.
pub fn floor_mse(a: &Matrix, w: &Matrix, rate: f64) -> Result<f64, FloorError> {
    Ok(floor_covariance(a, w, rate)?.trace())
}

/// The error covariance `P` at which [`floor_mse`] is reached (its trace is the floor). A
/// stable `A` at rate 0 gets the stationary covariance `Σ = A Σ Aᵀ + W` directly: there the
/// program has no strictly feasible point, which interior-point solvers handle poorly.
/// Accuracy: the trace (the optimal value) to about 1e-8 relative, the entries of `P` less
/// tightly (an interior-point minimizer is typically good to about the square root of that).
pub fn floor_covariance(a: &Matrix, w: &Matrix, rate: f64) -> Result<Matrix, FloorError> {
    Ok(solve_at(a, w, rate)?.0)
}

/// [`floor_mse`] at `rate` with its slope `dD/dR` there (MSE per bit per step, at most 0):
/// the floor is convex in the rate (the rate enters the program's constraints linearly), so
/// `mse + slope (r − rate)` lies below the floor at every rate `r`, and a curve solved once
/// bounds the floor everywhere from below without another program. The slope is the budget
/// constraint's multiplier (`−dD/db` of a row `e + b >= 0`, times `d b/d R = 2 ln 2`); at rate 0
/// (the stationary covariance, no program) it is not known and given as `−∞`, a tangent that
/// bounds nothing.
pub fn floor_point(a: &Matrix, w: &Matrix, rate: f64) -> Result<(f64, f64), FloorError> {
    let (p, slope) = solve_at(a, w, rate)?;
    Ok((p.trace(), slope))
}

/// The minimizer `P` and the slope of its trace in the rate (see [`floor_point`]).
fn solve_at(a: &Matrix, w: &Matrix, rate: f64) -> Result<(Matrix, f64), FloorError> {
    let scale = check_source(a, w)?;
    let min = min_rate(a);
    if rate.is_nan() || rate < 0.0 || (min > 0.0 && rate <= min) {
        return Err(FloorError::RateTooLow { rate, min });
    }
    if rate == 0.0 {
        return Ok((stationary_covariance(a, w)?, f64::NEG_INFINITY));
    }
    // The floor scales with W: solve for W / scale, whose entries are of order one.
    let ws = w / scale;
    let log_det_w = log_det(&ws)?;
    let (mut prog, blocks) = program(a, &ws);
    let mut budget = Affine::constant(2.0 * rate * std::f64::consts::LN_2 - log_det_w);
    let mut q = vec![0.0; prog.n_vars()];
    for block in &blocks {
        for i in 0..block.layout.n {
            budget.add(block.layout.t(i), 1.0);
            q[block.layout.p(i, i)] = 1.0;
        }
    }
    let budget_row = prog.nonnegative(budget);
    let solution = prog.minimize(&q)?;
    let slope = -solution.z[budget_row] * 2.0 * std::f64::consts::LN_2 * scale;
    Ok((
        covariance(&blocks, &solution.x, a.nrows()) * scale,
        slope.min(0.0),
    ))
}

/// The smallest rate (bits per step) at which any causal scheme holds the steady-state mean
/// squared error `trace(P)` to `d` on the fully observed source; 0 once `d` reaches the
/// stationary error of a stable source.
///
/// Errors: as [`floor_mse`], and [`FloorError::Invalid`] for `d` not positive and finite.
pub fn rate(a: &Matrix, w: &Matrix, d: f64) -> Result<f64, FloorError> {
    let scale = check_source(a, w)?;
    if !(d.is_finite() && d > 0.0) {
        return Err(FloorError::Invalid(format!(
            "distortion must be positive and finite, got {d}"
        )));
    }
    let ws = w / scale;
    let log_det_w = log_det(&ws)?;
    let (mut prog, blocks) = program(a, &ws);
    let mut budget = Affine::constant(d / scale);
    let mut q = vec![0.0; prog.n_vars()];
    for block in &blocks {
        for i in 0..block.layout.n {
            budget.add(block.layout.p(i, i), -1.0);
            q[block.layout.t(i)] = -1.0;
        }
    }
    prog.nonnegative(budget);
    let x = prog.minimize(&q)?.x;
    let log_det_pi: f64 = blocks
        .iter()
        .flat_map(|b| (0..b.layout.n).map(|i| x[b.layout.t(i)]))
        .sum();
    Ok((0.5 * (log_det_w - log_det_pi) / std::f64::consts::LN_2).max(0.0))
}

/// One independent part of the source: the state components `index` (in increasing order),
/// which `A` and `W` couple to no other component, and where its variables live.
struct Block {
    index: Vec<usize>,
    layout: Layout,
}

/// The state split into independent parts: components joined when `A` or `W` couples them
/// (an exactly nonzero entry either way), each part in increasing order, the parts in order
/// of their first component.
///
/// Why: for a block-diagonal `A` and `W` (two axes of a tracking model, say) the optimal `P`
/// is block diagonal too. Pinching a feasible `P` to its diagonal blocks keeps `trace(P)` and
/// `P ⪯ A P Aᵀ + W`, and does not lower `log det Π`: `Π = (P⁻¹ + AᵀW⁻¹A)⁻¹` is operator
/// concave in `P` and commutes with the pinching, and Fischer's inequality gives
/// `log det pinch(Π) >= log det Π`. So one program per part, joined by the one rate budget,
/// has the same optimum with far smaller cones: two 3-state parts instead of one 6-state
/// system make the KKT system's dense blocks about 14× smaller.
fn parts(a: &Matrix, w: &Matrix) -> Vec<Vec<usize>> {
    let n = a.nrows();
    let mut root: Vec<usize> = (0..n).collect();
    fn find(root: &mut [usize], mut i: usize) -> usize {
        while root[i] != i {
            root[i] = root[root[i]];
            i = root[i];
        }
        i
    }
    for i in 0..n {
        for j in 0..n {
            if a[(i, j)] != 0.0 || w[(i, j)] != 0.0 {
                let (ri, rj) = (find(&mut root, i), find(&mut root, j));
                root[ri.max(rj)] = ri.min(rj);
            }
        }
    }
    let mut parts: Vec<Vec<usize>> = Vec::new();
    let mut part_of_root = vec![usize::MAX; n];
    for i in 0..n {
        let r = find(&mut root, i);
        if part_of_root[r] == usize::MAX {
            part_of_root[r] = parts.len();
            parts.push(Vec::new());
        }
        parts[part_of_root[r]].push(i);
    }
    parts
}

/// The constraints of every independent part of the source (see [`parts`]), each over
/// variables of its own; a source of one part gives exactly the program of the whole.
fn program(a: &Matrix, w: &Matrix) -> (ConeProgram, Vec<Block>) {
    let mut blocks = Vec::new();
    let mut offset = 0;
    for index in parts(a, w) {
        let layout = Layout::at(index.len(), offset);
        offset += layout.n_vars();
        blocks.push(Block { index, layout });
    }
    let mut prog = ConeProgram::new(offset);
    for b in &blocks {
        let ab = a.select_rows(&b.index).select_columns(&b.index);
        let wb = w.select_rows(&b.index).select_columns(&b.index);
        constraints(&mut prog, &b.layout, &ab, &wb);
    }
    (prog, blocks)
}

/// The full `n x n` matrix `P` from the parts' upper triangles in `x` (zero across parts).
fn covariance(blocks: &[Block], x: &[f64], n: usize) -> Matrix {
    let mut p = Matrix::zeros(n, n);
    for b in blocks {
        for (i, &gi) in b.index.iter().enumerate() {
            for (j, &gj) in b.index.iter().enumerate() {
                p[(gi, gj)] = x[b.layout.p(i, j)];
            }
        }
    }
    p
}

/// The stationary covariance `Σ = A Σ Aᵀ + W` of a stable source, from the Kronecker form
/// `(I − A ⊗ A) vec Σ = vec W`.
///
/// Errors: [`FloorError::RateTooLow`] (at rate 0) when `A` is not stable.
pub fn stationary_covariance(a: &Matrix, w: &Matrix) -> Result<Matrix, FloorError> {
    let n = a.nrows();
    let min = min_rate(a);
    if min > 0.0 || a.nrows() != a.ncols() {
        return Err(FloorError::RateTooLow { rate: 0.0, min });
    }
    let lhs = Matrix::identity(n * n, n * n) - a.kronecker(a);
    let vec_w = nalgebra::DVector::from_column_slice(w.as_slice());
    let vec_s = lhs.lu().solve(&vec_w).ok_or(FloorError::RateTooLow {
        rate: 0.0,
        min: 0.0,
    })?;
    let s = Matrix::from_column_slice(n, n, vec_s.as_slice());
    Ok((&s + s.transpose()) * 0.5)
}

/// The constraints shared by both directions: the Schur-complement LMI, `P ⪯ A P Aᵀ + W`, and
/// the log-det construction for `Π`.
fn constraints(prog: &mut ConeProgram, layout: &Layout, a: &Matrix, w: &Matrix) {
    let n = layout.n;
    // (A P Aᵀ + W)_{ij} and (P Aᵀ)_{ij}.
    let prior = |i: usize, j: usize| {
        let mut e = Affine::constant(w[(i, j)]);
        for k in 0..n {
            for l in 0..n {
                e.add(layout.p(k, l), a[(i, k)] * a[(j, l)]);
            }
        }
        e
    };
    let p_at = |i: usize, j: usize| {
        let mut e = Affine::default();
        for k in 0..n {
            e.add(layout.p(i, k), a[(j, k)]);
        }
        e
    };
    prog.psd(2 * n, |i, j| match (i < n, j < n) {
        (true, true) => {
            let mut e = Affine::var(layout.p(i, j));
            e.add(layout.pi(i, j), -1.0);
            e
        }
        (true, false) => p_at(i, j - n),
        _ => prior(i - n, j - n),
    });
    prog.psd(n, |i, j| {
        let mut e = prior(i, j);
        e.add(layout.p(i, j), -1.0);
        e
    });
    let z = |i: usize, j: usize| {
        if i >= j {
            Affine::var(layout.z(i, j))
        } else {
            Affine::default()
        }
    };
    prog.psd(2 * n, |i, j| match (i < n, j < n) {
        (true, true) => Affine::var(layout.pi(i, j)),
        (true, false) => z(i, j - n),
        _ if i == j => z(i - n, i - n),
        _ => Affine::default(),
    });
    for i in 0..n {
        prog.exponential(Affine::var(layout.t(i)), Affine::constant(1.0), z(i, i));
    }
}

/// Where each matrix entry of one part lives in the variable vector: the part's variables
/// start at `offset`.
struct Layout {
    n: usize,
    tri: usize,
    offset: usize,
}

impl Layout {
    #[cfg(test)]
    fn new(n: usize) -> Self {
        Self::at(n, 0)
    }

    fn at(n: usize, offset: usize) -> Self {
        Layout {
            n,
            tri: n * (n + 1) / 2,
            offset,
        }
    }

    fn n_vars(&self) -> usize {
        3 * self.tri + self.n
    }

    /// Index of the symmetric entry (i, j) in an upper triangle stored column by column.
    fn sym(i: usize, j: usize) -> usize {
        let (i, j) = (i.min(j), i.max(j));
        j * (j + 1) / 2 + i
    }

    fn p(&self, i: usize, j: usize) -> usize {
        self.offset + Self::sym(i, j)
    }

    fn pi(&self, i: usize, j: usize) -> usize {
        self.offset + self.tri + Self::sym(i, j)
    }

    /// `Z` is lower triangular: (i, j) with i >= j, stored as the upper entry (j, i).
    fn z(&self, i: usize, j: usize) -> usize {
        self.offset + 2 * self.tri + Self::sym(j, i)
    }

    fn t(&self, i: usize) -> usize {
        self.offset + 3 * self.tri + i
    }
}

/// Checks shapes, finiteness and `W ≻ 0` (condition number at most 1e10); returns the scale `trace(W) / n` the programs divide
/// `W` by.
fn check_source(a: &Matrix, w: &Matrix) -> Result<f64, FloorError> {
    let n = a.nrows();
    if n == 0 || a.ncols() != n || w.nrows() != n || w.ncols() != n {
        return Err(FloorError::Invalid(format!(
            "A must be square and W the same size, got {}x{} and {}x{}",
            a.nrows(),
            a.ncols(),
            w.nrows(),
            w.ncols()
        )));
    }
    if a.iter().chain(w.iter()).any(|v| !v.is_finite()) {
        return Err(FloorError::Invalid("non-finite entry in A or W".into()));
    }
    check_symmetric(w).map_err(|e| FloorError::Invalid(format!("W: {e}")))?;
    cholesky(w).map_err(|e| FloorError::Invalid(format!("W: {e}")))?;
    // A W that only rounding keeps positive definite (a rank-deficient noise, such as the
    // estimate noise of a sensor that sees part of the state) puts a huge log det W against a
    // huge log det Π: the difference, the rate, would be noise.
    let eig = w.symmetric_eigenvalues();
    if eig.min() < 1e-10 * eig.max() {
        return Err(FloorError::Invalid(format!(
            "W is singular to working precision (eigenvalues {:.3e} to {:.3e}); the program \
             needs W positive definite",
            eig.min(),
            eig.max()
        )));
    }
    Ok(w.trace() / n as f64)
}

fn log_det(m: &Matrix) -> Result<f64, FloorError> {
    let c = cholesky(m).map_err(|e| FloorError::Invalid(format!("W: {e}")))?;
    Ok(2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_rate_counts_unstable_eigenvalue_magnitudes() {
        // 1.5 times a rotation: a complex pair of magnitude 1.5.
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let a = Matrix::from_row_slice(2, 2, &[c, -s, s, c]) * 1.5;
        assert!((min_rate(&a) - 2.0 * 1.5f64.log2()).abs() < 1e-12);
        let stable = Matrix::from_row_slice(2, 2, &[0.5, 3.0, 0.0, 0.9]);
        assert_eq!(min_rate(&stable), 0.0);
    }

    #[test]
    fn layout_indices_are_distinct_and_in_range() {
        let l = Layout::new(3);
        let mut seen = vec![false; l.n_vars()];
        for j in 0..3 {
            for i in 0..=j {
                for k in [l.p(i, j), l.pi(i, j), l.z(j, i)] {
                    assert!(!seen[k], "{k} used twice");
                    seen[k] = true;
                }
                assert_eq!(l.p(i, j), l.p(j, i));
            }
            seen[l.t(j)] = true;
        }
        assert!(seen.iter().all(|&s| s));
    }

    /// The slope from the budget's multiplier is the floor's derivative in the rate.
    #[test]
    #[cfg_attr(not(hushfuse_blas), ignore = "no BLAS/LAPACK in this build")]
    fn the_slope_is_the_derivative_of_the_floor() {
        let a = Matrix::from_row_slice(2, 2, &[1.1, 0.4, -0.2, 0.8]);
        let w = Matrix::from_row_slice(2, 2, &[0.5, 0.1, 0.1, 0.2]);
        for r in [1.0, 2.0, 5.0] {
            let (_, slope) = floor_point(&a, &w, r).unwrap();
            let h = 1e-3;
            let fd =
                (floor_mse(&a, &w, r + h).unwrap() - floor_mse(&a, &w, r - h).unwrap()) / (2.0 * h);
            assert!(
                (slope - fd).abs() < 1e-3 * fd.abs(),
                "R={r}: {slope} vs {fd}"
            );
        }
    }

    fn axes(eps: f64) -> (Matrix, Matrix) {
        // Two independent axes (components 0, 2 and 1, 3 interleaved), coupled by `eps`.
        let mut a = Matrix::zeros(4, 4);
        let mut w = Matrix::zeros(4, 4);
        for (x, v, s) in [(0, 2, 1.0), (1, 3, 2.0)] {
            a[(x, x)] = 1.0;
            a[(x, v)] = 0.5;
            a[(v, v)] = 0.95;
            w[(x, x)] = 0.1 * s;
            w[(v, v)] = 0.4 * s;
            w[(x, v)] = 0.05 * s;
            w[(v, x)] = 0.05 * s;
        }
        a[(0, 1)] = eps;
        (a, w)
    }

    #[test]
    fn independent_axes_are_found_as_parts() {
        let (a, w) = axes(0.0);
        assert_eq!(parts(&a, &w), vec![vec![0, 2], vec![1, 3]]);
        let (a, w) = axes(1e-9);
        assert_eq!(parts(&a, &w), vec![vec![0, 1, 2, 3]]);
    }

    /// The program of the parts (block-diagonal `P`) has the optimum of the whole: a coupling
    /// of 1e-9, which makes the whole one program, moves the floor by no more than that.
    #[test]
    #[cfg_attr(not(hushfuse_blas), ignore = "no BLAS/LAPACK in this build")]
    fn the_parts_have_the_optimum_of_the_whole() {
        for r in [1.0, 3.0, 8.0] {
            let (a, w) = axes(0.0);
            let split = floor_covariance(&a, &w, r).unwrap();
            let (a, w) = axes(1e-9);
            let whole = floor_covariance(&a, &w, r).unwrap();
            let (d0, d1) = (split.trace(), whole.trace());
            assert!((d0 - d1).abs() < 1e-6 * d1, "R={r}: parts {d0}, whole {d1}");
            // Nothing across the parts.
            assert_eq!(split[(0, 1)], 0.0);
            assert_eq!(split[(2, 3)], 0.0);
        }
    }

    /// At the optimum the rate budget is spent: `½ log2 det(A P Aᵀ + W) / det P = R`, computed
    /// from the returned `P` by determinants, not through `Π` as the program does.
    #[test]
    #[cfg_attr(not(hushfuse_blas), ignore = "no BLAS/LAPACK in this build")]
    fn optimum_spends_the_rate_exactly() {
        let a = Matrix::from_row_slice(2, 2, &[1.1, 0.4, -0.2, 0.8]);
        let w = Matrix::from_row_slice(2, 2, &[0.5, 0.1, 0.1, 0.2]);
        for r in [0.5, 1.0, 3.0] {
            let p = floor_covariance(&a, &w, r).unwrap();
            let prior = &a * &p * a.transpose() + &w;
            let spent = 0.5 * (prior.determinant() / p.determinant()).log2();
            assert!((spent - r).abs() < 1e-6, "R={r}: spent {spent}");
            // Posterior below prior (the constraint P ⪯ A P Aᵀ + W).
            assert!((prior - &p).symmetric_eigenvalues().min() > -1e-8);
        }
    }
}
