//! Fusion of estimates whose cross-correlations are unknown.
//!
//! **Covariance intersection** (Julier & Uhlmann, "A non-divergent estimation algorithm in the
//! presence of unknown correlations", ACC 1997 — the update P^{-1} = ω P_a^{-1} + (1 - ω)
//! P_b^{-1}, and its usual N-estimate form; equation numbers not checked against the paper):
//! P^{-1} = Σ ω_i P_i^{-1}, x = P Σ ω_i P_i^{-1} x_i, ω on the simplex.
//! For *any* ω on the simplex, P >= the true error covariance whatever the correlations
//! (the consistency property), so the choice of ω only affects accuracy: ω minimizes tr P,
//! a convex function of ω (trace of the inverse of an affine positive definite matrix).
//! Two estimates: golden-section search on ω_1 = ω, ω_2 = 1 - ω. More: exponentiated
//! gradient descent on the simplex with ∂ tr P / ∂ω_i = -tr(P P_i^{-1} P) and backtracking
//! (deterministic, a fixed budget of iterations).
//!
//! **Naive information sum**: P^{-1} = Σ P_i^{-1}, x = P Σ P_i^{-1} x_i — exact for
//! independent errors, overconfident when they are correlated (common process noise, common
//! prior), which is what it is here to show.
use crate::filter::information::Information;
use crate::filter::{FilterError, Gaussian};
use crate::linalg::fixed;
use crate::linalg::{cholesky_into, symmetrize, Matrix, Vector};

/// Golden-section iterations for two estimates: the bracket shrinks by 0.618 per step, so
/// 60 steps leave it below 1e-12.
const GOLDEN_STEPS: usize = 60;
/// Exponentiated-gradient iterations for more than two estimates.
const EG_STEPS: usize = 100;

/// Buffers of the fusion rules for `m` estimates of dimension `n`, allocated once so that a
/// fusion (the weight search included) allocates nothing. Every function below
/// works in them with the operations of the allocating forms (`Information::from_gaussian`,
/// `cholesky(..).inverse()`, nalgebra's products and `to_gaussian`), in the same order, hence
/// the same bits.
#[derive(Debug, Clone)]
pub struct FusionWork {
    /// The information form of every estimate (recomputed per fusion).
    infos: Vec<Information>,
    scratch: Scratch,
}

#[derive(Debug, Clone)]
struct Scratch {
    /// Σ ω_i Y_i and Σ ω_i y_i.
    sum: Information,
    /// Storage of the Cholesky factors.
    factor: Matrix,
    /// P = (Σ ω_i Y_i)^{-1} (unsymmetrized, as `Cholesky::inverse` gives it), P Y_i, P Y_i P.
    inv: Matrix,
    py: Matrix,
    pyp: Matrix,
    /// The weights, the gradient and a trial point of the descent.
    w: Vec<f64>,
    grad: Vec<f64>,
    trial: Vec<f64>,
}

impl FusionWork {
    /// Buffers for `m` estimates of dimension `n`.
    pub fn new(m: usize, n: usize) -> Self {
        let info = Information {
            matrix: Matrix::zeros(n, n),
            vector: Vector::zeros(n),
        };
        Self {
            infos: vec![info.clone(); m],
            scratch: Scratch {
                sum: info,
                factor: Matrix::zeros(n, n),
                inv: Matrix::zeros(n, n),
                py: Matrix::zeros(n, n),
                pyp: Matrix::zeros(n, n),
                w: vec![0.0; m],
                grad: vec![0.0; m],
                trial: vec![0.0; m],
            },
        }
    }

    /// The weights of the last fusion.
    pub fn weights(&self) -> &[f64] {
        &self.scratch.w
    }
}

/// `Information::from_gaussian(g)` into `info`, factoring in `factor`.
fn information_into(
    g: &Gaussian,
    info: &mut Information,
    factor: &mut Matrix,
) -> Result<(), FilterError> {
    let chol = cholesky_into(&g.cov, factor).map_err(|source| FilterError::Matrix {
        what: "covariance",
        source,
    })?;
    info.vector.copy_from(&g.mean);
    fixed::chol_solve(&chol, &mut info.vector);
    info.matrix.fill_with_identity();
    fixed::chol_solve_matrix(&chol, &mut info.matrix);
    *factor = chol.unpack_dirty();
    symmetrize(&mut info.matrix);
    Ok(())
}

/// The information form of every estimate (precomputed once per fusion), into `work`.
fn informations(estimates: &[Gaussian], work: &mut FusionWork) -> Result<(), FilterError> {
    if work.infos.len() != estimates.len() {
        let n = estimates.first().map_or(0, Gaussian::dim);
        *work = FusionWork::new(estimates.len(), n);
    }
    for (g, info) in estimates.iter().zip(&mut work.infos) {
        information_into(g, info, &mut work.scratch.factor)?;
    }
    Ok(())
}

/// Σ ω_i Y_i and Σ ω_i y_i (terms with ω_i = 0 left out) into `out`, from zero.
#[allow(clippy::assign_op_pattern)]
fn weighted(infos: &[Information], w: &[f64], out: &mut Information) {
    out.matrix.fill(0.0);
    out.vector.fill(0.0);
    for (info, &wi) in infos.iter().zip(w) {
        if wi > 0.0 {
            for (m, y) in out.matrix.iter_mut().zip(info.matrix.iter()) {
                *m = *m + y * wi;
            }
            for (v, y) in out.vector.iter_mut().zip(info.vector.iter()) {
                *v = *v + y * wi;
            }
        }
    }
}

/// `(Σ ω_i Y_i)^{-1}` (as `Cholesky::inverse`) into `s.inv`; `false` where the sum is not
/// positive definite.
fn inverse_of(infos: &[Information], w: &[f64], s: &mut Scratch) -> bool {
    weighted(infos, w, &mut s.sum);
    match cholesky_into(&s.sum.matrix, &mut s.factor) {
        Ok(c) => {
            s.inv.fill_with_identity();
            fixed::chol_solve_matrix(&c, &mut s.inv);
            s.factor = c.unpack_dirty();
            true
        }
        Err(_) => false,
    }
}

/// tr((Σ ω_i Y_i)^{-1}), +∞ where the sum is not positive definite.
fn trace_of(infos: &[Information], w: &[f64], s: &mut Scratch) -> f64 {
    if inverse_of(infos, w, s) {
        s.inv.trace()
    } else {
        f64::INFINITY
    }
}

/// The trace-minimizing covariance-intersection weights of `estimates` (module doc).
pub fn ci_weights(estimates: &[Gaussian]) -> Result<Vec<f64>, FilterError> {
    let mut work = FusionWork::new(0, 0);
    informations(estimates, &mut work)?;
    ci_weights_of(&work.infos, &mut work.scratch);
    Ok(work.scratch.w)
}

/// The weights into `s.w` (`m` of them).
fn ci_weights_of(infos: &[Information], s: &mut Scratch) {
    let m = infos.len();
    match m {
        0 => {}
        1 => s.w[0] = 1.0,
        2 => {
            let mut f = |a: f64| trace_of(infos, &[a, 1.0 - a], s);
            let g = 0.5 * (5f64.sqrt() - 1.0);
            let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
            let mut c = hi - g * (hi - lo);
            let mut d = lo + g * (hi - lo);
            let (mut fc, mut fd) = (f(c), f(d));
            for _ in 0..GOLDEN_STEPS {
                if fc < fd {
                    hi = d;
                    d = c;
                    fd = fc;
                    c = hi - g * (hi - lo);
                    fc = f(c);
                } else {
                    lo = c;
                    c = d;
                    fc = fd;
                    d = lo + g * (hi - lo);
                    fd = f(d);
                }
            }
            // The ends are candidates too (one estimate dominating the other).
            let mid = 0.5 * (lo + hi);
            let best = [(f(mid), mid), (f(0.0), 0.0), (f(1.0), 1.0)]
                .into_iter()
                .fold((f64::INFINITY, mid), |a, b| if b.0 < a.0 { b } else { a })
                .1;
            s.w[0] = best;
            s.w[1] = 1.0 - best;
        }
        _ => {
            s.w.fill(1.0 / m as f64);
            let w = std::mem::take(&mut s.w);
            let mut value = trace_of(infos, &w, s);
            s.w = w;
            let mut eta = 1.0;
            for _ in 0..EG_STEPS {
                let w = std::mem::take(&mut s.w);
                let ok = inverse_of(infos, &w, s);
                s.w = w;
                if !ok {
                    break;
                }
                // ∂ tr P / ∂ω_i = -tr(P Y_i P), scaled so the largest step is eta.
                for (gi, info) in s.grad.iter_mut().zip(infos) {
                    fixed::gemm(&mut s.py, &s.inv, &info.matrix);
                    fixed::gemm(&mut s.pyp, &s.py, &s.inv);
                    *gi = -s.pyp.trace();
                }
                let scale = s.grad.iter().fold(0.0_f64, |a, g| a.max(g.abs()));
                if scale.is_nan() || scale <= 0.0 {
                    break;
                }
                let mut improved = false;
                while eta > 1e-8 {
                    for ((t, wi), gi) in s.trial.iter_mut().zip(&s.w).zip(&s.grad) {
                        *t = wi * (-eta * gi / scale).exp();
                    }
                    let sum: f64 = s.trial.iter().sum();
                    s.trial.iter_mut().for_each(|t| *t /= sum);
                    let trial = std::mem::take(&mut s.trial);
                    let v = trace_of(infos, &trial, s);
                    s.trial = trial;
                    if v < value {
                        let gain = value - v;
                        std::mem::swap(&mut s.w, &mut s.trial);
                        value = v;
                        improved = gain > 1e-13 * value;
                        eta = (eta * 2.0).min(8.0);
                        break;
                    }
                    eta *= 0.5;
                }
                if !improved {
                    break;
                }
            }
        }
    }
}

/// Covariance intersection of `estimates` with the trace-minimizing weights; returns the
/// fused estimate and the weights.
pub fn covariance_intersection(
    estimates: &[Gaussian],
) -> Result<(Gaussian, Vec<f64>), FilterError> {
    let mut work = FusionWork::new(0, 0);
    let mut out = empty_like(estimates);
    covariance_intersection_into(estimates, &mut out, &mut work)?;
    Ok((out, work.scratch.w))
}

/// [`covariance_intersection`] into `out` through `work` (the weights in
/// [`FusionWork::weights`]): no allocation once `work` is sized for the estimates.
pub fn covariance_intersection_into(
    estimates: &[Gaussian],
    out: &mut Gaussian,
    work: &mut FusionWork,
) -> Result<(), FilterError> {
    informations(estimates, work)?;
    let s = &mut work.scratch;
    ci_weights_of(&work.infos, s);
    weighted(&work.infos, &s.w, &mut s.sum);
    s.sum.to_gaussian_into(out, &mut s.factor)
}

/// Covariance intersection with given weights (each ω_i >= 0, summing to 1).
pub fn covariance_intersection_with(
    estimates: &[Gaussian],
    weights: &[f64],
) -> Result<Gaussian, FilterError> {
    let mut work = FusionWork::new(0, 0);
    let mut out = empty_like(estimates);
    fuse_with(estimates, weights, &mut out, &mut work)?;
    Ok(out)
}

/// The naive information sum (module doc).
pub fn naive_sum(estimates: &[Gaussian]) -> Result<Gaussian, FilterError> {
    let mut work = FusionWork::new(0, 0);
    let mut out = empty_like(estimates);
    naive_sum_into(estimates, &mut out, &mut work)?;
    Ok(out)
}

/// [`naive_sum`] into `out` through `work` (all weights 1): no allocation once `work` is sized
/// for the estimates.
pub fn naive_sum_into(
    estimates: &[Gaussian],
    out: &mut Gaussian,
    work: &mut FusionWork,
) -> Result<(), FilterError> {
    informations(estimates, work)?;
    let s = &mut work.scratch;
    s.w.fill(1.0);
    weighted(&work.infos, &s.w, &mut s.sum);
    s.sum.to_gaussian_into(out, &mut s.factor)
}

/// `Σ ω_i Y_i`, `Σ ω_i y_i` of `estimates` back to covariance form, into `out`.
fn fuse_with(
    estimates: &[Gaussian],
    weights: &[f64],
    out: &mut Gaussian,
    work: &mut FusionWork,
) -> Result<(), FilterError> {
    informations(estimates, work)?;
    let s = &mut work.scratch;
    weighted(&work.infos, weights, &mut s.sum);
    s.sum.to_gaussian_into(out, &mut s.factor)
}

/// A zero estimate of the estimates' dimension (what the `_into` forms fill).
fn empty_like(estimates: &[Gaussian]) -> Gaussian {
    let n = estimates.first().map_or(0, Gaussian::dim);
    Gaussian::new(Vector::zeros(n), Matrix::zeros(n, n))
}
