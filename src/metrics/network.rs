//! A multi-hop network's share of `summary.json`: per node (sensor, relay, sink) the frames it
//! sent, received and forwarded, its radio's energy per step by part and its lifetime on the
//! `[radio]` battery, and the network's lifetime: the first node to die, named. The counters
//! are [`crate::network::topology::tally`]'s, summed over trials and steps in
//! [`Sums::nodes`]; the energy is [`crate::network::radio`]'s model applied to them (linear in
//! the counters, so the mean per step is the energy of the mean counters).
use crate::metrics::energy::EnergySummary;
use crate::metrics::Sums;
use crate::network::radio::EnergyParts;
use crate::network::topology::tally::{activity, frames};
use crate::network::topology::{NodeKind, Topology};
use crate::scenario::build::Experiment;
use serde::{Deserialize, Serialize};

/// One node of the network.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct NodeSummary {
    /// `s0`, `r0`, `sink`.
    pub name: String,
    /// `sensor`, `relay` or `sink`.
    pub kind: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 2]>,
    /// Its next hop to the sink (absent for the sink).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parent: Option<String>,
    /// Hops from it to the sink.
    pub hops: usize,
    /// Data frames on air per step, every attempt, its own reports and those it forwards.
    pub frames_sent_per_step: f64,
    /// Data frames it received per step (every attempt that arrived).
    pub frames_received_per_step: f64,
    /// Reports of other nodes it sent on, per step (packets, not attempts).
    pub forwarded_per_step: f64,
    /// Its radio's energy per step, µJ, and by part.
    pub energy_per_step_uj: f64,
    pub energy_parts_per_step_uj: EnergyParts,
    /// Whether it runs on mains (the sink by default): no battery to run out.
    pub mains: bool,
    /// Days it lasts on the `[radio]` battery (absent on mains, or when it spends nothing).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lifetime_days: Option<f64>,
}

/// The first node to die.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FirstToDie {
    pub node: String,
    pub lifetime_days: f64,
}

/// The network of a variant.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct NetworkSummary {
    /// Whether the relays summed this scheme's reports into one frame per link
    /// ([`crate::network::aggregate`]) rather than forward each report per source.
    #[serde(default)]
    pub aggregated: bool,
    pub nodes: Vec<NodeSummary>,
    /// Per step, mean over trials: frames on air, every node's attempts (`per_step.csv`'s
    /// `hop_frames`).
    #[serde(default)]
    pub frames_per_step: Vec<f64>,
    /// Per step, mean over trials: frames that carried what other nodes sent (`hop_forwards`).
    #[serde(default)]
    pub forwards_per_step: Vec<f64>,
    /// The network's lifetime: the battery-powered node that dies first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_to_die: Option<FirstToDie>,
}

/// The network summary of a variant's `sums` over `exp`'s multi-hop network, and its energy as
/// the scheme's [`EnergySummary`]: every battery-powered node's energy per step added
/// (`energy_per_sensor_step_uj` is that over the sensors), and the network's lifetime as
/// `lifetime_days`. `None` on a star. `aggregated`: whether the relays summed the variant's
/// reports.
pub fn summarize(
    exp: &Experiment,
    net: &Topology,
    sums: &Sums,
    aggregated: bool,
) -> (NetworkSummary, EnergySummary) {
    let node_steps = (sums.trials * sums.steps) as f64;
    let per = node_steps.max(1.0);
    let mut total = EnergyParts::default();
    let mut nodes = Vec::with_capacity(net.nodes.len());
    for (i, node) in net.nodes.iter().enumerate() {
        let counts = sums.nodes.get(i).copied().unwrap_or_default();
        let parts = exp.radio.energy(&activity(&counts, node_steps)).per(per);
        let mains = node.kind == NodeKind::Sink && net.sink_mains;
        if !mains {
            total = total + parts;
        }
        let (sent, received, forwarded) = frames(&counts);
        nodes.push(NodeSummary {
            name: node.name.clone(),
            kind: match node.kind {
                NodeKind::Sensor(_) => "sensor",
                NodeKind::Relay(_) => "relay",
                NodeKind::Sink => "sink",
            }
            .into(),
            position: node.position,
            parent: net.parent[i].map(|p| net.nodes[p].name.clone()),
            hops: net.hops(i),
            frames_sent_per_step: sent as f64 / per,
            frames_received_per_step: received as f64 / per,
            forwarded_per_step: forwarded as f64 / per,
            energy_per_step_uj: parts.total(),
            energy_parts_per_step_uj: parts,
            mains,
            lifetime_days: if mains {
                None
            } else {
                exp.radio.lifetime_days(parts.total())
            },
        });
    }
    let first_to_die = nodes
        .iter()
        .filter_map(|n| n.lifetime_days.map(|d| (d, &n.name)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(d, name)| FirstToDie {
            node: name.clone(),
            lifetime_days: d,
        });
    let per_step = total.total();
    let energy = EnergySummary {
        energy_per_step_uj: per_step,
        energy_per_sensor_step_uj: per_step / net.sensors().max(1) as f64,
        energy_parts_per_step_uj: total,
        lifetime_days: first_to_die.as_ref().map(|f| f.lifetime_days),
    };
    (
        NetworkSummary {
            aggregated,
            nodes,
            frames_per_step: hops_column(sums, 0),
            forwards_per_step: hops_column(sums, 1),
            first_to_die,
        },
        energy,
    )
}

/// Column `c` of [`Sums::hops`] per step, as a mean over the trials (zeros where nothing was
/// counted).
fn hops_column(sums: &Sums, c: usize) -> Vec<f64> {
    let trials = sums.trials.max(1) as f64;
    match sums.hops.is_empty() {
        true => vec![0.0; sums.steps],
        false => sums.hops.iter().map(|h| h[c] as f64 / trials).collect(),
    }
}

/// A variant's energy and, over a multi-hop network (or the graph a decentralized scheme runs
/// on, [`Experiment::graph_of`]), its network summary ([`summarize`]); on a star, the sensors'
/// energy of [`crate::metrics::energy::of_variant`].
pub fn energy_and_network(
    exp: &Experiment,
    v: &crate::scenario::build::Variant,
    sums: &Sums,
) -> (EnergySummary, Option<NetworkSummary>) {
    match exp.graph_of(v) {
        Some(net) => {
            let (network, energy) =
                summarize(exp, &net, sums, v.aggregated(exp.network.as_deref()));
            (energy, Some(network))
        }
        None => (crate::metrics::energy::of_variant(exp, v, sums), None),
    }
}
