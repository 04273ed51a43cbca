//! What the decentralized schemes' tests share: a 2-state constant-velocity target watched by
//! three sensors (position, velocity, position) on small graphs, deterministic readings, and the
//! information filter that fuses a chosen set of them (the limits the schemes must reach).
use super::spd_inverse as inverse;
use super::Model;
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::network::channel::ChannelSpec;
use crate::network::topology::spec::NetworkSpec;
use crate::network::topology::Topology;

/// The network of `edges` (a `[network]` `edges` value) over the three sensors and a sink, every
/// link of `channel`.
pub fn network(edges: &str, channel: &str) -> Topology {
    let spec: NetworkSpec = toml::from_str(&format!("edges = {edges}")).unwrap();
    let c: ChannelSpec = toml::from_str(channel).unwrap();
    Topology::build(&spec, &[None, None, None], Some(&c)).unwrap()
}

/// s0 – s1 – s2 – sink – s0: a ring of four.
pub fn ring(channel: &str) -> Topology {
    network(
        "[[\"s0\", \"s1\"], [\"s1\", \"s2\"], [\"s2\", \"sink\"], [\"sink\", \"s0\"]]",
        channel,
    )
}

pub fn model() -> Model {
    Model {
        a: Matrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
        q: Matrix::from_diagonal_element(2, 2, 0.1),
    }
}

pub fn prior() -> Gaussian {
    Gaussian::new(
        Vector::from_vec(vec![0.0, 1.0]),
        Matrix::from_diagonal_element(2, 2, 4.0),
    )
}

/// The three sensors' (H, R).
pub fn sensors() -> Vec<(Matrix, Matrix)> {
    vec![
        (
            Matrix::from_row_slice(1, 2, &[1.0, 0.0]),
            Matrix::from_element(1, 1, 1.0),
        ),
        (
            Matrix::from_row_slice(1, 2, &[0.0, 1.0]),
            Matrix::from_element(1, 1, 2.0),
        ),
        (
            Matrix::from_row_slice(1, 2, &[1.0, 0.0]),
            Matrix::from_element(1, 1, 0.5),
        ),
    ]
}

/// Readings z_k^i, deterministic.
pub fn reading(k: usize, i: usize) -> Vector {
    Vector::from_element(1, (k as f64 * 0.7 + i as f64).sin() * 3.0 + k as f64)
}

/// The information filter fusing sensors `which` with each (HᵀR⁻¹H, HᵀR⁻¹z) scaled by `scale`.
pub fn reference(which: &[usize], scale: f64, steps: usize) -> Vec<Gaussian> {
    let m = model();
    let mut p = prior();
    let s = sensors();
    let mut out = Vec::new();
    for k in 1..=steps {
        let mut omega = inverse(&p.cov).unwrap();
        let mut q = &omega * &p.mean;
        for &i in which {
            let (h, r) = &s[i];
            let ht_rinv = h.transpose() * inverse(r).unwrap();
            omega += &ht_rinv * h * scale;
            q += &ht_rinv * reading(k, i) * scale;
        }
        let cov = inverse(&omega).unwrap();
        let mean = &cov * q;
        out.push(Gaussian::new(mean.clone(), cov.clone()));
        p = Gaussian::new(&m.a * mean, &m.a * cov * m.a.transpose() + &m.q);
    }
    out
}

pub fn close(a: &Gaussian, b: &Gaussian, tol: f64) -> bool {
    (&a.mean - &b.mean).amax() < tol && (&a.cov - &b.cov).amax() < tol
}
