//! The standard normal distribution, with tails that stay accurate in log space.
//!
//! Why this module exists: the fusion center of a censoring scheme (Zheng, Niu and
//! Varshney) weighs every particle by the probability that a *silent* sensor's innovation fell
//! inside the no-send band, eq. (14):
//!
//! ```text
//! p(m = 0 | x) = Q(xi_1) - Q(xi_2),   xi_{1,2} = (-/+ sqrt(eta s) - mu) / sqrt(r)
//! ```
//!
//! which enters the full likelihoods (9), (15), (44) and (45). For particles far from the
//! truth both `xi` lie deep in one tail and `Q(xi_1) - Q(xi_2)` underflows or cancels to
//! zero in naive arithmetic, so a whole particle cloud can end up with weight zero. The
//! functions here return `log(Q(a) - Q(b))` accurately for any finite `a < b`, so the
//! likelihood can be accumulated in log space.
//!
//! The core is W. J. Cody's rational Chebyshev approximations for the normal integral
//! (Cody, "Rational Chebyshev approximations for the error function", Math. Comp. 23, 1969;
//! the `ANORM` routine of Cody's SPECFUN package, ACM TOMS Algorithm 715, 1993). They come
//! in three ranges and deliver close to full double precision:
//!
//! * `|x| <= 0.674`: `Phi(x) - 1/2 = x R1(x^2)`;
//! * `0.674 < |x| <= sqrt(32)`: `Q(|x|) = exp(-x^2/2) R2(|x|)`;
//! * `|x| > sqrt(32)`: `Q(|x|) = exp(-x^2/2) (1/sqrt(2 pi) - z R3(z)) / |x|`, `z = 1/x^2`.
//!
//! The last two give `Q` as `exp(-x^2/2)` times a slowly varying factor, so
//! `log Q(x) = -x^2/2 + log(factor)` never underflows (it is finite up to `x ~ 1.3e154`).
//! Everything is scalar, `#[inline]`, allocation free and has at most a few well-predicted
//! branches: it is meant for particle-filter likelihood loops of ~10^8 calls.
//!
//! The particle filters' hot loop itself, [`super::band_kernel::add_log_band_probability`] (one band, ~10^4
//! particles per call), goes further: it tabulates the band's log probability once per call as
//! a piecewise polynomial built from these functions and then costs ~3 ns per particle
//! (notes in [`super::band_kernel`], the module that holds it).

/// `1 / sqrt(2 pi)`.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
/// `log(sqrt(2 pi))`.
pub(crate) const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;
/// Boundary of Cody's first range, `Phi^{-1}(3/4)`.
const SPLIT1: f64 = 0.674_489_75;
/// Boundary of Cody's second range, `sqrt(32)`.
const SPLIT2: f64 = 5.656_854_249_492_381;
/// Beyond this `exp(-x^2/2)` is below the smallest subnormal double.
const EXP_UNDERFLOW: f64 = 38.7;
/// A band `[m - h, m + h]` is "narrow" when `h (|m| + 1) <= NARROW`; its probability is then
/// taken from a midpoint expansion (see [`log_q_band`]).
pub(crate) const NARROW: f64 = 1e-2;

// Cody's coefficients (SPECFUN ANORM). First range: Phi(x) - 1/2 = x * RA(x^2) / RB(x^2).
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CA: [f64; 5] = [
    2.235_252_035_460_683_928_7,
    161.028_231_068_555_878_81,
    1_067.689_485_460_370_958_2,
    18_154.981_253_343_561_249,
    0.065_682_337_918_207_449_113,
];
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CB: [f64; 4] = [
    47.202_581_904_688_241_87,
    976.098_551_737_776_693_22,
    10_260.932_208_618_978_205,
    45_507.789_335_026_729_956,
];
// Second range: Q(y) = exp(-y^2/2) * RC(y) / RD(y).
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CC: [f64; 9] = [
    0.398_941_512_088_134_667_64,
    8.883_149_794_388_375_941_2,
    93.506_656_132_177_855_979,
    597.270_276_394_800_262_26,
    2_494.537_585_290_372_671_1,
    6_848.190_450_536_282_332_6,
    11_602.651_437_647_350_124,
    9_842.714_838_383_978_021_8,
    1.076_557_677_372_019_231_7e-8,
];
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CD: [f64; 8] = [
    22.266_688_044_328_115_691,
    235.387_901_782_624_998_61,
    1_519.377_599_407_554_805,
    6_485.558_298_266_760_755,
    18_615.571_640_885_098_091,
    34_900.952_721_145_977_266,
    38_912.003_286_093_271_411,
    19_685.429_676_859_990_727,
];
// Third range: Q(y) = exp(-y^2/2) * (1/sqrt(2 pi) - z RP(z) / RQ(z)) / y, z = 1/y^2.
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CP: [f64; 6] = [
    0.215_898_534_057_956_99,
    0.127_401_161_160_247_363_9,
    0.022_235_277_870_649_807,
    0.001_421_619_193_227_893_466,
    2.911_287_495_116_879_2e-5,
    0.023_073_441_764_940_173_03,
];
#[allow(clippy::excessive_precision)] // Cody's published digits, kept verbatim
const CQ: [f64; 5] = [
    1.284_260_096_144_911_21,
    0.468_238_212_480_865_118,
    0.065_988_137_868_928_551_5,
    0.003_782_396_332_027_582_44,
    7.297_515_550_839_662_05e-5,
];

/// `P(0 < X < y)` for `0 <= y <= SPLIT1` (Cody's first range). No cancellation: this is
/// what makes bands straddling zero accurate to the last bit.
#[inline]
fn central_small(y: f64) -> f64 {
    let ysq = y * y;
    let mut num = CA[4] * ysq;
    let mut den = ysq;
    for i in 0..3 {
        num = (num + CA[i]) * ysq;
        den = (den + CB[i]) * ysq;
    }
    y * (num + CA[3]) / (den + CB[3])
}

/// `Q(y) exp(y^2/2)` for `y > SPLIT1` (Cody's second and third ranges). Slowly varying
/// (about `1 / (y sqrt(2 pi))` for large `y`), so its logarithm is harmless.
#[inline]
fn scaled_tail(y: f64) -> f64 {
    if y <= SPLIT2 {
        let mut num = CC[8] * y;
        let mut den = y;
        for i in 0..7 {
            num = (num + CC[i]) * y;
            den = (den + CD[i]) * y;
        }
        (num + CC[7]) / (den + CD[7])
    } else {
        let z = 1.0 / (y * y);
        let mut num = CP[5] * z;
        let mut den = z;
        for i in 0..4 {
            num = (num + CP[i]) * z;
            den = (den + CQ[i]) * z;
        }
        let r = z * (num + CP[4]) / (den + CQ[4]);
        (FRAC_1_SQRT_2PI - r) / y
    }
}

/// `exp(-y^2/2)` to nearly full relative precision: `y` is split as `ys + (y - ys)` with
/// `ys` a multiple of 1/16, so `ys^2` is exact and the rounding error of `y^2` (which would
/// cost `y^2 * 1e-16` relative accuracy, 1e-13 at y = 30) is avoided.
#[inline]
fn exp_neg_half_sq(y: f64) -> f64 {
    if y > EXP_UNDERFLOW {
        return 0.0;
    }
    let ys = (y * 16.0).trunc() / 16.0;
    let del = (y - ys) * (y + ys);
    (-0.5 * ys * ys).exp() * (-0.5 * del).exp()
}

/// `Q(y)` for `y > SPLIT1`.
#[inline]
fn tail(y: f64) -> f64 {
    exp_neg_half_sq(y) * scaled_tail(y)
}

/// `log Q(y) + y^2/2` for `y >= 0`: the log of the slowly varying factor of the tail.
/// Two calls of this let [`log_q_band`] form `log Q(b) - log Q(a)` without cancelling the
/// large `-y^2/2` parts against each other.
#[inline]
pub(crate) fn ln_scaled_q(y: f64) -> f64 {
    if y <= SPLIT1 {
        (0.5 - central_small(y)).ln() + 0.5 * y * y
    } else {
        scaled_tail(y).ln()
    }
}

/// `P(0 < X < y)` for `y >= 0`, accurate in relative terms for every `y`.
#[inline]
pub(crate) fn central_mass(y: f64) -> f64 {
    if y <= SPLIT1 {
        central_small(y)
    } else {
        0.5 - tail(y)
    }
}

/// `log(1 - exp(d))` for `d < 0` (Maechler's `log1mexp`): the branch keeps full relative
/// accuracy both for `d -> 0-` (narrow bands) and for very negative `d` (wide bands).
#[inline]
pub(crate) fn log1mexp(d: f64) -> f64 {
    // Guard against d >= 0, which only rounding in a degenerate band can produce.
    let d = d.min(-f64::MIN_POSITIVE);
    if d > -std::f64::consts::LN_2 {
        (-d.exp_m1()).ln()
    } else {
        (-d.exp()).ln_1p()
    }
}

/// Standard normal density `phi(x)`.
///
/// Relative error about `x^2 * 1e-16` from the rounding of `x^2` (use [`log_pdf`] in
/// likelihood products: it has no such loss and never underflows).
#[inline]
pub fn pdf(x: f64) -> f64 {
    FRAC_1_SQRT_2PI * (-0.5 * x * x).exp()
}

/// `log phi(x) = -x^2/2 - log sqrt(2 pi)`. The log-likelihood of a received scalar
/// innovation in eqs. (9), (15), (44), (45) is this, shifted and scaled.
#[inline]
pub fn log_pdf(x: f64) -> f64 {
    -0.5 * x * x - LN_SQRT_2PI
}

/// Upper tail `Q(x) = P(X > x) = 1 - Phi(x)`, the `Q(.)` of Zheng et al. (2014), eq. (9).
///
/// Relative error a few 1e-15 at most wherever the result is a normal double; it
/// underflows to 0 beyond `x ~ 38.5` (use [`log_q`] there).
#[inline]
pub fn q(x: f64) -> f64 {
    let y = x.abs();
    if y <= SPLIT1 {
        0.5 - central_small(x)
    } else {
        let t = tail(y);
        if x > 0.0 {
            t
        } else {
            1.0 - t
        }
    }
}

/// Standard normal CDF `Phi(x) = Q(-x)`.
#[inline]
pub fn cdf(x: f64) -> f64 {
    q(-x)
}

/// `log Q(x)`, accurate in both tails.
///
/// * upper tail: `-x^2/2 + log(Q(x) e^{x^2/2})`, no underflow (e.g. `log Q(40) = -804.608...`),
///   finite for `x` up to ~1.3e154, `-inf` only beyond;
/// * lower tail: `log1p(-Q(-x))`, so `log_q(-5) = -2.8665e-7` to full relative precision.
#[inline]
pub fn log_q(x: f64) -> f64 {
    let y = x.abs();
    if y <= SPLIT1 {
        (0.5 - central_small(x)).ln()
    } else if x > 0.0 {
        -0.5 * x * x + scaled_tail(x).ln()
    } else {
        (-tail(y)).ln_1p()
    }
}

/// `log Phi(x) = log Q(-x)`.
#[inline]
pub fn log_cdf(x: f64) -> f64 {
    log_q(-x)
}

/// `log(Q(a) - Q(b)) = log P(a < X < b)`: the log of the no-send probability of Zheng et al. (2014),
/// eq. (14), as it enters the full likelihoods (9), (15), (44), (45).
///
/// Computed stably for every `a < b`:
///
/// * narrow band (`h (|m| + 1) <= 1e-2` with `m`, `h` the band's midpoint and half-width):
///   `log phi(m) + log(b - a) + log(1 + He2(m) h^2/6 + He4(m) h^4/120)`, the midpoint
///   expansion of the integral (Hermite polynomials `He2 = m^2 - 1`, `He4 = m^4 - 6m^2 + 3`);
///   the first neglected term is below 2e-14 relative;
/// * both limits in the upper tail (`a >= 0`): `log Q(a) + log1p(-exp(log Q(b) - log Q(a)))`,
///   with the difference `log Q(b) - log Q(a)` formed as `-(b - a)(b + a)/2` plus the
///   difference of the slowly varying log factors, so it has no cancellation (and `Q(b)` is
///   not evaluated at all when `(b - a)(b + a)/2 > 40`, where it changes the log by < 5e-18);
/// * both in the lower tail (`b <= 0`): the mirror image `Phi(b) - Phi(a) = Q(-b) - Q(-a)`;
/// * straddling 0: `P(0 < X < -a) + P(0 < X < b)`, a sum of positives (no cancellation).
///
/// Accuracy (checked in the tests against 50-digit references): the band probability is
/// good to ~1e-13 relative, i.e. the log to ~1e-13 absolute plus a few ulps of its own
/// magnitude (1e-12 at `log ~ -800`). Never NaN and never `-inf` for finite `a < b`: a band too far out for even its
/// log to be a double (`|a| > ~1e154`) returns `f64::MIN`. An empty band (`a >= b`) returns
/// `-inf`; a NaN input returns NaN.
#[inline]
pub fn log_q_band(a: f64, b: f64) -> f64 {
    let w = b - a;
    if w <= 0.0 || w.is_nan() {
        return if a.is_nan() || b.is_nan() {
            f64::NAN
        } else {
            f64::NEG_INFINITY
        };
    }
    let h = 0.5 * w;
    let m = 0.5 * a + 0.5 * b;
    let r = if h * (m.abs() + 1.0) <= NARROW {
        let m2 = m * m;
        let h2 = h * h;
        let corr = (m2 - 1.0) * h2 / 6.0 + (m2 * m2 - 6.0 * m2 + 3.0) * h2 * h2 / 120.0;
        log_pdf(m) + w.ln() + corr.ln_1p()
    } else if a >= 0.0 {
        upper_band(a, b)
    } else if b <= 0.0 {
        upper_band(-b, -a)
    } else {
        (central_mass(-a) + central_mass(b)).ln()
    };
    r.max(f64::MIN)
}

/// `log(Q(a) - Q(b))` for `0 <= a < b`.
#[inline]
fn upper_band(a: f64, b: f64) -> f64 {
    let ra = ln_scaled_q(a);
    let la = -0.5 * a * a + ra;
    let gap = -0.5 * (b - a) * (b + a);
    // Q(b)/Q(a) = e^gap R(b)/R(a) <= e^gap (the scaled tail R decreases): below e^-40 the far
    // edge changes the log by less than 4.3e-18, so it is not evaluated.
    if gap < -40.0 {
        return la;
    }
    let rb = ln_scaled_q(b);
    la + log1mexp(gap + (rb - ra))
}

/// [`log_q_band`] over slices: `out[i] = log(Q(a[i]) - Q(b[i]))`. Allocation free; the loop
/// body is the inlined scalar function, so the compiler sees one straight loop.
///
/// # Panics
/// If the three slices do not have the same length.
pub fn log_q_band_slice(a: &[f64], b: &[f64], out: &mut [f64]) {
    assert!(
        a.len() == b.len() && a.len() == out.len(),
        "log_q_band_slice: slice lengths differ ({}, {}, {})",
        a.len(),
        b.len(),
        out.len()
    );
    for ((o, &ai), &bi) in out.iter_mut().zip(a).zip(b) {
        *o = log_q_band(ai, bi);
    }
}

// Acklam's rational approximation to the normal quantile (P. J. Acklam, "An algorithm for
// computing the inverse normal cumulative distribution function", 2003): relative error
// below 1.15e-9, refined below by one Halley step.
const AA: [f64; 6] = [
    -3.969_683_028_665_376e1,
    2.209_460_984_245_205e2,
    -2.759_285_104_469_687e2,
    1.383_577_518_672_69e2,
    -3.066_479_806_614_716e1,
    2.506_628_277_459_239,
];
const AB: [f64; 5] = [
    -5.447_609_879_822_406e1,
    1.615_858_368_580_409e2,
    -1.556_989_798_598_866e2,
    6.680_131_188_771_972e1,
    -1.328_068_155_288_572e1,
];
const AC: [f64; 6] = [
    -7.784_894_002_430_293e-3,
    -3.223_964_580_411_365e-1,
    -2.400_758_277_161_838,
    -2.549_732_539_343_734,
    4.374_664_141_464_968,
    2.938_163_982_698_783,
];
const AD: [f64; 4] = [
    7.784_695_709_041_462e-3,
    3.224_671_290_700_398e-1,
    2.445_134_137_142_996,
    3.754_408_661_907_416,
];
const ACKLAM_LOW: f64 = 0.024_25;

/// Acklam's initial guess for `Phi^{-1}(p)`, `0 < p <= 0.5`.
#[inline]
fn acklam_lower(p: f64) -> f64 {
    if p < ACKLAM_LOW {
        let t = (-2.0 * p.ln()).sqrt();
        (((((AC[0] * t + AC[1]) * t + AC[2]) * t + AC[3]) * t + AC[4]) * t + AC[5])
            / ((((AD[0] * t + AD[1]) * t + AD[2]) * t + AD[3]) * t + 1.0)
    } else {
        let t = p - 0.5;
        let r = t * t;
        (((((AA[0] * r + AA[1]) * r + AA[2]) * r + AA[3]) * r + AA[4]) * r + AA[5]) * t
            / (((((AB[0] * r + AB[1]) * r + AB[2]) * r + AB[3]) * r + AB[4]) * r + 1.0)
    }
}

/// `Phi^{-1}(p)` for `0 < p <= 0.5`: Acklam, then one Halley step on `Phi(x) = p`.
///
/// The residual is formed in log space, `Phi(x)/p - 1 = expm1(log Phi(x) - log p)`, and
/// scaled by `p / phi(x) = exp(log p - log phi(x))`, so the step stays accurate down to
/// subnormal `p` where `Phi(x) - p` itself would be a subnormal with few significant bits.
#[inline]
fn lower_quantile(p: f64) -> f64 {
    let x = acklam_lower(p);
    let lp = p.ln();
    let r = (log_cdf(x) - lp).exp_m1();
    let u = r * (lp - log_pdf(x)).exp();
    x - u / (1.0 + 0.5 * x * u)
}

/// Inverse of the standard normal CDF, `Phi^{-1}(p)`.
///
/// Acklam's approximation (relative error < 1.15e-9) refined by one Halley step using the
/// accurate [`log_cdf`]; Halley's cubic convergence takes the error to the rounding level
/// (the tests check ~1e-14 relative against 50-digit references, from `p = 1e-320` to
/// `1 - 1e-12`). Upper-half `p` is mapped to the lower half through `1 - p`, which is
/// exact for `p >= 1/2`. Returns `-inf` / `+inf` at `p = 0` / `1` and NaN outside `[0, 1]`.
#[inline]
pub fn inv_cdf(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return if p == 0.0 {
            f64::NEG_INFINITY
        } else if p == 1.0 {
            f64::INFINITY
        } else {
            f64::NAN
        };
    }
    if p > 0.5 {
        -lower_quantile(1.0 - p)
    } else {
        lower_quantile(p)
    }
}

#[cfg(test)]
mod tests {
    // Reference values are quoted with all the digits the high-precision source gave.
    #![allow(clippy::excessive_precision)]
    use super::*;

    /// Relative difference, with `b` the reference.
    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    #[test]
    fn q_matches_reference_values() {
        // References: 50-digit mpmath, Q(x) = erfc(x/sqrt 2)/2. Tolerance 5e-15 relative:
        // Cody's approximations are good to ~1e-16 and exp/ln add a few ulps.
        let cases = [
            (0.0, 0.5),
            (0.5, 0.308_537_538_725_986_9),
            (0.674, 0.250_155_656_840_322_6),
            (0.675, 0.249_837_882_471_777),
            (1.0, 0.158_655_253_931_457_05),
            (2.5, 0.006_209_665_325_776_135),
            (5.0, 2.866_515_718_791_939e-7),
            (5.65, 8.022_391_850_663_498e-9),
            (5.66, 7.568_649_751_997_714e-9),
            (10.0, 7.619_853_024_160_526e-24),
            (20.0, 2.753_624_118_606_233_7e-89),
            (30.0, 4.906_713_927_148_187e-198),
            (37.0, 5.725_571_222_524_577e-300),
            (-1.0, 0.841_344_746_068_542_9),
            (-5.0, 1.0 - 2.866_515_718_791_939e-7),
        ];
        for (x, want) in cases {
            assert!(rel(q(x), want) < 5e-15, "Q({x}) = {} want {want}", q(x));
            assert!(rel(cdf(-x), want) < 5e-15);
        }
        assert_eq!(q(0.0), 0.5);
        assert_eq!(q(50.0), 0.0);
        assert_eq!(q(-50.0), 1.0);
    }

    #[test]
    fn log_q_matches_reference_values_in_both_tails() {
        // 50-digit mpmath references. The log is compared with a relative tolerance of
        // 2e-15, i.e. an absolute one of ~1.6e-12 at x = 40: -x^2/2 alone is rounded to
        // half an ulp of 800 (5.7e-14), so this is a few ulps.
        let cases = [
            (0.0, -std::f64::consts::LN_2),
            (1.0, -1.841_021_645_009_263_5),
            (5.0, -15.064_998_393_988_726),
            (10.0, -53.231_285_150_512_47),
            (20.0, -203.917_155_371_097_26),
            (30.0, -454.321_243_956_343_2),
            (38.5, -745.695_270_290_411_1),
            (40.0, -804.608_442_013_753_8),
            (100.0, -5_005.524_208_694_205),
            (1000.0, -500_007.826_694_812_2),
            (-1.0, -0.172_753_779_023_449_9),
            (-5.0, -2.866_516_129_637_636e-7),
            (-10.0, -7.619_853_024_160_526e-24),
        ];
        for (x, want) in cases {
            let got = log_q(x);
            assert!(rel(got, want) < 2e-15, "log Q({x}) = {got} want {want}");
        }
        assert_eq!(log_q(-40.0), 0.0); // true value -3.7e-350 rounds to 0
        assert_eq!(log_q(f64::INFINITY), f64::NEG_INFINITY);
        assert_eq!(log_q(f64::NEG_INFINITY), 0.0);
        assert!(log_q(f64::NAN).is_nan());
    }

    #[test]
    fn log_q_is_finite_and_monotone_on_a_fine_grid() {
        let mut prev = f64::INFINITY;
        for i in 0..=80_000 {
            let x = -40.0 + i as f64 * 1e-3;
            let l = log_q(x);
            assert!(
                l.is_finite() || (x <= -38.0 && l == 0.0),
                "log_q({x}) = {l}"
            );
            assert!(l <= 0.0);
            // non-increasing; strictly decreasing wherever the value is not pinned at 0
            assert!(l <= prev, "not monotone at {x}: {l} > {prev}");
            // (strictness is only checkable while the value is a normal double, not a
            // subnormal such as log1p(-1e-323) near x = -38.5)
            if prev < -f64::MIN_POSITIVE {
                assert!(l < prev, "not strictly decreasing at {x}");
            }
            prev = l;
        }
    }

    #[test]
    fn log_q_is_continuous_across_the_range_boundaries() {
        // A wrong coefficient would show as a jump at Cody's range boundaries.
        for split in [SPLIT1, SPLIT2, -SPLIT1, -SPLIT2] {
            let below = log_q(split - 1e-12);
            let above = log_q(split + 1e-12);
            let slope = (log_q(split + 1e-6) - log_q(split - 1e-6)) / 2e-6;
            let jump = (above - below) - slope * 2e-12;
            // Allowed: a relative mismatch of 2e-15 in Q between Cody's adjacent approximations
            // (they are each good to ~1e-15). In log space that is 2e-15 absolute on the upper
            // side, and 2e-15 * |log Q| on the lower side where log Q = log1p(-Q(-x)) ~ -Q(-x).
            let tol = 2e-15 * below.abs().min(1.0);
            assert!(jump.abs() <= tol, "jump {jump} at {split}");
        }
    }

    #[test]
    fn pdf_and_log_pdf() {
        assert!(rel(pdf(0.0), FRAC_1_SQRT_2PI) < 1e-16);
        assert!(rel(pdf(1.0), 0.241_970_724_519_143_37) < 1e-15);
        assert!(rel(log_pdf(30.0), -450.918_938_533_204_7) < 3e-16);
        assert!(rel(log_pdf(2.0), pdf(2.0).ln()) < 1e-15);
    }

    /// `log(Q(a) - Q(b))` computed directly; accurate only where there is no cancellation.
    fn direct(a: f64, b: f64) -> f64 {
        (q(a) - q(b)).ln()
    }

    #[test]
    fn log_q_band_matches_direct_difference_where_that_is_accurate() {
        // Moderate bands away from the tails: the direct difference loses at most a few ulps
        // (no band here is narrower than 0.05 or has both ends beyond |x| = 3), so 1e-13
        // absolute in the log is a safe bound for both sides.
        let pts = [-3.0, -2.0, -1.0, -0.5, -0.1, 0.0, 0.2, 0.7, 1.5, 2.5, 3.0];
        for &a in &pts {
            for &b in &pts {
                if b > a {
                    let (g, d) = (log_q_band(a, b), direct(a, b));
                    assert!((g - d).abs() < 1e-13, "({a}, {b}): {g} vs {d}");
                }
            }
        }
    }

    #[test]
    fn log_q_band_far_tails_and_narrow_bands() {
        // 50-digit mpmath references. Tolerance 1e-12 absolute on logs of magnitude up to
        // 800 (a few ulps of -x^2/2) and 1e-13 on O(1)-magnitude logs.
        let cases = [
            (30.0, 30.1, -454.371_879_083_860_56, 1e-12),
            (-30.1, -30.0, -454.371_879_083_860_56, 1e-12),
            (-1e-3, 1e-3, -7.133_546_798_293_52, 1e-13),
            (1.0, 2.0, -1.995_798_269_180_755_4, 1e-13),
            (-2.0, -1.0, -1.995_798_269_180_755_4, 1e-13),
            (-0.5, 3.0, -0.370_900_559_562_032_5, 1e-13),
            (5.0, 6.0, -15.068_446_096_529_453, 1e-13),
            (38.0, 39.0, -726.557_216_018_820_1, 1e-12),
            (-39.0, -38.0, -726.557_216_018_820_1, 1e-12),
            (39.9, 40.0, -800.629_474_160_121_5, 1e-12),
            (-40.0, 40.0, 0.0, 1e-15),
            (-3.0, 1e-300, -0.695_850_627_645_421_3, 1e-13),
            (1e-3, 2e-3, -7.826_694_978_853_382, 1e-13),
            (2.0, 2.0005, -10.520_340_992_736_005, 1e-12),
            (0.0, 1e-6, -14.734_449_091_169_114, 1e-13),
        ];
        for (a, b, want, tol) in cases {
            let got = log_q_band(a, b);
            assert!((got - want).abs() < tol, "({a}, {b}): {got} want {want}");
        }
        // The band [10, 10 + 1e-9] as doubles: b - a is not exactly 1e-9, so compare with
        // the analytic narrow-band value log phi(m) + log(b - a) (error ~ (m h)^2 ~ 1e-16).
        let (a, b) = (10.0, 10.0 + 1e-9);
        let want = log_pdf(0.5 * (a + b)) + (b - a).ln();
        assert!((log_q_band(a, b) - want).abs() < 1e-13);
    }

    #[test]
    fn log_q_band_is_finite_on_a_grid_of_bands() {
        // Every finite band a < b in [-40, 40] must give a finite log (no NaN, no -inf),
        // at most 0, and larger bands must not give smaller probabilities.
        let n = 801;
        let xs: Vec<f64> = (0..n).map(|i| -40.0 + 0.1 * i as f64).collect();
        for i in 0..n {
            for j in (i + 1)..n {
                let l = log_q_band(xs[i], xs[j]);
                assert!(l.is_finite() && l <= 0.0, "({}, {}) -> {l}", xs[i], xs[j]);
                if j + 1 < n {
                    assert!(log_q_band(xs[i], xs[j + 1]) >= l);
                }
            }
        }
        // Tiny and astronomically far bands.
        for (a, b) in [
            (40.0, 40.0 + 1e-13),
            (-40.0 - 1e-13, -40.0),
            (1e5, 1e5 + 1.0),
            (1e200, 2e200),
            (-1e300, -1e299),
            (0.0, f64::MIN_POSITIVE),
            (7.0, 7.0 + 7.0 * f64::EPSILON),
        ] {
            let l = log_q_band(a, b);
            assert!(l.is_finite(), "({a}, {b}) -> {l}");
        }
        assert_eq!(log_q_band(1.0, 1.0), f64::NEG_INFINITY);
        assert_eq!(log_q_band(2.0, 1.0), f64::NEG_INFINITY);
        assert!(log_q_band(f64::NAN, 1.0).is_nan());
        assert_eq!(log_q_band(f64::NEG_INFINITY, f64::INFINITY), 0.0);
    }

    #[test]
    fn log_q_band_is_continuous_across_branch_switches() {
        // The narrow-band expansion and the tail formula must agree where one hands over to
        // the other (h (|m| + 1) = 1e-2); a mismatch beyond 1e-12 would be a bug.
        for m in [0.3f64, 1.0, 3.0, 10.0, 30.0, -2.0, -25.0] {
            let h = NARROW / (m.abs() + 1.0);
            let inside = log_q_band(m - h * (1.0 - 1e-9), m + h * (1.0 - 1e-9));
            let outside = log_q_band(m - h * (1.0 + 1e-9), m + h * (1.0 + 1e-9));
            // d/dh of log(2h phi(m)) is 1/h; the tiny change of h moves the log by ~2e-9.
            assert!((outside - inside - 2e-9).abs() < 1e-11, "m = {m}");
        }
    }

    #[test]
    fn log_q_band_slice_matches_scalar() {
        let a = [-1.0, 30.0, -30.1, 0.0];
        let b = [1.0, 30.1, -30.0, 1e-9];
        let mut out = [0.0; 4];
        log_q_band_slice(&a, &b, &mut out);
        for i in 0..4 {
            assert_eq!(out[i], log_q_band(a[i], b[i]));
        }
    }

    #[test]
    #[should_panic]
    fn log_q_band_slice_rejects_length_mismatch() {
        let mut out = [0.0; 2];
        log_q_band_slice(&[0.0, 1.0], &[1.0], &mut out);
    }

    #[test]
    fn inv_cdf_matches_reference_values() {
        // 50-digit mpmath references for the doubles nearest the listed p. Tolerance 1e-14
        // relative (the brief's target); the x ~ 2.5e-10 case is absolute-limited by the
        // spacing of doubles near p = 0.5 (p carries 5.6e-17 absolute uncertainty, i.e.
        // ~1.4e-16 in x), so it gets 1e-15 absolute.
        let cases = [
            (0.975, 1.959_963_984_540_053_9),
            (0.025, -1.959_963_984_540_054_2),
            (1e-10, -6.361_340_902_404_056),
            (1e-300, -37.047_096_299_361_2),
            (0.3, -0.524_400_512_708_040_8),
            (0.024_25, -1.972_961_051_311_884_8),
            (0.9, 1.281_551_565_544_600_6),
            (1.0 - 1e-12, 7.034_486_910_047_835),
            (1e-320, -38.269_125_343_032_65),
        ];
        for (p, want) in cases {
            let got = inv_cdf(p);
            assert!(rel(got, want) < 1e-14, "inv_cdf({p}) = {got} want {want}");
        }
        assert!((inv_cdf(0.5 + 1e-10) - 2.506_628_482_030_354e-10).abs() < 1e-15);
        assert_eq!(inv_cdf(0.5), 0.0);
        assert_eq!(inv_cdf(0.0), f64::NEG_INFINITY);
        assert_eq!(inv_cdf(1.0), f64::INFINITY);
        assert!(inv_cdf(1.5).is_nan() && inv_cdf(-0.1).is_nan() && inv_cdf(f64::NAN).is_nan());
    }

    #[test]
    fn inv_cdf_round_trips() {
        // Phi(Phi^{-1}(p)) = p to a few ulps over 1e-300..1-1e-15, and the quantile is
        // antisymmetric. Tolerance: even the double nearest the true quantile is off by half
        // an ulp, |x| * 1.1e-16, which moves log Phi by |d log Phi/dx| * that ~ x^2 * 1.1e-16
        // (1.5e-13 at x = 37); allow 3 x^2 eps plus 1e-14.
        let mut p = 1e-300;
        while p < 0.5 {
            let x = inv_cdf(p);
            let tol = 1e-14 + 3.0 * x * x * f64::EPSILON;
            assert!(rel(cdf(x), p) < tol, "p = {p}: cdf(inv) = {}", cdf(x));
            assert_eq!(inv_cdf(1.0 - p), -inv_cdf(1.0 - (1.0 - p)));
            p *= 1.7;
        }
        for i in 1..1000 {
            let p = i as f64 / 1000.0;
            assert!((cdf(inv_cdf(p)) - p).abs() < 2e-16 * p.max(1.0 - p) * 4.0);
        }
    }
}
