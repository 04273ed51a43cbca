//! CCM* against published vectors, frame sizes per level, round trips and refusals, key files.
use super::ccm_star::{self, eui64, nonce, open, secure, source_short, SecurityError};
use super::keys::{FrameCounters, Key, KeyRing};
use super::*;
use crate::link::codec802154::crc16_kermit;

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

/// IEEE 802.15.4-2006 Annex C.2.1: a beacon frame secured at level 2 (MIC-64), key C0..CF,
/// sender ACDE480000000001, frame counter 5: the MIC over the 26 octets of header and payload.
#[test]
fn annex_c_beacon_frame_mic_64() {
    let key = Key::new(std::array::from_fn(|i| 0xC0 + i as u8));
    let n = nonce(
        hex("AC DE 48 00 00 00 00 01").try_into().unwrap(),
        5,
        SecurityLevel::Mic64,
    );
    assert_eq!(n.to_vec(), hex("AC DE 48 00 00 00 00 01 00 00 00 05 02"));
    let a = hex("08 D0 84 21 43 01 00 00 00 00 48 DE AC 02 05 00 00 00 55 CF 00 00 51 52 53 54");
    let mic = ccm_star::seal(&key, &n, SecurityLevel::Mic64, &a, &mut []);
    assert_eq!(mic, hex("22 3B C1 EC 84 1A B5 53"));
    assert!(ccm_star::unseal(&key, &n, SecurityLevel::Mic64, &a, &mut [], &mic).is_ok());
    let mut forged = a.clone();
    forged[25] ^= 1;
    assert_eq!(
        ccm_star::unseal(&key, &n, SecurityLevel::Mic64, &forged, &mut [], &mic),
        Err(SecurityError::Forged)
    );
}

/// IEEE 802.15.4-2006 Annex C.2.3: a MAC command frame at level 6 (ENC-MIC-64): the command
/// payload CE encrypts to D8, the MIC over the 29 octets of header.
#[test]
fn annex_c_command_frame_enc_mic_64() {
    let key = Key::new(std::array::from_fn(|i| 0xC0 + i as u8));
    let n = nonce(eui64(1), 5, SecurityLevel::EncMic64);
    assert_eq!(n.to_vec(), hex("AC DE 48 00 00 00 00 01 00 00 00 05 06"));
    let a = hex(
        "2B DC 84 21 43 02 00 00 00 00 48 DE AC FF FF 01 00 00 00 00 48 DE AC 06 05 00 00 00 01",
    );
    let mut m = [0xCE];
    let mic = ccm_star::seal(&key, &n, SecurityLevel::EncMic64, &a, &mut m);
    assert_eq!(
        (m.to_vec(), mic.clone()),
        (vec![0xD8], hex("4F DE 52 90 61 F9 C6 F1"))
    );
    ccm_star::unseal(&key, &n, SecurityLevel::EncMic64, &a, &mut m, &mic).unwrap();
    assert_eq!(m, [0xCE]);
}

/// NIST SP 800-38C, Appendix C, Example 1 (a 7-octet nonce and a 4-octet tag): the `ccm`
/// crate is CCM as published, outside 802.15.4's nonce too.
#[test]
fn nist_sp800_38c_example_1() {
    use ccm::aead::{AeadInOut, KeyInit};
    use ccm::consts::{U4, U7};
    let key: [u8; 16] = std::array::from_fn(|i| 0x40 + i as u8);
    let c = ccm::Ccm::<aes::Aes128, U4, U7>::new(&key.into());
    let n: [u8; 7] = std::array::from_fn(|i| 0x10 + i as u8);
    let a: [u8; 8] = std::array::from_fn(|i| i as u8);
    let mut p: [u8; 4] = std::array::from_fn(|i| 0x20 + i as u8);
    let tag = c
        .encrypt_inout_detached(&n.into(), &a, (&mut p[..]).into())
        .unwrap();
    assert_eq!(
        [p.to_vec(), tag.to_vec()].concat(),
        hex("71 62 01 5B 4D AC 25 5D")
    );
}

/// A data frame of the live wire: frame control 0x8841, sequence 7, PAN 0x0003, to the center
/// (0x0000) from sensor 0 (0x0001), `payload`, FCS.
fn data_frame(payload: &[u8]) -> Vec<u8> {
    let mut f = vec![0x41, 0x88, 7, 0x03, 0x00, 0x00, 0x00, 0x01, 0x00];
    f.extend_from_slice(payload);
    let fcs = crc16_kermit(&f);
    f.extend_from_slice(&fcs.to_le_bytes());
    f
}

fn spec(level: SecurityLevel, key_id_mode: KeyIdMode) -> SecuritySpec {
    SecuritySpec {
        level,
        key_id_mode,
        secure_feedback: true,
    }
}

const MODES: [KeyIdMode; 4] = [
    KeyIdMode::Implicit,
    KeyIdMode::Index,
    KeyIdMode::Source4,
    KeyIdMode::Source8,
];

/// The octets the standard gives: a 4-octet payload (15 octets unsecured) grows to 24/25
/// (levels 1 and 5, key identifier mode 0/1), 28/29 (2 and 6), 36/37 (3 and 7); modes 2 and 3
/// add 4 and 8 more. Every level, mode and payload length round-trips, and the secured frame
/// is what [`SecuritySpec::overhead_octets`] prices.
#[test]
fn each_level_adds_exactly_the_standards_octets_and_round_trips() {
    let key = Key::new([7; 16]);
    let frame = data_frame(&[1, 2, 3, 4]);
    assert_eq!(frame.len(), 15);
    let want = |level: SecurityLevel, mode: KeyIdMode| {
        let base = match level.mic_octets() {
            4 => 24,
            8 => 28,
            16 => 36,
            _ => 15,
        };
        base + [0, 1, 5, 9][mode.code() as usize]
    };
    for level in SecurityLevel::ALL.into_iter().skip(1) {
        for mode in MODES {
            let s = spec(level, mode);
            for payload_len in [0, 1, 4, 12, 40] {
                let payload: Vec<u8> = (0..payload_len).map(|i| i as u8 * 3).collect();
                let plain = data_frame(&payload);
                let secured = secure(&plain, &s, &key, eui64(1), 42).unwrap();
                assert_eq!(secured.len(), plain.len() + s.overhead_octets(), "{s:?}");
                assert_eq!(source_short(&secured), Some(1));
                let opened = open(&secured, &s, &key, eui64(1)).unwrap();
                assert_eq!((opened.frame, opened.counter), (plain.clone(), 42), "{s:?}");
                // Encrypted levels hide the payload; MIC-only levels carry it in clear.
                let at = 9 + s.aux_header_octets();
                let carried = &secured[at..at + payload_len];
                assert_eq!(
                    carried == &payload[..],
                    !level.encrypts() || payload_len == 0
                );
            }
            let secured = secure(&frame, &s, &key, eui64(1), 1).unwrap();
            assert_eq!(secured.len(), want(level, mode), "{s:?}");
            assert_eq!(s.overhead_bits(), 8 * (want(level, mode) - 15) as u64);
        }
    }
    let none = SecuritySpec::default();
    assert_eq!(secure(&frame, &none, &key, eui64(1), 1).unwrap(), frame);
    assert_eq!(none.overhead_bits(), 0);
}

/// What a receiver refuses, by kind: a flipped bit anywhere (FCS), a forged MIC with a valid
/// FCS, another key, another sender's address in the nonce, another level, a truncated frame,
/// an unsecured frame.
#[test]
fn forged_altered_truncated_and_wrongly_keyed_frames_are_refused() {
    let key = Key::new([9; 16]);
    let s = spec(SecurityLevel::EncMic32, KeyIdMode::Index);
    let secured = secure(&data_frame(&[5, 6, 7, 8]), &s, &key, eui64(1), 3).unwrap();
    let refix_fcs = |mut f: Vec<u8>| {
        let n = f.len() - 2;
        let fcs = crc16_kermit(&f[..n]);
        f[n..].copy_from_slice(&fcs.to_le_bytes());
        f
    };
    for i in 0..secured.len() - 2 {
        let mut bad = secured.clone();
        bad[i] ^= 0x10;
        assert_eq!(
            open(&bad, &s, &key, eui64(1)),
            Err(SecurityError::BadFcs),
            "octet {i}"
        );
        let kind = open(&refix_fcs(bad), &s, &key, eui64(1)).unwrap_err();
        assert!(
            matches!(
                kind,
                SecurityError::Forged | SecurityError::WrongSecurity | SecurityError::Unsecured
            ) || (i < 2 && kind == SecurityError::Unsupported),
            "octet {i}: {kind:?}"
        );
    }
    let other = Key::new([8; 16]);
    assert_eq!(
        open(&secured, &s, &other, eui64(1)),
        Err(SecurityError::Forged)
    );
    assert_eq!(
        open(&secured, &s, &key, eui64(2)),
        Err(SecurityError::Forged)
    );
    let s64 = spec(SecurityLevel::EncMic64, KeyIdMode::Index);
    assert_eq!(
        open(&secured, &s64, &key, eui64(1)),
        Err(SecurityError::WrongSecurity)
    );
    let short = refix_fcs(secured[..12].to_vec());
    assert!(matches!(
        open(&short, &s, &key, eui64(1)),
        Err(SecurityError::Truncated(_) | SecurityError::WrongSecurity)
    ));
    assert_eq!(
        open(&data_frame(&[1, 2, 3, 4]), &s, &key, eui64(1)),
        Err(SecurityError::Unsecured)
    );
    assert_eq!(
        open(&secured[..3], &s, &key, eui64(1)),
        Err(SecurityError::Truncated(3))
    );
    // Too long once secured: 116 octets of payload fill an unsecured frame.
    let full = data_frame(&[0; 116]);
    assert_eq!(
        secure(&full, &s, &key, eui64(1), 1),
        Err(SecurityError::TooLong(127 + 10))
    );
}

#[test]
fn a_frame_counter_not_above_the_last_accepted_is_a_replay() {
    let mut c = FrameCounters::default();
    assert!(c.is_fresh(1, 0));
    c.accept(1, 5);
    assert!(!c.is_fresh(1, 5) && !c.is_fresh(1, 4) && c.is_fresh(1, 6));
    assert!(c.is_fresh(2, 0), "counters are per sender");
    c.accept(1, 3);
    assert_eq!(c.last(1), Some(5));
}

#[test]
fn scenario_names_of_the_levels_and_the_refusal_of_enc() {
    let parse = |t: &str| toml::from_str::<SecuritySpec>(t);
    let s = parse("level = \"enc-mic-128\"\nkey_id_mode = \"source8\"").unwrap();
    assert_eq!(
        (s.level.code(), s.key_id_mode.code(), s.secure_feedback),
        (7, 3, true)
    );
    assert_eq!(s.overhead_octets(), 14 + 16);
    assert_eq!(parse("").unwrap(), SecuritySpec::default());
    assert!(SecuritySpec::default().secure_feedback);
    let enc = parse("level = \"enc\"").unwrap_err().to_string();
    assert!(
        enc.contains("level 4") && enc.contains("authenticates nothing"),
        "{enc}"
    );
    let typo = parse("level = \"mic32\"").unwrap_err().to_string();
    assert!(typo.contains("mic-32"), "{typo}");
    assert!(parse("levle = \"mic-32\"").is_err());
    for l in SecurityLevel::ALL {
        assert_eq!(SecurityLevel::from_code(l.code()), Some(l));
    }
    assert_eq!(SecurityLevel::from_code(4), None);
}

#[test]
fn key_files_are_parsed_and_refused_with_the_file_named() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str, mode: u32| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(mode)).unwrap();
        p
    };
    let hexkey = "c0c1c2c3c4c5c6c7c8c9cacbcccdcecf";
    let ok = write(
        "ok.key",
        &format!(
            "# comment\nnetwork {hexkey}\nsensor 1 {}\n",
            "ab".repeat(16)
        ),
        0o600,
    );
    let ring = KeyRing::load(&ok, 3).unwrap();
    assert_eq!(ring.for_sensor(0).unwrap().bytes()[0], 0xC0);
    assert_eq!(ring.for_sensor(1).unwrap().bytes()[0], 0xAB);
    assert_eq!(
        format!("{:?}", ring.for_sensor(0).unwrap()),
        "Key(<hidden>)"
    );
    let cases = [
        (
            "open.key",
            format!("network {hexkey}\n"),
            0o644,
            "chmod 600",
        ),
        (
            "short.key",
            "network c0c1c2\n".to_string(),
            0o600,
            "32 hexadecimal digits",
        ),
        (
            "nonhex.key",
            format!("network {}zz\n", &hexkey[..30]),
            0o600,
            "not two hexadecimal",
        ),
        (
            "twice.key",
            format!("sensor 0 {hexkey}\nsensor 0 {hexkey}\nsensor 1 {hexkey}\nsensor 2 {hexkey}\n"),
            0o600,
            "named twice",
        ),
        (
            "missing.key",
            format!("sensor 0 {hexkey}\n"),
            0o600,
            "no key for sensor 1",
        ),
        ("junk.key", "hello\n".to_string(), 0o600, "line 1"),
        ("empty.key", "# nothing\n".to_string(), 0o600, "no key"),
    ];
    for (name, text, mode, says) in cases {
        let p = write(name, &text, mode);
        let e = KeyRing::load(&p, 3).unwrap_err();
        assert!(e.contains(name) && e.contains(says), "{name}: {e}");
        assert!(!e.contains(hexkey), "{name}: the key is printed: {e}");
    }
    let fresh = dir.path().join("fresh.key");
    let made = KeyRing::write_fresh(&fresh).unwrap();
    let mode = std::fs::metadata(&fresh).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    assert_eq!(KeyRing::load(&fresh, 5).unwrap(), made);
    assert_ne!(
        KeyRing::write_fresh(&dir.path().join("other.key")).unwrap(),
        made
    );
}

/// A spec written out (the scenario as run, `summary.json`) reads back the same.
#[test]
fn a_spec_round_trips_through_toml_by_name() {
    for level in SecurityLevel::ALL {
        for mode in MODES {
            let s = spec(level, mode);
            let text = toml::to_string(&s).unwrap();
            assert!(text.contains(&format!("\"{}\"", level.name())), "{text}");
            assert_eq!(toml::from_str::<SecuritySpec>(&text).unwrap(), s);
        }
    }
}

/// Every codec's frame (Zhang et al.'s dynamic codes and the fixed-length baselines, each of
/// their levels that sends) and the live wire's frames of 1 to 29 readings grow by exactly
/// [`SecuritySpec::overhead_octets`] at every level, and open back to themselves; a secured frame
/// still decodes with its codec once opened.
#[test]
fn every_codecs_frames_grow_by_the_standards_octets() {
    use crate::link::codec802154::{
        DynamicCodec, FixedLengthCodec, LevelCodec, LinkAddressing, Strategy,
    };
    use crate::link::quantizer::Level;
    let link = LinkAddressing::new(0x0003, 0x0000).unwrap();
    let mut codecs: Vec<Box<dyn LevelCodec>> = vec![Box::new(FixedLengthCodec::sign(link))];
    for s in [Strategy::FlagZone, Strategy::NoFlagZone] {
        for c in 1..=3 {
            codecs.push(Box::new(DynamicCodec::new(s, c, link).unwrap()));
        }
    }
    for c in [1, 3, 8] {
        codecs.push(Box::new(FixedLengthCodec::msechu(c, link).unwrap()));
        codecs.push(Box::new(FixedLengthCodec::you(c, link).unwrap()));
    }
    let key = Key::new([3; 16]);
    let mut frames: Vec<(Vec<u8>, Option<usize>)> = Vec::new();
    for (j, codec) in codecs.iter().enumerate() {
        for l in 0..codec.levels() {
            if let Some(f) = codec.encode(Level::new(l as u16), 1, 9).unwrap() {
                frames.push((f, Some(j)));
            }
        }
    }
    for m in 1..=29 {
        let payload = crate::live::wire::f32_payload((0..m).map(|i| i as f64 * 0.5));
        frames.push((
            crate::live::wire::mpdu(4, 0x0000, 0x0001, &payload).unwrap(),
            None,
        ));
    }
    for level in SecurityLevel::ALL.into_iter().skip(1) {
        for mode in MODES {
            let s = spec(level, mode);
            for (plain, codec) in &frames {
                let room = crate::link::codec802154::MAX_MPDU_OCTETS;
                match secure(plain, &s, &key, eui64(1), 77) {
                    Ok(secured) => {
                        assert_eq!(secured.len(), plain.len() + s.overhead_octets());
                        let opened = open(&secured, &s, &key, eui64(1)).unwrap().frame;
                        assert_eq!(&opened, plain);
                        if let Some(j) = codec {
                            assert!(codecs[*j].decode(&opened).is_ok());
                        }
                    }
                    Err(SecurityError::TooLong(n)) => {
                        assert!(n > room && plain.len() + s.overhead_octets() == n)
                    }
                    Err(e) => panic!("{s:?}: {e}"),
                }
            }
        }
    }
}
