//! What crosses the network: transmissions, messages and their bit cost, sensor-side
//! quantizers and the codecs that turn a message into real bits and back.
pub mod codec802154;
pub mod message;
pub mod quantizer;
pub mod security;

pub use message::{
    as_sent, round_as_sent, Message, Reals, Received, Transmission, BITS_PER_COMPONENT,
};
