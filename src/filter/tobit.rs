//! The Tobit Kalman filter measurement update for one scalar, two-sided censored reading
//! (Geng et al., Theorem 1, eq. (20)-(25), built on Lemma 1; Allik et al.'s TKF for p = 1).
//!
//! The reading is `y = clamp(ybar, tau_l, tau_r)` with `ybar = h x + v`, `v ~ N(0, r)`
//! (eq. (6)-(7)). With `zeta = h x^-` and `theta = (tau - zeta)/sqrt(r)`:
//!
//! ```text
//! alpha = Phi(theta_l), beta = 1 - Phi(theta_r), pi = 1 - alpha - beta          (9)
//! y^-    = alpha tau_l + beta tau_r + pi (zeta - sqrt(r) lambda)                 (23), (12)
//! P_xy   = pi P^- h^T                                                            (24)
//! P_yy   = pi^2 (h P^- h^T + extra) + r (1 + varphi)                             (25)
//! K      = P_xy / P_yy,  x = x^- + K (y - y^-),  P = P^- - K P_xy^T              (20)-(22)
//! ```
//!
//! `extra` is the protocol term `sum_{l>=1} Gamma C P_{k-l} C^T Gamma` of (25); it is zero on
//! the step a sensor is scheduled (only one Gamma_{m, h_{k-l}}, l = 0..p-1, is one).
//! The two printed typos are options ([`TobitOptions`]), the correct reading the default.
use super::{FilterError, Gaussian};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::stats::truncated_normal::{censoring_probabilities, truncated_standard};

/// How theta is standardized. The paper's definitions after (11) and after Lemma 1 divide by
/// R; the moments (12)-(17) (and (9) itself) need sqrt(R).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ThetaDenominator {
    /// `theta = (tau - zeta) / sqrt(R)` (correct; default).
    #[default]
    SqrtR,
    /// `theta = (tau - zeta) / R` (as printed).
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
    pub alpha: f64,
    pub beta: f64,
    /// `1 - alpha - beta`.
    pub pi: f64,
    pub theta_l: f64,
    pub theta_r: f64,
    /// The predicted reading y^- of (23).
    pub y_hat: f64,
    /// `1 + varphi(theta_r, theta_l)` of (13), (25).
    pub var_factor: f64,
}

/// Lemma 1 / eq. (9), (23) at `zeta` for noise variance `r`.
pub fn terms(zeta: f64, r: f64, thr: &Thresholds, opts: &TobitOptions) -> TobitTerms {
    let sd = r.sqrt();
    let den = match opts.theta_denominator {
        ThetaDenominator::SqrtR => sd,
        ThetaDenominator::R => r,
    };
    let (theta_l, theta_r) = ((thr.lo - zeta) / den, (thr.hi - zeta) / den);
    let p = censoring_probabilities(theta_l, theta_r);
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
        assert!((printed_r.alpha - d.alpha).abs() > 1e-3);
        assert!((printed_sign.y_hat - d.y_hat).abs() > 1e-3);
        // The printed sign puts the prediction outside the censoring region's mean.
        assert!(printed_sign.y_hat > d.y_hat);
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
