//! The vectorized slice loops the particle cloud is made of: `axpy`-style updates, the
//! gather of resampled states, lane-parallel reductions (maximum, dot product) with a fixed
//! summation order, and the branch-free exponential of the weight normalization. The loops are
//! plain loops over slices, compiled also for AVX2 and picked at run time (`multiversion`):
//! the same IEEE operations in the same order on wider registers, so results are bit-identical
//! on every x86-64 machine. Separate from `cloud` because they are the hot inner loops, written
//! for the vectorizer rather than for the reader of the filter.
use multiversion::multiversion;

/// `y += a x`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// `y = a x`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn scale_into(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi = a * xi;
    }
}

/// `w_i *= inv_s` and `l_i = (l_i - m) - ln_s`: the weights and log-weights after dividing
/// by their sum. `(l - m)` first: exact for the particles that matter (Sterbenz), so
/// normalized log-weights keep full relative precision even when the raw ones are ~1e3.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn normalize_in_place(w: &mut [f64], l: &mut [f64], inv_s: f64, m: f64, ln_s: f64) {
    for (w, l) in w.iter_mut().zip(l.iter_mut()) {
        *w *= inv_s;
        *l = (*l - m) - ln_s;
    }
}

/// `y = x + a`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn shift_into(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi = xi + a;
    }
}

/// `z = x * y` elementwise.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn mul_into(x: &[f64], y: &[f64], z: &mut [f64]) {
    for ((zi, xi), yi) in z.iter_mut().zip(x).zip(y) {
        *zi = xi * yi;
    }
}

/// `dst[k] = src[index[k]]`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn gather(src: &[f64], index: &[usize], dst: &mut [f64]) {
    for (d, &a) in dst.iter_mut().zip(index) {
        *d = src[a];
    }
}

/// Lanes for the reductions below: independent accumulators break the serial dependency of a
/// floating-point sum (which the compiler may not reorder) and map onto SIMD registers. The
/// summation order is fixed, so results are bit-reproducible.
const LANES: usize = 8;

/// Sum of the lane accumulators in the order that matches how they sit in SIMD registers
/// (pairs `k, k + 1`): the compiler then keeps the loop in vector form instead of shuffling
/// lanes every iteration (1.5x faster than `acc.iter().sum()`).
#[inline(always)]
fn reduce_lanes(acc: [f64; LANES]) -> f64 {
    ((acc[0] + acc[4]) + (acc[2] + acc[6])) + ((acc[1] + acc[5]) + (acc[3] + acc[7]))
}

/// Largest element; NaNs are ignored (they are caught later by the sum they poison).
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn max_lanes(x: &[f64]) -> f64 {
    let mut acc = [f64::NEG_INFINITY; LANES];
    let mut chunks = x.chunks_exact(LANES);
    for c in &mut chunks {
        for k in 0..LANES {
            acc[k] = if c[k] > acc[k] { c[k] } else { acc[k] };
        }
    }
    chunks
        .remainder()
        .iter()
        .chain(acc.iter())
        .fold(f64::NEG_INFINITY, |m, &v| if v > m { v } else { m })
}

/// `sum_i x_i y_i`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn dot_lanes(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0; LANES];
    let mut xc = x.chunks_exact(LANES);
    let mut yc = y.chunks_exact(LANES);
    for (a, b) in (&mut xc).zip(&mut yc) {
        for k in 0..LANES {
            acc[k] += a[k] * b[k];
        }
    }
    let tail: f64 = xc
        .remainder()
        .iter()
        .zip(yc.remainder())
        .map(|(a, b)| a * b)
        .sum();
    reduce_lanes(acc) + tail
}

/// `out_i = exp(l_i - m)`, returning `sum_i out_i`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn exp_shifted_into(l: &[f64], m: f64, out: &mut [f64]) -> f64 {
    let mut acc = [0.0; LANES];
    let mut oc = out.chunks_exact_mut(LANES);
    let mut lc = l.chunks_exact(LANES);
    for (o, x) in (&mut oc).zip(&mut lc) {
        for k in 0..LANES {
            o[k] = exp_nonpositive(x[k] - m);
            acc[k] += o[k];
        }
    }
    let mut tail = 0.0;
    for (o, x) in oc.into_remainder().iter_mut().zip(lc.remainder()) {
        *o = exp_nonpositive(x - m);
        tail += *o;
    }
    reduce_lanes(acc) + tail
}

/// `exp(x)` for `x <= 0`, branch-free so that loops over it vectorize (libm's `exp` is an
/// opaque call). Range reduction `x = k ln 2 + r`, `|r| <= ln 2 / 2` (Cody–Waite split of
/// `ln 2`), the degree-12 Taylor polynomial of `exp(r)` (truncation below 2e-16) evaluated by
/// Estrin's scheme (short dependency chains), and `2^k` built in the exponent bits. Relative
/// error within a few ulp (tested against libm). Returns 0 below -708 (where `2^k` would be
/// subnormal; such weights are below 1e-307 of the largest), 0 for `-inf`, NaN for NaN.
#[inline(always)]
fn exp_nonpositive(x: f64) -> f64 {
    // 1.5 * 2^52: adding it rounds to an integer and leaves that integer in the low bits.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    // fdlibm's split of ln 2: LN2_HI has trailing zero bits, so k * LN2_HI is exact.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    let t = x * std::f64::consts::LOG2_E + SHIFTER;
    let k = t - SHIFTER;
    let r = x - k * LN2_HI - k * LN2_LO;
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let p01 = 1.0 + r;
    let p23 = 0.5 + r * (1.0 / 6.0);
    let p45 = 1.0 / 24.0 + r * (1.0 / 120.0);
    let p67 = 1.0 / 720.0 + r * (1.0 / 5040.0);
    let p89 = 1.0 / 40_320.0 + r * (1.0 / 362_880.0);
    let p1011 = 1.0 / 3_628_800.0 + r * (1.0 / 39_916_800.0);
    let p12 = 1.0 / 479_001_600.0;
    let lo = (p01 + p23 * r2) + (p45 + p67 * r2) * r4;
    let hi = (p89 + p1011 * r2) + p12 * r4;
    let p = lo + hi * r8;
    // The low bits of t hold k + SHIFTER's mantissa; rebias to k + 1023 and shift into the
    // exponent field.
    let two_k = f64::from_bits(
        t.to_bits()
            .wrapping_add(1023u64.wrapping_sub(SHIFTER.to_bits()))
            << 52,
    );
    let y = p * two_k;
    if x < -708.0 {
        0.0
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::rng;
    use super::*;
    use rand::Rng;

    #[test]
    fn vectorized_exp_matches_libm() {
        let mut r = rng(1);
        let mut worst = 0.0_f64;
        for i in 0..200_000 {
            let x = -(i as f64) * 708.0 / 200_000.0 - 1e-3 * r.random::<f64>();
            let (e, c) = (x.exp(), exp_nonpositive(x));
            worst = worst.max(((c - e) / e).abs());
        }
        // A few ulp: the polynomial truncates below 2e-16 and the reduction adds one rounding.
        assert!(worst < 8.0 * f64::EPSILON, "worst relative error {worst:e}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-0.0), 1.0);
        assert_eq!(exp_nonpositive(-750.0), 0.0);
        assert_eq!(exp_nonpositive(f64::NEG_INFINITY), 0.0);
        assert!(exp_nonpositive(f64::NAN).is_nan());
    }
}
