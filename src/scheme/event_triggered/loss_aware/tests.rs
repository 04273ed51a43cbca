//! The loss-aware updates against hand computations: numerical integration of the exact
//! posterior (scalar), the mixture moments by hand, and the limits p = 0, δ = 0.
use super::*;
use crate::model::LinearSensor;

/// ∫ f over [lo, hi] by composite Simpson with `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, lo: f64, hi: f64, n: usize) -> f64 {
    let h = (hi - lo) / n as f64;
    let mut s = f(lo) + f(hi);
    for i in 1..n {
        s += f(lo + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

fn gauss(x: f64, m: f64, v: f64) -> f64 {
    (-(x - m) * (x - m) / (2.0 * v)).exp() / (2.0 * std::f64::consts::PI * v).sqrt()
}

fn scalar_sensor(r: f64) -> LinearSensor {
    LinearSensor::new(
        Matrix::from_element(1, 1, 1.0),
        Matrix::from_element(1, 1, r),
    )
    .unwrap()
}

fn g1(m: f64, p: f64) -> Gaussian {
    Gaussian::new(Vector::from_element(1, m), Matrix::from_element(1, 1, p))
}

/// Posterior mean and variance of x ~ N(m, pv) under the likelihood `lik(x)`, by Simpson.
fn posterior(m: f64, pv: f64, lik: impl Fn(f64) -> f64) -> (f64, f64) {
    let (lo, hi) = (m - 12.0 * pv.sqrt(), m + 12.0 * pv.sqrt());
    let w = |x: f64| gauss(x, m, pv) * lik(x);
    let z = simpson(w, lo, hi, 4000);
    let mean = simpson(|x| x * w(x), lo, hi, 4000) / z;
    let var = simpson(|x| (x - mean).powi(2) * w(x), lo, hi, 4000) / z;
    (mean, var)
}

#[test]
fn link_loss_must_be_a_probability_below_one_and_zero_is_the_published_update() {
    assert_eq!(effective_link_loss(None, 2).unwrap(), None);
    assert_eq!(effective_link_loss(Some(vec![0.0, 0.0]), 2).unwrap(), None);
    assert_eq!(
        effective_link_loss(Some(vec![0.3, 0.0]), 2).unwrap(),
        Some(vec![0.3, 0.0])
    );
    assert!(effective_link_loss(Some(vec![0.3]), 2).is_err());
    for bad in [1.0, -0.1, f64::NAN, 2.0] {
        match effective_link_loss(Some(vec![0.0, bad]), 2) {
            Err(SchemeError::Invalid { field, .. }) => assert_eq!(field, "link_loss"),
            other => panic!("{bad}: {other:?}"),
        }
    }
}

/// Wu et al.: the loss-aware second moment of a whitened component is the ratio of
/// ∫ ε² w(ε) and ∫ w(ε), w = 1{in} + p 1{out}, against the standard normal: by Simpson for
/// m = 1, and on a grid over the square for m = 2 (the box's complement is not a product).
#[test]
fn wu_no_arrival_variance_is_the_exact_second_moment_given_nothing_arrived() {
    for &(delta, p) in &[(0.5, 0.3), (1.0, 0.3), (2.0, 0.1), (1.0, 0.9)] {
        // Pieces split at ±δ, each with its own weight (the edges are not double counted):
        // Simpson integrates smooth pieces.
        let pieces = [(-12.0, -delta, p), (-delta, delta, 1.0), (delta, 12.0, p)];
        let int = |f: &dyn Fn(f64) -> f64| -> f64 {
            pieces
                .iter()
                .map(|&(a, b, w)| w * simpson(f, a, b, 4000))
                .sum()
        };
        let num = int(&|e| e * e * gauss(e, 0.0, 1.0));
        let den = int(&|e| gauss(e, 0.0, 1.0));
        let got = no_arrival_variance(delta, 1, p);
        assert!(
            (got - num / den).abs() < 1e-9,
            "m=1 δ={delta} p={p}: {got} vs {}",
            num / den
        );
        // m = 2: ∫∫ ε1² w(ε1, ε2) φ(ε1) φ(ε2), w = 1 in the box, p outside.
        let (mut num2, mut den2) = (0.0, 0.0);
        for (i, &(a0, a1, _)) in pieces.iter().enumerate() {
            for (j, &(b0, b1, _)) in pieces.iter().enumerate() {
                let w = if i == 1 && j == 1 { 1.0 } else { p };
                let inner = simpson(|b| gauss(b, 0.0, 1.0), b0, b1, 4000);
                num2 += w * inner * simpson(|a| a * a * gauss(a, 0.0, 1.0), a0, a1, 4000);
                den2 += w * inner * simpson(|a| gauss(a, 0.0, 1.0), a0, a1, 4000);
            }
        }
        let got2 = no_arrival_variance(delta, 2, p);
        assert!(
            (got2 - num2 / den2).abs() < 1e-9,
            "m=2 δ={delta} p={p}: {got2} vs {}",
            num2 / den2
        );
    }
}

#[test]
fn wu_no_arrival_variance_limits() {
    for m in [1, 2, 3] {
        for delta in [0.0, 0.3, 1.0, 3.0, 8.0] {
            // p = 0: Wu et al.'s truncated variance, bit for bit.
            assert_eq!(
                no_arrival_variance(delta, m, 0.0).to_bits(),
                crate::stats::truncated_normal::band_variance(delta).to_bits()
            );
            // Between v(δ) (p = 0) and 1 (p -> 1), increasing in p.
            let (a, b) = (
                no_arrival_variance(delta, m, 0.2),
                no_arrival_variance(delta, m, 0.6),
            );
            let v = crate::stats::truncated_normal::band_variance(delta);
            assert!(v <= a + 1e-15 && a <= b + 1e-15 && b <= 1.0, "{v} {a} {b}");
        }
        // δ = 0 always sends: nothing arriving is a loss and says nothing.
        assert!((no_arrival_variance(0.0, m, 0.3) - 1.0).abs() < 1e-15);
    }
    // By hand, m = 1, δ = 1, p = 0.5: P_in = 0.6826895, v = 1 - 2 φ(1) / P_in = 0.2911251
    // (P_in v = 0.1987480), E[ε² 1{out}] = 1 - P_in v = 0.8012520, P_out = 0.3173105.
    let want = (0.198_748_0 + 0.5 * 0.801_252_0) / (0.682_689_5 + 0.5 * 0.317_310_5);
    assert!((no_arrival_variance(1.0, 1, 0.5) - want).abs() < 1e-6);
}

/// Han et al., scalar: the exact posterior of x ~ N(m, P) given nothing arrived, whose
/// likelihood ∫ N(z; x, r) (p + (1 - p) exp(-½ y u²)) dz is itself integrated numerically over
/// z, against the moment-matched mixture.
#[test]
fn han_no_arrival_update_matches_the_numerically_integrated_posterior() {
    let (r, y) = (0.8, 1.5);
    let sensor = scalar_sensor(r);
    let noise = Matrix::from_element(1, 1, r + 1.0 / y);
    for &(m, pv, pseudo, p) in &[
        (0.7, 2.0, 0.0, 0.3),  // open loop: u = z
        (-1.2, 0.5, 0.0, 0.6), // open loop, far from 0
        (0.4, 1.0, 0.4, 0.3),  // closed loop: u = z - C x̂^- (pseudo = prediction)
        (0.4, 1.0, 1.1, 0.05), // closed loop after other sensors moved the mean
    ] {
        let lik = |x: f64| {
            simpson(
                |z| gauss(z, x, r) * (p + (1.0 - p) * (-0.5 * y * (z - pseudo).powi(2)).exp()),
                x - 14.0 * r.sqrt(),
                x + 14.0 * r.sqrt(),
                2000,
            )
        };
        let (mean, var) = posterior(m, pv, lik);
        let got = stochastic_no_arrival(
            &sensor,
            &g1(m, pv),
            &Vector::from_element(1, pseudo),
            &noise,
            -(y.ln()),
            p,
        )
        .unwrap();
        assert!(
            (got.estimate.mean[0] - mean).abs() < 1e-8,
            "{m} {pv} {pseudo} {p}: {} vs {mean}",
            got.estimate.mean[0]
        );
        assert!(
            (got.estimate.cov[(0, 0)] - var).abs() < 1e-8,
            "{} vs {var}",
            got.estimate.cov[(0, 0)]
        );
        // The weight of the silent component is P(silent | past, nothing) by Bayes.
        let s = pv + r + 1.0 / y;
        let pi = (1.0 / (y * s)).sqrt() * (-0.5 * (pseudo - m).powi(2) / s).exp();
        let w1 = (1.0 - p) * pi / (p + (1.0 - p) * pi);
        assert!((got.weight - w1).abs() < 1e-12);
    }
}

/// p = 0 is the published silence update (Theorems 1, 2): the KF with R + Y^{-1}.
#[test]
fn han_no_arrival_update_without_loss_is_the_published_one() {
    let sensor = scalar_sensor(1.0);
    let noise = Matrix::from_element(1, 1, 2.0);
    let est = g1(0.5, 1.5);
    let z = Vector::from_element(1, 0.0);
    let got = stochastic_no_arrival(&sensor, &est, &z, &noise, 0.0, 0.0).unwrap();
    let want = update_with_noise(&sensor, est, &z, &noise).unwrap();
    assert_eq!(got.estimate, want);
    assert_eq!(got.weight, 1.0);
}

#[test]
fn moment_matching_by_hand() {
    // 0.25 N(0, 1) + 0.75 N(2, 0.5): mean 1.5, var 0.25 + 0.375 + 0.25 * 0.75 * 4 = 1.375.
    let mut post = g1(2.0, 0.5);
    moment_match(0.75, &g1(0.0, 1.0), &mut post);
    assert!((post.mean[0] - 1.5).abs() < 1e-15);
    assert!((post.cov[(0, 0)] - 1.375).abs() < 1e-15);
    let m = mix(&[(0.25, &g1(0.0, 1.0)), (0.75, &g1(2.0, 0.5))]);
    assert!((m.mean[0] - 1.5).abs() < 1e-15 && (m.cov[(0, 0)] - 1.375).abs() < 1e-15);
}

/// Send-on-delta, scalar, q = 1: the weights are P_in : p (1 - P_in) : 0 with P_in the
/// predictive band mass (by hand), the lost component is the prior conditioned on z outside
/// the band (by Simpson), and q becomes w_A.
#[test]
fn send_on_delta_mixture_by_hand_and_by_integration() {
    let (r, delta, p) = (1.0, 1.0, 0.3);
    let sensor = scalar_sensor(r);
    let uniform = Matrix::from_element(1, 1, r + delta * delta / 3.0);
    let (m, pv, zr) = (0.2, 0.8, 0.9);
    let mix_ = SendOnDeltaMixture { delta, p };
    let est = g1(m, pv);
    let zr_v = Vector::from_element(1, zr);
    let s = pv + r;
    let p_in = normal::cdf((zr + delta - m) / s.sqrt()) - normal::cdf((zr - delta - m) / s.sqrt());
    assert!((mix_.log_in_band(&sensor, &est, &zr_v).unwrap().exp() - p_in).abs() < 1e-14);
    let got = mix_.update(&sensor, &est, &zr_v, &uniform, 1.0).unwrap();
    let w_a = p_in / (p_in + p * (1.0 - p_in));
    assert!((got.weight - w_a).abs() < 1e-14);
    // The lost component: x given |z - z_r| > δ, z = x + v.
    let out = |x: f64| {
        1.0 - (normal::cdf((zr + delta - x) / r.sqrt()) - normal::cdf((zr - delta - x) / r.sqrt()))
    };
    let (lm, lv) = posterior(m, pv, out);
    let a = update_with_noise(&sensor, est.clone(), &zr_v, &uniform).unwrap();
    let want = mix(&[(w_a, &a), (1.0 - w_a, &g1(lm, lv))]);
    assert!((got.estimate.mean[0] - want.mean[0]).abs() < 1e-9);
    assert!((got.estimate.cov[(0, 0)] - want.cov[(0, 0)]).abs() < 1e-9);
    // A stale reference (q = 0.4) adds the prediction with weight (1 - q)(p + (1 - p) P_in).
    let q = 0.4;
    let got = mix_.update(&sensor, &est, &zr_v, &uniform, q).unwrap();
    let w = [
        q * p_in,
        q * p * (1.0 - p_in),
        (1.0 - q) * (p + (1.0 - p) * p_in),
    ];
    let t: f64 = w.iter().sum();
    let want = mix(&[(w[0] / t, &a), (w[1] / t, &g1(lm, lv)), (w[2] / t, &est)]);
    assert!((got.weight - w[0] / t).abs() < 1e-14);
    assert!((got.estimate.mean[0] - want.mean[0]).abs() < 1e-9);
    assert!((got.estimate.cov[(0, 0)] - want.cov[(0, 0)]).abs() < 1e-9);
}
