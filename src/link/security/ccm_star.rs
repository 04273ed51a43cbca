//! Securing and opening 802.15.4 frames with CCM* (2006 §7.6.3 and Annex B): AES-128 from
//! RustCrypto's `aes`, CCM from its `ccm` (CCM* with a MIC of 4, 8 or 16 octets is CCM; the
//! MIC-less level 4 is refused by [`super::SecurityLevel`]).
//!
//! [`secure`] takes an unsecured MPDU (as the codecs and the live wire write it: frame control,
//! sequence number, addressing, payload, FCS) and returns it secured; [`open`] returns the
//! unsecured MPDU again, so every decoder downstream stays as it is.
//!
//! - The **nonce** (13 octets, §7.6.3.2) is the sender's extended address (EUI-64, most
//!   significant octet first), the frame counter **big-endian**, and the level. Nodes talk with
//!   short addresses, so a receiver maps a short address to its EUI-64 ([`eui64`]: the
//!   documented table, which a capture tool needs too).
//! - The **authenticated data** is the MAC header with the auxiliary security header, plus the
//!   payload at the MIC-only levels; levels 5–7 encrypt the payload instead.
//! - The key identifier (modes 1–3) carries key index [`KEY_INDEX`]; the key source of modes 2
//!   and 3 is the center's EUI-64 (its low 4 octets for mode 2), little-endian on air.
use super::keys::Key;
use super::{KeyIdMode, SecurityLevel, SecuritySpec};
use crate::link::codec802154::{crc16_kermit, FCS_OCTETS};
use aes::Aes128;
use ccm::aead::{AeadInOut, KeyInit};
use ccm::consts::{U13, U16, U4, U8};
use ccm::Ccm;

/// The key index every secured frame names (key identifier modes 1–3).
pub const KEY_INDEX: u8 = 1;

/// The high octets of every node's EUI-64: `AC DE 48` is the IEEE's example OUI, used by the
/// standard's own test vectors (Annex C) and by no product.
pub const EUI64_PREFIX: [u8; 6] = [0xAC, 0xDE, 0x48, 0x00, 0x00, 0x00];

/// The EUI-64 of the node with short address `short` (most significant octet first):
/// `AC DE 48 00 00 00` then the short address big-endian. The center (short address 0) is
/// `ACDE480000000000`; sensor i (short address i + 1) ends in i + 1.
pub fn eui64(short: u16) -> [u8; 8] {
    let mut e = [0; 8];
    e[..6].copy_from_slice(&EUI64_PREFIX);
    e[6..].copy_from_slice(&short.to_be_bytes());
    e
}

/// Why a frame could not be secured or opened. The receiver counts each kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SecurityError {
    #[error("truncated frame ({0} octets)")]
    Truncated(usize),
    #[error("bad FCS")]
    BadFcs,
    #[error("frame control names a frame type or addressing this network does not use")]
    Unsupported,
    #[error("unsecured frame where the network secures every frame")]
    Unsecured,
    #[error("security level or key identifier other than the network's")]
    WrongSecurity,
    #[error("MIC does not verify (forged, altered or under another key)")]
    Forged,
    #[error("frame too long for 802.15.4 once secured ({0} octets > 127)")]
    TooLong(usize),
}

/// Security Enabled (frame control bit 3).
const SECURITY_ENABLED: u16 = 1 << 3;
/// The frame version field (bits 12–13).
const VERSION_MASK: u16 = 0b11 << 12;
/// Frame version 1 (802.15.4-2006).
const VERSION_2006: u16 = 1 << 12;

/// Octets of the MAC header before the auxiliary security header (frame control, sequence
/// number, addressing fields) that frame control `fc` describes (2006 §7.2.1).
pub fn addressed_header_octets(fc: u16) -> Result<usize, SecurityError> {
    let address = |mode: u16| match mode {
        0 => Ok(0),
        2 => Ok(2),
        3 => Ok(8),
        _ => Err(SecurityError::Unsupported),
    };
    let (dst_mode, src_mode) = ((fc >> 10) & 0b11, (fc >> 14) & 0b11);
    let pan_compression = fc & (1 << 6) != 0;
    let dst = address(dst_mode)? + if dst_mode != 0 { 2 } else { 0 };
    let src_pan = src_mode != 0 && !(pan_compression && dst_mode != 0);
    let src = address(src_mode)? + if src_pan { 2 } else { 0 };
    Ok(3 + dst + src)
}

/// The source short address of an MPDU with short source addressing, else None.
pub fn source_short(frame: &[u8]) -> Option<u16> {
    let fc = u16::from_le_bytes([*frame.first()?, *frame.get(1)?]);
    if (fc >> 14) & 0b11 != 2 {
        return None;
    }
    let end = addressed_header_octets(fc).ok()?;
    let at = frame.get(end - 2..end)?;
    Some(u16::from_le_bytes([at[0], at[1]]))
}

/// The auxiliary security header of `spec` with frame counter `counter`.
fn aux_header(spec: &SecuritySpec, counter: u32) -> Vec<u8> {
    let mut aux = Vec::with_capacity(spec.aux_header_octets());
    aux.push(spec.level.code() | (spec.key_id_mode.code() << 3));
    aux.extend_from_slice(&counter.to_le_bytes());
    let center = eui64(0);
    match spec.key_id_mode {
        KeyIdMode::Implicit => {}
        KeyIdMode::Index => aux.push(KEY_INDEX),
        KeyIdMode::Source4 => {
            let mut source = center[4..].to_vec();
            source.reverse();
            aux.extend_from_slice(&source);
            aux.push(KEY_INDEX);
        }
        KeyIdMode::Source8 => {
            let mut source = center.to_vec();
            source.reverse();
            aux.extend_from_slice(&source);
            aux.push(KEY_INDEX);
        }
    }
    aux
}

/// The CCM* nonce (§7.6.3.2): sender EUI-64 (most significant first), counter big-endian, level.
pub fn nonce(source: [u8; 8], counter: u32, level: SecurityLevel) -> [u8; 13] {
    let mut n = [0; 13];
    n[..8].copy_from_slice(&source);
    n[8..12].copy_from_slice(&counter.to_be_bytes());
    n[12] = level.code();
    n
}

/// CCM* of `m` in place (encrypted at levels 5–7, left as it is otherwise) with authenticated
/// data `a`; returns the MIC ([`SecurityLevel::mic_octets`] long).
pub fn seal(key: &Key, nonce: &[u8; 13], level: SecurityLevel, a: &[u8], m: &mut [u8]) -> Vec<u8> {
    macro_rules! with_tag {
        ($t:ty) => {{
            let c = Ccm::<Aes128, $t, U13>::new(key.bytes().into());
            let tag = c
                .encrypt_inout_detached(nonce.into(), a, m.into())
                .expect("802.15.4 frames are far below CCM's length limit");
            tag.to_vec()
        }};
    }
    match level.mic_octets() {
        4 => with_tag!(U4),
        8 => with_tag!(U8),
        16 => with_tag!(U16),
        _ => Vec::new(),
    }
}

/// The inverse of [`seal`]: `m` decrypted in place if the MIC verifies.
pub fn unseal(
    key: &Key,
    nonce: &[u8; 13],
    level: SecurityLevel,
    a: &[u8],
    m: &mut [u8],
    mic: &[u8],
) -> Result<(), SecurityError> {
    macro_rules! with_tag {
        ($t:ty) => {{
            let c = Ccm::<Aes128, $t, U13>::new(key.bytes().into());
            let tag = mic.try_into().map_err(|_| SecurityError::Forged)?;
            c.decrypt_inout_detached(nonce.into(), a, m.into(), tag)
                .map_err(|_| SecurityError::Forged)
        }};
    }
    match level.mic_octets() {
        4 => with_tag!(U4),
        8 => with_tag!(U8),
        16 => with_tag!(U16),
        _ => Ok(()),
    }
}

/// Split of an MPDU into its addressed header, payload and FCS, the FCS checked.
fn parts(frame: &[u8]) -> Result<(u16, usize), SecurityError> {
    if frame.len() < 3 + FCS_OCTETS {
        return Err(SecurityError::Truncated(frame.len()));
    }
    let (body, fcs) = frame.split_at(frame.len() - FCS_OCTETS);
    if crc16_kermit(body).to_le_bytes() != [fcs[0], fcs[1]] {
        return Err(SecurityError::BadFcs);
    }
    let fc = u16::from_le_bytes([frame[0], frame[1]]);
    let header = addressed_header_octets(fc)?;
    if header > body.len() {
        return Err(SecurityError::Truncated(frame.len()));
    }
    Ok((fc, header))
}

/// `frame` (an unsecured MPDU with a valid FCS, frame version 0) secured at `spec`'s level by
/// the node of EUI-64 `source` with frame counter `counter` under `key`. Unchanged when `spec`
/// is not secured.
pub fn secure(
    frame: &[u8],
    spec: &SecuritySpec,
    key: &Key,
    source: [u8; 8],
    counter: u32,
) -> Result<Vec<u8>, SecurityError> {
    if !spec.is_secured() {
        return Ok(frame.to_vec());
    }
    let (fc, header) = parts(frame)?;
    let secured_len = frame.len() + spec.overhead_octets();
    if secured_len > crate::link::codec802154::MAX_MPDU_OCTETS {
        return Err(SecurityError::TooLong(secured_len));
    }
    let fc = (fc & !VERSION_MASK) | SECURITY_ENABLED | VERSION_2006;
    let mut out = Vec::with_capacity(secured_len);
    out.extend_from_slice(&fc.to_le_bytes());
    out.extend_from_slice(&frame[2..header]);
    out.extend_from_slice(&aux_header(spec, counter));
    let a_end = out.len();
    out.extend_from_slice(&frame[header..frame.len() - FCS_OCTETS]);
    let n = nonce(source, counter, spec.level);
    let mic = if spec.level.encrypts() {
        let (a, m) = out.split_at_mut(a_end);
        seal(key, &n, spec.level, a, m)
    } else {
        seal(key, &n, spec.level, &out, &mut [])
    };
    out.extend_from_slice(&mic);
    let fcs = crc16_kermit(&out);
    out.extend_from_slice(&fcs.to_le_bytes());
    Ok(out)
}

/// A secured frame opened: the unsecured MPDU it carried (as [`secure`] was given it) and its
/// frame counter, for the receiver's replay check ([`super::keys::FrameCounters`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Opened {
    pub frame: Vec<u8>,
    pub counter: u32,
}

/// `frame` verified (FCS, security at `spec`'s level and key identifier, MIC under `key` from
/// the node of EUI-64 `source`) and returned unsecured. The replay check is the caller's.
pub fn open(
    frame: &[u8],
    spec: &SecuritySpec,
    key: &Key,
    source: [u8; 8],
) -> Result<Opened, SecurityError> {
    let (fc, header) = parts(frame)?;
    if fc & SECURITY_ENABLED == 0 || fc & VERSION_MASK != VERSION_2006 {
        return Err(SecurityError::Unsecured);
    }
    let (aux, mic) = (spec.aux_header_octets(), spec.level.mic_octets());
    let body_end = frame.len() - FCS_OCTETS;
    if header + aux + mic > body_end {
        return Err(SecurityError::Truncated(frame.len()));
    }
    let control = frame[header];
    let want = spec.level.code() | (spec.key_id_mode.code() << 3);
    if control != want {
        return Err(SecurityError::WrongSecurity);
    }
    let counter = u32::from_le_bytes(frame[header + 1..header + 5].try_into().expect("4"));
    if frame[header..header + aux] != aux_header(spec, counter)[..] {
        return Err(SecurityError::WrongSecurity);
    }
    let a_end = header + aux;
    let mut payload = frame[a_end..body_end - mic].to_vec();
    let tag = &frame[body_end - mic..body_end];
    let n = nonce(source, counter, spec.level);
    if spec.level.encrypts() {
        unseal(key, &n, spec.level, &frame[..a_end], &mut payload, tag)?;
    } else {
        unseal(key, &n, spec.level, &frame[..body_end - mic], &mut [], tag)?;
    }
    let plain_fc = fc & !(SECURITY_ENABLED | VERSION_MASK);
    let mut out = Vec::with_capacity(frame.len() - aux - mic);
    out.extend_from_slice(&plain_fc.to_le_bytes());
    out.extend_from_slice(&frame[2..header]);
    out.extend_from_slice(&payload);
    let fcs = crc16_kermit(&out);
    out.extend_from_slice(&fcs.to_le_bytes());
    Ok(Opened {
        frame: out,
        counter,
    })
}
