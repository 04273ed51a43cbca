//! The scalar floors in closed form: fully observed `x' = a x + w` (Tatikonda–Sahai–Mitter) and
//! a noisy sensor `z = h x + v` (Kalman error plus the floor of the Kalman estimate process).
//! The derivations are in the parent module's doc.
use super::FloorError;

/// Smallest rate (bits per step) with a finite floor: `max(0, log2|a|)`. Below it no scheme
/// keeps the error bounded (the data-rate theorem); at it the floor is infinite for `|a| >= 1`.
pub fn min_rate(a: f64) -> f64 {
    a.abs().log2().max(0.0)
}

/// The causal rate–distortion floor of the fully observed scalar Gauss–Markov source
/// `x' = a x + w`, `w ~ N(0, w_var)`: `D(R) = W / (2^{2R} - a^2)`, the smallest steady-state
/// mean squared error of any causal scheme at `rate` bits per step.
///
/// Errors: [`FloorError::RateTooLow`] when `rate < 0` or `rate <= log2|a|` (the floor is
/// infinite there), [`FloorError::Invalid`] for a non-finite `a` or a `w_var` that is not
/// positive and finite. A stable source at `rate = 0` gets its stationary variance
/// `W / (1 - a^2)`.
pub fn distortion(a: f64, w_var: f64, rate: f64) -> Result<f64, FloorError> {
    check_source(a, w_var)?;
    check_rate(a, rate)?;
    let denom = (2.0 * rate).exp2() - a * a;
    if denom <= 0.0 {
        // Only reachable by rounding right at log2|a|.
        return Err(FloorError::RateTooLow {
            rate,
            min: min_rate(a),
        });
    }
    Ok(w_var / denom)
}

/// The inverse of [`distortion`]: the smallest rate (bits per step) at which a causal scheme can
/// hold the steady-state mean squared error to `d`, `R(D) = ½ log2(a^2 + W / D)`, and 0 once `d`
/// reaches the stationary variance of a stable source (sending nothing and estimating 0 does).
///
/// Errors: [`FloorError::Invalid`] for `d` not positive (every positive rate is too little for
/// zero error) or not finite, and for the source checks of [`distortion`].
pub fn rate(a: f64, w_var: f64, d: f64) -> Result<f64, FloorError> {
    check_source(a, w_var)?;
    if !(d.is_finite() && d > 0.0) {
        return Err(FloorError::Invalid(format!(
            "distortion must be positive and finite, got {d}"
        )));
    }
    Ok((0.5 * (a * a + w_var / d).log2()).max(0.0))
}

/// Steady state of the scalar Kalman filter for `x' = a x + w`, `z = h x + v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarKalman {
    /// Prediction (prior) variance `M = a^2 P + W`.
    pub prior: f64,
    /// Filtered (posterior) variance `P = M V / (h^2 M + V)`: the all-data error.
    pub posterior: f64,
}

impl ScalarKalman {
    /// Variance of the estimate's driving term `K nu` (gain times innovation): `K^2 S = M - P`.
    pub fn estimate_noise(&self) -> f64 {
        self.prior - self.posterior
    }
}

/// The steady-state Kalman variances from the positive root of the scalar Riccati equation
/// `h^2 M^2 + (V(1 - a^2) - W h^2) M - W V = 0`, each root form chosen to avoid cancellation.
///
/// Errors: [`FloorError::Invalid`] for non-finite inputs, `W <= 0` or `V <= 0`, and for `h = 0`
/// with `|a| >= 1` (the error grows without bound: no steady state).
pub fn kalman(a: f64, w_var: f64, h: f64, v_var: f64) -> Result<ScalarKalman, FloorError> {
    check_source(a, w_var)?;
    if !(h.is_finite() && v_var.is_finite() && v_var > 0.0) {
        return Err(FloorError::Invalid(format!(
            "sensor needs finite h and V > 0, got h = {h}, V = {v_var}"
        )));
    }
    let b = v_var * (1.0 - a * a) - w_var * h * h;
    let disc = (b * b + 4.0 * h * h * w_var * v_var).sqrt();
    let prior = if b > 0.0 {
        2.0 * w_var * v_var / (b + disc)
    } else if h != 0.0 {
        (disc - b) / (2.0 * h * h)
    } else {
        return Err(FloorError::Invalid(format!(
            "h = 0 and |a| = {} >= 1: the error has no steady state",
            a.abs()
        )));
    };
    let posterior = prior * v_var / (h * h * prior + v_var);
    Ok(ScalarKalman { prior, posterior })
}

/// The floor with a noisy sensor `z = h x + v`, `v ~ N(0, v_var)`: the all-data Kalman error
/// `P` plus the fully observed floor of the Kalman estimate process, which is Gauss–Markov with
/// the same `a` and driving variance `M - P`: `P + (M - P) / (2^{2R} - a^2)`.
///
/// Errors: those of [`kalman`] and [`distortion`]. An `h = 0` sensor with a stable `a` gives
/// `M = P`, and the floor is the stationary variance at every rate.
pub fn noisy_distortion(
    a: f64,
    w_var: f64,
    h: f64,
    v_var: f64,
    rate: f64,
) -> Result<f64, FloorError> {
    let kf = kalman(a, w_var, h, v_var)?;
    check_rate(a, rate)?;
    let noise = kf.estimate_noise();
    if noise <= 0.0 {
        return Ok(kf.posterior);
    }
    Ok(kf.posterior + distortion(a, noise, rate)?)
}

fn check_source(a: f64, w_var: f64) -> Result<(), FloorError> {
    if !(a.is_finite() && w_var.is_finite() && w_var > 0.0) {
        return Err(FloorError::Invalid(format!(
            "source needs finite a and W > 0, got a = {a}, W = {w_var}"
        )));
    }
    Ok(())
}

fn check_rate(a: f64, rate: f64) -> Result<(), FloorError> {
    let min = min_rate(a);
    if rate.is_nan() || rate < 0.0 || (a.abs() >= 1.0 && rate <= min) {
        return Err(FloorError::RateTooLow { rate, min });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_by_hand() {
        // 1 / (2^4 - 1.44) = 1 / 14.56.
        let d = distortion(1.2, 1.0, 2.0).unwrap();
        assert!((d - 0.068_681_318_681_318_68).abs() < 1e-15, "{d}");
        // Stable source at rate 0: the stationary variance 2 / (1 - 0.25).
        let d0 = distortion(0.5, 2.0, 0.0).unwrap();
        assert!((d0 - 8.0 / 3.0).abs() < 1e-15, "{d0}");
    }

    #[test]
    fn below_the_data_rate_is_an_error() {
        let min = 1.5f64.log2();
        assert!(matches!(
            distortion(1.5, 1.0, min),
            Err(FloorError::RateTooLow { .. })
        ));
        assert!(matches!(
            distortion(0.5, 1.0, -0.1),
            Err(FloorError::RateTooLow { .. })
        ));
        assert!(distortion(1.0, 0.0, 1.0).is_err());
        assert!(rate(1.0, 1.0, 0.0).is_err());
    }

    #[test]
    fn rate_inverts_distortion() {
        for &(a, w, r) in &[
            (1.2, 1.0, 2.0),
            (0.5, 3.0, 0.7),
            (-2.0, 0.1, 1.5),
            (1.0, 1.0, 0.01),
        ] {
            let d = distortion(a, w, r).unwrap();
            let back = rate(a, w, d).unwrap();
            assert!((back - r).abs() < 1e-12 * r.max(1.0), "{a} {w} {r}: {back}");
        }
        // Past the stationary variance a stable source needs no bits.
        assert_eq!(rate(0.5, 1.0, 100.0).unwrap(), 0.0);
    }

    #[test]
    fn kalman_solves_its_riccati_equation() {
        for &(a, w, h, v) in &[
            (1.2, 1.0, 1.0, 0.5),
            (0.9, 0.1, 2.0, 3.0),
            (2.0, 1e-3, 0.5, 1e2),
        ] {
            let kf = kalman(a, w, h, v).unwrap();
            let again = a * a * kf.posterior + w;
            assert!(
                (again - kf.prior).abs() < 1e-12 * kf.prior,
                "{again} {kf:?}"
            );
            // K^2 S with K = M h / S, S = h^2 M + V.
            let s = h * h * kf.prior + v;
            let k = kf.prior * h / s;
            assert!((k * k * s - kf.estimate_noise()).abs() < 1e-12 * kf.prior);
        }
        assert!(kalman(1.0, 1.0, 0.0, 1.0).is_err());
        let blind = kalman(0.5, 1.0, 0.0, 1.0).unwrap();
        assert!((blind.prior - 4.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn noisy_floor_lies_between_kalman_and_blind() {
        let kf = kalman(1.2, 1.0, 1.0, 0.5).unwrap();
        let mut last = f64::INFINITY;
        for r in [0.3, 0.5, 1.0, 2.0, 4.0, 8.0, 20.0] {
            let d = noisy_distortion(1.2, 1.0, 1.0, 0.5, r).unwrap();
            assert!(d > kf.posterior && d < last, "{r}: {d}");
            last = d;
        }
        assert!((last - kf.posterior) < 1e-10);
        // Stable source, rate 0: Kalman error plus the estimate's stationary variance is the
        // state's stationary variance W / (1 - a^2).
        let d0 = noisy_distortion(0.8, 1.0, 1.0, 0.5, 0.0).unwrap();
        assert!((d0 - 1.0 / 0.36).abs() < 1e-12, "{d0}");
    }
}
