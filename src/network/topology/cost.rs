//! What a report costs on its way to the sink: every hop sends the frame (with its retries),
//! the next node receives it and acknowledges it, and a relay pays both for every frame it
//! forwards. The energy model is [`RadioSpec`]'s (the CC2420's currents; IEEE 802.15.4-2006
//! timing), applied per hop as `../shared/notes/decentralized.md` §4 derives it:
//!
//! - the sender pays each attempt `P_tx (b / R + t_ta)` (airtime and one turnaround);
//! - with ARQ it then listens for the acknowledgement: `P_rx (t_ta + 88 bits / R)` when the ACK
//!   comes, `P_rx · macAckWaitDuration` when it does not;
//! - the receiver pays `P_rx b / R` for the frame that arrives and, with ARQ,
//!   `P_tx (t_ta + 88 bits / R)` for its acknowledgement.
//!
//! Expected values at loss p per attempt and r retries: attempts `(1 − p^{r+1}) / (1 − p)`,
//! delivery `1 − p^{r+1}` (the ACKs taken as heard: their loss is the downlink's). A hop is only
//! tried if the previous ones delivered, so a node's expected energy per report is its hops'
//! costs weighted by the probability the frame got that far.
use super::Topology;
use crate::link::codec802154::ACK_PPDU_BITS;
use crate::network::channel::{Arq, ChannelSpec};
use crate::network::radio::RadioSpec;

/// One frame over one hop: expected energy at both ends, µJ, and the hop's odds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HopCost {
    /// The sender's energy: its attempts and, with ARQ, waiting for the acknowledgements.
    pub sender_uj: f64,
    /// The receiver's energy: the frame that arrives and, with ARQ, its acknowledgement.
    pub receiver_uj: f64,
    /// Expected attempts on air.
    pub attempts: f64,
    /// Probability that the frame crosses the hop.
    pub delivered: f64,
}

/// One frame of `ppdu_bits` bits on air (PHY header included) over a hop of `channel`.
pub fn hop(radio: &RadioSpec, ppdu_bits: f64, channel: &ChannelSpec) -> HopCost {
    let retries = channel.arq.map(|a| a.max_retries.min(Arq::MAX_RETRIES));
    let delivered = 1.0 - channel.delivery_loss();
    // The model's expectation (a Gilbert–Elliott hop retries in one state).
    let attempts = retries.map_or(1.0, |r| {
        (channel.kind.model().expected_attempts)(channel, r)
    });
    let frame_rx = radio.rx_uj(ppdu_bits);
    let ack_us = radio.turnaround_us + radio.airtime_us(ACK_PPDU_BITS as f64);
    let (sender_ack, receiver_ack) = match retries {
        None => (0.0, 0.0),
        Some(_) => {
            let heard = delivered * radio.rx_mw() * ack_us / 1000.0;
            let waited = (attempts - delivered) * radio.rx_mw() * radio.ack_wait_us / 1000.0;
            (heard + waited, delivered * radio.tx_mw() * ack_us / 1000.0)
        }
    };
    HopCost {
        sender_uj: attempts * radio.frame_tx_uj(ppdu_bits) + sender_ack,
        receiver_uj: delivered * frame_rx + receiver_ack,
        attempts,
        delivered,
    }
}

pub use crate::network::channel::models::expected_attempts;

/// Expected energy of every node, µJ, when every sensor sends one frame of `ppdu_bits` bits
/// to the sink along its route and relays forward each one as it is (no aggregation).
pub fn per_report(topology: &Topology, radio: &RadioSpec, ppdu_bits: f64) -> Vec<f64> {
    let mut energy = vec![0.0; topology.nodes.len()];
    for s in 0..topology.sensors() {
        let route = topology.route(s);
        let mut reach = 1.0;
        for (w, link) in route.windows(2).zip(topology.route_links(s)) {
            let c = hop(radio, ppdu_bits, &link.channel);
            energy[w[0]] += reach * c.sender_uj;
            energy[w[1]] += reach * c.receiver_uj;
            reach *= c.delivered;
        }
    }
    energy
}
