//! Probability that a Gaussian quadratic form stays below a bound, `P(q^T q < eta)` with
//! `q ~ N(m, C)`.
//!
//! Why: with vector measurements a censoring sensor of Zheng et al. (2014) stays silent when its
//! normalized innovation squared is below `eta` (eq. (31)), and the fusion center's full
//! likelihood (33) weighs each particle by `P(q^T q < eta)` with
//! `q ~ N(S^{-1/2} H (x - x_pred), S^{-1/2} R S^{-1/2})`. The paper estimates this by
//! counting Monte Carlo samples (Section VI); [`prob_below_monte_carlo`] reproduces that.
//! The exact computation below is deterministic and cheap enough to run for every particle.
//!
//! # Reduction
//! Diagonalize `C = U diag(lambda) U^T` and set `b = U^T m`. Then
//! `q^T q = sum_j (b_j + sqrt(lambda_j) z_j)^2` with `z ~ N(0, I)`: components with
//! `lambda_j = 0` add the constant `b_j^2`, the others give a generalized chi-square
//! `Q = sum_j lambda_j (z_j + delta_j)^2`, `delta_j = b_j / sqrt(lambda_j)`. So
//! `P(q^T q < eta) = P(Q < x)` with `x = eta - sum_{lambda_j = 0} b_j^2`.
//! One positive eigenvalue: `P = Q(-s - delta) - Q(s - delta)`, `s = sqrt(x / lambda)`,
//! exactly, through [`normal::log_q_band`].
//!
//! # Two exact methods, chosen per call
//! **Ruben's series** (Ruben 1962, "Probability content of regions under spherical normal
//! distributions IV", Ann. Math. Stat. 33). With `beta = min lambda_j`, `Q` is a mixture of
//! scaled central chi-squares: `Q ~ beta chi^2_{r + 2K}` with `K` a random index of
//! weights `c_k >= 0`, `sum c_k = 1`. Hence, with `t = x / (2 beta)`,
//! `g_k = e^{-t} t^{r/2 + k} / Gamma(r/2 + k + 1)` and `C_k = c_0 + ... + c_k`,
//!
//! ```text
//! P(Q < x) = sum_k c_k P(r/2 + k, t) = sum_k g_k C_k        (all terms >= 0).
//! ```
//!
//! The weights come from the generating function
//! `sum c_k w^k = prod_j (beta/lambda_j)^{1/2} e^{-delta_j^2/2} (1 - a_j w)^{-1/2}
//! exp(e_j w / (1 - a_j w))`, `a_j = 1 - beta/lambda_j`, `e_j = delta_j^2 beta / (2 lambda_j)`,
//! whose log-derivative is a sum of geometric-times-linear sequences; running sums of
//! those make each new weight cost O(r) (Ruben's textbook recurrence is O(k)). Everything
//! is a sum of nonnegative terms, so there is no cancellation and small probabilities keep
//! their relative accuracy. Truncation after `M` terms is bounded rigorously: the remainder
//! lies between `C_{M-1} G_M` and `G_M` with `G_M = P(r/2 + M, t)`; the loop stops when
//! either the mass `1 - C_{M-1}` or the Poisson-type tail bound on `G_M` is below 1e-12
//! relative. The number of terms grows like `max(x, E[Q]) / min lambda`.
//!
//! **Gil-Pelaez inversion with Davies' trapezoidal rule** (Davies 1973, Biometrika 60;
//! Imhof 1961, Biometrika 48, gives the integrand). The midpoint rule with step `Delta`,
//! `F = 1/2 - (1/pi) sum_k Im[phi(t_k) e^{-i t_k x}] / (k + 1/2)`, `t_k = (k + 1/2) Delta`,
//! is exact except for the probability of `|Q - x| > 2 pi / Delta` (the square-wave series
//! argument); `Delta` is chosen so that Chernoff bounds put that below 1e-11. The sum is
//! truncated where Imhof's bound on the remaining integral,
//! `(2/(pi r)) prod(2 lambda_j)^{-1/2} T^{-r/2} exp(-sum 2 delta_j^2 lambda_j^2 T^2 /
//! (1 + 4 lambda_j^2 T^2))`, is below 1e-11. This is fast when the noncentrality is large
//! (the characteristic function then decays like a Gaussian), exactly where Ruben's series
//! needs many terms; with small noncentrality the `T^{-r/2}` tail makes it slow, and Ruben
//! is cheap. (Plain Imhof integration was not used: for `r = 2, 3` its tail alone needs
//! truncation points ~1e6 to reach 1e-9.) When a Chernoff bound already shows that
//! `P < 1e-11` or `P > 1 - 1e-11` (a particle far outside, or deep inside, a small-noise
//! band), the inversion returns exactly 0 or 1 without summing.
//!
//! Ruben's series is used when it needs at most 3000 terms (the usual case: ~0.5 us for
//! `n = 2`, ~3 us for `n = 6`); otherwise the cheaper of the two by estimated cost.
//!
//! Absolute error of [`QuadFormCdf::prob_below`]: below 1e-10 (the bounds above plus
//! rounding of O(terms * 1e-16), so this holds up to ~1e5 terms; the tests check 1e-9 up
//! to condition numbers of 1e5). With Ruben's series small probabilities also keep
//! ~1e-12 relative accuracy; with the inversion they are only absolutely accurate.
//!
//! # Limits
//! Eigenvalues below `1e-12 * lambda_max` are treated as exactly zero (the decomposition
//! cannot resolve them anyway). With an ill-conditioned spectrum *and* small noncentrality
//! the cost grows like `lambda_max / lambda_min` (~30 us at 1e3, ~3 ms at 1e5); beyond
//! ~1e7 both methods would exceed the 2e7-term budget and the call returns
//! [`StatsError::NoConvergence`] rather than a wrong number.

use super::chi2::{ln_reg_gamma, StatsError};
use super::normal;
use nalgebra::{Cholesky, DMatrix, DVector, SymmetricEigen};
use rand::Rng;
use rand_distr::StandardNormal;
use statrs::function::gamma::ln_gamma;
use std::f64::consts::{LN_2, PI};

/// Eigenvalues at or below this fraction of the largest are treated as exactly zero.
const ZERO_REL: f64 = 1e-12;
/// Eigenvalues below `-NEG_REL * max |lambda|` make the matrix "not PSD".
const NEG_REL: f64 = 1e-9;
/// Relative asymmetry `|c_ij - c_ji| / max |c|` tolerated (then symmetrized).
const SYM_REL: f64 = 1e-9;
/// Relative truncation tolerance of Ruben's series.
const RUBEN_REL: f64 = 1e-12;
/// Bound on each of the aliasing tails and on the truncation of the trapezoid sum.
const GP_TOL: f64 = 1e-11;
/// Ruben's series is used without further thought when it needs at most this many terms.
const RUBEN_CHEAP: f64 = 3000.0;
/// Hard cap on the number of terms either method may take.
const MAX_TERMS: f64 = 2e7;
/// Per-call scratch lives on the stack up to this dimension.
const STACK_DIM: usize = 8;
/// Ruben's weights start at `c_0 = exp(ln c_0)`; below this the series is not used (the
/// weights would underflow; such large noncentralities suit the inversion method anyway).
const MIN_LN_C0: f64 = -600.0;

/// `P(q^T q < eta)` for `q ~ N(m, C)` with the eigen-decomposition of `C` precomputed.
///
/// The fusion center evaluates this for many particles (different `m`) and one `C`:
/// [`QuadFormCdf::new`] pays for the decomposition once, and [`QuadFormCdf::prob_below`]
/// then costs one `n x n` rotation plus the series or sum, without heap allocation for
/// `n <= 8`.
#[derive(Debug, Clone)]
pub struct QuadFormCdf {
    n: usize,
    /// Eigenvectors as rows, row-major `n x n`: the `r` positive-eigenvalue directions
    /// first (ascending eigenvalue), then the null directions.
    rows: Vec<f64>,
    /// The `r` positive eigenvalues, ascending.
    lam: Vec<f64>,
    /// Ruben's `a_j = 1 - beta / lambda_j`, `beta = lam[0]`.
    a: Vec<f64>,
    /// `(1/2) sum_j log(beta / lambda_j)`: the determinant part of `log c_0`.
    half_ln_det_ratio: f64,
}

impl QuadFormCdf {
    /// Decompose the covariance `c` (symmetric positive semidefinite, `n >= 1`).
    ///
    /// # Errors
    /// [`StatsError::InvalidArgument`] for an empty, non-square, non-finite or asymmetric
    /// (beyond 1e-9 relative) matrix; [`StatsError::NotPositiveSemidefinite`] if an
    /// eigenvalue is below `-1e-9` times the largest magnitude.
    pub fn new(c: &DMatrix<f64>) -> Result<Self, StatsError> {
        let n = c.nrows();
        if n == 0 || c.ncols() != n {
            return Err(StatsError::InvalidArgument(
                "covariance must be square and non-empty",
            ));
        }
        if c.iter().any(|v| !v.is_finite()) {
            return Err(StatsError::InvalidArgument(
                "covariance has non-finite entries",
            ));
        }
        let scale = c.amax();
        let sym = (c + c.transpose()) * 0.5;
        if (c - c.transpose()).amax() > SYM_REL * scale {
            return Err(StatsError::InvalidArgument("covariance is not symmetric"));
        }
        let eig = SymmetricEigen::new(sym);
        let lam_abs_max = eig.eigenvalues.amax();
        let lam_min = eig.eigenvalues.min();
        if lam_min < -NEG_REL * lam_abs_max {
            return Err(StatsError::NotPositiveSemidefinite {
                min_eigenvalue: lam_min,
            });
        }
        let lam_max = eig.eigenvalues.max();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
        let positive: Vec<usize> = order
            .iter()
            .copied()
            .filter(|&i| eig.eigenvalues[i] > ZERO_REL * lam_max && lam_max > 0.0)
            .collect();
        let null: Vec<usize> = order
            .iter()
            .copied()
            .filter(|i| !positive.contains(i))
            .collect();
        let mut rows = Vec::with_capacity(n * n);
        for &i in positive.iter().chain(null.iter()) {
            rows.extend(eig.eigenvectors.column(i).iter());
        }
        let lam: Vec<f64> = positive.iter().map(|&i| eig.eigenvalues[i]).collect();
        let beta = lam.first().copied().unwrap_or(1.0);
        let a = lam.iter().map(|&l| 1.0 - beta / l).collect();
        let half_ln_det_ratio = 0.5 * lam.iter().map(|&l| (beta / l).ln()).sum::<f64>();
        Ok(QuadFormCdf {
            n,
            rows,
            lam,
            a,
            half_ln_det_ratio,
        })
    }

    /// Dimension `n` of `q`.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// The positive eigenvalues of `C` (ascending); the rest were treated as zero.
    pub fn eigenvalues(&self) -> &[f64] {
        &self.lam
    }

    /// `P(q^T q < eta)` for `q ~ N(m, C)`: Zheng et al.'s (2014) `p(q^T q < eta)` in eq. (33).
    ///
    /// `eta <= 0` gives 0 (the inequality is strict). See the module documentation for the
    /// method and its error (absolute below 1e-10).
    ///
    /// # Errors
    /// [`StatsError::DimensionMismatch`] if `m` has the wrong length;
    /// [`StatsError::InvalidArgument`] for non-finite `m` or NaN `eta`;
    /// [`StatsError::NoConvergence`] in the ill-conditioned corner described in the module
    /// documentation.
    pub fn prob_below(&self, m: &DVector<f64>, eta: f64) -> Result<f64, StatsError> {
        self.prob_below_slice(m.as_slice(), eta)
    }

    /// As [`QuadFormCdf::prob_below`], with the mean as a slice.
    pub fn prob_below_slice(&self, m: &[f64], eta: f64) -> Result<f64, StatsError> {
        if m.len() != self.n {
            return Err(StatsError::DimensionMismatch {
                expected: self.n,
                found: m.len(),
            });
        }
        if eta.is_nan() {
            return Err(StatsError::InvalidArgument("eta is NaN"));
        }
        if m.iter().any(|v| !v.is_finite()) {
            return Err(StatsError::InvalidArgument("mean has non-finite entries"));
        }
        if eta <= 0.0 {
            return Ok(0.0);
        }
        if eta == f64::INFINITY {
            return Ok(1.0);
        }
        let r = self.lam.len();
        // Per-call scratch: b (n), then four arrays of length r.
        let need = self.n + 4 * r;
        let mut stack = [0.0; 5 * STACK_DIM];
        let mut heap;
        let work: &mut [f64] = if need <= stack.len() {
            &mut stack[..need]
        } else {
            heap = vec![0.0; need];
            &mut heap
        };
        let (b, rest) = work.split_at_mut(self.n);
        for (j, bj) in b.iter_mut().enumerate() {
            let row = &self.rows[j * self.n..(j + 1) * self.n];
            *bj = row.iter().zip(m).map(|(u, v)| u * v).sum();
        }
        let c0: f64 = b[r..].iter().map(|v| v * v).sum();
        let x = eta - c0;
        if x <= 0.0 {
            return Ok(0.0);
        }
        if r == 0 {
            return Ok(1.0);
        }
        if r == 1 {
            let sl = self.lam[0].sqrt();
            let s = (x / self.lam[0]).sqrt();
            let d = b[0] / sl;
            return Ok(normal::log_q_band(-s - d, s - d).exp());
        }
        let (d2, rest) = rest.split_at_mut(r);
        for j in 0..r {
            d2[j] = b[j] * b[j] / self.lam[j];
        }
        self.positive_part(d2, x, rest, Method::Auto)
    }

    /// `P(sum_j lambda_j (z_j + delta_j)^2 < x)` for `x > 0`, `r >= 2`, choosing the method.
    fn positive_part(
        &self,
        d2: &[f64],
        x: f64,
        scratch: &mut [f64],
        method: Method,
    ) -> Result<f64, StatsError> {
        let lam = &self.lam;
        let r = lam.len();
        let beta = lam[0];
        let lam_max = lam[r - 1];
        let sum_d2: f64 = d2.iter().sum();
        let ln_c0 = self.half_ln_det_ratio - 0.5 * sum_d2;
        // Expected number of Ruben terms: the index K has mean sum_j (lambda_j/beta - 1)/2 +
        // delta_j^2 lambda_j / (2 beta) and (for a_j -> 1) geometric tails of rate a_max; the
        // Poisson weights g_k are negligible beyond t + 8 sqrt(t).
        let t = x / (2.0 * beta);
        let ruben_terms = if ln_c0 < MIN_LN_C0 {
            f64::INFINITY
        } else {
            let mut mean = 0.0;
            let mut var = 0.0;
            for j in 0..r {
                let ratio = lam[j] / beta; // 1 / (1 - a_j)
                let aj = self.a[j];
                let ej = 0.5 * d2[j] / ratio;
                let mj = 0.5 * (ratio - 1.0) + d2[j] * ratio * 0.5;
                mean += mj;
                var += 0.5 * aj * aj * ratio * ratio + 2.0 * ej * aj * ratio * ratio * ratio + mj;
            }
            let mass = mean + 8.0 * var.sqrt() + 28.0 * lam_max / beta + 10.0;
            let poisson = t + 8.0 * t.sqrt() + 30.0;
            mass.min(poisson)
        };
        let mut plan = None;
        let use_ruben = match method {
            Method::Ruben => true,
            Method::GilPelaez => false,
            Method::Auto => {
                if ruben_terms <= RUBEN_CHEAP {
                    true
                } else {
                    // A trapezoid term costs about as much as 10 Ruben terms (atan, log,
                    // exp, sin per component versus a few multiply-adds).
                    plan = gil_pelaez_plan(lam, d2, x);
                    let gp_terms = plan.map_or(f64::INFINITY, |p| p.terms());
                    if ruben_terms.min(10.0 * gp_terms) > MAX_TERMS {
                        return Err(StatsError::NoConvergence(
                            "quadratic form: spectrum too ill-conditioned for the term budget",
                        ));
                    }
                    ruben_terms <= 10.0 * gp_terms
                }
            }
        };
        if use_ruben {
            if ln_c0 < MIN_LN_C0 {
                return Err(StatsError::NoConvergence(
                    "quadratic form: Ruben weights underflow",
                ));
            }
            self.ruben(d2, x, ln_c0, scratch)
        } else {
            let plan =
                plan.or_else(|| gil_pelaez_plan(lam, d2, x))
                    .ok_or(StatsError::NoConvergence(
                        "quadratic form: no trapezoid step found",
                    ))?;
            match plan {
                GpPlan::Known(p) => Ok(p),
                GpPlan::Sum { terms, .. } if terms > MAX_TERMS => Err(StatsError::NoConvergence(
                    "quadratic form: trapezoid sum exceeds the term budget",
                )),
                GpPlan::Sum { delta, terms } => {
                    Ok(gil_pelaez_sum(lam, d2, x, delta, terms as usize))
                }
            }
        }
    }

    /// Ruben's mixture series (see the module documentation).
    fn ruben(
        &self,
        d2: &[f64],
        x: f64,
        ln_c0: f64,
        scratch: &mut [f64],
    ) -> Result<f64, StatsError> {
        let lam = &self.lam;
        let a = &self.a;
        let r = lam.len();
        let beta = lam[0];
        let (e, rest) = scratch.split_at_mut(r);
        let (s, rest) = rest.split_at_mut(r);
        let u = &mut rest[..r];
        for j in 0..r {
            e[j] = 0.5 * d2[j] * beta / lam[j];
            s[j] = 0.0;
            u[j] = 0.0;
        }
        let t = x / (2.0 * beta);
        let a0 = 0.5 * r as f64;
        // g_k = g_tilde * exp(ln_gs), rescaled by 2^{+-500} to survive e^{-t} underflow.
        const BIG: f64 = 3.273_390_607_896_142e150; // 2^500
        const SMALL: f64 = 3.054_936_363_499_605e-151; // 2^-500
        let mut ln_gs = -t + a0 * t.ln() - ln_gamma(a0 + 1.0);
        let mut gs = ln_gs.exp();
        let mut g_tilde = 1.0;
        let mut c = ln_c0.exp();
        let mut cum = 0.0;
        let mut sum = 0.0;
        let max_terms = MAX_TERMS as usize;
        for k in 0..max_terms {
            if k > 0 {
                let mut acc = 0.0;
                for j in 0..r {
                    acc += 0.5 * a[j] * s[j] + e[j] * u[j];
                }
                c = acc / k as f64;
            }
            cum += c;
            for j in 0..r {
                let s_old = s[j];
                s[j] = a[j] * s_old + c;
                u[j] = a[j] * (u[j] + s_old) + c;
            }
            sum += g_tilde * gs * cum;
            // Advance to g_{k+1}.
            let kf = k as f64;
            let ratio = t / (a0 + kf + 1.0);
            g_tilde *= ratio;
            if g_tilde > BIG {
                g_tilde *= SMALL;
                ln_gs += 500.0 * LN_2;
                gs = ln_gs.exp();
            } else if g_tilde < SMALL && g_tilde > 0.0 {
                g_tilde *= BIG;
                ln_gs -= 500.0 * LN_2;
                gs = ln_gs.exp();
            }
            // Remainder R = sum_{i>k} g_i C_i lies in [C_k G, G], G = sum_{i>k} g_i.
            if 1.0 - cum <= RUBEN_REL {
                // Mass exhausted: R = C_k G up to (1 - C_k) G <= 1e-12 G.
                let g_tail = ln_reg_gamma(a0 + kf + 1.0, t).0.exp();
                return Ok((sum + cum.min(1.0) * g_tail).min(1.0));
            }
            let next_ratio = t / (a0 + kf + 2.0);
            if next_ratio < 1.0 {
                // Past the peak of g: G <= g_{k+1} / (1 - next_ratio) (geometric bound).
                let bound = g_tilde * gs / (1.0 - next_ratio);
                if bound <= RUBEN_REL * sum || bound < 1e-300 {
                    return Ok(sum.min(1.0));
                }
            }
        }
        Err(StatsError::NoConvergence(
            "quadratic form: Ruben series exceeds the term budget",
        ))
    }
}

/// Which method [`QuadFormCdf::positive_part`] uses (forcing one is for tests).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(not(test), allow(dead_code))]
enum Method {
    Auto,
    Ruben,
    GilPelaez,
}

/// Cumulant generating function `K(s) = log E[e^{sQ}]`, `s < 1 / (2 lambda_max)`.
fn cgf(lam: &[f64], d2: &[f64], s: f64) -> f64 {
    lam.iter()
        .zip(d2)
        .map(|(&l, &d)| {
            let v = 1.0 - 2.0 * l * s;
            -0.5 * v.ln() + d * l * s / v
        })
        .sum()
}

/// What the Chernoff bounds and Imhof's truncation bound say about the inversion.
#[derive(Debug, Clone, Copy, PartialEq)]
enum GpPlan {
    /// `x` lies beyond a Chernoff bound: the probability is this value to within 1e-11.
    Known(f64),
    /// Trapezoidal sum with step `delta` and `terms` midpoints.
    Sum { delta: f64, terms: f64 },
}

impl GpPlan {
    fn terms(&self) -> f64 {
        match self {
            GpPlan::Known(_) => 0.0,
            GpPlan::Sum { terms, .. } => *terms,
        }
    }
}

/// Plan the trapezoidal Gil-Pelaez sum: step from Chernoff bounds on both tails of `Q`,
/// number of terms from Imhof's truncation bound. `None` if no finite truncation point
/// exists below ~2^200 / lambda_max.
fn gil_pelaez_plan(lam: &[f64], d2: &[f64], x: f64) -> Option<GpPlan> {
    let r = lam.len();
    let lam_max = lam[r - 1];
    let ln_tol = GP_TOL.ln();
    // Chernoff: P(Q > y) <= exp(K(s) - s y) <= tol for y >= (K(s) - ln tol) / s.
    let mut upper = f64::INFINITY;
    for i in 1..=40 {
        let f = if i <= 20 {
            1.0 - 0.5_f64.powi(i)
        } else {
            0.5_f64.powi(i - 19)
        };
        let s = f / (2.0 * lam_max);
        upper = upper.min((cgf(lam, d2, s) - ln_tol) / s);
    }
    // P(Q < y) <= exp(K(-s) + s y) <= tol for y <= (ln tol - K(-s)) / s.
    let mut lower = f64::NEG_INFINITY;
    for i in -8..48 {
        let s = 2.0_f64.powi(i) / (2.0 * lam_max);
        lower = lower.max((ln_tol - cgf(lam, d2, -s)) / s);
    }
    if x <= lower {
        return Some(GpPlan::Known(0.0));
    }
    if x >= upper {
        return Some(GpPlan::Known(1.0));
    }
    let width = (x - lower).max(upper - x);
    if !(width > 0.0 && width.is_finite()) {
        return None;
    }
    let delta = 2.0 * PI / width;
    // Truncation: smallest T (to a factor 1.001) with Imhof's bound below tol. The bound
    // decreases in T; bracket it by doubling or halving from 1 / lambda_max, then bisect.
    let ln_const =
        (2.0 / (PI * r as f64)).ln() - 0.5 * lam.iter().map(|&l| (2.0 * l).ln()).sum::<f64>();
    let ln_bound = |tt: f64| -> f64 {
        let mut v = ln_const - 0.5 * r as f64 * tt.ln();
        for (&l, &d) in lam.iter().zip(d2) {
            let lt2 = 4.0 * l * l * tt * tt;
            v -= 0.5 * d * lt2 / (1.0 + lt2);
        }
        v
    };
    let start = 1.0 / lam_max;
    let (mut lo, mut hi) = (start, start);
    if ln_bound(start) > ln_tol {
        let mut steps = 0;
        while ln_bound(hi) > ln_tol {
            lo = hi;
            hi *= 2.0;
            steps += 1;
            if steps > 200 {
                return None;
            }
        }
    } else {
        let mut steps = 0;
        while ln_bound(lo) <= ln_tol {
            hi = lo;
            lo *= 0.5;
            steps += 1;
            if steps > 200 {
                break;
            }
        }
    }
    while hi > 1.001 * lo {
        let mid = (lo * hi).sqrt();
        if ln_bound(mid) > ln_tol {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // Need (K - 1/2) Delta >= T.
    let terms = (hi / delta + 0.5).ceil();
    Some(GpPlan::Sum { delta, terms })
}

/// The trapezoidal Gil-Pelaez sum with `terms` midpoints `t_k = (k + 1/2) delta`.
fn gil_pelaez_sum(lam: &[f64], d2: &[f64], x: f64, delta: f64, terms: usize) -> f64 {
    let mut sum = 0.0;
    for k in 0..terms {
        let kh = k as f64 + 0.5;
        let t = kh * delta;
        let mut theta = -t * x;
        let mut ln_mod = 0.0;
        for (&l, &d) in lam.iter().zip(d2) {
            let lt = 2.0 * l * t;
            let lt2 = lt * lt;
            let inv = 1.0 / (1.0 + lt2);
            theta += 0.5 * lt.atan() + 0.5 * d * lt * inv;
            ln_mod -= 0.25 * lt2.ln_1p() + 0.5 * d * lt2 * inv;
        }
        sum += ln_mod.exp() * theta.sin() / kh;
    }
    (0.5 - sum / PI).clamp(0.0, 1.0)
}

/// `P(q^T q < eta)` for `q ~ N(m, C)`; one-off form of [`QuadFormCdf`].
///
/// # Errors
/// As [`QuadFormCdf::new`] and [`QuadFormCdf::prob_below`].
pub fn prob_below(m: &DVector<f64>, c: &DMatrix<f64>, eta: f64) -> Result<f64, StatsError> {
    QuadFormCdf::new(c)?.prob_below(m, eta)
}

/// Monte Carlo estimate of `P(q^T q < eta)`, as Zheng et al. (2014) computes it (Section VI): draw
/// `n_samples` vectors `q = m + F z` with `F F^T = C` (Cholesky factor, or
/// `U diag(sqrt(lambda))` when `C` is singular) and return the fraction with
/// `q^T q < eta`. Its standard error is `sqrt(p (1 - p) / n_samples)`; kept to reproduce the
/// paper and as an independent check of [`prob_below`].
///
/// # Errors
/// As [`QuadFormCdf::new`] (for the factorization), plus
/// [`StatsError::InvalidArgument`] if `n_samples == 0` or an input is non-finite or NaN.
pub fn prob_below_monte_carlo<R: Rng + ?Sized>(
    m: &DVector<f64>,
    c: &DMatrix<f64>,
    eta: f64,
    n_samples: usize,
    rng: &mut R,
) -> Result<f64, StatsError> {
    let n = c.nrows();
    if n == 0 || c.ncols() != n {
        return Err(StatsError::InvalidArgument(
            "covariance must be square and non-empty",
        ));
    }
    if m.len() != n {
        return Err(StatsError::DimensionMismatch {
            expected: n,
            found: m.len(),
        });
    }
    if n_samples == 0 {
        return Err(StatsError::InvalidArgument("n_samples must be positive"));
    }
    if eta.is_nan() || m.iter().any(|v| !v.is_finite()) {
        return Err(StatsError::InvalidArgument("non-finite input"));
    }
    // Validates symmetry, finiteness and semidefiniteness.
    QuadFormCdf::new(c)?;
    let f = match Cholesky::new(c.clone()) {
        Some(ch) => ch.unpack(),
        None => {
            // Singular: use the eigen factor U diag(sqrt(lambda)).
            let eig = SymmetricEigen::new((c + c.transpose()) * 0.5);
            let mut f = eig.eigenvectors.clone();
            for (j, mut col) in f.column_iter_mut().enumerate() {
                col *= eig.eigenvalues[j].max(0.0).sqrt();
            }
            f
        }
    };
    let mut z = DVector::<f64>::zeros(n);
    let mut q = DVector::<f64>::zeros(n);
    let mut count = 0usize;
    for _ in 0..n_samples {
        for zi in z.iter_mut() {
            *zi = rng.sample(StandardNormal);
        }
        q.copy_from(m);
        q.gemv(1.0, &f, &z, 1.0);
        if q.norm_squared() < eta {
            count += 1;
        }
    }
    Ok(count as f64 / n_samples as f64)
}

#[cfg(test)]
mod tests;
