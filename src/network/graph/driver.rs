//! The graph driver: runs a network's nodes round by round, carries their addressed messages
//! over the links, draws each frame's fate ([`super::fates`]) and prices it at the sender and
//! every receiver ([`Tally`]): the one place where the graph's delivery rules live.
//!
//! - A unicast ([`Address::Node`]) to a neighbour is one hop; to a node up the routing tree it
//!   is relayed hop by hop (the relays' frames counted as forwarded), each hop with the link's
//!   acknowledgements and retries; lost on any hop, the hops after it are not tried; the hops'
//!   delays add.
//! - A broadcast ([`Address::Neighbours`]) is one frame on air, each neighbour receiving its
//!   copy when its own fate keeps it; no acknowledgement.
//! - A frame down the tree ([`Address::Down`]) is sent once by every node of the sender's
//!   subtree that holds it and has children; a child hears the frame when its parent sent it
//!   and holds it when its own link kept it. Its delay is not modelled (as the star's feedback).
//! - Each node keeps its receiver on for the windows it declares ([`NetworkNode::windows`]).
use super::fates::GraphFates;
use super::{Address, Envelope, NetworkNode, Outbox, Payload, Round};
use crate::linalg::Vector;
use crate::network::topology::tally::{NodeCounts, Tally};
use crate::network::topology::Topology;

/// Runs the nodes of one trial over a network.
pub struct GraphDriver<P> {
    fates: GraphFates,
    tally: Tally,
    rounds: usize,
    names: Vec<String>,
    parent: Vec<Option<usize>>,
    children: Vec<Vec<usize>>,
    neighbours: Vec<Vec<usize>>,
    sensors: usize,
    /// What each node reads in the current round.
    inboxes: Vec<Vec<Envelope<P>>>,
    /// What arrives for the next round.
    next: Vec<Vec<Envelope<P>>>,
    /// Delayed messages: (step they arrive at, node, message).
    later: Vec<(usize, usize, Envelope<P>)>,
    out: Outbox<P>,
    done: usize,
    /// Work lists of a broadcast: the neighbours that heard it (with their delays), by index.
    heard: Vec<(usize, u32)>,
    receivers: Vec<usize>,
}

impl<P: Payload + Clone> GraphDriver<P> {
    /// The driver of trial `trial` of a run seeded `seed` of `steps` steps on `net`, its nodes
    /// running `rounds` rounds per step.
    pub fn new(net: &Topology, rounds: usize, steps: usize, seed: u64, trial: u64) -> Self {
        let n = net.nodes.len();
        let mut children = vec![Vec::new(); n];
        for (c, p) in net.parent.iter().enumerate() {
            if let Some(p) = p {
                children[*p].push(c);
            }
        }
        let neighbours: Vec<Vec<usize>> = (0..n).map(|i| net.neighbours(i)).collect();
        Self {
            fates: GraphFates::new(net, steps, seed, trial),
            tally: Tally::new(net),
            rounds,
            names: net.nodes.iter().map(|x| x.name.clone()).collect(),
            parent: net.parent.clone(),
            children,
            neighbours,
            sensors: net.sensors(),
            inboxes: (0..n).map(|_| Vec::new()).collect(),
            next: (0..n).map(|_| Vec::new()).collect(),
            later: Vec::new(),
            out: Outbox::default(),
            done: 0,
            heard: Vec::new(),
            receivers: Vec::new(),
        }
    }

    /// Step `k` (1, 2, … in order): every round of every node, in node order within a round;
    /// `readings[i]` is sensor i's (`None`: it has none at this step). An error names the node,
    /// the step and the round.
    pub fn step(
        &mut self,
        k: usize,
        nodes: &mut [Box<dyn NetworkNode<P> + '_>],
        readings: &[Option<&Vector>],
    ) -> Result<(), String> {
        if k != self.done + 1 || nodes.len() != self.names.len() || readings.len() != self.sensors {
            return Err(format!(
                "step {k}: expected step {} with {} nodes and {} readings, got {} nodes and {} readings",
                self.done + 1,
                self.names.len(),
                self.sensors,
                nodes.len(),
                readings.len()
            ));
        }
        self.done = k;
        self.tally.start_step();
        let mut j = 0;
        while j < self.later.len() {
            if self.later[j].0 == k {
                let (_, n, env) = self.later.swap_remove(j);
                self.inboxes[n].push(env);
            } else {
                j += 1;
            }
        }
        for round in 0..self.rounds {
            for (n, node) in nodes.iter_mut().enumerate() {
                let at = Round {
                    k,
                    round,
                    reading: readings.get(n).copied().flatten(),
                };
                node.round(at, &self.inboxes[n], &mut self.out)
                    .map_err(|e| format!("node {}, step {k}, round {round}: {e}", self.names[n]))?;
                let mut out = std::mem::take(&mut self.out);
                for (to, payload) in out.drain() {
                    self.send(k, n, to, payload)?;
                }
                self.out = out;
            }
            for inbox in &mut self.inboxes {
                inbox.clear();
            }
            std::mem::swap(&mut self.inboxes, &mut self.next);
        }
        for (n, node) in nodes.iter().enumerate() {
            self.tally.listen(n, node.windows(k));
        }
        Ok(())
    }

    /// What every node did in the last step.
    pub fn counts(&self) -> &[NodeCounts] {
        self.tally.counts()
    }

    /// Node `from` sends `payload` to `to` at step `k`.
    fn send(&mut self, k: usize, from: usize, to: Address, payload: P) -> Result<(), String> {
        let envelope = |sender: usize, hops: u32, payload: P| Envelope {
            source: from,
            sender,
            destination: to,
            hops,
            sent: k,
            payload,
        };
        let bits = payload.mac_bits();
        match to {
            Address::Node(d) => {
                let path = self.path(from, d)?;
                let mut delay = 0u32;
                for (h, &(a, b)) in path.iter().enumerate() {
                    let arq = self.fates.channel(a, b).is_some_and(|c| c.arq.is_some());
                    let f = self.fates.frame(k, a, b, from, true);
                    if !self.tally.frame(a, b, &f, bits, arq, h > 0) {
                        return Ok(());
                    }
                    delay = delay.saturating_add(f.delay);
                }
                let last = path.last().map_or(from, |&(a, _)| a);
                self.deliver(k, d, delay, envelope(last, path.len() as u32, payload));
            }
            Address::Neighbours => {
                // The work lists are kept from call to call (a consensus step broadcasts L
                // times from every node).
                let (mut heard, mut receivers) = (
                    std::mem::take(&mut self.heard),
                    std::mem::take(&mut self.receivers),
                );
                heard.clear();
                for &b in &self.neighbours[from] {
                    let f = self.fates.frame(k, from, b, from, false);
                    if !f.lost {
                        heard.push((b, f.delay));
                    }
                }
                receivers.clear();
                receivers.extend(heard.iter().map(|&(b, _)| b));
                self.tally.broadcast(from, &receivers, bits);
                // Every receiver but the last gets a copy; the last gets the payload itself.
                let mut payload = Some(payload);
                for (i, &(b, delay)) in heard.iter().enumerate() {
                    let p = match i + 1 == heard.len() {
                        true => payload.take().expect("the last receiver's"),
                        false => payload.clone().expect("kept for the last receiver"),
                    };
                    self.deliver(k, b, delay, envelope(from, 1, p));
                }
                (self.heard, self.receivers) = (heard, receivers);
            }
            Address::Down => {
                let ppdu = self.tally.ppdu(bits);
                let mut holders = vec![(from, 0u32)];
                while let Some((m, depth)) = holders.pop() {
                    if self.children[m].is_empty() {
                        continue;
                    }
                    self.tally.down_sent(m, ppdu);
                    for j in 0..self.children[m].len() {
                        let c = self.children[m][j];
                        self.tally.down_heard(c, ppdu);
                        if !self.fates.frame(k, m, c, from, false).lost {
                            self.next[c].push(envelope(m, depth + 1, payload.clone()));
                            holders.push((c, depth + 1));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The links a unicast from `from` to `to` crosses: one when they are neighbours, else the
    /// routing tree's from `from` up to `to`.
    fn path(&self, from: usize, to: usize) -> Result<Vec<(usize, usize)>, String> {
        let no_route = || {
            format!(
                "no route from {} to {}: it is neither a neighbour nor up the routing tree",
                self.names[from],
                self.names.get(to).map_or("an unknown node", |s| s.as_str())
            )
        };
        if to >= self.names.len() || to == from {
            return Err(no_route());
        }
        if self.neighbours[from].binary_search(&to).is_ok() {
            return Ok(vec![(from, to)]);
        }
        let mut path = Vec::new();
        let mut m = from;
        while m != to {
            let p = self.parent[m].ok_or_else(no_route)?;
            path.push((m, p));
            m = p;
        }
        Ok(path)
    }

    /// A message reaching node `n`: in the next round, or `delay` steps later.
    fn deliver(&mut self, k: usize, n: usize, delay: u32, env: Envelope<P>) {
        if delay == 0 {
            self.next[n].push(env);
        } else {
            self.later.push((k + delay as usize, n, env));
        }
    }
}
