//! The `energy-ratio` claim: the network radio energy a step of a consensus scheme against that
//! of the all-data Kalman filter's convergecast (the relays sum the information, the sink sends
//! its estimate back down the tree), each checked against an independent count, and their
//! ratio against a stated floor. It answers the deployment question of decentralized
//! estimation — let the peers agree, or fuse at a sink and tell everyone? — in joules.
//!
//! The independent count uses the graph (each node's degree, the routing tree's children),
//! the `[radio]` constants and the IEEE 802.15.4 frame layout written out here (PHY header
//! 6 octets: preamble 4, SFD 1, PHR 1; MAC header 9: frame control 2, sequence number 1,
//! destination PAN 2, short addresses 2 + 2 with the source PAN compressed; FCS 2), never the
//! run's counters or the library's frame helpers. With n the state dimension, a pair
//! (information matrix and vector, or estimate and covariance) is n + n(n+1)/2 singles:
//! - consensus with L iterations and p pairs a message (p = 2 for the hybrid and the
//!   information-weighted filter): each node broadcasts L frames a step, each received by each
//!   of its d neighbours in a listening window of its own (d·L windows);
//! - the convergecast: every node but the sink holding reports sends one frame to its parent —
//!   the one report itself (its m singles) when its subtree holds one sensor, else one pair;
//!   a node with c children listens c windows and receives their frames; with the estimate sent back
//!   (`broadcast_estimate`), every node with children sends it in one frame, and every node but
//!   the sink listens one window for it and receives it;
//! - each frame sent costs its airtime and the turnaround at the TX current, each frame received
//!   its airtime at the RX current, each window `listen_us` at the RX current; the rest of the
//!   step is sleep. The network's energy sums the battery-powered nodes (a sink on mains is
//!   left out).
//!
//! Ideal links only: a lost frame changes the counts, and the claim refuses a lossy network.
//! The counts are the same in every trial, so the verdict needs no standard error: each energy
//! must equal its count to a relative 1e-9, and the ratio must reach `at_least`.
use super::verdict::{ClaimResult, Verdict};
use crate::decentralized::trial::{FusionKind, PeerKind};
use crate::metrics::results::Summary;
use crate::network::radio::RadioSpec;
use crate::network::topology::{NodeKind, Topology};
use crate::scenario::build::Experiment;

/// Relative agreement of a measured energy with its count (rounding of sums over trials).
const EXACT: f64 = 1e-9;
/// PHY header (preamble, SFD, PHR) and MAC header and footer, octets (module docs).
const PHY_OCTETS: f64 = 6.0;
const MAC_OVERHEAD_OCTETS: f64 = 9.0 + 2.0;

/// What one node's radio does in a step.
#[derive(Debug, Default, Clone, Copy)]
struct NodeStep {
    /// Frames sent and their bits on air.
    tx: f64,
    tx_bits: f64,
    /// Bits received on air.
    rx_bits: f64,
    /// Listening windows.
    windows: f64,
}

impl NodeStep {
    /// Its energy in µJ under `radio`: TX, RX, listening, and sleep for the rest of the step.
    fn energy_uj(&self, radio: &RadioSpec) -> f64 {
        let us = |bits: f64| bits / radio.bit_rate_kbps * 1000.0;
        let tx_us = us(self.tx_bits) + self.tx * radio.turnaround_us;
        let rx_us = us(self.rx_bits) + self.windows * radio.listen_us;
        let sleep_us = (radio.step_seconds * 1e6 - tx_us - rx_us).max(0.0);
        radio.supply_v * (radio.tx_ma * tx_us + radio.rx_ma * rx_us + radio.sleep_ma * sleep_us)
            / 1000.0
    }
}

/// Bits on air of a frame carrying `singles` singles.
fn frame_bits(singles: usize) -> f64 {
    8.0 * (PHY_OCTETS + MAC_OVERHEAD_OCTETS) + 32.0 * singles as f64
}

/// Singles of `pairs` pairs of an `n`-dimensional state.
fn pair_singles(n: usize, pairs: usize) -> usize {
    pairs * (n + n * (n + 1) / 2)
}

/// The network's energy a step, µJ: the battery-powered nodes' sum.
fn network_uj(net: &Topology, radio: &RadioSpec, steps: &[NodeStep]) -> f64 {
    let sink = net.sink().filter(|_| net.sink_mains);
    steps
        .iter()
        .enumerate()
        .filter(|&(i, _)| Some(i) != sink)
        .map(|(_, s)| s.energy_uj(radio))
        .sum()
}

/// Consensus with `iterations` broadcasts of `pairs` pairs a step at every node.
fn consensus_uj(
    net: &Topology,
    radio: &RadioSpec,
    n: usize,
    iterations: usize,
    pairs: usize,
) -> f64 {
    let bits = frame_bits(pair_singles(n, pairs));
    let l = iterations as f64;
    let steps: Vec<NodeStep> = (0..net.nodes.len())
        .map(|i| {
            let d = net.neighbours(i).len() as f64;
            NodeStep {
                tx: l,
                tx_bits: l * bits,
                rx_bits: d * l * bits,
                windows: d * l,
            }
        })
        .collect();
    network_uj(net, radio, &steps)
}

/// The convergecast up the routing tree (a node sends the one report its subtree holds, of
/// `report_singles(sensor)` singles, or the pair of their sum), and the estimate back down it.
fn convergecast_uj(
    net: &Topology,
    radio: &RadioSpec,
    n: usize,
    report_singles: &dyn Fn(usize) -> usize,
    back: bool,
) -> f64 {
    let nodes = net.nodes.len();
    // The sensors below (and at) each node: its frame's content.
    let mut reports: Vec<Vec<usize>> = vec![Vec::new(); nodes];
    for (i, node) in net.nodes.iter().enumerate() {
        if let NodeKind::Sensor(s) = node.kind {
            let mut at = Some(i);
            while let Some(j) = at {
                reports[j].push(s);
                at = net.parent[j];
            }
        }
    }
    let up_bits = |i: usize| match reports[i].as_slice() {
        [] => None,
        [one] => Some(frame_bits(report_singles(*one))),
        _ => Some(frame_bits(pair_singles(n, 1))),
    };
    let estimate = frame_bits(pair_singles(n, 1));
    let mut s = vec![NodeStep::default(); nodes];
    for i in 0..nodes {
        let (Some(p), Some(bits)) = (net.parent[i], up_bits(i)) else {
            continue;
        };
        s[i].tx += 1.0;
        s[i].tx_bits += bits;
        s[p].rx_bits += bits;
    }
    for (i, parent) in net.parent.iter().enumerate() {
        if let Some(p) = parent {
            // The parent's window for this child, whether or not it sends.
            s[*p].windows += 1.0;
            if back {
                s[i].windows += 1.0;
                s[i].rx_bits += estimate;
            }
        }
    }
    if back {
        for p in net
            .parent
            .iter()
            .flatten()
            .collect::<std::collections::BTreeSet<_>>()
        {
            s[*p].tx += 1.0;
            s[*p].tx_bits += estimate;
        }
    }
    network_uj(net, radio, &s)
}

/// The independent count of `label`'s network energy a step, or why it has none.
fn counted(exp: &Experiment, label: &str) -> Result<f64, String> {
    let net = exp
        .network
        .as_deref()
        .ok_or("the claim needs a [network]")?;
    if net.links.iter().any(|l| !l.channel.is_lossless()) {
        return Err("the claim counts frames on ideal links; this network has a lossy one".into());
    }
    if net.security.is_secured() {
        return Err(
            "the claim counts unsecured frames; this scenario sets a [security] level".into(),
        );
    }
    let ci =
        super::curve_index(exp, label).ok_or_else(|| format!("no scheme labelled {label:?}"))?;
    let v = exp
        .variants
        .iter()
        .find(|v| v.curve == ci)
        .ok_or_else(|| format!("{label}: no variant"))?;
    let n = exp.system.state_dim();
    match v.scheme.peers().map(|p| &p.kind) {
        Some(PeerKind::Consensus { fusion, iterations, .. }) => {
            let pairs = if *fusion == FusionKind::Hybrid { 2 } else { 1 };
            Ok(consensus_uj(net, &exp.radio, n, *iterations, pairs))
        }
        Some(_) => Err(format!("{label}: the claim counts the consensus family only among the decentralized schemes")),
        None if v.kind == "centralized-kf" && v.aggregated(Some(net)) => {
            let singles = |sensor: usize| exp.system.sensors[sensor].meas_dim();
            Ok(convergecast_uj(net, &exp.radio, n, &singles, net.broadcast_estimate))
        }
        None => Err(format!(
            "{label}: the claim counts the all-data KF summed by the relays (network.aggregate) among the sink schemes"
        )),
    }
}

/// The claim: `a`'s network energy over `b`'s is at least `at_least`, both as counted.
pub fn check(
    exp: &Experiment,
    summary: &Summary,
    text: &str,
    (a, b): (&str, &str),
    at_least: f64,
) -> ClaimResult {
    let measured = |label: &str| {
        let ci = super::curve_index(exp, label)?;
        summary
            .schemes
            .iter()
            .find(|s| s.curve == ci)
            .map(|s| s.energy.energy_per_step_uj)
    };
    let fails = |why: String| ClaimResult::new(text, Verdict::Fails, None, why);
    let (ca, cb) = match (counted(exp, a), counted(exp, b)) {
        (Ok(x), Ok(y)) => (x, y),
        (Err(e), _) | (_, Err(e)) => return fails(e),
    };
    let (Some(ma), Some(mb)) = (measured(a), measured(b)) else {
        return fails("a scheme of the claim has no row".into());
    };
    let off = |m: f64, c: f64| (m - c).abs() / c.abs().max(f64::MIN_POSITIVE);
    let ratio = ma / mb;
    let words = format!(
        "{a}: {ma:.1} µJ a step (counted {ca:.1}); {b}: {mb:.1} µJ (counted {cb:.1}); ratio {ratio:.1} (counted {:.1}, claimed at least {at_least})",
        ca / cb
    );
    let verdict = if off(ma, ca) > EXACT || off(mb, cb) > EXACT || ratio < at_least {
        Verdict::Fails
    } else {
        Verdict::Holds
    };
    ClaimResult::new(text, verdict, None, words)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One node's step by hand under the CC2420 defaults: a 14-single frame (n = 4) is 56 + 11
    /// octets of MAC and 6 of PHY = 73 octets = 584 bits = 2336 µs; sent: (2336 + 192) µs at
    /// 52.2 mW = 131.9616 µJ; received: 2336 µs at 56.4 mW = 131.7504 µJ; a window 56.4 µJ.
    #[test]
    fn a_node_step_by_hand() {
        let radio = RadioSpec::default();
        assert_eq!(frame_bits(pair_singles(4, 1)), 584.0);
        assert_eq!(frame_bits(1), 120.0 + 48.0);
        let s = NodeStep {
            tx: 1.0,
            tx_bits: 584.0,
            rx_bits: 2.0 * 584.0,
            windows: 2.0,
        };
        let awake = 2528.0 + 2.0 * 2336.0 + 2000.0;
        let want = 131.9616 + 2.0 * 131.7504 + 2.0 * 56.4 + 0.06 * (1e6 - awake) / 1000.0;
        assert!(
            (s.energy_uj(&radio) - want).abs() < 1e-9,
            "{}",
            s.energy_uj(&radio)
        );
    }
}
