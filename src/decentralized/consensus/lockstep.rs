//! The consensus family on a graph whose every link is lossless (no loss, no delay, no ARQ):
//! every broadcast reaches every neighbour at once, so the graph driver's envelopes, fates and
//! per-receiver copies carry nothing a flat array does not. The nodes' pairs live in one buffer
//! (node by node: each pair's matrix column by column, then its vector), and each iteration
//! mixes it into a second buffer with exactly the operations of `ConsensusNode::combine` in
//! the same order (own weight first, then the neighbours in the node's order), so the numbers
//! are the driver's bit for bit (tested), as are the counters: every node broadcasts L frames a
//! step, each received by every neighbour, and listens its L windows per neighbour.
//!
//! Consensus on information of a state of 1 to 6 dimensions (every node's one pair, the
//! benchmark's case) starts and predicts in fixed size straight from and into the flat buffer
//! (`start_information`, `predict_information`): `ConsensusNode::start` and `predict`'s
//! operations in their order on arrays, without the matrices' dispatch and copies.
use super::{ConsensusNode, Fusion, InformationPairs};
use crate::filter::Gaussian;
use crate::linalg::fixed;
use crate::linalg::Vector;
use crate::network::graph::NetworkNode;
use crate::network::topology::tally::NodeCounts;
use crate::network::topology::Topology;
use multiversion::multiversion;

use crate::network::topology::tally::Tally;

/// `$f::<N>(args)` for the state dimension `$n` in 1..=6 ([`fixed_information_dim`]).
macro_rules! for_dim {
    ($n:expr, $f:ident ( $($arg:expr),* )) => {
        match $n {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            _ => $f::<6>($($arg),*),
        }
    };
}

/// Whether every link of `net` is lossless: the lock-step loop gives the driver's numbers.
pub fn applies(net: &Topology) -> bool {
    net.links.iter().all(|l| l.channel.is_lossless())
}

/// Gets step k's estimates of every node and every node's counters of the step (the trial's
/// recorder, `crate::decentralized::trial::Recorder`).
pub type Record<'r> = dyn FnMut(usize, &[&Gaussian], &[NodeCounts]) -> Result<(), String> + 'r;

/// Runs `nodes` (one per node of `net`) over every step of `measurements` (`[k - 1][i]`:
/// sensor i's reading at step k) in lock step, each step's estimates and counters to `record`.
pub fn run(
    net: &Topology,
    measurements: &[Vec<Vector>],
    nodes: &mut [ConsensusNode],
    record: &mut Record,
) -> Result<(), String> {
    let sensors = net.sensors();
    let mut tally = Tally::new(net);
    let hearers: Vec<Vec<usize>> = nodes
        .iter()
        .map(|node| node.neighbours.iter().map(|&(j, _)| j).collect())
        .collect();
    let weights: Vec<(f64, Vec<(usize, f64)>)> = nodes
        .iter()
        .map(|node| (node.own_weight, node.neighbours.clone()))
        .collect();
    let fixed_dim = fixed_information_dim(nodes);
    let mut current: Vec<f64> = Vec::new();
    let mut mixed: Vec<f64> = Vec::new();
    for (j, z) in measurements.iter().enumerate() {
        let k = j + 1;
        tally.start_step();
        let reading = |i: usize| if i < sensors { z.get(i) } else { None };
        let stride = match fixed_dim {
            Some(n) => {
                current.resize(nodes.len() * (n * n + n), 0.0);
                for_dim!(n, start_information(nodes, &reading, &mut current));
                n * n + n
            }
            None => {
                for (i, node) in nodes.iter_mut().enumerate() {
                    node.start(reading(i));
                }
                let stride = stride(&nodes[0]);
                gather(nodes, stride, &mut current);
                stride
            }
        };
        let iterations = nodes[0].iterations;
        if nodes[0].iterations > 0 {
            let n = nodes[0].prior.1.len();
            let bits = InformationPairs::frame_bits(nodes[0].pair_count(), n);
            for (i, heard) in hearers.iter().enumerate() {
                tally.broadcast_times(i, heard, bits, iterations as u64);
            }
        }
        mixed.resize(current.len(), 0.0);
        iterate(iterations, stride, &weights, &mut current, &mut mixed);
        let predicted = match fixed_dim {
            Some(n) => for_dim!(n, predict_information(nodes, &current)),
            None => {
                scatter(nodes, stride, &current);
                nodes
                    .iter_mut()
                    .enumerate()
                    .try_for_each(|(i, node)| node.predict().map_err(|e| (i, e)))
            }
        };
        predicted.map_err(|(i, e)| {
            format!(
                "node {}, step {k}, round {iterations}: {e}",
                net.nodes[i].name
            )
        })?;
        for (i, node) in nodes.iter().enumerate() {
            tally.listen(i, node.windows(k));
        }
        let estimates: Vec<&Gaussian> = nodes.iter().map(|n| &n.estimate).collect();
        record(k, &estimates, tally.counts())?;
    }
    Ok(())
}

/// The state dimension when every node runs consensus on information of a state the fixed-size
/// step covers (1 to 5, and 6 where [`fixed::gemm_square`] does), else None.
fn fixed_information_dim(nodes: &[ConsensusNode]) -> Option<usize> {
    let n = nodes.first()?.prior.1.len();
    let information = nodes
        .iter()
        .all(|node| node.fusion == Fusion::Information && node.prior.1.len() == n);
    (information && (1..=6).contains(&n) && fixed::gemm_square_covers(n)).then_some(n)
}

/// `ConsensusNode::start` of consensus on information for every node, each node's pair into
/// its row of `flat` (Ω column by column, then q): Ω⁻ + U and q⁻ + Hᵀ R⁻¹ z, or Ω⁻ + 0 and
/// q⁻ + 0 without a reading, the same sums (`x + y` entry by entry, the product as `gemv`).
fn start_information<'z, const N: usize>(
    nodes: &[ConsensusNode],
    reading: &impl Fn(usize) -> Option<&'z Vector>,
    flat: &mut [f64],
) {
    for (i, (node, row)) in nodes
        .iter()
        .zip(flat.chunks_exact_mut(N * N + N))
        .enumerate()
    {
        let (omega, q) = (node.prior.0.as_slice(), node.prior.1.as_slice());
        let (m, v) = row.split_at_mut(N * N);
        match (&node.sensor, reading(i)) {
            (Some((ht_rinv, u)), Some(z)) => {
                let novel = fixed::mat_vec_cols::<N>(ht_rinv.as_slice(), z.as_slice());
                add_into(m, omega, u.as_slice());
                add_into(v, q, &novel);
            }
            _ => {
                add_into(m, omega, &[0.0; 36]);
                add_into(v, q, &[0.0; 6]);
            }
        }
    }
}

/// `out = a + b`, entry by entry (as many as `out` has).
fn add_into(out: &mut [f64], a: &[f64], b: &[f64]) {
    for ((x, a), b) in out.iter_mut().zip(a).zip(b) {
        *x = a + b;
    }
}

/// `ConsensusNode::predict` of consensus on information for every node from its row of `flat`
/// (the pair after the L-th iteration), in fixed size: P = Ω⁻¹, x̂ = P q, P⁻ = A P Aᵀ + Q,
/// x̂⁻ = A x̂, Ω⁻ = (P⁻)⁻¹, q⁻ = Ω⁻ x̂⁻ — the fixed kernels are nalgebra's operations bit for
/// bit (`linalg::fixed`), so the estimates and priors are the node's own. The failing node and
/// its message on error.
fn predict_information<const N: usize>(
    nodes: &mut [ConsensusNode],
    flat: &[f64],
) -> Result<(), (usize, String)> {
    for (i, (node, row)) in nodes
        .iter_mut()
        .zip(flat.chunks_exact(N * N + N))
        .enumerate()
    {
        let fail = |m: &str| (i, m.to_string());
        let (omega, q) = row.split_at(N * N);
        let q: &[f64; N] = q.try_into().expect("N reals");
        let mut cov = [[0.0; N]; N];
        if !spd_inverse::<N>(omega, cov.as_flattened_mut()) {
            return Err(fail("the fused information is not positive definite"));
        }
        let mean = fixed::mat_vec::<N, N>(cov.as_flattened(), q);
        let (a, a_t) = (node.model.a.as_slice(), node.work.a_t.as_slice());
        let (mut ap, mut predicted) = ([[0.0; N]; N], [[0.0; N]; N]);
        fixed::gemm_square::<N>(ap.as_flattened_mut(), a, cov.as_flattened());
        fixed::gemm_square::<N>(predicted.as_flattened_mut(), ap.as_flattened(), a_t);
        let predicted = predicted.as_flattened_mut();
        for (p, q) in predicted.iter_mut().zip(node.model.q.as_slice()) {
            *p += q;
        }
        let predicted_mean = fixed::mat_vec::<N, N>(a, &mean);
        let mut omega_pred = [[0.0; N]; N];
        if !spd_inverse::<N>(predicted, omega_pred.as_flattened_mut()) {
            return Err(fail("the predicted covariance is singular"));
        }
        let q_pred = fixed::mat_vec::<N, N>(omega_pred.as_flattened(), &predicted_mean);
        node.estimate.cov.copy_from_slice(cov.as_flattened());
        node.estimate.mean.copy_from_slice(&mean);
        node.prior.0.copy_from_slice(omega_pred.as_flattened());
        node.prior.1.copy_from_slice(&q_pred);
    }
    Ok(())
}

/// `linalg::spd_inverse_small_into` of the N x N column-major `a` into `out` (finite, then the
/// Cholesky factor and the symmetrized inverse from it); false where it errs.
#[inline(always)]
fn spd_inverse<const N: usize>(a: &[f64], out: &mut [f64]) -> bool {
    let mut factor = [[0.0; N]; N];
    let factor = factor.as_flattened_mut();
    factor.copy_from_slice(&a[..N * N]);
    if !fixed::all_finite(factor) || !fixed::cholesky_square::<N>(factor) {
        return false;
    }
    fixed::chol_inverse_sym_square::<N>(factor, out);
    true
}

/// `iterations` consensus iterations on `current` (rows of `stride` reals), `mixed` the work
/// space. The common strides (one pair of a 1- to 4-dimensional state, two for the hybrid) as
/// fixed-size rows the compiler unrolls, any other in slices: the same sums. Compiled also for
/// AVX2 and picked at run time (the same IEEE operations on wider vectors, so the same bits).
#[multiversion(targets("x86_64+avx2"))]
fn iterate(
    iterations: usize,
    stride: usize,
    weights: &[(f64, Vec<(usize, f64)>)],
    current: &mut Vec<f64>,
    mixed: &mut Vec<f64>,
) {
    for _ in 0..iterations {
        match stride {
            2 => mix::<2>(weights, current, mixed),
            4 => mix::<4>(weights, current, mixed),
            6 => mix::<6>(weights, current, mixed),
            12 => mix::<12>(weights, current, mixed),
            20 => mix::<20>(weights, current, mixed),
            24 => mix::<24>(weights, current, mixed),
            40 => mix::<40>(weights, current, mixed),
            _ => mix_any(stride, weights, current, mixed),
        }
        std::mem::swap(current, mixed);
    }
}

/// One consensus iteration of rows of `S` reals: row i of `mixed` is πᵢᵢ times row i of
/// `current` plus πᵢⱼ times row j for each neighbour j in order (`ConsensusNode::combine`).
#[inline(always)]
fn mix<const S: usize>(weights: &[(f64, Vec<(usize, f64)>)], current: &[f64], mixed: &mut [f64]) {
    let row_of =
        |n: usize| -> &[f64; S] { current[n * S..(n + 1) * S].try_into().expect("S reals") };
    for (i, ((own, others), out)) in weights.iter().zip(mixed.chunks_exact_mut(S)).enumerate() {
        let mut row = [0.0; S];
        for (x, y) in row.iter_mut().zip(row_of(i)) {
            *x = y * own;
        }
        for &(n, w) in others {
            for (x, y) in row.iter_mut().zip(row_of(n)) {
                *x += y * w;
            }
        }
        out.copy_from_slice(&row);
    }
}

/// [`mix`] for any row length.
#[inline(always)]
fn mix_any(
    stride: usize,
    weights: &[(f64, Vec<(usize, f64)>)],
    current: &[f64],
    mixed: &mut [f64],
) {
    for (i, ((own, others), out)) in weights
        .iter()
        .zip(mixed.chunks_exact_mut(stride))
        .enumerate()
    {
        for (x, y) in out.iter_mut().zip(&current[i * stride..(i + 1) * stride]) {
            *x = y * own;
        }
        for &(n, w) in others {
            for (x, y) in out.iter_mut().zip(&current[n * stride..(n + 1) * stride]) {
                *x += y * w;
            }
        }
    }
}

/// Reals of one node's pairs in the flat buffer.
fn stride(node: &ConsensusNode) -> usize {
    node.pairs.iter().map(|(m, v)| m.len() + v.len()).sum()
}

/// Every node's pairs into `flat`, node by node.
fn gather(nodes: &[ConsensusNode], stride: usize, flat: &mut Vec<f64>) {
    flat.clear();
    flat.reserve(nodes.len() * stride);
    for node in nodes {
        for (m, v) in &node.pairs {
            flat.extend_from_slice(m.as_slice());
            flat.extend_from_slice(v.as_slice());
        }
    }
}

/// `flat` back into every node's pairs.
fn scatter(nodes: &mut [ConsensusNode], stride: usize, flat: &[f64]) {
    for (node, chunk) in nodes.iter_mut().zip(flat.chunks_exact(stride)) {
        let mut at = 0;
        for (m, v) in &mut node.pairs {
            let (a, b) = (m.len(), v.len());
            m.as_mut_slice().copy_from_slice(&chunk[at..at + a]);
            v.as_mut_slice().copy_from_slice(&chunk[at + a..at + a + b]);
            at += a + b;
        }
    }
}
