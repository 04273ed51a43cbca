//! The Tobit Kalman filter measurement update for one scalar, two-sided censored reading
//! (Geng et al., Theorem 1, eq. (20)-(25), built on Lemma 1; Allik et al.'s TKF for p = 1).
//!
//! The reading is `y = clamp(ybar, tau_l, tau_r)` with `ybar = h x + v`, `v ~ N(0, r)`
//! (eq. (6)-(7)). With `zeta = h x^-`, `u = (tau - zeta)/sqrt(r)` and `theta` the argument of
//! (14)-(15) (equal to `u` in the corrected form, see below):
//!
//! ```text
//! alpha = Phi(u_l), beta = Phi(-u_r) = Phi((zeta - tau_r)/sqrt(r)), pi = 1 - alpha - beta  (9)
//! lambda = (phi(theta_r) - phi(theta_l)) / (Phi(theta_r) - Phi(theta_l))                 (14)
//! varphi = (theta_l phi(theta_l) - theta_r phi(theta_r)) / (Phi(theta_r) - Phi(theta_l))
//!          - lambda^2                                                                    (15)
//! y^-    = alpha tau_l + beta tau_r + pi (zeta - sqrt(r) lambda)                 (23), (12)
//! P_xy   = pi P^- h^T                                                            (24)
//! P_yy   = pi^2 (h P^- h^T + extra) + r (1 + varphi)                             (25)
//! K      = P_xy / P_yy,  x = x^- + K (y - y^-),  P = P^- - K P_xy^T              (20)-(22)
//! ```
//!
//! `extra` is the protocol term `sum_{l>=1} Gamma C P_{k-l} C^T Gamma` of (25); it is zero on
//! the step a sensor is scheduled (only one Gamma_{m, h_{k-l}}, l = 0..p-1, is one).
//!
//! **Printed and corrected form.** The paper standardizes by two different quantities:
//!
//! * the censoring probabilities (9) divide by `sqrt(R)`, the standard deviation:
//!   `alpha ~ Phi((tau_l - zeta^-)/sqrt(R))`, `beta ~ Phi((zeta^- - tau_r)/sqrt(R))`;
//! * the `theta` of (14)-(15) is defined after (11) (and, with `zeta^-`, in the notation
//!   before Lemma 2 that Theorem 1 uses) as `theta = (tau - zeta)/R`, the variance; (23) and
//!   (25) evaluate `lambda` and `varphi` at that theta (and Theorem 4's bound at `theta_l`).
//!
//! The corrected form ([`ThetaDenominator::SqrtR`], the default) uses `sqrt(R)` in all of them:
//! that is what (16)-(17) themselves write (`phi` and `Phi` of `(tau - zeta)/sqrt(R)`) and what
//! the truncated-normal moments (31)-(32) of `N(zeta, R)` need, so `theta = u` and `pi` equals
//! the denominator `Phi(theta_r) - Phi(theta_l)` of (14)-(15). The printed form
//! ([`ThetaDenominator::R`]) follows the equations literally: `sqrt(R)` in (9), `R` in the
//! theta of (14)-(15); then `pi` of (9) and the mass `Phi(theta_r) - Phi(theta_l)` in (14)-(15)
//! differ unless `R = 1`. The `sqrt(R)` factor before `lambda` in (23) and the `R` before
//! `1 + varphi` in (25) are printed that way and are the same in both forms.
//! The sign of the lambda term of (23) is the other printed typo ([`LambdaSign`]); the correct
//! reading of both is the default ([`TobitOptions`]).
use super::{FilterError, Gaussian};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::stats::truncated_normal::{censoring_probabilities, truncated_standard};

/// What standardizes the theta of (14)-(15). The censoring probabilities (9) divide by
/// `sqrt(R)` under either (as (9) prints); see the module doc for the two forms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ThetaDenominator {
    /// `theta = (tau - zeta) / sqrt(R)` in (14)-(15), as in (9) (corrected form; default).
    #[default]
    SqrtR,
    /// `theta = (tau - zeta) / R` in (14)-(15), as printed after (11) and before Lemma 2;
    /// (9) keeps the printed `sqrt(R)` (printed form).
    R,
}

/// The sign of the lambda term of (23). (12) and the truncated-normal mean (32) give
/// `zeta - sqrt(R) lambda(theta_r, theta_l)`; (23) prints `+ sqrt(R) lambda(theta_r - theta_l)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LambdaSign {
    /// `zeta - sqrt(R) lambda` (correct; default).
    #[default]
    Minus,
    /// `zeta + sqrt(R) lambda` (as printed in (23)).
    Plus,
}

/// Options for the printed typos.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TobitOptions {
    pub theta_denominator: ThetaDenominator,
    pub lambda_sign: LambdaSign,
}

/// Censoring thresholds `tau_l < tau_r` (eq. (6)); either may be infinite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    lo: f64,
    hi: f64,
}

impl Thresholds {
    /// `None` unless `lo < hi` and neither is NaN.
    pub fn new(lo: f64, hi: f64) -> Option<Self> {
        (lo < hi).then_some(Self { lo, hi })
    }
    /// No censoring.
    pub fn none() -> Self {
        Self {
            lo: f64::NEG_INFINITY,
            hi: f64::INFINITY,
        }
    }
    pub fn lo(&self) -> f64 {
        self.lo
    }
    pub fn hi(&self) -> f64 {
        self.hi
    }
    /// The detection device of eq. (6): `tau_l` if `ybar <= tau_l`, `tau_r` if `ybar >= tau_r`,
    /// else `ybar`.
    pub fn censor(&self, ybar: f64) -> f64 {
        censor(ybar, self.lo, self.hi).value(self.lo, self.hi)
    }
}

/// Where a reading fell against the censoring region `(tau_l, tau_r)` (Geng et al., eq. (6)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Censored {
    /// `z <= tau_l`: the estimator sees `y = tau_l` (alpha = 1 in eq. (7)).
    Left,
    /// `z >= tau_r`: the estimator sees `y = tau_r` (beta = 1 in eq. (7)).
    Right,
    /// `tau_l < z < tau_r`: the estimator sees `y = z`.
    Inside(f64),
}

impl Censored {
    /// The censored observation `y` of eq. (6): `tau_l`, `tau_r` or `z`.
    pub fn value(self, tau_l: f64, tau_r: f64) -> f64 {
        match self {
            Censored::Left => tau_l,
            Censored::Right => tau_r,
            Censored::Inside(z) => z,
        }
    }

    /// Whether the reading was censored (left or right).
    pub fn is_censored(self) -> bool {
        !matches!(self, Censored::Inside(_))
    }
}

/// Geng et al., eq. (6): the two-sided (dead-zone-like) censoring of a reading `z` with
/// `tau_l < tau_r`. The boundaries belong to the censored sides, as printed (`z <= tau_l` is
/// left-censored, `z >= tau_r` right-censored). Infinite thresholds never censor a finite `z`.
/// A NaN `z` compares false with everything and comes back as `Inside(NaN)`: callers reject
/// non-finite readings first (the fusion center does).
#[inline]
pub fn censor(z: f64, tau_l: f64, tau_r: f64) -> Censored {
    if z <= tau_l {
        Censored::Left
    } else if z >= tau_r {
        Censored::Right
    } else {
        Censored::Inside(z)
    }
}

/// The Lemma 1 quantities at a predicted reading `zeta` (what (22)-(25) and the bounds of
/// Theorem 4 use).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TobitTerms {
    /// The censoring probabilities of (9), standardized by `sqrt(R)` under either option.
    pub alpha: f64,
    pub beta: f64,
    /// `1 - alpha - beta` of (9) (computed as `Phi(u_r) - Phi(u_l)`).
    pub pi: f64,
    /// The arguments of (14)-(15) (`/ sqrt(R)` or, printed, `/ R`).
    pub theta_l: f64,
    pub theta_r: f64,
    /// The predicted reading y^- of (23).
    pub y_hat: f64,
    /// `1 + varphi(theta_r, theta_l)` of (13), (15), (25).
    pub var_factor: f64,
}

/// Lemma 1 / eq. (9), (14), (15), (23) at `zeta` for noise variance `r`: the censoring
/// probabilities (9) from `(tau - zeta)/sqrt(r)`, `lambda` (14) and `varphi` (15) from the
/// theta `opts` chooses (`/ sqrt(r)`, or `/ r` as printed).
pub fn terms(zeta: f64, r: f64, thr: &Thresholds, opts: &TobitOptions) -> TobitTerms {
    let sd = r.sqrt();
    // (9): alpha = Phi((tau_l - zeta)/sqrt(R)), beta = Phi((zeta - tau_r)/sqrt(R)).
    let (u_l, u_r) = ((thr.lo - zeta) / sd, (thr.hi - zeta) / sd);
    let p = censoring_probabilities(u_l, u_r);
    // (14)-(15) at theta: the same standardization, or the printed one by R.
    let (theta_l, theta_r) = match opts.theta_denominator {
        ThetaDenominator::SqrtR => (u_l, u_r),
        ThetaDenominator::R => ((thr.lo - zeta) / r, (thr.hi - zeta) / r),
    };
    let t = truncated_standard(theta_l, theta_r);
    let lambda_term = match opts.lambda_sign {
        LambdaSign::Minus => -sd * t.lambda(),
        LambdaSign::Plus => sd * t.lambda(),
    };
    let mut y_hat = p.pi * (zeta + lambda_term);
    if p.alpha > 0.0 {
        y_hat += p.alpha * thr.lo;
    }
    if p.beta > 0.0 {
        y_hat += p.beta * thr.hi;
    }
    TobitTerms {
        alpha: p.alpha,
        beta: p.beta,
        pi: p.pi,
        theta_l,
        theta_r,
        y_hat,
        var_factor: t.var,
    }
}

/// Theorem 1's update (20)-(25) of the prediction `pred` with the censored reading `y` of a
/// scalar sensor `h` (1 x n), noise variance `r`. `extra` is the protocol term of (25) (zero
/// on a scheduled step). The covariance is formed in the Joseph-like form
/// `(I - pi K h) P^- (I - pi K h)^T + K (P_yy - pi^2 h P^- h^T) K^T`, which equals (21) and
/// stays positive semi-definite under rounding.
pub fn update(
    pred: Gaussian,
    h: &Matrix,
    r: f64,
    y: f64,
    extra: f64,
    thr: &Thresholds,
    opts: &TobitOptions,
) -> Result<(Gaussian, TobitTerms), FilterError> {
    if !y.is_finite() {
        return Err(FilterError::NonFiniteMeasurement(vec![y]));
    }
    let zeta = (h * &pred.mean)[0];
    let t = terms(zeta, r, thr, opts);
    let ph = &pred.cov * h.transpose(); // P^- h^T, n x 1
    let hph = (h * &ph)[0];
    let s = t.pi * t.pi * (hph + extra) + r * t.var_factor; // (25)
    if !(s > 0.0 && s.is_finite()) {
        return Err(FilterError::Matrix {
            what: "Tobit innovation variance P_yy (25)",
            source: crate::linalg::LinalgError::NotPositiveDefinite,
        });
    }
    let k = &ph * (t.pi / s); // (22) with (24)
    let mean = &pred.mean + &k * (y - t.y_hat); // (20)
    let n = pred.dim();
    let i_kh = Matrix::identity(n, n) - &k * h * t.pi;
    let rest = s - t.pi * t.pi * hph;
    let mut cov = &i_kh * &pred.cov * i_kh.transpose() + &k * k.transpose() * rest; // (21)
    symmetrize(&mut cov);
    Ok((Gaussian { mean, cov }, t))
}

/// Buffers of [`update_in_place`] for an n-dimensional state, sized at construction so an
/// update allocates nothing.
#[derive(Debug, Clone)]
pub struct UpdateWork {
    /// `h x^-` (1).
    zeta: Vector,
    /// `h^T` (n x 1), copied per update (a transpose is exact).
    ht: Matrix,
    /// `P^- h^T` (n x 1).
    ph: Matrix,
    /// `h P^- h^T` (1 x 1).
    hph: Matrix,
    /// The gain K of (22) (n x 1) and its transpose.
    k: Matrix,
    kt: Matrix,
    /// `I - pi K h` and its transpose (n x n).
    i_kh: Matrix,
    i_kh_t: Matrix,
    /// `(I - pi K h) P^-`, then `K K^T` (n x n).
    prod: Matrix,
    kk: Matrix,
}

impl UpdateWork {
    /// Buffers for an n-dimensional state.
    pub fn new(n: usize) -> Self {
        Self {
            zeta: Vector::zeros(1),
            ht: Matrix::zeros(n, 1),
            ph: Matrix::zeros(n, 1),
            hph: Matrix::zeros(1, 1),
            k: Matrix::zeros(n, 1),
            kt: Matrix::zeros(1, n),
            i_kh: Matrix::zeros(n, n),
            i_kh_t: Matrix::zeros(n, n),
            prod: Matrix::zeros(n, n),
            kk: Matrix::zeros(n, n),
        }
    }
}

/// [`update`] of `est` in place through `work`: the same operations in the same order (each
/// product by nalgebra's gemm into a buffer, as `a * b` computes it, the n x n ones by
/// [`fixed::gemm`](crate::linalg::fixed::gemm), which is that gemm bit for bit; the scalings, sums and
/// differences entry by entry with the same operands), hence the same bits, without
/// allocating. On an error `est` is left as it was.
#[allow(clippy::too_many_arguments, clippy::assign_op_pattern)]
pub fn update_in_place(
    est: &mut Gaussian,
    h: &Matrix,
    r: f64,
    y: f64,
    extra: f64,
    thr: &Thresholds,
    opts: &TobitOptions,
    work: &mut UpdateWork,
) -> Result<TobitTerms, FilterError> {
    use crate::linalg::fixed;
    if !y.is_finite() {
        return Err(FilterError::NonFiniteMeasurement(vec![y]));
    }
    let w = work;
    fixed::gemv(&mut w.zeta, h, &est.mean);
    let t = terms(w.zeta[0], r, thr, opts);
    w.ht.tr_copy_from(h);
    w.ph.gemm(1.0, &est.cov, &w.ht, 0.0); // P^- h^T, n x 1
    w.hph.gemm(1.0, h, &w.ph, 0.0);
    let hph = w.hph[0];
    let s = t.pi * t.pi * (hph + extra) + r * t.var_factor; // (25)
    if !(s > 0.0 && s.is_finite()) {
        return Err(FilterError::Matrix {
            what: "Tobit innovation variance P_yy (25)",
            source: crate::linalg::LinalgError::NotPositiveDefinite,
        });
    }
    // (22) with (24): K = P_xy / P_yy.
    let c = t.pi / s;
    for (ki, phi) in w.k.iter_mut().zip(w.ph.iter()) {
        *ki = phi * c;
    }
    // (20): x = x^- + K (y - y^-).
    let d = y - t.y_hat;
    for (xi, ki) in est.mean.iter_mut().zip(w.k.iter()) {
        *xi = *xi + ki * d;
    }
    // I - (K h) pi.
    w.i_kh.gemm(1.0, &w.k, h, 0.0);
    let n = est.mean.len();
    for j in 0..n {
        for i in 0..n {
            let id = if i == j { 1.0 } else { 0.0 };
            w.i_kh[(i, j)] = id - w.i_kh[(i, j)] * t.pi;
        }
    }
    let rest = s - t.pi * t.pi * hph;
    // (21): ((I - pi K h) P^-) (I - pi K h)^T + (K K^T) rest.
    fixed::gemm(&mut w.prod, &w.i_kh, &est.cov);
    w.i_kh_t.tr_copy_from(&w.i_kh);
    fixed::gemm(&mut est.cov, &w.prod, &w.i_kh_t);
    w.kt.tr_copy_from(&w.k);
    w.kk.gemm(1.0, &w.k, &w.kt, 0.0);
    for (p, kk) in est.cov.iter_mut().zip(w.kk.iter()) {
        *p = *p + kk * rest;
    }
    symmetrize(&mut est.cov);
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::kf;
    use crate::linalg::{matrix_from_rows, Vector};
    use crate::model::LinearSensor;

    fn pred() -> Gaussian {
        Gaussian::new(
            Vector::from_vec(vec![1.0, -0.5, 0.2]),
            matrix_from_rows(&[
                vec![0.5, 0.1, 0.0],
                vec![0.1, 0.3, 0.05],
                vec![0.0, 0.05, 0.2],
            ]),
        )
    }

    /// Thresholds at +-infinity: the Tobit update is the Kalman update.
    #[test]
    fn without_censoring_it_is_the_kalman_update() {
        let h = matrix_from_rows(&[vec![1.0, 0.5, 0.0]]);
        let r = 0.6;
        let sensor = LinearSensor::new(h.clone(), Matrix::from_element(1, 1, r)).unwrap();
        for y in [-3.0, 0.4, 2.0] {
            let kfu = kf::update(&sensor, pred(), &Vector::from_element(1, y)).unwrap();
            let (tu, t) = update(
                pred(),
                &h,
                r,
                y,
                0.0,
                &Thresholds::none(),
                &TobitOptions::default(),
            )
            .unwrap();
            assert_eq!((t.alpha, t.beta, t.pi, t.var_factor), (0.0, 0.0, 1.0, 1.0));
            assert!((&tu.mean - &kfu.mean).amax() < 1e-14);
            assert!((&tu.cov - &kfu.cov).amax() < 1e-14);
        }
    }

    /// (21) in its printed short form equals the Joseph-like form used.
    #[test]
    fn covariance_equals_the_printed_short_form() {
        let h = matrix_from_rows(&[vec![0.0, 1.0, 0.0]]);
        let thr = Thresholds::new(-1.0, 0.0).unwrap();
        let (u, t) = update(pred(), &h, 0.6, -1.0, 0.0, &thr, &TobitOptions::default()).unwrap();
        let p = pred().cov;
        let ph = &p * h.transpose();
        let s = t.pi * t.pi * (&h * &ph)[0] + 0.6 * t.var_factor;
        let k = &ph * (t.pi / s);
        let short = &p - &k * ph.transpose() * t.pi;
        assert!((&u.cov - short).amax() < 1e-14);
        assert!(t.alpha > 0.0 && t.beta > 0.0 && t.pi < 1.0);
    }

    /// The printed typos change the answer (so the options are live), and the default reading
    /// predicts the censored reading's mean of Lemma 1 (12).
    #[test]
    fn typo_options_differ_and_default_is_lemma1() {
        let thr = Thresholds::new(-1.0, 1.0).unwrap();
        let d = terms(0.8, 0.6, &thr, &TobitOptions::default());
        let lemma = crate::stats::truncated_normal::censored_moments(0.8, 0.6, -1.0, 1.0);
        assert!((d.y_hat - lemma.mean).abs() < 1e-14);
        let printed_r = terms(
            0.8,
            0.6,
            &thr,
            &TobitOptions {
                theta_denominator: ThetaDenominator::R,
                ..Default::default()
            },
        );
        let printed_sign = terms(
            0.8,
            0.6,
            &thr,
            &TobitOptions {
                lambda_sign: LambdaSign::Plus,
                ..Default::default()
            },
        );
        // (9) prints sqrt(R) under both readings: only (14)-(15) see the printed R.
        assert_eq!(
            (printed_r.alpha, printed_r.beta, printed_r.pi),
            (d.alpha, d.beta, d.pi)
        );
        assert!((printed_r.var_factor - d.var_factor).abs() > 1e-3);
        assert!((printed_r.y_hat - d.y_hat).abs() > 1e-3);
        assert!((printed_sign.y_hat - d.y_hat).abs() > 1e-3);
        // The printed sign puts the prediction outside the censoring region's mean.
        assert!(printed_sign.y_hat > d.y_hat);
    }

    /// The printed form worked by hand at `zeta = 0`, `R = 0.25` (`sqrt(R) = 0.5`),
    /// `tau_l = -0.5`, `tau_r = 1`, against the corrected form at the same point.
    ///
    /// (9), `sqrt(R)` under both: `alpha = Phi(-0.5 / 0.5) = Phi(-1) = 0.15865525393145705`,
    /// `beta = Phi((0 - 1) / 0.5) = Phi(-2) = 0.02275013194817921`,
    /// `pi = Phi(2) - Phi(-1) = 0.8185946141203637` (30-digit values, rounded).
    ///
    /// (14)-(15), printed: `theta_l = -0.5 / 0.25 = -2`, `theta_r = 1 / 0.25 = 4`;
    /// `phi(-2) = 0.05399096651318806`, `phi(4) = 0.00013383022576488537`,
    /// `Z = Phi(4) - Phi(-2) = 0.9772181968099877`;
    /// `lambda = (phi(4) - phi(-2)) / Z = -0.05511270304138151`;
    /// `varphi = (-2 phi(-2) - 4 phi(4)) / Z - lambda^2 = -0.11408451730865699`, so
    /// `1 + varphi = 0.885915482691343`; (23):
    /// `y^- = -0.5 alpha + 1 beta + pi (0 - 0.5 lambda) = -0.03402001407790437`.
    ///
    /// Corrected: `theta = (-1, 2)`, `Z = pi`, `lambda = (phi(2) - phi(-1)) / pi =
    /// -0.22963717909132897`, `1 + varphi = 1 + (-phi(-1) - 2 phi(2)) / pi - lambda^2 =
    /// 0.5197625392115339`, `y^- = 0.03741238398542833`.
    ///
    /// The old printed option divided (9) by R too: `alpha = Phi(-2) = 0.0228`,
    /// `beta = Phi(-4) = 3.2e-5`, `y^- = 0.0156`; the asserts below tell it apart.
    #[test]
    fn printed_theta_by_hand_sqrt_r_in_9_and_r_in_14_15() {
        let thr = Thresholds::new(-0.5, 1.0).unwrap();
        let close = |got: f64, want: f64, what: &str| {
            assert!((got - want).abs() < 1e-14, "{what}: {got} vs {want}");
        };
        let printed = TobitOptions {
            theta_denominator: ThetaDenominator::R,
            ..Default::default()
        };
        for (opts, thetas, var_factor, y_hat) in [
            (
                printed,
                (-2.0, 4.0),
                0.885915482691343,
                -0.03402001407790437,
            ),
            (
                TobitOptions::default(),
                (-1.0, 2.0),
                0.5197625392115339,
                0.03741238398542833,
            ),
        ] {
            let t = terms(0.0, 0.25, &thr, &opts);
            close(t.alpha, 0.15865525393145705, "alpha (9)");
            close(t.beta, 0.02275013194817921, "beta (9)");
            close(t.pi, 0.8185946141203637, "pi (9)");
            assert_eq!((t.theta_l, t.theta_r), thetas);
            close(t.var_factor, var_factor, "1 + varphi (15)");
            close(t.y_hat, y_hat, "y^- (23) with lambda (14)");
        }
        // lambda (14) and varphi (15) on their own at the printed theta.
        let m = truncated_standard(-2.0, 4.0);
        close(m.lambda(), -0.05511270304138151, "lambda (14)");
        close(m.varphi(), -0.11408451730865699, "varphi (15)");
    }

    /// `update_in_place` is `update` bit for bit: random priors of dimensions 1..=7 (the
    /// fixed-size kernels, matrixmultiply's 6 x 6 and nalgebra's dynamic path), readings
    /// inside and at both thresholds, both printed typos, one buffer reused across sizes.
    #[test]
    fn update_in_place_is_update_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let bits = |m: &Matrix| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
        let thr = Thresholds::new(-0.5, 0.7).unwrap();
        for trial in 0..600 {
            let n = 1 + trial % 7;
            let mut work = UpdateWork::new(n);
            let b = Matrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
            let mut cov = &b * b.transpose() + Matrix::identity(n, n) * 0.1;
            symmetrize(&mut cov);
            let pred = Gaussian::new(Vector::from_fn(n, |_, _| rng.random_range(-1.0..1.0)), cov);
            let h = Matrix::from_fn(1, n, |_, _| rng.random_range(-1.0..1.0));
            let r = rng.random_range(0.01..1.0);
            let y = thr.censor(rng.random_range(-1.5..1.5));
            let opts = TobitOptions {
                theta_denominator: if trial % 3 == 0 {
                    ThetaDenominator::R
                } else {
                    ThetaDenominator::SqrtR
                },
                lambda_sign: if trial % 5 == 0 {
                    LambdaSign::Plus
                } else {
                    LambdaSign::Minus
                },
            };
            let extra = if trial % 2 == 0 { 0.0 } else { 0.3 };
            let (want, wt) = update(pred.clone(), &h, r, y, extra, &thr, &opts).unwrap();
            let mut got = pred.clone();
            let gt = update_in_place(&mut got, &h, r, y, extra, &thr, &opts, &mut work).unwrap();
            assert_eq!(wt, gt);
            assert_eq!(bits(&want.cov), bits(&got.cov), "n {n}");
            assert_eq!(
                want.mean.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                got.mean.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
        let mut e = pred();
        let h = matrix_from_rows(&[vec![1.0, 0.0, 0.0]]);
        let opts = TobitOptions::default();
        let err = update_in_place(
            &mut e,
            &h,
            0.6,
            f64::NAN,
            0.0,
            &thr,
            &opts,
            &mut UpdateWork::new(3),
        );
        assert!(err.is_err());
        assert_eq!(e, pred());
    }

    #[test]
    fn detection_device_censors_at_the_thresholds() {
        let thr = Thresholds::new(-5.0, 5.0).unwrap();
        assert_eq!(thr.censor(-7.0), -5.0);
        assert_eq!(thr.censor(-5.0), -5.0);
        assert_eq!(thr.censor(4.9), 4.9);
        assert_eq!(thr.censor(5.0), 5.0);
        assert_eq!(thr.censor(9.0), 5.0);
        assert!(Thresholds::new(1.0, 1.0).is_none());
        assert!(Thresholds::new(f64::NAN, 1.0).is_none());
    }
}
