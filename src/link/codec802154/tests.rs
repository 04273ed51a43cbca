//! Tests that run every codec of the module against the frame format: round trips of every
//! level, the specific rejections of the decoders, fuzzing with random and corrupted frames,
//! and error detection by the FCS. The helpers [`link`] and `all_codecs` are shared with the
//! tests of the submodules.
use super::*;
use crate::link::quantizer::Level;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

pub(super) fn link() -> LinkAddressing {
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

#[test]
fn acknowledgement_frame_sizes() {
    // The standard's example acknowledgment frame (2006 §7.2.1.9): a 3-octet MHR (Frame
    // Control 0x0002, Sequence Number 0x6a) and the 2-octet FCS, nothing else.
    let mhr = [0x02u8, 0x00, 0x6a];
    let fcs = crc16_kermit(&mhr).to_le_bytes();
    assert_eq!(ACK_MPDU_OCTETS, mhr.len() + fcs.len());
    assert_eq!(ACK_MPDU_OCTETS, 5);
    // On air with the 4-octet preamble, SFD and PHR: 11 octets, 88 bits.
    assert_eq!(ACK_PPDU_OCTETS, 11);
    assert_eq!(ACK_PPDU_BITS, 88);
}
