//! Steady-state NEES: the divergence rule, the chi-square bounds NEES is compared with, and the
//! mergeable log-spaced histogram of NEES / n from which the median is read (with the fast,
//! exact-bin log10 approximation it counts through).
use multiversion::multiversion;

/// The divergence rule: a trial has diverged when its NEES exceeds the chi-square(n) 99.9%
/// quantile for this many consecutive steps, or when any step's squared error or NEES is not
/// finite. A consistent filter does so with probability about 1e-30 per window of steps.
pub const DIVERGENCE_RUN: usize = 10;
/// Upper tail probability of the divergence threshold (the 99.9% quantile).
pub const DIVERGENCE_TAIL: f64 = 1e-3;

/// A fixed log-spaced histogram of steady-state NEES / n: exact counts that merge by addition,
/// from which the median is read by interpolating inside the bin that holds it (50 bins per
/// decade from 1e-4 to 1e12; a few tenths of a percent for a smooth distribution).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct NeesHistogram {
    /// Bin 0: below 1e-4; bin BINS + 1: at or above 1e12, or not finite.
    pub counts: Vec<u64>,
    /// Bins lo..hi hold every nonzero count (a block's few hundred values touch a fraction of
    /// the 802 bins, and merging and clearing visit only these). Not stored: a histogram read
    /// from a file is taken as touching every bin.
    #[serde(skip, default = "NeesHistogram::every_bin")]
    pub(super) touched: (usize, usize),
}

/// Equal counts (which bins were touched is bookkeeping).
impl PartialEq for NeesHistogram {
    fn eq(&self, other: &Self) -> bool {
        self.counts == other.counts
    }
}

impl NeesHistogram {
    pub(super) const LO: f64 = -4.0;
    pub(super) const PER_DECADE: f64 = 50.0;
    pub(super) const BINS: usize = 800;

    pub(super) fn new() -> Self {
        Self {
            counts: vec![0; Self::BINS + 2],
            touched: (0, 0),
        }
    }

    pub(super) fn every_bin() -> (usize, usize) {
        (0, Self::BINS + 2)
    }

    /// Widens the touched range to hold bins lo..hi.
    pub(super) fn touch(&mut self, lo: usize, hi: usize) {
        let (a, b) = self.touched;
        self.touched = if a == b {
            (lo, hi)
        } else {
            (a.min(lo), b.max(hi))
        };
    }

    #[cfg(test)]
    pub(super) fn add(&mut self, v: f64) {
        let b = Self::bin(v);
        self.counts[b] += 1;
        self.touch(b, b + 1);
    }

    /// Adds `v / divisor` for every `v` of `values` (the table looked up and the touched
    /// range widened once for all).
    pub(super) fn add_divided(&mut self, values: &[f64], divisor: f64) {
        let (lo, hi) = count_divided(&mut self.counts, log_table(), values, divisor);
        if lo < hi {
            self.touch(lo, hi);
        }
    }

    /// Back to no counts, keeping the allocation.
    pub(super) fn clear(&mut self) {
        let (lo, hi) = self.touched;
        self.counts[lo..hi].fill(0);
        self.touched = (0, 0);
    }

    /// The bin of `v`: 0 below 1e-4 (and for v <= 0), `BINS + 1` at or above 1e12 (and for
    /// anything not finite), else `1 + floor((log10 v - LO) * PER_DECADE)` with the library's
    /// log10. That log10 costs more than the rest of a step's bookkeeping, so the bin is first
    /// read from a cheap approximation of t = (log10 v - LO) * PER_DECADE that is within
    /// [`APPROX_T_ERROR`] of it; only when t is that close to a bin edge (a few in a million
    /// values) is the library's log10 called. Either way the bin is the one `exact_bin` gives.
    #[cfg(test)]
    pub(super) fn bin(v: f64) -> usize {
        match quick_bin(log_table(), v) {
            UNDECIDED => Self::exact_bin(v),
            b => b as usize,
        }
    }

    /// The bin by the definition (see [`NeesHistogram::bin`]).
    pub(super) fn exact_bin(v: f64) -> usize {
        if !v.is_finite() {
            Self::BINS + 1
        } else if v <= 0.0 {
            0
        } else {
            let t = (v.log10() - Self::LO) * Self::PER_DECADE;
            if t < 0.0 {
                0
            } else if t >= Self::BINS as f64 {
                Self::BINS + 1
            } else {
                1 + t as usize
            }
        }
    }

    pub(super) fn merge(&mut self, o: &NeesHistogram) {
        let (lo, hi) = o.touched;
        let hi = hi.min(o.counts.len()).min(self.counts.len());
        if lo >= hi {
            return;
        }
        for (a, b) in self.counts[lo..hi].iter_mut().zip(&o.counts[lo..hi]) {
            *a += b;
        }
        self.touch(lo, hi);
    }

    /// Number of values added.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// The median, interpolated log-linearly inside the bin that holds it; `None` when empty,
    /// the bin edge when it lies in the underflow or overflow bin (infinite for overflow).
    pub fn median(&self) -> Option<f64> {
        let total = self.total();
        if total == 0 {
            return None;
        }
        let half = total as f64 / 2.0;
        let mut acc = 0.0;
        for (b, &c) in self.counts.iter().enumerate() {
            let next = acc + c as f64;
            if next >= half && c > 0 {
                if b == 0 {
                    return Some(10f64.powf(Self::LO));
                }
                if b == Self::BINS + 1 {
                    return Some(f64::INFINITY);
                }
                let frac = (half - acc) / c as f64;
                return Some(10f64.powf(Self::LO + (b as f64 - 1.0 + frac) / Self::PER_DECADE));
            }
            acc = next;
        }
        None
    }
}

/// [`NeesHistogram::add_divided`]'s counting: the bin of every `v / divisor` counted, and the
/// range of bins counted in (empty: `lo >= hi`). Compiled also for AVX2 and picked at run
/// time: the same IEEE operations (no FMA contraction), hence the same bins.
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn count_divided(
    counts: &mut [u64],
    table: &LogTable,
    values: &[f64],
    divisor: f64,
) -> (usize, usize) {
    let (mut lo, mut hi) = (usize::MAX, 0);
    // In chunks: first every value's bin where the approximation decides it, in a loop
    // without branches (the compiler runs it four values at a time), then the counts, with
    // the library's log10 for the few values the approximation leaves undecided.
    const CHUNK: usize = 32;
    let mut bins = [0u32; CHUNK];
    for chunk in values.chunks(CHUNK) {
        for (b, &v) in bins.iter_mut().zip(chunk) {
            *b = quick_bin(table, v / divisor);
        }
        for (&b, &v) in bins.iter().zip(chunk) {
            let b = if b == UNDECIDED {
                NeesHistogram::exact_bin(v / divisor)
            } else {
                b as usize
            };
            counts[b] += 1;
            lo = lo.min(b);
            hi = hi.max(b + 1);
        }
    }
    (lo, hi)
}

/// What [`quick_bin`] returns for a value whose bin the approximation does not decide.
const UNDECIDED: u32 = u32::MAX;

/// The bin of `v` where the approximation of t ([`approx_t`]) decides it, [`UNDECIDED`]
/// otherwise (the caller then takes `exact_bin`): for a positive normal `v` whose t is at
/// least [`APPROX_T_ERROR`] from every bin edge, `1 + floor(t)`, the bin of the exact t too;
/// for one whose t is beyond the histogram's ends by that much, the end bin. Written without
/// branches, so that the compiler runs it four values at a time.
#[inline(always)]
fn quick_bin(table: &LogTable, v: f64) -> u32 {
    // approx_t's t, computed for every value (selected below only where it is defined).
    let t = t_in(table, v);
    let bins = NeesHistogram::BINS as f64;
    let defined = v.is_normal() && v > 0.0;
    let inside = (0.0..bins).contains(&t);
    // t in [0, BINS): its integer part by truncation, the fraction exactly (Sterbenz).
    let i = if inside { t as i32 } else { 0 };
    let frac = t - f64::from(i);
    let clear = (APPROX_T_ERROR..1.0 - APPROX_T_ERROR).contains(&frac);
    let bin = if inside {
        if clear {
            1 + i as u32
        } else {
            UNDECIDED
        }
    } else if t + APPROX_T_ERROR < 0.0 {
        0
    } else if t - APPROX_T_ERROR >= bins {
        NeesHistogram::BINS as u32 + 1
    } else {
        UNDECIDED
    };
    if defined {
        bin
    } else {
        UNDECIDED
    }
}

/// The chi-square(n) 99%, 95% and 99.9% quantiles that NEES is compared with: computed once
/// per state dimension for the whole process (an iterative inversion, once per trial and
/// variant before), the same numbers.
pub(super) fn nees_bounds(n: usize) -> [f64; 3] {
    use std::sync::OnceLock;
    const CACHED: usize = 32;
    static BOUNDS: [OnceLock<[f64; 3]>; CACHED] = [const { OnceLock::new() }; CACHED];
    let compute = || {
        let q =
            |tail: f64| crate::stats::chi2::upper_quantile(n as f64, tail).unwrap_or(f64::INFINITY);
        [q(0.01), q(0.05), q(DIVERGENCE_TAIL)]
    };
    match BOUNDS.get(n) {
        Some(cell) => *cell.get_or_init(compute),
        None => compute(),
    }
}

/// A bound on |approx_t(v) - t(v)|, where t(v) = (log10 v - LO) * PER_DECADE as
/// [`NeesHistogram::exact_bin`] computes it. The approximation's own error is below 1e-8 (see
/// [`approx_t`]); the library's log10 and the two roundings of t add a few 1e-13 at most.
pub(super) const APPROX_T_ERROR: f64 = 1e-6;

/// Entries of the table of log10 over the leading mantissa bits.
pub(super) const LOG_TABLE_BITS: u32 = 8;

/// Per leading-mantissa cell: 1/c and log10(c) of its centre c (see [`log_table`]).
pub(super) type LogTable = [[f64; 2]; 1 << LOG_TABLE_BITS];

/// Per leading-mantissa cell i (mantissa m in [1 + i/256, 1 + (i+1)/256)): the cell's centre
/// c, 1/c and log10(c).
pub(super) fn log_table() -> &'static LogTable {
    use std::sync::OnceLock;
    static TABLE: OnceLock<LogTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        let cells = (1u32 << LOG_TABLE_BITS) as f64;
        std::array::from_fn(|i| {
            let c = 1.0 + (i as f64 + 0.5) / cells;
            [1.0 / c, c.log10()]
        })
    })
}

/// (log10 v - LO) * PER_DECADE within 1e-8, for a positive normal v (`None` otherwise):
/// v = 2^e m with m in [1, 2); log10 v = e log10 2 + log10 c + log10(m / c) for the centre c
/// of m's table cell, the last term by three terms of the series of ln(1 + d) / ln 10 with
/// |d| < 1/512 (the first omitted term is below 1e-11, times 50 per decade below 1e-9; the
/// rounding of a dozen operations on numbers below 1000 adds about 1e-13).
#[cfg(test)]
pub(super) fn approx_t(v: f64) -> Option<f64> {
    approx_t_in(log_table(), v)
}

/// [`approx_t`] with its table at hand.
#[cfg(test)]
fn approx_t_in(table: &LogTable, v: f64) -> Option<f64> {
    (v.is_normal() && v > 0.0).then(|| t_in(table, v))
}

/// [`approx_t`]'s arithmetic for any `v` (meaningful for a positive normal one only).
#[inline(always)]
fn t_in(table: &LogTable, v: f64) -> f64 {
    let bits = v.to_bits();
    // The exponent as i32: its conversion to f64 is one instruction four values at a time
    // (AVX2 has none from i64), and the same number.
    let e = ((bits >> 52) & 0x7ff) as i32 - 1023;
    let cell = ((bits >> (52 - LOG_TABLE_BITS)) & ((1 << LOG_TABLE_BITS) - 1)) as usize;
    let m = f64::from_bits((bits & ((1u64 << 52) - 1)) | (1023u64 << 52));
    let [inv_c, log_c] = table[cell];
    let d = m * inv_c - 1.0;
    let ln1p = d * (1.0 - d * (0.5 - d * (1.0 / 3.0)));
    let log10 = f64::from(e) * std::f64::consts::LOG10_2 + log_c + ln1p * std::f64::consts::LOG10_E;
    (log10 - NeesHistogram::LO) * NeesHistogram::PER_DECADE
}

/// [`mahalanobis_sq`] with the factorization done in `buf` and the solve in `white`: the same
/// checks (square, finite), the same Cholesky factorization of a copy of `p` and the same
/// triangular solve, hence the same number, without allocating.
pub(super) fn nees_buffered(
    e: &[f64],
    p: &crate::linalg::Matrix,
    white: &mut crate::linalg::Vector,
    buf: &mut Option<crate::linalg::Matrix>,
) -> Result<f64, crate::linalg::LinalgError> {
    use crate::linalg::LinalgError;
    if p.nrows() != p.ncols() {
        return Err(LinalgError::NotSquare {
            rows: p.nrows(),
            cols: p.ncols(),
        });
    }
    if p.as_slice().iter().any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    // Dimensions 1..=6: the same factorization, solve and sum in fixed-size buffers.
    if let Some(r) = crate::linalg::fixed::mahalanobis_sq_small_slice(e, p) {
        return r.ok_or(LinalgError::NotPositiveDefinite);
    }
    let mut m = match buf.take() {
        Some(m) if m.shape() == p.shape() => m,
        _ => crate::linalg::Matrix::zeros(p.nrows(), p.ncols()),
    };
    m.copy_from(p);
    let chol = nalgebra::Cholesky::new(m).ok_or(LinalgError::NotPositiveDefinite)?;
    if white.len() != e.len() {
        *white = crate::linalg::Vector::zeros(e.len());
    }
    white.as_mut_slice().copy_from_slice(e);
    // Only the lower triangle is read: the dirty factor solves as `chol.l()` does.
    let solved = chol.l_dirty().solve_lower_triangular_mut(white);
    *buf = Some(chol.unpack_dirty());
    if !solved {
        return Err(LinalgError::NotPositiveDefinite);
    }
    Ok(white.norm_squared())
}
