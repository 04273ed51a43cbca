//! ZLL's dynamic transmission strategy (Tables 1-4): the zone arithmetic of [`Strategy`] that
//! places each magnitude `t` of eq. (5) in a [`ZoneLayout`] (flag-zone and quantization-zone
//! lengths `a_i`, `b_i`) and a [`ZoneCode`], and the [`DynamicCodec`] that writes it into the
//! payload octet of a [`super::frame`] MAC frame. Apart from the fixed-length baselines
//! because this is the paper's own scheme, with its own layout code and decoding checks.
use super::frame::{build_frame, check_unicast, parse_frame, LevelCodec, LinkAddressing, Received};
use super::{CodecError, DecodeError, BROADCAST};
use crate::link::quantizer::{
    zhang_level, zhang_symbol, Level, QuantizerError, TxMode, ZhangQuantizer, ZhangSymbol,
};

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
pub(super) const MAX_ZONE_BITS: u8 = 8;

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

#[cfg(test)]
mod tests {
    use super::super::tests::link;
    use super::super::*;
    use super::*;
    use crate::link::quantizer::InnovationQuantizer;

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
}
