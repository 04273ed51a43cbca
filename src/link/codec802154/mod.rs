//! Real bits on an IEEE 802.15.4 link for quantized innovations: the dynamic transmission
//! strategy of Zhang, Li & Liu (Sci China Inf Sci 59:022316, 2016, "ZLL"), Tables 1-4, the
//! fixed-length codes of the baselines, and the paper's bandwidth tables 2, 4, 5, 6 (and the
//! `ρ` comparison of Table 7) as data a CLI can print.
//!
//! # Two measures of cost
//!
//! * **Payload bits `c_i`** (the paper's measure, Tables 1-6): flag-zone bits `a_i` plus
//!   quantization-zone bits `b_i`. Silence (the centre level) costs 0.
//! * **Frame bits**: what actually goes on air. An 802.15.4 payload is whole octets, so every
//!   non-silent message here is one 12-octet MPDU (96 bits) whatever `c_i` is, 18 octets
//!   (144 bits) with the PHY synchronization header and PHR. At the frame level the payload
//!   savings of Tables 5/6 therefore vanish; what saves energy is silence.
//!
//! # Frame format (every codec in this module)
//!
//! A minimal data frame of IEEE 802.15.4-2006 §7.2.2.2 (clause numbers of 802.15.4-2011 in
//! brackets, §5.2.x), multi-octet fields least significant octet first (§7.2 [§5.2]):
//!
//! | field | octets | clause | value |
//! |---|---|---|---|
//! | Frame Control | 2 | 7.2.1.1 [5.2.1.1] | [`FRAME_CONTROL`] = `0x8841`: data frame, no security, no frame pending, no ACK request, PAN ID compression, short destination and source addresses, frame version 0 (the 2003-compatible format, which 2006/2011 receivers accept; no 2006 feature is used) |
//! | Sequence Number | 1 | 7.2.1.2 [5.2.1.2] | caller's |
//! | Destination PAN Identifier | 2 | 7.2.1.3 [5.2.1.3] | the network's PAN id |
//! | Destination Address | 2 | 7.2.1.4 [5.2.1.4] | `0xffff` (broadcast) or the fusion centre's short address (peer-to-peer) |
//! | Source Address | 2 | 7.2.1.6 [5.2.1.6] | the sensor's short address (Source PAN id elided by the PAN ID Compression subfield of 7.2.1.1 \[5.2.1.1\]) |
//! | Frame Payload | 1 | 7.2.1.8 [5.2.1.8] | see the codecs |
//! | FCS | 2 | 7.2.1.9 [5.2.1.9] | ITU-T CRC-16 `x^16 + x^12 + x^5 + 1` over MHR and payload (= CRC-16/KERMIT: reflected, init 0, no final xor), low octet first |
//!
//! MHR = 9 octets, MFR = 2, MPDU = 12. Not part of the `Vec<u8>` but counted in
//! [`FrameCost::ppdu_bits`]: the PHY synchronization header and PHR of §6.3 (2006) for the
//! 2450 MHz O-QPSK PHY used by the paper's CC2430 testbed — Preamble 4 octets (§6.3.1),
//! SFD 1 octet (§6.3.2), PHR 1 octet (§6.3.3: 7-bit frame length + 1 reserved bit).
//!
//! **The transmission mode** of ZLL eq. (5) (broadcast vs peer-to-peer, "selected by changing a
//! parameter in the MAC header", Remark 1) is the Destination Address: the broadcast short
//! address `0xffff` (§7.2.1.4) or the fusion centre's address.
//!
//! **Where the zone lengths go.** ZLL §3.2 keeps the flag-zone length `a_i` in "reserved
//! zones" of the PHR/MHR and derives `c_i` from the payload length. Neither works as such: the
//! PHR has a single reserved bit, the Frame Control's reserved bits 7-9 of 2006/2011 were
//! given meanings by 802.15.4e-2012 (sequence-number suppression, IE present), and the
//! payload length is in octets, not bits. So the dynamic codec carries the zone layout
//! `(a_i, b_i)` in the 3 spare high bits of the single payload octet; since
//! `3 + c_i ≤ 6 ≤ 8` this costs no octet, i.e. it is as free on air as the paper assumes.
//!
//! # Decoding
//!
//! Decoders never panic and return a [`DecodeError`] for a frame of the wrong length, a bad
//! FCS, a non-data frame, any other frame-control value, a foreign PAN or destination, an
//! invalid source, a reserved or out-of-scheme layout, non-zero padding or an unused code.
//! Every accepted frame is canonical: re-encoding the decoded message gives the same octets.
//! The FCS detects every error pattern of up to 3 flipped bits and every burst of up to 16
//! bits in these 96-bit frames (the generator has the factor `x + 1` and Hamming distance 4
//! up to 32751 data bits); heavier random corruption slips through with probability ≈ 2^-16.
//!
//! # Layout of this module
//!
//! One file per kind of content, all re-exported here so every item keeps its path
//! `link::codec802154::X`: `frame` (the MAC frame both codecs write and read, the FCS, the
//! addressing, the cost of a message and the [`LevelCodec`] interface), `dynamic` (ZLL's
//! dynamic strategy: [`Strategy`], [`ZoneLayout`], [`ZoneCode`], [`DynamicCodec`]), `fixed`
//! (the baselines' [`FixedLengthCodec`] and their bit counts) and `tables` (the paper's Tables
//! 1-7 as data, derived from the codecs' own arithmetic). This file keeps the frame constants
//! and the error types they all share; the tests that run every codec against the frame format
//! are in `tests`.
mod dynamic;
mod fixed;
mod frame;
mod tables;
#[cfg(test)]
mod tests;

pub use dynamic::{DynamicCodec, Strategy, ZoneCode, ZoneLayout};
pub use fixed::{msechu_payload_bits, you_payload_bits, FixedLengthCodec};
pub use frame::{crc16_kermit, FrameCost, LevelCodec, LinkAddressing, Received};
pub use tables::{
    bandwidth_table, scheme_table, strategy_table, table_1, table_2, table_3, table_4, table_5,
    table_6, table_7, BandwidthRow, RhoRow, SchemeRow, StrategyRow,
};

/// Frame Control field length (§7.2.1.1).
pub const FRAME_CONTROL_OCTETS: usize = 2;
/// Sequence Number field length (§7.2.1.2).
pub const SEQUENCE_NUMBER_OCTETS: usize = 1;
/// Addressing fields: Destination PAN id 2 (§7.2.1.3) + Destination short address 2
/// (§7.2.1.4) + Source short address 2 (§7.2.1.6); Source PAN id elided (PAN ID compression).
pub const ADDRESSING_OCTETS: usize = 6;
/// MAC header.
pub const MHR_OCTETS: usize = FRAME_CONTROL_OCTETS + SEQUENCE_NUMBER_OCTETS + ADDRESSING_OCTETS;
/// MAC payload: one octet carries every message of this module (`c_i ≤ 3` plus the 3-bit
/// layout for the dynamic codec, `≤ 8` bits for the fixed-length ones).
pub const PAYLOAD_OCTETS: usize = 1;
/// MAC footer: the FCS (§7.2.1.9).
pub const FCS_OCTETS: usize = 2;
/// Whole MAC frame (MPDU = PSDU), the value of the PHR's Frame Length.
pub const MPDU_OCTETS: usize = MHR_OCTETS + PAYLOAD_OCTETS + FCS_OCTETS;
/// PHY preamble, 2450 MHz O-QPSK (§6.3.1, 2006).
pub const PREAMBLE_OCTETS: usize = 4;
/// Start-of-frame delimiter (§6.3.2, 2006).
pub const SFD_OCTETS: usize = 1;
/// PHY header: Frame Length (7 bits) + reserved bit (§6.3.3, 2006).
pub const PHR_OCTETS: usize = 1;
/// Whole PHY packet.
pub const PPDU_OCTETS: usize = PREAMBLE_OCTETS + SFD_OCTETS + PHR_OCTETS + MPDU_OCTETS;
/// Acknowledgment frame (§7.2.2.3 [§5.2.2.3], the immediate acknowledgement of a data frame
/// with its ACK Request subfield set): Frame Control 2 (frame type 010) + Sequence Number 1
/// (copied from the acknowledged frame) + FCS 2; no addressing fields, no payload.
pub const ACK_MPDU_OCTETS: usize = FRAME_CONTROL_OCTETS + SEQUENCE_NUMBER_OCTETS + FCS_OCTETS;
/// The acknowledgment frame on air: preamble, SFD and PHR (§6.3, 2450 MHz O-QPSK) around its
/// 5-octet MPDU = 11 octets.
pub const ACK_PPDU_OCTETS: usize = PREAMBLE_OCTETS + SFD_OCTETS + PHR_OCTETS + ACK_MPDU_OCTETS;
/// Bits of one acknowledgment on air ([`ACK_PPDU_OCTETS`] x 8 = 88), what the network's ARQ
/// counts per ACK (`crate::network::Traffic::ack_bits`).
pub const ACK_PPDU_BITS: u64 = 8 * ACK_PPDU_OCTETS as u64;
/// Largest MPDU of 802.15.4 (`aMaxPHYPacketSize`, 2006 §6.4.1), octets.
pub const MAX_MPDU_OCTETS: usize = 127;
/// The largest MAC payload of one frame: [`MAX_MPDU_OCTETS`] less the MAC header and FCS (116).
pub const MAX_PAYLOAD_OCTETS: usize = MAX_MPDU_OCTETS - MHR_OCTETS - FCS_OCTETS;
/// Bits of the 802.15.4 MAC frame (MPDU) around a payload of `payload_bits` bits: the MAC
/// header and footer ([`MHR_OCTETS`] + [`FCS_OCTETS`] = 11 octets) around the payload in whole
/// octets. Every message the network prices outside a codec's own frame, and every payload
/// enlarged by a sequence number (`crate::link::Message::frame_bits_with_sequence`), is
/// counted with it.
pub fn mpdu_bits_for_payload(payload_bits: u64) -> u64 {
    8 * (MHR_OCTETS + FCS_OCTETS) as u64 + 8 * payload_bits.div_ceil(8)
}
/// Broadcast short address / PAN id (§7.2.1.3, §7.2.1.4).
pub const BROADCAST: u16 = 0xffff;
/// Short address meaning "associated but no short address allocated" (`macShortAddress`,
/// MAC PIB, 2006 §7.4.2).
pub const NO_SHORT_ADDRESS: u16 = 0xfffe;
/// Frame Control value of every frame here: frame type 001 (data, bits 0-2), security 0
/// (bit 3), frame pending 0 (4), ACK request 0 (5; ZLL assume a loss-free link and
/// broadcasts cannot be acknowledged), PAN ID compression 1 (6), reserved 000 (7-9),
/// destination addressing mode 10 = short (10-11), frame version 00 (12-13), source
/// addressing mode 10 = short (14-15). On air: `41 88`.
pub const FRAME_CONTROL: u16 = 0x8841;

/// Why a codec could not be built or a level not encoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    /// `0xffff` is the broadcast PAN id, not a network's.
    #[error("PAN id 0xffff is the broadcast PAN id")]
    BroadcastPan,
    /// `0xffff` / `0xfffe` cannot address one device.
    #[error("{0:#06x} is not a unicast short address")]
    InvalidAddress(u16),
    /// The level does not exist in this codec's quantizer.
    #[error("level {level} out of range for {levels} levels")]
    LevelOutOfRange {
        /// Offending level index.
        level: usize,
        /// Levels of the codec.
        levels: usize,
    },
    /// Payload-bit budget not supported.
    #[error("unsupported payload bit budget {0}")]
    UnsupportedBits(u8),
    /// Number of levels not supported by a fixed-length code.
    #[error("unsupported number of levels {0}")]
    UnsupportedLevels(usize),
}

/// Why a frame was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Truncated or extended frame.
    #[error("frame has {got} octets, expected {expected}")]
    WrongLength {
        /// [`MPDU_OCTETS`].
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// FCS mismatch: the frame was corrupted.
    #[error("bad FCS: computed {computed:#06x}, received {received:#06x}")]
    BadFcs {
        /// CRC of the received MHR and payload.
        computed: u16,
        /// FCS field.
        received: u16,
    },
    /// Frame type other than data (001).
    #[error("frame type {frame_type} is not a data frame")]
    NotADataFrame {
        /// Frame Type subfield.
        frame_type: u8,
    },
    /// A data frame with other options (security, addressing modes, version, …).
    #[error("unsupported frame control {0:#06x}")]
    UnsupportedFrameControl(u16),
    /// Destination PAN is not ours.
    #[error("destination PAN {0:#06x} is not ours")]
    WrongPan(u16),
    /// Destination neither broadcast nor the fusion centre.
    #[error("destination {0:#06x} is neither broadcast nor the fusion centre")]
    NotForUs(u16),
    /// Source is the broadcast address or "no short address".
    #[error("invalid source address {0:#06x}")]
    InvalidSource(u16),
    /// A broadcast frame for a codec that only sends peer-to-peer.
    #[error("this codec never broadcasts")]
    UnexpectedBroadcast,
    /// Zone-layout code 6 or 7.
    #[error("reserved zone-layout code {0}")]
    ReservedLayout(u8),
    /// A layout that this codec's strategy or bit budget never uses.
    #[error("layout a={flag_bits}, b={quant_bits} not used by this codec")]
    LayoutNotInScheme {
        /// Flag-zone bits.
        flag_bits: u8,
        /// Quantization-zone bits.
        quant_bits: u8,
    },
    /// Padding bits after the code are not zero.
    #[error("non-zero padding in payload octet {0:#04x}")]
    NonZeroPadding(u8),
    /// A code that maps to no level.
    #[error("payload octet {0:#04x} encodes no level")]
    UnusedCode(u8),
}
