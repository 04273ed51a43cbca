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
    /// Per node: (neighbour, link index), by neighbour.
    adjacency: Vec<Vec<(usize, usize)>>,
    channels: Vec<ChannelSpec>,
    /// Per node: the loss per step of its uplink (to its parent); empty for the sink.
    up_loss: Vec<Vec<f64>>,
    /// Per node: the loss per step of its downlink (from its parent): frames sent down, ACKs of
    /// its own frames.
    down_loss: Vec<Vec<f64>>,
    /// Per directed link ([`directed`]): its loss per step when it lies outside the tree
    /// (drawn at its first use).
    lateral_loss: Vec<Option<Vec<f64>>>,
    /// Per directed link: frames already sent over it this step, per source (a short list: one
    /// source for a broadcast, those relayed for a unicast).
    sent: Vec<Vec<(usize, u64)>>,
    /// The directed links with frames this step (the entries of `sent` to clear).
    touched: Vec<usize>,
    step: usize,
}

/// The index of link `j` taken from `a` to `b`: even from its lower node to its higher one, odd
/// back.
fn directed(j: usize, a: usize, b: usize) -> usize {
    2 * j + usize::from(a > b)
}

impl GraphFates {
    /// The fates of trial `trial` of a run seeded `seed` over `steps` steps on `net`.
    pub fn new(net: &Topology, steps: usize, seed: u64, trial: u64) -> Self {
        let nodes = net.nodes.len();
        let mut adjacency = vec![Vec::new(); nodes];
        for (j, l) in net.links.iter().enumerate() {
            adjacency[l.a].push((l.b, j));
            adjacency[l.b].push((l.a, j));
        }
        for list in &mut adjacency {
            list.sort_unstable();
        }
        let link_of = |a: usize, b: usize| {
            adjacency[a]
                .iter()
                .find(|(n, _)| *n == b)
                .map(|&(_, j)| j)
                .expect("a parent is linked")
        };
        let channels: Vec<_> = net.links.iter().map(|l| l.channel.clone()).collect();
        let slots = |key: usize, down: bool| seeding::sensor_slots(seed, trial, key, down);
        let mut up_loss = vec![Vec::new(); nodes];
        let mut down_loss = vec![Vec::new(); nodes];
        for n in 0..nodes {
            if let Some(p) = net.parent[n] {
                let c = &channels[link_of(n, p)];
                up_loss[n] = loss_path(c, steps, slots(n, false));
                down_loss[n] = loss_path(&c.downlink_spec(), steps, slots(n, true));
            }
        }
        Self {
            seed,
            trial,
            steps,
            parent: net.parent.clone(),
            lateral_loss: vec![None; 2 * channels.len()],
            sent: vec![Vec::new(); 2 * channels.len()],
            touched: Vec::new(),
            adjacency,
            channels,
            up_loss,
            down_loss,
            step: 0,
        }
    }

    /// The channel of the link between `a` and `b`, if they are linked.
    pub fn channel(&self, a: usize, b: usize) -> Option<&ChannelSpec> {
        self.link(a, b).map(|j| &self.channels[j])
    }

    /// The index of the link between `a` and `b`, if they are linked.
    fn link(&self, a: usize, b: usize) -> Option<usize> {
        self.adjacency
            .get(a)?
            .iter()
            .find(|(n, _)| *n == b)
            .map(|&(_, j)| j)
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
    fn next_index(&mut self, k: usize, d: usize, source: usize) -> u64 {
        if self.step != k {
            for t in self.touched.drain(..) {
                self.sent[t].clear();
            }
            self.step = k;
        }
        let list = &mut self.sent[d];
        if list.is_empty() {
            self.touched.push(d);
        }
        match list.iter_mut().find(|(s, _)| *s == source) {
            Some((_, m)) => {
                *m += 1;
                *m - 1
            }
            None => {
                list.push((source, 1));
                0
            }
        }
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
        let j = self.link(a, b).expect("a frame crosses a link");
        let m = self.next_index(k, directed(j, a, b), source);
        let at = k - 1;
        let direction = self.direction(a, b);
        let (loss, ack_loss) = match direction {
            Direction::Lateral => (self.lateral(j, a, b)[at], self.lateral(j, b, a)[at]),
            _ => (0.0, 0.0),
        };
        let link = &self.channels[j];
        let arq = |ack_loss: f64| {
            link.arq
                .filter(|_| acknowledged)
                .map(|a| (a.max_retries.min(Arq::MAX_RETRIES), ack_loss))
        };
        match direction {
            Direction::Up => {
                let base = if source == a {
                    a
                } else {
                    forward_key(a, source)
                };
                let slot = self.slot(seeding::message_key(base, m), false, k);
                slot_fate(link, self.up_loss[a][at], slot, arq(self.down_loss[a][at]))
            }
            Direction::Down => {
                let spec = link.downlink_spec();
                let slot = self.slot(seeding::message_key(b, m), true, k);
                slot_fate(&spec, self.down_loss[b][at], slot, arq(self.up_loss[b][at]))
            }
            Direction::Lateral => {
                let slot = self.slot(seeding::message_key(lateral_key(a, b), m), false, k);
                slot_fate(link, loss, slot, arq(ack_loss))
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

    /// The loss per step of link `j` outside the tree taken from `a` to `b` (drawn at its
    /// first use).
    fn lateral(&mut self, j: usize, a: usize, b: usize) -> &[f64] {
        let d = directed(j, a, b);
        if self.lateral_loss[d].is_none() {
            let slots = seeding::sensor_slots(self.seed, self.trial, lateral_key(a, b), false);
            self.lateral_loss[d] = Some(loss_path(&self.channels[j], self.steps, slots));
        }
        self.lateral_loss[d].as_deref().expect("drawn above")
    }
}
