//! `ln P(q^T q < eta)` with `q ~ N(m, C)` in two dimensions, for one `C` and `eta` and many
//! means `m`: the particle filter's vector-measurement likelihood (Zheng et al. (2014), eq. (33)).
//!
//! Why a separate kernel: [`QuadFormCdf::prob_below_slice`] is exact but general (any `n`,
//! either of two methods chosen per call, truncation bounds recomputed per mean) and costs
//! ~0.5 us per particle. With `n = 2`, one `C` and one `eta` per call, everything that does
//! not depend on `m` can be computed once, and the remaining per-mean work is a short
//! recurrence of multiply-adds that runs in SIMD lanes over eight means at a time.
//!
//! # Method: Ruben's series with the mean-independent parts hoisted
//! Rotate to the eigenbasis of `C` (`lambda_s <= lambda_b`, `b = U^T m`), so that
//! `q^T q = lambda_s (z_s + delta_s)^2 + lambda_b (z_b + delta_b)^2`,
//! `delta_j = b_j / sqrt(lambda_j)`. Ruben (1962, "Probability content of regions under
//! spherical normal distributions IV", Ann. Math. Stat. 33, 542-570; see also Kotz, Johnson
//! and Boyd 1967, Ann. Math. Stat. 38, 823-837) writes this generalized chi-square as a
//! mixture of scaled central chi-squares with `2 + 2k` degrees of freedom, which gives
//! (with `beta = lambda_s`, `t = eta / (2 beta)`)
//!
//! ```text
//! P = sum_k g_k C_k,   g_k = e^{-t} t^{k+1} / (k+1)!,   C_k = c_0 + ... + c_k,
//! sum_k c_k w^k = c_0 (1 - a w)^{-1/2} exp(e_s w + e_b w / (1 - a w)),
//! c_0 = sqrt(beta / lambda_b) exp(-(delta_s^2 + delta_b^2) / 2),
//! a = 1 - beta / lambda_b,  e_s = delta_s^2 / 2,  e_b = delta_b^2 beta / (2 lambda_b).
//! ```
//!
//! This is the same series [`QuadFormCdf`] sums (its module documentation derives it), so
//! the two agree to the series' truncation tolerance. Differences that make it fast:
//! * the Poisson weights `g_k`, and `1 / k`, `t / (k + 2)`, depend on `C` and `eta` only and
//!   are tabulated in [`EllipseBand2::new`];
//! * the weights `c_k` follow from the log-derivative of the generating function,
//!   `(k+1) c_{k+1} = sum_{i<=k} l_i c_{k-i}`, `l_i = (a/2 + e_b (i+1)) a^i + e_s [i = 0]`,
//!   carried by two running sums (`S = sum a^i c_{k-i}`, `U = sum (i+1) a^i c_{k-i}`), i.e.
//!   about ten flops per term and no transcendental function;
//! * the weights are computed relative to `c_0` (scaled by `c_0^{-1}`, or by `e^{680}` at
//!   most), so means far outside the disk do not underflow; the log of `c_0` is added at the
//!   end. All terms are nonnegative: no cancellation, relative accuracy down to the smallest
//!   probabilities the series is used for (~e^{-720}).
//!
//! **Truncation (rigorous, per mean).** Since every `l_i >= 0`,
//! `(k+1) c_{k+1} <= L C_k` with `L = e_s + a/2 + e_b max_i (i+1) a^i`, so the term ratio
//! obeys `T_{k+1} / T_k = (t / (k+2)) (1 + c_{k+1} / C_k) <= rho_k = (t / (k+2)) (1 + L / (k+1))`,
//! which decreases in `k`. Once `rho_k < 1` the remainder is at most
//! `T_k rho_k / (1 - rho_k)`; a lane stops when that is below `1e-13` of its partial sum.
//! Near means (`|m| < 3`) need ~15-30 terms, far ones (`|m| ~ 30`) ~100. Rounding adds
//! O(terms * 1e-16) relative. So the log is good to ~1e-12 absolute wherever the series is
//! used; the tests check 1e-9 against [`QuadFormCdf`].
//!
//! # Far means: a rigorous switch, then the saddlepoint approximation
//! Chernoff's bound `ln P <= K(-s) + s eta` (`K` the cumulant generating function of
//! `q^T q`) with `s = (|b| / sqrt(eta) - 1) / (2 lambda_b)` (the optimum for `C = lambda_b I`)
//! and the log-determinant part dropped gives, with two divisions,
//! `ln P <= s eta - sum_j b_j^2 s / (1 + 2 lambda_j s)`. Where that is below -720 the
//! probability is below e^{-720} < 1e-300, which the caller can only use as a very small
//! weight; there the kernel returns the saddlepoint approximation of the lower tail
//! (Daniels 1954, Ann. Math. Stat. 25, 631-650; the leading term of Lugannani and Rice 1980,
//! Adv. Appl. Prob. 12, 475-490):
//! `ln P ~ K(-s) + s eta - ln s - ln sqrt(2 pi K''(-s))` with `K'(-s) = eta`, found by Newton's
//! method (monotone convergence from the left: `K'` is convex in `s`), with the
//! Lugannani-Rice correction term. Its log differs from the exact series by at most 0.02
//! beyond `ln P = -500` in the tests (worst for a tiny disk, `eta = 0.05`, and a 24:1
//! spectrum; typically ~1e-3), so the switch moves the log by that much at most; it is finite for every finite mean and decreasing
//! along rays (tested to `|m| = 1e6`). The series would also be exact there but its length
//! grows like `|m|`, and it would need rescaling to survive `c_0 < e^{-1400}`.
//!
//! # Other cases
//! * `C` singular (one eigenvalue at most 1e-12 of the other, as [`QuadFormCdf`] decides):
//!   the null direction contributes the constant `b_n^2`, the other is the exact band
//!   `ln(Q(-s - d) - Q(s - d))` from [`normal::log_q_band`], `s = sqrt((eta - b_n^2) / lambda)`.
//!   `C = 0`: the indicator of `|m|^2 < eta`.
//! * Where such a probability is exactly 0 or below `e^{-700}`, the kernel returns
//!   `-700 - |m|^2 / eta`: finite, below every value returned inside, decreasing along rays.
//! * `t = eta / (2 lambda_s) > 200` (a nearly singular `C` with a wide disk; the series would
//!   need more than ~300 terms): each mean goes to [`QuadFormCdf::prob_below_slice`]
//!   (absolute accuracy 1e-10 there), the saddlepoint value where that returns 0. Slow
//!   (microseconds per mean) but exact; typical filters never get here.
//! * A mean with an infinite component returns `-1e300` (the value "at infinite radius"; the
//!   saddlepoint value is also clamped there, which only matters for `|m| > ~1e150`); a NaN
//!   component returns NaN.
//!
//! Deterministic: no fused multiply-adds, no reassociation, per-lane state only, and a
//! mean's value does not depend on the other means of the call (finished lanes freeze).

use super::chi2::StatsError;
use super::normal;
use super::quadform::QuadFormCdf;
use multiversion::multiversion;
use nalgebra::{DMatrix, SymmetricEigen};
use std::f64::consts::PI;

/// Eigenvalues at or below this fraction of the largest are exactly zero (as in QuadFormCdf).
const ZERO_REL: f64 = 1e-12;
/// Lanes of the series kernel.
const W: usize = 8;
/// Relative truncation tolerance of the series.
const TOL: f64 = 1e-13;
/// Beyond this `t = eta / (2 lambda_s)` the series is not used.
const T_MAX: f64 = 200.0;
/// Hard cap on the tabulated series length.
const K_CAP: usize = 2000;
/// The series is not extended where the Poisson weight `g_k` drops below this.
const G_MIN: f64 = 1e-290;
/// Chernoff bound below which a mean is "far" (saddlepoint approximation).
const LN_FAR: f64 = -720.0;
/// Largest log scale of the relative weights (keeps `e_b U` below the overflow threshold).
const LN_SCALE_MAX: f64 = 680.0;
/// Exact-zero and underflowing probabilities of the singular cases are reported below this.
const LN_CUT: f64 = -700.0;
/// The most negative value returned for a non-NaN mean.
const LN_MIN: f64 = -1e300;

/// What the covariance reduces to.
#[derive(Debug, Clone)]
enum Kind {
    /// `C = 0`: the indicator of `|m|^2 < eta`.
    Zero,
    /// Rank one: eigenvalue `lam` along `u`; `n` spans the null direction.
    Line { u: [f64; 2], n: [f64; 2], lam: f64 },
    /// Rank two: the series kernel (or the exact fallback when `series` is false).
    Full,
}

/// `P(q^T q < eta)`, `q ~ N(m, C)`, for one 2x2 `C` and `eta`, over many means.
///
/// See the module documentation for the method. Construction costs about as much as a few
/// dozen means (the tables of the series); [`EllipseBand2::add_log_prob_below`] allocates
/// nothing.
#[derive(Debug, Clone)]
pub struct EllipseBand2 {
    eta: f64,
    kind: Kind,
    /// Eigenvector of the smaller eigenvalue `lam_s`.
    u_s: [f64; 2],
    /// Eigenvector of the larger eigenvalue `lam_b`.
    u_b: [f64; 2],
    lam_s: f64,
    lam_b: f64,
    /// Ruben's `a = 1 - lam_s / lam_b`, and `a / 2`.
    a: f64,
    half_a: f64,
    /// `max_i (i + 1) a^i`.
    a_max: f64,
    /// `(1/2) ln(lam_s / lam_b)`.
    half_ln_ratio: f64,
    /// `(sqrt(eta) + sqrt(-2 LN_FAR lam_s))^2`: no mean with `|m|^2` below this is far.
    r2_near: f64,
    /// Whether the series kernel is used (`t <= T_MAX`); otherwise the exact fallback.
    series: bool,
    /// `g_k = e^{-t} t^{k+1} / (k+1)!`.
    g: Vec<f64>,
    /// `1 / k` (entry 0 unused).
    inv_k: Vec<f64>,
    /// `1 / (k + 1)`.
    inv_k1: Vec<f64>,
    /// `t / (k + 2)`.
    t_k2: Vec<f64>,
    exact: QuadFormCdf,
}

impl EllipseBand2 {
    /// Prepare for `C = c` (2x2 symmetric positive semidefinite, possibly singular) and `eta`.
    ///
    /// # Errors
    /// [`StatsError::InvalidArgument`] if `c` is not 2x2, is not symmetric (beyond 1e-9
    /// relative) or has non-finite entries, or if `eta` is not finite and positive;
    /// [`StatsError::NotPositiveSemidefinite`] as [`QuadFormCdf::new`] decides.
    pub fn new(c: &DMatrix<f64>, eta: f64) -> Result<Self, StatsError> {
        if c.nrows() != 2 || c.ncols() != 2 {
            return Err(StatsError::InvalidArgument("covariance must be 2x2"));
        }
        if !(eta.is_finite() && eta > 0.0) {
            return Err(StatsError::InvalidArgument(
                "eta must be finite and positive",
            ));
        }
        // Validation (symmetry, finiteness, PSD) exactly as the exact method does it.
        let exact = QuadFormCdf::new(c)?;
        let sym = (c + c.transpose()) * 0.5;
        let eig = SymmetricEigen::new(sym);
        let (i_s, i_b) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let lam_b = eig.eigenvalues[i_b].max(0.0);
        let lam_s = eig.eigenvalues[i_s];
        let col = |i: usize| [eig.eigenvectors[(0, i)], eig.eigenvectors[(1, i)]];
        let u_s = col(i_s);
        let u_b = col(i_b);
        let kind = if lam_b <= 0.0 {
            Kind::Zero
        } else if lam_s <= ZERO_REL * lam_b {
            Kind::Line {
                u: u_b,
                n: u_s,
                lam: lam_b,
            }
        } else {
            Kind::Full
        };
        let mut s = EllipseBand2 {
            eta,
            kind,
            u_s,
            u_b,
            lam_s,
            lam_b,
            a: 0.0,
            half_a: 0.0,
            a_max: 1.0,
            half_ln_ratio: 0.0,
            r2_near: 0.0,
            series: false,
            g: Vec::new(),
            inv_k: Vec::new(),
            inv_k1: Vec::new(),
            t_k2: Vec::new(),
            exact,
        };
        if matches!(s.kind, Kind::Full) {
            s.prepare_series();
        }
        Ok(s)
    }

    /// Tables of the series for rank-two `C`.
    fn prepare_series(&mut self) {
        let t = self.eta / (2.0 * self.lam_s);
        self.a = 1.0 - self.lam_s / self.lam_b;
        self.half_a = 0.5 * self.a;
        self.half_ln_ratio = 0.5 * (self.lam_s / self.lam_b).ln();
        self.r2_near = (self.eta.sqrt() + (-2.0 * LN_FAR * self.lam_s).sqrt()).powi(2);
        // max_i (i+1) a^i: the sequence increases while (i+2) a > (i+1).
        let mut v = 1.0;
        let mut best: f64 = 1.0;
        let mut i = 0.0;
        while (i + 2.0) * self.a > i + 1.0 {
            v *= self.a * (i + 2.0) / (i + 1.0);
            best = best.max(v);
            i += 1.0;
        }
        self.a_max = best;
        if t > T_MAX {
            return;
        }
        self.series = true;
        let mut g = t * (-t).exp();
        for k in 0..K_CAP {
            let kf = k as f64;
            if k > 0 {
                g *= t / (kf + 1.0);
            }
            if k > 0 && g < G_MIN && kf > t {
                break;
            }
            self.g.push(g);
            self.inv_k.push(if k == 0 { 0.0 } else { 1.0 / kf });
            self.inv_k1.push(1.0 / (kf + 1.0));
            self.t_k2.push(t / (kf + 2.0));
        }
    }

    /// `out[p] += ln P(q^T q < eta)` with `q ~ N((m0[p], m1[p]), C)`.
    ///
    /// Accurate to ~1e-12 in the log wherever `P >= e^{-720}` (tests: 1e-9 against
    /// [`QuadFormCdf`]); below, finite and decreasing along rays (see the module
    /// documentation). An infinite mean component gives `-1e300`, a NaN one NaN.
    ///
    /// # Panics
    /// If the three slices do not have the same length.
    pub fn add_log_prob_below(&self, m0: &[f64], m1: &[f64], out: &mut [f64]) {
        assert!(
            m0.len() == m1.len() && m0.len() == out.len(),
            "EllipseBand2::add_log_prob_below: slice lengths differ"
        );
        match self.kind {
            Kind::Zero => {
                for ((&x, &y), o) in m0.iter().zip(m1).zip(out.iter_mut()) {
                    *o += self.log_zero(x, y);
                }
            }
            Kind::Line { u, n, lam } => {
                for ((&x, &y), o) in m0.iter().zip(m1).zip(out.iter_mut()) {
                    *o += self.log_line(x, y, u, n, lam);
                }
            }
            Kind::Full => {
                let mut i = 0;
                while i < m0.len() {
                    let end = (i + W).min(m0.len());
                    self.full_block(&m0[i..end], &m1[i..end], &mut out[i..end]);
                    i = end;
                }
            }
        }
    }

    /// Value reported where the probability is exactly zero or underflows (singular `C`).
    fn log_negligible(&self, x: f64, y: f64) -> f64 {
        (LN_CUT - (x * x + y * y) / self.eta).max(LN_MIN)
    }

    fn log_zero(&self, x: f64, y: f64) -> f64 {
        if let Some(v) = non_finite(x, y) {
            return v;
        }
        if x * x + y * y < self.eta {
            0.0
        } else {
            self.log_negligible(x, y)
        }
    }

    fn log_line(&self, x: f64, y: f64, u: [f64; 2], n: [f64; 2], lam: f64) -> f64 {
        if let Some(v) = non_finite(x, y) {
            return v;
        }
        let b = u[0] * x + u[1] * y;
        let bn = n[0] * x + n[1] * y;
        let rest = self.eta - bn * bn;
        if rest <= 0.0 {
            return self.log_negligible(x, y);
        }
        let sl = lam.sqrt();
        let s = (rest / lam).sqrt();
        let d = b / sl;
        let lp = normal::log_q_band(-s - d, s - d);
        if lp >= LN_CUT {
            lp.min(0.0)
        } else {
            self.log_negligible(x, y)
        }
    }

    /// Up to `W` means of the rank-two case.
    fn full_block(&self, m0: &[f64], m1: &[f64], out: &mut [f64]) {
        let n = m0.len();
        let mut e_s = [0.0; W];
        let mut e_b = [0.0; W];
        let mut l_bound = [0.0; W];
        let mut scale = [0.0; W];
        let mut active = [0.0; W];
        // ln c_0 - ln(scale) per lane.
        let mut ln_off = [0.0; W];
        // Lanes decided outside the series (far, non-finite, or no series at all).
        let mut direct: [Option<f64>; W] = [None; W];
        for p in 0..n {
            let (x, y) = (m0[p], m1[p]);
            if let Some(v) = non_finite(x, y) {
                direct[p] = Some(v);
                continue;
            }
            let bs = self.u_s[0] * x + self.u_s[1] * y;
            let bb = self.u_b[0] * x + self.u_b[1] * y;
            // The bound is at least -(|b| - sqrt(eta))^2 / (2 lam_s): skip it inside that.
            if bs * bs + bb * bb > self.r2_near && self.chernoff(bs, bb) < LN_FAR {
                direct[p] = Some(self.saddlepoint(bs, bb));
                continue;
            }
            if !self.series {
                direct[p] = Some(self.fallback(x, y, bs, bb));
                continue;
            }
            let d2s = bs * bs / self.lam_s;
            let d2b = bb * bb / self.lam_b;
            let ln_c0 = self.half_ln_ratio - 0.5 * (d2s + d2b);
            e_s[p] = 0.5 * d2s;
            e_b[p] = 0.5 * d2b * (1.0 - self.a);
            l_bound[p] = e_s[p] + self.half_a + e_b[p] * self.a_max;
            // Weights relative to c_0, times e^{ln_c0 + LN_SCALE_MAX} when 1/c_0 would
            // exceed e^{LN_SCALE_MAX}.
            let ln_scale = (ln_c0 + LN_SCALE_MAX).min(0.0);
            if ln_scale < -LN_SCALE_MAX {
                direct[p] = Some(self.fallback(x, y, bs, bb));
                continue;
            }
            scale[p] = if ln_scale == 0.0 { 1.0 } else { ln_scale.exp() };
            ln_off[p] = ln_c0 - ln_scale;
            active[p] = 1.0;
        }
        let mut sum = [0.0; W];
        let mut still = [0.0; W];
        if active.iter().any(|&a| a > 0.0) {
            series_lanes(
                &SeriesTables {
                    a: self.a,
                    half_a: self.half_a,
                    g: &self.g,
                    inv_k: &self.inv_k,
                    inv_k1: &self.inv_k1,
                    t_k2: &self.t_k2,
                },
                &e_s,
                &e_b,
                &l_bound,
                &scale,
                &active,
                &mut sum,
                &mut still,
            );
        }
        for p in 0..n {
            let v = if let Some(v) = direct[p] {
                v
            } else if still[p] > 0.0 {
                // The table ended before the lane converged.
                let (x, y) = (m0[p], m1[p]);
                let bs = self.u_s[0] * x + self.u_s[1] * y;
                let bb = self.u_b[0] * x + self.u_b[1] * y;
                self.fallback(x, y, bs, bb)
            } else {
                (sum[p].ln() + ln_off[p]).min(0.0)
            };
            out[p] += v;
        }
    }

    /// Chernoff upper bound on `ln P` (see the module documentation).
    fn chernoff(&self, bs: f64, bb: f64) -> f64 {
        let r = ((bs * bs + bb * bb) / self.eta).sqrt();
        if r <= 1.0 {
            return 0.0;
        }
        let s = (r - 1.0) / (2.0 * self.lam_b);
        s * self.eta
            - bs * bs * s / (1.0 + 2.0 * self.lam_s * s)
            - bb * bb * s / (1.0 + 2.0 * self.lam_b * s)
    }

    /// Saddlepoint approximation of `ln P` in the lower tail (Daniels 1954).
    fn saddlepoint(&self, bs: f64, bb: f64) -> f64 {
        let lam = [self.lam_s, self.lam_b];
        let b2 = [bs * bs, bb * bb];
        let eta = self.eta;
        // Solve f(s) = K'(-s) - eta = sum lam/v + b^2/v^2 - eta = 0, v = 1 + 2 lam s. f is
        // decreasing and convex, and the isotropic start lies left of the root.
        let r = ((b2[0] + b2[1]) / eta).sqrt();
        let mut s = ((r - 1.0) / (2.0 * self.lam_b)).max(0.0);
        for _ in 0..100 {
            let mut f = -eta;
            let mut df = 0.0;
            for j in 0..2 {
                let v = 1.0 + 2.0 * lam[j] * s;
                let iv = 1.0 / v;
                f += lam[j] * iv + b2[j] * iv * iv;
                df += 2.0 * lam[j] * lam[j] * iv * iv + 4.0 * lam[j] * b2[j] * iv * iv * iv;
            }
            let step = f / df;
            s += step;
            if step.is_nan() || step <= 1e-15 * s {
                break;
            }
        }
        let mut k = 0.0;
        let mut k2 = 0.0;
        for j in 0..2 {
            let v = 1.0 + 2.0 * lam[j] * s;
            let iv = 1.0 / v;
            k += -0.5 * v.ln() - b2[j] * s * iv;
            k2 += 2.0 * lam[j] * lam[j] * iv * iv + 4.0 * lam[j] * b2[j] * iv * iv * iv;
        }
        // Lugannani-Rice with w^2 = -2 (K + s eta), u = s sqrt(K''): in the far tail
        // P = phi(w) (1/|u| + M(|w|) - 1/|w|), M the Mills ratio, whose difference from
        // 1/|w| is -1/|w|^3 + 3/|w|^5 - 15/|w|^7 + ... (|w| > 37 here: ~1e-10 relative).
        let expo = k + s * eta;
        let inv_u = 1.0 / (s * k2.sqrt());
        let w2 = -2.0 * expo;
        let iw2 = 1.0 / w2;
        let iw3 = iw2 / w2.sqrt();
        let corr = inv_u - iw3 * (1.0 - iw2 * (3.0 - 15.0 * iw2));
        let v = if w2 > 400.0 && corr > 0.5 * inv_u {
            expo - 0.5 * (2.0 * PI).ln() + corr.ln()
        } else {
            expo - s.ln() - 0.5 * (2.0 * PI * k2).ln()
        };
        if v.is_nan() {
            LN_MIN
        } else {
            v.clamp(LN_MIN, 0.0)
        }
    }

    /// The exact method, for means the series does not cover.
    fn fallback(&self, x: f64, y: f64, bs: f64, bb: f64) -> f64 {
        match self.exact.prob_below_slice(&[x, y], self.eta) {
            Ok(p) if p > 0.0 => p.ln().min(0.0),
            _ => self.saddlepoint(bs, bb),
        }
    }
}

/// `Some(value)` for a mean with a non-finite component.
fn non_finite(x: f64, y: f64) -> Option<f64> {
    if x.is_nan() || y.is_nan() {
        Some(f64::NAN)
    } else if x.is_infinite() || y.is_infinite() {
        Some(LN_MIN)
    } else {
        None
    }
}

/// The mean-independent parts of the series.
struct SeriesTables<'a> {
    a: f64,
    half_a: f64,
    g: &'a [f64],
    inv_k: &'a [f64],
    inv_k1: &'a [f64],
    t_k2: &'a [f64],
}

/// Ruben's series for `W` lanes at once: `sum[l] = sum_k g_k C_k / c_0 * scale[l]` for the
/// lanes with `active[l] = 1`; `still[l] = 1` for a lane that had not converged when the
/// table ended. A converged lane's state is zeroed, so it adds exact zeros afterwards (its
/// sum keeps its bits, and no subnormals or infinities arise).
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx2"))]
fn series_lanes<'t>(
    tb: &SeriesTables<'t>,
    e_s: &[f64; W],
    e_b: &[f64; W],
    l_bound: &[f64; W],
    scale: &[f64; W],
    active: &[f64; W],
    sum: &mut [f64; W],
    still: &mut [f64; W],
) {
    let a = tb.a;
    let half_a = tb.half_a;
    let mut c = [0.0; W];
    let mut s = [0.0; W];
    let mut u = [0.0; W];
    let mut cum = [0.0; W];
    let mut mask = [0.0; W];
    let g0 = tb.g[0];
    for l in 0..W {
        let c0 = scale[l] * active[l];
        c[l] = c0;
        s[l] = c0;
        u[l] = c0;
        cum[l] = c0;
        sum[l] = g0 * c0;
        mask[l] = active[l];
    }
    // Stopping test for the k = 0 term as for the others. (Written out here and in the loop:
    // a shared helper over a struct of the lane arrays measured 20% slower, `cargo bench
    // --bench quadform2d`.)
    {
        let t2 = tb.t_k2[0];
        for l in 0..W {
            let rho = t2 * (1.0 + l_bound[l] * tb.inv_k1[0]);
            let term = g0 * cum[l];
            // Non-short-circuit `|` and a select: one vector compare per condition.
            let go_on = (rho >= 1.0) | (term * rho > TOL * (1.0 - rho) * sum[l]);
            let keep = if go_on { mask[l] } else { 0.0 };
            c[l] *= keep;
            s[l] *= keep;
            u[l] *= keep;
            cum[l] *= keep;
            mask[l] = keep;
        }
    }
    let kmax = tb.g.len();
    let mut k = 1;
    while k < kmax && mask.iter().any(|&m| m > 0.0) {
        let gk = tb.g[k];
        let ik = tb.inv_k[k];
        let ik1 = tb.inv_k1[k];
        let t2 = tb.t_k2[k];
        for l in 0..W {
            let cn = (e_s[l] * c[l] + half_a * s[l] + e_b[l] * u[l]) * ik;
            let so = s[l];
            s[l] = a * so + cn;
            u[l] = a * (u[l] + so) + cn;
            c[l] = cn;
            cum[l] += cn;
            let term = gk * cum[l];
            sum[l] += term;
            let rho = t2 * (1.0 + l_bound[l] * ik1);
            // Non-short-circuit `|` and a select: one vector compare per condition.
            let go_on = (rho >= 1.0) | (term * rho > TOL * (1.0 - rho) * sum[l]);
            let keep = if go_on { mask[l] } else { 0.0 };
            c[l] *= keep;
            s[l] *= keep;
            u[l] *= keep;
            cum[l] *= keep;
            mask[l] = keep;
        }
        k += 1;
    }
    *still = mask;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(c: [[f64; 2]; 2], th: f64) -> DMatrix<f64> {
        let (s, co) = th.sin_cos();
        let u = DMatrix::from_row_slice(2, 2, &[co, -s, s, co]);
        let d = DMatrix::from_row_slice(2, 2, &[c[0][0], c[0][1], c[1][0], c[1][1]]);
        &u * d * u.transpose()
    }

    fn diag(a: f64, b: f64) -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, &[a, 0.0, 0.0, b])
    }

    /// The covariances of the accuracy tests, with names.
    fn covariances() -> Vec<(&'static str, DMatrix<f64>)> {
        vec![
            ("isotropic 0.6", diag(0.6, 0.6)),
            ("diag 0.3/0.9", diag(0.3, 0.9)),
            ("diag 0.9/0.3", diag(0.9, 0.3)),
            ("rotated 0.3/0.9", rot([[0.3, 0.0], [0.0, 0.9]], 0.7)),
            ("rotated 0.05/1.2", rot([[0.05, 0.0], [0.0, 1.2]], -1.1)),
            ("nearly singular 1e-6", rot([[1e-6, 0.0], [0.0, 1.0]], 0.3)),
            ("singular", rot([[0.0, 0.0], [0.0, 0.7]], 0.4)),
            ("zero", DMatrix::zeros(2, 2)),
        ]
    }

    const ETAS: [f64; 5] = [0.05, 0.5, 1.4, 2.8, 9.0];

    fn fast_one(k: &EllipseBand2, x: f64, y: f64) -> f64 {
        let mut o = [0.0];
        k.add_log_prob_below(&[x], &[y], &mut o);
        o[0]
    }

    /// Dense grid of means against the exact QuadFormCdf, batch call (mixed lanes).
    #[test]
    fn matches_quadform_cdf_on_a_dense_grid() {
        let mut worst = (0.0, "", 0.0, 0.0, 0.0);
        let mut checked = 0usize;
        for (name, c) in covariances() {
            let exact = QuadFormCdf::new(&c).unwrap();
            for &eta in &ETAS {
                let k = EllipseBand2::new(&c, eta).unwrap();
                let mut m0 = Vec::new();
                let mut m1 = Vec::new();
                // The nearly singular C routes every mean to QuadFormCdf (milliseconds each at
                // this conditioning), so it gets a coarser grid: the test there checks the
                // routing, not the series.
                let stride = if name.starts_with("nearly") { 5 } else { 1 };
                for ir in (0..=225).step_by(stride) {
                    let r = 0.2 * ir as f64;
                    for ia in 0..29 {
                        let th = 0.2167 * ia as f64 + 0.05;
                        m0.push(r * th.cos());
                        m1.push(r * th.sin());
                    }
                }
                let mut out = vec![0.0; m0.len()];
                k.add_log_prob_below(&m0, &m1, &mut out);
                for i in 0..m0.len() {
                    assert!(out[i].is_finite(), "{name} eta {eta}: not finite");
                    let p = exact.prob_below_slice(&[m0[i], m1[i]], eta).unwrap();
                    if p >= 1e-300 {
                        checked += 1;
                        let err = (out[i] - p.ln()).abs();
                        if err > worst.0 {
                            worst = (err, name, eta, m0[i], m1[i]);
                        }
                        assert!(
                            err <= 1e-9,
                            "{name} eta {eta} m ({}, {}): fast {} exact {}",
                            m0[i],
                            m1[i],
                            out[i],
                            p.ln()
                        );
                    } else {
                        // The exact method returns 0 where its Chernoff bound is below 1e-11.
                        assert!(out[i] < (1e-11f64).ln(), "{name} eta {eta}: {}", out[i]);
                    }
                }
            }
        }
        eprintln!("checked {checked}; worst |ln error| {worst:?}");
    }

    /// Along rays outward from the disk: finite and decreasing, out to |m| = 1e6.
    #[test]
    fn decreasing_and_finite_along_rays() {
        for (name, c) in covariances() {
            for &eta in &ETAS {
                let k = EllipseBand2::new(&c, eta).unwrap();
                // The nearly singular C takes the slow QuadFormCdf route: fewer, wider steps.
                let (angles, points, step) = if name.starts_with("nearly") {
                    (4, 800, 0.05)
                } else {
                    (16, 4000, 0.01)
                };
                for ia in 0..angles {
                    let th = std::f64::consts::FRAC_PI_8 * (16 / angles * ia) as f64 + 0.01;
                    let (s, co) = th.sin_cos();
                    let mut rs: Vec<f64> = (0..points)
                        .map(|i| 2.0 * eta.sqrt() + 0.5 + step * i as f64)
                        .collect();
                    let last = *rs.last().unwrap();
                    rs.extend((1..=400).map(|i| last * (1e6 / last).powf(i as f64 / 400.0)));
                    let m0: Vec<f64> = rs.iter().map(|r| r * co).collect();
                    let m1: Vec<f64> = rs.iter().map(|r| r * s).collect();
                    let mut out = vec![0.0; rs.len()];
                    k.add_log_prob_below(&m0, &m1, &mut out);
                    for i in 0..rs.len() {
                        assert!(out[i].is_finite(), "{name} eta {eta} r {}", rs[i]);
                        if i > 0 {
                            assert!(
                                out[i] <= out[i - 1],
                                "{name} eta {eta} th {th} r {} -> {}: {} -> {}",
                                rs[i - 1],
                                rs[i],
                                out[i - 1],
                                out[i]
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn symmetric_under_negated_mean() {
        for (name, c) in covariances() {
            for &eta in &ETAS {
                let k = EllipseBand2::new(&c, eta).unwrap();
                for i in 0..400 {
                    let r = 0.11 * i as f64;
                    let th = 0.37 * i as f64;
                    let (x, y) = (r * th.cos(), r * th.sin());
                    let a = fast_one(&k, x, y);
                    let b = fast_one(&k, -x, -y);
                    assert!(
                        (a - b).abs() <= 1e-12 * a.abs().max(1.0),
                        "{name} {eta}: {a} {b}"
                    );
                }
            }
        }
    }

    /// A mean's value does not depend on the other means of the call.
    #[test]
    fn independent_of_batch_and_deterministic() {
        let c = rot([[0.3, 0.0], [0.0, 0.9]], 0.7);
        let k = EllipseBand2::new(&c, 1.4).unwrap();
        let m0 = [0.1, 25.0, -3.0, 7.0, 0.0, 1e5, 2.0, -30.0, 0.5, 4.0];
        let m1 = [0.2, -3.0, 1.0, -7.0, 0.0, 3.0, 2.0, 1.0, 0.5, -1.0];
        let mut out = [0.0; 10];
        k.add_log_prob_below(&m0, &m1, &mut out);
        let mut again = [0.0; 10];
        k.add_log_prob_below(&m0, &m1, &mut again);
        for i in 0..10 {
            assert_eq!(out[i].to_bits(), again[i].to_bits());
            assert_eq!(
                out[i].to_bits(),
                fast_one(&k, m0[i], m1[i]).to_bits(),
                "{i}"
            );
        }
    }

    #[test]
    fn adds_to_out_and_handles_non_finite_means() {
        let k = EllipseBand2::new(&diag(0.4, 0.8), 1.0).unwrap();
        let mut out = [1.0, 2.0, 0.0, 0.0];
        k.add_log_prob_below(
            &[0.0, 0.0, f64::INFINITY, f64::NAN],
            &[0.0, 0.0, 1.0, 0.0],
            &mut out,
        );
        let v = fast_one(&k, 0.0, 0.0);
        assert_eq!(out[0], 1.0 + v);
        assert_eq!(out[1], 2.0 + v);
        assert_eq!(out[2], LN_MIN);
        assert!(out[3].is_nan());
        assert!(fast_one(&k, 1e300, 1e300) >= LN_MIN);
    }

    #[test]
    #[should_panic(expected = "slice lengths differ")]
    fn panics_on_length_mismatch() {
        let k = EllipseBand2::new(&diag(0.4, 0.8), 1.0).unwrap();
        k.add_log_prob_below(&[0.0, 1.0], &[0.0], &mut [0.0, 0.0]);
    }

    #[test]
    fn rejects_bad_inputs() {
        let good = diag(0.4, 0.8);
        assert!(EllipseBand2::new(&good, 1.0).is_ok());
        for eta in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(EllipseBand2::new(&good, eta).is_err(), "eta {eta}");
        }
        let asym = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.2, 1.0]);
        assert!(EllipseBand2::new(&asym, 1.0).is_err());
        let neg = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(
            EllipseBand2::new(&neg, 1.0),
            Err(StatsError::NotPositiveSemidefinite { .. })
        ));
        assert!(EllipseBand2::new(&DMatrix::identity(3, 3), 1.0).is_err());
        assert!(EllipseBand2::new(&DMatrix::zeros(2, 3), 1.0).is_err());
        assert!(EllipseBand2::new(&DMatrix::zeros(0, 0), 1.0).is_err());
        let nan = DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
        assert!(EllipseBand2::new(&nan, 1.0).is_err());
    }

    /// The saddlepoint value used beyond the switch is close to the exact series where both
    /// apply, so the switch changes the log by little (and it stays below the exact bound).
    #[test]
    fn saddlepoint_is_close_to_the_series_in_the_tail() {
        let mut worst: f64 = 0.0;
        let mut at = ("", 0.0, 0.0, 0.0, 0.0);
        for (name, c) in covariances().into_iter().take(5) {
            for &eta in &ETAS {
                let k = EllipseBand2::new(&c, eta).unwrap();
                for i in 0..200 {
                    let th = 0.031 * i as f64;
                    for r in [20.0, 25.0, 30.0, 35.0, 40.0] {
                        let (x, y) = (r * th.cos(), r * th.sin());
                        let bs = k.u_s[0] * x + k.u_s[1] * y;
                        let bb = k.u_b[0] * x + k.u_b[1] * y;
                        if k.chernoff(bs, bb) < LN_FAR {
                            continue;
                        }
                        let series = fast_one(&k, x, y);
                        if series > -500.0 {
                            continue;
                        }
                        let sp = k.saddlepoint(bs, bb);
                        if (sp - series).abs() > worst {
                            worst = (sp - series).abs();
                            at = (name, eta, x, y, series);
                        }
                    }
                }
            }
        }
        eprintln!(
            "worst |saddlepoint - series| in the log beyond ln P = -500: {worst:e} at {at:?}"
        );
        assert!(worst < 5e-2, "{worst}");
    }
}
