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
//! benchmark's case) runs in two halves (`consensus::split`): the information matrices, the same
//! in every trial on lossless links, once per run and thread; each trial's vectors in fixed
//! size. The same operations in their order as the nodes' own, hence the same numbers.
use super::mixing::{iterate, NodeWeights};
use super::split;
use super::{ConsensusNode, Fusion, InformationPairs};
use crate::filter::Gaussian;
use crate::linalg::fixed;
use crate::linalg::Vector;
use crate::network::graph::NetworkNode;
use crate::network::topology::tally::NodeCounts;
use crate::network::topology::Topology;

use crate::network::topology::tally::Tally;

/// Whether every link of `net` is lossless: the lock-step loop gives the driver's numbers.
pub fn applies(net: &Topology) -> bool {
    net.links.iter().all(|l| l.channel.is_lossless())
}

/// Gets step k's estimates of every node, every node's counters of the step and, where the
/// loop has them, the Cholesky factors of the estimates' covariances as NEES computes them
/// (`linalg::fixed::nees_factor`, n² reals a node, node by node), so that the recorder need not
/// factor again what is the same in every trial (the trial's recorder,
/// `crate::decentralized::trial::Recorder`).
pub type Record<'r> =
    dyn FnMut(usize, &[&Gaussian], &[NodeCounts], Option<&[f64]>) -> Result<(), String> + 'r;

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
    let weights: Vec<NodeWeights> = nodes
        .iter()
        .map(|node| (node.own_weight, node.neighbours.clone()))
        .collect();
    let mut split = fixed_information_dim(nodes)
        .map(|n| split::for_dimension(n, nodes, &weights, measurements, sensors));
    let mut current: Vec<f64> = Vec::new();
    let mut mixed: Vec<f64> = Vec::new();
    for (j, z) in measurements.iter().enumerate() {
        let k = j + 1;
        tally.start_step();
        let iterations = nodes[0].iterations;
        if iterations > 0 {
            let n = nodes[0].prior.1.len();
            let bits = InformationPairs::frame_bits(nodes[0].pair_count(), n);
            for (i, heard) in hearers.iter().enumerate() {
                tally.broadcast_times(i, heard, bits, iterations as u64);
            }
        }
        let stepped = match &mut split {
            Some(split) => split.step(j, nodes, &weights, z),
            None => {
                let reading = |i: usize| if i < sensors { z.get(i) } else { None };
                for (i, node) in nodes.iter_mut().enumerate() {
                    node.start(reading(i));
                }
                let stride = stride(&nodes[0]);
                gather(nodes, stride, &mut current);
                mixed.resize(current.len(), 0.0);
                iterate(iterations, stride, &weights, &mut current, &mut mixed);
                scatter(nodes, stride, &current);
                nodes
                    .iter_mut()
                    .enumerate()
                    .try_for_each(|(i, node)| node.predict().map_err(|e| (i, e)))
                    .map(|()| None)
            }
        };
        let factors = stepped.map_err(|(i, e)| {
            format!(
                "node {}, step {k}, round {iterations}: {e}",
                net.nodes[i].name
            )
        })?;
        for (i, node) in nodes.iter().enumerate() {
            tally.listen(i, node.windows(k));
        }
        let estimates: Vec<&Gaussian> = nodes.iter().map(|n| &n.estimate).collect();
        record(k, &estimates, tally.counts(), factors)?;
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
