//! The Tobit Kalman filter measurement update for one scalar, two-sided censored reading
//! (seed 002, Theorem 1, eq. (20)-(25), built on Lemma 1; Allik et al.'s TKF for p = 1).
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
use crate::linalg::{symmetrize, Matrix};
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

/// Where a reading fell against the censoring region `(tau_l, tau_r)` (seed 002, eq. (6)).
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

/// Seed 002, eq. (6): the two-sided (dead-zone-like) censoring of a reading `z` with
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
