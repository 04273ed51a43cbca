//! The datagrams of a live run: an envelope (what the network layer of a real deployment
//! gives for free: who is talking, which step, how long) around at most one IEEE 802.15.4 MAC
//! frame, the octets a radio would send and the only ones counted as bits.
//!
//! # Envelope (every datagram)
//!
//! | octets | field |
//! |---|---|
//! | 0..2 | magic `HF` |
//! | 2 | version ([`VERSION`]) |
//! | 3 | kind ([`Kind`]) |
//! | 4..6 | sensor index (u16, little endian) |
//! | 6..8 | variant of the scenario (u16) |
//! | 8..12 | step (u32) |
//! | 12..14 | aux (u16): the payload bits of a frame's message |
//! | 14 | flags (per kind) |
//! | 15 | body length L (0..=127 for a frame: `aMaxPHYPacketSize`) |
//! | 16..16+L | body: an 802.15.4 MPDU, or a control body |
//! | 16+L..18+L | CRC-16/KERMIT of octets 0..16+L, low octet first |
//!
//! The envelope's CRC protects the control fields (a flipped "has a reading" bit would change
//! an estimate); the MPDU inside keeps its own FCS, which the center checks on its own, so a
//! frame corrupted on a real radio (or by a test) is counted as a bad FCS and dropped.
//!
//! # Frames
//!
//! A measurement or estimate goes as a data frame of the 802.15.4 format of
//! [`crate::link::codec802154`] (frame control `0x8841`, sequence number = step mod 256, the
//! PAN [`PAN_ID`], destination the center [`CENTER_ADDRESS`], source the sensor's short address
//! `i + 1`) whose payload is each component as an IEEE 754 single, little endian: 11 + 4m
//! octets, exactly [`crate::link::Message::frame_bits`]. A codec's frame (quantized
//! innovations) goes as the codec wrote it. The center's feedback goes down the same way, from
//! the center's address: a prediction broadcast (mean, then the covariance's upper triangle
//! row by row when the scheme sends it), an innovation reference unicast to its sensor
//! (ŷ, Δ).
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::{crc16_kermit, BROADCAST, FCS_OCTETS, FRAME_CONTROL, MHR_OCTETS};
use crate::scheme::{Feedback, InnovationReference};

/// Version of the envelope; a datagram of another version is dropped.
pub const VERSION: u8 = 1;
/// Envelope octets before the body.
pub const HEADER_OCTETS: usize = 16;
/// The envelope's CRC after the body.
pub const CRC_OCTETS: usize = 2;
/// Octets of an 802.15.4 MPDU at most (aMaxPHYPacketSize, 2006 §6.4.1).
pub use crate::link::codec802154::MAX_MPDU_OCTETS;
/// The live network's PAN id (the one the quantized-innovation codecs use).
pub const PAN_ID: u16 = 0x0003;
/// The fusion center's short address; sensor i has `i + 1`.
pub const CENTER_ADDRESS: u16 = 0x0000;

/// What a datagram is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Node -> center: "sensor i is here" (body: the scenario's fingerprint, 8 octets;
    /// flags bit 0: the node has just started).
    Hello,
    /// Center -> node: refused (body: the reason, UTF-8).
    Reject,
    /// Center -> node: step `step` of variant `variant` begins (body: the downlink frame of the
    /// feedback, if any; flags: [`STEP_CATCH_UP`] and the feedback's form).
    Step,
    /// Node -> center: the frame sensor i sends at this step (flags: [`MessageKind`]; aux:
    /// its payload bits).
    Frame,
    /// Node -> center: sensor i has finished the step (flags bit 0: it had a reading).
    Done,
    /// Node -> center: sensor i has done variant `variant` up to step `step` and asks for the
    /// steps it missed.
    CatchUp,
    /// Center -> node: the run is over.
    End,
}

impl Kind {
    fn code(self) -> u8 {
        match self {
            Kind::Hello => b'H',
            Kind::Reject => b'X',
            Kind::Step => b'S',
            Kind::Frame => b'F',
            Kind::Done => b'D',
            Kind::CatchUp => b'C',
            Kind::End => b'E',
        }
    }

    fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            b'H' => Kind::Hello,
            b'X' => Kind::Reject,
            b'S' => Kind::Step,
            b'F' => Kind::Frame,
            b'D' => Kind::Done,
            b'C' => Kind::CatchUp,
            b'E' => Kind::End,
            _ => return None,
        })
    }
}

/// A [`Kind::Step`] that replays a step the node missed: the node updates its state and
/// sends nothing.
pub const STEP_CATCH_UP: u8 = 1;
/// The feedback frame of a [`Kind::Step`] is a prediction (mean only).
pub const STEP_PREDICTION: u8 = 2;
/// ... a prediction with its covariance.
pub const STEP_PREDICTION_COV: u8 = 4;
/// ... an innovation reference for this sensor.
pub const STEP_REFERENCE: u8 = 8;
/// A [`Kind::Done`] of a sensor that had a reading.
pub const DONE_READING: u8 = 1;
/// A [`Kind::Hello`] of a node that has just started (it holds no state yet).
pub const HELLO_FRESH: u8 = 1;

/// What a [`Kind::Frame`] carries, which fixes how the center reads its payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageKind {
    Measurement,
    Estimate,
    /// A codec's own frame, passed to the scheme's center as it is.
    Codec,
}

impl MessageKind {
    pub fn code(self) -> u8 {
        match self {
            MessageKind::Measurement => 0,
            MessageKind::Estimate => 1,
            MessageKind::Codec => 2,
        }
    }

    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            0 => MessageKind::Measurement,
            1 => MessageKind::Estimate,
            2 => MessageKind::Codec,
            _ => return None,
        })
    }
}

/// One datagram, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Datagram {
    pub kind: Kind,
    pub sensor: u16,
    pub variant: u16,
    pub step: u32,
    pub aux: u16,
    pub flags: u8,
    pub body: Vec<u8>,
}

/// Why a datagram was dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("{0} octets: shorter than an envelope")]
    Short(usize),
    #[error("not a hushfuse datagram (magic or version)")]
    Foreign,
    #[error("envelope length {declared} does not match the datagram's {got} octets")]
    Length { declared: usize, got: usize },
    #[error("envelope CRC mismatch")]
    Crc,
    #[error("unknown datagram kind {0:#04x}")]
    UnknownKind(u8),
}

impl Datagram {
    pub fn new(kind: Kind, sensor: usize, variant: usize, step: usize) -> Self {
        Self {
            kind,
            sensor: sensor as u16,
            variant: variant as u16,
            step: step as u32,
            aux: 0,
            flags: 0,
            body: Vec::new(),
        }
    }

    /// The octets on the wire.
    pub fn encode(&self) -> Vec<u8> {
        assert!(
            self.body.len() <= u8::MAX as usize,
            "body fits its length octet"
        );
        let mut out = Vec::with_capacity(HEADER_OCTETS + self.body.len() + CRC_OCTETS);
        out.extend_from_slice(b"HF");
        out.push(VERSION);
        out.push(self.kind.code());
        out.extend_from_slice(&self.sensor.to_le_bytes());
        out.extend_from_slice(&self.variant.to_le_bytes());
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&self.aux.to_le_bytes());
        out.push(self.flags);
        out.push(self.body.len() as u8);
        out.extend_from_slice(&self.body);
        let crc = crc16_kermit(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Reads a datagram; never panics (any octets in, a [`WireError`] for anything else).
    pub fn decode(octets: &[u8]) -> Result<Self, WireError> {
        if octets.len() < HEADER_OCTETS + CRC_OCTETS {
            return Err(WireError::Short(octets.len()));
        }
        if &octets[..2] != b"HF" || octets[2] != VERSION {
            return Err(WireError::Foreign);
        }
        let len = usize::from(octets[15]);
        let total = HEADER_OCTETS + len + CRC_OCTETS;
        if octets.len() != total {
            return Err(WireError::Length {
                declared: total,
                got: octets.len(),
            });
        }
        let crc = u16::from_le_bytes([octets[total - 2], octets[total - 1]]);
        if crc16_kermit(&octets[..total - 2]) != crc {
            return Err(WireError::Crc);
        }
        let kind = Kind::from_code(octets[3]).ok_or(WireError::UnknownKind(octets[3]))?;
        let u16_at = |i: usize| u16::from_le_bytes([octets[i], octets[i + 1]]);
        Ok(Self {
            kind,
            sensor: u16_at(4),
            variant: u16_at(6),
            step: u32::from_le_bytes([octets[8], octets[9], octets[10], octets[11]]),
            aux: u16_at(12),
            flags: octets[14],
            body: octets[HEADER_OCTETS..HEADER_OCTETS + len].to_vec(),
        })
    }
}

/// The sensor index field of an envelope (octets 4..6), read without any other check: what a
/// secured receiver needs to pick the key before the MIC vouches for the rest.
pub fn sensor_field(octets: &[u8]) -> Option<usize> {
    octets
        .get(4..6)
        .map(|s| usize::from(u16::from_le_bytes([s[0], s[1]])))
}

/// Why a frame's octets were refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("frame of {0} octets is shorter than a MAC header and FCS")]
    Short(usize),
    #[error("bad FCS")]
    Fcs,
    #[error("frame control {0:#06x} is not this network's data frame")]
    FrameControl(u16),
    #[error("PAN {0:#06x} is not this network's")]
    Pan(u16),
    #[error("source {got:#06x}, expected {expected:#06x}")]
    Source { got: u16, expected: u16 },
    #[error("destination {0:#06x} is not for us")]
    Destination(u16),
    #[error("payload of {got} octets, expected {expected}")]
    Payload { got: usize, expected: usize },
    #[error("frame of {0} octets is longer than 802.15.4 allows (127)")]
    TooLong(usize),
}

/// The short address of sensor `i`.
pub fn sensor_address(i: usize) -> u16 {
    (i + 1) as u16
}

/// An 802.15.4 data frame around `payload`.
pub fn mpdu(sequence: u8, dst: u16, src: u16, payload: &[u8]) -> Result<Vec<u8>, FrameError> {
    let len = MHR_OCTETS + payload.len() + FCS_OCTETS;
    if len > MAX_MPDU_OCTETS {
        return Err(FrameError::TooLong(len));
    }
    let mut f = Vec::with_capacity(len);
    f.extend_from_slice(&FRAME_CONTROL.to_le_bytes());
    f.push(sequence);
    f.extend_from_slice(&PAN_ID.to_le_bytes());
    f.extend_from_slice(&dst.to_le_bytes());
    f.extend_from_slice(&src.to_le_bytes());
    f.extend_from_slice(payload);
    let fcs = crc16_kermit(&f);
    f.extend_from_slice(&fcs.to_le_bytes());
    Ok(f)
}

/// Checks a data frame of this network (FCS, frame control, PAN, source `src`, destination
/// `dst` or broadcast) and returns its payload.
pub fn check_mpdu(frame: &[u8], src: u16, dst: u16) -> Result<&[u8], FrameError> {
    if frame.len() < MHR_OCTETS + FCS_OCTETS {
        return Err(FrameError::Short(frame.len()));
    }
    if frame.len() > MAX_MPDU_OCTETS {
        return Err(FrameError::TooLong(frame.len()));
    }
    let body = frame.len() - FCS_OCTETS;
    let le = |i: usize| u16::from_le_bytes([frame[i], frame[i + 1]]);
    if crc16_kermit(&frame[..body]) != le(body) {
        return Err(FrameError::Fcs);
    }
    if le(0) != FRAME_CONTROL {
        return Err(FrameError::FrameControl(le(0)));
    }
    if le(3) != PAN_ID {
        return Err(FrameError::Pan(le(3)));
    }
    if le(5) != dst && le(5) != BROADCAST {
        return Err(FrameError::Destination(le(5)));
    }
    if le(7) != src {
        return Err(FrameError::Source {
            got: le(7),
            expected: src,
        });
    }
    Ok(&frame[MHR_OCTETS..body])
}

/// Components as IEEE 754 singles, little endian (what [`crate::link::BITS_PER_COMPONENT`]
/// prices).
pub fn f32_payload(values: impl IntoIterator<Item = f64>) -> Vec<u8> {
    values
        .into_iter()
        .flat_map(|x| (x as f32).to_le_bytes())
        .collect()
}

/// The numbers of an [`f32_payload`] of exactly `count` components.
pub fn read_f32s(payload: &[u8], count: usize) -> Result<Vec<f64>, FrameError> {
    if payload.len() != 4 * count {
        return Err(FrameError::Payload {
            got: payload.len(),
            expected: 4 * count,
        });
    }
    Ok(payload
        .chunks_exact(4)
        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .collect())
}

/// The downlink frame that carries `feedback` to sensor `i`, with the [`Kind::Step`] flags
/// that say its form; `None` when sensor i gets nothing (an innovation reference for another
/// sensor).
pub fn feedback_frame(
    feedback: &Feedback,
    i: usize,
    step: usize,
) -> Result<Option<(u8, Vec<u8>)>, FrameError> {
    let seq = step as u8;
    match feedback {
        Feedback::Prediction { mean, cov } => {
            let mut values: Vec<f64> = mean.iter().copied().collect();
            if let Some(c) = cov {
                for r in 0..c.nrows() {
                    values.extend((r..c.ncols()).map(|col| c[(r, col)]));
                }
            }
            let flag = if cov.is_some() {
                STEP_PREDICTION_COV
            } else {
                STEP_PREDICTION
            };
            let f = mpdu(seq, BROADCAST, CENTER_ADDRESS, &f32_payload(values))?;
            Ok(Some((flag, f)))
        }
        Feedback::InnovationReference(refs) => match refs.get(i).copied().flatten() {
            None => Ok(None),
            Some(r) => {
                let payload = f32_payload([r.y_hat, r.delta]);
                let f = mpdu(seq, sensor_address(i), CENTER_ADDRESS, &payload)?;
                Ok(Some((STEP_REFERENCE, f)))
            }
        },
    }
}

/// The feedback sensor `i` of `n_sensors` reads from a [`Kind::Step`]'s frame (`None`: the
/// step carried none), for a state of dimension `n`.
pub fn read_feedback(
    flags: u8,
    frame: &[u8],
    i: usize,
    n_sensors: usize,
    n: usize,
) -> Result<Option<Feedback>, FrameError> {
    if flags & (STEP_PREDICTION | STEP_PREDICTION_COV | STEP_REFERENCE) == 0 {
        return Ok(None);
    }
    let payload = check_mpdu(frame, CENTER_ADDRESS, sensor_address(i))?;
    if flags & STEP_REFERENCE != 0 {
        let v = read_f32s(payload, 2)?;
        let mut refs = vec![None; n_sensors];
        refs[i] = Some(InnovationReference {
            y_hat: v[0],
            delta: v[1],
        });
        return Ok(Some(Feedback::InnovationReference(refs)));
    }
    let with_cov = flags & STEP_PREDICTION_COV != 0;
    let count = n + if with_cov { n * (n + 1) / 2 } else { 0 };
    let v = read_f32s(payload, count)?;
    let mean = Vector::from_column_slice(&v[..n]);
    let cov = with_cov.then(|| {
        let mut c = Matrix::zeros(n, n);
        let mut it = v[n..].iter();
        for r in 0..n {
            for col in r..n {
                let x = *it.next().expect("counted");
                c[(r, col)] = x;
                c[(col, r)] = x;
            }
        }
        c
    });
    Ok(Some(Feedback::Prediction { mean, cov }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datagram_round_trips_and_rejects_every_corruption() {
        let mut d = Datagram::new(Kind::Frame, 3, 2, 70_000);
        d.aux = 32;
        d.flags = MessageKind::Estimate.code();
        d.body = mpdu(7, CENTER_ADDRESS, 4, &f32_payload([1.5, -2.25])).unwrap();
        let octets = d.encode();
        assert_eq!(octets.len(), HEADER_OCTETS + 11 + 8 + CRC_OCTETS);
        assert_eq!(Datagram::decode(&octets).unwrap(), d);
        // Every single flipped bit is caught by the envelope (magic, length or CRC).
        for bit in 0..8 * octets.len() {
            let mut bad = octets.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            assert!(Datagram::decode(&bad).is_err(), "bit {bit}");
        }
        for cut in 0..octets.len() {
            assert!(Datagram::decode(&octets[..cut]).is_err(), "cut {cut}");
        }
    }

    #[test]
    fn measurement_frame_has_the_simulation_s_size_and_f32_values() {
        let f = mpdu(1, CENTER_ADDRESS, sensor_address(0), &f32_payload([0.1])).unwrap();
        let priced = crate::link::Message::Measurement(Vector::from_vec(vec![0.1])).frame_bits();
        assert_eq!(8 * f.len() as u64, priced);
        let payload = check_mpdu(&f, 1, CENTER_ADDRESS).unwrap();
        assert_eq!(read_f32s(payload, 1).unwrap(), vec![f64::from(0.1f32)]);
        let mut bad = f.clone();
        bad[10] ^= 0x10;
        assert_eq!(check_mpdu(&bad, 1, CENTER_ADDRESS), Err(FrameError::Fcs));
        assert!(matches!(
            check_mpdu(&f, 2, CENTER_ADDRESS),
            Err(FrameError::Source { .. })
        ));
    }

    #[test]
    fn feedback_round_trips_through_its_frame() {
        let mean = Vector::from_vec(vec![1.0, 2.0]);
        let cov = Matrix::from_row_slice(2, 2, &[4.0, 0.5, 0.5, 3.0]);
        let fb = Feedback::Prediction {
            mean: mean.clone(),
            cov: Some(cov.clone()),
        };
        let (flags, f) = feedback_frame(&fb, 1, 9).unwrap().unwrap();
        assert_eq!(read_feedback(flags, &f, 1, 3, 2).unwrap(), Some(fb));
        let refs = Feedback::InnovationReference(vec![
            None,
            Some(InnovationReference {
                y_hat: 0.5,
                delta: 2.0,
            }),
        ]);
        assert_eq!(feedback_frame(&refs, 0, 1).unwrap(), None);
        let (flags, f) = feedback_frame(&refs, 1, 1).unwrap().unwrap();
        assert_eq!(read_feedback(flags, &f, 1, 2, 2).unwrap(), Some(refs));
    }

    proptest::proptest! {
        /// Any octets: an error or a datagram, never a panic; frames and feedback likewise.
        #[test]
        fn any_octets_decode_without_panic(octets in proptest::collection::vec(proptest::num::u8::ANY, 0..200), flags in 0u8..16) {
            if let Ok(d) = Datagram::decode(&octets) {
                proptest::prop_assert_eq!(d.encode(), octets.clone());
            }
            let _ = check_mpdu(&octets, 1, CENTER_ADDRESS);
            let _ = read_feedback(flags, &octets, 0, 3, 2);
            let _ = read_f32s(&octets, 2);
        }
    }
}
