//! What every node of a multi-hop network does in a step, counted from the hops' fates
//! ([`crate::network::channel::route`]) as the trial loop runs: the frames it sends (its own
//! and those it forwards, every attempt), the frames it receives, the acknowledgements on both
//! sides, the feedback it passes down the tree and the windows it listens. Integers, summed over
//! trials and steps in [`crate::metrics::Sums::nodes`]; the energy is the radio model's
//! ([`crate::network::radio`]) applied to them ([`activity`]).
//!
//! The counting rules (`../shared/notes/decentralized.md` §4):
//! - each attempt of a hop is a frame on air at the sender (its PPDU: MAC frame and PHY
//!   header); each attempt that arrives is received by the next node;
//! - with ARQ the receiver acknowledges every attempt that arrives (an ACK frame sent), and the
//!   sender waits after every attempt, hearing the ACK when the hop delivered (as the star's
//!   model, [`crate::network::radio`], a delivered frame whose every ACK was lost is charged as
//!   heard);
//! - the hops after a loss are not tried;
//! - a node with children keeps its receiver on for a window (`listen_us`) per child per step,
//!   the slot in which that child may send (it cannot know whether it will);
//! - a step with feedback: every node holding it that has children sends it down in one frame
//!   (header and the whole payload, as on the star), every node but the sink listens for it
//!   (one window) and receives the frame when its parent sent it.
use super::Topology;
use crate::network::channel::route::Routes;
use crate::network::channel::Fate;
use crate::network::radio::{Activity, DOWNLINK_OVERHEAD_BITS, PHY_OVERHEAD_BITS};

/// Number of counters of a node.
pub const NODE_FIELDS: usize = 12;

/// The names of a node's counters, in order (`summary.json`'s `network.nodes[]`).
pub const NODE_COUNTERS: [&str; NODE_FIELDS] = [
    "frames_sent",
    "frame_bits_sent",
    "frames_received",
    "frame_bits_received",
    "acks_sent",
    "acks_heard",
    "ack_waits",
    "forwarded",
    "feedback_frames_sent",
    "feedback_bits_sent",
    "feedback_bits_received",
    "listens",
];

/// A node's counters ([`NODE_COUNTERS`]).
pub type NodeCounts = [u64; NODE_FIELDS];

const TX: usize = 0;
const TX_BITS: usize = 1;
const RX: usize = 2;
const RX_BITS: usize = 3;
const ACKS_SENT: usize = 4;
const ACKS_HEARD: usize = 5;
const ACK_WAITS: usize = 6;
const FORWARDED: usize = 7;
const FB_TX: usize = 8;
const FB_TX_BITS: usize = 9;
const FB_RX_BITS: usize = 10;
const LISTENS: usize = 11;

/// One step's counters of every node.
#[derive(Debug, Clone)]
pub struct Tally {
    counts: Vec<NodeCounts>,
    children: Vec<u64>,
    /// Bits 802.15.4 security adds to every data frame, and to the feedback's frame
    /// ([`Topology::security`]; 0 unsecured).
    secured: u64,
    secured_feedback: u64,
}

impl Tally {
    /// Counters for the nodes of `net`, all zero.
    pub fn new(net: &Topology) -> Self {
        Tally {
            counts: vec![[0; NODE_FIELDS]; net.nodes.len()],
            // One pass over the parents (a count per node would be O(nodes²) a trial).
            children: net
                .parent
                .iter()
                .flatten()
                .fold(vec![0; net.nodes.len()], |mut c, &p| {
                    c[p] += 1;
                    c
                }),
            secured: net.security.overhead_bits(),
            secured_feedback: net.security.feedback_overhead_bits(),
        }
    }

    /// Bits on air of a data frame whose MAC frame (header, payload, FCS) has `mac_bits` bits:
    /// the PHY header, and the auxiliary security header and MIC of a secured network.
    pub fn ppdu(&self, mac_bits: u64) -> u64 {
        mac_bits + PHY_OVERHEAD_BITS + self.secured
    }

    /// A new step: every counter back to zero.
    pub fn start_step(&mut self) {
        self.counts.fill([0; NODE_FIELDS]);
    }

    /// The report of sensor `source` (a MAC frame of `mac_bits` bits) over its route, whose
    /// hops met `hops`.
    pub fn report(&mut self, routes: &Routes, hops: &[Fate], source: usize, mac_bits: u64) {
        for (h, (&n, f)) in routes.senders[source].iter().zip(hops).enumerate() {
            if routes.uplinks[n].is_none() || !self.hop(routes, n, f, mac_bits, h > 0) {
                break;
            }
        }
    }

    /// One frame of `mac_bits` bits sent by node `n` to its parent, which met `f`; `forwarded`:
    /// whether it carries what other nodes sent. Returns whether it arrived.
    pub fn hop(
        &mut self,
        routes: &Routes,
        n: usize,
        f: &Fate,
        mac_bits: u64,
        forwarded: bool,
    ) -> bool {
        let Some((parent, channel)) = &routes.uplinks[n] else {
            return false;
        };
        self.frame(n, *parent, f, mac_bits, channel.arq.is_some(), forwarded)
    }

    /// One unicast frame of `mac_bits` bits (MAC header, payload, FCS) from `sender` to
    /// `receiver`, whose attempts met `f`; `arq`: whether the link acknowledges and retries;
    /// `forwarded`: whether it carries what another node sent. Returns whether it arrived.
    pub fn frame(
        &mut self,
        sender: usize,
        receiver: usize,
        f: &Fate,
        mac_bits: u64,
        arq: bool,
        forwarded: bool,
    ) -> bool {
        let ppdu = self.ppdu(mac_bits);
        let attempts = u64::from(1 + f.retries);
        let arrived = if arq {
            u64::from(f.acks)
        } else {
            u64::from(!f.lost)
        };
        let c = &mut self.counts[sender];
        c[TX] += attempts;
        c[TX_BITS] += attempts * ppdu;
        c[FORWARDED] += u64::from(forwarded);
        if arq {
            c[ACK_WAITS] += attempts;
            c[ACKS_HEARD] += u64::from(!f.lost);
        }
        let p = &mut self.counts[receiver];
        p[RX] += arrived;
        p[RX_BITS] += arrived * ppdu;
        p[ACKS_SENT] += if arq { arrived } else { 0 };
        !f.lost
    }

    /// One broadcast frame of `mac_bits` bits from `sender` (no acknowledgement, no retry):
    /// one frame on air, received by each of `heard` (the neighbours whose fate kept it).
    pub fn broadcast(&mut self, sender: usize, heard: &[usize], mac_bits: u64) {
        let ppdu = self.ppdu(mac_bits);
        self.counts[sender][TX] += 1;
        self.counts[sender][TX_BITS] += ppdu;
        for &r in heard {
            self.counts[r][RX] += 1;
            self.counts[r][RX_BITS] += ppdu;
        }
    }

    /// [`Tally::broadcast`] `times` times over: the same counts, added at once (the consensus
    /// family's L identical broadcasts of a step on lossless links).
    pub fn broadcast_times(&mut self, sender: usize, heard: &[usize], mac_bits: u64, times: u64) {
        let ppdu = self.ppdu(mac_bits);
        self.counts[sender][TX] += times;
        self.counts[sender][TX_BITS] += times * ppdu;
        for &r in heard {
            self.counts[r][RX] += times;
            self.counts[r][RX_BITS] += times * ppdu;
        }
    }

    /// Node `n` sends one frame down the tree to its children (the feedback's frame, one for
    /// all of them), `ppdu_bits` on air.
    pub fn down_sent(&mut self, n: usize, ppdu_bits: u64) {
        self.counts[n][FB_TX] += 1;
        self.counts[n][FB_TX_BITS] += ppdu_bits;
    }

    /// Node `n` receives a frame its parent sent down (`ppdu_bits` on air; its receiver is on
    /// whether or not the frame survives).
    pub fn down_heard(&mut self, n: usize, ppdu_bits: u64) {
        self.counts[n][FB_RX_BITS] += ppdu_bits;
    }

    /// Node `n` keeps its receiver on for `windows` slots this step.
    pub fn listen(&mut self, n: usize, windows: u64) {
        self.counts[n][LISTENS] += windows;
    }

    /// The step's listening and its feedback of `payload_bits` (0: none) going down the tree;
    /// `holds(n)`: whether node n got it.
    pub fn feedback(&mut self, routes: &Routes, payload_bits: u64, holds: impl Fn(usize) -> bool) {
        let frame = DOWNLINK_OVERHEAD_BITS + payload_bits + self.secured_feedback;
        for n in 0..self.counts.len() {
            self.listen(n, self.children[n]);
            if payload_bits == 0 {
                continue;
            }
            if self.children[n] > 0 && holds(n) {
                self.down_sent(n, frame);
            }
            if let Some((parent, _)) = &routes.uplinks[n] {
                self.listen(n, 1);
                if holds(*parent) {
                    self.down_heard(n, frame);
                }
            }
        }
    }

    /// Every node's counters of this step.
    pub fn counts(&self) -> &[NodeCounts] {
        &self.counts
    }
}

/// What a node's radio did over `node_steps` steps (trials × steps) with `counts` summed over
/// them, for [`crate::network::radio::RadioSpec::energy`].
pub fn activity(counts: &NodeCounts, node_steps: f64) -> Activity {
    let f = |i: usize| counts[i] as f64;
    Activity {
        sensor_steps: node_steps,
        frames: f(TX),
        frame_ppdu_bits: f(TX_BITS),
        ack_waits: f(ACK_WAITS),
        acks_heard: f(ACKS_HEARD),
        listens: f(LISTENS),
        downlink_rx_bits: f(FB_RX_BITS),
        rx_ppdu_bits: f(RX_BITS),
        acks_sent: f(ACKS_SENT),
        downlink_tx_frames: f(FB_TX),
        downlink_tx_bits: f(FB_TX_BITS),
    }
}

/// Data frames a node put on air (every attempt) and their bits on air (PPDU), from its
/// counters.
pub fn sent(counts: &NodeCounts) -> (u64, u64) {
    (counts[TX], counts[TX_BITS])
}

/// Frames a node sent (every attempt, its own and forwarded) and received, from its counters.
pub fn frames(counts: &NodeCounts) -> (u64, u64, u64) {
    (counts[TX], counts[RX], counts[FORWARDED])
}
