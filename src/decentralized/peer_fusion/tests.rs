//! Peer fusion: covariance intersection by hand, and against the truth by Monte Carlo:
//! consistent (ANEES ≤ n within its Monte Carlo error) on random graphs, where naive fusion on a
//! triangle is not.
use super::*;
use crate::decentralized::fixture::model;
use crate::network::channel::ChannelSpec;
use crate::network::graph::driver::GraphDriver;
use crate::network::topology::spec::NetworkSpec;
use crate::network::topology::Topology;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

fn scalar(mean: f64, var: f64) -> Gaussian {
    Gaussian::new(
        Vector::from_element(1, mean),
        Matrix::from_element(1, 1, var),
    )
}

#[test]
fn scalar_intersection_keeps_the_better_estimate() {
    // P⁻¹ = ω/a + (1 − ω)/b is linear in ω: its best is an end, the smaller variance.
    let f = intersect(&scalar(3.0, 1.0), &scalar(-2.0, 4.0)).unwrap();
    assert!((f.cov[(0, 0)] - 1.0).abs() < 1e-12 && (f.mean[0] - 3.0).abs() < 1e-12);
    // Two dimensions, complementary: the intersection is tighter than either in det.
    let a = Gaussian::new(
        Vector::zeros(2),
        Matrix::from_diagonal(&Vector::from_vec(vec![1.0, 9.0])),
    );
    let b = Gaussian::new(
        Vector::zeros(2),
        Matrix::from_diagonal(&Vector::from_vec(vec![9.0, 1.0])),
    );
    let f = intersect(&a, &b).unwrap();
    // By symmetry ω = 1/2: P = diag(2 / (1 + 1/9), same) = diag(1.8, 1.8).
    assert!(
        (f.cov[(0, 0)] - 1.8).abs() < 1e-6 && (f.cov[(1, 1)] - 1.8).abs() < 1e-6,
        "{f:?}"
    );
}

#[test]
fn inverse_intersection_by_hand() {
    // Scalars a = 1, b = 4 (the digest's §1.6): at ω = 0.9, 1/P = 1 + 1/4 − 1/(0.9 + 0.4) =
    // 0.48077, P = 2.08 > P_CI = 1/(0.9 + 0.025) = 1.081; at the best ω both keep min(a, b) = 1.
    let (a, b) = (scalar(3.0, 1.0), scalar(-2.0, 4.0));
    let ici = inverse_intersect_at(&a, &b, 0.9).unwrap();
    let ci = intersect_at(&a, &b, 0.9).unwrap();
    let want = 1.0 / (1.25 - 1.0 / 1.3);
    assert!((ici.cov[(0, 0)] - want).abs() < 1e-12, "{ici:?}");
    assert!((ci.cov[(0, 0)] - 1.0 / 0.925).abs() < 1e-12);
    assert!(ici.cov[(0, 0)] > ci.cov[(0, 0)]);
    let best = inverse_intersect(&a, &b).unwrap();
    assert!(
        (best.cov[(0, 0)] - 1.0).abs() < 1e-9 && (best.mean[0] - 3.0).abs() < 1e-6,
        "{best:?}"
    );
    // K + L = I: the fusion of two equal means is that mean.
    let same = inverse_intersect_at(&scalar(2.0, 1.0), &scalar(2.0, 3.0), 0.4).unwrap();
    assert!((same.mean[0] - 2.0).abs() < 1e-12);
}

/// A random symmetric positive definite n × n matrix (B Bᵀ + I/2).
fn random_spd(n: usize, rng: &mut Xoshiro256PlusPlus) -> Matrix {
    let b = Matrix::from_fn(n, n, |_, _| rng.sample::<f64, _>(StandardNormal));
    &b * b.transpose() + Matrix::identity(n, n) * 0.5
}

/// The searches score products of scalars from relative eigenvalues; the determinant they stand
/// for, scanned on a grid of 10⁴ ω, has its best no better than at the chosen ω (to rounding),
/// for both rules on random 4 × 4 pairs.
#[test]
fn the_chosen_omega_beats_a_determinant_scan() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    for _ in 0..20 {
        let a = Gaussian::new(Vector::zeros(4), random_spd(4, &mut rng));
        let b = Gaussian::new(Vector::zeros(4), random_spd(4, &mut rng));
        for (rule, fuse, at) in [
            (
                "CI",
                intersect as fn(&Gaussian, &Gaussian) -> Result<Gaussian, String>,
                intersect_at as fn(&Gaussian, &Gaussian, f64) -> Result<Gaussian, String>,
            ),
            ("ICI", inverse_intersect, inverse_intersect_at),
        ] {
            let best = fuse(&a, &b).unwrap().cov.determinant();
            let scan = (0..=10_000)
                .map(|i| at(&a, &b, i as f64 / 1e4).unwrap().cov.determinant())
                .fold(f64::INFINITY, f64::min);
            assert!(best <= scan * (1.0 + 1e-9), "{rule}: {best} vs scan {scan}");
            assert!(best.is_finite() && best > 0.0);
        }
    }
}

/// `s` sensors and the sink linked by `edges` (node indices; the sink is `s`).
fn graph(s: usize, edges: &[(usize, usize)]) -> Topology {
    let name = |i: usize| {
        if i == s {
            "sink".to_string()
        } else {
            format!("s{i}")
        }
    };
    let list: Vec<String> = edges
        .iter()
        .map(|&(a, b)| format!("[\"{}\", \"{}\"]", name(a), name(b)))
        .collect();
    let spec: NetworkSpec = toml::from_str(&format!("edges = [{}]", list.join(", "))).unwrap();
    let c = ChannelSpec::default();
    Topology::build(&spec, &vec![None; s], Some(&c)).unwrap()
}

/// A random connected graph of `n` nodes: a random tree and `extra` more edges.
fn random_edges(n: usize, extra: usize, rng: &mut Xoshiro256PlusPlus) -> Vec<(usize, usize)> {
    let mut edges: Vec<(usize, usize)> = (1..n).map(|i| (rng.random_range(0..i), i)).collect();
    while edges.len() < n - 1 + extra {
        let (a, b) = (rng.random_range(0..n), rng.random_range(0..n));
        let (a, b) = (a.min(b), a.max(b));
        if a != b && !edges.contains(&(a, b)) {
            edges.push((a, b));
        }
    }
    edges
}

/// Mean NEES over `trials` × `steps` × nodes of `rule` on `t` (every node but the sink a
/// position or velocity sensor, R = 1), and its Monte Carlo standard error (from the trials'
/// means, which are independent).
fn anees(t: &Topology, rule: Rule, trials: usize, steps: usize, seed: u64) -> (f64, f64) {
    let n = t.nodes.len();
    let s = n - 1;
    let m = model();
    let prior = Gaussian::new(
        Vector::from_vec(vec![0.0, 1.0]),
        Matrix::from_diagonal_element(2, 2, 4.0),
    );
    let h = |i: usize| {
        Matrix::from_row_slice(
            1,
            2,
            if i.is_multiple_of(2) {
                &[1.0, 0.0]
            } else {
                &[0.0, 1.0]
            },
        )
    };
    let r = Matrix::from_element(1, 1, 1.0);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let normal = |rng: &mut Xoshiro256PlusPlus| rng.sample::<f64, _>(StandardNormal);
    let mut per_trial = Vec::with_capacity(trials);
    for trial in 0..trials {
        let mut nodes: Vec<Box<dyn NetworkNode<Estimate>>> = (0..n)
            .map(|i| {
                let neighbours = (0..n)
                    .filter(|&j| j != i && t.link(i, j).is_some())
                    .collect();
                let hi = h(i);
                let sensor = (i < s).then_some((&hi, &r));
                Box::new(PeerFusionNode::new(rule, m.clone(), &prior, sensor, neighbours).unwrap())
                    as Box<dyn NetworkNode<Estimate>>
            })
            .collect();
        let mut d = GraphDriver::new(t, ROUNDS, steps, seed, trial as u64);
        // x₀ from the prior (sd 2 each), then x' = A x + w (Q = 0.1 I).
        let mut x = Vector::from_vec(vec![2.0 * normal(&mut rng), 1.0 + 2.0 * normal(&mut rng)]);
        let mut sum = 0.0;
        for k in 1..=steps {
            if k > 1 {
                let w = Vector::from_vec(vec![normal(&mut rng), normal(&mut rng)]) * 0.1f64.sqrt();
                x = &m.a * &x + w;
            }
            let z: Vec<Vector> = (0..s)
                .map(|i| &h(i) * &x + Vector::from_element(1, normal(&mut rng)))
                .collect();
            let readings: Vec<Option<&Vector>> = z.iter().map(Some).collect();
            d.step(k, &mut nodes, &readings).unwrap();
            for node in &nodes {
                let e = node.estimate().unwrap();
                let err = &e.mean - &x;
                let p_inv = inverse(&e.cov).unwrap();
                sum += (err.transpose() * p_inv * &err)[(0, 0)];
            }
        }
        per_trial.push(sum / (steps * n) as f64);
    }
    let mean = per_trial.iter().sum::<f64>() / trials as f64;
    let var = per_trial.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (trials - 1) as f64;
    let se = (var / trials as f64).sqrt();
    // Shown with `cargo test --release --lib peer_fusion -- --nocapture`.
    eprintln!("{rule:?} on {n} nodes: ANEES {mean:.3} ± {se:.3}");
    (mean, se)
}

#[test]
fn covariance_intersections_are_consistent_on_random_graphs() {
    // ANEES of a consistent 2-state estimator is at most 2; allow 3 Monte Carlo standard errors.
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(40);
    for g in 0..3 {
        let t = graph(5, &random_edges(6, 3, &mut rng));
        // Inverse CI too: the peers' correlation is their common information (prior, shared
        // past), the case it is made for.
        for rule in [
            Rule::CovarianceIntersection,
            Rule::InverseCovarianceIntersection,
        ] {
            let (mean, se) = anees(&t, rule, 200, 20, 7 + g);
            assert!(
                mean <= 2.0 + 3.0 * se,
                "{rule:?}, graph {g}: ANEES {mean} ± {se}"
            );
        }
    }
}

#[test]
fn naive_fusion_on_a_triangle_is_not() {
    // Two sensors and the sink in a triangle: every exchange counts the shared past again.
    let t = graph(2, &[(0, 1), (1, 2), (2, 0)]);
    let (mean, se) = anees(&t, Rule::Naive, 200, 20, 11);
    assert!(mean > 2.0 + 3.0 * se, "naive ANEES {mean} ± {se}");
    // The same network with covariance intersection is consistent.
    let (mean, se) = anees(&t, Rule::CovarianceIntersection, 200, 20, 11);
    assert!(mean <= 2.0 + 3.0 * se, "CI ANEES {mean} ± {se}");
}
