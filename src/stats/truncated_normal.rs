//! Truncated and censored normal moments for the Tobit Kalman filter (Geng, Wang,
//! Alsaadi, Alharbi and Cheng: Lemma 1, eq. (12)-(17), and the censoring probabilities (9)).
//!
//! Everything is in the standardized variable: a latent reading `ybar ~ N(zeta, R)` is censored
//! to `[tau_l, tau_r]` (eq. (6)); with `theta = (tau - zeta) / sqrt(R)` (eq. (12)-(17) need
//! sqrt(R); the paper prints R in the definitions of theta, a typo listed in DESIGN.md) the
//! standard normal `X` is truncated to `(theta_l, theta_r)`.
//!
//! Why a module: the inverse Mills ratios `phi(theta) / (Phi(theta_r) - Phi(theta_l))` of (14)
//! and (15) are 0/0 in naive arithmetic as soon as the band lies beyond |theta| ~ 38 (both
//! densities and the mass underflow), and the variance (15) cancels catastrophically long
//! before that. Here the mass is taken in the log domain ([`crate::stats::normal::log_q_band`]),
//! each ratio is `exp(log phi - log mass)`, and in a far one-sided tail the mean excess and the
//! variance come from the continued fraction of the Mills ratio, which has no cancellation.
//! Finite and accurate (tests: relative 1e-9 against numerical integration) for |theta| up to
//! 40 and beyond.
use super::normal::{log_cdf, log_pdf, log_q, log_q_band};

/// Beyond this a one-sided tail uses the continued fraction (no cancellation in the variance).
const CF_FROM: f64 = 5.0;
/// Depth of the backward continued-fraction evaluation (converged to ~1e-16 for x >= 5).
const CF_DEPTH: usize = 120;
/// When `log P(far edge) - log P(near edge)` is below this, the far edge of a band is ignored
/// (it changes the moments by less than e^-40 relative).
const FAR_EDGE: f64 = -40.0;

/// The censoring probabilities of eq. (9) for standardized thresholds `theta_l < theta_r`:
/// `alpha = Phi(theta_l)` (left-censored), `beta = 1 - Phi(theta_r)` (right-censored) and
/// `pi = 1 - alpha - beta` (uncensored), each also as an accurate logarithm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CensoringProbabilities {
    pub alpha: f64,
    pub beta: f64,
    pub pi: f64,
    pub log_alpha: f64,
    pub log_beta: f64,
    pub log_pi: f64,
}

/// Eq. (9): `alpha = Phi(theta_l)`, `beta = Phi(-theta_r)`, `pi = Phi(theta_r) - Phi(theta_l)`.
/// `theta_l` may be `-inf` and `theta_r` `+inf` (no censoring on that side).
pub fn censoring_probabilities(theta_l: f64, theta_r: f64) -> CensoringProbabilities {
    let log_alpha = if theta_l == f64::NEG_INFINITY {
        f64::NEG_INFINITY
    } else {
        log_cdf(theta_l)
    };
    let log_beta = if theta_r == f64::INFINITY {
        f64::NEG_INFINITY
    } else {
        log_q(theta_r)
    };
    let log_pi = log_mass(theta_l, theta_r);
    CensoringProbabilities {
        alpha: log_alpha.exp(),
        beta: log_beta.exp(),
        pi: log_pi.exp(),
        log_alpha,
        log_beta,
        log_pi,
    }
}

/// `log P(a < X < b)` for a standard normal, `-inf <= a < b <= inf`.
pub fn log_mass(a: f64, b: f64) -> f64 {
    match (a == f64::NEG_INFINITY, b == f64::INFINITY) {
        (true, true) => 0.0,
        (true, false) => log_cdf(b),
        (false, true) => log_q(a),
        (false, false) => log_q_band(a, b),
    }
}

/// Moments of the standard normal truncated to `(a, b)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruncatedMoments {
    /// `log P(a < X < b)`.
    pub log_mass: f64,
    /// `E[X | a < X < b] = (phi(a) - phi(b)) / P = -lambda(b, a)` of eq. (14).
    pub mean: f64,
    /// `var[X | a < X < b] = 1 + varphi(b, a)` of eq. (15), in [0, 1].
    pub var: f64,
}

impl TruncatedMoments {
    /// Eq. (14): `lambda(theta_r, theta_l) = (phi(theta_r) - phi(theta_l)) / (Phi(theta_r) -
    /// Phi(theta_l))`, so that the truncated mean is `zeta - sqrt(R) lambda` (eq. (12), (32)).
    pub fn lambda(&self) -> f64 {
        -self.mean
    }
    /// Eq. (15): `varphi = var - 1` (the uncensored part's variance is `R (1 + varphi)`, (13)).
    pub fn varphi(&self) -> f64 {
        self.var - 1.0
    }
}

/// `phi(x) / P` as `exp(log phi(x) - log P)`: finite wherever the result is (no 0/0).
#[inline]
fn ratio(x: f64, log_p: f64) -> f64 {
    if x.is_infinite() {
        0.0
    } else {
        (log_pdf(x) - log_p).exp()
    }
}

/// For `x >= CF_FROM`: `(delta, var)` of the standard normal truncated to `(x, inf)`, with
/// `lambda = phi(x)/Q(x) = x + delta` (the inverse Mills ratio) and `var = 1 - lambda delta`.
/// From the continued fraction `Q(x)/phi(x) = 1/(x + 1/(x + 2/(x + 3/(x + ...))))`:
/// `delta = 1/(x + eps)`, `eps = 2/(x + 3/(x + ...))`, and `var = (eps - delta)/(x + eps)`,
/// both free of cancellation.
fn upper_tail_cf(x: f64) -> (f64, f64) {
    let mut t = 0.0;
    for n in (2..=CF_DEPTH).rev() {
        t = n as f64 / (x + t);
    }
    let eps = t;
    let delta = 1.0 / (x + eps);
    (delta, (eps - delta) / (x + eps))
}

/// Moments of the standard normal truncated to `(a, b)` (Lemma 1's `lambda`, `varphi`; eq.
/// (14)-(15) with `a = theta_l`, `b = theta_r`). `a = -inf` and/or `b = +inf` are allowed.
///
/// Callers pass `a < b`; a band that rounding collapsed (`a == b` when the thresholds are tiny
/// next to the mean, e.g. a state of 1e18) is treated as its edge: mean `a`, variance 0, mass
/// 0. NaN gives NaN moments, which the filter's covariance checks then refuse.
pub fn truncated_standard(a: f64, b: f64) -> TruncatedMoments {
    if a.is_nan() || b.is_nan() || a >= b {
        return TruncatedMoments {
            log_mass: f64::NEG_INFINITY,
            mean: if a.is_nan() || b.is_nan() {
                f64::NAN
            } else {
                a
            },
            var: 0.0,
        };
    }
    let log_p = log_mass(a, b);
    // A far edge that carries no mass relative to the near one is dropped, so that a band deep
    // in a tail is treated by the cancellation-free one-sided formulas.
    let upper_only =
        b == f64::INFINITY || (a >= CF_FROM && (log_q(b) - log_q(a)) < FAR_EDGE && b.is_finite());
    let lower_only = a == f64::NEG_INFINITY
        || (b <= -CF_FROM && (log_cdf(a) - log_cdf(b)) < FAR_EDGE && a.is_finite());
    if upper_only && a >= CF_FROM {
        let (delta, var) = upper_tail_cf(a);
        return TruncatedMoments {
            log_mass: log_p,
            mean: a + delta,
            var,
        };
    }
    if lower_only && b <= -CF_FROM {
        let (delta, var) = upper_tail_cf(-b);
        return TruncatedMoments {
            log_mass: log_p,
            mean: b - delta,
            var,
        };
    }
    let ra = ratio(a, log_p);
    let rb = ratio(b, log_p);
    let mean = ra - rb;
    // var = 1 + (a - mean) phi(a)/P - (b - mean) phi(b)/P  (= 1 + varphi of (15)).
    let ta = if a.is_finite() { (a - mean) * ra } else { 0.0 };
    let tb = if b.is_finite() { (b - mean) * rb } else { 0.0 };
    let var = (1.0 + ta - tb).clamp(0.0, 1.0);
    TruncatedMoments {
        log_mass: log_p,
        mean,
        var,
    }
}

/// Lemma 1 for one reading: latent `ybar ~ N(zeta, r)` censored to `[tau_l, tau_r]` (eq. (6)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CensoredMoments {
    pub probabilities: CensoringProbabilities,
    /// The truncated part: `E[ybar | tau_l < ybar < tau_r] = zeta - sqrt(r) lambda` (32).
    pub truncated_mean: f64,
    /// Eq. (13) as printed: `r (1 + varphi)`, the variance of the *uncensored part* (37): what
    /// the Tobit Kalman filter uses. (The variance of the censored reading itself adds the
    /// between-parts spread; see [`CensoredMoments::total_variance`].)
    pub truncated_variance: f64,
    /// Eq. (12): `E[y] = alpha tau_l + beta tau_r + pi (zeta - sqrt(r) lambda)`.
    pub mean: f64,
    tau_l: f64,
    tau_r: f64,
}

impl CensoredMoments {
    /// `var[y]` of the censored reading (law of total variance over the three parts); for
    /// the tests and for comparison with (13).
    pub fn total_variance(&self) -> f64 {
        let p = &self.probabilities;
        let mut ey2 = p.pi * (self.truncated_variance + self.truncated_mean.powi(2));
        if p.alpha > 0.0 {
            ey2 += p.alpha * self.tau_l * self.tau_l;
        }
        if p.beta > 0.0 {
            ey2 += p.beta * self.tau_r * self.tau_r;
        }
        (ey2 - self.mean * self.mean).max(0.0)
    }
}

/// Lemma 1, eq. (12)-(13), for `ybar ~ N(zeta, r)` censored to `[tau_l, tau_r]`
/// (`tau_l < tau_r`, either may be infinite; `r > 0`).
pub fn censored_moments(zeta: f64, r: f64, tau_l: f64, tau_r: f64) -> CensoredMoments {
    let sd = r.sqrt();
    let (a, b) = ((tau_l - zeta) / sd, (tau_r - zeta) / sd);
    let probabilities = censoring_probabilities(a, b);
    let t = truncated_standard(a, b);
    let truncated_mean = zeta + sd * t.mean;
    let p = &probabilities;
    let mut mean = p.pi * truncated_mean;
    if p.alpha > 0.0 {
        mean += p.alpha * tau_l;
    }
    if p.beta > 0.0 {
        mean += p.beta * tau_r;
    }
    CensoredMoments {
        probabilities,
        truncated_mean,
        truncated_variance: r * t.var,
        mean,
        tau_l,
        tau_r,
    }
}

/// Variance of a standard normal truncated to [-δ, δ]: v(δ) = 1 - 2 δ φ(δ) / (1 - 2 Q(δ))
/// (Wu et al. 2013, the factor of Theorem 2). v(0) = 0, v(∞) = 1. A series below δ = 1e-3,
/// where the closed form cancels: v = δ²/3 (1 - 2δ²/15) + O(δ⁶).
pub fn band_variance(delta: f64) -> f64 {
    if delta < 1e-3 {
        let d2 = delta * delta;
        return d2 / 3.0 * (1.0 - 2.0 * d2 / 15.0);
    }
    let mass = 1.0 - 2.0 * super::normal::q(delta);
    (1.0 - 2.0 * delta * super::normal::pdf(delta) / mass).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::normal::cdf;

    /// `(log mass, mean, var)` of N(0,1) on (a, b) by composite Simpson on the density scaled
    /// by its largest value on the band, so that far tails do not underflow.
    fn integrate(a: f64, b: f64) -> (f64, f64, f64) {
        let x0: f64 = if a > 0.0 {
            a
        } else if b < 0.0 {
            b
        } else {
            0.0
        };
        // Finite range: the density falls below e^-60 of its peak beyond x0 +- w.
        let w = if x0.abs() > 1.0 {
            (60.0 / x0.abs() + 1.5).min(40.0)
        } else {
            40.0
        };
        let lo = a.max(x0 - w);
        let hi = b.min(x0 + w);
        let n = 400_000;
        let h = (hi - lo) / n as f64;
        let f = |x: f64| (-0.5 * (x * x - x0 * x0)).exp();
        let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
        for i in 0..=n {
            let x = lo + i as f64 * h;
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let fx = w * f(x);
            s0 += fx;
            s1 += fx * (x - x0);
            s2 += fx * (x - x0) * (x - x0);
        }
        let mass = s0 * h / 3.0;
        let m1 = s1 / s0;
        let var = s2 / s0 - m1 * m1;
        let log_mass = mass.ln() - 0.5 * x0 * x0 - 0.918_938_533_204_672_8;
        (log_mass, x0 + m1, var)
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(1e-300)
    }

    #[test]
    fn moments_match_numerical_integration_in_both_tails() {
        let inf = f64::INFINITY;
        let bands = [
            (-1.0, 1.0),
            (-0.3, 2.5),
            (0.5, 0.9),
            (3.0, inf),
            (-inf, -3.0),
            (-inf, 0.7),
            (5.0, inf),
            (5.5, 7.0),
            (12.0, inf),
            (25.0, inf),
            (40.0, inf),
            (-inf, -40.0),
            (-41.0, -38.0),
            (30.0, 30.5),
            (-30.5, -30.0),
            (38.0, 39.0),
            (-inf, 39.0),
            (-39.0, inf),
        ];
        for (a, b) in bands {
            let t = truncated_standard(a, b);
            let (lm, mean, var) = integrate(a, b);
            assert!(t.mean.is_finite() && t.var.is_finite() && t.log_mass.is_finite());
            assert!(
                (t.log_mass - lm).abs() < 1e-8 * lm.abs().max(1.0),
                "({a}, {b}): log mass {} vs {lm}",
                t.log_mass
            );
            assert!(
                (t.mean - mean).abs() < 1e-8 * mean.abs().max(1.0),
                "({a}, {b}): mean {} vs {mean}",
                t.mean
            );
            assert!(rel(t.var, var) < 2e-6, "({a}, {b}): var {} vs {var}", t.var);
        }
    }

    #[test]
    fn continued_fraction_agrees_with_the_direct_formula_where_both_are_good() {
        for x in [5.0, 5.5, 6.5, 8.0] {
            let (delta, var) = upper_tail_cf(x);
            let lp = log_q(x);
            let r = ratio(x, lp);
            let direct_var = 1.0 + (x - r) * r;
            assert!(rel(x + delta, r) < 1e-13, "{x}: {} vs {r}", x + delta);
            assert!(rel(var, direct_var) < 1e-9, "{x}: {var} vs {direct_var}");
        }
        // Asymptotics: lambda ~ x + 1/x, var ~ 1/x^2.
        let (d, v) = upper_tail_cf(1e6);
        assert!(rel(d, 1e-6) < 1e-9 && rel(v, 1e-12) < 1e-9);
    }

    #[test]
    fn no_censoring_gives_the_gaussian_moments() {
        let m = censored_moments(1.3, 0.6, f64::NEG_INFINITY, f64::INFINITY);
        assert_eq!(m.probabilities.alpha, 0.0);
        assert_eq!(m.probabilities.beta, 0.0);
        assert_eq!(m.probabilities.pi, 1.0);
        assert!((m.mean - 1.3).abs() < 1e-15);
        assert!((m.truncated_variance - 0.6).abs() < 1e-15);
        assert!((m.total_variance() - 0.6).abs() < 1e-15);
        // Thresholds far outside the signal: the same to double precision.
        let m = censored_moments(1.3, 0.6, -1e3, 1e3);
        assert!((m.mean - 1.3).abs() < 1e-14 && (m.truncated_variance - 0.6).abs() < 1e-14);
    }

    #[test]
    fn fully_censored_gives_the_threshold_and_zero_variance() {
        // The latent mean 50 standard deviations above tau_r: y = tau_r surely.
        let m = censored_moments(55.0, 0.01, -5.0, 5.0);
        assert!((m.probabilities.beta - 1.0).abs() < 1e-15);
        assert!((m.mean - 5.0).abs() < 1e-12, "{}", m.mean);
        assert!(m.total_variance() < 1e-12);
        assert!(m.truncated_mean.is_finite() && m.truncated_variance.is_finite());
        // ... and below tau_l.
        let m = censored_moments(-60.0, 1.0, -5.0, 5.0);
        assert!((m.mean + 5.0).abs() < 1e-12 && m.total_variance() < 1e-12);
        assert!(m.probabilities.log_pi < -800.0 && m.probabilities.log_pi.is_finite());
    }

    #[test]
    fn lemma1_mean_matches_integration_of_the_censored_reading() {
        // E[y] by integrating clamp(ybar) against N(zeta, r).
        for (zeta, r, tl, tr) in [
            (0.3, 0.6, -1.0, 1.0),
            (4.8, 0.6, -5.0, 5.0),
            (-2.0, 2.0, -1.5, 0.5),
        ] {
            let m = censored_moments(zeta, r, tl, tr);
            let sd: f64 = r.sqrt();
            let n = 200_000;
            let (lo, hi) = (zeta - 12.0 * sd, zeta + 12.0 * sd);
            let h = (hi - lo) / n as f64;
            let (mut e1, mut e2) = (0.0, 0.0);
            for i in 0..n {
                let x = lo + (i as f64 + 0.5) * h;
                let w = (-(x - zeta).powi(2) / (2.0 * r)).exp()
                    / (2.0 * std::f64::consts::PI * r).sqrt()
                    * h;
                let y = x.clamp(tl, tr);
                e1 += w * y;
                e2 += w * y * y;
            }
            assert!((m.mean - e1).abs() < 1e-7, "{zeta}: {} vs {e1}", m.mean);
            assert!((m.total_variance() - (e2 - e1 * e1)).abs() < 1e-7);
            assert!(m.truncated_variance <= r);
        }
    }

    #[test]
    fn lambda_and_varphi_are_the_printed_quantities() {
        // (14) and (15) evaluated naively where that is safe.
        let (a, b) = (-0.7, 1.9);
        let t = truncated_standard(a, b);
        let pdf = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let z = cdf(b) - cdf(a);
        let lambda = (pdf(b) - pdf(a)) / z;
        let varphi = (a * pdf(a) - b * pdf(b)) / z - lambda * lambda;
        assert!((t.lambda() - lambda).abs() < 1e-14);
        assert!((t.varphi() - varphi).abs() < 1e-14);
    }
}
