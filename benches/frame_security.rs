//! Securing and verifying one 802.15.4 frame (issue 41): a sensor's frame of one 32-bit reading
//! (15 octets) at each MIC-only and encrypted level, `link::security::ccm_star::{secure, open}`
//! (AES-128 CCM* through RustCrypto's `aes` and `ccm`): `cargo bench --bench frame_security`.
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hushfuse::link::codec802154::crc16_kermit;
use hushfuse::link::security::ccm_star::{eui64, open, secure};
use hushfuse::link::security::keys::Key;
use hushfuse::link::security::{KeyIdMode, SecurityLevel, SecuritySpec};

/// The live wire's frame of one reading from sensor 0 to the center.
fn frame() -> Vec<u8> {
    let mut f = vec![
        0x41, 0x88, 7, 0x03, 0x00, 0x00, 0x00, 0x01, 0x00, 1, 2, 3, 4,
    ];
    let fcs = crc16_kermit(&f);
    f.extend_from_slice(&fcs.to_le_bytes());
    f
}

fn benches(c: &mut Criterion) {
    let key = Key::new([0x5a; 16]);
    let plain = frame();
    for level in [
        SecurityLevel::Mic32,
        SecurityLevel::Mic128,
        SecurityLevel::EncMic32,
        SecurityLevel::EncMic128,
    ] {
        let spec = SecuritySpec {
            level,
            key_id_mode: KeyIdMode::Index,
            secure_feedback: true,
        };
        let mut counter = 0u32;
        c.bench_function(
            &format!("secure one 15-octet frame, {}", level.name()),
            |b| {
                b.iter(|| {
                    counter = counter.wrapping_add(1);
                    secure(black_box(&plain), &spec, &key, eui64(1), counter).unwrap()
                })
            },
        );
        let secured = secure(&plain, &spec, &key, eui64(1), 9).unwrap();
        c.bench_function(
            &format!("verify one secured frame, {}", level.name()),
            |b| b.iter(|| open(black_box(&secured), &spec, &key, eui64(1)).unwrap()),
        );
    }
}

criterion_group!(security, benches);
criterion_main!(security);
