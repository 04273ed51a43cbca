//! The consensus family on a graph whose every link is lossless (no loss, no delay, no ARQ):
//! every broadcast reaches every neighbour at once, so the graph driver's envelopes, fates and
//! per-receiver copies carry nothing a flat array does not. The nodes' pairs live in one buffer
//! (node by node: each pair's matrix column by column, then its vector), and each iteration
//! mixes it into a second buffer with exactly the operations of `ConsensusNode::combine` in
//! the same order (own weight first, then the neighbours in the node's order), so the numbers
//! are the driver's bit for bit (tested), as are the counters: every node broadcasts L frames a
//! step, each received by every neighbour, and listens its L windows per neighbour.
use super::{ConsensusNode, InformationPairs};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::network::graph::{NetworkNode, Payload};
use crate::network::topology::tally::NodeCounts;
use crate::network::topology::Topology;

use crate::network::topology::tally::Tally;

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
    let mut current: Vec<f64> = Vec::new();
    let mut mixed: Vec<f64> = Vec::new();
    for (j, z) in measurements.iter().enumerate() {
        let k = j + 1;
        tally.start_step();
        for (i, node) in nodes.iter_mut().enumerate() {
            node.start(if i < sensors { z.get(i) } else { None });
        }
        let stride = stride(&nodes[0]);
        let iterations = nodes[0].iterations;
        if nodes[0].iterations > 0 {
            let bits = InformationPairs {
                iteration: 0,
                pairs: nodes[0].pairs.clone(),
            }
            .mac_bits();
            for (i, heard) in hearers.iter().enumerate() {
                tally.broadcast_times(i, heard, bits, iterations as u64);
            }
        }
        gather(nodes, stride, &mut current);
        mixed.resize(current.len(), 0.0);
        for _ in 0..iterations {
            // The common strides (one pair of a 1- to 4-dimensional state, two for the hybrid)
            // as fixed-size rows the compiler unrolls; any other in slices. The same sums.
            match stride {
                2 => mix::<2>(&weights, &current, &mut mixed),
                4 => mix::<4>(&weights, &current, &mut mixed),
                6 => mix::<6>(&weights, &current, &mut mixed),
                12 => mix::<12>(&weights, &current, &mut mixed),
                20 => mix::<20>(&weights, &current, &mut mixed),
                24 => mix::<24>(&weights, &current, &mut mixed),
                40 => mix::<40>(&weights, &current, &mut mixed),
                _ => mix_any(stride, &weights, &current, &mut mixed),
            }
            std::mem::swap(&mut current, &mut mixed);
        }
        scatter(nodes, stride, &current);
        for (i, node) in nodes.iter_mut().enumerate() {
            node.predict().map_err(|e| {
                format!(
                    "node {}, step {k}, round {iterations}: {e}",
                    net.nodes[i].name
                )
            })?;
            tally.listen(i, node.windows(k));
        }
        let estimates: Vec<&Gaussian> = nodes.iter().map(|n| &n.estimate).collect();
        record(k, &estimates, tally.counts())?;
    }
    Ok(())
}

/// One consensus iteration of rows of `S` reals: row i of `mixed` is πᵢᵢ times row i of
/// `current` plus πᵢⱼ times row j for each neighbour j in order (`ConsensusNode::combine`).
fn mix<const S: usize>(weights: &[(f64, Vec<(usize, f64)>)], current: &[f64], mixed: &mut [f64]) {
    let rows: Vec<&[f64; S]> = current
        .chunks_exact(S)
        .map(|r| r.try_into().expect("rows of S reals"))
        .collect();
    for (i, ((own, others), out)) in weights.iter().zip(mixed.chunks_exact_mut(S)).enumerate() {
        let mut row = [0.0; S];
        for (x, y) in row.iter_mut().zip(rows[i]) {
            *x = y * own;
        }
        for &(n, w) in others {
            for (x, y) in row.iter_mut().zip(rows[n]) {
                *x += y * w;
            }
        }
        out.copy_from_slice(&row);
    }
}

/// [`mix`] for any row length.
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
