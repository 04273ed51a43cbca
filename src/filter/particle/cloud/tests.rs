use super::super::test_support::{rng, ALL_SCHEMES};
use super::*;
use crate::filter::kf;
use crate::linalg::matrix_from_rows;
use crate::model::LinearSensor;
use rand::RngCore;
use rand_distr::Distribution;

#[test]
fn normalize_is_stable_for_huge_negative_log_weights() {
    let mut c = ParticleCloud::new(1, 3).unwrap();
    c.log_weights_mut()
        .copy_from_slice(&[-1000.0, -1001.0, -2000.0]);
    let log_z = c.normalize().unwrap();
    let e = (-1.0_f64).exp();
    // Exact: w = (1, e^-1, e^-1000) / (1 + e^-1 + e^-1000), and e^-1000 underflows.
    assert!((log_z - (-1000.0 + (1.0 + e).ln())).abs() < 1e-12);
    let w = c.weights().unwrap().to_vec();
    assert!(w.iter().all(|v| v.is_finite()));
    assert!((w[0] - 1.0 / (1.0 + e)).abs() < 1e-15);
    assert!((w[1] / w[0] - e).abs() < 1e-15);
    assert_eq!(w[2], 0.0);
    // The log-weights are now normalized: they sum to one in the linear domain.
    let s: f64 = c.log_weights().iter().map(|l| l.exp()).sum();
    assert!((s - 1.0).abs() < 1e-15);
    // Normalizing again changes nothing and reports log Z = 0.
    assert!(c.normalize().unwrap().abs() < 1e-15);
}

#[test]
fn degenerate_weights_are_errors_and_leave_log_weights_alone() {
    let mut c = ParticleCloud::new(1, 3).unwrap();
    for bad in [
        [f64::NEG_INFINITY; 3],
        [0.0, f64::NAN, 1.0],
        [0.0, f64::INFINITY, 1.0],
    ] {
        c.log_weights_mut().copy_from_slice(&bad);
        assert_eq!(c.normalize(), Err(ParticleError::DegenerateWeights));
        assert_eq!(c.ess(), Err(ParticleError::DegenerateWeights));
        assert_eq!(
            c.resample(Resampling::Systematic, &mut rng(0)),
            Err(ParticleError::DegenerateWeights)
        );
        let kept = c.log_weights();
        assert!(kept
            .iter()
            .zip(&bad)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

#[test]
fn ess_of_equal_and_of_single_weight() {
    let n = 1000;
    let mut c = ParticleCloud::new(1, n).unwrap();
    c.log_weights_mut().fill(-3.7);
    assert!((c.ess().unwrap() - n as f64).abs() < 1e-9);
    let lw = c.log_weights_mut();
    lw.fill(f64::NEG_INFINITY);
    lw[417] = -5.0;
    assert_eq!(c.ess().unwrap(), 1.0);
    // Two equal weights among zeros: ESS 2.
    let lw = c.log_weights_mut();
    lw[3] = lw[417];
    assert!((c.ess().unwrap() - 2.0).abs() < 1e-12);
}

#[test]
fn normalize_returns_the_evidence_after_resampling() {
    // After resampling the log-weights are -ln n, so adding log-likelihoods ln(1..4) and
    // normalizing returns ln of their average, (1 + 2 + 3 + 4) / 4.
    let mut c = ParticleCloud::new(1, 4).unwrap();
    c.log_weights_mut().copy_from_slice(&[0.0, -1.0, 2.0, 0.5]);
    c.resample(Resampling::Systematic, &mut rng(3)).unwrap();
    for (l, v) in c.log_weights_mut().iter_mut().zip([1.0_f64, 2.0, 3.0, 4.0]) {
        *l += v.ln();
    }
    assert!((c.normalize().unwrap() - 2.5_f64.ln()).abs() < 1e-15);
}

#[test]
fn resample_if_follows_the_policy() {
    let mut c = ParticleCloud::new(1, 100).unwrap();
    let mut r = rng(4);
    // Equal weights: ESS = n, not below half.
    assert!(!c
        .resample_if(
            ResamplePolicy::EssBelow(0.5),
            Resampling::Systematic,
            &mut r
        )
        .unwrap());
    // One dominant particle: ESS near 1.
    c.log_weights_mut()[10] = 50.0;
    for (i, x) in c.component_mut(0).iter_mut().enumerate() {
        *x = i as f64;
    }
    assert!(c
        .resample_if(
            ResamplePolicy::EssBelow(0.5),
            Resampling::Systematic,
            &mut r
        )
        .unwrap());
    assert!(c.component(0).iter().all(|x| *x == 10.0));
    assert!(c
        .resample_if(ResamplePolicy::Always, Resampling::Systematic, &mut r)
        .unwrap());
    for bad in [-0.1, 1.5, f64::NAN] {
        assert!(matches!(
            c.resample_if(
                ResamplePolicy::EssBelow(bad),
                Resampling::Systematic,
                &mut r
            ),
            Err(ParticleError::Threshold(_))
        ));
    }
}

#[test]
fn single_particle_cloud_works() {
    let mut c = ParticleCloud::new(2, 1).unwrap();
    c.component_mut(1)[0] = 3.0;
    for s in ALL_SCHEMES {
        c.log_weights_mut()[0] = -12.0;
        c.resample(s, &mut rng(5)).unwrap();
        assert_eq!(c.ancestors(), &[0]);
        assert_eq!(c.component(1), &[3.0]);
    }
    assert_eq!(c.ess().unwrap(), 1.0);
}

fn sample_moments_within_mc_error(c: &mut ParticleCloud, m: &Vector, p: &Matrix) {
    // With n independent draws from N(m, P): the sample mean of component j has standard
    // error sqrt(P_jj / n) and the sample covariance entry (j, k) has standard error
    // sqrt((P_jj P_kk + P_jk^2) / n) (Isserlis). 4 standard errors each.
    let n = c.len() as f64;
    let est = c.estimate().unwrap();
    for j in 0..m.len() {
        let se = (p[(j, j)] / n).sqrt();
        assert!(
            (est.mean[j] - m[j]).abs() <= 4.0 * se,
            "mean[{j}] {} vs {}",
            est.mean[j],
            m[j]
        );
        for k in 0..m.len() {
            let se = ((p[(j, j)] * p[(k, k)] + p[(j, k)].powi(2)) / n).sqrt();
            assert!(
                (est.cov[(j, k)] - p[(j, k)]).abs() <= 4.0 * se,
                "cov[{j},{k}] {} vs {}",
                est.cov[(j, k)],
                p[(j, k)]
            );
        }
    }
}

#[test]
fn gaussian_initialization_has_the_right_moments() {
    let m = Vector::from_vec(vec![1.0, -2.0, 0.5]);
    let p = matrix_from_rows(&[
        vec![4.0, 1.2, -0.5],
        vec![1.2, 2.0, 0.3],
        vec![-0.5, 0.3, 1.0],
    ]);
    let prior = Gaussian::new(m.clone(), p.clone());
    let mut c = ParticleCloud::from_gaussian(100_000, &prior, &mut rng(11)).unwrap();
    sample_moments_within_mc_error(&mut c, &m, &p);
    // estimate() agrees with mean() and covariance().
    let est = c.estimate().unwrap();
    assert_eq!(est.mean, c.mean().unwrap());
    assert_eq!(est.cov, c.covariance().unwrap());
}

#[test]
fn singular_prior_puts_particles_on_a_line() {
    // P = g g^T with g = (1, 2): every particle satisfies x_1 - m_1 = 2 (x_0 - m_0).
    let prior = Gaussian::new(
        Vector::from_vec(vec![3.0, -1.0]),
        matrix_from_rows(&[vec![1.0, 2.0], vec![2.0, 4.0]]),
    );
    let c = ParticleCloud::from_gaussian(1000, &prior, &mut rng(12)).unwrap();
    for (x0, x1) in c.component(0).iter().zip(c.component(1)) {
        assert!(((x1 + 1.0) - 2.0 * (x0 - 3.0)).abs() < 1e-12);
    }
    assert!(c.component(0).iter().any(|x| (x - 3.0).abs() > 0.5));
}

/// Zheng et al. (2014), Section VII-A: white-noise acceleration, D = 1, sigma^2 = 4. Q is rank one.
fn paper_cv() -> LinearTransition {
    let d = 1.0_f64;
    let s2 = 4.0;
    LinearTransition::new(
        matrix_from_rows(&[vec![1.0, d], vec![0.0, 1.0]]),
        matrix_from_rows(&[
            vec![s2 * d.powi(4) / 4.0, s2 * d.powi(3) / 2.0],
            vec![s2 * d.powi(3) / 2.0, s2 * d * d],
        ]),
    )
    .unwrap()
}

#[test]
fn propagation_matches_the_linear_gaussian_moments() {
    let model = paper_cv();
    let t = ParticleTransition::new(&model).unwrap();
    assert_eq!(t.noise_rank(), 1);
    let prior = Gaussian::new(
        Vector::from_vec(vec![0.0, 10.0]),
        matrix_from_rows(&[vec![4.0, 1.0], vec![1.0, 1.0]]),
    );
    let n = 100_000;
    let mut c = ParticleCloud::from_gaussian(n, &prior, &mut rng(13)).unwrap();
    let before = c.estimate().unwrap();
    let (x0, x1) = (c.component(0).to_vec(), c.component(1).to_vec());
    c.propagate(&t, &mut rng(14)).unwrap();
    // Given the cloud, F m_hat and F P_hat F^T are exact; only the noise is random. Its
    // contribution to the errors (sample mean of w, cross terms F x w^T, sample
    // covariance of w) is bounded by the error of a full sample from N(F m, F P F^T + Q),
    // which is what the helper checks against.
    let f = model.f();
    let m = f * &before.mean;
    let p = f * &before.cov * f.transpose() + model.q();
    sample_moments_within_mc_error(&mut c, &m, &p);
    // The noise is sigma (D^2 / 2, D) z: position noise is exactly half the velocity noise.
    for i in 0..n {
        let w0 = c.component(0)[i] - (x0[i] + x1[i]);
        let w1 = c.component(1)[i] - x1[i];
        assert!((w0 - 0.5 * w1).abs() < 1e-12, "particle {i}: {w0} vs {w1}");
    }
}

#[test]
fn bootstrap_filter_tracks_the_kalman_filter() {
    // x' = 0.9 x + w (q = 0.5), z = x + v (r = 1), prior N(0, 1), 20 steps.
    let (a, q, r) = (0.9, 0.5, 1.0);
    let model = LinearTransition::new(Matrix::from_element(1, 1, a), Matrix::from_element(1, 1, q))
        .unwrap();
    let sensor = LinearSensor::new(
        Matrix::from_element(1, 1, 1.0),
        Matrix::from_element(1, 1, r),
    )
    .unwrap();
    let prior = Gaussian::new(Vector::zeros(1), Matrix::identity(1, 1));
    let mut truth_rng = rng(20);
    let mut x = Vector::from_element(1, rand_distr::StandardNormal.sample(&mut truth_rng));
    let zs: Vec<Vector> = (0..20)
        .map(|_| {
            x = model.sample_next(&x, &mut truth_rng);
            crate::model::MeasurementModel::sample(&sensor, &x, &mut truth_rng)
        })
        .collect();
    let t = ParticleTransition::new(&model).unwrap();
    let n = 20_000;
    for (s, scheme) in ALL_SCHEMES.into_iter().enumerate() {
        let mut pf_rng = rng(30 + s as u64);
        let mut cloud = ParticleCloud::from_gaussian(n, &prior, &mut pf_rng).unwrap();
        let mut est = prior.clone();
        let (mut log_z_pf, mut log_z_kf) = (0.0, 0.0);
        for (k, z) in zs.iter().enumerate() {
            let pred = kf::predict(&model, &est);
            let s_k = pred.cov[(0, 0)] + r;
            log_z_kf += -0.5
                * ((z[0] - pred.mean[0]).powi(2) / s_k + (2.0 * std::f64::consts::PI * s_k).ln());
            est = kf::step(&model, &est, &[(&sensor, z)]).unwrap();

            cloud.propagate(&t, &mut pf_rng).unwrap();
            let (states, lw) = cloud.states_and_log_weights_mut();
            let c0 = -0.5 * (2.0 * std::f64::consts::PI * r).ln();
            for (l, xi) in lw.iter_mut().zip(states.component(0)) {
                *l += c0 - 0.5 * (z[0] - xi).powi(2) / r;
            }
            log_z_pf += cloud.normalize().unwrap();
            let g = cloud.estimate().unwrap();
            let ess = cloud.ess().unwrap();
            // A weighted mean of particles drawn from the prediction has variance about
            // P_k / ESS (the self-normalized importance sampling rule; ESS rather than N
            // because one outlying z can cut the ESS to a few percent). The particles
            // themselves carry the Monte Carlo error of earlier steps, which resampling
            // re-injects and the dynamics damp by a^2 = 0.81 per step: a geometric sum
            // below 5. So sd <= sqrt(5 P_k / ESS), and we allow 4 sd. The weighted
            // variance has relative sd about sqrt(2 * 5 / ESS) on the same argument.
            let p = est.cov[(0, 0)];
            let sd = (5.0 * p / ess).sqrt();
            assert!(
                (g.mean[0] - est.mean[0]).abs() <= 4.0 * sd,
                "{scheme:?} step {k}: PF {} vs KF {} (sd {sd})",
                g.mean[0],
                est.mean[0]
            );
            let rel = (g.cov[(0, 0)] - p).abs() / p;
            assert!(
                rel <= 4.0 * (10.0 / ess).sqrt(),
                "{scheme:?} step {k}: PF var {} vs KF {p}",
                g.cov[(0, 0)]
            );
            cloud
                .resample_if(ResamplePolicy::Always, scheme, &mut pf_rng)
                .unwrap();
        }
        // The product of the normalizing constants estimates p(z_1:20) (the returned log
        // Z is the per-step evidence because weights stay normalized). Its log has
        // variance about sum_k (E[w^2]/E[w]^2 - 1) / N ~ 20 * 0.12 / N; with the same 5x
        // allowance for resampling, 4 sd is under 0.1 nats.
        assert!(
            (log_z_pf - log_z_kf).abs() < 0.1,
            "{scheme:?}: log evidence PF {log_z_pf} vs KF {log_z_kf}"
        );
    }
}

fn run_a_few_steps(seed: u64, scheme: Resampling) -> (Vec<u64>, Vec<u64>) {
    let model = paper_cv();
    let t = ParticleTransition::new(&model).unwrap();
    let prior = Gaussian::new(
        Vector::from_vec(vec![0.0, 10.0]),
        Matrix::identity(2, 2) * 3.0,
    );
    let mut r = rng(seed);
    // Through a trait object, as a scheme holding `&mut dyn RngCore` would call it.
    let r: &mut dyn RngCore = &mut r;
    let mut c = ParticleCloud::from_gaussian(500, &prior, r).unwrap();
    for k in 0..5 {
        c.propagate(&t, r).unwrap();
        let (s, lw) = c.states_and_log_weights_mut();
        for (l, x) in lw.iter_mut().zip(s.component(0)) {
            *l += -0.5 * (x - 10.0 * k as f64).powi(2);
        }
        c.normalize().unwrap();
        c.resample_if(ResamplePolicy::EssBelow(0.6), scheme, r)
            .unwrap();
    }
    c.log_weights_mut()[0] += 0.25;
    c.normalize().unwrap();
    let states = (0..2)
        .flat_map(|j| {
            c.component(j)
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        })
        .collect();
    let weights = c.weights().unwrap().iter().map(|v| v.to_bits()).collect();
    (states, weights)
}

/// `propagate` gives the bits of the term-by-term rule: for each row, `F`'s first nonzero
/// entry scaled into it, the others added, then `L z` added column by column, the normals
/// drawn one block of `n` per kept column in column order. A full-rank `Q` (several noise
/// terms per row), an `F` with an empty row and one with three terms, and sizes around the
/// block of `lanes::combine_rows`.
#[test]
fn propagation_is_the_term_by_term_rule_bit_for_bit() {
    let f = matrix_from_rows(&[
        vec![1.0, 0.5, 0.0],
        vec![0.0, 0.0, 0.0],
        vec![-0.3, 0.7, 1.1],
    ]);
    let q = matrix_from_rows(&[
        vec![2.0, 0.3, 0.1],
        vec![0.3, 1.0, -0.2],
        vec![0.1, -0.2, 0.5],
    ]);
    let model = LinearTransition::new(f.clone(), q).unwrap();
    let t = ParticleTransition::new(&model).unwrap();
    assert_eq!(t.noise_rank(), 3);
    let prior = Gaussian::new(
        Vector::from_vec(vec![1.0, -2.0, 3.0]),
        Matrix::identity(3, 3),
    );
    for n in [1, 7, 255, 256, 257, 1000] {
        let mut c = ParticleCloud::from_gaussian(n, &prior, &mut rng(5)).unwrap();
        let x: Vec<Vec<f64>> = (0..3).map(|j| c.component(j).to_vec()).collect();
        c.propagate(&t, &mut rng(6)).unwrap();

        let mut want = vec![vec![0.0; n]; 3];
        for (i, row) in want.iter_mut().enumerate() {
            let terms: Vec<(usize, f64)> = (0..3)
                .filter(|&j| f[(i, j)] != 0.0)
                .map(|j| (j, f[(i, j)]))
                .collect();
            for (k, &(j, a)) in terms.iter().enumerate() {
                for (y, xj) in row.iter_mut().zip(&x[j]) {
                    *y = if k == 0 { a * xj } else { *y + a * xj };
                }
            }
        }
        let mut r = rng(6);
        let mut z = vec![0.0; n];
        for column in &t.noise.columns {
            fill_standard_normal(&mut z, &mut r);
            for &(row, coef) in column {
                for (y, zi) in want[row].iter_mut().zip(&z) {
                    *y += coef * zi;
                }
            }
        }
        for (j, w) in want.iter().enumerate() {
            let got: Vec<u64> = c.component(j).iter().map(|v| v.to_bits()).collect();
            let w: Vec<u64> = w.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, w, "n = {n}, component {j}");
        }
    }
}

#[test]
fn same_seed_gives_bit_identical_clouds() {
    for scheme in ALL_SCHEMES {
        let a = run_a_few_steps(42, scheme);
        assert_eq!(a, run_a_few_steps(42, scheme), "{scheme:?}");
        assert_ne!(a, run_a_few_steps(43, scheme), "{scheme:?}");
    }
}

#[test]
fn noiseless_model_propagates_deterministically() {
    // Q = 0: no normal draws at all, x' = F x exactly.
    let model = LinearTransition::new(
        matrix_from_rows(&[vec![1.0, 0.5], vec![0.0, 1.0]]),
        Matrix::zeros(2, 2),
    )
    .unwrap();
    let t = ParticleTransition::new(&model).unwrap();
    assert_eq!(t.noise_rank(), 0);
    let prior = Gaussian::new(Vector::from_vec(vec![1.0, 2.0]), Matrix::identity(2, 2));
    let mut c = ParticleCloud::from_gaussian(100, &prior, &mut rng(15)).unwrap();
    let mut before = [0.0; 2];
    c.copy_particle(7, &mut before).unwrap();
    c.propagate(&t, &mut rng(16)).unwrap();
    let mut after = [0.0; 2];
    c.copy_particle(7, &mut after).unwrap();
    assert_eq!(after, [before[0] + 0.5 * before[1], before[1]]);
    assert!(matches!(
        c.copy_particle(100, &mut after),
        Err(ParticleError::Index {
            index: 100,
            len: 100
        })
    ));
}

#[test]
fn dimension_mismatches_are_errors() {
    assert_eq!(ParticleCloud::new(0, 10).unwrap_err(), ParticleError::Empty);
    assert_eq!(ParticleCloud::new(2, 0).unwrap_err(), ParticleError::Empty);
    let mut c = ParticleCloud::new(3, 10).unwrap();
    let t = ParticleTransition::new(&paper_cv()).unwrap();
    assert!(matches!(
        c.propagate(&t, &mut rng(0)),
        Err(ParticleError::Dimension {
            expected: 3,
            got: 2,
            ..
        })
    ));
    let prior = Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2));
    assert!(matches!(
        c.init_gaussian(&prior, &mut rng(0)),
        Err(ParticleError::Dimension { .. })
    ));
    let not_psd = Gaussian::new(
        Vector::zeros(3),
        matrix_from_rows(&[
            vec![1.0, 2.0, 0.0],
            vec![2.0, 1.0, 0.0],
            vec![0.0, 0.0, 1.0],
        ]),
    );
    assert!(matches!(
        c.init_gaussian(&not_psd, &mut rng(0)),
        Err(ParticleError::Matrix { .. })
    ));
    let mut out = [0.0; 2];
    assert!(matches!(
        c.mean_into(&mut out),
        Err(ParticleError::Dimension { .. })
    ));
}
