//! The fixed-length codes of the baselines (SOI-KF's sign bit, Msechu et al., You et al.):
//! [`FixedLengthCodec`], which sends every non-silent level peer-to-peer as a fixed-width
//! index, and the payload bits each baseline needs for a level count, the You and Msechu
//! columns of ZLL Tables 5-6. Apart from the dynamic codec because the two share only the
//! frame (`frame`).
use super::frame::{build_frame, check_unicast, parse_frame, LevelCodec, LinkAddressing, Received};
use super::{CodecError, DecodeError};
use crate::link::quantizer::{Level, TxMode};

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

    /// Msechu et al.'s `c`-bit code for
    /// [`MsechuQuantizer`](crate::link::quantizer::MsechuQuantizer).
    pub fn msechu(bits: u8, link: LinkAddressing) -> Result<Self, CodecError> {
        if !(1..=8).contains(&bits) {
            return Err(CodecError::UnsupportedBits(bits));
        }
        Self::new(1 << bits, false, link)
    }

    /// You et al.'s `c`-bit code for
    /// [`YouQuantizer`](crate::link::quantizer::YouQuantizer).
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
