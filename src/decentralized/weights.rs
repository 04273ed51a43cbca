//! Consensus weights on a graph: the matrix W with which every node averages its neighbours'
//! values, ξᵢ ← Σⱼ Wᵢⱼ ξⱼ, and how fast that converges.
//!
//! - Metropolis–Hastings (the default): Wᵢⱼ = 1 / (1 + max(dᵢ, dⱼ)) on every edge, Wᵢᵢ = 1 − Σⱼ Wᵢⱼ
//!   (each node needs only its neighbours' degrees; Xiao & Boyd, "Fast linear iterations for
//!   distributed averaging", Systems & Control Letters 53, 2004, §4.2).
//! - Max-degree: W = I − εL with ε = 1 / (1 + Δ_max) (Olfati-Saber & Murray; the step of the
//!   information-weighted consensus filter, Kamal et al. 2013, needs ε < 1/Δ_max).
//! - Given by hand: checked symmetric, non-negative, supported on the edges and the diagonal,
//!   and doubly stochastic.
//!
//! Both built-in rules give a symmetric, doubly stochastic W, so the iteration converges to the
//! average on any connected graph at the rate ρ = ‖W − 11ᵀ/N‖₂ < 1 ([`Weights::rho`]); the error
//! after k iterations is at most ρᵏ times the initial disagreement, and ⌈ln ε / ln ρ⌉ iterations
//! reach accuracy ε ([`Weights::iterations_for`]). On a ring with Metropolis weights
//! ρ = (1 + 2 cos 2π/N) / 3.
use crate::linalg::Matrix;

/// How the weights are chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum WeightRule {
    MetropolisHastings,
    MaxDegree,
    /// Row i, column j: Wᵢⱼ, as given (checked by [`Weights::new`]).
    Given(Vec<Vec<f64>>),
}

/// Doubly stochastic consensus weights of a graph.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    w: Matrix,
}

/// Tolerance of the checks on given weights (rows and columns summing to 1, symmetry).
const TOLERANCE: f64 = 1e-9;

impl Weights {
    /// The weights of `rule` on the graph of `n` nodes with undirected edges `edges`. An error
    /// names the field (`weights`) and the offending nodes.
    pub fn new(rule: &WeightRule, n: usize, edges: &[(usize, usize)]) -> Result<Self, String> {
        let mut degree = vec![0usize; n];
        let mut linked = vec![vec![false; n]; n];
        for &(a, b) in edges {
            if a >= n || b >= n || a == b {
                return Err(format!(
                    "weights: edge ({a}, {b}) is not between two of the {n} nodes"
                ));
            }
            if !linked[a][b] {
                degree[a] += 1;
                degree[b] += 1;
            }
            linked[a][b] = true;
            linked[b][a] = true;
        }
        let mut w = Matrix::zeros(n, n);
        match rule {
            WeightRule::MetropolisHastings | WeightRule::MaxDegree => {
                let max_degree = degree.iter().copied().max().unwrap_or(0);
                for a in 0..n {
                    for b in 0..n {
                        if linked[a][b] {
                            let d = match rule {
                                WeightRule::MetropolisHastings => degree[a].max(degree[b]),
                                _ => max_degree,
                            };
                            w[(a, b)] = 1.0 / (1.0 + d as f64);
                        }
                    }
                    let off: f64 = (0..n).filter(|&b| b != a).map(|b| w[(a, b)]).sum();
                    w[(a, a)] = 1.0 - off;
                }
            }
            WeightRule::Given(rows) => {
                if rows.len() != n || rows.iter().any(|r| r.len() != n) {
                    return Err(format!("weights: expected a {n} × {n} matrix"));
                }
                for (a, row) in rows.iter().enumerate() {
                    for (b, &x) in row.iter().enumerate() {
                        if !x.is_finite() || x < 0.0 {
                            return Err(format!("weights[{a}][{b}] = {x} is not a weight ≥ 0"));
                        }
                        if x != 0.0 && a != b && !linked[a][b] {
                            return Err(format!(
                                "weights[{a}][{b}] = {x}: nodes {a} and {b} are not linked"
                            ));
                        }
                        if (x - rows[b][a]).abs() > TOLERANCE {
                            return Err(format!(
                                "weights[{a}][{b}] = {x} but weights[{b}][{a}] = {}: not symmetric",
                                rows[b][a]
                            ));
                        }
                        w[(a, b)] = x;
                    }
                    let sum: f64 = row.iter().sum();
                    if (sum - 1.0).abs() > TOLERANCE {
                        return Err(format!(
                            "weights[{a}] sums to {sum}, not 1: not doubly stochastic"
                        ));
                    }
                }
            }
        }
        Ok(Self { w })
    }

    /// Wᵢⱼ.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.w[(i, j)]
    }

    pub fn matrix(&self) -> &Matrix {
        &self.w
    }

    /// ρ = ‖W − 11ᵀ/N‖₂: the largest modulus of W's eigenvalues but the one of the average
    /// (W is symmetric, so the 2-norm is the largest |eigenvalue|).
    pub fn rho(&self) -> f64 {
        let n = self.w.nrows();
        let centred = &self.w - Matrix::from_element(n, n, 1.0 / n as f64);
        centred
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .fold(0.0f64, |m, l| m.max(l.abs()))
    }

    /// Iterations that bring the disagreement down by a factor `eps`: ⌈ln ε / ln ρ⌉ (`None`
    /// when ρ ≥ 1, a disconnected graph that never agrees).
    pub fn iterations_for(&self, eps: f64) -> Option<u64> {
        let rho = self.rho();
        (rho < 1.0).then(|| {
            if rho <= 0.0 {
                1
            } else {
                (eps.ln() / rho.ln()).ceil() as u64
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Vector;

    fn ring(n: usize) -> Vec<(usize, usize)> {
        (0..n).map(|i| (i, (i + 1) % n)).collect()
    }

    #[test]
    fn the_ring_converges_at_its_closed_form_rate() {
        for (n, digest_rho, k3) in [(10, 0.87268, 51), (20, 0.96737, 209), (50, 0.99474, 1311)] {
            let w = Weights::new(&WeightRule::MetropolisHastings, n, &ring(n)).unwrap();
            let closed = (1.0 + 2.0 * (2.0 * std::f64::consts::PI / n as f64).cos()) / 3.0;
            assert!((w.rho() - closed).abs() < 1e-12, "N = {n}");
            assert!((w.rho() - digest_rho).abs() < 5e-6, "N = {n}");
            assert_eq!(w.iterations_for(1e-3), Some(k3), "N = {n}");
        }
    }

    #[test]
    fn the_error_stays_under_rho_to_the_k() {
        // A random geometric-like graph: a ring with chords; max-degree weights too.
        let n = 12;
        let mut edges = ring(n);
        edges.extend([(0, 6), (3, 9), (2, 7)]);
        for rule in [WeightRule::MetropolisHastings, WeightRule::MaxDegree] {
            let w = Weights::new(&rule, n, &edges).unwrap();
            let rho = w.rho();
            assert!(rho < 1.0);
            let mut x = Vector::from_fn(n, |i, _| ((i * 7919) % 13) as f64 - 4.0);
            let mean = x.mean();
            let start = (x.add_scalar(-mean)).norm();
            for k in 1..=60 {
                x = w.matrix() * &x;
                // The average is kept (doubly stochastic) and the error shrinks at least as ρᵏ.
                assert!((x.mean() - mean).abs() < 1e-12);
                let err = x.add_scalar(-mean).norm();
                assert!(
                    err <= rho.powi(k) * start * (1.0 + 1e-9),
                    "{rule:?}, k = {k}"
                );
            }
        }
    }

    #[test]
    fn every_rule_is_symmetric_and_doubly_stochastic() {
        let edges = [(0, 1), (1, 2), (2, 3), (1, 3)];
        for rule in [WeightRule::MetropolisHastings, WeightRule::MaxDegree] {
            let w = Weights::new(&rule, 4, &edges).unwrap();
            let m = w.matrix();
            assert!((m - m.transpose()).abs().max() < 1e-15);
            for i in 0..4 {
                assert!((m.row(i).sum() - 1.0).abs() < 1e-15);
                assert!(m.row(i).iter().all(|&x| x >= 0.0));
            }
        }
        // By hand: Metropolis on the path 0 – 1 – 2: degrees 1, 2, 1; every edge 1/3.
        let w = Weights::new(&WeightRule::MetropolisHastings, 3, &[(0, 1), (1, 2)]).unwrap();
        let got = [w.get(0, 0), w.get(0, 1), w.get(1, 1), w.get(0, 2)];
        for (g, want) in got.iter().zip([2.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 0.0]) {
            assert!((g - want).abs() < 1e-15, "{got:?}");
        }
    }

    #[test]
    fn given_weights_are_checked_and_named() {
        let edges = [(0, 1), (1, 2)];
        let given = |rows: Vec<Vec<f64>>| Weights::new(&WeightRule::Given(rows), 3, &edges);
        let ok = vec![
            vec![0.5, 0.5, 0.0],
            vec![0.5, 0.25, 0.25],
            vec![0.0, 0.25, 0.75],
        ];
        assert!(given(ok).is_ok());
        let e = given(vec![
            vec![0.5, 0.5, 0.0],
            vec![0.4, 0.3, 0.3],
            vec![0.0, 0.3, 0.7],
        ])
        .unwrap_err();
        assert!(e.contains("not symmetric"), "{e}");
        let e = given(vec![
            vec![0.6, 0.5, 0.0],
            vec![0.5, 0.25, 0.25],
            vec![0.0, 0.25, 0.75],
        ])
        .unwrap_err();
        assert!(e.contains("weights[0] sums to 1.1"), "{e}");
        let e = given(vec![
            vec![0.5, 0.4, 0.1],
            vec![0.4, 0.35, 0.25],
            vec![0.1, 0.25, 0.65],
        ])
        .unwrap_err();
        assert!(e.contains("nodes 0 and 2 are not linked"), "{e}");
        assert!(given(vec![vec![1.0; 2]; 2]).unwrap_err().contains("3 × 3"));
        let e = Weights::new(&WeightRule::MaxDegree, 2, &[(0, 0)]).unwrap_err();
        assert!(e.contains("edge (0, 0)"), "{e}");
    }
}
