//! The IEEE 802.15.4 MAC data frame every codec of this module sends (layout in the module
//! documentation of [`super`]): the FCS (CRC-16/KERMIT), the PAN and fusion-centre
//! addressing, building and parsing the frame, the decoded [`Received`] message, the
//! [`FrameCost`] of a message and the [`LevelCodec`] interface the codecs implement. Apart from
//! the codecs because it is the part they share: a codec only chooses the payload octet and
//! the destination address.
use super::{
    CodecError, DecodeError, BROADCAST, FCS_OCTETS, FRAME_CONTROL, MPDU_OCTETS, NO_SHORT_ADDRESS,
    PAYLOAD_OCTETS, PPDU_OCTETS,
};
use crate::link::quantizer::{Level, TxMode};

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

/// PAN and fusion-centre addresses shared by the sensors and the fusion centre.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkAddressing {
    pan_id: u16,
    pub(super) coordinator: u16,
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

pub(super) fn check_unicast(addr: u16) -> Result<(), CodecError> {
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

pub(super) fn build_frame(
    link: &LinkAddressing,
    dst: u16,
    source: u16,
    sequence: u8,
    payload: u8,
) -> Vec<u8> {
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
pub(super) struct Parsed {
    pub(super) mode: TxMode,
    pub(super) source: u16,
    pub(super) sequence: u8,
    pub(super) payload: u8,
}

pub(super) fn parse_frame(link: &LinkAddressing, frame: &[u8]) -> Result<Parsed, DecodeError> {
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

#[cfg(test)]
mod tests {
    use super::super::tests::link;
    use super::super::*;
    use crate::link::quantizer::Level;

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
}
