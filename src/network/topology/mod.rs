//! The network as a graph: the sensors, relays and one sink of a `[network]` table
//! ([`spec::NetworkSpec`]), the links between them (each with its channel), and the routing
//! tree along which a sensor's report travels to the sink. Without `[network]` (or with
//! `edges = "star"` and no relay) it is today's one-hop star, the sink being the fusion center.
//!
//! Names: sensors are `s0, s1, …` in file order, relays `r0, r1, …` in file order, the sink
//! `sink`; nodes are numbered in that order (sensors, relays, sink last). Every check names the
//! field and the nodes (a disconnected graph lists the nodes that cannot reach the sink).
//!
//! What a report costs on its way ([`cost`]) and what it loses ([`Topology::path_loss`]) come
//! from the links' channels: every hop pays a frame, its acknowledgement and its retries.
pub mod cost;
pub mod distance;
pub mod spec;
pub mod tally;

use crate::network::channel::ChannelSpec;
use petgraph::graph::{NodeIndex, UnGraph};
use spec::{EdgeRule, Edges, NetworkSpec, Relays, RouteRule, Sink};

/// Most nodes a network may have (sensors, relays and the sink): the routing and the per-node
/// sums grow with it, and 802.15.4's 16-bit short addresses are not the limit here.
pub const MAX_NODES: usize = 4096;
// The link's fates key every (node, source) pair apart only below this stride.
const _: () = assert!(MAX_NODES <= crate::network::channel::route::KEY_STRIDE);

/// The name of the sink.
pub const SINK: &str = "sink";

/// What a node is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// Sensor i of the scenario.
    Sensor(usize),
    /// Relay j of `relays`.
    Relay(usize),
    /// The sink (the star's fusion center).
    Sink,
}

/// A node of the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    pub kind: NodeKind,
    /// `s0`, `r0`, `sink`.
    pub name: String,
    /// Position, metres, where it has one.
    pub position: Option<[f64; 2]>,
}

/// A link between two nodes and its channel (both directions).
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    pub a: usize,
    pub b: usize,
    pub channel: ChannelSpec,
}

/// A checked network: nodes, links, and each node's next hop to the sink.
#[derive(Debug, Clone)]
pub struct Topology {
    pub nodes: Vec<Node>,
    pub links: Vec<Link>,
    /// The next hop of every node towards the sink (`None` for the sink).
    pub parent: Vec<Option<usize>>,
    /// Whether the sink runs on mains (no battery to run out).
    pub sink_mains: bool,
    /// Whether the relays sum the information of aggregable schemes
    /// ([`crate::network::aggregate`]) rather than forward their reports per source.
    pub aggregate: bool,
    /// Whether the sink sends its estimate down the tree after every step (`[network]
    /// broadcast_estimate`; priced by [`tally::Tally::feedback`], the frame of the feedback).
    pub broadcast_estimate: bool,
    /// The frames' 802.15.4 security (`[security]`): what every data frame and the feedback's
    /// frame add on air, priced per hop by [`tally::Tally`]. None unless the scenario sets it.
    pub security: crate::link::security::SecuritySpec,
    graph: UnGraph<(), usize>,
}

/// A `[network]` that cannot be built: the field (below `network.`) and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("network.{field}: {message}")]
pub struct TopologyError {
    pub field: String,
    pub message: String,
}

fn err(field: impl Into<String>, message: impl Into<String>) -> TopologyError {
    TopologyError {
        field: field.into(),
        message: message.into(),
    }
}

/// Nodes listed by name, at most a dozen, then how many more.
fn names(nodes: &[Node], idx: impl IntoIterator<Item = usize>) -> String {
    let all: Vec<&str> = idx.into_iter().map(|i| nodes[i].name.as_str()).collect();
    let shown = all.iter().take(12).copied().collect::<Vec<_>>().join(", ");
    match all.len() {
        n if n > 12 => format!("{shown} and {} more", n - 12),
        _ => shown,
    }
}

fn point(field: &str, v: &[f64]) -> Result<[f64; 2], TopologyError> {
    match v {
        [x, y] if x.is_finite() && y.is_finite() => Ok([*x, *y]),
        [_, _] => Err(err(
            field,
            format!("expected finite coordinates, got {v:?}"),
        )),
        _ => Err(err(
            field,
            format!("expected a position [x, y], got {} numbers", v.len()),
        )),
    }
}

impl Topology {
    /// The network of `spec` over sensors at `sensors` (their positions, where they have one),
    /// every link carrying `channel` (the scenario's `[channel]`; ideal when `None`) unless
    /// `links` gives it its own.
    pub fn build(
        spec: &NetworkSpec,
        sensors: &[Option<[f64; 2]>],
        channel: Option<&ChannelSpec>,
    ) -> Result<Self, TopologyError> {
        let nodes = nodes(spec, sensors)?;
        let pairs = edges(spec, &nodes)?;
        let default = channel.cloned().unwrap_or_default();
        let mut links: Vec<Link> = pairs
            .iter()
            .map(|&(a, b)| Link {
                a,
                b,
                channel: default.clone(),
            })
            .collect();
        let mut graph = UnGraph::<(), usize>::with_capacity(nodes.len(), links.len());
        for _ in &nodes {
            graph.add_node(());
        }
        for (k, l) in links.iter().enumerate() {
            graph.add_edge(NodeIndex::new(l.a), NodeIndex::new(l.b), k);
        }
        if let Some(model) = &spec.distance_loss {
            model.apply(&mut links, &nodes)?;
        }
        let mut overridden = vec![false; links.len()];
        for (j, o) in spec.links.iter().enumerate() {
            let field = format!("links[{j}]");
            let [a, b] = pair(&nodes, &format!("{field}.between"), &o.between)?;
            let k = graph
                .find_edge(NodeIndex::new(a), NodeIndex::new(b))
                .map(|e| graph[e])
                .ok_or_else(|| {
                    err(
                        format!("{field}.between"),
                        format!("{} and {} are not linked", nodes[a].name, nodes[b].name),
                    )
                })?;
            if std::mem::replace(&mut overridden[k], true) {
                return Err(err(
                    format!("{field}.between"),
                    format!(
                        "the link {} – {} is given twice",
                        nodes[a].name, nodes[b].name
                    ),
                ));
            }
            o.channel
                .validate_at(&format!("network.{field}.channel"))
                .map_err(|m| err(format!("{field}.channel"), m))?;
            links[k].channel = o.channel.clone();
        }
        let mut topology = Topology {
            parent: vec![None; nodes.len()],
            sink_mains: spec.sink_mains.unwrap_or(true),
            aggregate: spec.aggregate.unwrap_or(true),
            broadcast_estimate: spec.broadcast_estimate.unwrap_or(false),
            security: Default::default(),
            nodes,
            links,
            graph,
        };
        topology.parent = match (&spec.parent, topology.sink()) {
            (Some(_), None) => {
                return Err(err(
                    "parent",
                    "a network of peers (sink = false) has no routing tree to give",
                ))
            }
            (None, None) => {
                topology.check_connected()?;
                vec![None; topology.nodes.len()]
            }
            (Some(given), Some(_)) => topology.given_parents(given)?,
            (None, Some(_)) => topology.routed(spec.routes.unwrap_or_default())?,
        };
        debug_assert!(topology.sink().is_none_or(|s| topology.parent[s].is_none()));
        Ok(topology)
    }

    /// The one-hop star of a scenario without `[network]`: sensor i linked to the sink over
    /// `channels[i]` (its link as the star's per-sensor `[channel]` gives it), no relay, the sink
    /// on mains.
    pub fn star(channels: &[ChannelSpec]) -> Self {
        let n = channels.len();
        let mut nodes: Vec<Node> = (0..n)
            .map(|i| Node {
                kind: NodeKind::Sensor(i),
                name: format!("s{i}"),
                position: None,
            })
            .collect();
        nodes.push(Node {
            kind: NodeKind::Sink,
            name: SINK.to_string(),
            position: None,
        });
        let links: Vec<Link> = channels
            .iter()
            .enumerate()
            .map(|(i, c)| Link {
                a: i,
                b: n,
                channel: c.clone(),
            })
            .collect();
        let mut graph = UnGraph::<(), usize>::with_capacity(n + 1, n);
        for _ in &nodes {
            graph.add_node(());
        }
        for (k, l) in links.iter().enumerate() {
            graph.add_edge(NodeIndex::new(l.a), NodeIndex::new(l.b), k);
        }
        let mut parent = vec![Some(n); n];
        parent.push(None);
        Topology {
            nodes,
            links,
            parent,
            sink_mains: true,
            aggregate: false,
            broadcast_estimate: false,
            security: Default::default(),
            graph,
        }
    }

    /// The sink's index (the last node), if the network has one (`sink = false`: a network of
    /// peers, no routing tree).
    pub fn sink(&self) -> Option<usize> {
        let last = self.nodes.len().checked_sub(1)?;
        (self.nodes[last].kind == NodeKind::Sink).then_some(last)
    }

    /// The sink's index, or an error saying that `what` needs one.
    pub fn sink_for(&self, what: &str) -> Result<usize, String> {
        self.sink().ok_or_else(|| {
            format!("{what} needs a sink, and this network has none (network.sink = false)")
        })
    }

    /// The undirected links as node pairs, in link order.
    pub fn edges(&self) -> Vec<(usize, usize)> {
        self.links.iter().map(|l| (l.a, l.b)).collect()
    }

    /// Each node's neighbours, in increasing order.
    pub fn neighbours(&self, node: usize) -> Vec<usize> {
        let mut out: Vec<usize> = self
            .graph
            .neighbors(NodeIndex::new(node))
            .map(|n| n.index())
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// A network of peers must be connected (every node reaches every other).
    fn check_connected(&self) -> Result<(), TopologyError> {
        let mut seen = vec![false; self.nodes.len()];
        let mut dfs = petgraph::visit::Dfs::new(&self.graph, NodeIndex::new(0));
        while let Some(n) = dfs.next(&self.graph) {
            seen[n.index()] = true;
        }
        let cut: Vec<usize> = (0..self.nodes.len()).filter(|&i| !seen[i]).collect();
        if cut.is_empty() {
            return Ok(());
        }
        Err(err(
            "edges",
            format!(
                "the graph is disconnected: {} cannot reach {}",
                names(&self.nodes, cut),
                self.nodes[0].name
            ),
        ))
    }

    /// Number of sensors.
    pub fn sensors(&self) -> usize {
        self.nodes
            .iter()
            .filter(|n| matches!(n.kind, NodeKind::Sensor(_)))
            .count()
    }

    /// The link between `a` and `b`, if any.
    pub fn link(&self, a: usize, b: usize) -> Option<&Link> {
        self.graph
            .find_edge(NodeIndex::new(a), NodeIndex::new(b))
            .map(|e| &self.links[self.graph[e]])
    }

    /// The nodes a report of `node` passes, from it to the sink.
    pub fn route(&self, node: usize) -> Vec<usize> {
        let mut path = vec![node];
        let mut at = node;
        while let Some(p) = self.parent[at] {
            path.push(p);
            at = p;
        }
        path
    }

    /// Hops from `node` to the sink.
    pub fn hops(&self, node: usize) -> usize {
        self.route(node).len() - 1
    }

    /// The links of `node`'s route, in order.
    pub fn route_links(&self, node: usize) -> Vec<&Link> {
        self.route(node)
            .windows(2)
            .map(|w| self.link(w[0], w[1]).expect("a route follows links"))
            .collect()
    }

    /// The long-run probability that a report of `node` does not reach the sink: one minus the
    /// product over its hops of each hop's delivery, `1 − Π_h (1 − p_h)` with `p_h` the hop's
    /// [`ChannelSpec::delivery_loss`] (its retries included). What a loss-aware center
    /// assumes for that sensor (`link_loss = "channel"`).
    pub fn path_loss(&self, node: usize) -> f64 {
        1.0 - self
            .route_links(node)
            .iter()
            .map(|l| 1.0 - l.channel.delivery_loss())
            .product::<f64>()
    }

    /// The routing tree as the link's fates take it ([`crate::network::channel::route`]): every
    /// node's parent and uplink channel, every sensor's senders.
    pub fn routes(&self) -> crate::network::channel::route::Routes {
        let uplinks = (0..self.nodes.len())
            .map(|n| {
                self.parent[n].map(|p| {
                    let link = self.link(n, p).expect("a parent is linked");
                    (p, link.channel.clone())
                })
            })
            .collect();
        let senders = (0..self.sensors())
            .map(|s| {
                let mut r = self.route(s);
                r.pop();
                r
            })
            .collect();
        crate::network::channel::route::Routes { uplinks, senders }
    }

    /// How many nodes have `node` as their parent.
    pub fn children(&self, node: usize) -> usize {
        self.parent.iter().filter(|p| **p == Some(node)).count()
    }

    /// Whether this is the one-hop star: no relay, and every sensor linked straight to the sink.
    pub fn is_star(&self) -> bool {
        let Some(sink) = self.sink() else {
            return false;
        };
        self.nodes
            .iter()
            .all(|n| !matches!(n.kind, NodeKind::Relay(_)))
            && (0..sink).all(|i| self.parent[i] == Some(sink))
    }

    /// Parents as written: every node but the sink has one, linked to it, and following them
    /// ends at the sink.
    fn given_parents(
        &self,
        given: &std::collections::BTreeMap<String, String>,
    ) -> Result<Vec<Option<usize>>, TopologyError> {
        let sink = self.sink().expect("given parents need a sink");
        let mut parent = vec![None; self.nodes.len()];
        for (child, p) in given {
            let field = format!("parent.{child}");
            let c = index_of(&self.nodes, &field, child)?;
            let p = index_of(&self.nodes, &field, p)?;
            if c == sink {
                return Err(err(field, "the sink has no parent"));
            }
            if self.link(c, p).is_none() {
                return Err(err(
                    field,
                    format!(
                        "{} and {} are not linked",
                        self.nodes[c].name, self.nodes[p].name
                    ),
                ));
            }
            parent[c] = Some(p);
        }
        let missing: Vec<usize> = (0..sink).filter(|&i| parent[i].is_none()).collect();
        if !missing.is_empty() {
            return Err(err(
                "parent",
                format!(
                    "every node but the sink needs a parent; missing: {}",
                    names(&self.nodes, missing)
                ),
            ));
        }
        for start in 0..sink {
            let mut seen = vec![start];
            let mut at = start;
            while let Some(p) = parent[at] {
                if seen.contains(&p) {
                    seen.push(p);
                    let cycle: Vec<&str> = seen
                        .iter()
                        .skip_while(|&&n| n != p)
                        .map(|&n| self.nodes[n].name.as_str())
                        .collect();
                    return Err(err(
                        "parent",
                        format!(
                            "{} is a cycle: it never reaches the sink",
                            cycle.join(" → ")
                        ),
                    ));
                }
                seen.push(p);
                at = p;
            }
        }
        Ok(parent)
    }

    /// The shortest-path tree to the sink by `rule`; each node's parent is its neighbour on a
    /// shortest path (the lowest-numbered one where several are). A link that loses every
    /// packet carries no route.
    fn routed(&self, rule: RouteRule) -> Result<Vec<Option<usize>>, TopologyError> {
        let weight = |k: usize| match rule {
            RouteRule::Hops => 1.0,
            RouteRule::Etx => 1.0 / (1.0 - self.links[k].channel.delivery_loss()),
        };
        let usable = |k: usize| weight(k).is_finite();
        let sink_at = self.sink().expect("routes need a sink");
        let sink = NodeIndex::new(sink_at);
        let dist = petgraph::algo::dijkstra(&self.graph, sink, None, |e| {
            let w = weight(*e.weight());
            if w.is_finite() {
                w
            } else {
                f64::INFINITY
            }
        });
        let unreachable: Vec<usize> = (0..self.nodes.len())
            .filter(|&i| dist.get(&NodeIndex::new(i)).is_none_or(|d| !d.is_finite()))
            .collect();
        if !unreachable.is_empty() {
            return Err(err(
                "edges",
                format!(
                    "the graph is disconnected: {} cannot reach the sink",
                    names(&self.nodes, unreachable)
                ),
            ));
        }
        let d = |i: usize| dist[&NodeIndex::new(i)];
        let mut parent = vec![None; self.nodes.len()];
        for (v, slot) in parent.iter_mut().enumerate().take(sink_at) {
            let mut best: Option<(usize, f64)> = None;
            for e in self.graph.edges(NodeIndex::new(v)) {
                let k = *e.weight();
                if !usable(k) {
                    continue;
                }
                let l = &self.links[k];
                let u = if l.a == v { l.b } else { l.a };
                let via = d(u) + weight(k);
                let better = match best {
                    None => true,
                    Some((bu, bv)) => via < bv - 1e-12 * bv || (via <= bv + 1e-12 * bv && u < bu),
                };
                if better && d(u) < d(v) {
                    best = Some((u, via));
                }
            }
            *slot = best.map(|(u, _)| u);
        }
        Ok(parent)
    }
}

/// The index of the node named `name`.
fn index_of(nodes: &[Node], field: &str, name: &str) -> Result<usize, TopologyError> {
    nodes.iter().position(|n| n.name == name).ok_or_else(|| {
        let last = nodes.len() - 1;
        err(
            field,
            format!(
                "unknown node {name:?} (the nodes are {}{})",
                names(nodes, 0..last.min(6)),
                match (last > 6, &nodes[last].name) {
                    (true, l) => format!(", …, {l}"),
                    (false, l) => format!(", {l}"),
                }
            ),
        )
    })
}

/// Two distinct known nodes.
fn pair(nodes: &[Node], field: &str, names: &[String]) -> Result<[usize; 2], TopologyError> {
    let [a, b] = names else {
        return Err(err(
            field,
            format!("expected two node names, got {}", names.len()),
        ));
    };
    let (a, b) = (index_of(nodes, field, a)?, index_of(nodes, field, b)?);
    if a == b {
        return Err(err(field, format!("{} is linked to itself", nodes[a].name)));
    }
    Ok([a, b])
}

/// Sensors, relays and the sink, with their positions.
fn nodes(spec: &NetworkSpec, sensors: &[Option<[f64; 2]>]) -> Result<Vec<Node>, TopologyError> {
    let relays: Vec<Option<[f64; 2]>> = match &spec.relays {
        None => Vec::new(),
        Some(Relays::Count(n)) => vec![None; (*n).min(MAX_NODES + 1)],
        Some(Relays::At(at)) => at
            .iter()
            .enumerate()
            .map(|(j, p)| point(&format!("relays[{j}]"), p).map(Some))
            .collect::<Result<_, _>>()?,
        Some(Relays::Random(r)) => random_relays(r)?,
    };
    let (has_sink, sink) = match &spec.sink {
        None => (true, None),
        Some(Sink::Present(b)) => (*b, None),
        Some(Sink::At(p)) => (true, Some(point("sink", p)?)),
    };
    let total = sensors.len() + relays.len() + usize::from(has_sink);
    if total > MAX_NODES {
        return Err(err(
            "relays",
            format!("at most {MAX_NODES} nodes (sensors, relays and the sink), got {total}"),
        ));
    }
    let mut nodes: Vec<Node> = sensors
        .iter()
        .enumerate()
        .map(|(i, p)| Node {
            kind: NodeKind::Sensor(i),
            name: format!("s{i}"),
            position: *p,
        })
        .collect();
    nodes.extend(relays.into_iter().enumerate().map(|(j, p)| Node {
        kind: NodeKind::Relay(j),
        name: format!("r{j}"),
        position: p,
    }));
    if has_sink {
        nodes.push(Node {
            kind: NodeKind::Sink,
            name: SINK.into(),
            position: sink,
        });
    }
    if !has_sink && nodes.len() < 2 {
        return Err(err(
            "sink",
            "a network of peers needs at least two nodes (sensors and relays)",
        ));
    }
    Ok(nodes)
}

/// `relays = { count, area, seed }`: uniform in the rectangle, x then y of each relay in turn
/// from a generator of the placement's own seed.
fn random_relays(r: &spec::RandomRelays) -> Result<Vec<Option<[f64; 2]>>, TopologyError> {
    use rand::{Rng, SeedableRng};
    let [lo, hi] = match r.area.as_slice() {
        [a, b] => [point("relays.area[0]", a)?, point("relays.area[1]", b)?],
        _ => {
            return Err(err(
                "relays.area",
                format!(
                    "expected two corners [[x0, y0], [x1, y1]], got {}",
                    r.area.len()
                ),
            ))
        }
    };
    if r.count > MAX_NODES {
        return Err(err(
            "relays.count",
            format!("at most {MAX_NODES} nodes, got {}", r.count),
        ));
    }
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(r.seed);
    let mut at = |a: f64, b: f64| a.min(b) + rng.random::<f64>() * (a - b).abs();
    Ok((0..r.count)
        .map(|_| {
            let x = at(lo[0], hi[0]);
            Some([x, at(lo[1], hi[1])])
        })
        .collect())
}

/// The node pairs linked, each once, by the rule or the list.
fn edges(spec: &NetworkSpec, nodes: &[Node]) -> Result<Vec<(usize, usize)>, TopologyError> {
    let n = nodes.len();
    // The last node: the sink, or in a network of peers the last sensor or relay.
    let last = n - 1;
    let rule = match &spec.edges {
        None => EdgeRule::Star,
        Some(Edges::Rule(r)) => *r,
        Some(Edges::List(list)) => {
            if spec.range.is_some() {
                return Err(err("range", "only for edges = \"radius\""));
            }
            let mut out: Vec<(usize, usize)> = Vec::with_capacity(list.len());
            for (j, names) in list.iter().enumerate() {
                let field = format!("edges[{j}]");
                let [a, b] = pair(nodes, &field, names)?;
                let key = (a.min(b), a.max(b));
                if out.contains(&key) {
                    return Err(err(
                        field,
                        format!(
                            "the link {} – {} is given twice",
                            nodes[a].name, nodes[b].name
                        ),
                    ));
                }
                out.push(key);
            }
            return Ok(out);
        }
    };
    match (rule, spec.range) {
        (EdgeRule::Radius, None) => {
            return Err(err("range", "edges = \"radius\" needs a range in metres"))
        }
        (EdgeRule::Radius, Some(r)) if !(r.is_finite() && r > 0.0) => {
            return Err(err(
                "range",
                format!("expected a positive number of metres, got {r}"),
            ))
        }
        (EdgeRule::Radius, _) => {}
        (_, Some(_)) => return Err(err("range", "only for edges = \"radius\"")),
        _ => {}
    }
    let positions = || -> Result<Vec<[f64; 2]>, TopologyError> {
        let missing: Vec<usize> = (0..n).filter(|&i| nodes[i].position.is_none()).collect();
        if missing.is_empty() {
            Ok(nodes.iter().map(|x| x.position.expect("checked")).collect())
        } else {
            Err(err(
                "edges",
                format!(
                    "edges = \"{}\" needs every node's position; none for {}",
                    format!("{rule:?}").to_lowercase(),
                    names(nodes, missing)
                ),
            ))
        }
    };
    let dist = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
    let pairs = (0..n).flat_map(|a| (a + 1..n).map(move |b| (a, b)));
    Ok(match rule {
        EdgeRule::Star if nodes[last].kind != NodeKind::Sink => {
            return Err(err(
                "edges",
                "edges = \"star\" links every node to the sink, and this network has none (sink = false): give the edges",
            ))
        }
        EdgeRule::Star => (0..last).map(|i| (i, last)).collect(),
        EdgeRule::Line => (0..last).map(|i| (i, i + 1)).collect(),
        EdgeRule::Ring => {
            let mut e: Vec<(usize, usize)> = (0..last).map(|i| (i, i + 1)).collect();
            if n >= 3 {
                e.push((0, last));
            }
            e
        }
        EdgeRule::Complete => pairs.collect(),
        EdgeRule::Radius => {
            let p = positions()?;
            let r = spec.range.expect("checked");
            pairs.filter(|&(a, b)| dist(p[a], p[b]) <= r).collect()
        }
        EdgeRule::Grid => {
            let p = positions()?;
            let step = pairs
                .clone()
                .map(|(a, b)| dist(p[a], p[b]))
                .fold(f64::INFINITY, f64::min);
            if step.is_nan() || step <= 0.0 {
                return Err(err(
                    "edges",
                    "edges = \"grid\" needs distinct positions (two nodes share one)",
                ));
            }
            pairs
                .filter(|&(a, b)| dist(p[a], p[b]) <= step * (1.0 + 1e-9))
                .collect()
        }
    })
}

#[cfg(test)]
mod tests;
