//! The `[network]` table as written: nodes beyond the sensors (relays, the sink), how they are
//! linked, which links differ from the scenario's `[channel]`, and how reports are routed.
//! [`super::Topology::build`] checks it and turns it into a graph.
use crate::network::channel::ChannelSpec;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `[network]`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSpec {
    /// Relays `r0, r1, …`: their positions `[[x, y], …]`, how many there are (when every
    /// edge is given by name, positions may be left out), or `{ count, area, seed }`: placed
    /// uniformly at random in the rectangle `area = [[x0, y0], [x1, y1]]` by their own seed.
    #[serde(default)]
    pub relays: Option<Relays>,
    /// The sink's position `[x, y]` (optional when no edge rule needs positions), or `false`:
    /// no sink, a network of peers where every node estimates (the decentralized schemes,
    /// [`crate::decentralized`]).
    #[serde(default)]
    pub sink: Option<Sink>,
    /// Whether the sink runs on mains (default true, as the fusion center of a star does): its
    /// energy is reported but it has no battery to run out.
    #[serde(default)]
    pub sink_mains: Option<bool>,
    /// How the nodes are linked (default `"star"`).
    #[serde(default)]
    pub edges: Option<Edges>,
    /// `edges = "radius"`: link the nodes within this many metres of each other.
    #[serde(default)]
    pub range: Option<f64>,
    /// The routing tree to the sink: by `"hops"` (default) or by `"etx"` (expected
    /// transmissions, 1 / (1 − loss) per hop). Ignored where `parent` is given.
    #[serde(default)]
    pub routes: Option<RouteRule>,
    /// The routing tree written out: the next hop of every node but the sink, by name.
    #[serde(default)]
    pub parent: Option<BTreeMap<String, String>>,
    /// Links whose channel differs from the scenario's `[channel]`.
    #[serde(default)]
    pub links: Vec<LinkSpec>,
    /// Whether the relays sum the information of the schemes that allow it (default true;
    /// [`crate::network::aggregate`]); `false` forwards every report per source.
    #[serde(default)]
    pub aggregate: Option<bool>,
    /// Whether the sink sends its estimate (mean and covariance) down the routing tree after
    /// every step, so that every node knows it (default false; the sink schemes only, the
    /// decentralized ones estimate at every node already). It rides in the step's feedback
    /// frame where the scheme sends one, else in a frame of its own, one per node with
    /// children.
    #[serde(default)]
    pub broadcast_estimate: Option<bool>,
    /// Every link's loss from its length ([`super::distance`]), unless `[[network.links]]`
    /// gives the link its own channel.
    #[serde(default)]
    pub distance_loss: Option<super::distance::DistanceLoss>,
}

/// `sink`: its position, or whether there is one (`false`: a network of peers; `true`: a sink
/// without a position).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Sink {
    At(Vec<f64>),
    Present(bool),
}

/// `relays`: positions or a count.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Relays {
    Count(usize),
    At(Vec<Vec<f64>>),
    Random(RandomRelays),
}

/// `relays = { count = …, area = [[x0, y0], [x1, y1]], seed = … }`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RandomRelays {
    pub count: usize,
    /// Opposite corners of the rectangle, metres.
    pub area: Vec<Vec<f64>>,
    /// Seed of the placement (independent of the scenario's seed, so the network stays fixed).
    #[serde(default)]
    pub seed: u64,
}

/// `edges`: a rule or the list of links by name.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Edges {
    Rule(EdgeRule),
    List(Vec<Vec<String>>),
}

/// The edge rules. Nodes are taken in the order sensors, relays, sink.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EdgeRule {
    /// Every node linked to the sink: today's one-hop network.
    Star,
    /// `s0 – s1 – … – r0 – … – sink`.
    Line,
    /// The line closed by `sink – s0`.
    Ring,
    /// Positions on a lattice, each node linked to those at the smallest distance between any
    /// two nodes (its 4-neighbours on a square lattice).
    Grid,
    /// Every pair linked.
    Complete,
    /// A geometric graph: the pairs within `range` metres.
    Radius,
}

/// How the routing tree is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RouteRule {
    #[default]
    Hops,
    Etx,
}

/// `[[network.links]]`: one link's own channel.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    /// The two nodes, by name.
    pub between: Vec<String>,
    /// The link's channel, in place of the scenario's `[channel]` (both directions).
    pub channel: ChannelSpec,
}
