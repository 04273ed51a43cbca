//! The vectorized slice loops the particle cloud is made of: `axpy`-style updates and the
//! propagation `F x + L z` in one blocked pass, the gather of resampled states, lane-parallel
//! reductions (maximum, dot product, the weighted mean and covariance, the ESS's sum of squares
//! inside the normalization) with a fixed summation order, and the branch-free exponential of
//! the weight normalization. The fused loops give the bits of the separate passes they replace
//! (the same operations per element, the same lanes, the same order). The loops are
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

/// `w_i *= inv_s` and `l_i = (l_i - m) - ln_s`: the weights and log-weights after dividing
/// by their sum. `(l - m)` first: exact for the particles that matter (Sterbenz), so
/// normalized log-weights keep full relative precision even when the raw ones are ~1e3.
/// Returns `sum_i w_i^2` of the new weights, summed as [`dot_lanes`] sums (the same lanes in
/// the same order, so the same bits): the effective sample size without a pass of its own.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn normalize_in_place(
    w: &mut [f64],
    l: &mut [f64],
    inv_s: f64,
    m: f64,
    ln_s: f64,
) -> f64 {
    let mut acc = [0.0; LANES];
    let mut wc = w.chunks_exact_mut(LANES);
    let mut lc = l.chunks_exact_mut(LANES);
    for (w, l) in (&mut wc).zip(&mut lc) {
        for k in 0..LANES {
            w[k] *= inv_s;
            l[k] = (l[k] - m) - ln_s;
            acc[k] += w[k] * w[k];
        }
    }
    let (w, l) = (wc.into_remainder(), lc.into_remainder());
    for (w, l) in w.iter_mut().zip(l.iter_mut()) {
        *w *= inv_s;
        *l = (*l - m) - ln_s;
    }
    let tail: f64 = w.iter().map(|a| a * a).sum();
    reduce_lanes(acc) + tail
}

/// Particles per block of [`combine_rows`]: a block of every array it touches stays in L1.
const ROW_BLOCK: usize = 256;

/// `out_i = sum_t a_t x_t` for each row `i` of a component-major array of `n` particles, where
/// the terms of row `i` are `rows[i]` ((component of `xs`, coefficient), the first one scaled
/// into the row, the others added; an empty list starts the row at 0) followed by
/// `extra[i]` ((component of `ys`, coefficient), added). Each element sees the same
/// operations in the same order as one scaling (`y = a x`) and one [`axpy`] per term over
/// whole rows, so the same bits, but block by block: one pass over the particles instead of one
/// per term. The propagation `x' = F x + L z` of a cloud.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn combine_rows(
    rows: &[Vec<(usize, f64)>],
    xs: &[f64],
    extra: &[Vec<(usize, f64)>],
    ys: &[f64],
    n: usize,
    out: &mut [f64],
) {
    for start in (0..n).step_by(ROW_BLOCK) {
        let end = (start + ROW_BLOCK).min(n);
        // Row `j`'s part of the block.
        let part = |j: usize| j * n + start..j * n + end;
        for (i, (terms, added)) in rows.iter().zip(extra).enumerate() {
            let y = &mut out[part(i)];
            match terms.split_first() {
                None => y.fill(0.0),
                Some((&(j, c), rest)) => {
                    for (yi, xi) in y.iter_mut().zip(&xs[part(j)]) {
                        *yi = c * xi;
                    }
                    for &(j, c) in rest {
                        for (yi, xi) in y.iter_mut().zip(&xs[part(j)]) {
                            *yi += c * xi;
                        }
                    }
                }
            }
            for &(j, c) in added {
                for (yi, xi) in y.iter_mut().zip(&ys[part(j)]) {
                    *yi += c * xi;
                }
            }
        }
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

/// `acc[k] += a[k] * x[k]`: one block of lanes of [`dot_lanes`].
#[inline(always)]
fn add_products(acc: &mut [f64; LANES], a: &[f64; LANES], x: &[f64; LANES]) {
    for k in 0..LANES {
        acc[k] += a[k] * x[k];
    }
}

/// `acc[k] += a[k] * (x[k] + shift)`: one block of lanes of [`dot_lanes`] with `x` centred.
#[inline(always)]
fn add_centered_products(acc: &mut [f64; LANES], a: &[f64; LANES], x: &[f64; LANES], shift: f64) {
    for k in 0..LANES {
        acc[k] += a[k] * (x[k] + shift);
    }
}

/// The weighted mean `sum_i w_i x_i` of the component-major `states` (`w.len()` particles,
/// `out.len()` components) into `out`: [`dots_with`] over groups of up to [`GROUP`]
/// components, so the bits of one [`dot_lanes`] per component in a fraction of the passes.
pub(super) fn weighted_mean(w: &[f64], states: &[f64], out: &mut [f64]) {
    let (n, dim) = (w.len(), out.len());
    for k0 in (0..dim).step_by(GROUP) {
        let o = &mut out[k0..(k0 + GROUP).min(dim)];
        match o.len() {
            1 => o.copy_from_slice(&dots_with(w, components::<1>(states, n, k0))),
            2 => o.copy_from_slice(&dots_with(w, components::<2>(states, n, k0))),
            3 => o.copy_from_slice(&dots_with(w, components::<3>(states, n, k0))),
            _ => o.copy_from_slice(&dots_with(w, components::<GROUP>(states, n, k0))),
        }
    }
}

/// Components `k0..k0 + C` of the component-major `states` of `n` particles.
fn components<const C: usize>(states: &[f64], n: usize, k0: usize) -> [&[f64]; C] {
    std::array::from_fn(|c| &states[(k0 + c) * n..(k0 + c + 1) * n])
}

/// `[sum_i w_i x_c[i] for each of the C slices x_c]`: [`dot_lanes`] of `w` with each (the
/// same lanes in the same order, so the same bits), in one pass over `w`. The weighted mean
/// of a cloud's components.
///
/// # Panics
/// If a slice is shorter than `w`.
#[multiversion(targets("x86_64+avx2"))]
fn dots_with<const C: usize>(w: &[f64], xs: [&[f64]; C]) -> [f64; C] {
    let n = w.len();
    let (wb, wt) = w.as_chunks::<LANES>();
    let xs = xs.map(|x| x[..n].as_chunks::<LANES>());
    let mut acc = [[0.0; LANES]; C];
    for (i, wc) in wb.iter().enumerate() {
        for c in 0..C {
            add_products(&mut acc[c], wc, &xs[c].0[i]);
        }
    }
    let mut out = [0.0; C];
    for c in 0..C {
        let tail: f64 = wt.iter().zip(xs[c].1).map(|(a, b)| a * b).sum();
        out[c] = reduce_lanes(acc[c]) + tail;
    }
    out
}

/// Entries per pass of the fused weighted sums ([`weighted_mean`] and the rows of
/// [`weighted_covariance`]): four sets of lane accumulators fit the vector registers.
const GROUP: usize = 4;

/// The lane accumulators of up to [`GROUP`] entries of a covariance row.
pub(super) type LaneSums = [[f64; LANES]; GROUP];

/// Particles per block of [`weighted_covariance`] (a multiple of `LANES`): a block of every
/// component stays in L1 while each covariance row passes over it.
const COV_BLOCK: usize = 512;

/// The weighted covariance `sum_i w_i (x_i - m)(x_i - m)^T` of the component-major `states`
/// (`w.len()` particles, `mean.len()` components) into `cov` (row-major or column-major: it is
/// symmetric). Entry `(j, k)` is `sum_i t_i a_k[i]` with the centred components
/// `a_k = x_k + (-m_k)` and `t = w a_j`, its products summed in the lanes and the order of
/// [`dot_lanes`]: the bits of centring every component into a buffer, forming `t` in another
/// and taking [`dot_lanes`] of the two, without writing either buffer. Each row runs over the
/// particles in groups of up to [`GROUP`] entries, block by block, so a component is read
/// from memory once rather than once per entry. `acc` is scratch (kept by the caller so that
/// nothing is allocated per call once it has grown).
///
/// # Panics
/// If `states` holds fewer than `mean.len() * w.len()` values or `cov` fewer than `mean.len()^2`.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn weighted_covariance(
    w: &[f64],
    states: &[f64],
    mean: &[f64],
    acc: &mut Vec<LaneSums>,
    cov: &mut [f64],
) {
    let (n, dim) = (w.len(), mean.len());
    let component = |j: usize| &states[j * n..(j + 1) * n];
    // (row j, first column k0, entries) of each group on or right of the diagonal.
    let groups = (0..dim).flat_map(|j| {
        (j..dim)
            .step_by(GROUP)
            .map(move |k0| (j, k0, (dim - k0).min(GROUP)))
    });
    acc.clear();
    acc.resize(groups.clone().count(), [[0.0; LANES]; GROUP]);
    let body = n - n % LANES;
    for start in (0..body).step_by(COV_BLOCK) {
        let part = start..(start + COV_BLOCK).min(body);
        let w = &w[part.clone()];
        for (a, (j, k0, len)) in acc.iter_mut().zip(groups.clone()) {
            let row = (&component(j)[part.clone()], -mean[j]);
            let xs = |c: usize| &component(k0 + c)[part.clone()];
            let shifts = |c: usize| -mean[k0 + c];
            match len {
                1 => add_row_block::<1>(a, w, row, [xs(0)], [shifts(0)]),
                2 => add_row_block::<2>(a, w, row, [xs(0), xs(1)], [shifts(0), shifts(1)]),
                3 => add_row_block::<3>(
                    a,
                    w,
                    row,
                    [xs(0), xs(1), xs(2)],
                    [shifts(0), shifts(1), shifts(2)],
                ),
                _ => add_row_block::<GROUP>(
                    a,
                    w,
                    row,
                    std::array::from_fn(xs),
                    std::array::from_fn(shifts),
                ),
            }
        }
    }
    for (a, (j, k0, len)) in acc.iter().zip(groups) {
        let (xj, sj) = (component(j), -mean[j]);
        for (c, lanes) in a.iter().enumerate().take(len) {
            let (k, xk, sk) = (k0 + c, component(k0 + c), -mean[k0 + c]);
            let tail: f64 = (body..n)
                .map(|i| (w[i] * (xj[i] + sj)) * (xk[i] + sk))
                .sum();
            let v = reduce_lanes(*lanes) + tail;
            cov[j * dim + k] = v;
            cov[k * dim + j] = v;
        }
    }
}

/// One block of [`weighted_covariance`]: `acc[c][k] += t * (x_c + shift_c)` with
/// `t = w (x_j + shift_j)`, lane `k` taking the particles `k mod LANES` (whole chunks only).
#[inline(always)]
fn add_row_block<const C: usize>(
    acc: &mut LaneSums,
    w: &[f64],
    (xj, shift_j): (&[f64], f64),
    xs: [&[f64]; C],
    shifts: [f64; C],
) {
    let (wb, _) = w.as_chunks::<LANES>();
    let (jb, _) = xj.as_chunks::<LANES>();
    let xs = xs.map(|x| x.as_chunks::<LANES>().0);
    // Sums in a local copy, which lives in registers (through `acc` they would make a round
    // trip through memory every chunk).
    let mut sums: [[f64; LANES]; C] = std::array::from_fn(|c| acc[c]);
    for (i, (wc, jc)) in wb.iter().zip(jb).enumerate() {
        let t: [f64; LANES] = std::array::from_fn(|k| wc[k] * (jc[k] + shift_j));
        for c in 0..C {
            add_centered_products(&mut sums[c], &t, &xs[c][i], shifts[c]);
        }
    }
    acc[..C].copy_from_slice(&sums);
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

    /// The fused passes give the bits of the passes they replace: [`dot_lanes`] of the weights
    /// with each component (the mean), the squares summed by [`dot_lanes`] (the ESS), and the
    /// covariance row as "centre each component into a buffer, multiply by the weights into
    /// another, [`dot_lanes`] the two". Lengths around the lane width and its multiples, and
    /// values with large, tiny, negative and zero entries, so any change of order shows.
    #[test]
    fn fused_passes_give_the_bits_of_the_separate_passes() {
        let mut r = rng(11);
        for n in [1, 5, 7, 8, 9, 15, 16, 17, 31, 64, 67, 1000, 1003] {
            // Weights: uniform, with zeros, no huge ones (they would swamp the sums).
            let raw: Vec<f64> = (0..n)
                .map(|i| if i % 5 == 2 { 0.0 } else { r.random() })
                .collect();
            let mut draw = |scale: f64| -> Vec<f64> {
                (0..n)
                    .map(|i| match i % 11 {
                        3 => 0.0,
                        7 => -scale * 1e8 * r.random::<f64>(),
                        _ => scale * (r.random::<f64>() - 0.3),
                    })
                    .collect()
            };
            let xs: Vec<Vec<f64>> = (0..4).map(|c| draw(10f64.powi(c))).collect();

            // Normalization: the same weights and log-weights, and dot_lanes(w, w).
            let (mut w, mut l) = (raw.clone(), draw(5.0));
            let (mut w2, mut l2) = (w.clone(), l.clone());
            let sum_sq = normalize_in_place(&mut w, &mut l, 0.37, -2.0, 0.11);
            for (w, l) in w2.iter_mut().zip(l2.iter_mut()) {
                *w *= 0.37;
                *l = (*l + 2.0) - 0.11;
            }
            assert_eq!(w, w2);
            assert_eq!(l, l2);
            assert_eq!(sum_sq.to_bits(), dot_lanes(&w, &w).to_bits(), "n = {n}");

            let dots = dots_with(&w, [&xs[0][..], &xs[1], &xs[2], &xs[3]]);
            for c in 0..4 {
                assert_eq!(
                    dots[c].to_bits(),
                    dot_lanes(&w, &xs[c]).to_bits(),
                    "n = {n}"
                );
            }
            assert_eq!(dots_with(&w, [&xs[2][..]])[0], dots[2]);
        }
        // The mean and the covariance: every state dimension up to two groups of entries, and
        // lengths around the lane width and the block.
        for n in [1, 7, 8, 9, 511, 512, 513, 1029] {
            let w: Vec<f64> = (0..n)
                .map(|i| if i % 5 == 2 { 0.0 } else { r.random() })
                .collect();
            for dim in 1..=6 {
                let states: Vec<f64> = (0..dim * n)
                    .map(|i| match i % 13 {
                        4 => 0.0,
                        9 => -1e6 * r.random::<f64>(),
                        _ => 10f64.powi((i / n) as i32 - 2) * (r.random::<f64>() - 0.4),
                    })
                    .collect();
                let mut means = vec![f64::NAN; dim];
                weighted_mean(&w, &states, &mut means);
                for (j, m) in means.iter().enumerate() {
                    let want = dot_lanes(&w, &states[j * n..(j + 1) * n]);
                    assert_eq!(
                        m.to_bits(),
                        want.to_bits(),
                        "n = {n}, dim = {dim}, mean {j}"
                    );
                }
                let mean: Vec<f64> = (0..dim).map(|j| 0.7 * j as f64 - 1.3).collect();
                let centred: Vec<Vec<f64>> = (0..dim)
                    .map(|c| {
                        states[c * n..(c + 1) * n]
                            .iter()
                            .map(|x| x + -mean[c])
                            .collect()
                    })
                    .collect();
                let mut cov = vec![f64::NAN; dim * dim];
                weighted_covariance(&w, &states, &mean, &mut Vec::new(), &mut cov);
                for j in 0..dim {
                    let t: Vec<f64> = w.iter().zip(&centred[j]).map(|(w, a)| w * a).collect();
                    for k in 0..dim {
                        let want = dot_lanes(&t, &centred[k]);
                        let (a, b) = (j.min(k), j.max(k));
                        // The upper triangle is computed; the lower one mirrors it.
                        let want = if j <= k { want } else { cov[a * dim + b] };
                        assert_eq!(
                            cov[j * dim + k].to_bits(),
                            want.to_bits(),
                            "n = {n}, dim = {dim}, ({j}, {k})"
                        );
                    }
                }
            }
        }
    }

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
