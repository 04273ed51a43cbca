//! Fates over multi-hop routes: a report crosses every link of its route to the sink, each hop
//! with a fate of its own (loss, delay, retries with real ACKs), drawn from the link stream.
//!
//! # Keys of the draws
//!
//! Every node n but the sink has one uplink, the link to its parent in the routing tree
//! (`crate::network::topology`). The fates on it come from generators keyed like a star
//! sensor's link ([`seeding::sensor_slots`] of key n), so that a sensor's first hop is drawn
//! exactly as its one-hop link was, and a one-hop tree (the star) keeps today's draws:
//!
//! - the Gilbert–Elliott state of the uplink of n (one chain per link: every frame crossing it
//!   at a step sees the same state) and of its downlink (which loses the ACKs and the feedback)
//!   from key n, as a star sensor's;
//! - n's own report at step k from key n's slot k, as a star sensor's;
//! - a report of source s that n forwards, from key [`forward_key`]`(n, s)`'s slot k: every
//!   (link, step, source) has its own coins, so no source's fate depends on which others sent;
//! - the feedback going down the link of n at step k from key n's downlink slot k.
//!
//! A report sent at step k meets on every hop the fate of step k (the MAC forwards within
//! milliseconds); the hops' delays add. It is lost when any hop loses it (after that hop's
//! retries); the hops after a loss are not tried. A sensor holds the feedback of a step when
//! every link from the sink down to it delivered it.
use std::sync::Arc;

use super::fate::{loss_path, slot_fate};
use super::spec::{Arq, ChannelSpec};
use super::{Fate, FateTable};
use crate::stats::seeding;

/// Node indices below this are keyed apart by [`forward_key`] (the topology's node limit is at
/// most this).
pub const KEY_STRIDE: usize = 4096;

/// The key of the coins of the reports of source `source` that node `node` forwards: far from
/// every node's own key (below 2^24 for nodes and sources below [`KEY_STRIDE`]).
pub fn forward_key(node: usize, source: usize) -> usize {
    usize::MAX - (node * KEY_STRIDE + source)
}

/// The routes of a trial's reports: for every node but the sink, its parent and the channel of
/// its uplink; for every sensor, the nodes that send its report (itself, then its relays).
#[derive(Debug, Clone, PartialEq)]
pub struct Routes {
    /// Per node: `(parent, channel of the link to it)`; `None` for the sink.
    pub uplinks: Vec<Option<(usize, ChannelSpec)>>,
    /// Per sensor: the senders along its route, the sensor first (the sink excluded).
    pub senders: Vec<Vec<usize>>,
}

impl Routes {
    /// The steps a late packet of sensor `i` may take at most: its hops' horizons added.
    pub fn horizon(&self, i: usize) -> u64 {
        self.senders[i]
            .iter()
            .map(|&n| self.uplink(n).delay().horizon())
            .fold(0u64, |a, h| a.saturating_add(u64::from(h)))
    }

    /// The channel of node `n`'s uplink; only nodes that send (never the sink) have one.
    fn uplink(&self, n: usize) -> &ChannelSpec {
        &self.uplinks[n].as_ref().expect("the sink sends nothing").1
    }

    /// Whether every link's downlink is lossless (feedback and ACKs always arrive).
    pub fn downlinks_lossless(&self) -> bool {
        self.uplinks
            .iter()
            .flatten()
            .all(|(_, c)| c.downlink_spec().is_lossless())
    }
}

/// The fates of one trial over [`Routes`]: every hop of every sensor's report at every step,
/// and what they add up to per sensor (the tables the link layer reads as a star's).
#[derive(Debug, Clone)]
pub struct RouteFates {
    /// Per (sensor, step): the route's fate ([`Fate::relayed`] counts its hops after the first).
    pub up: Arc<FateTable>,
    /// Per (sensor, step): whether the step's feedback reached the sensor (`None` when every
    /// downlink is lossless).
    pub down: Option<Arc<FateTable>>,
    /// Per (node, step): whether the feedback reached the node (`None` as `down`).
    pub node_down: Option<FateTable>,
    /// Per (node, step): the fate of the node's own frame on its uplink, drawn from the node's
    /// key (a sensor's is its report's first hop): what an aggregate frame meets
    /// ([`crate::network::aggregate`]). The sink's are never read.
    pub node_up: FateTable,
    /// Every hop's fate, sensor-major, then step, then hop.
    hops: Vec<Fate>,
    /// Per sensor: where its fates start in `hops`.
    offsets: Vec<usize>,
    steps: usize,
}

impl RouteFates {
    /// Draws the fates of `routes` over steps `1..=steps` of trial `trial` (see the module
    /// documentation for the keys). `per_source`: whether any variant forwards reports per
    /// source (else only the nodes' own frames are drawn, [`RouteFates::node_up`], and `up`
    /// holds no fate: O(nodes) a step rather than O(Σ route lengths)).
    pub fn draw(routes: &Routes, steps: usize, seed: u64, trial: u64, per_source: bool) -> Self {
        let nodes = routes.uplinks.len();
        let slots = |key: usize, down: bool| seeding::sensor_slots(seed, trial, key, down);
        // Per node: its uplink's loss per step and its ACKs' loss per step (the downlink's).
        let mut up_loss = vec![Vec::new(); nodes];
        let mut ack_loss = vec![Vec::new(); nodes];
        for (n, link) in routes.uplinks.iter().enumerate() {
            if let Some((_, c)) = link {
                up_loss[n] = loss_path(c, steps, slots(n, false));
                if c.arq.is_some() {
                    ack_loss[n] = loss_path(&c.downlink_spec(), steps, slots(n, true));
                }
            }
        }
        let mut hops = Vec::new();
        let mut offsets = Vec::with_capacity(routes.senders.len());
        let mut composed = Vec::with_capacity(routes.senders.len() * steps);
        let sources = if per_source { routes.senders.len() } else { 0 };
        for (s, senders) in routes.senders.iter().enumerate().take(sources) {
            offsets.push(hops.len());
            let keyed: Vec<_> = senders
                .iter()
                .map(|&n| slots(if n == s { n } else { forward_key(n, s) }, false))
                .collect();
            for k in 1..=steps {
                let mut path = Fate::default();
                for (h, (&n, slot)) in senders.iter().zip(&keyed).enumerate() {
                    let c = routes.uplink(n);
                    let arq = c
                        .arq
                        .map(|a| (a.max_retries.min(Arq::MAX_RETRIES), ack_loss[n][k - 1]));
                    let f = slot_fate(c, up_loss[n][k - 1], || slot(k), arq);
                    hops.push(f);
                    if path.lost {
                        continue;
                    }
                    path.relayed += u32::from(h > 0);
                    path.retries += f.retries;
                    path.acks += f.acks;
                    path.lost = f.lost;
                    path.delay = if f.lost {
                        0
                    } else {
                        path.delay.saturating_add(f.delay)
                    };
                }
                composed.push(path);
            }
        }
        let sensors = routes.senders.len();
        if !per_source {
            composed.resize(sensors * steps, Fate::default());
        }
        // Every node's own frame from its own key: a sensor's is drawn as its report's first
        // hop is (the same generator and slot), a relay's as a sensor's would be.
        let mut own = Vec::with_capacity(nodes * steps);
        for n in 0..nodes {
            let Some((_, c)) = &routes.uplinks[n] else {
                own.extend((0..steps).map(|_| Fate::default()));
                continue;
            };
            let slot = slots(n, false);
            own.extend((1..=steps).map(|k| {
                let arq = c
                    .arq
                    .map(|a| (a.max_retries.min(Arq::MAX_RETRIES), ack_loss[n][k - 1]));
                slot_fate(c, up_loss[n][k - 1], || slot(k), arq)
            }));
        }
        let node_up = FateTable::from_fates(nodes, steps, own);
        let (down, node_down) = if routes.downlinks_lossless() {
            (None, None)
        } else {
            let mut per_node = Vec::with_capacity(nodes * steps);
            for n in 0..nodes {
                if routes.uplinks[n].is_none() {
                    // The sink: the feedback starts there (its fates are never read).
                    per_node.extend((0..steps).map(|_| Fate::default()));
                    continue;
                }
                let c = routes.uplink(n).downlink_spec();
                let losses = loss_path(&c, steps, slots(n, true));
                let down = slots(n, true);
                per_node
                    .extend((1..=steps).map(|k| slot_fate(&c, losses[k - 1], || down(k), None)));
            }
            let node_table = FateTable::from_fates(nodes, steps, per_node);
            let table = &node_table;
            let sensor_fates = (0..sensors)
                .flat_map(|s| {
                    (1..=steps).map(move |k| Fate {
                        lost: !holds(routes, table, s, k),
                        ..Fate::default()
                    })
                })
                .collect();
            (
                Some(Arc::new(FateTable::from_fates(
                    sensors,
                    steps,
                    sensor_fates,
                ))),
                Some(node_table),
            )
        };
        RouteFates {
            up: Arc::new(FateTable::from_fates(sensors, steps, composed)),
            down,
            node_down,
            node_up,
            hops,
            offsets,
            steps,
        }
    }

    /// The fates of sensor `s`'s report at step `k` on each hop of its route (those after a
    /// loss were drawn but not tried).
    pub fn hops(&self, s: usize, k: usize) -> &[Fate] {
        let len = self
            .offsets
            .get(s + 1)
            .copied()
            .unwrap_or(self.hops.len())
            .saturating_sub(self.offsets[s])
            / self.steps.max(1);
        let at = self.offsets[s] + (k - 1) * len;
        &self.hops[at..at + len]
    }

    /// Whether node `n` holds the feedback of step `k`.
    pub fn node_holds(&self, routes: &Routes, n: usize, k: usize) -> bool {
        self.node_down
            .as_ref()
            .is_none_or(|t| holds(routes, t, n, k))
    }
}

/// Whether node `n` holds the feedback of step `k`: its link and every link above it delivered
/// it (`down`: per node, the fate of the feedback on its uplink's downlink).
fn holds(routes: &Routes, down: &FateTable, mut n: usize, k: usize) -> bool {
    loop {
        match &routes.uplinks[n] {
            None => return true,
            Some((p, _)) if !down.get(n, k).lost => n = *p,
            Some(_) => return false,
        }
    }
}
