//! Lloyd-Max (MSE-optimal, fixed-rate) scalar quantizers for a standard normal input.
//!
//! Zhang, Li & Liu (Sci China Inf Sci 59:022316, 2016), Section 3.1, take the thresholds
//! `τ_1 < τ_2 < … < τ_{L+1}` of the quantizer of eq. (5) from the Lloyd-Max design for the
//! normalized innovation `ψ ~ N(0, 1)` (eq. (3) and (A9)). The same design also gives the
//! baselines the paper compares against (Table 7): the Table 7 values of `ρ` are exactly
//! `1 - MSE` of Lloyd-Max quantizers with 2, 3, 4, 5 and 21 levels, see [`LloydMax::rho`].
//!
//! # Indexing
//!
//! The paper numbers thresholds from 1 with `τ_1 = -∞` and `τ_{L+1} = +∞` and cell `j` is
//! `(τ_j, τ_{j+1}]`. Here only the `L - 1` finite thresholds are stored, 0-based and
//! increasing, so cell `i` (0-based) is `(thresholds[i - 1], thresholds[i]]` with the
//! convention `thresholds[-1] = -∞`, `thresholds[L - 1] = +∞`; i.e. the paper's `τ_{i+2}`
//! is `thresholds[i]`. Cells are left-open and right-closed as in eq. (5).
//!
//! # Method
//!
//! The two optimality conditions (nearest-neighbour: every threshold is the midpoint of its
//! two neighbouring levels; centroid: every level is the conditional mean of its cell) are
//! solved simultaneously by Newton's method on the thresholds alone, the levels being
//! eliminated through the centroid condition. The standard normal is symmetric and the
//! optimal quantizer of a symmetric unimodal log-concave density is unique and symmetric
//! (Fleischer 1964, Trushkin 1982), so only the positive thresholds are unknowns and the
//! quantizer is mirrored afterwards: that halves the system and makes the result exactly
//! symmetric (the centre level of an odd `L` is exactly `0.0`). The Jacobian is tridiagonal
//! (a threshold only interacts with its two neighbouring cells), so each Newton step is
//! `O(L)`. Plain Lloyd iteration would also work but its contraction factor is
//! `1 - O(1/L²)`, far too slow for 1e-10 at the 69 levels the paper's Table 2 needs.
//! The start is the asymptotically optimal compander (point density ∝ φ^{1/3}, i.e.
//! thresholds at the quantiles of `N(0, 3)`, Panter & Dite 1951), polished by a few Lloyd
//! sweeps; Newton steps are damped so the residual decreases monotonically.

use statrs::function::erf::erf_inv;
use std::f64::consts::SQRT_2;

/// `1 / sqrt(2π)`.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Largest number of levels [`LloydMax::design`] accepts: `2^8 + 1`, the largest quantizer
/// the link module builds (You et al.'s with 8 bits). The paper itself needs at most 69
/// (Table 2, `c_i ≤ 3`). The limit is about accuracy, not cost: the Jacobian of the
/// optimality conditions has condition number `O(L²)`, so a rounding-level residual
/// (~1e-15) moves the thresholds by ~6e-13 at `L = 69`, ~8e-12 at `L = 256` and ~1e-10 at
/// `L = 1024`; capping at 257 keeps the promised 1e-10 with margin.
pub const MAX_LEVELS: usize = 257;

/// Why a Lloyd-Max design failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LloydMaxError {
    /// A quantizer needs at least one level.
    #[error("a quantizer needs at least one level")]
    NoLevels,
    /// More levels than [`MAX_LEVELS`].
    #[error("{levels} levels requested, at most {max} supported")]
    TooManyLevels {
        /// Requested number of levels.
        levels: usize,
        /// [`MAX_LEVELS`].
        max: usize,
    },
    /// Newton's method did not reach the optimality conditions (should not happen for
    /// `L ≤ MAX_LEVELS`; kept so a numerical surprise is an error, not a wrong quantizer).
    #[error("Lloyd-Max design for {levels} levels did not converge (residual {residual:e})")]
    NoConvergence {
        /// Requested number of levels.
        levels: usize,
        /// Largest violation of the midpoint condition when giving up.
        residual: f64,
    },
}

/// Moments of a standard normal `ψ` restricted to one cell `(lo, hi]`: what the fusion
/// centre needs to know about a quantized innovation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellMoments {
    /// `Pr{lo < ψ ≤ hi} = Φ(hi) - Φ(lo)`, the denominator of eqs. (11), (14), (16).
    pub probability: f64,
    /// `E[ψ | lo < ψ ≤ hi]`: the `σ_k^i` of eq. (14) / (A28), the factor multiplying the
    /// normalized gain in the state update (13).
    pub mean: f64,
    /// `1 - Var[ψ | lo < ψ ≤ hi]`: the `η_k^i` of eq. (11) / (A30), the fraction of the
    /// analog-measurement covariance reduction that this cell achieves in (10).
    pub eta: f64,
}

/// Standard normal density; exactly 0 at ±∞.
fn pdf(x: f64) -> f64 {
    if x.is_infinite() {
        0.0
    } else {
        FRAC_1_SQRT_2PI * (-0.5 * x * x).exp()
    }
}

/// `x φ(x)`, with the limit 0 at ±∞ (avoids `∞ · 0 = NaN`).
fn x_pdf(x: f64) -> f64 {
    if x.is_infinite() {
        0.0
    } else {
        x * pdf(x)
    }
}

/// Upper tail `Q(x) = 1 - Φ(x)` on the crate's accurate tail function
/// ([`crate::stats::normal::q`], a few 1e-15 relative; statrs' `erfc` has about 1e-10, which
/// limited the midpoint condition and `rho` to that).
fn upper_tail(x: f64) -> f64 {
    if x == f64::INFINITY {
        0.0
    } else if x == f64::NEG_INFINITY {
        1.0
    } else {
        crate::stats::normal::q(x)
    }
}

/// `Pr{a < ψ ≤ b}` for `a ≤ b`; differences of upper tails on the side away from the
/// mode so that outer cells keep their relative accuracy (`Φ(b) - Φ(a)` near 1 would not).
fn mass(a: f64, b: f64) -> f64 {
    if a >= 0.0 {
        upper_tail(a) - upper_tail(b)
    } else if b <= 0.0 {
        upper_tail(-b) - upper_tail(-a)
    } else {
        1.0 - upper_tail(b) - upper_tail(-a)
    }
}

/// `φ(a) - φ(b)` (the numerator of eq. (14)) without the cancellation of the direct
/// difference when `a` and `b` are close: factor out the larger density and use `expm1`.
fn pdf_drop(a: f64, b: f64) -> f64 {
    if a.is_infinite() || b.is_infinite() {
        return pdf(a) - pdf(b);
    }
    if a.abs() <= b.abs() {
        // φ(a) - φ(b) = φ(a) (1 - e^{-(b² - a²)/2}), exponent ≤ 0.
        -pdf(a) * (-0.5 * (b - a) * (b + a)).exp_m1()
    } else {
        // φ(a) - φ(b) = φ(b) (e^{-(a² - b²)/2} - 1), exponent ≤ 0.
        pdf(b) * (-0.5 * (a - b) * (a + b)).exp_m1()
    }
}

/// Moments of `N(0, 1)` on the cell `(lo, hi]`, `lo < hi`, either end possibly infinite.
///
/// Returns a zero probability (and NaN mean/eta) when the cell's mass underflows; callers
/// that accept arbitrary thresholds must check `probability > 0`.
pub fn cell_moments(lo: f64, hi: f64) -> CellMoments {
    let probability = mass(lo, hi);
    let mean = pdf_drop(lo, hi) / probability;
    // η = σ² - (τ_j φ(τ_j) - τ_{j+1} φ(τ_{j+1})) / (Φ(τ_{j+1}) - Φ(τ_j)), eq. (11); this is
    // 1 - Var of the truncated normal.
    let eta = mean * mean - (x_pdf(lo) - x_pdf(hi)) / probability;
    CellMoments {
        probability,
        mean,
        eta,
    }
}

/// Centroid `m(a, b)` of the cell `(a, b)` and its partial derivatives
/// `∂m/∂a = φ(a)(m - a)/P`, `∂m/∂b = φ(b)(b - m)/P` (zero at infinite ends).
fn centroid_with_derivatives(a: f64, b: f64) -> (f64, f64, f64) {
    let p = mass(a, b);
    let m = pdf_drop(a, b) / p;
    let da = if a.is_infinite() {
        0.0
    } else {
        pdf(a) * (m - a) / p
    };
    let db = if b.is_infinite() {
        0.0
    } else {
        pdf(b) * (b - m) / p
    };
    (m, da, db)
}

/// A Lloyd-Max quantizer for `N(0, 1)`: `L - 1` increasing finite thresholds and `L`
/// reconstruction levels (the conditional means of the cells).
#[derive(Debug, Clone, PartialEq)]
pub struct LloydMax {
    /// The `L - 1` finite thresholds, increasing (the paper's `τ_2 … τ_L`).
    pub thresholds: Vec<f64>,
    /// The `L` reconstruction levels, increasing; `levels[i]` is the centroid of cell `i`.
    pub levels: Vec<f64>,
}

/// Tridiagonal Jacobian rows of the half system (see [`HalfSystem`]).
struct Residual {
    r: Vec<f64>,
    lower: Vec<f64>,
    diag: Vec<f64>,
    upper: Vec<f64>,
}

/// The optimality conditions restricted to the positive thresholds `u_1 < … < u_m`.
///
/// For even `L = 2n` the thresholds are `0, ±u_1, …, ±u_{n-1}` and the first positive
/// cell is `(0, u_1]`; for odd `L = 2n + 1` they are `±u_1, …, ±u_n` and the cell left of
/// `u_1` is the centre cell `(-u_1, u_1]` whose centroid is 0 whatever `u_1` is.
struct HalfSystem {
    odd: bool,
    m: usize,
}

impl HalfSystem {
    fn new(levels: usize) -> Self {
        let odd = levels % 2 == 1;
        let m = if odd {
            (levels - 1) / 2
        } else {
            levels / 2 - 1
        };
        Self { odd, m }
    }

    /// Midpoint-condition residuals `r_i = u_i - (y_left + y_right)/2` and, if asked, the
    /// tridiagonal Jacobian `∂r_i/∂u_{i-1}, ∂r_i/∂u_i, ∂r_i/∂u_{i+1}`.
    fn evaluate(&self, u: &[f64], out: &mut Residual, with_jacobian: bool) {
        let m = self.m;
        for i in 0..m {
            // Cell to the left of u_i.
            let (yl, dl_a, dl_b) = if i == 0 {
                if self.odd {
                    (0.0, 0.0, 0.0) // centre cell, centroid 0 by symmetry
                } else {
                    let (y, _, db) = centroid_with_derivatives(0.0, u[0]);
                    (y, 0.0, db) // lower end fixed at 0
                }
            } else {
                centroid_with_derivatives(u[i - 1], u[i])
            };
            // Cell to the right of u_i.
            let hi = if i + 1 < m { u[i + 1] } else { f64::INFINITY };
            let (yr, dr_a, dr_b) = centroid_with_derivatives(u[i], hi);
            out.r[i] = u[i] - 0.5 * (yl + yr);
            if with_jacobian {
                out.lower[i] = -0.5 * dl_a;
                out.diag[i] = 1.0 - 0.5 * (dl_b + dr_a);
                out.upper[i] = -0.5 * dr_b;
            }
        }
    }

    /// Thresholds must stay positive, finite and strictly increasing.
    fn admissible(u: &[f64]) -> bool {
        (u.is_empty() || u[0] > 0.0)
            && u.iter().all(|x| x.is_finite())
            && u.windows(2).all(|w| w[0] < w[1])
    }
}

/// Solve the tridiagonal system `J x = rhs` (Thomas algorithm). `J` is close to the
/// identity minus a small positive-definite correction (the midpoint map is a contraction
/// for log-concave densities), so no pivoting is needed.
fn solve_tridiagonal(lower: &[f64], diag: &[f64], upper: &[f64], rhs: &mut [f64]) {
    let n = diag.len();
    let mut c = vec![0.0; n];
    let mut beta = diag[0];
    rhs[0] /= beta;
    for i in 1..n {
        c[i - 1] = upper[i - 1] / beta;
        beta = diag[i] - lower[i] * c[i - 1];
        rhs[i] = (rhs[i] - lower[i] * rhs[i - 1]) / beta;
    }
    for i in (0..n.saturating_sub(1)).rev() {
        rhs[i] -= c[i] * rhs[i + 1];
    }
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |a: f64, &x| a.max(x.abs()))
}

impl LloydMax {
    /// Design the `levels`-level Lloyd-Max quantizer of `N(0, 1)`.
    ///
    /// The returned thresholds satisfy the midpoint condition to rounding (~1e-14; more than
    /// 1e-12 is reported as [`LloydMaxError::NoConvergence`]) and the levels are
    /// the cell centroids to rounding, which the tests check against an independent
    /// erf-based evaluation to 1e-9 (1e-10 or better in practice) for every `L ≤ 70`.
    pub fn design(levels: usize) -> Result<LloydMax, LloydMaxError> {
        if levels == 0 {
            return Err(LloydMaxError::NoLevels);
        }
        if levels > MAX_LEVELS {
            return Err(LloydMaxError::TooManyLevels {
                levels,
                max: MAX_LEVELS,
            });
        }
        let u = Self::solve_positive_thresholds(levels)?;
        let sys = HalfSystem::new(levels);
        let mut thresholds = Vec::with_capacity(levels - 1);
        thresholds.extend(u.iter().rev().map(|&x| -x));
        if !sys.odd {
            thresholds.push(0.0);
        }
        thresholds.extend_from_slice(&u);
        debug_assert_eq!(thresholds.len(), levels - 1);

        // Levels: centroids of the positive cells (indices L - L/2 .. L), mirrored so that
        // levels[i] is exactly -levels[L - 1 - i] and an odd L has the centre level 0.0.
        let mut q = LloydMax {
            thresholds,
            levels: Vec::with_capacity(levels),
        };
        let positive: Vec<f64> = (levels - levels / 2..levels)
            .map(|i| {
                let (lo, hi) = q.cell_bounds(i);
                pdf_drop(lo, hi) / mass(lo, hi)
            })
            .collect();
        q.levels.extend(positive.iter().rev().map(|&y| -y));
        if sys.odd {
            q.levels.push(0.0);
        }
        q.levels.extend_from_slice(&positive);
        Ok(q)
    }

    /// Newton's method on the half system; returns `u_1 < … < u_m`.
    fn solve_positive_thresholds(levels: usize) -> Result<Vec<f64>, LloydMaxError> {
        let sys = HalfSystem::new(levels);
        let m = sys.m;
        if m == 0 {
            return Ok(Vec::new()); // L = 1 (no threshold) or L = 2 (threshold 0 only)
        }
        // Compander start: thresholds at quantiles of N(0, 3); the positive ones are the
        // quantiles i/L for i > L/2.
        let first = levels - m; // index i of the first positive threshold
        let mut u: Vec<f64> = (first..levels)
            .map(|i| {
                let p = i as f64 / levels as f64;
                3f64.sqrt() * SQRT_2 * erf_inv(2.0 * p - 1.0)
            })
            .collect();
        let mut res = Residual {
            r: vec![0.0; m],
            lower: vec![0.0; m],
            diag: vec![0.0; m],
            upper: vec![0.0; m],
        };
        // A few Lloyd sweeps (u ← u - r is exactly the Lloyd update) to enter Newton's
        // basin; each sweep keeps the ordering.
        for _ in 0..8 {
            sys.evaluate(&u, &mut res, false);
            let cand: Vec<f64> = u.iter().zip(&res.r).map(|(x, r)| x - r).collect();
            if HalfSystem::admissible(&cand) {
                u = cand;
            } else {
                break;
            }
        }

        let mut trial = Residual {
            r: vec![0.0; m],
            lower: vec![0.0; m],
            diag: vec![0.0; m],
            upper: vec![0.0; m],
        };
        // Residual scale: rounding of u_i - (y_l + y_r)/2 is a few ulps of the largest u.
        let floor = 8.0 * f64::EPSILON * (1.0 + u[m - 1]);
        let mut norm = f64::INFINITY;
        for _ in 0..100 {
            sys.evaluate(&u, &mut res, true);
            norm = max_abs(&res.r);
            if norm <= floor {
                return Ok(u);
            }
            let mut step: Vec<f64> = res.r.iter().map(|r| -r).collect();
            solve_tridiagonal(&res.lower, &res.diag, &res.upper, &mut step);
            let mut lambda = 1.0;
            let mut accepted = false;
            while lambda > 1e-12 {
                let cand: Vec<f64> = u.iter().zip(&step).map(|(x, s)| x + lambda * s).collect();
                if HalfSystem::admissible(&cand) {
                    sys.evaluate(&cand, &mut trial, false);
                    if max_abs(&trial.r) < norm {
                        u = cand;
                        accepted = true;
                        break;
                    }
                }
                lambda *= 0.5;
            }
            if !accepted {
                // No step decreases the residual: we sit at the rounding floor.
                break;
            }
        }
        sys.evaluate(&u, &mut res, false);
        norm = norm.min(max_abs(&res.r));
        if norm <= 1e-12 {
            Ok(u)
        } else {
            Err(LloydMaxError::NoConvergence {
                levels,
                residual: norm,
            })
        }
    }

    /// Number of levels `L`.
    pub fn num_levels(&self) -> usize {
        self.levels.len()
    }

    /// The cell `(lo, hi]` of level `index` (0-based, increasing); `lo = -∞` for the first
    /// cell and `hi = +∞` for the last.
    ///
    /// # Panics
    /// If `index >= L`.
    pub fn cell(&self, index: usize) -> (f64, f64) {
        assert!(
            index < self.levels.len(),
            "level index {index} out of range"
        );
        self.cell_bounds(index)
    }

    /// Bounds of cell `index` from the thresholds alone (`index ≤ thresholds.len()`).
    fn cell_bounds(&self, index: usize) -> (f64, f64) {
        let lo = if index == 0 {
            f64::NEG_INFINITY
        } else {
            self.thresholds[index - 1]
        };
        let hi = self.thresholds.get(index).copied().unwrap_or(f64::INFINITY);
        (lo, hi)
    }

    /// Index of the cell `(lo, hi]` containing `x` (so `x` equal to a threshold goes to the
    /// lower cell, as in eq. (5)). A NaN input is treated as `0.0`, the innovation's mean,
    /// so that a numerical failure upstream cannot produce an extreme level.
    pub fn quantize(&self, x: f64) -> usize {
        let x = if x.is_nan() { 0.0 } else { x };
        self.thresholds.partition_point(|&t| t < x)
    }

    /// Probability `Φ(hi) - Φ(lo)` of cell `index`.
    ///
    /// # Panics
    /// If `index >= L`.
    pub fn probability(&self, index: usize) -> f64 {
        let (lo, hi) = self.cell(index);
        mass(lo, hi)
    }

    /// Mean squared error `E[(ψ - q(ψ))²]` for `ψ ~ N(0, 1)`, computed from the stored
    /// levels (not assuming they are centroids):
    /// `Σ_i ∫_cell (x - y_i)² φ = Σ_i [P_i + a φ(a) - b φ(b) - 2 y_i (φ(a) - φ(b)) + y_i² P_i]`.
    pub fn mse(&self) -> f64 {
        (0..self.levels.len())
            .map(|i| {
                let (a, b) = self.cell(i);
                let p = mass(a, b);
                let y = self.levels[i];
                p + x_pdf(a) - x_pdf(b) - 2.0 * y * pdf_drop(a, b) + y * y * p
            })
            .sum()
    }

    /// The covariance-correction coefficient `ρ` of eq. (16):
    /// `ρ = (1/2π) Σ_j [e^{-τ_j²/2} - e^{-τ_{j+1}²/2}]² / (Φ(τ_{j+1}) - Φ(τ_j))`,
    /// evaluated from the thresholds only.
    ///
    /// `ρ = Σ_j P_j σ_j²` with `σ_j` the cell mean (14), i.e. `E[E[ψ|cell]²]`; it is also the
    /// expectation over cells of `η` in (11) (the `τ φ(τ)` terms telescope to zero). For any
    /// partition with centroid reconstruction `E[ψ q] = E[q²]`, so `MSE = 1 - ρ`; the
    /// Lloyd-Max levels are centroids, hence `ρ = 1 - mse()` (checked in the tests for
    /// `L = 1..=32`). The paper's definition (15)-(16) agrees with this: Table 7's values
    /// 0.6366, 0.8098, 0.8825, 0.9201, 0.9943 are `1 - MSE` for `L = 2, 3, 4, 5, 21`.
    /// (Eq. (15) as printed has `ΔP = +ρ …`; the correction is a decrease, `-ρ …`, as in (10).)
    pub fn rho(&self) -> f64 {
        (0..self.levels.len())
            .map(|i| {
                let (a, b) = self.cell(i);
                let n = pdf_drop(a, b);
                n * n / mass(a, b)
            })
            .sum()
    }

    /// Moments of cell `index` (probability, `σ` of (14), `η` of (11)).
    ///
    /// # Panics
    /// If `index >= L`.
    pub fn moments(&self, index: usize) -> CellMoments {
        let (lo, hi) = self.cell(index);
        cell_moments(lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;
    use statrs::function::erf::{erf, erfc};

    /// Independent evaluation of the truncated-normal mean: erf for the probability (erfc
    /// on the far side of the mode to keep relative accuracy) and the direct pdf
    /// difference, no expm1 tricks.
    fn reference_mean(a: f64, b: f64) -> f64 {
        let phi = |x: f64| {
            if x.is_infinite() {
                0.0
            } else {
                (-x * x / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt()
            }
        };
        let p = if a >= 0.0 {
            0.5 * (erfc(a / SQRT_2) - erfc(b / SQRT_2))
        } else if b <= 0.0 {
            0.5 * (erfc(-b / SQRT_2) - erfc(-a / SQRT_2))
        } else {
            0.5 * (erf(b / SQRT_2) - erf(a / SQRT_2))
        };
        (phi(a) - phi(b)) / p
    }

    /// Reference values computed once with mpmath at 40 digits (findroot on the midpoint
    /// condition with centroid levels, symmetric positive thresholds; rho from eq. (16)),
    /// independently of this file: (L, positive thresholds, rho). Kept at full printed
    /// precision as data (rho of L = 2 is 2 / pi).
    #[allow(clippy::excessive_precision, clippy::approx_constant)]
    const MPMATH: &[(usize, &[f64], f64)] = &[
        (2, &[], 0.636_619_772_367_581_343_075_535),
        (
            3,
            &[0.612_003_180_962_480_760_568_090],
            0.809_825_960_752_098_521_317_809,
        ),
        (
            4,
            &[0.981_598_821_567_793_705_900_327],
            0.882_518_152_170_670_712_875_813,
        ),
        (
            5,
            &[
                0.382_283_785_584_909_633_280_812,
                1.244_357_489_165_485_128_513_04,
            ],
            0.920_058_872_911_722_561_231_678,
        ),
        (
            8,
            &[
                0.500_549_730_075_049_471_506_591,
                1.049_957_279_855_438_574_996_85,
                1.747_927_491_520_993_580_260_45,
            ],
            0.965_452_239_211_496_269_723_403,
        ),
        // L = 16, 33, 65: mpmath 40 digits, Newton (findroot) on the midpoint conditions of
        // the positive thresholds from a float Lloyd start, written independently of this file.
        (
            16,
            &[
                0.25822166467071860332,
                0.52240370901137678873,
                0.79954978750971237589,
                1.0992858269170692617,
                1.4371387916845298898,
                1.8435318062766346034,
                2.4008033987632748243,
            ],
            0.99049899199180811389,
        ),
        (
            33,
            &[
                0.063989468206298217001,
                0.19231996727007421778,
                0.32171887437133144374,
                0.45294561414445010579,
                0.58683559346681104398,
                0.72434223138928918971,
                0.86659367361714413281,
                1.014974026526525003,
                1.1712462564315130177,
                1.3377487165652322865,
                1.5177294170424570797,
                1.7159585336745902837,
                1.9399641934399271288,
                2.2028830028685414428,
                2.5315381164305307068,
                2.9999866014581022336,
            ],
            0.99764086535239232616,
        ),
        (
            65,
            &[
                0.032908767109304523055,
                0.098773900080873197732,
                0.16478231308422180148,
                0.23103115153389783935,
                0.29762004444290802503,
                0.36465219126849936811,
                0.43223554794374938521,
                0.50048414923988145174,
                0.56951961224661636505,
                0.63947287641733822077,
                0.71048625036076071414,
                0.78271585593214783445,
                0.85633458850373275331,
                0.93153575206159012042,
                1.0085375843059609547,
                1.0875889684940285101,
                1.1689767484769613146,
                1.253035242537746835,
                1.3401588256829122338,
                1.4308188797199193092,
                1.525587103247322246,
                1.6251683268843822371,
                1.7304479702673178942,
                1.8425628650738347811,
                1.9630109652908370186,
                2.0938291402937800255,
                2.2378978551017329881,
                2.3995018583006626426,
                2.5854643709023086373,
                2.8077679659557927016,
                3.0909926887373537284,
                3.503250549221548411,
            ],
            0.99937514901399491029,
        ),
    ];

    #[test]
    fn thresholds_and_rho_match_high_precision_references() {
        for &(l, pos, rho) in MPMATH {
            let q = LloydMax::design(l).unwrap();
            let mut got: Vec<f64> = q.thresholds.iter().copied().filter(|&t| t > 0.0).collect();
            got.sort_by(f64::total_cmp);
            assert_eq!(got.len(), pos.len(), "L={l}");
            // rho is stationary at the optimum, so it is held to 1e-14 for every L; the
            // thresholds themselves solve a system whose conditioning grows with L (about
            // 2.5e-14 of error at L = 16 from f64 residuals of 1e-16), so they are held to
            // 1e-14 up to L = 8 and to 1e-12 beyond.
            let tol = if l <= 8 { 1e-14 } else { 1e-12 };
            for (g, r) in got.iter().zip(pos) {
                assert!((g - r).abs() < tol, "L={l}: threshold {g} vs {r}");
            }
            assert!(
                (q.rho() - rho).abs() < 1e-14,
                "L={l}: rho {} vs {rho}",
                q.rho()
            );
        }
    }

    #[test]
    fn optimality_conditions_hold_to_1e_14_up_to_65_levels() {
        for l in 2..=65 {
            let q = LloydMax::design(l).unwrap();
            for i in 0..q.thresholds.len() {
                let mid = 0.5 * (q.levels[i] + q.levels[i + 1]);
                assert!((q.thresholds[i] - mid).abs() < 1e-14, "L={l} i={i}");
            }
            for i in 0..l {
                let m = q.moments(i).mean;
                assert!(
                    (q.levels[i] - m).abs() < 1e-14 * m.abs().max(1.0),
                    "L={l} i={i}"
                );
            }
            assert!((q.rho() - (1.0 - q.mse())).abs() < 1e-14, "L={l}");
        }
    }

    #[test]
    fn zero_and_too_many_levels_are_errors() {
        assert_eq!(LloydMax::design(0), Err(LloydMaxError::NoLevels));
        assert!(matches!(
            LloydMax::design(MAX_LEVELS + 1),
            Err(LloydMaxError::TooManyLevels { .. })
        ));
    }

    #[test]
    fn one_level_is_the_mean() {
        let q = LloydMax::design(1).unwrap();
        assert!(q.thresholds.is_empty());
        assert_eq!(q.levels, vec![0.0]);
        assert!((q.mse() - 1.0).abs() < 1e-15);
        assert!(q.rho().abs() < 1e-15);
        assert_eq!(q.cell(0), (f64::NEG_INFINITY, f64::INFINITY));
        assert_eq!(q.quantize(3.0), 0);
    }

    /// Midpoint condition: rounding of the solved residual is ~1e-15; 1e-10 is the
    /// accuracy promised by the module.
    #[test]
    fn thresholds_are_midpoints_of_neighbouring_levels() {
        for l in 1..=70 {
            let q = LloydMax::design(l).unwrap();
            assert_eq!(q.thresholds.len(), l - 1);
            assert_eq!(q.levels.len(), l);
            for (i, t) in q.thresholds.iter().enumerate() {
                let mid = 0.5 * (q.levels[i] + q.levels[i + 1]);
                assert!((t - mid).abs() < 1e-10, "L={l} i={i}: {t} vs {mid}");
            }
            assert!(q.thresholds.windows(2).all(|w| w[0] < w[1]), "L={l}");
        }
    }

    /// Centroid condition against an independent erf/pdf evaluation. The reference's own
    /// rounding (erf differences, pdf differences of neighbours) is ≲ 1e-13 here, so 1e-9
    /// leaves room while still failing for any real design error.
    #[test]
    fn levels_are_conditional_means() {
        for l in 1..=70 {
            let q = LloydMax::design(l).unwrap();
            for i in 0..l {
                let (a, b) = q.cell(i);
                let m = reference_mean(a, b);
                assert!(
                    (q.levels[i] - m).abs() < 1e-9,
                    "L={l} i={i}: {} vs {m}",
                    q.levels[i]
                );
            }
        }
    }

    #[test]
    fn quantizer_is_exactly_symmetric() {
        for l in 1..=40 {
            let q = LloydMax::design(l).unwrap();
            for i in 0..l {
                assert_eq!(q.levels[i], -q.levels[l - 1 - i]);
            }
            for i in 0..l - 1 {
                assert_eq!(q.thresholds[i], -q.thresholds[l - 2 - i]);
            }
        }
    }

    /// Published values (Max 1960, Table I; also Jayant & Noll Table 4.3) are given to 4
    /// significant digits, so they are compared to half a unit in the last printed digit.
    #[test]
    fn known_values() {
        let q2 = LloydMax::design(2).unwrap();
        let a = (2.0 / std::f64::consts::PI).sqrt();
        assert_eq!(q2.thresholds, vec![0.0]);
        assert!((q2.levels[1] - a).abs() < 1e-14 && (q2.levels[0] + a).abs() < 1e-14);
        assert!((q2.mse() - (1.0 - 2.0 / std::f64::consts::PI)).abs() < 1e-14);
        assert!((q2.mse() - 0.3634).abs() < 5e-5);

        let q3 = LloydMax::design(3).unwrap();
        assert!((q3.thresholds[1] - 0.6120).abs() < 5e-5);
        assert!((q3.levels[2] - 1.224).abs() < 5e-4);
        assert!((q3.mse() - 0.1902).abs() < 5e-5);

        let q4 = LloydMax::design(4).unwrap();
        assert_eq!(q4.thresholds[1], 0.0);
        assert!((q4.thresholds[2] - 0.9816).abs() < 5e-5);
        assert!((q4.thresholds[0] + 0.9816).abs() < 5e-5);
        assert!((q4.levels[2] - 0.4528).abs() < 5e-5);
        assert!((q4.levels[3] - 1.510).abs() < 5e-4);
        assert!((q4.mse() - 0.1175).abs() < 5e-5);

        let q5 = LloydMax::design(5).unwrap();
        assert!((q5.thresholds[2] - 0.3823).abs() < 5e-5);
        assert!((q5.thresholds[3] - 1.244).abs() < 5e-4);
        assert!((q5.levels[3] - 0.7646).abs() < 5e-5);
        assert!((q5.levels[4] - 1.724).abs() < 5e-4);
        assert!((q5.mse() - 0.07994).abs() < 5e-6);

        // Max's table truncates rather than rounds this one (exact 0.0345478), so allow a
        // full unit of the last printed digit.
        let q8 = LloydMax::design(8).unwrap();
        assert!((q8.mse() - 0.03454).abs() < 1e-5);
        assert!((q8.thresholds[6] - 1.748).abs() < 5e-4);
        assert!((q8.levels[7] - 2.152).abs() < 5e-4);
    }

    /// `ρ` of eq. (16) is computed from the thresholds only, `mse()` from the levels; they
    /// agree only if the levels are centroids. Both are sums of `L` terms of size ≤ 1, so
    /// 1e-12 is far above rounding.
    #[test]
    fn rho_is_one_minus_mse() {
        for l in 1..=32 {
            let q = LloydMax::design(l).unwrap();
            assert!((q.rho() - (1.0 - q.mse())).abs() < 1e-12, "L={l}");
        }
    }

    /// Table 7 of the paper: `ρ` for L = 2, 3, 4, 5, 21, printed to 4 decimals.
    #[test]
    #[allow(clippy::approx_constant)] // 0.6366 is the paper's printed ρ, not a stand-in for 2/π
    fn rho_matches_paper_table_7() {
        for (l, printed) in [
            (2, 0.6366),
            (3, 0.8098),
            (4, 0.8825),
            (5, 0.9201),
            (21, 0.9943),
        ] {
            let rho = LloydMax::design(l).unwrap().rho();
            assert!((rho - printed).abs() <= 5e-5, "L={l}: {rho} vs {printed}");
        }
    }

    /// Large L: still converges, optimal, and the MSE approaches the Panter-Dite
    /// asymptote `(√3 π / 2) / L²` (relative gap ≈ 1% at L ≈ 100, shrinking with L).
    #[test]
    fn large_designs_converge_and_follow_panter_dite() {
        for l in [127, 128, 256, MAX_LEVELS] {
            let q = LloydMax::design(l).unwrap();
            for (i, t) in q.thresholds.iter().enumerate() {
                let mid = 0.5 * (q.levels[i] + q.levels[i + 1]);
                assert!((t - mid).abs() < 1e-10, "L={l} i={i}");
            }
            let pd = 3f64.sqrt() * std::f64::consts::PI / 2.0 / (l as f64 * l as f64);
            let rel = (q.mse() - pd).abs() / pd;
            assert!(rel < 0.03, "L={l}: mse {} vs Panter-Dite {pd}", q.mse());
            assert!((q.rho() - (1.0 - q.mse())).abs() < 1e-12);
        }
    }

    #[test]
    fn quantize_lands_in_its_cell() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x4c4d_0001);
        for l in [1, 2, 3, 4, 5, 8, 13, 21, 29, 69] {
            let q = LloydMax::design(l).unwrap();
            for _ in 0..20_000 {
                let x: f64 = rng.random_range(-6.0..6.0);
                let i = q.quantize(x);
                let (lo, hi) = q.cell(i);
                assert!(lo < x && x <= hi, "L={l} x={x} cell {i} = ({lo}, {hi}]");
            }
            // Thresholds themselves belong to the lower cell (right-closed cells).
            for (k, &t) in q.thresholds.iter().enumerate() {
                assert_eq!(q.quantize(t), k);
            }
            assert_eq!(q.quantize(f64::INFINITY), l - 1);
            assert_eq!(q.quantize(f64::NAN), q.quantize(0.0));
        }
    }

    #[test]
    fn cell_moments_are_consistent() {
        let q = LloydMax::design(9).unwrap();
        let total: f64 = (0..9).map(|i| q.probability(i)).sum();
        assert!((total - 1.0).abs() < 1e-14);
        // Expected η over cells is ρ (the τφ(τ) terms telescope).
        let e_eta: f64 = (0..9)
            .map(|i| {
                let m = q.moments(i);
                m.probability * m.eta
            })
            .sum();
        assert!((e_eta - q.rho()).abs() < 1e-13);
        for i in 0..9 {
            let m = q.moments(i);
            assert!((m.mean - q.levels[i]).abs() < 1e-12);
            assert!(m.eta > 0.0 && m.eta < 1.0);
        }
        // Whole line: mean 0, variance 1, so η = 0.
        let all = cell_moments(f64::NEG_INFINITY, f64::INFINITY);
        assert_eq!(all.probability, 1.0);
        assert!(all.mean.abs() < 1e-15 && all.eta.abs() < 1e-15);
    }
}
