//! A small builder of conic programs for Clarabel: constraints are written as affine
//! expressions of the variables that must lie in a cone, which is how the rate–distortion SDP
//! reads on paper, and turned here into Clarabel's `A x + s = b, s ∈ K` form.
//!
//! Clarabel's PSD cone calls BLAS/LAPACK (Fortran symbols such as `dsyevr_`); the system's
//! reference BLAS and LAPACK provide them (or OpenBLAS) when the build found them (`build.rs`,
//! cfg `hushfuse_blas`). Without them a program is not solved: `ConeProgram::minimize` says what
//! to install.
use clarabel::algebra::CscMatrix;
use clarabel::solver::SupportedConeT;
#[cfg(hushfuse_blas)]
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus};

use super::FloorError;

/// Whether this build can solve the vector floor's programs (it found a BLAS/LAPACK library).
pub const AVAILABLE: bool = cfg!(hushfuse_blas);

/// `constant + Σ coefficient · x[index]`.
#[derive(Debug, Clone, Default)]
pub(super) struct Affine {
    pub constant: f64,
    pub terms: Vec<(usize, f64)>,
}

impl Affine {
    pub fn constant(c: f64) -> Self {
        Affine {
            constant: c,
            terms: Vec::new(),
        }
    }

    pub fn var(index: usize) -> Self {
        Affine {
            constant: 0.0,
            terms: vec![(index, 1.0)],
        }
    }

    /// Adds `coefficient · x[index]`.
    pub fn add(&mut self, index: usize, coefficient: f64) {
        if coefficient != 0.0 {
            self.terms.push((index, coefficient));
        }
    }
}

/// Minimize `qᵀ x` subject to the pushed cone constraints.
pub(super) struct ConeProgram {
    n_vars: usize,
    /// One row per slack entry: the entries of `-A` are the expression's coefficients.
    rows: Vec<Affine>,
    cones: Vec<SupportedConeT<f64>>,
}

/// A solved program: the primal point and the constraints' multipliers.
#[derive(Debug, Clone)]
pub struct Solution {
    /// The minimizer.
    pub x: Vec<f64>,
    /// One multiplier per row (the dual cone's point): for a row `e >= 0`, the rate at which
    /// the optimal value falls as the row's constant grows.
    pub z: Vec<f64>,
}

impl ConeProgram {
    /// Number of variables.
    pub fn n_vars(&self) -> usize {
        self.n_vars
    }

    pub fn new(n_vars: usize) -> Self {
        ConeProgram {
            n_vars,
            rows: Vec::new(),
            cones: Vec::new(),
        }
    }

    /// `expression >= 0`; returns the row, where [`Solution::z`] holds its multiplier.
    pub fn nonnegative(&mut self, expression: Affine) -> usize {
        self.rows.push(expression);
        self.cones.push(SupportedConeT::NonnegativeConeT(1));
        self.rows.len() - 1
    }

    /// `(x, y, z)` in the exponential cone `y e^{x/y} <= z`, `y > 0`: with `y = 1`,
    /// `x <= log z`.
    pub fn exponential(&mut self, x: Affine, y: Affine, z: Affine) {
        self.rows.extend([x, y, z]);
        self.cones.push(SupportedConeT::ExponentialConeT());
    }

    /// The symmetric `dim x dim` matrix with entries `entry(i, j)` (asked for `i <= j` only) is
    /// positive semidefinite. Clarabel takes the upper triangle column by column with the
    /// off-diagonal entries scaled by √2 (so that the vector inner product is the trace one).
    pub fn psd(&mut self, dim: usize, entry: impl Fn(usize, usize) -> Affine) {
        for j in 0..dim {
            for i in 0..=j {
                let mut e = entry(i, j);
                if i != j {
                    let s = std::f64::consts::SQRT_2;
                    e.constant *= s;
                    e.terms.iter_mut().for_each(|t| t.1 *= s);
                }
                self.rows.push(e);
            }
        }
        self.cones.push(SupportedConeT::PSDTriangleConeT(dim));
    }

    /// Solves and returns the primal solution.
    ///
    /// Errors: [`FloorError::Solver`] for any status but `Solved` or `AlmostSolved`
    /// (infeasible, iteration limit, numerical trouble), and for a problem Clarabel refuses to
    /// set up.
    #[cfg(not(hushfuse_blas))]
    pub fn minimize(&self, q: &[f64]) -> Result<Solution, FloorError> {
        let _ = q;
        Err(FloorError::Solver(
            "the vector rate-distortion floor needs a BLAS/LAPACK library, which this build did \
             not find: install the reference BLAS and LAPACK (Debian: apt-get install libblas-dev \
             liblapack-dev) and rebuild"
                .into(),
        ))
    }

    /// Solves and returns the primal solution (see above).
    #[cfg(hushfuse_blas)]
    pub fn minimize(&self, q: &[f64]) -> Result<Solution, FloorError> {
        single_threaded_blas();
        let (a, b) = self.constraint_matrix();
        let p = CscMatrix::zeros((self.n_vars, self.n_vars));
        let settings = DefaultSettings {
            verbose: std::env::var("HF_VERBOSE").is_ok(),
            // Clarabel's default tolerances (1e-8 on gap and feasibility); tighter ones stall
            // at the last digits and end in `AlmostSolved` on these log-det problems.
            chordal_decomposition_enable: false,
            ..DefaultSettings::default()
        };
        let mut solver = DefaultSolver::new(&p, q, &a, &b, &self.cones, settings)
            .map_err(|e| FloorError::Solver(format!("setup: {e:?}")))?;
        solver.solve();
        match solver.solution.status {
            // `AlmostSolved`: Clarabel's reduced tolerances (gap 5e-5, feasibility 1e-4) met
            // where the full ones stall in the last digits. Which points stall depends on the
            // BLAS the build links (rate 0.5 of the built-in 1-D floor does with the reference
            // BLAS, not with OpenBLAS's AVX2 kernels): refusing them would make the floor's
            // very points depend on the library.
            SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(Solution {
                x: solver.solution.x.clone(),
                z: solver.solution.z.clone(),
            }),
            status => Err(FloorError::Solver(format!("status {status:?}"))),
        }
    }

    /// `A` (as CSC, duplicate terms of a row summed) and `b` of `A x + s = b`.
    #[cfg_attr(not(hushfuse_blas), allow(dead_code))]
    fn constraint_matrix(&self) -> (CscMatrix<f64>, Vec<f64>) {
        let mut columns: Vec<Vec<(usize, f64)>> = vec![Vec::new(); self.n_vars];
        for (row, e) in self.rows.iter().enumerate() {
            for &(var, c) in &e.terms {
                let column = &mut columns[var];
                match column.last_mut() {
                    Some(last) if last.0 == row => last.1 -= c,
                    _ => column.push((row, -c)),
                }
            }
        }
        let mut colptr = vec![0];
        let (mut rowval, mut nzval) = (Vec::new(), Vec::new());
        for column in columns {
            for (row, v) in column {
                if v != 0.0 {
                    rowval.push(row);
                    nzval.push(v);
                }
            }
            colptr.push(rowval.len());
        }
        let b = self.rows.iter().map(|e| e.constant).collect();
        (
            CscMatrix::new(self.rows.len(), self.n_vars, colptr, rowval, nzval),
            b,
        )
    }
}

/// OpenBLAS (the fallback of `build.rs`) on one thread, once per process. The programs here
/// have matrices of order below ten: OpenBLAS's worker threads only spin on them (a floor of
/// Dormann et al.'s 93 curves took 4 s of system time on 2 cores with its default threads, none
/// with one), and the runs already use every core. The reference BLAS has no threads.
#[cfg(all(hushfuse_blas, not(hushfuse_openblas)))]
fn single_threaded_blas() {}

/// See above.
#[cfg(hushfuse_openblas)]
fn single_threaded_blas() {
    extern "C" {
        fn openblas_set_num_threads(n: std::os::raw::c_int);
    }
    static ONCE: std::sync::Once = std::sync::Once::new();
    // SAFETY: OpenBLAS's documented setter, called with a valid count before any of our calls
    // into it (and again harmless if another part of the process set it).
    ONCE.call_once(|| unsafe { openblas_set_num_threads(1) });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// max log det X over 2x2 X with trace 2 is at X = I (log det 0); the build goes through
    /// the same log-det construction as the floor, so a wrong scaling or index fails here.
    #[test]
    #[cfg_attr(not(hushfuse_blas), ignore = "no BLAS/LAPACK in this build")]
    fn log_det_with_trace_budget() {
        // x = [X00, X01, X11, Z00, Z10, Z11, t0, t1]
        let mut prog = ConeProgram::new(8);
        let mut tr = Affine::constant(2.0);
        tr.add(0, -1.0);
        tr.add(2, -1.0);
        prog.nonnegative(tr);
        // [[X, Z], [Zᵀ, diag Z]] with Z lower triangular: Z = [[Z00, 0], [Z10, Z11]].
        let z = |i: usize, j: usize| match (i, j) {
            (0, 0) => Affine::var(3),
            (1, 0) => Affine::var(4),
            (1, 1) => Affine::var(5),
            _ => Affine::default(),
        };
        prog.psd(4, |i, j| match (i < 2, j < 2) {
            (true, true) => Affine::var([[0, 1], [1, 2]][i][j]),
            (true, false) => z(i, j - 2),
            _ if i == j => z(i - 2, i - 2),
            _ => Affine::default(),
        });
        for k in 0..2 {
            prog.exponential(Affine::var(6 + k), Affine::constant(1.0), z(k, k));
        }
        let x = prog
            .minimize(&[0., 0., 0., 0., 0., 0., -1., -1.])
            .unwrap()
            .x;
        // The optimal value is as accurate as the gap (1e-8); the maximizer, where log det is
        // flat to second order, only to about its square root.
        assert!((x[6] + x[7]).abs() < 1e-7, "{x:?}");
        assert!((x[0] - 1.0).abs() < 1e-4 && x[1].abs() < 1e-4, "{x:?}");
    }
}
