// Reference values are quoted with all the digits the high-precision source gave.
#![allow(clippy::excessive_precision)]
use super::*;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Independent noncentral chi-square CDF: the Poisson mixture
/// `sum_k Pois(k; nc/2) F_{chi^2_{n+2k}}(y)` with statrs' central chi-square CDF, summed
/// over `k` within 40 standard deviations of the Poisson mean (weights beyond are
/// below 1e-300) with log-space weights.
fn noncentral_chi2_cdf(n: f64, nc: f64, y: f64) -> f64 {
    let mu = 0.5 * nc;
    let lo = (mu - 40.0 * mu.sqrt() - 40.0).max(0.0) as usize;
    let hi = (mu + 40.0 * mu.sqrt() + 40.0) as usize;
    let mut sum = 0.0;
    for k in lo..=hi {
        let kf = k as f64;
        let ln_w = if mu > 0.0 {
            -mu + kf * mu.ln() - ln_gamma(kf + 1.0)
        } else if k == 0 {
            0.0
        } else {
            f64::NEG_INFINITY
        };
        let w = ln_w.exp();
        if w > 0.0 {
            sum += w * ChiSquared::new(n + 2.0 * kf).unwrap().cdf(y);
        }
    }
    sum
}

/// Exact 2-D reference for diagonal `C = diag(l1, l2)`: with `v = sqrt(l1)(z1 + d1) =
/// sqrt(x) sin(theta)` the probability is a smooth one-dimensional integral of a normal
/// band probability; composite Simpson with 400000 panels is accurate far below 1e-10
/// for the widths used here.
fn reference_2d(l1: f64, l2: f64, b1: f64, b2: f64, x: f64) -> f64 {
    let (s1, s2) = (l1.sqrt(), l2.sqrt());
    let (d1, d2) = (b1 / s1, b2 / s2);
    let rx = x.sqrt();
    let f = |th: f64| -> f64 {
        let v = rx * th.sin();
        let w = rx * th.cos();
        let dens = normal::pdf(v / s1 - d1) / s1;
        let band = normal::log_q_band(-w / s2 - d2, w / s2 - d2).exp();
        dens * band * rx * th.cos()
    };
    let n = 400_000;
    let h = PI / n as f64;
    let mut sum = f(-0.5 * PI) + f(0.5 * PI);
    for i in 1..n {
        let th = -0.5 * PI + i as f64 * h;
        sum += if i % 2 == 1 { 4.0 } else { 2.0 } * f(th);
    }
    sum * h / 3.0
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_row_slice(v))
}

/// Rotate `diag(l)` by a fixed orthogonal matrix (from a QR of a fixed matrix).
fn rotated(l: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = l.len();
    let a = DMatrix::from_fn(n, n, |i, j| {
        ((i * 7 + j * 3) as f64 * 0.37).sin() + if i == j { 2.0 } else { 0.0 }
    });
    let qm = a.qr().q();
    (&qm * diag(l) * qm.transpose(), qm)
}

#[test]
fn isotropic_matches_noncentral_chi_square() {
    // C = s^2 I: q^T q / s^2 ~ noncentral chi^2_n(|m|^2 / s^2). Tolerance 1e-9 absolute,
    // the brief's target; statrs' central CDFs are good to ~1e-13 and the mixture adds
    // at most a few hundred of them. The large-|m| cases go to the inversion method.
    for n in [2usize, 3, 4, 6] {
        for s2 in [0.3, 1.0, 2.5] {
            for mscale in [0.0, 0.5, 1.0, 2.0, 4.0, 15.0] {
                let m = DVector::from_fn(n, |i, _| mscale * (1.0 + i as f64).sqrt() / 2.0);
                let c = diag(&vec![s2; n]);
                let nc = m.norm_squared() / s2;
                for eta in [0.5, 2.0, 6.0, 15.0, 60.0] {
                    let got = prob_below(&m, &c, eta).unwrap();
                    let want = noncentral_chi2_cdf(n as f64, nc, eta / s2);
                    assert!(
                        (got - want).abs() < 1e-9,
                        "n {n} s2 {s2} nc {nc} eta {eta}: {got} vs {want}"
                    );
                }
            }
        }
    }
}

#[test]
fn central_identity_matches_chi_square_cdf() {
    // m = 0, C = I: P(chi^2_n < eta). 1e-12: both sides are ~1e-14 accurate.
    for n in 1..=6 {
        let c = DMatrix::identity(n, n);
        let m = DVector::zeros(n);
        for eta in [0.01, 0.5, 1.0, 3.0, 7.8, 20.0, 50.0] {
            let got = prob_below(&m, &c, eta).unwrap();
            let want = ChiSquared::new(n as f64).unwrap().cdf(eta);
            assert!(
                (got - want).abs() < 1e-12,
                "n {n} eta {eta}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn two_dimensional_matches_direct_integration() {
    // Anisotropic (and rotated) 2-D cases against the Simpson reference, including
    // ill-conditioned spectra (ratios 1e-3 and 1e-5, the latter ~1e5 Ruben terms, which
    // checks the accumulated rounding) and near-boundary means. Tolerance 1e-9.
    let cases = [
        (0.2, 0.8, 0.3, -0.4, 1.5),
        (0.05, 1.0, 0.0, 0.0, 3.0),
        (0.5, 0.7, 1.2, 0.9, 2.7),
        (1e-3, 1.0, 0.4, 0.1, 4.0),
        (1e-5, 1.0, 0.0, 0.3, 4.0),
        (0.01, 0.9, 1.9, 0.2, 4.0),
        (0.3, 0.3, 5.0, 5.0, 40.0),
        (0.02, 0.04, 2.0, -1.0, 5.0),
    ];
    for (l1, l2, b1, b2, eta) in cases {
        let want = reference_2d(l1, l2, b1, b2, eta);
        let got = prob_below(&DVector::from_row_slice(&[b1, b2]), &diag(&[l1, l2]), eta).unwrap();
        assert!(
            (got - want).abs() < 1e-9,
            "{l1} {l2} {b1} {b2} {eta}: {got} vs {want}"
        );
        // Same after a rotation of coordinates: m -> Q m, C -> Q C Q^T.
        let (c, qm) = rotated(&[l1, l2]);
        let m = &qm * DVector::from_row_slice(&[b1, b2]);
        let got_rot = prob_below(&m, &c, eta).unwrap();
        assert!(
            (got_rot - want).abs() < 1e-9,
            "rotated {l1} {l2}: {got_rot} vs {want}"
        );
    }
}

#[test]
fn ruben_and_inversion_agree() {
    // The two methods share nothing but the reduction; forcing each on cases where both
    // are affordable checks one against the other. Tolerance 1e-9. (The inversion is
    // only affordable with some noncentrality: with little, its T^{-r/2} tail needs
    // too many terms; those cases are skipped, but most must run.)
    let mut compared = 0;
    let spectra: [&[f64]; 4] = [
        &[0.1, 0.5, 0.9],
        &[0.2, 0.2, 0.6, 1.0],
        &[0.05, 0.3, 0.4, 0.6, 0.8, 1.0],
        &[0.5, 2.0],
    ];
    for lam in spectra {
        let cdf = QuadFormCdf::new(&diag(lam)).unwrap();
        for d in [0.0, 0.7, 2.0, 3.0, 5.0] {
            for eta in [0.3, 1.0, 4.0, 9.0] {
                let d2: Vec<f64> = (0..lam.len())
                    .map(|j| d * d * (1.0 + j as f64 * 0.3))
                    .collect();
                let mut scratch = vec![0.0; 4 * lam.len()];
                let ru = cdf
                    .positive_part(&d2, eta, &mut scratch, Method::Ruben)
                    .unwrap();
                let terms = gil_pelaez_plan(lam, &d2, eta).unwrap().terms();
                if terms > 2e5 {
                    continue;
                }
                let gp = cdf
                    .positive_part(&d2, eta, &mut scratch, Method::GilPelaez)
                    .unwrap();
                assert!(
                    (ru - gp).abs() < 1e-9,
                    "{lam:?} d {d} eta {eta}: {ru} vs {gp}"
                );
                compared += 1;
            }
        }
    }
    assert!(compared >= 30, "only {compared} comparisons");
}

#[test]
fn general_covariance_matches_monte_carlo() {
    // A correlated 3-D covariance; 200000 samples with a fixed seed. The Monte Carlo
    // estimate is binomial, so it must lie within 4 standard errors (a 6e-5 chance of a
    // false failure per comparison for a correct exact value).
    let c = DMatrix::from_row_slice(3, 3, &[1.0, 0.4, -0.2, 0.4, 0.8, 0.1, -0.2, 0.1, 0.5]);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(20240611);
    for (m, eta) in [
        (DVector::from_row_slice(&[0.3, -0.5, 0.8]), 2.0),
        (DVector::from_row_slice(&[1.5, 1.0, -0.5]), 6.25),
        (DVector::from_row_slice(&[0.0, 0.0, 0.0]), 1.0),
    ] {
        let exact = prob_below(&m, &c, eta).unwrap();
        let n = 200_000;
        let mc = prob_below_monte_carlo(&m, &c, eta, n, &mut rng).unwrap();
        let se = (exact * (1.0 - exact) / n as f64).sqrt();
        assert!(
            (mc - exact).abs() < 4.0 * se,
            "exact {exact} mc {mc} se {se}"
        );
    }
}

#[test]
fn singular_covariance_uses_constant_part() {
    // C = diag(s^2, 0): q2 = m2 exactly, so P = P(s^2 (z + m1/s)^2 < eta - m2^2).
    let (s2, m1, m2, eta) = (0.5_f64, 0.4, 1.1, 3.0);
    let c = diag(&[s2, 0.0]);
    let m = DVector::from_row_slice(&[m1, m2]);
    let x = eta - m2 * m2;
    let s = (x / s2).sqrt();
    let d = m1 / s2.sqrt();
    let want = normal::cdf(s - d) - normal::cdf(-s - d);
    let got = prob_below(&m, &c, eta).unwrap();
    assert!((got - want).abs() < 1e-14);
    // The mean's constant part alone exceeds eta: probability 0.
    assert_eq!(
        prob_below(&DVector::from_row_slice(&[0.0, 2.0]), &c, 3.0).unwrap(),
        0.0
    );
    // Rank 2 of 3, rotated: compare with the 2-D reference.
    let (cr, qm) = rotated(&[0.3, 0.0, 0.9]);
    let b = [0.2, 0.5, -0.3];
    let m3 = &qm * DVector::from_row_slice(&b);
    let want = reference_2d(0.3, 0.9, b[0], b[2], 2.0 - b[1] * b[1]);
    let got = prob_below(&m3, &cr, 2.0).unwrap();
    assert!((got - want).abs() < 1e-9, "{got} vs {want}");
    // Zero covariance: deterministic q = m.
    let z = DMatrix::zeros(2, 2);
    assert_eq!(
        prob_below(&DVector::from_row_slice(&[1.0, 1.0]), &z, 2.5).unwrap(),
        1.0
    );
    assert_eq!(
        prob_below(&DVector::from_row_slice(&[1.0, 1.0]), &z, 1.5).unwrap(),
        0.0
    );
}

#[test]
fn one_dimension_closed_form_agrees_with_series() {
    // r = 1 goes through the normal band; it must agree with the independent Poisson
    // mixture and with Ruben's series forced on the same input. Tolerance 1e-12.
    let single = QuadFormCdf::new(&diag(&[0.7])).unwrap();
    for (b, eta) in [(0.0, 1.0), (0.5, 0.3), (2.0, 5.0), (-1.0, 0.01), (3.0, 0.5)] {
        let band = single.prob_below_slice(&[b], eta).unwrap();
        let want = noncentral_chi2_cdf(1.0, b * b / 0.7, eta / 0.7);
        assert!(
            (band - want).abs() < 1e-12,
            "b {b} eta {eta}: {band} vs {want}"
        );
        let mut scratch = [0.0; 4];
        let d2 = [b * b / 0.7];
        let ru = single
            .positive_part(&d2, eta, &mut scratch, Method::Ruben)
            .unwrap();
        assert!(
            (band - ru).abs() < 1e-12,
            "b {b} eta {eta}: {band} vs Ruben {ru}"
        );
    }
}

#[test]
fn far_particles_and_small_noise() {
    // Large noncentrality (far particle) gives a tiny probability, not garbage; small
    // noise relative to eta (vague prior: C tiny) behaves like the indicator |m|^2 < eta.
    let c = diag(&[0.2, 0.5, 0.9]);
    let far = prob_below(&DVector::from_row_slice(&[30.0, -20.0, 10.0]), &c, 4.0).unwrap();
    assert!((0.0..1e-12).contains(&far), "{far}");
    let tiny = diag(&[1e-6, 2e-6]);
    let inside = prob_below(&DVector::from_row_slice(&[0.5, 0.5]), &tiny, 1.0).unwrap();
    let outside = prob_below(&DVector::from_row_slice(&[0.8, 0.7]), &tiny, 1.0).unwrap();
    assert!(
        (inside - 1.0).abs() < 1e-9 && outside < 1e-9,
        "{inside} {outside}"
    );
    // On the boundary the answer is ~1/2; compare with the 2-D reference.
    let m = [0.6, 0.8]; // |m|^2 = 1 = eta
    let want = reference_2d(1e-6, 2e-6, m[0], m[1], 1.0);
    let got = prob_below(&DVector::from_row_slice(&m), &tiny, 1.0).unwrap();
    assert!(
        (got - want).abs() < 1e-8 && (got - 0.5).abs() < 0.1,
        "{got} vs {want}"
    );
}

#[test]
fn monotone_in_eta_and_bounded() {
    let (c, _) = rotated(&[0.1, 0.4, 0.7, 1.3]);
    let cdf = QuadFormCdf::new(&c).unwrap();
    let m = DVector::from_row_slice(&[0.5, -0.3, 0.2, 0.9]);
    let mut prev = 0.0;
    for i in 0..200 {
        let eta = 0.05 * i as f64;
        let p = cdf.prob_below(&m, eta).unwrap();
        assert!((0.0..=1.0).contains(&p));
        assert!(p >= prev - 1e-12, "eta {eta}: {p} < {prev}");
        prev = p;
    }
    assert!((cdf.prob_below(&m, 1e4).unwrap() - 1.0).abs() < 1e-12);
    assert_eq!(cdf.prob_below(&m, f64::INFINITY).unwrap(), 1.0);
    assert_eq!(cdf.prob_below(&m, -1.0).unwrap(), 0.0);
}

#[test]
fn invalid_inputs_are_rejected() {
    let c = DMatrix::identity(2, 2);
    let m3 = DVector::zeros(3);
    assert!(matches!(
        prob_below(&m3, &c, 1.0),
        Err(StatsError::DimensionMismatch {
            expected: 2,
            found: 3
        })
    ));
    let not_psd = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
    assert!(matches!(
        QuadFormCdf::new(&not_psd),
        Err(StatsError::NotPositiveSemidefinite { .. })
    ));
    let asym = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
    assert!(QuadFormCdf::new(&asym).is_err());
    assert!(QuadFormCdf::new(&DMatrix::zeros(2, 3)).is_err());
    assert!(prob_below(&DVector::zeros(2), &c, f64::NAN).is_err());
    assert!(prob_below(&DVector::from_row_slice(&[f64::NAN, 0.0]), &c, 1.0).is_err());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    assert!(prob_below_monte_carlo(&DVector::zeros(2), &c, 1.0, 0, &mut rng).is_err());
}

#[test]
fn higher_dimension_uses_heap_scratch() {
    // n = 10 > STACK_DIM: same answer as the chi-square CDF for C = 2 I, m = 0.
    let c = DMatrix::identity(10, 10) * 2.0;
    let got = prob_below(&DVector::zeros(10), &c, 18.0).unwrap();
    let want = ChiSquared::new(10.0).unwrap().cdf(9.0);
    assert!((got - want).abs() < 1e-12);
}
