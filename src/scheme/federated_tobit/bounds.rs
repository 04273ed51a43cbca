//! The self-propagating covariance bounds of Geng et al., Theorem 4 (local filters) and
//! Theorem 5 (fused), computed along a recorded run.
//!
//! Readings (the printed recursion mixes `P` and `P^u` and has sign slips; documented choices):
//!
//! * upper bound, Theorem 4: with `c_u = (1 - alpha)^2` and `h = Gamma_{m,h_k} C_m`,
//!   `P^u_{k+1} = A P^u A^T + Q - c_u A P^u h^T (c_u h P^u h^T + R (1 + varphi_l))^{-1} h P^u A^T`,
//!   `P^u` throughout (a recursion that uses the filter's own `P` would not be
//!   self-propagating); the protocol sum of the braces is zero on scheduled steps and the
//!   whole update term is zero on the others (`h = 0`). `1 + varphi_l` is the variance factor
//!   of the one-sided truncation at `theta_l`, i.e. (15) at `theta_r = +inf`, which is
//!   `1 - lambda (lambda - theta_l)`; the printed `varphi = lambda (lambda - theta_l)` has the
//!   opposite sign ([`UpperVarphi`] offers both). `alpha` is (9)'s (`sqrt(R)`) and `theta_l`
//!   the theta of (14)-(15), so under the printed `theta_denominator = "r"` it is
//!   `(tau_l - zeta^-)/R`, the theorem's printed `theta-bar_l` (see [`crate::filter::tobit`]).
//! * lower bound, Theorem 4: `P^l_{k+1} = (1 - (1 - alpha - beta)^2) A P^l A^T + Q` as in the
//!   theorem's statement (the appendix's `(1 - alpha - beta)^2 Q` is looser). `alpha`, `beta`
//!   are those of what the estimator holds, on every step (as printed).
//! * both start from the filter's first prediction covariance `P^-_1` (the proof's
//!   `P^u_0 = P_0`).
//! * Theorem 5: `[sum_m (P^u_m)^{-1}]^{-1}` and the same for `P^l`, from the local bounds.
//!
//! Whether these bounds hold is an empirical question the tests answer: see
//! `tests::theorem4_*` and docs/reproductions.md.
use crate::linalg::{spd_inverse, symmetrize, Matrix};
use crate::model::LinearTransition;
use crate::stats::truncated_normal::truncated_standard;

/// Which `varphi` the upper bound uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpperVarphi {
    /// (15) at `theta_r = +inf`: `1 + varphi = 1 - lambda (lambda - theta_l)` (default).
    #[default]
    Lemma1,
    /// As printed under Theorem 4: `1 + varphi = 1 + lambda (lambda - theta_l)`.
    Printed,
}

/// What one step contributes to the recursions.
#[derive(Debug, Clone, PartialEq)]
pub struct BoundStep {
    /// `Gamma_{m,h_k} C_m` (1 x n) on a scheduled step, `None` otherwise.
    pub h: Option<Matrix>,
    pub r: f64,
    pub alpha: f64,
    pub beta: f64,
    pub theta_l: f64,
}

/// Lower and upper bound of one prediction covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    pub lower: Matrix,
    pub upper: Matrix,
}

/// Theorem 4 along `steps` (step k = 1, 2, ...): element j bounds `P^-_{j+1}`; element 0 is
/// `(p1, p1)`, the first prediction covariance.
pub fn theorem4(
    model: &LinearTransition,
    p1: &Matrix,
    steps: &[BoundStep],
    varphi: UpperVarphi,
) -> Vec<Bounds> {
    let a = model.f();
    let q = model.q();
    let mut out = Vec::with_capacity(steps.len() + 1);
    let mut pl = p1.clone();
    let mut pu = p1.clone();
    out.push(Bounds {
        lower: pl.clone(),
        upper: pu.clone(),
    });
    for s in steps {
        let mut next_u = a * &pu * a.transpose() + q;
        if let Some(h) = &s.h {
            let cu = (1.0 - s.alpha).powi(2);
            let t = truncated_standard(s.theta_l, f64::INFINITY);
            let vf = match varphi {
                UpperVarphi::Lemma1 => t.var,
                UpperVarphi::Printed => 2.0 - t.var,
            };
            let ph = &pu * h.transpose();
            let denom = cu * (h * &ph)[0] + s.r * vf;
            if denom > 0.0 {
                let aph = a * &ph;
                next_u -= &aph * aph.transpose() * (cu / denom);
            }
        }
        symmetrize(&mut next_u);
        let c = (1.0 - s.alpha - s.beta).clamp(0.0, 1.0).powi(2);
        let mut next_l = a * &pl * a.transpose() * (1.0 - c) + q;
        symmetrize(&mut next_l);
        pu = next_u;
        pl = next_l;
        out.push(Bounds {
            lower: pl.clone(),
            upper: pu.clone(),
        });
    }
    out
}

/// Theorem 5: `[sum_m B_m^{-1}]^{-1}` of the local bounds at one step (lower and upper).
pub fn theorem5(locals: &[&Bounds]) -> Option<Bounds> {
    let fuse = |f: &dyn Fn(&Bounds) -> &Matrix| -> Option<Matrix> {
        let n = f(locals[0]).nrows();
        let mut info = Matrix::zeros(n, n);
        for b in locals {
            info += spd_inverse(f(b)).ok()?;
        }
        spd_inverse(&info).ok()
    };
    Some(Bounds {
        lower: fuse(&|b| &b.lower)?,
        upper: fuse(&|b| &b.upper)?,
    })
}

/// The smallest eigenvalue of the symmetric `a - b` relative to the scale of `a` and `b`:
/// >= -tol means `a >= b` in the positive-semidefinite order up to rounding.
pub fn psd_margin(a: &Matrix, b: &Matrix) -> f64 {
    let mut d = a - b;
    symmetrize(&mut d);
    let scale = a.amax().max(b.amax()).max(1e-300);
    d.symmetric_eigenvalues().min() / scale
}
