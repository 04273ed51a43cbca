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
    /// (Dormann et al.: the globalized covariance is common to all sensors).
    Estimate(Vector),
    /// An encoded frame, exactly the octets a radio sends (Zhang et al.'s (2016) 802.15.4 codecs), with
    /// the paper's payload bits c_i.
    Frame { octets: Vec<u8>, payload_bits: u32 },
}

impl Message {
    /// Payload bits of this message: 32 per component unless a codec defines its own.
    pub fn bits(&self) -> u64 {
        match self {
            Message::Measurement(z) => z.len() as u64 * BITS_PER_COMPONENT,
            Message::Estimate(x) => x.len() as u64 * BITS_PER_COMPONENT,
            Message::Frame { payload_bits, .. } => u64::from(*payload_bits),
        }
    }

    /// Bits of the whole IEEE 802.15.4 MAC frame (MPDU) that carries the message: the MAC
    /// header and footer of [`crate::link::codec802154`] (9 + 2 octets) around the payload in
    /// whole octets. A codec's frame is counted as it is. A real radio pays for this, not for
    /// the payload alone.
    pub fn frame_bits(&self) -> u64 {
        match self {
            Message::Frame { octets, .. } => 8 * octets.len() as u64,
            other => crate::link::codec802154::mpdu_bits_for_payload(other.bits()),
        }
    }

    /// Payload bits of this message carrying a `sequence_bits`-bit sequence number: the
    /// message's own bits plus the sequence number's. With 0 bits, [`Message::bits`].
    pub fn bits_with_sequence(&self, sequence_bits: u32) -> u64 {
        self.bits() + u64::from(sequence_bits)
    }

    /// Bits of the 802.15.4 MAC frame that carries this message and a `sequence_bits`-bit
    /// sequence number: the frame of the larger payload
    /// ([`crate::link::codec802154::mpdu_bits_for_payload`] of [`Message::bits_with_sequence`]),
    /// so the number costs a whole octet only when the payload no longer fits its octets. A
    /// codec's frame has no spare payload bits to lend (the dynamic codec fills its payload
    /// octet's high bits with the zone layout, and the decoders reject non-zero padding), so its
    /// sequence number takes octets of its own after the codec's payload. With 0 bits,
    /// [`Message::frame_bits`], bit for bit.
    pub fn frame_bits_with_sequence(&self, sequence_bits: u32) -> u64 {
        if sequence_bits == 0 {
            return self.frame_bits();
        }
        let b = u64::from(sequence_bits);
        match self {
            Message::Frame { octets, .. } => 8 * (octets.len() as u64 + b.div_ceil(8)),
            other => crate::link::codec802154::mpdu_bits_for_payload(other.bits() + b),
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
    /// Frame octets arrived; the fusion center decodes them (and rejects corrupt ones).
    Frame(Vec<u8>),
}

/// How real numbers cross the network: as IEEE 754 singles (the default, 32 bits per component,
/// [`BITS_PER_COMPONENT`]), or as doubles (`reals = "f64"` in a scenario, 64 bits per
/// component) for the papers whose analysis assumes real-valued delivery, where the rounding
/// of a single would be a noise of its own (an unstable plant whose state grows to 1e10, where
/// a single's step is about 1000).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reals {
    #[default]
    F32,
    F64,
}

impl Reals {
    /// Bits per component beyond the [`BITS_PER_COMPONENT`] that [`Message::bits`] counts.
    pub fn extra_bits(self) -> u64 {
        match self {
            Reals::F32 => 0,
            Reals::F64 => 64 - BITS_PER_COMPONENT,
        }
    }

    pub fn is_f32(&self) -> bool {
        *self == Reals::F32
    }
}

/// A real number as it crosses the network: the IEEE 754 single that
/// [`BITS_PER_COMPONENT`] prices, read back as an f64 (round to nearest, ties to even). A
/// message priced at 32 bits per component must not deliver the 53-bit mantissa it was not
/// charged for, and a sensor and a center in separate processes exchanging real frames
/// receive exactly this.
///
/// A finite value beyond the single range (|x| > `f32::MAX`, about 3.4e38, after rounding)
/// becomes ±infinity, as the single on the wire would be, and NaN stays NaN. The conversion
/// stays infallible: a center then sees a non-finite component exactly as a live one would
/// decode it, and rejects it as it rejects any non-finite measurement or estimate, at the
/// step it arrives (see the tests). No model of this crate comes near that range.
#[inline]
pub fn as_sent(x: f64) -> f64 {
    x as f32 as f64
}

/// [`as_sent`] of every component, in place.
pub fn round_as_sent(v: &mut [f64]) {
    for x in v {
        *x = as_sent(*x);
    }
}

/// What crosses the network: measurements and estimates arrive as singles ([`as_sent`]),
/// frames as their octets.
impl From<Transmission> for Received {
    fn from(t: Transmission) -> Self {
        match t {
            Transmission::Silent => Received::Silent,
            Transmission::Send(Message::Measurement(mut z)) => {
                round_as_sent(z.as_mut_slice());
                Received::Measurement(z)
            }
            Transmission::Send(Message::Estimate(mut x)) => {
                round_as_sent(x.as_mut_slice());
                Received::Estimate(x)
            }
            Transmission::Send(Message::Frame { octets, .. }) => Received::Frame(octets),
        }
    }
}
