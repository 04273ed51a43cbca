//! The standard normal distribution, with tails that stay accurate in log space.
//!
//! Why this module exists: the fusion center of a censoring scheme (paper 000, Zheng, Niu and
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
//! The particle filters' hot loop itself, [`add_log_band_probability`] (one band, ~10^4
//! particles per call), goes further: it tabulates the band's log probability once per call as
//! a piecewise polynomial built from these functions and then costs ~3 ns per particle
//! (notes at the kernel's constants, near the end of this file).

/// `1 / sqrt(2 pi)`.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
/// `log(sqrt(2 pi))`.
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;
/// Boundary of Cody's first range, `Phi^{-1}(3/4)`.
const SPLIT1: f64 = 0.674_489_75;
/// Boundary of Cody's second range, `sqrt(32)`.
const SPLIT2: f64 = 5.656_854_249_492_381;
/// Beyond this `exp(-x^2/2)` is below the smallest subnormal double.
const EXP_UNDERFLOW: f64 = 38.7;
/// A band `[m - h, m + h]` is "narrow" when `h (|m| + 1) <= NARROW`; its probability is then
/// taken from a midpoint expansion (see [`log_q_band`]).
const NARROW: f64 = 1e-2;

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
fn ln_scaled_q(y: f64) -> f64 {
    if y <= SPLIT1 {
        (0.5 - central_small(y)).ln() + 0.5 * y * y
    } else {
        scaled_tail(y).ln()
    }
}

/// `P(0 < X < y)` for `y >= 0`, accurate in relative terms for every `y`.
#[inline]
fn central_mass(y: f64) -> f64 {
    if y <= SPLIT1 {
        central_small(y)
    } else {
        0.5 - tail(y)
    }
}

/// `log(1 - exp(d))` for `d < 0` (Maechler's `log1mexp`): the branch keeps full relative
/// accuracy both for `d -> 0-` (narrow bands) and for very negative `d` (wide bands).
#[inline]
fn log1mexp(d: f64) -> f64 {
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

/// Upper tail `Q(x) = P(X > x) = 1 - Phi(x)`, the `Q(.)` of paper 000, eq. (9).
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

/// `log(Q(a) - Q(b)) = log P(a < X < b)`: the log of the no-send probability of paper 000,
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

// ---------------------------------------------------------------------------------------------
// The band-likelihood kernel of the particle filters.
// ---------------------------------------------------------------------------------------------
//
// `add_log_band_probability` adds `ln P` for ~10^4 particles per call, ~3 10^8 times in one
// benchmark, so it must cost a few ns per particle; the accurate scalar `log_q_band` costs
// 30-40 ns. In units of the noise sd (`m = mu s`, `c = half_width s`) the band probability is
// `P = Phi(c - m) - Phi(-c - m)`: symmetric about `m = 0`, so a function of `x = |m|` alone,
// and within one call `c` is fixed. The kernel therefore tabulates the one-variable function
//
//     f(x) = ln P(x),   P(x) = Q(a) - Q(a + 2c),   a = x - c,
//
// once per call as a piecewise polynomial (~1-3 us), and then spends one table-row lookup and
// one degree-8 Horner evaluation per particle.
//
// * Pieces. `f` is analytic; its nearest complex singularities (zeros of `P`, and the erfc zeros
//   in `ln Q(a)`) are 2.6 or more from the real axis, so degree-8 Chebyshev interpolation is
//   good to ~1e-13 on pieces 0.375 wide where `f` bends (`a` in [-6, 3]) and on pieces growing
//   to 3.375 wide at `a = 40.5` (`SCHEDULE`). Below `a = -9` the band covers the particle,
//   `P > 1 - 3e-19`: `f = 0`. Above `a = 40.5` (`P < 1e-357`, where no accuracy is promised)
//   `f` continues as the quadratic Taylor polynomial of the last piece at its end, which keeps
//   decreasing like `-a^2/2`; particles beyond `x = 1e150` are evaluated there (~ -5e299).
// * Lookup. Bins 0.375 wide in `a` address the pieces: a bin's row holds its piece's centre,
//   inverse half-width and monomial coefficients (in units of `mu`, so the particles skip the
//   product `mu s`). Per particle: `|mu|`, a clamp, a multiply-add, a clamp and a magic-number
//   rounding for the row, a subtract and a multiply for the local variable `t` in [-1, 1], and
//   the Horner steps, run in lockstep over blocks of 16 particles (the row loads vectorize as
//   pairs of scalar loads; the lockstep gives the out-of-order core independent work).
// * Construction. The interpolation nodes sit at fixed offsets in `a`, whatever `c`, so their
//   near-edge part is computed once per process: `ln Q(a) = T(a) - a^2/2` with
//   `T(y) = ln(e^{y^2/2} Q(y))` (the log of the scaled tail: smooth, O(ln y)). Per call and
//   node only the far edge `b = a + 2c` is new:
//   `f = T(a) - a^2/2 + L(-(2xc + T(a) - T(b)))`, `L(d) = ln(1 - e^d)`,
//   with `T(b)` and `L` read from process-wide piecewise-polynomial tables (`T` on uniform
//   pieces, `L` on pieces geometric in `-d`, for its log singularity at 0), batched like the
//   particles. Where `2xc >= 37` the far edge is below 1e-16 relative and the node needs nothing;
//   such whole pieces reuse coefficients fitted once. Outside the band what the polynomials
//   interpolate is the small, smooth `h = f + a^2/2`, and the exact `-a(t)^2/2` is added to the
//   coefficients, so the large magnitudes of `f` (to -820) cost only the final roundings;
//   inside (`a <= 0`, `P` near 1) they interpolate `f` itself, from `ln Q(a)` computed once.
// * Narrow bands (`c < 0.01`): `T(b) - T(a)` would lose too many digits relative to
//   `ln(Q(a) / Q(b))`, so their nodes come from an accurate scalar evaluation with the exact
//   half-width (`band_h`, ~10 us per call); the table and the per-particle work are the same.
//
// Accuracy (tests `kernel_tests`): within 2.3e-13 of `log_q_band` on a dense grid of exactly
// representable inputs, narrow bands included, wherever `P >= 1e-300`.

use multiversion::multiversion;
use std::cell::RefCell;
use std::sync::OnceLock;

/// Degree of the kernel's piecewise polynomials.
const KDEG: usize = 8;
/// Coefficients (and interpolation nodes) per piece.
const KN: usize = KDEG + 1;
/// Width in `a = |m| - c` of the lookup bins; every piece boundary is a multiple of it.
const BIN: f64 = 0.375;
/// Lower end of the tabulated range of `a` (below: `f = 0`, row 0).
const A_LO: f64 = -9.0;
/// Upper end of the piecewise polynomials (above: quadratic continuation, `CAP_ROW`).
const A_CAP: f64 = 40.5;
/// Row of the quadratic continuation beyond `A_CAP`; rows `1..CAP_ROW` are the bins.
const CAP_ROW: usize = 133;
/// Rows allocated per table (a power of two, so that masking the index needs no bounds check).
const TABLE_ROWS: usize = 256;
/// Piece widths: `(a_lo, a_hi, width)`. Narrow where `f` bends (around the band edge `a = 0`
/// and, for `c` near 1.5-2, near `x = 0`), growing like `a / 7` in the far tail, where the
/// nearest singularity of `ln Q(a)` is the first erfc zero, `|a + 1.9 -+ 2.8i|` away.
const SCHEDULE: [(f64, f64, f64); 8] = [
    (-9.0, -6.0, 0.75),
    (-6.0, 3.0, 0.375),
    (3.0, 4.5, 0.75),
    (4.5, 9.0, 1.125),
    (9.0, 13.5, 1.5),
    (13.5, 24.75, 2.25),
    (24.75, 33.75, 3.0),
    (33.75, 40.5, 3.375),
];
/// A node whose `2xc` reaches this has `Q(b)/Q(a) < e^-37 < 1e-16`: the far edge is negligible.
const FAR: f64 = 37.0;
/// Below this half-width (in sd units) the nodes are evaluated by `band_h`.
const FAST_C_MIN: f64 = 0.01;
/// Above this half-width (or for a non-positive or non-finite one) the kernel falls back to the
/// scalar `log_q_band` loop (such bands cover every particle of any sensible filter).
const KERNEL_C_MAX: f64 = 1e6;
/// Particles beyond this `|m|` are evaluated as if at it: `f ~ -5e299`, finite.
const KERNEL_X_MAX: f64 = 1e150;
/// Below this many particles building the table (1-3 us) does not pay.
const KERNEL_MIN_LEN: usize = 64;
/// `1.5 * 2^52`: adding it to `v` in `[-0.5, 2^51)` leaves `round(v)` in the low mantissa bits.
const MAGIC: f64 = 6_755_399_441_055_744.0;
/// The process-wide table of `T(y) = ln(e^{y^2/2} Q(y))`: uniform pieces `1 / T_SCALE` wide on
/// `[T_LO, T_LO + T_PIECES / T_SCALE)`, covering every `b = a + 2c = x + c` a node can need
/// (`b <= 40.5 + 2c` and `2xc < FAR` give `b < 42`).
const T_LO: f64 = 0.0;
const T_SCALE: f64 = 4.0;
const T_PIECES: usize = 168;
/// The process-wide table of `L(d) = ln(1 - e^d)` in `g = -d`: `L_SUB` pieces per binade for
/// `g` in `[2^L_EMIN, 2^(L_EMIN + L_BINADES))`. Fast-path nodes have `g >= ~1.6 c >= 0.016`.
const L_EMIN: i32 = -7;
const L_BINADES: usize = 14;
const L_SUB: usize = 16;
const L_PIECES: usize = L_BINADES * L_SUB;

/// One lookup row: `value = sum_k c[k] t^k`, `t = (x - xm) * inv_hw`.
#[derive(Clone, Copy)]
struct Row {
    xm: f64,
    inv_hw: f64,
    c: [f64; KN],
}

const ZERO_ROW: Row = Row {
    xm: 0.0,
    inv_hw: 0.0,
    c: [0.0; KN],
};

/// One piece of the partition in `a`, with what can be computed once per process.
struct Piece {
    a_lo: f64,
    a_hi: f64,
    /// Its bins, `first..end`.
    first: usize,
    end: usize,
    mid: f64,
    hw: f64,
    /// Node positions `a_j = mid + hw t_j` and `T(a_j)`.
    a: [f64; KN],
    ta: [f64; KN],
    /// Inside the band (`a_hi <= 0`): there `f` is small (`P` near 1) and interpolated
    /// directly, on `ln Q(a_j)`; elsewhere `h = f + a^2/2` is, on `T(a_j)`.
    interior: bool,
    /// `ln Q(a_j)` for an interior piece, else `T(a_j)`.
    base: [f64; KN],
    /// Coefficients of `f` when the far edge is negligible at every node: `ln Q(a)`.
    far: [f64; KN],
}

/// Nodes per block of the batched node evaluation.
const NODE_LANES: usize = 16;
/// Upper bound on the nodes one call evaluates through the process-wide tables (a multiple of
/// `NODE_LANES`).
const MAX_NODES: usize = 64 * 16;

/// Process-wide constants of the kernel, built on first use (~0.15 ms).
struct Kernel {
    /// Chebyshev nodes `t_j = cos((2j + 1) pi / (2 KN))`.
    tn: [f64; KN],
    /// `fit_t[j][k]`: monomial coefficient `k` of the interpolant of unit data at node `j`.
    fit_t: [[f64; KN]; KN],
    /// `T` pieces (`T_PIECES` used; a power of two allocated so that masked indices need no
    /// bounds checks).
    t_tab: Box<[[f64; KN]; 256]>,
    /// `L` pieces, as rows over `g = -d`: `t = (g - xm) inv_hw` (exact: a difference of
    /// nearby numbers times a power of two).
    l_tab: Box<[Row; 256]>,
    pieces: Vec<Piece>,
}

static KERNEL: OnceLock<Kernel> = OnceLock::new();

thread_local! {
    /// Per-thread cache of lookup tables (one per recently used band) and build scratch.
    static WORKSPACE: RefCell<Box<Workspace>> = RefCell::new(Workspace::new());
}

/// `sum_k c[k] t^k`.
#[inline(always)]
fn horner(c: &[f64; KN], t: f64) -> f64 {
    let mut p = c[KDEG];
    for k in (0..KDEG).rev() {
        p = p * t + c[k];
    }
    p
}

/// Particles per block of the per-particle loops: the Horner chains of a block run in lockstep,
/// which gives the out-of-order core enough independent work to hide their latency.
const LANES: usize = 16;

/// `p[i] = sum_k r.c[k] t^k`, `t = (x[i] - r.xm) r.inv_hw`, `r = rows[index(x[i])]`, for one
/// block of `L` arguments.
#[inline(always)]
fn eval_block<const L: usize>(
    rows: &[Row; 256],
    x: &[f64; L],
    index: impl Fn(f64) -> usize,
) -> [f64; L] {
    let r: [&Row; L] = std::array::from_fn(|k| &rows[index(x[k])]);
    let t: [f64; L] = std::array::from_fn(|k| (x[k] - r[k].xm) * r[k].inv_hw);
    let mut p: [f64; L] = std::array::from_fn(|k| r[k].c[KDEG]);
    for j in (0..KDEG).rev() {
        for k in 0..L {
            p[k] = p[k] * t[k] + r[k].c[j];
        }
    }
    p
}

/// `round(v)` for `v` in `[0, 255]` as an index (NaN-free input).
#[inline(always)]
fn round_index(v: f64) -> usize {
    ((v + MAGIC).to_bits() & 255) as usize
}

/// `round(v)` for `v` in `[0, 255]`, as an index and as a float.
#[inline(always)]
fn round_both(v: f64) -> (usize, f64) {
    let z = v + MAGIC;
    ((z.to_bits() & 255) as usize, z - MAGIC)
}

/// `v` clamped to `[0, hi]` by comparisons (a NaN becomes `hi`).
#[inline(always)]
fn clamp_to(v: f64, hi: f64) -> f64 {
    let v = if v > 0.0 { v } else { 0.0 };
    if v < hi {
        v
    } else {
        hi
    }
}

/// `T(y) = ln(e^{y^2/2} Q(y))`, accurately (the function the process-wide table holds).
fn ln_scaled_q_any(y: f64) -> f64 {
    if y >= 0.0 {
        ln_scaled_q(y)
    } else {
        log_q(y) + 0.5 * y * y
    }
}

/// `h = ln P + a^2/2` for the band of half-width `c > 0` around `x >= 0` (`a = x - c`), from
/// the accurate scalar functions, with the half-width exact (not recovered as a difference of
/// band limits): the node values of narrow bands, and a reference for the tests.
fn band_h(x: f64, c: f64) -> f64 {
    let a = x - c;
    if c * (x + 1.0) <= NARROW {
        // log phi(x) + ln(2c) + ln(1 + ...) + a^2/2, the a^2/2 cancelled analytically.
        let m2 = x * x;
        let h2 = c * c;
        let corr = (m2 - 1.0) * h2 / 6.0 + (m2 * m2 - 6.0 * m2 + 3.0) * h2 * h2 / 120.0;
        (0.5 * c - x) * c - LN_SQRT_2PI + (2.0 * c).ln() + corr.ln_1p()
    } else if a >= 0.0 {
        let ra = ln_scaled_q(a);
        let rb = ln_scaled_q(x + c);
        ra + log1mexp(-2.0 * x * c + (rb - ra))
    } else {
        (central_mass(-a) + central_mass(x + c)).ln() + 0.5 * a * a
    }
}

impl Kernel {
    fn get() -> &'static Kernel {
        KERNEL.get_or_init(Kernel::new)
    }

    fn new() -> Kernel {
        let n = KN as f64;
        let theta: [f64; KN] =
            std::array::from_fn(|j| (2 * j + 1) as f64 * std::f64::consts::PI / (2.0 * n));
        let tn = theta.map(f64::cos);
        // Monomial coefficients of the Chebyshev polynomials (small integers, exact).
        let mut cheb = [[0.0; KN]; KN];
        cheb[0][0] = 1.0;
        cheb[1][1] = 1.0;
        for m in 2..KN {
            for k in 0..KN {
                let up = if k > 0 { 2.0 * cheb[m - 1][k - 1] } else { 0.0 };
                cheb[m][k] = up - cheb[m - 2][k];
            }
        }
        // Interpolant's Chebyshev coefficient m of data v: w_m sum_j v_j cos(m theta_j).
        let mut fit_t = [[0.0; KN]; KN];
        for (j, row) in fit_t.iter_mut().enumerate() {
            for (k, e) in row.iter_mut().enumerate() {
                *e = (0..KN)
                    .map(|m| {
                        let w = if m == 0 { 1.0 / n } else { 2.0 / n };
                        cheb[m][k] * w * (m as f64 * theta[j]).cos()
                    })
                    .sum();
            }
        }
        let mut kernel = Kernel {
            tn,
            fit_t,
            t_tab: Box::new([[0.0; KN]; 256]),
            l_tab: Box::new([ZERO_ROW; 256]),
            pieces: Vec::new(),
        };
        let hw = 0.5 / T_SCALE;
        for i in 0..T_PIECES {
            let mid = T_LO + (i as f64 + 0.5) / T_SCALE;
            let v = tn.map(|t| ln_scaled_q_any(mid + hw * t));
            kernel.t_tab[i] = kernel.fit(&v);
        }
        for i in 0..L_PIECES {
            // Piece i: binade 2^e, sub-interval j; t = (g - mid) / hw = g 2^(5-e) - (33 + 2j),
            // exactly (a power-of-two scaling and a subtraction of nearby numbers).
            let e = L_EMIN + (i / L_SUB) as i32;
            let j = (i % L_SUB) as f64;
            let scale = 2f64.powi(5 - e);
            let off = 33.0 + 2.0 * j;
            let v = tn.map(|t| log1mexp(-(t + off) / scale));
            kernel.l_tab[i] = Row {
                xm: off / scale,
                inv_hw: scale,
                c: kernel.fit(&v),
            };
        }
        for &(lo, hi, w) in &SCHEDULE {
            let count = ((hi - lo) / w).round() as usize;
            for i in 0..count {
                let a_lo = lo + i as f64 * w;
                let a_hi = a_lo + w;
                let mid = 0.5 * (a_lo + a_hi);
                let hw = 0.5 * w;
                let a = tn.map(|t| mid + hw * t);
                let ta = a.map(ln_scaled_q_any);
                let interior = a_hi <= 0.0;
                let base = if interior { a.map(log_q) } else { ta };
                let far = kernel.fit_piece(interior, &base, mid, hw);
                kernel.pieces.push(Piece {
                    a_lo,
                    a_hi,
                    first: ((a_lo - A_LO) / BIN).round() as usize + 1,
                    end: ((a_hi - A_LO) / BIN).round() as usize + 1,
                    mid,
                    hw,
                    a,
                    ta,
                    interior,
                    base,
                    far,
                });
            }
        }
        debug_assert_eq!(kernel.pieces.last().map(|p| p.end), Some(CAP_ROW));
        debug_assert!(kernel.pieces.len() * KN <= MAX_NODES);
        kernel
    }

    /// Monomial coefficients in `t` of the degree-8 interpolant of `v` at the nodes `tn`. The
    /// interpolant's constant and linear Chebyshev parts are taken out first, so the rounding
    /// of the (growing) monomial conversion scales with the small remainder.
    fn fit(&self, v: &[f64; KN]) -> [f64; KN] {
        let b0 = v.iter().sum::<f64>() * (1.0 / KN as f64);
        let b1 = v.iter().zip(&self.tn).map(|(v, t)| v * t).sum::<f64>() * (2.0 / KN as f64);
        let r: [f64; KN] = std::array::from_fn(|j| v[j] - b0 - b1 * self.tn[j]);
        let mut c = [0.0; KN];
        for (fj, rj) in self.fit_t.iter().zip(&r) {
            for (ck, m) in c.iter_mut().zip(fj) {
                *ck += m * rj;
            }
        }
        c[0] += b0;
        c[1] += b1;
        c
    }

    /// Coefficients of `f` on a piece `a = mid + hw t` from node values of `f` (interior) or
    /// of `h = f + a^2/2` (then `-a(t)^2/2` is added exactly to the coefficients).
    fn fit_piece(&self, interior: bool, v: &[f64; KN], mid: f64, hw: f64) -> [f64; KN] {
        let mut c = self.fit(v);
        if !interior {
            c[0] -= 0.5 * mid * mid;
            c[1] -= mid * hw;
            c[2] -= 0.5 * hw * hw;
        }
        c
    }

    /// `T(y)` from the table, for `y` in `[0, 42)` (it extrapolates a little beyond).
    #[inline(always)]
    fn t_lookup(&self, y: f64) -> f64 {
        let u = (y - T_LO) * T_SCALE - 0.5;
        let (i, k) = round_both(clamp_to(u, (T_PIECES - 1) as f64));
        horner(&self.t_tab[i], 2.0 * (u - k))
    }

    /// The row of the `L` table for `g` in `[2^-7, 2^7)` (from its exponent and leading
    /// mantissa bits; clamped to the table outside).
    #[inline(always)]
    fn l_index(g: f64) -> usize {
        let bin = (g.to_bits() >> 48) as i64 - (((1023 + L_EMIN) as i64) << 4);
        bin.clamp(0, L_PIECES as i64 - 1) as usize
    }

    /// `base + L(-g)` at nodes `a` with `ta = T(a)`, for a band of half-width
    /// `c >= FAST_C_MIN`: the far edges `T(b)`, `b = a + 2c`, and then `L(-g)`,
    /// `g = 2xc + T(a) - T(b)`, come from the tables in blocks of `NODE_LANES` run in lockstep
    /// (like the per-particle loop). Nodes with `2xc >= FAR` keep `base`. The length is a
    /// multiple of `NODE_LANES`.
    fn nodes(&self, a: &[f64], ta: &[f64], base: &[f64], c: f64, h: &mut [f64]) {
        const L: usize = NODE_LANES;
        let blocks = a
            .chunks_exact(L)
            .zip(ta.chunks_exact(L))
            .zip(base.chunks_exact(L))
            .zip(h.chunks_exact_mut(L));
        for (((a, ta), base), h) in blocks {
            let mut ti = [0usize; L];
            let mut tt = [0.0; L];
            for k in 0..L {
                let u = (a[k] + 2.0 * c - T_LO) * T_SCALE - 0.5;
                let (i, kf) = round_both(clamp_to(u, (T_PIECES - 1) as f64));
                ti[k] = i;
                tt[k] = 2.0 * (u - kf);
            }
            let mut tb: [f64; L] = std::array::from_fn(|k| self.t_tab[ti[k]][KDEG]);
            for j in (0..KDEG).rev() {
                for k in 0..L {
                    tb[k] = tb[k] * tt[k] + self.t_tab[ti[k]][j];
                }
            }
            let two_xc: [f64; L] = std::array::from_fn(|k| 2.0 * (a[k] + c) * c);
            let g: [f64; L] = std::array::from_fn(|k| two_xc[k] + (ta[k] - tb[k]));
            let l = eval_block(&self.l_tab, &g, Kernel::l_index);
            for k in 0..L {
                h[k] = if two_xc[k] >= FAR {
                    base[k]
                } else {
                    base[k] + l[k]
                };
            }
        }
    }

    /// Fills `rows` with the table of `f = ln P` for half-width `c` (`0 < c <= KERNEL_C_MAX`),
    /// against `|mu| = x / s` (the rows' centres and scales are divided and multiplied by `s`,
    /// which saves the particles the multiplication `mu s`).
    fn build(&self, c: f64, s: f64, w: &mut BuildScratch, rows: &mut [Row; TABLE_ROWS]) {
        let fast = c >= FAST_C_MIN;
        let np = self.pieces.len();
        // Pass 1: which pieces need node values; those of the batched kind are gathered for one
        // evaluation through the tables. Kinds: 0 only x < 0 (unused), 1 far edge negligible
        // (coefficients fitted once), 2 batched nodes, 3 nodes placed and evaluated here (the
        // piece holding x = 0, clipped to x >= 0, and every piece of a narrow band).
        let mut nn = 0;
        for (p, kd) in self.pieces.iter().zip(w.kind.iter_mut()) {
            *kd = if p.a_hi <= -c {
                0
            } else if p.a_lo < -c || !fast {
                3
            } else if 2.0 * (p.a_lo + c) * c >= FAR {
                1
            } else {
                w.na[nn..nn + KN].copy_from_slice(&p.a);
                w.nta[nn..nn + KN].copy_from_slice(&p.ta);
                w.nbase[nn..nn + KN].copy_from_slice(&p.base);
                nn += KN;
                2
            };
        }
        // Pad to whole blocks with copies of a harmless node.
        let padded = nn.div_ceil(NODE_LANES) * NODE_LANES;
        w.na[nn..padded].fill(0.0);
        w.nta[nn..padded].fill(0.0);
        w.nbase[nn..padded].fill(0.0);
        let (na, nta, nbase) = (&w.na[..padded], &w.nta[..padded], &w.nbase[..padded]);
        self.nodes(na, nta, nbase, c, &mut w.nh[..padded]);
        // Pass 2: each piece's row.
        let mut next = 0;
        for (i, p) in self.pieces.iter().enumerate() {
            w.piece_rows[i] = match w.kind[i] {
                0 => ZERO_ROW,
                1 => Row {
                    xm: p.mid + c,
                    inv_hw: 1.0 / p.hw,
                    c: p.far,
                },
                2 => {
                    let h: [f64; KN] = std::array::from_fn(|j| w.nh[next + j]);
                    next += KN;
                    Row {
                        xm: p.mid + c,
                        inv_hw: 1.0 / p.hw,
                        c: self.fit_piece(p.interior, &h, p.mid, p.hw),
                    }
                }
                _ => {
                    let x_lo = (p.a_lo + c).max(0.0);
                    let x_hi = p.a_hi + c;
                    let xm = 0.5 * (x_lo + x_hi);
                    let hw = 0.5 * (x_hi - x_lo);
                    let interior = fast && p.interior;
                    let h = if fast {
                        let mut a = [0.0; NODE_LANES];
                        let mut ta = [0.0; NODE_LANES];
                        let mut base = [0.0; NODE_LANES];
                        for j in 0..KN {
                            a[j] = xm + hw * self.tn[j] - c;
                            if a[j] < 0.0 {
                                let lq = log_q(a[j]);
                                ta[j] = lq + 0.5 * a[j] * a[j];
                                base[j] = if interior { lq } else { ta[j] };
                            } else {
                                ta[j] = self.t_lookup(a[j]);
                                base[j] = ta[j];
                            }
                        }
                        let mut h = [0.0; NODE_LANES];
                        self.nodes(&a, &ta, &base, c, &mut h);
                        std::array::from_fn(|j| h[j])
                    } else {
                        self.tn.map(|t| band_h(xm + hw * t, c))
                    };
                    Row {
                        xm,
                        inv_hw: 1.0 / hw,
                        c: self.fit_piece(interior, &h, xm - c, hw),
                    }
                }
            };
        }
        // Pass 3: the bins, in units of mu.
        for (r, &kd) in w.piece_rows.iter_mut().zip(&w.kind) {
            if kd != 0 {
                r.xm /= s;
                r.inv_hw *= s;
            }
        }
        rows[0] = ZERO_ROW;
        let mut first = np;
        for (i, p) in self.pieces.iter().enumerate() {
            if w.kind[i] != 0 {
                first = first.min(i);
                rows[p.first..p.end].fill(w.piece_rows[i]);
            }
        }
        // A particle at x = 0 exactly on a bin boundary may round into the bin below the first
        // piece: give that bin the first piece too (it extrapolates by rounding errors only).
        let first_bin = self.pieces[first].first;
        if first_bin > 1 {
            rows[first_bin - 1] = w.piece_rows[first];
        }
        // Beyond A_CAP: the quadratic Taylor polynomial of the last piece at its end (t = 1).
        let last = &w.piece_rows[np - 1];
        let lc = &last.c;
        let p0: f64 = lc.iter().sum();
        let p1: f64 = (1..KN).map(|k| k as f64 * lc[k]).sum();
        let p2: f64 = (2..KN).map(|k| (k * (k - 1)) as f64 * lc[k]).sum();
        let mut cap = [0.0; KN];
        cap[0] = p0;
        cap[1] = p1;
        cap[2] = 0.5 * p2;
        rows[CAP_ROW] = Row {
            xm: (A_CAP + c) / s,
            inv_hw: last.inv_hw,
            c: cap,
        };
    }
}

/// Most pieces a partition may have.
const MAX_PIECES: usize = 64;

/// Tables a thread keeps. A table is a deterministic function of its band `(c, s)`, so a
/// cached one is exactly the one a rebuild would give. A particle filter calls the kernel
/// with the same few bands again and again: once its covariances have converged, and, with
/// linear sensors, in every trial (the local covariances follow the same sequence in each),
/// so a few dozen tables remove nearly every rebuild. 32 tables are 720 KB per thread.
const CACHED_TABLES: usize = 32;

/// One cached table and when it was last used.
struct CachedTable {
    /// Bit patterns of the band `(c, s)` it was built for.
    key: (u64, u64),
    last_used: u64,
    rows: Box<[Row; TABLE_ROWS]>,
}

/// Scratch space of a table's construction.
struct BuildScratch {
    piece_rows: [Row; MAX_PIECES],
    kind: [u8; MAX_PIECES],
    na: [f64; MAX_NODES],
    nta: [f64; MAX_NODES],
    nbase: [f64; MAX_NODES],
    nh: [f64; MAX_NODES],
}

/// A thread's cached tables and build scratch, reused by every call.
struct Workspace {
    scratch: BuildScratch,
    tables: Vec<CachedTable>,
    clock: u64,
}

impl Workspace {
    fn new() -> Box<Workspace> {
        Box::new(Workspace {
            scratch: BuildScratch {
                piece_rows: [ZERO_ROW; MAX_PIECES],
                kind: [0; MAX_PIECES],
                na: [0.0; MAX_NODES],
                nta: [0.0; MAX_NODES],
                nbase: [0.0; MAX_NODES],
                nh: [0.0; MAX_NODES],
            },
            tables: Vec::with_capacity(CACHED_TABLES),
            clock: 0,
        })
    }

    /// The table for half-width `c` and scale `s`: a cached one, or one built into a new slot
    /// or in place of the least recently used.
    fn table(&mut self, kernel: &Kernel, c: f64, s: f64) -> &[Row; TABLE_ROWS] {
        self.clock += 1;
        let key = (c.to_bits(), s.to_bits());
        let slot = match self.tables.iter().position(|t| t.key == key) {
            Some(i) => i,
            None => {
                let i = if self.tables.len() < CACHED_TABLES {
                    self.tables.push(CachedTable {
                        key,
                        last_used: 0,
                        rows: Box::new([ZERO_ROW; TABLE_ROWS]),
                    });
                    self.tables.len() - 1
                } else {
                    (0..self.tables.len())
                        .min_by_key(|&i| self.tables[i].last_used)
                        .unwrap_or(0)
                };
                let t = &mut self.tables[i];
                kernel.build(c, s, &mut self.scratch, &mut t.rows);
                t.key = key;
                i
            }
        };
        let t = &mut self.tables[slot];
        t.last_used = self.clock;
        &t.rows
    }
}

/// The per-particle loop: `out[p] += f(|h[p] - center| s)` from the table built for half-width
/// `c` and scale `s`.
fn add_from_table(
    rows: &[Row; TABLE_ROWS],
    h: &[f64],
    center: f64,
    s: f64,
    c: f64,
    out: &mut [f64],
) {
    // Particles left of bin 1 (a < -9) exist only when c > 9.
    if c > -A_LO {
        add_from_table_clamped::<true>(rows, h, center, s, c, out);
    } else {
        add_from_table_clamped::<false>(rows, h, center, s, c, out);
    }
}

/// [`add_from_table`], with the row index clamped below at 0 when `LOWER` (else `c <= 9` makes
/// it at least 0 for every `x >= 0`). Compiled also for AVX2 and picked at run time: the
/// same IEEE operations on wider registers (no FMA contraction), so the results are
/// bit-identical on every x86-64 machine.
#[multiversion(targets("x86_64+avx2"))]
fn add_from_table_clamped<const LOWER: bool>(
    rows: &[Row; TABLE_ROWS],
    h: &[f64],
    center: f64,
    s: f64,
    c: f64,
    out: &mut [f64],
) {
    // Row index round(y): y = (x - c - A_LO) / BIN + 1/2 with x = |mu| s, clamped to
    // [0, CAP_ROW]. The clamps are comparisons, not f64::min/max, and keep a NaN: a NaN
    // particle lands in the cap row, whose polynomial at t = NaN is NaN.
    let scale = s / BIN;
    let off = (-c - A_LO) / BIN + 0.5;
    let cap = CAP_ROW as f64;
    let index = |x: f64| {
        let y = x * scale + off;
        let y = if LOWER && y < 0.0 { 0.0 } else { y };
        round_index(if y < cap { y } else { cap })
    };
    let x_max = KERNEL_X_MAX / s;
    // mu = h - center is formed here, not in a pass of its own.
    let position = |m: f64| {
        let x = (m - center).abs();
        if x > x_max {
            x_max
        } else {
            x
        }
    };
    let mut oc = out.chunks_exact_mut(LANES);
    let mut mc = h.chunks_exact(LANES);
    for (o, m) in (&mut oc).zip(&mut mc) {
        let x: [f64; LANES] = std::array::from_fn(|k| position(m[k]));
        let p = eval_block(rows, &x, index);
        for k in 0..LANES {
            o[k] += p[k];
        }
    }
    for (o, &m) in oc.into_remainder().iter_mut().zip(mc.remainder()) {
        let p = eval_block(rows, &[position(m)], index);
        *o += p[0];
    }
}

/// The kernel's reference loop (and its fallback): `log_q_band` per particle.
fn add_log_band_probability_scalar(
    h: &[f64],
    center: f64,
    half_width: f64,
    inv_sd: f64,
    out: &mut [f64],
) {
    for (o, m) in out.iter_mut().zip(h) {
        let mu = m - center;
        *o += log_q_band((-half_width - mu) * inv_sd, (half_width - mu) * inv_sd);
    }
}

/// Seed 000's censored-sensor likelihood over many particles: for each `mu[p]` (the
/// innovation mean h(x_p) - h(x_ref)), adds `log(Phi((c - mu) s) - Phi((-c - mu) s))` to
/// `out[p]`, with `c = sqrt(eta s_k)` the half-width of the no-send band and `s = 1/sqrt(r)`
/// (eq. (9), (14), (44), (45): `Q(xi_1) - Q(xi_2)`). This is the particle filter's hot loop.
///
/// A call tabulates `ln P` against `|mu|` for its band (1-3 us; see the notes above the
/// kernel's constants; the thread keeps the tables of its 32 most recently used bands) and
/// then costs a table lookup and a degree-8 polynomial per particle, ~2.5 ns instead of the
/// ~35 ns of [`log_q_band`].
///
/// Accuracy, against [`log_q_band`]: the log is good to ~3e-13 absolute wherever the band
/// probability is at least 1e-300 (`|mu| s` up to `c s + 37`), narrow bands included (checked
/// down to `c s = 5e-4`). Where it is smaller the result is a large negative finite number,
/// decreasing in `|mu|`, within 1% of the true log up to `|mu| s = c s + 1000`; particles with
/// `|mu| s >= 1e150` (also infinite ones) get the value at `1e150`, about `-5e299`. A NaN `mu`
/// gives NaN. Slices shorter than 64, and bands that are empty, not finite, wider than 1e6 sd
/// or with `s` outside `[1e-100, 1e100]`, take the scalar [`log_q_band`] per particle.
///
/// # Panics
/// If the slices differ in length.
pub fn add_log_band_probability(mu: &[f64], half_width: f64, inv_sd: f64, out: &mut [f64]) {
    add_log_band_probability_about(mu, 0.0, half_width, inv_sd, out);
}

/// [`add_log_band_probability`] with `mu[p] = h[p] - center` formed inside the kernel (the
/// predicted measurements of the particles and that of the reference point): the same
/// numbers, without a pass over the particles to subtract `center` first.
///
/// # Panics
/// If the slices differ in length.
pub fn add_log_band_probability_about(
    h: &[f64],
    center: f64,
    half_width: f64,
    inv_sd: f64,
    out: &mut [f64],
) {
    assert_eq!(
        h.len(),
        out.len(),
        "add_log_band_probability: slice lengths differ"
    );
    let c = half_width * inv_sd;
    let usable =
        half_width > 0.0 && (1e-100..=1e100).contains(&inv_sd) && c > 0.0 && c <= KERNEL_C_MAX;
    if !usable || h.len() < KERNEL_MIN_LEN {
        add_log_band_probability_scalar(h, center, half_width, inv_sd, out);
        return;
    }
    let kernel = Kernel::get();
    WORKSPACE.with(|w| {
        let mut w = w.borrow_mut();
        add_from_table(w.table(kernel, c, inv_sd), h, center, inv_sd, c, out);
    });
}

#[cfg(test)]
mod kernel_tests {
    use super::*;

    /// `ln(1e-300)`: below it the band probability is not required to be accurate.
    const LN_1E300: f64 = -690.775_527_898_213_7;
    /// The accuracy required where the band probability is at least 1e-300.
    const TOL: f64 = 1e-12;

    fn kernel(mu: &[f64], c: f64, s: f64) -> Vec<f64> {
        let mut out = vec![0.0; mu.len()];
        add_log_band_probability(mu, c, s, &mut out);
        out
    }

    fn reference(mu: &[f64], c: f64, s: f64) -> Vec<f64> {
        let mut out = vec![0.0; mu.len()];
        add_log_band_probability_scalar(mu, 0.0, c, s, &mut out);
        out
    }

    /// Largest `|got - want|` where `want >= ln 1e-300`; also checks that every value is
    /// finite and not above 0 by more than rounding.
    fn worst_error(mu: &[f64], got: &[f64], want: &[f64], what: &str) -> f64 {
        let mut worst: f64 = 0.0;
        for ((&m, &g), &w) in mu.iter().zip(got).zip(want) {
            assert!(g.is_finite() && g <= 1e-15, "{what}, mu = {m}: {g}");
            if w >= LN_1E300 {
                worst = worst.max((g - w).abs());
            }
        }
        worst
    }

    #[test]
    fn matches_log_q_band_on_a_dense_grid_of_exact_inputs() {
        // mu on a grid of multiples of 2^-7 out to +-60, half-widths multiples of 2^-10 from
        // 2^-10 to ~16 (steps of 2^(1/4)), s a power of two: the reference's inputs
        // (-c - mu) s and (c - mu) s are then exact, so it is accurate even for narrow bands
        // far out (where a rounded band width would cost it ulp(mu) / 2c relative).
        let mu: Vec<f64> = (-60 * 128..=60 * 128).map(|i| i as f64 / 128.0).collect();
        let mut worst: f64 = 0.0;
        for i in 0..=56 {
            let c = (2f64.powf(-10.0 + 0.25 * i as f64) * 1024.0).round() / 1024.0;
            for s in [0.5, 1.0, 2.0] {
                let what = format!("c = {c}, s = {s}");
                let e = worst_error(&mu, &kernel(&mu, c, s), &reference(&mu, c, s), &what);
                assert!(e <= TOL, "{what}: error {e:e}");
                worst = worst.max(e);
            }
        }
        // What is achieved (2.3e-13 when written), with margin.
        assert!(worst < 4e-13, "worst error {worst:e}");
    }

    #[test]
    fn matches_the_exact_band_for_rounded_inputs() {
        // Generic s and c: the reference's own inputs are rounded, which moves its log by up to
        // ~|a| ulp(mu); the kernel (which sees |mu| and c s) is compared against band_h at
        // x = |mu| s, c s instead, and against log_q_band with the input rounding allowed.
        let mu: Vec<f64> = (0..20_000)
            .map(|i| -50.0 + i as f64 * 0.005_000_37)
            .collect();
        for (c, s) in [
            (0.1, 1.0),
            (0.7, 1.0 / 3f64.sqrt()),
            (1.3, 0.83),
            (2.9, 1.71),
            (4.99, 0.5),
            (0.003, 1.9),
            (0.013, 0.77),
        ] {
            let got = kernel(&mu, c, s);
            let want = reference(&mu, c, s);
            let cs = c * s;
            for ((&m, &g), &w) in mu.iter().zip(&got).zip(&want) {
                assert!(g.is_finite(), "c = {c}, s = {s}, mu = {m}: {g}");
                let x = (m * s).abs();
                let a = x - cs;
                let exact = band_h(x, cs) - 0.5 * a * a;
                if exact >= LN_1E300 {
                    assert!(
                        (g - exact).abs() <= TOL,
                        "c {c} s {s} mu {m}: {g} vs {exact}"
                    );
                    let input_rounding = 4.0 * (a.abs() + 1.0) * f64::EPSILON * (m.abs() + c) * s;
                    assert!(
                        (g - w).abs() <= TOL + input_rounding,
                        "c {c} s {s} mu {m}: {g} vs log_q_band {w}"
                    );
                }
            }
        }
    }

    #[test]
    fn bin_boundaries_and_the_band_centre() {
        // Particles exactly on bin and piece boundaries, at mu = 0, and half-widths on the bin
        // grid (so that x = 0 falls on a boundary): rounding may pick either neighbouring row.
        for c in [0.375, 0.75, 1.5, 3.0, 9.0, 9.375, 12.0, 0.1, 1.0] {
            let mut mu: Vec<f64> = (0..=140)
                .map(|k| c + A_LO + k as f64 * BIN)
                .filter(|&x| x >= 0.0)
                .flat_map(|x| [x, -x, x * (1.0 + 1e-15), x * (1.0 - 1e-15)])
                .collect();
            mu.extend([0.0, -0.0, 1e-300, c, -c]);
            mu.resize(mu.len().max(KERNEL_MIN_LEN), 0.5);
            let e = worst_error(&mu, &kernel(&mu, c, 1.0), &reference(&mu, c, 1.0), "");
            assert!(e <= TOL, "c = {c}: {e:e}");
        }
    }

    #[test]
    fn far_tails_are_finite_decreasing_and_close() {
        for (c, s) in [
            (0.05, 1.0),
            (1.0, 1.0),
            (3.0, 2.0),
            (20.0, 1.0),
            (0.004, 1.0),
        ] {
            let mu: Vec<f64> = (0..4000).map(|i| i as f64 * 0.25).collect();
            let got = kernel(&mu, c, s);
            let want = reference(&mu, c, s);
            for i in 1..mu.len() {
                // Non-increasing (strictly, where P is not within rounding of 1).
                let d = got[i] - got[i - 1];
                assert!(
                    d < 0.0 || (d <= 1e-15 && got[i] > -1e-12),
                    "c {c}: not decreasing"
                );
                if want[i] < LN_1E300 {
                    let rel = ((got[i] - want[i]) / want[i]).abs();
                    assert!(rel < 0.01, "c {c}, mu {}: {} vs {}", mu[i], got[i], want[i]);
                }
            }
        }
        // Astronomically far particles: large, negative, finite; NaN stays NaN.
        let mut mu = vec![0.0; KERNEL_MIN_LEN];
        let far = [
            1e100,
            -1e149,
            1e150,
            1e200,
            f64::MAX,
            -f64::MAX,
            f64::INFINITY,
        ];
        mu[..far.len()].copy_from_slice(&far);
        mu[10] = f64::NAN;
        for s in [1.0, 1e-90, 1e90] {
            let got = kernel(&mu, 1.0 / s, s);
            for (m, g) in far.iter().zip(&got) {
                assert!(
                    g.is_finite() && *g < -1e100 * s.min(1.0),
                    "mu {m}, s {s}: {g}"
                );
            }
            assert!(got[10].is_nan());
        }
        let got = kernel(&mu, 1.0, 1.0);
        assert!(got[0] > got[2] && got[2] < -4e299);
        assert!(got[2] == got[3] && got[3] == got[4] && got[4] == got[6]);
    }

    #[test]
    fn symmetric_additive_and_thread_safe() {
        let mu: Vec<f64> = (0..1000).map(|i| (i as f64 - 500.0) * 0.0731).collect();
        let neg: Vec<f64> = mu.iter().map(|m| -m).collect();
        assert_eq!(kernel(&mu, 1.7, 0.9), kernel(&neg, 1.7, 0.9));
        let mut out: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        add_log_band_probability(&mu, 1.7, 0.9, &mut out);
        let plain = kernel(&mu, 1.7, 0.9);
        for (i, (o, p)) in out.iter().zip(&plain).enumerate() {
            assert_eq!(*o, i as f64 + p);
        }
        // Each thread has its own table.
        let handles: Vec<_> = (0..4)
            .map(|t| {
                let mu = mu.clone();
                std::thread::spawn(move || {
                    let c = 0.3 + t as f64;
                    for _ in 0..50 {
                        let got = kernel(&mu, c, 1.0);
                        let e = worst_error(&mu, &got, &reference(&mu, c, 1.0), "");
                        assert!(e <= TOL);
                    }
                })
            })
            .collect();
        for h in handles {
            h.join().unwrap();
        }
    }

    #[test]
    fn short_slices_and_degenerate_bands_take_the_scalar_path() {
        let mu: Vec<f64> = (0..KERNEL_MIN_LEN - 1)
            .map(|i| i as f64 * 0.37 - 9.0)
            .collect();
        assert_eq!(kernel(&mu, 1.0, 1.0), reference(&mu, 1.0, 1.0));
        let mu: Vec<f64> = (0..200).map(|i| i as f64 * 0.37 - 30.0).collect();
        for (c, s) in [
            (0.0, 1.0),
            (-1.0, 1.0),
            (1.0, -1.0),
            (1.0, 0.0),
            (f64::NAN, 1.0),
            (1.0, f64::INFINITY),
            (1e7, 1.0),
            (1.0, 1e-101),
        ] {
            let (got, want) = (kernel(&mu, c, s), reference(&mu, c, s));
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    g == w || (g.is_nan() && w.is_nan()),
                    "c {c} s {s}: {g} vs {w}"
                );
            }
        }
        assert!(kernel(&mu, 0.0, 1.0)
            .iter()
            .all(|&v| v == f64::NEG_INFINITY));
    }

    #[test]
    fn centering_inside_the_kernel_changes_no_bit() {
        // Both the table path (>= 64 particles) and the scalar fallback (fewer).
        for len in [40usize, 3000] {
            let h: Vec<f64> = (0..len)
                .map(|i| 7.3 + (i as f64 * 0.731).sin() * 9.0)
                .collect();
            let center = 7.9;
            let mu: Vec<f64> = h.iter().map(|v| v - center).collect();
            for (c, s) in [(0.8, 1.0), (2.5, 0.6), (0.004, 3.0)] {
                let mut a = vec![0.5; len];
                let mut b = vec![0.5; len];
                add_log_band_probability(&mu, c, s, &mut a);
                add_log_band_probability_about(&h, center, c, s, &mut b);
                assert_eq!(a, b, "len {len}, c {c}, s {s}");
            }
        }
    }

    #[test]
    fn cached_tables_equal_fresh_ones_through_evictions() {
        // More bands than the cache holds, visited twice in an order that evicts every one:
        // the second visit (rebuilt or cached) must give the first visit's values bit for bit,
        // and each must equal a table built from scratch.
        let mu: Vec<f64> = (0..2000).map(|i| -20.0 + i as f64 * 0.02).collect();
        let bands: Vec<(f64, f64)> = (0..CACHED_TABLES + 7)
            .map(|i| (0.05 + 0.37 * i as f64, 1.0 / (1.0 + 0.1 * i as f64)))
            .collect();
        let first: Vec<Vec<f64>> = bands.iter().map(|&(c, s)| kernel(&mu, c, s)).collect();
        for round in 0..2 {
            for (b, &(c, s)) in bands.iter().enumerate().rev() {
                assert_eq!(kernel(&mu, c, s), first[b], "round {round}, band {b}");
            }
        }
        let k = Kernel::get();
        let mut scratch = Workspace::new();
        for (b, &(c, s)) in bands.iter().enumerate() {
            let mut rows = Box::new([ZERO_ROW; TABLE_ROWS]);
            let c_sd = c * s;
            k.build(c_sd, s, &mut scratch.scratch, &mut rows);
            let mut fresh = vec![0.0; mu.len()];
            add_from_table(&rows, &mu, 0.0, s, c_sd, &mut fresh);
            assert_eq!(fresh, first[b], "band {b}");
        }
    }

    #[test]
    #[should_panic]
    fn rejects_length_mismatch() {
        add_log_band_probability(&[0.0; 100], 1.0, 1.0, &mut [0.0; 99]);
    }

    #[test]
    fn process_wide_tables_are_accurate() {
        let k = Kernel::get();
        for i in 0..=50_000 {
            let y = i as f64 * (42.0 / 50_000.0);
            let (got, want) = (k.t_lookup(y), ln_scaled_q_any(y));
            assert!((got - want).abs() <= 1e-15 * want.abs().max(1.0), "T({y})");
        }
        for i in 0..=50_000 {
            let g = 2f64.powf(-6.9 + i as f64 * 13.8 / 50_000.0);
            let l = eval_block(&k.l_tab, &[g], Kernel::l_index)[0];
            let want = log1mexp(-g);
            assert!(
                (l - want).abs() <= 5e-16 * want.abs().max(1.0),
                "L({g}): {l} vs {want}"
            );
        }
    }
}
