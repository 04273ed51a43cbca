//! Blocks of exact standard-normal draws: a 1024-layer ziggurat that takes 99.57% of its
//! draws from a single `u64` on a branch-light fast path.
//!
//! Why: the particle filters draw their process and measurement noise one
//! `rand_distr::StandardNormal` sample at a time (~2.3-2.7 ns per draw on the development
//! machine, ~12% of the hottest benchmark). [`fill_standard_normal`] fills a whole slice in
//! one loop that keeps the generator's state in registers and spends, per draw, one table
//! index, one compare-and-branch against the layer's acceptance bound (an integer compare on
//! the raw word, so the rare miss is detected early), one integer-to-float conversion, one
//! add and one multiply. See `benches/normal_block.rs` for the measured speed.
//!
//! # The algorithm
//!
//! The ziggurat of Marsaglia & Tsang ("The Ziggurat Method for Generating Random
//! Variables", J. Stat. Softw. 5(8), 2000), with the correction of Doornik ("An Improved
//! Ziggurat Method to Generate Normal Random Samples", 2005): the layer index and the
//! position inside the layer come from *disjoint* bits of the word, so they are independent
//! (Marsaglia & Tsang took the index from the low bits of the same 32-bit integer that gives
//! the position, which correlates the two; Doornik shows the resulting test failures).
//!
//! Cover the half density `f(x) = exp(-x^2/2)`, `x >= 0`, with `N = 1024` layers of equal
//! area `v`: a base strip made of the rectangle `[0, r] x [0, f(r)]` plus the tail `x > r`,
//! and `N - 1` horizontal rectangles `[0, x_i] x [f(x_i), f(x_{i+1})]`, `i = 1..N-1`, with
//! `x_1 = r > x_2 > ... > x_{N-1} > x_N = 0`. Give the base strip the virtual width
//! `x_0 = v / f(r)`. A draw picks a layer `i` uniformly (equal areas make that the right
//! layer probability), a sign, and a magnitude `|z| = u x_i` with `u` uniform on `(0, 1)`:
//!
//! * `|z| < x_{i+1}` (the fast path, probability `x_{i+1} / x_i`): the point lies under `f`
//!   at every height of the layer, so it is accepted whatever the height; no height is drawn.
//! * `i = 0` and `|z| >= r` (probability `5.4e-5` per draw): a draw from the tail `x > r`
//!   by Marsaglia's exact method (function `tail`).
//! * `i >= 1` and `x_{i+1} <= |z| < x_i` (the wedge): draw the height `y` uniform on
//!   `[f(x_i), f(x_{i+1})]` and accept `z` when `y < f(|z|)`; otherwise start again from
//!   scratch with a new word, new layer included (restarting rather than redrawing only `u`
//!   is what makes the result exact).
//!
//! Every point under the curve is accepted with the same density, so the output has density
//! proportional to `f`: exactly N(0, 1) up to the `2^-52` grid of `u` and the rounding of
//! the product `u x_i` (relative `2^-53`). No approximation of the density is made anywhere:
//! `exp` and `ln` are evaluated wherever `f` and the tail need them.
//!
//! Why 1024 layers and not the usual 128 or 256: the fast path misses with probability
//! 2.76% (128 layers), 1.49% (256), 0.80% (512), 0.43% (1024), and each miss costs a branch
//! misprediction, which throws away the speculative work of the draws in flight behind it,
//! plus the wedge or tail work: ~140 cycles in all here, against ~4 cycles for a fast draw.
//! Measured: 1.38 ns per draw with 512 layers, 1.29 ns with 1024, no gain with 2048. The
//! fast-path tables are `2 x 2N x 8` bytes = 32 KiB (the sign is a table index bit, so that
//! the fast path needs no sign operation); the wedge heights add 8 KiB used only on misses.
//!
//! # Bits of one word `b`
//!
//! * bits 0-9: the layer `i`; bit 10: the sign; bit 11: unused;
//! * bits 12-63: `m` in `0..2^52`, the magnitude `u = (m + 1/2) 2^-52`, a symmetric midpoint
//!   grid of `(0, 1)` that never gives 0 (`m + 1/2` is exact in `f64`).
//!
//! The fast-path test is the integer compare `b < k_j` with `k_j = k_i 2^12`, which is
//! `m < k_i`; `k_i` is computed (and checked by a test) so that it holds exactly when the
//! *returned* value satisfies `|z| = fl((m + 1/2) x_i 2^-52) < x_{i+1}`: the fast path and
//! the wedge test agree on every double. The wedge height and the tail take further whole
//! words (53-bit uniforms).
//!
//! # Tables
//!
//! Computed once, at first use ([`OnceLock`]), from the definition: `r` is the root of the
//! closing condition (the recursion `x_{i+1} = f^{-1}(f(x_i) + v / x_i)` started at
//! `x_1 = r` with `v = r f(r) + sqrt(2 pi) Q(r)` must end with
//! `f(x_{N-1}) + v / x_{N-1} = 1`, i.e. the top layer `[0, x_{N-1}] x [f(x_{N-1}), 1]` has
//! area `v` too), found by bisection down to adjacent doubles; `Q` is
//! [`super::normal::q`] (relative error a few 1e-15). The recursion is evaluated as
//! `x_{i+1} = sqrt(-2 ln_1p(expm1(-x_i^2/2) + v / x_i))` to keep the digits near the top.
//! The tests check every layer's area against `v`, and `r`, `v` against 50-digit references
//! (mpmath) for 1024 layers and against Marsaglia & Tsang's published values for 128 and 256
//! layers, which the same code computes.
//!
//! # Determinism and block semantics
//!
//! The output is a deterministic function of the generator's state: words are taken with
//! `next_u64` strictly in the order of the output slots, and a draw that misses the fast path
//! takes its extra words right away, before the next slot's word. Hence filling `[a; m + n]`
//! gives the same values, and leaves the generator in the same state, as filling `[a; m]` and
//! then `[a; n]` (any split), or as drawing the slots one at a time. No state is kept between
//! calls besides the constant tables. Bit-identical results across platforms additionally
//! need the same `exp`/`ln` (they decide the rare wedge and tail draws and the tables).
use rand::RngCore;
use std::sync::OnceLock;

/// Number of layers (a power of two: the layer index is `b & (N - 1)`).
const N: usize = 1024;
/// Layer and sign bits of a word: `j = b & SIGNED_LAYER_MASK = i + N * sign`.
const SIGNED_LAYER_MASK: u64 = 2 * N as u64 - 1;
/// `2^-52`: one step of the magnitude grid.
const TWO_POW_M52: f64 = 1.0 / (1u64 << 52) as f64;
/// `2^-53`: one step of a 53-bit uniform.
const TWO_POW_M53: f64 = 1.0 / (1u64 << 53) as f64;

struct Ziggurat {
    /// `w[i + N * sign] = +-x_i 2^-52`, so that the point of word `b` is `z = (m + 1/2) w[j]`.
    w: [f64; 2 * N],
    /// `k[i + N * sign] = k_i 2^12`: the fast path accepts word `b` iff `b < k[j]`.
    k: [u64; 2 * N],
    /// `f[i] = f(x_i)` for the wedge heights (`f[0]` is unused: layer 0 has no wedge).
    f: [f64; N + 1],
    /// Where the tail starts.
    r: f64,
}

/// The unnormalized half density `f(x) = exp(-x^2 / 2)`.
#[inline]
fn density(x: f64) -> f64 {
    (-0.5 * x * x).exp()
}

/// Runs the layer recursion from `x_1 = r` for `n = x.len() - 1` layers and fills `x`
/// (`x[0] = v / f(r)`, ..., `x[n] = 0`); returns `v` and the closing residual
/// `f(x_{n-1}) + v / x_{n-1} - 1`, positive when `r` is too small (the layers reach the top
/// early; an early overshoot also returns a positive residual).
fn build_layers(r: f64, x: &mut [f64]) -> (f64, f64) {
    let n = x.len() - 1;
    // Base strip: rectangle [0, r] x [0, f(r)] plus the tail, int_r^inf f = sqrt(2 pi) Q(r).
    let v = r * density(r) + (2.0 * std::f64::consts::PI).sqrt() * super::normal::q(r);
    x[0] = v / density(r);
    x[1] = r;
    for i in 1..n - 1 {
        // f(x_{i+1}) - 1 = (f(x_i) - 1) + v / x_i, kept as a difference from 1.
        let gm1 = (-0.5 * x[i] * x[i]).exp_m1() + v / x[i];
        if gm1 >= 0.0 {
            return (v, 1.0);
        }
        x[i + 1] = (-2.0 * gm1.ln_1p()).sqrt();
    }
    x[n] = 0.0;
    let last = x[n - 1];
    (v, (-0.5 * last * last).exp_m1() + v / last)
}

/// Where the tail of the `N` = 1024 layers starts: the root [`solve_layers`] finds, kept as its
/// bits because the bisection (about 55 rounds of the 1024-layer recursion, 8 million
/// instructions, 2-3 ms) would otherwise run at the start of every process that draws. The
/// test `the_kept_tail_start_is_the_bisections_root` finds it again.
const TAIL_START_BITS: u64 = 0x401027c84109fad5;

/// The ziggurat for `x.len() - 1` layers: finds `r` by bisection on the closing residual,
/// down to adjacent doubles, fills `x` and returns `(r, v)`.
#[cfg(test)]
fn solve_layers(x: &mut [f64]) -> (f64, f64) {
    let (mut lo, mut hi) = (1.0f64, 8.0f64);
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if build_layers(mid, x).1 > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let (v, _) = build_layers(hi, x);
    (hi, v)
}

/// The fast-path bound of a layer: the number `k` of grid points `m` whose returned
/// magnitude `fl((m + 1/2) w)` lies below `inner` (monotone in `m`, so they are `0..k`).
fn accept_bound(w: f64, inner: f64) -> u64 {
    let below = |m: u64| (m as f64 + 0.5) * w < inner;
    let mut k = ((inner / w) as u64).min(1 << 52);
    while k > 0 && !below(k - 1) {
        k -= 1;
    }
    while k < (1 << 52) && below(k) {
        k += 1;
    }
    k
}

fn ziggurat() -> &'static Ziggurat {
    static TABLES: OnceLock<Box<Ziggurat>> = OnceLock::new();
    TABLES.get_or_init(|| {
        let mut x = [0.0; N + 1];
        let r = f64::from_bits(TAIL_START_BITS);
        build_layers(r, &mut x);
        let mut f = [0.0; N + 1];
        for (fi, &xi) in f.iter_mut().zip(&x) {
            *fi = density(xi);
        }
        let w = std::array::from_fn(|j| {
            let w = x[j % N] * TWO_POW_M52;
            if j < N {
                w
            } else {
                -w
            }
        });
        // k_i < 2^52 because x_{i+1} < x_i, so k_i << 12 does not overflow.
        let k = std::array::from_fn(|j| {
            let i = j % N;
            accept_bound(x[i] * TWO_POW_M52, x[i + 1]) << 12
        });
        Box::new(Ziggurat { w, k, f, r })
    })
}

/// The candidate of word `b`: whether the fast path accepts it, and its signed point
/// `z = +-(m + 1/2) x_i 2^-52`.
#[inline(always)]
fn candidate(b: u64, t: &Ziggurat) -> (bool, f64) {
    let j = (b & SIGNED_LAYER_MASK) as usize;
    (b < t.k[j], ((b >> 12) as f64 + 0.5) * t.w[j])
}

/// A 53-bit uniform on `[0, 1)`.
#[inline]
fn uniform_co(b: u64) -> f64 {
    (b >> 11) as f64 * TWO_POW_M53
}

/// A 53-bit uniform on `(0, 1]` (safe under `ln`).
#[inline]
fn uniform_oc(b: u64) -> f64 {
    ((b >> 11) + 1) as f64 * TWO_POW_M53
}

/// Marsaglia's exact sampler of the normal tail `x > r` ("Generating a variable from the
/// tail of the normal distribution", Technometrics 6, 1964): with `a ~ Exp(rate r)` and
/// `e ~ Exp(1)`, accepting when `2 e > a^2` gives `r + a` the density
/// `r exp(-r a) exp(-a^2/2) ~ exp(-(r + a)^2 / 2)`, the normal tail. Acceptance ~94% at
/// `r = 4.04`.
fn tail<R: RngCore + ?Sized>(r: f64, rng: &mut R) -> f64 {
    loop {
        let a = -uniform_oc(rng.next_u64()).ln() / r;
        let e = -uniform_oc(rng.next_u64()).ln();
        if 2.0 * e > a * a {
            return r + a;
        }
    }
}

/// One complete draw whose first word is `b` (already taken from `rng`): the fast path, or
/// the tail, or the wedge test, restarting with a fresh word when the wedge rejects.
#[cold]
#[inline(never)]
fn slow_path<R: RngCore + ?Sized>(mut b: u64, rng: &mut R, t: &Ziggurat) -> f64 {
    loop {
        let (fast, z) = candidate(b, t);
        if fast {
            return z;
        }
        let i = (b & (N as u64 - 1)) as usize;
        if i == 0 {
            return tail(t.r, rng).copysign(z);
        }
        // Wedge of layer i: height uniform on [f(x_i), f(x_{i+1})], accept under the curve.
        let y = t.f[i] + uniform_co(rng.next_u64()) * (t.f[i + 1] - t.f[i]);
        if y < density(z) {
            return z;
        }
        b = rng.next_u64();
    }
}

/// Fills `out` from its start until the first word that misses the fast path; returns how
/// many slots were filled, and that word (`None` when all of `out` was filled).
///
/// No calls inside, so the generator's state stays in registers; unrolled by 4 so that the
/// loop counter costs little next to the generator.
#[inline(always)]
fn fast_run<R: RngCore + ?Sized>(
    out: &mut [f64],
    rng: &mut R,
    t: &Ziggurat,
) -> (usize, Option<u64>) {
    let mut done = 0;
    let mut quads = out.chunks_exact_mut(4);
    for quad in &mut quads {
        for (j, o) in quad.iter_mut().enumerate() {
            let b = rng.next_u64();
            let (fast, z) = candidate(b, t);
            if !fast {
                return (done + j, Some(b));
            }
            *o = z;
        }
        done += 4;
    }
    for o in quads.into_remainder() {
        let b = rng.next_u64();
        let (fast, z) = candidate(b, t);
        if !fast {
            return (done, Some(b));
        }
        *o = z;
        done += 1;
    }
    (done, None)
}

/// Fills `out` with independent N(0, 1) draws from `rng`.
///
/// Exact: the ziggurat of Marsaglia & Tsang (2000) with Doornik's (2005) independent bits,
/// 1024 layers, Marsaglia's (1964) tail (see the module documentation). About twice as fast
/// as a loop over `rand_distr::StandardNormal`; not the same values.
///
/// Deterministic: the values depend only on the generator's state, one `next_u64` per slot
/// in slot order plus, for the 0.43% of slots that miss the fast path, further words taken
/// at once. Filling a slice in pieces gives the same values, and the same final generator
/// state, as filling it at once.
pub fn fill_standard_normal<R: RngCore + ?Sized>(out: &mut [f64], rng: &mut R) {
    let t = ziggurat();
    let mut rest = out;
    loop {
        let (filled, missed) = fast_run(rest, rng, t);
        let Some(b) = missed else { return };
        let Some((slot, after)) = std::mem::take(&mut rest)[filled..].split_first_mut() else {
            unreachable!("a missed word always has its slot")
        };
        *slot = slow_path(b, rng, t);
        rest = after;
    }
}

#[cfg(test)]
mod tests {
    // Reference values are quoted with all the digits the high-precision source gave.
    #![allow(clippy::excessive_precision)]
    use super::*;
    use crate::stats::{chi2, normal};
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn draws(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut z = vec![0.0; n];
        fill_standard_normal(&mut z, &mut rng);
        z
    }

    /// `|observed - expected| / standard error`.
    fn z_score(observed: f64, expected: f64, se: f64) -> f64 {
        (observed - expected) / se
    }

    /// Binomial check of a count: within 5 standard errors `sqrt(n p (1 - p))`.
    fn assert_frequency(count: usize, n: usize, p: f64, what: &str) {
        let se = (n as f64 * p * (1.0 - p)).sqrt();
        let zs = z_score(count as f64, n as f64 * p, se);
        assert!(
            zs.abs() < 5.0,
            "{what}: {count} of {n}, expected {:.1} (z = {zs:.2})",
            n as f64 * p
        );
    }

    #[test]
    fn layers_have_equal_areas_and_reference_constants() {
        // r and v: 50-digit mpmath bisection of the same closing condition (1024 layers);
        // Marsaglia & Tsang (2000) publish r = 3.442619855899, v = 9.91256303526217e-3 for
        // 128 layers and r = 3.6541528853610088 for 256.
        let cases: [(usize, f64, f64); 3] = [
            (
                128,
                3.44261985589665212142432,
                9.912563035336461079095685e-3,
            ),
            (
                256,
                3.65415288536100877164543,
                4.928673233974655347361775e-3,
            ),
            (
                1024,
                4.038849846109504522714423,
                1.226324646353088072885371e-3,
            ),
        ];
        for (n, r_ref, v_ref) in cases {
            let mut x = vec![0.0; n + 1];
            let (r, v) = solve_layers(&mut x);
            assert!(
                (r - r_ref).abs() < 1e-12,
                "{n} layers: r = {r}, reference {r_ref}"
            );
            assert!(((v - v_ref) / v_ref).abs() < 1e-10, "{n} layers: v = {v}");
            // Every layer has area v: the base strip by construction of v (checked against
            // the reference above), the rectangles here, the top one included.
            for i in 1..n {
                let area = x[i] * (density(x[i + 1]) - density(x[i]));
                assert!(
                    ((area - v) / v).abs() < 1e-9,
                    "{n} layers: layer {i} area {area} vs {v}"
                );
                assert!(x[i + 1] < x[i]);
            }
            assert!(x[0] > x[1] && x[n] == 0.0);
        }
    }

    #[test]
    fn the_kept_tail_start_is_the_bisections_root() {
        let (mut solved, mut kept) = ([0.0; N + 1], [0.0; N + 1]);
        let (r, v) = solve_layers(&mut solved);
        assert_eq!(r.to_bits(), TAIL_START_BITS, "r = {r:e}");
        let (v_kept, _) = build_layers(f64::from_bits(TAIL_START_BITS), &mut kept);
        assert_eq!(v_kept.to_bits(), v.to_bits());
        assert!(solved
            .iter()
            .zip(&kept)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(ziggurat().r.to_bits(), TAIL_START_BITS);
    }

    #[test]
    fn fast_path_bounds_match_the_returned_values() {
        // k_i is exact on the grid: the last accepted point lies below x_{i+1}, the first
        // rejected one does not, and the tables use the layer boundaries of solve_layers.
        let t = ziggurat();
        let mut x = [0.0; N + 1];
        let (r, _) = solve_layers(&mut x);
        assert_eq!(t.r, r);
        let mut p_fast = 0.0;
        for j in 0..2 * N {
            let i = j % N;
            let sign = if j < N { 1.0 } else { -1.0 };
            assert_eq!(t.w[j], sign * x[i] * TWO_POW_M52);
            assert_eq!(t.k[j] & 0xfff, 0);
            let k = t.k[j] >> 12;
            assert!(k < 1 << 52);
            if k > 0 {
                assert!(
                    ((k - 1) as f64 + 0.5) * t.w[j].abs() < x[i + 1],
                    "layer {i}"
                );
            }
            assert!((k as f64 + 0.5) * t.w[j].abs() >= x[i + 1], "layer {i}");
            p_fast += k as f64 * TWO_POW_M52 / (2 * N) as f64;
        }
        // The fast path takes 99.572% of the first words (the sum of x_{i+1} / x_i / N).
        assert!(
            (p_fast - 0.99572).abs() < 1e-5,
            "fast-path probability {p_fast}"
        );
    }

    #[test]
    fn moments_match_standard_normal() {
        // 10^7 draws. Monte Carlo standard errors from the normal's moments: the mean has
        // variance 1/n; the variance estimate, Var(z^2)/n = 2/n; the sample skewness 6/n and
        // the sample excess kurtosis 24/n (their asymptotic variances under normality).
        let n = 10_000_000;
        let z = draws(n, 1);
        let nf = n as f64;
        let mean = z.iter().sum::<f64>() / nf;
        let (mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0);
        for &v in &z {
            let d = v - mean;
            let d2 = d * d;
            m2 += d2;
            m3 += d2 * d;
            m4 += d2 * d2;
        }
        let (m2, m3, m4) = (m2 / nf, m3 / nf, m4 / nf);
        let skew = m3 / m2.powf(1.5);
        let kurt = m4 / (m2 * m2) - 3.0;
        for (name, est, se) in [
            ("mean", mean, (1.0 / nf).sqrt()),
            ("variance - 1", m2 - 1.0, (2.0 / nf).sqrt()),
            ("skewness", skew, (6.0 / nf).sqrt()),
            ("excess kurtosis", kurt, (24.0 / nf).sqrt()),
        ] {
            assert!(
                (est / se).abs() < 5.0,
                "{name} = {est:.3e}, {:.2} standard errors",
                est / se
            );
        }
    }

    #[test]
    fn kolmogorov_smirnov_against_phi() {
        // 10^6 draws; the asymptotic critical value of sqrt(n) D at level 0.001 is 1.9495.
        let n = 1_000_000;
        let mut z = draws(n, 2);
        z.sort_by(f64::total_cmp);
        let nf = n as f64;
        let mut d: f64 = 0.0;
        for (k, &v) in z.iter().enumerate() {
            let c = normal::cdf(v);
            d = d.max(c - k as f64 / nf).max((k + 1) as f64 / nf - c);
        }
        assert!(
            nf.sqrt() * d < 1.9495,
            "KS: sqrt(n) D = {:.3}",
            nf.sqrt() * d
        );
    }

    #[test]
    fn chi_square_on_100_equiprobable_bins() {
        // 10^6 draws into the bins between the k/100 quantiles; critical value at 0.001.
        let n = 1_000_000;
        let edges: Vec<f64> = (1..100)
            .map(|k| normal::inv_cdf(k as f64 / 100.0))
            .collect();
        let mut counts = [0usize; 100];
        for v in draws(n, 3) {
            counts[edges.partition_point(|&e| e <= v)] += 1;
        }
        let expected = n as f64 / 100.0;
        let stat: f64 = counts
            .iter()
            .map(|&c| (c as f64 - expected).powi(2) / expected)
            .sum();
        let crit = chi2::upper_quantile(99.0, 1e-3).unwrap();
        assert!(stat < crit, "chi-square {stat:.1} >= {crit:.1} (99 dof)");
    }

    #[test]
    fn tail_frequencies() {
        // 2 x 10^7 draws; P(|z| > r) is the tail path's share (r = 4.039), P(|z| > 4.5) lies
        // deep in it. Binomial standard errors, 5 of them allowed.
        let n = 20_000_000;
        let z = draws(n, 4);
        let r = ziggurat().r;
        let count = |pred: &dyn Fn(f64) -> bool| z.iter().filter(|&&v| pred(v)).count();
        let two_sided = |c: f64| 2.0 * normal::q(c);
        assert_frequency(count(&|v| v.abs() > 2.0), n, two_sided(2.0), "|z| > 2");
        assert_frequency(count(&|v| v.abs() > 3.0), n, two_sided(3.0), "|z| > 3");
        assert_frequency(count(&|v| v.abs() > 3.7), n, two_sided(3.7), "|z| > 3.7");
        assert_frequency(count(&|v| v > 3.7), n, normal::q(3.7), "z > 3.7");
        assert_frequency(count(&|v| v < -3.7), n, normal::q(3.7), "z < -3.7");
        assert_frequency(count(&|v| v.abs() > 4.0), n, two_sided(4.0), "|z| > 4");
        assert_frequency(count(&|v| v.abs() > r), n, two_sided(r), "|z| > r");
        assert_frequency(count(&|v| v.abs() > 4.5), n, two_sided(4.5), "|z| > 4.5");
        assert!(z.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn tail_sampler_is_the_truncated_normal() {
        // The tail path on its own, 2 x 10^5 draws: KS against P(X <= t | X > r) =
        // 1 - Q(t) / Q(r), critical value 1.9495 / sqrt(n) at level 0.001.
        let r = ziggurat().r;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let n = 200_000;
        let mut s: Vec<f64> = (0..n).map(|_| tail(r, &mut rng)).collect();
        assert!(s.iter().all(|&v| v > r));
        s.sort_by(f64::total_cmp);
        let qr = normal::q(r);
        let nf = n as f64;
        let mut d: f64 = 0.0;
        for (k, &v) in s.iter().enumerate() {
            let c = 1.0 - normal::q(v) / qr;
            d = d.max(c - k as f64 / nf).max((k + 1) as f64 / nf - c);
        }
        assert!(
            nf.sqrt() * d < 1.9495,
            "tail KS: sqrt(n) D = {:.3}",
            nf.sqrt() * d
        );
    }

    /// The word with layer `i`, sign bit `neg` and magnitude index `m`.
    fn word(i: usize, neg: bool, m: u64) -> u64 {
        (m << 12) | ((neg as u64) << 10) | i as u64
    }

    #[test]
    fn wedge_accepts_with_the_right_probability() {
        // A word landing in the wedge of layer i at |z| is kept with probability
        // (f(|z|) - f(x_i)) / (f(x_{i+1}) - f(x_i)); otherwise the draw restarts and returns
        // a fresh value (equal to z with probability ~0). Layers at the bottom, in the
        // convex and concave parts, around the inflection x = 1, and the top layer (all
        // wedge); points near both ends and the middle of each wedge. 4 x 10^4 trials each,
        // 5 binomial standard errors.
        let t = ziggurat();
        let mut x = [0.0; N + 1];
        solve_layers(&mut x);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(6);
        let trials = 40_000;
        for i in [1, 2, 50, 300, 700, 850, 1000, N - 1] {
            let k = t.k[i] >> 12;
            for frac in [0.02, 0.5, 0.98] {
                // Grid points from k (first wedge point) to the last one, 2^52 - 1.
                let m = k + (frac * ((1u64 << 52) - 1 - k) as f64) as u64;
                for neg in [false, true] {
                    let b = word(i, neg, m);
                    let (fast, z) = candidate(b, t);
                    assert!(!fast && z.abs() >= x[i + 1] && z.abs() < x[i]);
                    assert_eq!(z < 0.0, neg);
                    let p = (density(z) - density(x[i])) / (density(x[i + 1]) - density(x[i]));
                    let kept = (0..trials)
                        .filter(|_| slow_path(b, &mut rng, t) == z)
                        .count();
                    assert_frequency(kept, trials, p, &format!("layer {i}, frac {frac}"));
                }
            }
        }
    }

    #[test]
    fn base_strip_beyond_r_goes_to_the_tail() {
        // Layer 0 words with |z| >= r return a tail value of the same sign; below r they are
        // fast-path points of the base rectangle.
        let t = ziggurat();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let k0 = t.k[0] >> 12;
        for neg in [false, true] {
            for m in [k0, k0 + 1, (1 << 52) - 1] {
                let b = word(0, neg, m);
                for _ in 0..1000 {
                    let v = slow_path(b, &mut rng, t);
                    assert!(v.abs() > t.r && (v < 0.0) == neg, "{v}");
                }
            }
            let (fast, z) = candidate(word(0, neg, k0 - 1), t);
            assert!(fast && z.abs() < t.r);
        }
    }

    #[test]
    fn layer_intervals_chi_square() {
        // |z| binned at the layer boundaries: [x_{i+1}, x_i) for i >= 1 and [r, inf) for
        // i = 0; each bin is filled by the rectangles of the layers below it plus the wedge
        // of layer i (the base strip's bin by the tail path alone). 10^7 draws, 1023 dof.
        let n = 10_000_000;
        let mut x = [0.0; N + 1];
        solve_layers(&mut x);
        // Ascending boundaries x_{N-1} < ... < x_1 = r.
        let asc: Vec<f64> = x[1..N].iter().rev().copied().collect();
        let mut counts = vec![0usize; N];
        for v in draws(n, 8) {
            // position p in asc -> layer N - 1 - p
            counts[N - 1 - asc.partition_point(|&e| e <= v.abs())] += 1;
        }
        let mut stat = 0.0;
        for (i, &c) in counts.iter().enumerate() {
            let hi = if i == 0 { 0.0 } else { normal::q(x[i]) };
            let p = 2.0 * (normal::q(x[i + 1]) - hi);
            let e = n as f64 * p;
            stat += (c as f64 - e).powi(2) / e;
        }
        let crit = chi2::upper_quantile((N - 1) as f64, 1e-3).unwrap();
        assert!(stat < crit, "chi-square {stat:.1} >= {crit:.1}");
    }

    /// The same algorithm, one slot at a time, written without the fast loop.
    fn reference_fill(out: &mut [f64], rng: &mut Xoshiro256PlusPlus) {
        let t = ziggurat();
        for o in out {
            *o = slow_path(rng.next_u64(), rng, t);
        }
    }

    /// Asserts bit-identical slices, naming the first difference (not dumping them).
    fn assert_same_bits(a: &[f64], b: &[f64], what: &str) {
        assert_eq!(a.len(), b.len(), "{what}: lengths");
        if let Some(k) = (0..a.len()).find(|&k| a[k].to_bits() != b[k].to_bits()) {
            panic!("{what}: first difference at {k}: {} vs {}", a[k], b[k]);
        }
    }

    #[test]
    fn deterministic_and_independent_of_the_split() {
        let seed = 9;
        for n in [0, 1, 7, 1000, 10_001] {
            let a = draws(n, seed);
            assert_same_bits(&a, &draws(n, seed), &format!("same seed, n = {n}"));
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let mut b = vec![0.0; n];
            reference_fill(&mut b, &mut rng);
            assert_same_bits(&a, &b, &format!("fast loop vs slot by slot, n = {n}"));
        }
        // Pieces of any lengths, one generator: same values and same final state.
        let total = 10_001;
        let mut whole_rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut whole = vec![0.0; total];
        fill_standard_normal(&mut whole, &mut whole_rng);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut pieces = vec![0.0; total];
        let mut start = 0;
        for len in [0, 1, 7, 3, 1000, 2, 5000].into_iter().cycle() {
            let end = (start + len).min(total);
            fill_standard_normal(&mut pieces[start..end], &mut rng);
            start = end;
            if start == total {
                break;
            }
        }
        assert_same_bits(&whole, &pieces, "whole vs pieces");
        assert_eq!(
            whole_rng.next_u64(),
            rng.next_u64(),
            "generator state after"
        );
        // Another seed, other values.
        assert_ne!(draws(100, seed), draws(100, seed + 1));
    }
}
