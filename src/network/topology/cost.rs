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
use crate::network::channel::{Arq, ChannelKind, ChannelSpec};
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

/// The loss of one attempt on `channel` in the long run (a Gilbert–Elliott link at its
/// stationary state, without retries).
fn attempt_loss(channel: &ChannelSpec) -> f64 {
    ChannelSpec {
        arq: None,
        ..channel.clone()
    }
    .delivery_loss()
}

/// One frame of `ppdu_bits` bits on air (PHY header included) over a hop of `channel`.
pub fn hop(radio: &RadioSpec, ppdu_bits: f64, channel: &ChannelSpec) -> HopCost {
    let p = attempt_loss(channel);
    let retries = channel.arq.map(|a| a.max_retries.min(Arq::MAX_RETRIES));
    let delivered = 1.0 - channel.delivery_loss();
    // A Gilbert–Elliott hop retries in one state: attempts from the two states' losses.
    let attempts = match (retries, channel.kind) {
        (None, _) => 1.0,
        (Some(r), ChannelKind::GilbertElliott) => {
            let (gb, bg) = (channel.p_gb.unwrap_or(0.0), channel.p_bg.unwrap_or(0.0));
            let bad = if gb + bg > 0.0 { gb / (gb + bg) } else { 0.0 };
            (1.0 - bad) * expected_attempts(channel.loss_good(), r)
                + bad * expected_attempts(channel.loss_bad(), r)
        }
        (Some(r), _) => expected_attempts(p, r),
    };
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

/// Expected attempts of a frame at loss `p` per attempt with `r` retries:
/// `Σ_{j=0}^{r} p^j = (1 − p^{r+1}) / (1 − p)`.
pub fn expected_attempts(p: f64, r: u32) -> f64 {
    (0..=r as i32).map(|j| p.powi(j)).sum()
}

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
