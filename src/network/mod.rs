//! Delivery between sensors and the fusion center. The network wraps every transmission and
//! counts messages and bits, so no scheme can forget to count.
use crate::link::{Received, Transmission};

/// Counters of one delivery round (one time step).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Traffic {
    /// Number of sensors that sent a message.
    pub messages: u64,
    /// Payload bits of those messages.
    pub bits: u64,
    /// Bits of the 802.15.4 MAC frames that carry them.
    pub frame_bits: u64,
    /// Bits the fusion center sent back to sensors (feedback).
    pub downlink_bits: u64,
}

/// Which sensors may talk at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Schedule {
    /// Every sensor may send at every step.
    #[default]
    All,
    /// Round-robin: at step k only sensor (k - 1) mod N may send (seed 002's protocol).
    RoundRobin,
}

impl Schedule {
    /// Whether sensor `i` of `n` may send at step `k` (k starts at 1).
    pub fn allows(self, k: usize, i: usize, n: usize) -> bool {
        match self {
            Schedule::All => true,
            Schedule::RoundRobin => (k.saturating_sub(1)) % n.max(1) == i,
        }
    }
}

/// Turns the sensors' transmissions into the fusion center's inbox and counts the traffic.
/// `inbox` is reused across steps so the loop does not allocate.
pub fn deliver(
    transmissions: impl IntoIterator<Item = Transmission>,
    inbox: &mut Vec<Received>,
) -> Traffic {
    inbox.clear();
    let mut traffic = Traffic::default();
    for t in transmissions {
        if let Transmission::Send(m) = &t {
            traffic.messages += 1;
            traffic.bits += m.bits();
            traffic.frame_bits += m.frame_bits();
        }
        inbox.push(t.into());
    }
    traffic
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Vector;
    use crate::link::Message;

    #[test]
    fn counts_messages_and_bits() {
        let tx = vec![
            Transmission::Silent,
            Transmission::Send(Message::Measurement(Vector::zeros(2))),
            Transmission::Send(Message::Estimate(Vector::zeros(6))),
        ];
        let mut inbox = Vec::new();
        let t = deliver(tx, &mut inbox);
        assert_eq!(t.messages, 2);
        assert_eq!(t.bits, 64 + 192);
        // (9 + 2) octets of MAC header and footer around 8 and 24 payload octets.
        assert_eq!(t.frame_bits, 8 * (11 + 8) + 8 * (11 + 24));
        assert_eq!(inbox[0], Received::Silent);
    }

    #[test]
    fn round_robin_lets_one_sensor_talk() {
        let s = Schedule::RoundRobin;
        assert!(s.allows(1, 0, 3) && s.allows(2, 1, 3) && s.allows(4, 0, 3));
        assert!(!s.allows(1, 1, 3));
    }
}
