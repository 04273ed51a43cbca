//! The fate of every frame the graph driver ([`super::driver`]) sends: one per (directed link,
//! step, source, message), drawn from the link stream so that every scheme meets the same ones.
//!
//! The keys extend the multi-hop network's ([`crate::network::channel::route`]), so that a star
//! and a tree keep their draws whoever sends the frames:
//! - a frame node n sends up to its parent: key n for its own frame, `forward_key(n, s)` for
//!   one it forwards for source s, on the uplink's Gilbert–Elliott chain (key n), the ACKs on the
//!   downlink's chain (key n, downlink);
//! - a frame a parent sends down to child c: key c on the downlink side, on the link's
//!   `downlink` model (the direction the star's feedback takes; ideal unless the link gives one);
//! - a frame over a link outside the routing tree: [`lateral_key`]`(a, b)` per direction, its
//!   chain from the same key;
//! - the m-th frame (m ≥ 1) of the same (link, direction, source) in one step (a consensus
//!   iteration, a second broadcast): [`seeding::message_key`] of the first's key and m.
//!
//! A frame sent at step k meets the link's state of step k (the MAC sends within milliseconds).
use std::collections::HashMap;

use crate::network::channel::fate::{loss_path, slot_fate};
use crate::network::channel::route::{forward_key, KEY_STRIDE};
use crate::network::channel::{Arq, ChannelSpec, Fate};
use crate::network::topology::Topology;
use crate::stats::seeding;

/// The key of the coins of frames node `a` sends to node `b` over a link of neither's uplink:
/// below every [`forward_key`] (which stay above `usize::MAX − KEY_STRIDE²`).
pub fn lateral_key(a: usize, b: usize) -> usize {
    usize::MAX - (KEY_STRIDE * KEY_STRIDE + a * KEY_STRIDE + b)
}

/// How a directed link lies on the routing tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    /// From a node to its parent.
    Up,
    /// From a parent to its child.
    Down,
    /// Over a link outside the tree.
    Lateral,
}

/// The fates of one trial's frames over a graph, drawn as they are asked for.
pub struct GraphFates {
    seed: u64,
    trial: u64,
    steps: usize,
    parent: Vec<Option<usize>>,
    /// Link index by (lower node, higher node).
    links: HashMap<(usize, usize), usize>,
    channels: Vec<ChannelSpec>,
    /// Per node: the loss per step of its uplink (to its parent); empty for the sink.
    up_loss: Vec<Vec<f64>>,
    /// Per node: the loss per step of its downlink (from its parent): frames sent down, ACKs of
    /// its own frames.
    down_loss: Vec<Vec<f64>>,
    /// Per directed lateral link: its loss per step.
    lateral_loss: HashMap<(usize, usize), Vec<f64>>,
    /// Frames already sent this step per (sender, receiver, source).
    sent: HashMap<(usize, usize, usize), u64>,
    step: usize,
}

impl GraphFates {
    /// The fates of trial `trial` of a run seeded `seed` over `steps` steps on `net`.
    pub fn new(net: &Topology, steps: usize, seed: u64, trial: u64) -> Self {
        let nodes = net.nodes.len();
        let links: HashMap<_, _> = net
            .links
            .iter()
            .enumerate()
            .map(|(j, l)| ((l.a.min(l.b), l.a.max(l.b)), j))
            .collect();
        let channels: Vec<_> = net.links.iter().map(|l| l.channel.clone()).collect();
        let slots = |key: usize, down: bool| seeding::sensor_slots(seed, trial, key, down);
        let mut up_loss = vec![Vec::new(); nodes];
        let mut down_loss = vec![Vec::new(); nodes];
        for n in 0..nodes {
            if let Some(p) = net.parent[n] {
                let c = &channels[links[&(n.min(p), n.max(p))]];
                up_loss[n] = loss_path(c, steps, slots(n, false));
                down_loss[n] = loss_path(&c.downlink_spec(), steps, slots(n, true));
            }
        }
        Self {
            seed,
            trial,
            steps,
            parent: net.parent.clone(),
            links,
            channels,
            up_loss,
            down_loss,
            lateral_loss: HashMap::new(),
            sent: HashMap::new(),
            step: 0,
        }
    }

    /// The channel of the link between `a` and `b`, if they are linked.
    pub fn channel(&self, a: usize, b: usize) -> Option<&ChannelSpec> {
        self.links
            .get(&(a.min(b), a.max(b)))
            .map(|&j| &self.channels[j])
    }

    fn direction(&self, a: usize, b: usize) -> Direction {
        if self.parent[a] == Some(b) {
            Direction::Up
        } else if self.parent[b] == Some(a) {
            Direction::Down
        } else {
            Direction::Lateral
        }
    }

    /// The index of the next frame from `a` to `b` for `source` at step `k` (0 for the first).
    fn next_index(&mut self, k: usize, a: usize, b: usize, source: usize) -> u64 {
        if self.step != k {
            self.sent.clear();
            self.step = k;
        }
        let m = self.sent.entry((a, b, source)).or_insert(0);
        *m += 1;
        *m - 1
    }

    /// The fate at step `k` of a frame of `source` that `a` sends to its neighbour `b`;
    /// `acknowledged`: whether the link's ARQ applies (a unicast frame; never a broadcast).
    /// Panics when `a` and `b` are not linked (the driver checks first).
    pub fn frame(
        &mut self,
        k: usize,
        a: usize,
        b: usize,
        source: usize,
        acknowledged: bool,
    ) -> Fate {
        let m = self.next_index(k, a, b, source);
        let link = self.channel(a, b).expect("a frame crosses a link").clone();
        let arq = |ack_loss: f64| {
            link.arq
                .filter(|_| acknowledged)
                .map(|a| (a.max_retries.min(Arq::MAX_RETRIES), ack_loss))
        };
        let at = k - 1;
        match self.direction(a, b) {
            Direction::Up => {
                let base = if source == a {
                    a
                } else {
                    forward_key(a, source)
                };
                let slot = self.slot(seeding::message_key(base, m), false, k);
                slot_fate(&link, self.up_loss[a][at], slot, arq(self.down_loss[a][at]))
            }
            Direction::Down => {
                let spec = link.downlink_spec();
                let slot = self.slot(seeding::message_key(b, m), true, k);
                slot_fate(&spec, self.down_loss[b][at], slot, arq(self.up_loss[b][at]))
            }
            Direction::Lateral => {
                let loss = self.lateral(a, b)[at];
                let ack_loss = self.lateral(b, a)[at];
                let slot = self.slot(seeding::message_key(lateral_key(a, b), m), false, k);
                slot_fate(&link, loss, slot, arq(ack_loss))
            }
        }
    }

    /// The generator of slot `k` of key `key`.
    fn slot(
        &self,
        key: usize,
        down: bool,
        k: usize,
    ) -> impl FnOnce() -> rand_xoshiro::Xoshiro256PlusPlus {
        let (seed, trial) = (self.seed, self.trial);
        move || seeding::slot_rng(seed, trial, key, k, down)
    }

    /// The loss per step of the lateral link from `a` to `b` (drawn at its first use).
    fn lateral(&mut self, a: usize, b: usize) -> &[f64] {
        if !self.lateral_loss.contains_key(&(a, b)) {
            let c = self.channel(a, b).expect("a linked pair").clone();
            let slots = seeding::sensor_slots(self.seed, self.trial, lateral_key(a, b), false);
            let path = loss_path(&c, self.steps, slots);
            self.lateral_loss.insert((a, b), path);
        }
        &self.lateral_loss[&(a, b)]
    }
}
