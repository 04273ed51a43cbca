//! The band-likelihood kernel of the particle filters: [`add_log_band_probability`] and
//! [`add_log_band_probability_about`], the log no-send probability of Zheng et al. (2014), eq. (14),
//! for a whole particle cloud at once.
//!
//! Why a module of its own: [`super::normal`] holds the accurate scalar functions of the
//! standard normal (`Q`, `log Q`, [`log_q_band`], the quantile); this kernel is a different
//! kind of code built on top of them: process-wide and per-thread tables, piecewise
//! Chebyshev interpolation and a SIMD-dispatched per-particle loop, ~1000 lines with its own
//! tests. It uses the scalar functions of [`super::normal`]; `normal` does not use it (the
//! callers and the benchmarks reach both entry points here, as `stats::band_kernel::…`).
//!
//! `add_log_band_probability` adds `ln P` for ~10^4 particles per call, ~3 10^8 times in one
//! benchmark, so it must cost a few ns per particle; the accurate scalar `log_q_band` costs
//! 30-40 ns. In units of the noise sd (`m = mu s`, `c = half_width s`) the band probability is
//! `P = Phi(c - m) - Phi(-c - m)`: symmetric about `m = 0`, so a function of `x = |m|` alone,
//! and within one call `c` is fixed. The kernel therefore tabulates the one-variable function
//!
//! ```text
//! f(x) = ln P(x),   P(x) = Q(a) - Q(a + 2c),   a = x - c,
//! ```
//!
//! once per call as a piecewise polynomial (~1-3 us), and then spends one table-row lookup and
//! one degree-8 Horner evaluation per particle.
//!
//! * Pieces. `f` is analytic; its nearest complex singularities (zeros of `P`, and the erfc zeros
//!   in `ln Q(a)`) are 2.6 or more from the real axis, so degree-8 Chebyshev interpolation is
//!   good to ~1e-13 on pieces 0.375 wide where `f` bends (`a` in [-6, 3]) and on pieces growing
//!   to 3.375 wide at `a = 40.5` (`SCHEDULE`). Below `a = -9` the band covers the particle,
//!   `P > 1 - 3e-19`: `f = 0`. Above `a = 40.5` (`P < 1e-357`, where no accuracy is promised)
//!   `f` continues as the quadratic Taylor polynomial of the last piece at its end, which keeps
//!   decreasing like `-a^2/2`; particles beyond `x = 1e150` are evaluated there (~ -5e299).
//! * Lookup. Bins 0.375 wide in `a` address the pieces: a bin's row holds its piece's centre,
//!   inverse half-width and monomial coefficients (in units of `mu`, so the particles skip the
//!   product `mu s`). Per particle: `|mu|`, a clamp, a multiply-add, a clamp and a magic-number
//!   rounding for the row, a subtract and a multiply for the local variable `t` in [-1, 1], and
//!   the Horner steps, run in lockstep over blocks of 16 particles (the row loads vectorize as
//!   pairs of scalar loads; the lockstep gives the out-of-order core independent work).
//! * Construction. The interpolation nodes sit at fixed offsets in `a`, whatever `c`, so their
//!   near-edge part is computed once per process: `ln Q(a) = T(a) - a^2/2` with
//!   `T(y) = ln(e^{y^2/2} Q(y))` (the log of the scaled tail: smooth, O(ln y)). Per call and
//!   node only the far edge `b = a + 2c` is new:
//!   `f = T(a) - a^2/2 + L(-(2xc + T(a) - T(b)))`, `L(d) = ln(1 - e^d)`,
//!   with `T(b)` and `L` read from process-wide piecewise-polynomial tables (`T` on uniform
//!   pieces, `L` on pieces geometric in `-d`, for its log singularity at 0), batched like the
//!   particles. Where `2xc >= 37` the far edge is below 1e-16 relative and the node needs nothing;
//!   such whole pieces reuse coefficients fitted once. Outside the band what the polynomials
//!   interpolate is the small, smooth `h = f + a^2/2`, and the exact `-a(t)^2/2` is added to the
//!   coefficients, so the large magnitudes of `f` (to -820) cost only the final roundings;
//!   inside (`a <= 0`, `P` near 1) they interpolate `f` itself, from `ln Q(a)` computed once.
//! * Narrow bands (`c < 0.01`): `T(b) - T(a)` would lose too many digits relative to
//!   `ln(Q(a) / Q(b))`, so their nodes come from an accurate scalar evaluation with the exact
//!   half-width (`band_h`, ~10 us per call); the table and the per-particle work are the same.
//!
//! Accuracy (tests `kernel_tests`): within 2.3e-13 of `log_q_band` on a dense grid of exactly
//! representable inputs, narrow bands included, wherever `P >= 1e-300`.

use super::normal::{central_mass, ln_scaled_q, log1mexp, log_q, log_q_band, LN_SQRT_2PI, NARROW};
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

/// Zheng et al.'s (2014) censored-sensor likelihood over many particles: for each `mu[p]` (the
/// innovation mean h(x_p) - h(x_ref)), adds `log(Phi((c - mu) s) - Phi((-c - mu) s))` to
/// `out[p]`, with `c = sqrt(eta s_k)` the half-width of the no-send band and `s = 1/sqrt(r)`
/// (eq. (9), (14), (44), (45): `Q(xi_1) - Q(xi_2)`). This is the particle filter's hot loop.
///
/// A call tabulates `ln P` against `|mu|` for its band (1-3 us; see the notes at the top
/// of this module; the thread keeps the tables of its 32 most recently used bands) and
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
mod kernel_tests;
