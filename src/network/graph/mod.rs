//! Addressed messages over the network's graph, and the nodes that send them: the one
//! interface every estimator of a network implements, whether it fuses at a sink (the star's
//! schemes, through the adapter in [`crate::engine::star_nodes`]) or has no center at all
//! (consensus, diffusion, peer-to-peer fusion).
//!
//! A node ([`NetworkNode`]) runs a fixed number of rounds per step, declared by its protocol
//! (the star: feedback down, sense and report, fuse). In each round it reads what arrived
//! ([`Envelope`]s) and puts what it sends in its [`Outbox`], each message with an [`Address`]:
//! a neighbour or a node up the routing tree (a unicast, relayed hop by hop), every neighbour
//! (one broadcast frame), or its whole subtree (a frame down the tree, as the feedback goes).
//! The driver ([`driver::GraphDriver`]) draws every frame's fate ([`fates`]), prices it at the
//! sender and every receiver ([`crate::network::topology::tally`]) and delivers what survives
//! in the next round (what the last round of a step sends arrives in the first round of the
//! next; a delayed frame in the first round of the step it arrives at).
pub mod driver;
pub mod fates;

use crate::filter::Gaussian;
use crate::linalg::Vector;

/// Where a message goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Address {
    /// One node: a neighbour (one hop), or a node up the routing tree (the sink, a relay), the
    /// message relayed hop by hop, every hop a unicast frame with the link's acknowledgements
    /// and retries.
    Node(usize),
    /// Every neighbour: one broadcast frame, no acknowledgement, each neighbour's copy with its
    /// own fate.
    Neighbours,
    /// The sender's subtree of the routing tree: every node holding the message that has
    /// children sends it down in one frame (no acknowledgement), as the star's feedback goes.
    Down,
}

/// A message as it arrives.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope<P> {
    /// The node that wrote it.
    pub source: usize,
    /// The last node that sent it (its neighbour).
    pub sender: usize,
    pub destination: Address,
    /// Links it crossed.
    pub hops: u32,
    /// The step it was sent at.
    pub sent: usize,
    pub payload: P,
}

/// What a message costs on air: its MAC frame (header, payload, FCS) in bits; the PHY's
/// preamble and header are the driver's to add.
pub trait Payload {
    fn mac_bits(&self) -> u64;
}

/// What a node sends in one round.
#[derive(Debug)]
pub struct Outbox<P> {
    messages: Vec<(Address, P)>,
}

impl<P> Default for Outbox<P> {
    fn default() -> Self {
        Self {
            messages: Vec::new(),
        }
    }
}

impl<P> Outbox<P> {
    /// Sends `payload` to `to`.
    pub fn send(&mut self, to: Address, payload: P) {
        self.messages.push((to, payload));
    }

    fn drain(&mut self) -> std::vec::Drain<'_, (Address, P)> {
        self.messages.drain(..)
    }
}

/// Where a node is in the step when it runs a round.
#[derive(Debug, Clone, Copy)]
pub struct Round<'a> {
    /// The step, 1-based.
    pub k: usize,
    /// The round within the step, 0-based.
    pub round: usize,
    /// The node's reading at this step (a sensor with one).
    pub reading: Option<&'a Vector>,
}

/// A node of a network that estimates, relays or fuses.
pub trait NetworkNode<P> {
    /// One round: read `inbox` (what arrived since the last round), send into `out`.
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<P>],
        out: &mut Outbox<P>,
    ) -> Result<(), String>;

    /// Receive windows the node kept open in step `k` (its listening energy): the slots in
    /// which a neighbour may send to it, whether or not one did.
    fn windows(&self, k: usize) -> u64;

    /// The node's estimate after its last round, if it estimates.
    fn estimate(&self) -> Option<&Gaussian> {
        None
    }
}

#[cfg(test)]
mod tests;
