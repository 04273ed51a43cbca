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
use crate::linalg::{cholesky, Matrix, Vector};

/// Golden-section iterations for two estimates: the bracket shrinks by 0.618 per step, so
/// 60 steps leave it below 1e-12.
const GOLDEN_STEPS: usize = 60;
/// Exponentiated-gradient iterations for more than two estimates.
const EG_STEPS: usize = 100;

/// The information form of every estimate (precomputed once per fusion).
fn informations(estimates: &[Gaussian]) -> Result<Vec<Information>, FilterError> {
    estimates.iter().map(Information::from_gaussian).collect()
}

fn weighted(infos: &[Information], w: &[f64]) -> Information {
    let n = infos[0].vector.len();
    let mut matrix = Matrix::zeros(n, n);
    let mut vector = Vector::zeros(n);
    for (info, &wi) in infos.iter().zip(w) {
        if wi > 0.0 {
            matrix += &info.matrix * wi;
            vector += &info.vector * wi;
        }
    }
    Information { matrix, vector }
}

/// tr((Σ ω_i Y_i)^{-1}), +∞ where the sum is not positive definite.
fn trace_of(infos: &[Information], w: &[f64]) -> f64 {
    match cholesky(&weighted(infos, w).matrix) {
        Ok(c) => c.inverse().trace(),
        Err(_) => f64::INFINITY,
    }
}

/// The trace-minimizing covariance-intersection weights of `estimates` (module doc).
pub fn ci_weights(estimates: &[Gaussian]) -> Result<Vec<f64>, FilterError> {
    let infos = informations(estimates)?;
    Ok(ci_weights_of(&infos))
}

fn ci_weights_of(infos: &[Information]) -> Vec<f64> {
    let m = infos.len();
    match m {
        0 => vec![],
        1 => vec![1.0],
        2 => {
            let f = |a: f64| trace_of(infos, &[a, 1.0 - a]);
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
            vec![best, 1.0 - best]
        }
        _ => {
            let mut w = vec![1.0 / m as f64; m];
            let mut value = trace_of(infos, &w);
            let mut eta = 1.0;
            for _ in 0..EG_STEPS {
                let Ok(c) = cholesky(&weighted(infos, &w).matrix) else {
                    break;
                };
                let p = c.inverse();
                // ∂ tr P / ∂ω_i = -tr(P Y_i P), scaled so the largest step is eta.
                let grad: Vec<f64> = infos
                    .iter()
                    .map(|info| -(&p * &info.matrix * &p).trace())
                    .collect();
                let scale = grad.iter().fold(0.0_f64, |a, g| a.max(g.abs()));
                if scale.is_nan() || scale <= 0.0 {
                    break;
                }
                let mut improved = false;
                while eta > 1e-8 {
                    let mut trial: Vec<f64> = w
                        .iter()
                        .zip(&grad)
                        .map(|(wi, gi)| wi * (-eta * gi / scale).exp())
                        .collect();
                    let sum: f64 = trial.iter().sum();
                    trial.iter_mut().for_each(|t| *t /= sum);
                    let v = trace_of(infos, &trial);
                    if v < value {
                        let gain = value - v;
                        w = trial;
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
            w
        }
    }
}

/// Covariance intersection of `estimates` with the trace-minimizing weights; returns the
/// fused estimate and the weights.
pub fn covariance_intersection(
    estimates: &[Gaussian],
) -> Result<(Gaussian, Vec<f64>), FilterError> {
    let infos = informations(estimates)?;
    let w = ci_weights_of(&infos);
    Ok((weighted(&infos, &w).to_gaussian()?, w))
}

/// Covariance intersection with given weights (each ω_i >= 0, summing to 1).
pub fn covariance_intersection_with(
    estimates: &[Gaussian],
    weights: &[f64],
) -> Result<Gaussian, FilterError> {
    let infos = informations(estimates)?;
    weighted(&infos, weights).to_gaussian()
}

/// The naive information sum (module doc).
pub fn naive_sum(estimates: &[Gaussian]) -> Result<Gaussian, FilterError> {
    let infos = informations(estimates)?;
    weighted(&infos, &vec![1.0; infos.len()]).to_gaussian()
}
