//! Chi-square distribution: CDF, survival function and the upper quantile that sets the
//! censoring threshold.
//!
//! Why: a censoring sensor of Zheng et al. (2014) sends only when its normalized innovation squared
//! `nu^T S^{-1} nu`, which is chi-square with `n_nu` degrees of freedom when the sensor's
//! model is right, reaches a threshold `eta`. To have on average `l` of `N` sensors send,
//! `P(chi^2_{n_nu} >= eta) = l / N`, i.e. `eta = chi^2_{n_nu}(l/N)`, the value *exceeded*
//! with probability `l/N` (eq. (8) for scalar, (32) for vector, (43) for nonlinear
//! measurements). [`upper_quantile`] computes exactly that.
//!
//! Degrees of freedom 1 and 2 (the paper's scalar and planar cases) use closed forms through
//! the normal tail and the exponential; other degrees of freedom use the regularized
//! incomplete gamma function (series below `x/2 < dof/2 + 1`, Lentz continued fraction
//! above), evaluated in log space so that tails far below 1e-300 stay representable.

use super::normal;
use statrs::function::gamma::ln_gamma;
use std::fmt;

/// Errors of the `stats` functions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StatsError {
    /// A probability outside the range the function accepts.
    InvalidProbability(f64),
    /// Degrees of freedom not finite and positive.
    InvalidDof(f64),
    /// A scalar argument that is NaN or otherwise unusable; the text names it.
    InvalidArgument(&'static str),
    /// Vector and matrix dimensions that do not fit together.
    DimensionMismatch {
        /// The dimension required.
        expected: usize,
        /// The dimension given.
        found: usize,
    },
    /// A covariance that is not symmetric positive semidefinite (within rounding).
    NotPositiveSemidefinite {
        /// Its most negative eigenvalue.
        min_eigenvalue: f64,
    },
    /// An iterative method would need more work than its budget allows.
    NoConvergence(&'static str),
}

impl fmt::Display for StatsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StatsError::InvalidProbability(p) => write!(f, "probability {p} out of range"),
            StatsError::InvalidDof(d) => {
                write!(f, "degrees of freedom {d} must be finite and positive")
            }
            StatsError::InvalidArgument(what) => write!(f, "invalid argument: {what}"),
            StatsError::DimensionMismatch { expected, found } => {
                write!(f, "dimension mismatch: expected {expected}, found {found}")
            }
            StatsError::NotPositiveSemidefinite { min_eigenvalue } => write!(
                f,
                "matrix is not positive semidefinite (eigenvalue {min_eigenvalue})"
            ),
            StatsError::NoConvergence(what) => write!(f, "no convergence: {what}"),
        }
    }
}

impl std::error::Error for StatsError {}

/// Relative tolerance of the incomplete-gamma series and continued fraction.
const GAMMA_EPS: f64 = 1e-16;
/// Iteration cap of the series and continued fraction (never reached for `a` below ~1e8).
const GAMMA_MAX_ITER: usize = 100_000;

/// `(log P(a, t), log Q(a, t))`, the logs of the regularized lower and upper incomplete
/// gamma functions, for `a > 0`, `t >= 0`.
///
/// Whichever of `P`, `Q` is smaller is computed directly (series for `t < a + 1`, modified
/// Lentz continued fraction otherwise) and the other as `log1p(-exp(.))`, so both keep full
/// relative accuracy. The prefactor `a log t - t - log Gamma(a)` cancels for large `a`,
/// which costs about `a log a * 1e-16` relative accuracy (2e-14 at `a = 50`).
pub(crate) fn ln_reg_gamma(a: f64, t: f64) -> (f64, f64) {
    if t <= 0.0 {
        return (f64::NEG_INFINITY, 0.0);
    }
    if t == f64::INFINITY {
        return (0.0, f64::NEG_INFINITY);
    }
    let ln_pref = a * t.ln() - t - ln_gamma(a);
    if t < a + 1.0 {
        // P = t^a e^-t / Gamma(a+1) * sum_{n>=0} t^n / ((a+1)...(a+n))
        let mut term = 1.0;
        let mut sum = 1.0;
        let mut ap = a;
        for _ in 0..GAMMA_MAX_ITER {
            ap += 1.0;
            term *= t / ap;
            sum += term;
            if term <= sum * GAMMA_EPS {
                break;
            }
        }
        let ln_p = ln_pref - a.ln() + sum.ln();
        (ln_p, (-ln_p.exp()).ln_1p())
    } else {
        // Q = t^a e^-t / Gamma(a) * 1/(t+1-a- 1(1-a)/(t+3-a- 2(2-a)/(t+5-a- ...)))
        const TINY: f64 = 1e-300;
        let mut b = t + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..GAMMA_MAX_ITER {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < TINY {
                d = TINY;
            }
            c = b + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() <= GAMMA_EPS {
                break;
            }
        }
        let ln_q = ln_pref + h.ln();
        ((-ln_q.exp()).ln_1p(), ln_q)
    }
}

fn check_dof(dof: f64) -> Result<(), StatsError> {
    if dof.is_finite() && dof > 0.0 {
        Ok(())
    } else {
        Err(StatsError::InvalidDof(dof))
    }
}

/// `(log CDF, log SF)` of chi-square(`dof`) at `x`, without argument checks.
fn ln_cdf_sf(dof: f64, x: f64) -> (f64, f64) {
    if x <= 0.0 {
        return (f64::NEG_INFINITY, 0.0);
    }
    if dof == 1.0 {
        // chi^2_1 = Z^2: CDF = P(|Z| < sqrt x), SF = 2 Q(sqrt x).
        let s = x.sqrt();
        (
            normal::log_q_band(-s, s),
            std::f64::consts::LN_2 + normal::log_q(s),
        )
    } else if dof == 2.0 {
        // chi^2_2 is exponential with mean 2.
        let h = -0.5 * x;
        ((-h.exp_m1()).ln(), h)
    } else {
        ln_reg_gamma(0.5 * dof, 0.5 * x)
    }
}

/// CDF `P(chi^2_dof <= x)`. `x <= 0` gives 0.
///
/// # Errors
/// [`StatsError::InvalidDof`] unless `dof` is finite and positive;
/// [`StatsError::InvalidArgument`] if `x` is NaN.
pub fn cdf(dof: f64, x: f64) -> Result<f64, StatsError> {
    check_dof(dof)?;
    if x.is_nan() {
        return Err(StatsError::InvalidArgument("x is NaN"));
    }
    Ok(ln_cdf_sf(dof, x).0.exp())
}

/// Survival function `P(chi^2_dof > x)`: the probability that a sensor whose innovation is
/// exactly as its filter predicts transmits at threshold `x` (Zheng et al. (2014), eq. (7)).
///
/// # Errors
/// As [`cdf`].
pub fn sf(dof: f64, x: f64) -> Result<f64, StatsError> {
    check_dof(dof)?;
    if x.is_nan() {
        return Err(StatsError::InvalidArgument("x is NaN"));
    }
    Ok(ln_cdf_sf(dof, x).1.exp())
}

/// `log P(chi^2_dof > x)`, finite far beyond the underflow of [`sf`].
///
/// # Errors
/// As [`cdf`].
pub fn ln_sf(dof: f64, x: f64) -> Result<f64, StatsError> {
    check_dof(dof)?;
    if x.is_nan() {
        return Err(StatsError::InvalidArgument("x is NaN"));
    }
    Ok(ln_cdf_sf(dof, x).1)
}

/// The censoring threshold `eta = chi^2_dof(p)`: the value with `P(chi^2_dof > eta) = p`
/// (Zheng et al. (2014), eqs. (8), (32), (43), with `p = l/N` the target fraction of sensors that
/// transmit). `p = 1` gives `eta = 0` (everyone sends).
///
/// * `dof = 1`: `eta = z^2` with `z = -Phi^{-1}(p/2)` (relative error ~1e-15);
/// * `dof = 2`: `eta = -2 log p` (exact up to rounding);
/// * otherwise: safeguarded Newton iteration on `log SF(x) = log p` (or on
///   `log CDF(x) = log(1 - p)` when `p > 1/2`, where `1 - p` is exact), started from the
///   Wilson-Hilferty approximation and kept inside a shrinking bracket; it stops when the
///   step is below 1e-15 relative, so the result is as accurate as the CDF itself
///   (~1e-14 for dof up to ~50).
///
/// # Errors
/// [`StatsError::InvalidDof`] unless `dof` is finite and positive;
/// [`StatsError::InvalidProbability`] unless `0 < p <= 1`;
/// [`StatsError::NoConvergence`] if the safeguarded iteration fails (not observed).
pub fn upper_quantile(dof: f64, p: f64) -> Result<f64, StatsError> {
    check_dof(dof)?;
    if !(p > 0.0 && p <= 1.0) {
        return Err(StatsError::InvalidProbability(p));
    }
    if p == 1.0 {
        return Ok(0.0);
    }
    if dof == 1.0 {
        let z = normal::inv_cdf(0.5 * p);
        return Ok(z * z);
    }
    if dof == 2.0 {
        return Ok(-2.0 * p.ln());
    }
    general_upper_quantile(dof, p)
}

/// Safeguarded Newton for `P(chi^2_dof > x) = p` through the incomplete gamma function.
fn general_upper_quantile(dof: f64, p: f64) -> Result<f64, StatsError> {
    let a = 0.5 * dof;
    let ln_gamma_a = ln_gamma(a);
    // Solve in t = x/2. Match the smaller tail: for p <= 1/2 the upper one, log Q(a,t) = log p;
    // otherwise the lower one, log P(a,t) = log(1 - p). Both residuals are decreasing in t
    // after the sign flip below.
    let upper = p <= 0.5;
    let target = if upper { p.ln() } else { (1.0 - p).ln() };
    let residual = |t: f64| -> (f64, f64) {
        let (ln_p, ln_q) = ln_reg_gamma(a, t);
        // d/dt log Q = -dens/Q, d/dt log P = dens/P with dens = t^(a-1) e^-t / Gamma(a).
        let ln_dens = (a - 1.0) * t.ln() - t - ln_gamma_a;
        if upper {
            (ln_q - target, -(ln_dens - ln_q).exp())
        } else {
            (target - ln_p, -(ln_dens - ln_p).exp())
        }
    };

    // Wilson-Hilferty start, or the small-t form P(a,t) ~ t^a / Gamma(a+1) if it fails.
    let z = -normal::inv_cdf(p);
    let k = 2.0 / (9.0 * dof);
    let wh = 1.0 - k + z * k.sqrt();
    let mut t = if wh > 0.0 {
        0.5 * dof * wh * wh * wh
    } else {
        0.0
    };
    if !(t > 0.0 && t.is_finite()) {
        t = (((1.0 - p).ln() + ln_gamma(a + 1.0)) / a).exp();
    }
    let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
    for _ in 0..200 {
        let (f, df) = residual(t);
        if f == 0.0 {
            return Ok(2.0 * t);
        }
        // f is decreasing in t: f > 0 means t is too small.
        if f > 0.0 {
            lo = lo.max(t);
        } else {
            hi = hi.min(t);
        }
        let mut next = t - f / df;
        if !(next > lo && next < hi && next.is_finite()) {
            next = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * t.max(lo)
            };
        }
        if (next - t).abs() <= 1e-15 * t || (hi.is_finite() && hi - lo <= 1e-15 * hi) {
            return Ok(2.0 * next);
        }
        t = next;
    }
    Err(StatsError::NoConvergence("chi-square quantile iteration"))
}

#[cfg(test)]
mod tests {
    // Reference values are quoted with all the digits the high-precision source gave.
    #![allow(clippy::excessive_precision)]
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    #[test]
    fn upper_quantile_matches_tables() {
        // References: 50-digit mpmath root of the regularized incomplete gamma. Tolerance
        // 1e-14 relative: the closed forms (dof 1, 2) are ~1e-15 and Newton converges to the
        // accuracy of the CDF, ~1e-15 for these small dof.
        let cases = [
            (1.0, 0.5, 0.454_936_423_119_572_75),
            (2.0, 0.05, 5.991_464_547_107_982),
            (1.0, 0.05, 3.841_458_820_694_125_8),
            (3.0, 0.05, 7.814_727_903_251_18),
            (4.0, 0.05, 9.487_729_036_781_157),
            (5.0, 0.01, 15.086_272_469_388_99),
            (6.0, 0.001, 22.457_744_484_825_325),
            (6.0, 0.01, 16.811_893_829_770_93),
            (3.0, 0.9, 0.584_374_374_155_183_2),
            (2.5, 0.2, 3.942_681_708_688_069),
            (10.0, 1e-10, 68.167_618_138_617_92),
            (1.0, 1e-12, 50.844_127_911_818_156),
            (4.0, 0.999, 0.090_804_035_538_979_15),
            (3.0, 1e-100, 466.214_357_571_291_35),
        ];
        for (dof, p, want) in cases {
            let got = upper_quantile(dof, p).unwrap();
            assert!(
                rel(got, want) < 1e-14,
                "chi2_{dof}({p}) = {got} want {want}"
            );
        }
        assert_eq!(upper_quantile(3.0, 1.0).unwrap(), 0.0);
        assert_eq!(upper_quantile(1.0, 1.0).unwrap(), 0.0);
    }

    #[test]
    fn upper_quantile_round_trips_through_sf() {
        // sf(upper_quantile(p)) = p. Tolerance 1e-12 relative: the slope of log SF is at
        // most ~x/2 ~ 60 here, times the quantile's ~1e-14 relative error.
        for dof in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 1.5, 7.3, 20.0] {
            for p in [
                1e-30,
                1e-8,
                0.001,
                0.05,
                0.1,
                1.0 / 3.0,
                0.5,
                0.8,
                0.99,
                0.999_999,
            ] {
                let eta = upper_quantile(dof, p).unwrap();
                let back = sf(dof, eta).unwrap();
                assert!(rel(back, p) < 1e-12, "dof {dof} p {p}: eta {eta} sf {back}");
            }
        }
    }

    #[test]
    fn general_path_agrees_with_closed_forms() {
        // The incomplete-gamma route must reproduce the dof 1 and 2 closed forms, which are
        // built on different functions (normal tail, exponential). Tolerance 1e-13 relative.
        for dof in [1.0, 2.0] {
            for p in [1e-20, 1e-5, 0.05, 0.5, 0.9] {
                let closed = upper_quantile(dof, p).unwrap();
                let general = general_upper_quantile(dof, p).unwrap();
                assert!(rel(general, closed) < 1e-13, "dof {dof} p {p}");
            }
            for x in [1e-6, 0.3, 1.0, 4.0, 30.0, 200.0] {
                let (lc, ls) = ln_cdf_sf(dof, x);
                let (lp, lq) = ln_reg_gamma(0.5 * dof, 0.5 * x);
                assert!(
                    (lc - lp).abs() < 1e-13 * lc.abs().max(1e-3),
                    "cdf dof {dof} x {x}"
                );
                assert!(
                    (ls - lq).abs() < 1e-13 * ls.abs().max(1e-3),
                    "sf dof {dof} x {x}"
                );
            }
        }
    }

    #[test]
    fn cdf_and_sf_match_references() {
        // 50-digit mpmath regularized incomplete gamma; 1e-13 relative.
        let cases = [
            (3.0, 1.0, 0.801_251_956_901_200_8, 0.198_748_043_098_799_2),
            (
                3.0,
                20.0,
                1.697_424_355_528_264_3e-4,
                0.999_830_257_564_447_2,
            ),
            (
                5.0,
                0.1,
                0.999_837_683_388_077_4,
                1.623_166_119_226_150_4e-4,
            ),
            (2.5, 7.0, 0.048_333_605_272_569_006, 0.951_666_394_727_431),
            (
                6.0,
                60.0,
                4.501_016_648_012_124e-11,
                0.999_999_999_954_989_8,
            ),
            (1.0, 100.0, 1.523_970_604_832_105_2e-23, 1.0),
            (10.0, 200.0, 1.613_930_533_697_730_5e-37, 1.0),
            (
                4.0,
                1e-3,
                0.999_999_875_041_658_9,
                1.249_583_411_447_917_8e-7,
            ),
        ];
        for (dof, x, want_sf, want_cdf) in cases {
            assert!(rel(sf(dof, x).unwrap(), want_sf) < 1e-13, "sf {dof} {x}");
            assert!(rel(cdf(dof, x).unwrap(), want_cdf) < 1e-13, "cdf {dof} {x}");
        }
        // Far tail in log space: log P(chi^2_7 > 3000) = log(9.4984562965599055e-645).
        let want = 9.498_456_296_559_905_5f64.ln() - 645.0 * std::f64::consts::LN_10;
        assert!(rel(ln_sf(7.0, 3000.0).unwrap(), want) < 1e-13);
        assert_eq!(cdf(3.0, 0.0).unwrap(), 0.0);
        assert_eq!(sf(3.0, -1.0).unwrap(), 1.0);
        assert_eq!(sf(3.0, f64::INFINITY).unwrap(), 0.0);
    }

    #[test]
    fn invalid_arguments_are_rejected() {
        assert_eq!(
            upper_quantile(1.0, 0.0),
            Err(StatsError::InvalidProbability(0.0))
        );
        assert!(upper_quantile(1.0, 1.5).is_err());
        assert!(upper_quantile(1.0, f64::NAN).is_err());
        assert_eq!(upper_quantile(0.0, 0.5), Err(StatsError::InvalidDof(0.0)));
        assert!(upper_quantile(-1.0, 0.5).is_err());
        assert!(upper_quantile(f64::INFINITY, 0.5).is_err());
        assert!(cdf(f64::NAN, 1.0).is_err());
        assert!(sf(2.0, f64::NAN).is_err());
        // Display works and names the problem.
        let msg = StatsError::InvalidDof(-1.0).to_string();
        assert!(msg.contains("-1"));
    }
}
