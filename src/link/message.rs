//! Messages a sensor sends, what the fusion center finds in its inbox, and the bit cost of each.
use crate::linalg::Vector;

/// Bits of one real-valued component on the wire unless a scheme defines its own codec:
/// an IEEE 754 single-precision float. Sending measurements and sending estimates are then
/// priced on the same axis.
pub const BITS_PER_COMPONENT: u64 = 32;

/// What a sensor puts on the network.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// A raw measurement z.
    Measurement(Vector),
    /// A local (possibly globalized) state estimate. The covariance is not sent where it is a
    /// deterministic function of the model that the fusion center computes itself
    /// (seed 004: the globalized covariance is common to all sensors).
    Estimate(Vector),
}

impl Message {
    /// Payload bits of this message under the default codec (32 bits per component).
    pub fn bits(&self) -> u64 {
        match self {
            Message::Measurement(z) => z.len() as u64 * BITS_PER_COMPONENT,
            Message::Estimate(x) => x.len() as u64 * BITS_PER_COMPONENT,
        }
    }
}

/// A sensor's decision at one step.
#[derive(Debug, Clone, PartialEq)]
pub enum Transmission {
    /// The sensor stays silent. Silence is data: the fusion center knows the rule that made it.
    Silent,
    /// The sensor sends a message.
    Send(Message),
}

/// What the fusion center knows about one sensor at one step. Never a NaN: every case of
/// "nothing arrived" is its own variant.
#[derive(Debug, Clone, PartialEq)]
pub enum Received {
    /// The sensor was scheduled and chose not to send.
    Silent,
    /// The sensor was not scheduled by the network (e.g. round-robin) and could not send.
    NotScheduled,
    /// A measurement arrived.
    Measurement(Vector),
    /// A state estimate arrived.
    Estimate(Vector),
}

impl From<Transmission> for Received {
    fn from(t: Transmission) -> Self {
        match t {
            Transmission::Silent => Received::Silent,
            Transmission::Send(Message::Measurement(z)) => Received::Measurement(z),
            Transmission::Send(Message::Estimate(x)) => Received::Estimate(x),
        }
    }
}
