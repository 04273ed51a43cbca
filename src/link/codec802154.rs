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

use crate::link::quantizer::{
    zhang_level, zhang_symbol, InnovationQuantizer, Level, MsechuQuantizer, QuantizerError, TxMode,
    YouQuantizer, ZhangQuantizer, ZhangSymbol,
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

/// The IEEE 802.15.4 FCS (§7.2.1.9): ITU-T CRC-16, generator `x^16 + x^12 + x^5 + 1`,
/// register initialized to 0, bits processed least significant first (the order they go on
/// air), no final inversion — the CRC-16/KERMIT parameter set. The FCS field is this value,
/// low octet first.
pub fn crc16_kermit(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &byte in data {
        crc ^= u16::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x8408 // 0x1021 bit-reversed
            } else {
                crc >> 1
            };
        }
    }
    crc
}

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

/// PAN and fusion-centre addresses shared by the sensors and the fusion centre.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkAddressing {
    pan_id: u16,
    coordinator: u16,
}

impl LinkAddressing {
    /// `pan_id` must not be the broadcast PAN id; `coordinator` (the fusion centre's short
    /// address) must be a unicast address.
    pub fn new(pan_id: u16, coordinator: u16) -> Result<Self, CodecError> {
        if pan_id == BROADCAST {
            return Err(CodecError::BroadcastPan);
        }
        check_unicast(coordinator)?;
        Ok(Self {
            pan_id,
            coordinator,
        })
    }

    /// PAN identifier.
    pub fn pan_id(&self) -> u16 {
        self.pan_id
    }

    /// Fusion centre's short address (destination of peer-to-peer frames).
    pub fn coordinator(&self) -> u16 {
        self.coordinator
    }
}

fn check_unicast(addr: u16) -> Result<(), CodecError> {
    if addr == BROADCAST || addr == NO_SHORT_ADDRESS {
        Err(CodecError::InvalidAddress(addr))
    } else {
        Ok(())
    }
}

/// A decoded message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The quantization level.
    pub level: Level,
    /// How it was sent (destination address).
    pub mode: TxMode,
    /// Sender's short address.
    pub source: u16,
    /// MAC sequence number.
    pub sequence: u8,
    /// The paper's payload bits `c_i` of this message.
    pub payload_bits: u8,
}

/// Cost of one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameCost {
    /// ZLL's `c_i` (flag + quantization zones); 0 when silent.
    pub payload_bits: u8,
    /// Octets of MAC payload on air (0 when silent).
    pub mac_payload_octets: usize,
    /// MPDU octets (MHR + payload + FCS; 0 when silent).
    pub mpdu_octets: usize,
    /// PPDU octets (preamble + SFD + PHR + MPDU; 0 when silent).
    pub ppdu_octets: usize,
}

impl FrameCost {
    /// Nothing sent.
    pub const SILENT: FrameCost = FrameCost {
        payload_bits: 0,
        mac_payload_octets: 0,
        mpdu_octets: 0,
        ppdu_octets: 0,
    };

    fn sent(payload_bits: u8) -> Self {
        FrameCost {
            payload_bits,
            mac_payload_octets: PAYLOAD_OCTETS,
            mpdu_octets: MPDU_OCTETS,
            ppdu_octets: PPDU_OCTETS,
        }
    }

    /// MAC frame bits.
    pub fn mpdu_bits(&self) -> usize {
        8 * self.mpdu_octets
    }

    /// Bits on air including the PHY synchronization header and PHR.
    pub fn ppdu_bits(&self) -> usize {
        8 * self.ppdu_octets
    }
}

/// A codec between quantization levels and 802.15.4 frames.
pub trait LevelCodec {
    /// Number of quantization levels `L` it carries.
    fn levels(&self) -> usize;

    /// Largest payload `c_i` over all levels.
    fn max_payload_bits(&self) -> u8;

    /// The paper's `c_i` for `level` (0 for the silent level).
    fn payload_bits(&self, level: Level) -> Result<u8, CodecError>;

    /// The frame for `level` from sensor `source`, or `None` if the level is silent.
    fn encode(
        &self,
        level: Level,
        source: u16,
        sequence: u8,
    ) -> Result<Option<Vec<u8>>, CodecError>;

    /// The message in `frame`; never panics.
    fn decode(&self, frame: &[u8]) -> Result<Received, DecodeError>;

    /// Payload and frame cost of sending `level`.
    fn cost(&self, level: Level) -> Result<FrameCost, CodecError> {
        Ok(match self.payload_bits(level)? {
            0 => FrameCost::SILENT,
            c => FrameCost::sent(c),
        })
    }
}

fn build_frame(link: &LinkAddressing, dst: u16, source: u16, sequence: u8, payload: u8) -> Vec<u8> {
    let mut f = Vec::with_capacity(MPDU_OCTETS);
    f.extend_from_slice(&FRAME_CONTROL.to_le_bytes());
    f.push(sequence);
    f.extend_from_slice(&link.pan_id.to_le_bytes());
    f.extend_from_slice(&dst.to_le_bytes());
    f.extend_from_slice(&source.to_le_bytes());
    f.push(payload);
    let fcs = crc16_kermit(&f);
    f.extend_from_slice(&fcs.to_le_bytes());
    debug_assert_eq!(f.len(), MPDU_OCTETS);
    f
}

/// Parsed MAC fields of one of our frames.
struct Parsed {
    mode: TxMode,
    source: u16,
    sequence: u8,
    payload: u8,
}

fn parse_frame(link: &LinkAddressing, frame: &[u8]) -> Result<Parsed, DecodeError> {
    if frame.len() != MPDU_OCTETS {
        return Err(DecodeError::WrongLength {
            expected: MPDU_OCTETS,
            got: frame.len(),
        });
    }
    let le = |i: usize| u16::from_le_bytes([frame[i], frame[i + 1]]);
    let body = MPDU_OCTETS - FCS_OCTETS;
    let computed = crc16_kermit(&frame[..body]);
    let received = le(body);
    if computed != received {
        return Err(DecodeError::BadFcs { computed, received });
    }
    let fc = le(0);
    let frame_type = (fc & 0b111) as u8;
    if frame_type != 0b001 {
        return Err(DecodeError::NotADataFrame { frame_type });
    }
    if fc != FRAME_CONTROL {
        return Err(DecodeError::UnsupportedFrameControl(fc));
    }
    let sequence = frame[2];
    let pan = le(3);
    if pan != link.pan_id {
        return Err(DecodeError::WrongPan(pan));
    }
    let dst = le(5);
    let mode = if dst == BROADCAST {
        TxMode::Broadcast
    } else if dst == link.coordinator {
        TxMode::PeerToPeer
    } else {
        return Err(DecodeError::NotForUs(dst));
    };
    let source = le(7);
    if check_unicast(source).is_err() {
        return Err(DecodeError::InvalidSource(source));
    }
    Ok(Parsed {
        mode,
        source,
        sequence,
        payload: frame[9],
    })
}

/// Which of ZLL's two dynamic transmission strategies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Strategy {
    /// Tables 1-2: flag zone + quantization zone.
    FlagZone,
    /// Tables 3-4: quantization zone only.
    NoFlagZone,
}

/// Bit lengths of the two payload zones of one message (ZLL Table 1: `a_i`, `b_i`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ZoneLayout {
    /// Flag-zone bits `a_i`.
    pub flag_bits: u8,
    /// Quantization-zone bits `b_i ≥ 1` (sign + offset within the group).
    pub quant_bits: u8,
}

impl ZoneLayout {
    /// `c_i = a_i + b_i`.
    pub fn payload_bits(self) -> u8 {
        self.flag_bits + self.quant_bits
    }

    /// 3-bit code carried in the payload octet: `c(c - 1)/2 + a` enumerates the layouts of
    /// `c = 1, 2, 3` as 0..=5; 6 and 7 are reserved.
    fn code(self) -> u8 {
        let c = self.payload_bits();
        c * (c - 1) / 2 + self.flag_bits
    }

    fn from_code(code: u8) -> Option<Self> {
        let (c, a) = match code {
            0 => (1, 0),
            1 | 2 => (2, code - 1),
            3..=5 => (3, code - 3),
            _ => return None,
        };
        Some(ZoneLayout {
            flag_bits: a,
            quant_bits: c - a,
        })
    }
}

/// Where magnitude `t` of eq. (5) sits in the payload: layout, flag-zone value and the
/// offset of `t` within its group (the quantization zone is `sign · 2^{b-1} + offset`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ZoneCode {
    /// Zone lengths.
    pub layout: ZoneLayout,
    /// Flag-zone value, `< 2^a`.
    pub flag: u8,
    /// Offset within the group, `< 2^{b-1}`.
    pub offset: u8,
}

/// Largest payload budget the zone arithmetic below handles (codes fit in a `u8`).
const MAX_ZONE_BITS: u8 = 8;

impl Strategy {
    /// Number of magnitudes `t` sent with exactly `c` payload bits: with a flag zone each
    /// `a = 0..c` gives `2^a` flags × `2^{c-a-1}` magnitudes (one quantization-zone bit is
    /// the sign), i.e. `c · 2^{c-1}` (1, 4, 12 for Table 1); without, `2^{c-1}` (1, 2, 4 for
    /// Table 3). Each magnitude stands for 4 levels `±λ_t^{b,p}`.
    pub fn magnitudes_with_bits(self, c: u8) -> usize {
        if c == 0 || c > 63 {
            return 0;
        }
        let half = 1usize << (c - 1);
        match self {
            Strategy::FlagZone => half.saturating_mul(usize::from(c)),
            Strategy::NoFlagZone => half,
        }
    }

    /// Magnitudes reachable with at most `c_max` payload bits, `l` of eq. (5)
    /// (Table 2: 1, 5, 17; Table 4: 1, 3, 7).
    pub fn max_magnitude(self, c_max: u8) -> usize {
        (1..=c_max).fold(0usize, |acc, c| {
            acc.saturating_add(self.magnitudes_with_bits(c))
        })
    }

    /// Levels `L = 4l + 1` with at most `c_max` payload bits (Table 2: 5, 21, 69;
    /// Table 4: 5, 13, 29).
    pub fn levels(self, c_max: u8) -> usize {
        self.max_magnitude(c_max)
            .saturating_mul(4)
            .saturating_add(1)
    }

    /// Smallest `c_max` whose scheme has at least `levels` levels (`levels = 4l + 1`);
    /// `None` if `levels` is not of that form. The Zhang column of Tables 5 and 6.
    pub fn payload_bits_for_levels(self, levels: usize) -> Option<u8> {
        if levels < 5 || levels % 4 != 1 {
            return None;
        }
        let l = (levels - 1) / 4;
        (1..=63u8).find(|&c| self.max_magnitude(c) >= l)
    }

    /// Payload position of magnitude `t ≥ 1`; `None` if it needs more than 8 bits.
    ///
    /// Groups are filled as in Tables 1 and 3: by payload length `c`, then flag length
    /// `a` (with a flag zone), then flag value, then magnitude.
    pub fn zone(self, t: usize) -> Option<ZoneCode> {
        if t == 0 {
            return None;
        }
        let mut start = 1;
        for c in 1..=MAX_ZONE_BITS {
            let n = self.magnitudes_with_bits(c);
            if t < start + n {
                let k = t - start;
                let half = 1usize << (c - 1);
                let (a, r) = match self {
                    Strategy::FlagZone => ((k / half) as u8, k % half),
                    Strategy::NoFlagZone => (0, k),
                };
                let b = c - a;
                let per_flag = 1usize << (b - 1);
                return Some(ZoneCode {
                    layout: ZoneLayout {
                        flag_bits: a,
                        quant_bits: b,
                    },
                    flag: (r / per_flag) as u8,
                    offset: (r % per_flag) as u8,
                });
            }
            start += n;
        }
        None
    }

    /// Inverse of [`zone`](Self::zone); `None` if the code is not one this strategy uses.
    pub fn magnitude(self, code: ZoneCode) -> Option<usize> {
        let ZoneLayout {
            flag_bits: a,
            quant_bits: b,
        } = code.layout;
        let c = a.checked_add(b)?;
        if b == 0 || c > MAX_ZONE_BITS {
            return None;
        }
        if self == Strategy::NoFlagZone && a != 0 {
            return None;
        }
        if usize::from(code.flag) >= 1 << a || usize::from(code.offset) >= 1 << (b - 1) {
            return None;
        }
        let start = 1 + self.max_magnitude(c - 1);
        let within = match self {
            Strategy::FlagZone => (usize::from(a) << (c - 1)) + (usize::from(code.flag) << (b - 1)),
            Strategy::NoFlagZone => 0,
        };
        Some(start + within + usize::from(code.offset))
    }
}

/// ZLL's dynamic transmission strategy (Tables 1-2 with [`Strategy::FlagZone`], Tables 3-4
/// with [`Strategy::NoFlagZone`]) for the `4l + 1`-level quantizer of eq. (5).
///
/// Payload octet, most significant bit first: 3-bit zone-layout code
/// ([`ZoneLayout`]), then the flag zone (`a_i` bits), then the quantization zone (`b_i`
/// bits: sign — 1 for negative — then the offset of `t` within its group), then zero
/// padding. Broadcast/peer-to-peer is the destination address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DynamicCodec {
    strategy: Strategy,
    max_bits: u8,
    l: u16,
    link: LinkAddressing,
}

impl DynamicCodec {
    /// Largest supported `c_max`: the paper's 3 (the 3-bit layout code has room for the 6
    /// layouts of `c ≤ 3` only).
    pub const MAX_PAYLOAD_BITS: u8 = 3;

    /// Codec with at most `max_payload_bits` (`1..=3`) payload bits per message.
    pub fn new(
        strategy: Strategy,
        max_payload_bits: u8,
        link: LinkAddressing,
    ) -> Result<Self, CodecError> {
        if !(1..=Self::MAX_PAYLOAD_BITS).contains(&max_payload_bits) {
            return Err(CodecError::UnsupportedBits(max_payload_bits));
        }
        Ok(Self {
            strategy,
            max_bits: max_payload_bits,
            // ≤ 17 by the check above.
            l: strategy.max_magnitude(max_payload_bits) as u16,
            link,
        })
    }

    /// The strategy.
    pub fn strategy(&self) -> Strategy {
        self.strategy
    }

    /// Magnitudes `l` of the matching quantizer.
    pub fn magnitudes(&self) -> u16 {
        self.l
    }

    /// The quantizer whose levels this codec carries.
    pub fn quantizer(&self) -> Result<ZhangQuantizer, QuantizerError> {
        ZhangQuantizer::new(self.l)
    }

    fn symbol(&self, level: Level) -> Result<Option<ZhangSymbol>, CodecError> {
        if level.index() >= self.levels() {
            return Err(CodecError::LevelOutOfRange {
                level: level.index(),
                levels: self.levels(),
            });
        }
        Ok(zhang_symbol(self.l, level))
    }

    fn zone_of(&self, symbol: ZhangSymbol) -> ZoneCode {
        self.strategy
            .zone(usize::from(symbol.magnitude))
            .expect("magnitudes up to l need at most c_max <= 3 bits")
    }
}

impl LevelCodec for DynamicCodec {
    fn levels(&self) -> usize {
        4 * usize::from(self.l) + 1
    }

    fn max_payload_bits(&self) -> u8 {
        self.max_bits
    }

    fn payload_bits(&self, level: Level) -> Result<u8, CodecError> {
        Ok(match self.symbol(level)? {
            None => 0,
            Some(s) => self.zone_of(s).layout.payload_bits(),
        })
    }

    fn encode(
        &self,
        level: Level,
        source: u16,
        sequence: u8,
    ) -> Result<Option<Vec<u8>>, CodecError> {
        check_unicast(source)?;
        let Some(symbol) = self.symbol(level)? else {
            return Ok(None); // d = 0: no transmission (ZLL §3.1)
        };
        let z = self.zone_of(symbol);
        let (a, b) = (z.layout.flag_bits, z.layout.quant_bits);
        let c = a + b;
        let quant = (u8::from(symbol.negative) << (b - 1)) | z.offset;
        let bits = (z.flag << b) | quant;
        let payload = (z.layout.code() << 5) | (bits << (5 - c));
        let dst = match symbol.mode {
            TxMode::Broadcast => BROADCAST,
            TxMode::PeerToPeer => self.link.coordinator,
        };
        Ok(Some(build_frame(
            &self.link, dst, source, sequence, payload,
        )))
    }

    fn decode(&self, frame: &[u8]) -> Result<Received, DecodeError> {
        let p = parse_frame(&self.link, frame)?;
        let code = p.payload >> 5;
        let layout = ZoneLayout::from_code(code).ok_or(DecodeError::ReservedLayout(code))?;
        let (a, b) = (layout.flag_bits, layout.quant_bits);
        let c = a + b;
        if c > self.max_bits || (self.strategy == Strategy::NoFlagZone && a != 0) {
            return Err(DecodeError::LayoutNotInScheme {
                flag_bits: a,
                quant_bits: b,
            });
        }
        let pad = 5 - c;
        if p.payload & ((1u8 << pad) - 1) != 0 {
            return Err(DecodeError::NonZeroPadding(p.payload));
        }
        let bits = (p.payload >> pad) & ((1u8 << c) - 1);
        let quant = bits & ((1u8 << b) - 1);
        let zone = ZoneCode {
            layout,
            flag: bits >> b,
            offset: quant & ((1u8 << (b - 1)) - 1),
        };
        let unused = DecodeError::UnusedCode(p.payload);
        let t = self.strategy.magnitude(zone).ok_or(unused.clone())?;
        let symbol = ZhangSymbol {
            magnitude: u16::try_from(t).map_err(|_| unused.clone())?,
            negative: quant >> (b - 1) == 1,
            mode: p.mode,
        };
        let level = zhang_level(self.l, symbol).ok_or(unused)?;
        Ok(Received {
            level,
            mode: p.mode,
            source: p.source,
            sequence: p.sequence,
            payload_bits: c,
        })
    }
}

fn ceil_log2(n: usize) -> u8 {
    if n <= 1 {
        0
    } else {
        (usize::BITS - (n - 1).leading_zeros()) as u8
    }
}

/// Bits Msechu et al.'s fixed-length code needs for `levels` levels: `⌈log2 L⌉` (ZLL §4.1
/// `L = 2^c`; Tables 5-6, Msechu column). `None` below 2 levels.
pub fn msechu_payload_bits(levels: usize) -> Option<u8> {
    (levels >= 2).then(|| ceil_log2(levels))
}

/// Bits You et al.'s code needs for `levels` levels, the centre one silent: `⌈log2 (L - 1)⌉`
/// (ZLL §4.1 `L = 2^c + 1`; Tables 5-6, You column). `None` below 3 levels.
pub fn you_payload_bits(levels: usize) -> Option<u8> {
    (levels >= 3).then(|| ceil_log2(levels - 1))
}

/// Fixed-length code for the baselines: every non-silent level is sent peer-to-peer as a
/// `⌈log2(#non-silent levels)⌉`-bit index, most significant bit first in the payload octet,
/// zero padding. SOI-KF: 2 levels, 1 bit; Msechu: `2^c` levels; You: `2^c + 1` levels with
/// the centre silent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FixedLengthCodec {
    levels: usize,
    silent: Option<usize>,
    bits: u8,
    link: LinkAddressing,
}

impl FixedLengthCodec {
    /// `levels` levels, the centre one silent if `silent_centre` (then `levels` must be
    /// odd); the non-silent levels must need between 1 and 8 bits.
    pub fn new(
        levels: usize,
        silent_centre: bool,
        link: LinkAddressing,
    ) -> Result<Self, CodecError> {
        if silent_centre && levels.is_multiple_of(2) {
            return Err(CodecError::UnsupportedLevels(levels));
        }
        let codes = levels - usize::from(silent_centre && levels > 0);
        if !(2..=256).contains(&codes) {
            return Err(CodecError::UnsupportedLevels(levels));
        }
        Ok(Self {
            levels,
            silent: silent_centre.then_some(levels / 2),
            bits: ceil_log2(codes),
            link,
        })
    }

    /// SOI-KF's sign code (1 bit).
    pub fn sign(link: LinkAddressing) -> Self {
        Self::new(2, false, link).expect("2 levels are supported")
    }

    /// Msechu et al.'s `c`-bit code for [`MsechuQuantizer`].
    pub fn msechu(bits: u8, link: LinkAddressing) -> Result<Self, CodecError> {
        if !(1..=8).contains(&bits) {
            return Err(CodecError::UnsupportedBits(bits));
        }
        Self::new(1 << bits, false, link)
    }

    /// You et al.'s `c`-bit code for [`YouQuantizer`].
    pub fn you(bits: u8, link: LinkAddressing) -> Result<Self, CodecError> {
        if !(1..=8).contains(&bits) {
            return Err(CodecError::UnsupportedBits(bits));
        }
        Self::new((1 << bits) + 1, true, link)
    }

    fn code_count(&self) -> usize {
        self.levels - usize::from(self.silent.is_some())
    }
}

impl LevelCodec for FixedLengthCodec {
    fn levels(&self) -> usize {
        self.levels
    }

    fn max_payload_bits(&self) -> u8 {
        self.bits
    }

    fn payload_bits(&self, level: Level) -> Result<u8, CodecError> {
        let i = level.index();
        if i >= self.levels {
            return Err(CodecError::LevelOutOfRange {
                level: i,
                levels: self.levels,
            });
        }
        Ok(if Some(i) == self.silent { 0 } else { self.bits })
    }

    fn encode(
        &self,
        level: Level,
        source: u16,
        sequence: u8,
    ) -> Result<Option<Vec<u8>>, CodecError> {
        check_unicast(source)?;
        if self.payload_bits(level)? == 0 {
            return Ok(None);
        }
        let i = level.index();
        let code = match self.silent {
            Some(s) if i > s => i - 1,
            _ => i,
        };
        // code < 256 and bits ≤ 8, so the shifted code fits the octet.
        let payload = ((code << (8 - self.bits)) & 0xff) as u8;
        let dst = self.link.coordinator;
        Ok(Some(build_frame(
            &self.link, dst, source, sequence, payload,
        )))
    }

    fn decode(&self, frame: &[u8]) -> Result<Received, DecodeError> {
        let p = parse_frame(&self.link, frame)?;
        if p.mode == TxMode::Broadcast {
            return Err(DecodeError::UnexpectedBroadcast);
        }
        let pad = 8 - u32::from(self.bits);
        let payload = u32::from(p.payload);
        if payload & ((1 << pad) - 1) != 0 {
            return Err(DecodeError::NonZeroPadding(p.payload));
        }
        let code = (payload >> pad) as usize;
        if code >= self.code_count() {
            return Err(DecodeError::UnusedCode(p.payload));
        }
        let i = match self.silent {
            Some(s) if code >= s => code + 1,
            _ => code,
        };
        Ok(Received {
            level: Level::new(i as u16),
            mode: p.mode,
            source: p.source,
            sequence: p.sequence,
            payload_bits: self.bits,
        })
    }
}

// ---------------------------------------------------------------------------------------
// The paper's tables as data.
// ---------------------------------------------------------------------------------------

/// One row of ZLL Table 1 (or Table 3, where `flag` is always empty).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StrategyRow {
    /// Flag-zone bits as printed (`""`, `"0"`, `"01"`, …).
    pub flag: String,
    /// `a_i`.
    pub flag_bits: u8,
    /// First and last magnitude `t` of the quantization-zone group.
    pub magnitudes: (usize, usize),
    /// `b_i`.
    pub quant_bits: u8,
    /// `c_i = a_i + b_i`.
    pub payload_bits: u8,
}

impl StrategyRow {
    /// The "Quantization zone" cell, e.g. `±λ_2^{b,p}, ±λ_3^{b,p}`.
    pub fn quantization_zone(&self) -> String {
        (self.magnitudes.0..=self.magnitudes.1)
            .map(|t| format!("±λ_{t}^{{b,p}}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Rows of Table 1 ([`Strategy::FlagZone`]) or Table 3 ([`Strategy::NoFlagZone`]) up to
/// `c_max` payload bits, derived from the codec's own zone arithmetic.
pub fn strategy_table(strategy: Strategy, c_max: u8) -> Vec<StrategyRow> {
    let mut rows = Vec::new();
    for c in 1..=c_max.min(MAX_ZONE_BITS) {
        let flag_lengths = match strategy {
            Strategy::FlagZone => 0..c,
            Strategy::NoFlagZone => 0..1,
        };
        for a in flag_lengths {
            let b = c - a;
            for flag in 0..(1u16 << a) {
                let layout = ZoneLayout {
                    flag_bits: a,
                    quant_bits: b,
                };
                let code = |offset: u8| ZoneCode {
                    layout,
                    flag: flag as u8,
                    offset,
                };
                let last = ((1u16 << (b - 1)) - 1) as u8;
                let (Some(first_t), Some(last_t)) =
                    (strategy.magnitude(code(0)), strategy.magnitude(code(last)))
                else {
                    continue;
                };
                rows.push(StrategyRow {
                    flag: (0..a)
                        .rev()
                        .map(|k| if flag >> k & 1 == 1 { '1' } else { '0' })
                        .collect(),
                    flag_bits: a,
                    magnitudes: (first_t, last_t),
                    quant_bits: b,
                    payload_bits: c,
                });
            }
        }
    }
    rows
}

/// ZLL Table 1 (dynamic transmission strategy).
pub fn table_1() -> Vec<StrategyRow> {
    strategy_table(Strategy::FlagZone, 3)
}

/// ZLL Table 3 (dynamic transmission strategy without flag zone).
pub fn table_3() -> Vec<StrategyRow> {
    strategy_table(Strategy::NoFlagZone, 3)
}

/// One row of ZLL Table 2 / Table 4.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SchemeRow {
    /// Largest magnitude `l`: `d ∈ {0, ±λ_1^{b,p}, …, ±λ_l^{b,p}}`.
    pub max_magnitude: usize,
    /// `L = 4l + 1`.
    pub levels: usize,
    /// `c_i ≤ this`.
    pub max_payload_bits: u8,
}

impl SchemeRow {
    /// The `d_k^i` cell, e.g. `{0, ±λ_1^{b,p}, …, ±λ_5^{b,p}}`.
    pub fn symbol_set(&self) -> String {
        match self.max_magnitude {
            1 => "{0, ±λ_1^{b,p}}".to_string(),
            l => format!("{{0, ±λ_1^{{b,p}}, …, ±λ_{l}^{{b,p}}}}"),
        }
    }
}

/// Rows of Table 2 / Table 4 for `c_max = 1..=max_bits`.
pub fn scheme_table(strategy: Strategy, max_bits: u8) -> Vec<SchemeRow> {
    (1..=max_bits)
        .map(|c| SchemeRow {
            max_magnitude: strategy.max_magnitude(c),
            levels: strategy.levels(c),
            max_payload_bits: c,
        })
        .collect()
}

/// ZLL Table 2 (transmission scheme).
pub fn table_2() -> Vec<SchemeRow> {
    scheme_table(Strategy::FlagZone, 3)
}

/// ZLL Table 4 (transmission scheme without flag zone).
pub fn table_4() -> Vec<SchemeRow> {
    scheme_table(Strategy::NoFlagZone, 3)
}

/// One row of ZLL Table 5 / Table 6: maximal payload bits at equal level count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BandwidthRow {
    /// `L`.
    pub levels: usize,
    /// ZLL's dynamic strategy.
    pub zhang: u8,
    /// You et al. (`L = 2^c + 1`).
    pub you: u8,
    /// Msechu et al. (`L = 2^c`).
    pub msechu: u8,
}

/// Rows for the given level counts (each of the form `4l + 1`, at least 5).
pub fn bandwidth_table(strategy: Strategy, levels: &[usize]) -> Option<Vec<BandwidthRow>> {
    levels
        .iter()
        .map(|&l| {
            Some(BandwidthRow {
                levels: l,
                zhang: strategy.payload_bits_for_levels(l)?,
                you: you_payload_bits(l)?,
                msechu: msechu_payload_bits(l)?,
            })
        })
        .collect()
}

/// ZLL Table 5 (L = 5, 21; with flag zone).
pub fn table_5() -> Vec<BandwidthRow> {
    bandwidth_table(Strategy::FlagZone, &[5, 21]).expect("5 and 21 are of the form 4l + 1")
}

/// ZLL Table 6 (L = 5, 13; without flag zone).
pub fn table_6() -> Vec<BandwidthRow> {
    bandwidth_table(Strategy::NoFlagZone, &[5, 13]).expect("5 and 13 are of the form 4l + 1")
}

/// One row of ZLL Table 7: `ρ` (eq. (16)) at equal payload budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RhoRow {
    /// `c_i ≤ this`.
    pub max_payload_bits: u8,
    /// ZLL, with flag zone (`L` of Table 2).
    pub zhang: f64,
    /// You et al. (`2^c + 1` levels).
    pub you: f64,
    /// Msechu et al. (`2^c` levels).
    pub msechu: f64,
}

/// ZLL Table 7 (`c ≤ 1, 2`), computed from the Lloyd-Max designs.
pub fn table_7() -> Result<Vec<RhoRow>, QuantizerError> {
    (1..=2u8)
        .map(|c| {
            let l = Strategy::FlagZone.max_magnitude(c) as u16;
            Ok(RhoRow {
                max_payload_bits: c,
                zhang: ZhangQuantizer::new(l)?.rho(),
                you: YouQuantizer::new(c)?.rho(),
                msechu: MsechuQuantizer::new(c)?.rho(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn link() -> LinkAddressing {
        LinkAddressing::new(0x1234, 0x0001).unwrap()
    }

    fn all_codecs() -> Vec<Box<dyn LevelCodec>> {
        let mut v: Vec<Box<dyn LevelCodec>> = Vec::new();
        for s in [Strategy::FlagZone, Strategy::NoFlagZone] {
            for c in 1..=3 {
                v.push(Box::new(DynamicCodec::new(s, c, link()).unwrap()));
            }
        }
        v.push(Box::new(FixedLengthCodec::sign(link())));
        for c in [1, 2, 3, 5, 8] {
            v.push(Box::new(FixedLengthCodec::msechu(c, link()).unwrap()));
            v.push(Box::new(FixedLengthCodec::you(c, link()).unwrap()));
        }
        v.push(Box::new(FixedLengthCodec::new(5, false, link()).unwrap()));
        v.push(Box::new(FixedLengthCodec::new(21, true, link()).unwrap()));
        v
    }

    fn with_fcs(mut body: Vec<u8>) -> Vec<u8> {
        let fcs = crc16_kermit(&body);
        body.extend_from_slice(&fcs.to_le_bytes());
        body
    }

    fn bits_lsb_first(bytes: &[u8]) -> String {
        bytes
            .iter()
            .map(|b| {
                (0..8)
                    .map(|k| if b >> k & 1 == 1 { '1' } else { '0' })
                    .collect::<String>()
            })
            .collect::<Vec<_>>()
            .join("")
    }

    #[test]
    fn crc_matches_kermit_and_the_standard_example() {
        assert_eq!(crc16_kermit(b"123456789"), 0x2189); // CRC-16/KERMIT check value
                                                        // IEEE 802.15.4-2006 §7.2.1.9 example (acknowledgment frame), bits in transmission
                                                        // order: MHR 0100 0000 0000 0000 0101 0110, FCS 0010 0111 1001 1110.
        let mhr = [0x02, 0x00, 0x6a];
        assert_eq!(bits_lsb_first(&mhr), "010000000000000001010110");
        let fcs = crc16_kermit(&mhr).to_le_bytes();
        assert_eq!(bits_lsb_first(&fcs), "0010011110011110");
    }

    #[test]
    fn frame_geometry() {
        assert_eq!(MHR_OCTETS, 9);
        assert_eq!(MPDU_OCTETS, 12);
        assert_eq!(PPDU_OCTETS, 18);
        let codec = DynamicCodec::new(Strategy::FlagZone, 3, link()).unwrap();
        let f = codec.encode(Level::new(0), 0x0042, 7).unwrap().unwrap();
        assert_eq!(f.len(), MPDU_OCTETS);
        assert_eq!(&f[..3], &[0x41, 0x88, 7]);
        assert_eq!(&f[3..9], &[0x34, 0x12, 0xff, 0xff, 0x42, 0x00]); // level 0 = -λ_17^b
        let cost = codec.cost(Level::new(0)).unwrap();
        assert_eq!(
            (cost.payload_bits, cost.mpdu_bits(), cost.ppdu_bits()),
            (3, 96, 144)
        );
        assert_eq!(codec.cost(Level::new(34)).unwrap(), FrameCost::SILENT);
    }

    /// Every level of every codec: silent ⇒ no frame, otherwise decode(encode) = level,
    /// with the mode of eq. (5) in the destination address and `c_i` as in the tables.
    #[test]
    fn every_level_round_trips() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x802_154);
        for codec in all_codecs() {
            let mut max_bits = 0;
            for i in 0..codec.levels() {
                let level = Level::new(i as u16);
                let (src, seq) = (rng.random_range(0..0xfffe), rng.random::<u8>());
                let bits = codec.payload_bits(level).unwrap();
                max_bits = max_bits.max(bits);
                match codec.encode(level, src, seq).unwrap() {
                    None => assert_eq!(bits, 0),
                    Some(frame) => {
                        let r = codec.decode(&frame).unwrap();
                        assert_eq!(r.level, level);
                        assert_eq!((r.source, r.sequence, r.payload_bits), (src, seq, bits));
                        assert!(bits >= 1);
                    }
                }
            }
            assert_eq!(max_bits, codec.max_payload_bits());
            assert!(codec
                .payload_bits(Level::new(codec.levels() as u16))
                .is_err());
            assert!(codec
                .encode(Level::new(codec.levels() as u16), 1, 0)
                .is_err());
        }
    }

    #[test]
    fn dynamic_codec_modes_follow_eq_5() {
        for s in [Strategy::FlagZone, Strategy::NoFlagZone] {
            let codec = DynamicCodec::new(s, 3, link()).unwrap();
            let q = codec.quantizer().unwrap();
            assert_eq!(q.levels(), codec.levels());
            for i in 0..codec.levels() {
                let level = Level::new(i as u16);
                match (q.symbol(level), codec.encode(level, 9, 0).unwrap()) {
                    (None, None) => assert!(q.is_silent(level)),
                    (Some(sym), Some(frame)) => {
                        assert_eq!(codec.decode(&frame).unwrap().mode, sym.mode);
                        let dst = u16::from_le_bytes([frame[5], frame[6]]);
                        assert_eq!(dst == BROADCAST, sym.mode == TxMode::Broadcast);
                        // c_i as listed for this magnitude in Table 1 / 3.
                        let t = usize::from(sym.magnitude);
                        let row = strategy_table(s, 3)
                            .into_iter()
                            .find(|r| r.magnitudes.0 <= t && t <= r.magnitudes.1)
                            .unwrap();
                        assert_eq!(codec.payload_bits(level).unwrap(), row.payload_bits);
                    }
                    _ => panic!("silence mismatch at level {i}"),
                }
            }
        }
    }

    #[test]
    fn zone_arithmetic_is_a_bijection() {
        for s in [Strategy::FlagZone, Strategy::NoFlagZone] {
            let n = s.max_magnitude(MAX_ZONE_BITS);
            for t in 1..=n {
                let z = s.zone(t).unwrap();
                assert_eq!(s.magnitude(z), Some(t));
            }
            assert_eq!(s.zone(n + 1), None);
            assert_eq!(s.zone(0), None);
        }
    }

    /// ZLL Table 1 as printed: (flag zone, a_i, quantization zone t-range, b_i, c_i).
    /// (flag zone, a_i, quantization-zone magnitudes, b_i, c_i)
    type Table1Row<'a> = (&'a str, u8, (usize, usize), u8, u8);

    #[test]
    fn table_1_as_printed() {
        let printed: [Table1Row; 11] = [
            ("", 0, (1, 1), 1, 1),
            ("", 0, (2, 3), 2, 2),
            ("0", 1, (4, 4), 1, 2),
            ("1", 1, (5, 5), 1, 2),
            ("", 0, (6, 9), 3, 3),
            ("0", 1, (10, 11), 2, 3),
            ("1", 1, (12, 13), 2, 3),
            ("00", 2, (14, 14), 1, 3),
            ("01", 2, (15, 15), 1, 3),
            ("10", 2, (16, 16), 1, 3),
            ("11", 2, (17, 17), 1, 3),
        ];
        let rows = table_1();
        assert_eq!(rows.len(), printed.len());
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(
                (
                    row.flag.as_str(),
                    row.flag_bits,
                    row.magnitudes,
                    row.quant_bits,
                    row.payload_bits
                ),
                p
            );
        }
        assert_eq!(
            rows[4].quantization_zone(),
            "±λ_6^{b,p}, ±λ_7^{b,p}, ±λ_8^{b,p}, ±λ_9^{b,p}"
        );
    }

    /// ZLL Table 3 as printed: (t-range, b_i, c_i).
    #[test]
    fn table_3_as_printed() {
        let printed = [((1, 1), 1, 1), ((2, 3), 2, 2), ((4, 7), 3, 3)];
        let rows = table_3();
        assert_eq!(rows.len(), 3);
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(row.flag, "");
            assert_eq!((row.magnitudes, row.quant_bits, row.payload_bits), p);
        }
    }

    /// ZLL Tables 2 and 4 as printed: (l in "±λ_l", L, c_i ≤).
    #[test]
    fn tables_2_and_4_as_printed() {
        let t2 = [(1, 5, 1), (5, 21, 2), (17, 69, 3)];
        let t4 = [(1, 5, 1), (3, 13, 2), (7, 29, 3)];
        for (rows, printed) in [(table_2(), t2), (table_4(), t4)] {
            assert_eq!(rows.len(), 3);
            for (row, p) in rows.iter().zip(printed) {
                assert_eq!((row.max_magnitude, row.levels, row.max_payload_bits), p);
            }
        }
        assert_eq!(table_2()[0].symbol_set(), "{0, ±λ_1^{b,p}}");
        assert_eq!(table_2()[1].symbol_set(), "{0, ±λ_1^{b,p}, …, ±λ_5^{b,p}}");
        // The codecs realize them: a c_max codec carries exactly L levels.
        for (s, rows) in [
            (Strategy::FlagZone, table_2()),
            (Strategy::NoFlagZone, table_4()),
        ] {
            for row in rows {
                let codec = DynamicCodec::new(s, row.max_payload_bits, link()).unwrap();
                assert_eq!(codec.levels(), row.levels);
            }
        }
    }

    /// ZLL Tables 5 and 6 as printed: (L, Zhang, You, Msechu).
    #[test]
    fn tables_5_and_6_as_printed() {
        let t5 = [(5, 1, 2, 3), (21, 2, 5, 5)];
        let t6 = [(5, 1, 2, 3), (13, 2, 4, 4)];
        for (rows, printed) in [(table_5(), t5), (table_6(), t6)] {
            assert_eq!(rows.len(), 2);
            for (row, p) in rows.iter().zip(printed) {
                assert_eq!((row.levels, row.zhang, row.you, row.msechu), p);
            }
        }
        // And the fixed-length codecs realize the baseline columns.
        for l in [5, 13, 21] {
            let you = FixedLengthCodec::new(l, true, link()).unwrap();
            let msechu = FixedLengthCodec::new(l, false, link()).unwrap();
            assert_eq!(Some(you.max_payload_bits()), you_payload_bits(l));
            assert_eq!(Some(msechu.max_payload_bits()), msechu_payload_bits(l));
        }
        assert_eq!(bandwidth_table(Strategy::FlagZone, &[6]), None);
    }

    /// ZLL Table 7, printed to 4 decimals.
    #[test]
    #[allow(clippy::approx_constant)] // 0.6366 is the paper's printed ρ, not a stand-in for 2/π
    fn table_7_as_printed() {
        let printed = [(1, 0.9201, 0.8098, 0.6366), (2, 0.9943, 0.9201, 0.8825)];
        let rows = table_7().unwrap();
        assert_eq!(rows.len(), 2);
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(row.max_payload_bits, p.0);
            assert!((row.zhang - p.1).abs() <= 5e-5);
            assert!((row.you - p.2).abs() <= 5e-5);
            assert!((row.msechu - p.3).abs() <= 5e-5);
        }
    }

    #[test]
    fn specific_rejections() {
        let codec2 = DynamicCodec::new(Strategy::FlagZone, 2, link()).unwrap();
        let noflag = DynamicCodec::new(Strategy::NoFlagZone, 3, link()).unwrap();
        let frame = codec2.encode(Level::new(0), 5, 1).unwrap().unwrap();
        let mut body = frame[..10].to_vec();
        let with_payload = |body: &mut Vec<u8>, p: u8| {
            body[9] = p;
            with_fcs(body.clone())
        };
        assert_eq!(
            codec2.decode(&with_payload(&mut body, 6 << 5)),
            Err(DecodeError::ReservedLayout(6))
        );
        assert_eq!(
            codec2.decode(&with_payload(&mut body, 7 << 5)),
            Err(DecodeError::ReservedLayout(7))
        );
        // A 3-bit layout is valid in general but not for c_max = 2.
        assert_eq!(
            codec2.decode(&with_payload(&mut body, 3 << 5)),
            Err(DecodeError::LayoutNotInScheme {
                flag_bits: 0,
                quant_bits: 3
            })
        );
        // A flag zone in the no-flag strategy.
        assert_eq!(
            noflag.decode(&with_payload(&mut body, 2 << 5)),
            Err(DecodeError::LayoutNotInScheme {
                flag_bits: 1,
                quant_bits: 1
            })
        );
        // Layout 0 (c = 1) followed by a non-zero padding bit.
        assert_eq!(
            codec2.decode(&with_payload(&mut body, 0b0000_0001)),
            Err(DecodeError::NonZeroPadding(1))
        );
        // Beacon frame type.
        let mut b = frame[..10].to_vec();
        b[0] &= !0b111;
        assert_eq!(
            codec2.decode(&with_fcs(b)),
            Err(DecodeError::NotADataFrame { frame_type: 0 })
        );
        // Security enabled.
        let mut b = frame[..10].to_vec();
        b[0] |= 0b1000;
        assert!(matches!(
            codec2.decode(&with_fcs(b)),
            Err(DecodeError::UnsupportedFrameControl(_))
        ));
        // Foreign PAN, foreign destination, broadcast source.
        let mut b = frame[..10].to_vec();
        b[3] ^= 1;
        assert_eq!(
            codec2.decode(&with_fcs(b)),
            Err(DecodeError::WrongPan(0x1235))
        );
        let mut b = frame[..10].to_vec();
        b[5..7].copy_from_slice(&0x0002u16.to_le_bytes());
        assert_eq!(codec2.decode(&with_fcs(b)), Err(DecodeError::NotForUs(2)));
        let mut b = frame[..10].to_vec();
        b[7..9].copy_from_slice(&BROADCAST.to_le_bytes());
        assert_eq!(
            codec2.decode(&with_fcs(b)),
            Err(DecodeError::InvalidSource(BROADCAST))
        );
        // Broadcast to a fixed-length codec; unused code of a 5-level, 3-bit code.
        let fixed = FixedLengthCodec::new(5, false, link()).unwrap();
        assert_eq!(fixed.decode(&frame), Err(DecodeError::UnexpectedBroadcast));
        let mut b = fixed.encode(Level::new(4), 5, 1).unwrap().unwrap()[..10].to_vec();
        b[9] = 5 << 5;
        assert_eq!(
            fixed.decode(&with_fcs(b)),
            Err(DecodeError::UnusedCode(5 << 5))
        );
        // Corruption and truncation.
        let mut bad = frame.clone();
        bad[11] ^= 0x80;
        assert!(matches!(
            codec2.decode(&bad),
            Err(DecodeError::BadFcs { .. })
        ));
        assert_eq!(
            codec2.decode(&frame[..11]),
            Err(DecodeError::WrongLength {
                expected: 12,
                got: 11
            })
        );
        // Encoder-side validation.
        assert_eq!(
            codec2.encode(Level::new(1), BROADCAST, 0),
            Err(CodecError::InvalidAddress(BROADCAST))
        );
        assert_eq!(
            LinkAddressing::new(BROADCAST, 1),
            Err(CodecError::BroadcastPan)
        );
        assert_eq!(
            LinkAddressing::new(1, NO_SHORT_ADDRESS),
            Err(CodecError::InvalidAddress(NO_SHORT_ADDRESS))
        );
        assert!(DynamicCodec::new(Strategy::FlagZone, 4, link()).is_err());
        assert!(DynamicCodec::new(Strategy::FlagZone, 0, link()).is_err());
        assert!(FixedLengthCodec::new(4, true, link()).is_err());
        assert!(FixedLengthCodec::new(1, false, link()).is_err());
        assert!(FixedLengthCodec::new(258, true, link()).is_err());
        assert!(FixedLengthCodec::msechu(9, link()).is_err());
    }

    /// Accepted frames must be canonical: re-encoding the decoded message reproduces them.
    fn assert_canonical(codec: &dyn LevelCodec, frame: &[u8]) -> bool {
        match codec.decode(frame) {
            Ok(r) => {
                let again = codec.encode(r.level, r.source, r.sequence).unwrap();
                assert_eq!(again.as_deref(), Some(frame), "non-canonical accept");
                true
            }
            Err(_) => false,
        }
    }

    /// 100000 random byte strings (lengths 0..=24, a third exactly 12 so the CRC is
    /// reached): no panic, and anything accepted is canonical.
    #[test]
    fn fuzz_random_bytes() {
        let codecs = all_codecs();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xf022);
        let mut buf = [0u8; 24];
        for _ in 0..100_000 {
            let len = if rng.random_bool(1.0 / 3.0) {
                MPDU_OCTETS
            } else {
                rng.random_range(0..=24)
            };
            rng.fill(&mut buf[..len]);
            for codec in &codecs {
                assert_canonical(codec.as_ref(), &buf[..len]);
            }
        }
    }

    /// Frames with a correct FCS but random header fields and payload: exercises every
    /// check after the CRC; no panic, accepted frames canonical, and both outcomes occur.
    #[test]
    fn fuzz_valid_fcs_random_fields() {
        let codecs = all_codecs();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xf023);
        let mut accepted = vec![0usize; codecs.len()];
        for _ in 0..100_000 {
            let mut body = vec![0x41, 0x88, rng.random(), 0x34, 0x12, 0xff, 0xff, 0, 0, 0];
            if rng.random_bool(0.1) {
                body[0] = rng.random();
                body[1] = rng.random();
            }
            if rng.random_bool(0.05) {
                body[3] = rng.random();
            }
            let dst: u16 = match rng.random_range(0..3) {
                0 => BROADCAST,
                1 => 0x0001,
                _ => rng.random(),
            };
            body[5..7].copy_from_slice(&dst.to_le_bytes());
            let src: u16 = if rng.random_bool(0.05) {
                0xfffe | rng.random_range(0..2)
            } else {
                rng.random()
            };
            body[7..9].copy_from_slice(&src.to_le_bytes());
            body[9] = rng.random();
            let frame = with_fcs(body);
            for (k, codec) in codecs.iter().enumerate() {
                accepted[k] += usize::from(assert_canonical(codec.as_ref(), &frame));
            }
        }
        for (k, &n) in accepted.iter().enumerate() {
            assert!(n > 0 && n < 100_000, "codec {k}: {n} accepted");
        }
    }

    fn valid_frames(codec: &dyn LevelCodec) -> Vec<Vec<u8>> {
        (0..codec.levels())
            .filter_map(|i| codec.encode(Level::new(i as u16), 0x0a0b, i as u8).unwrap())
            .collect()
    }

    /// Every truncation and one-octet extension of every valid frame is rejected.
    #[test]
    fn truncations_and_extensions_are_rejected() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xf024);
        for codec in all_codecs() {
            for frame in valid_frames(codec.as_ref()) {
                for len in 0..frame.len() {
                    assert!(codec.decode(&frame[..len]).is_err());
                }
                let mut longer = frame.clone();
                longer.push(rng.random());
                assert!(codec.decode(&longer).is_err());
            }
        }
    }

    /// All 1- and 2-bit flips (and random 3-bit flips) of every valid frame of the two
    /// largest dynamic codecs and a baseline are detected: the CRC-16 has Hamming distance
    /// 4 at this length, so this must hold exactly, not just with high probability.
    #[test]
    fn low_weight_bit_flips_are_detected() {
        let codecs: Vec<Box<dyn LevelCodec>> = vec![
            Box::new(DynamicCodec::new(Strategy::FlagZone, 3, link()).unwrap()),
            Box::new(DynamicCodec::new(Strategy::NoFlagZone, 3, link()).unwrap()),
            Box::new(FixedLengthCodec::you(2, link()).unwrap()),
        ];
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xf025);
        let nbits = 8 * MPDU_OCTETS;
        let flip = |f: &mut [u8], k: usize| f[k / 8] ^= 1 << (k % 8);
        for codec in &codecs {
            for frame in valid_frames(codec.as_ref()) {
                for i in 0..nbits {
                    let mut f = frame.clone();
                    flip(&mut f, i);
                    assert!(codec.decode(&f).is_err(), "1-bit flip {i} undetected");
                    for j in i + 1..nbits {
                        let mut g = f.clone();
                        flip(&mut g, j);
                        assert!(codec.decode(&g).is_err(), "flips {i},{j} undetected");
                    }
                }
                for _ in 0..300 {
                    let mut f = frame.clone();
                    let mut ks = [0usize; 3];
                    while ks[0] == ks[1] || ks[1] == ks[2] || ks[0] == ks[2] {
                        ks = [0; 3].map(|_| rng.random_range(0..nbits));
                    }
                    for k in ks {
                        flip(&mut f, k);
                    }
                    assert!(codec.decode(&f).is_err());
                }
            }
        }
    }

    /// 100000 random multi-bit corruptions: no panic; an undetected error needs an error
    /// pattern divisible by the generator (≈ 2^-16 each, ~1.5 expected), and any frame that
    /// passes must still be canonical.
    #[test]
    fn random_corruption_is_almost_always_detected() {
        let codec = DynamicCodec::new(Strategy::FlagZone, 3, link()).unwrap();
        let frames = valid_frames(&codec);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xf026);
        let mut undetected = 0;
        for _ in 0..100_000 {
            let mut f = frames[rng.random_range(0..frames.len())].clone();
            let p = rng.random_range(0.02..0.5);
            let mut changed = false;
            for byte in f.iter_mut() {
                for k in 0..8 {
                    if rng.random_bool(p) {
                        *byte ^= 1 << k;
                        changed = true;
                    }
                }
            }
            if changed && assert_canonical(&codec, &f) {
                undetected += 1;
            }
        }
        assert!(undetected <= 10, "{undetected} corruptions undetected");
    }
}
