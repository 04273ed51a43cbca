//! External schemes: scheme kinds supplied at run time (the Python package's user-written
//! schemes), beside the built-in list [`super::SCHEMES`]. A kind is registered once with its
//! declaration (label, summary, parameters, bandwidth knob) and a builder that turns a scheme
//! table into a [`Scheme`]; from then on [`registry::find`] knows it, so scenario files
//! (`[[schemes]] kind = "my-scheme"`), `every_scheme` arenas, `--loss` copies and the
//! calibrator treat it as they treat a built-in kind, and the engine gives it the same truth,
//! noise, schedule and link. The core knows nothing of Python: the builder is a closure.
//!
//! Messages of an external scheme are the library's [`Message`]s, priced by the same rules
//! (32 bits per component for a measurement or an estimate; a payload's declared bits and the
//! 802.15.4 frame around it, [`payload_message`]).
//!
//! Registration leaks the declaration's strings (a registered kind lives as long as the
//! process, like the built-in list); registering a kind again replaces its builder.
use super::registry::{self, Applies, BuildContext, Knob, ParamDoc, ParamError, SchemeEntry};
use super::Scheme;
use crate::link::codec802154::{self, crc16_kermit, BROADCAST, FRAME_CONTROL};
use crate::link::Message;

pub use super::registry::RuntimeBuilder as Builder;

/// A scheme kind declared at run time.
pub struct Declaration {
    /// The `kind` of scenario files; must not be a built-in kind.
    pub kind: String,
    /// Default curve label.
    pub label: String,
    pub summary: String,
    /// (name, default as text, meaning) of each parameter.
    pub params: Vec<(String, String, String)>,
    /// The bandwidth knob (its name among the parameters), for calibration.
    pub knob: Option<Knob>,
    /// The example table (TOML) `every_scheme` arenas use.
    pub example: String,
    pub builder: Builder,
}

fn leak(s: String) -> &'static str {
    Box::leak(s.into_boxed_str())
}

/// Never called: an external entry is built by [`build`] (a function pointer cannot hold the
/// builder); kept so that an external [`SchemeEntry`] is a whole entry.
fn unreachable_build(_: toml::Table, _: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    Err(ParamError::whole(
        "an external scheme kind is built through registry::build_entry",
    ))
}

/// Registers (or replaces) an external kind. Refuses a built-in kind's name and a knob that is
/// not one of the declared parameters.
pub fn register(d: Declaration) -> Result<(), String> {
    if super::SCHEMES.iter().any(|e| e.kind == d.kind) {
        return Err(format!(
            "{:?} is a built-in scheme kind; give your scheme another name",
            d.kind
        ));
    }
    if d.kind.is_empty() || d.kind.chars().any(|c| c.is_whitespace() || c == '"') {
        return Err(format!(
            "scheme kind {:?}: expected a non-empty name without spaces or quotes",
            d.kind
        ));
    }
    if let Some(k) = &d.knob {
        if !d.params.iter().any(|(n, _, _)| n == k.name) {
            return Err(format!(
                "scheme {}: the knob {:?} is not one of its parameters",
                d.kind, k.name
            ));
        }
    }
    let params: Vec<ParamDoc> = d
        .params
        .into_iter()
        .map(|(name, default, meaning)| ParamDoc {
            name: leak(name),
            values: "number",
            default: leak(default),
            meaning: leak(meaning),
        })
        .collect();
    let entry: &'static SchemeEntry = Box::leak(Box::new(SchemeEntry {
        kind: leak(d.kind),
        label: leak(d.label),
        summary: leak(d.summary),
        params: Box::leak(params.into_boxed_slice()),
        knob: d.knob,
        applies: Applies::Any,
        build: unreachable_build,
        example: leak(d.example),
        missing_packet: "a missing packet reaches the center as nothing (Received::NotScheduled is not used; the center sees a silence): the scheme's own center decides",
    }));
    registry::register_runtime(entry, d.builder);
    Ok(())
}

/// Removes an external kind; whether it was registered.
pub fn unregister(kind: &str) -> bool {
    registry::unregister_runtime(kind)
}

/// Every registered external kind, in registration order.
pub fn kinds() -> Vec<&'static str> {
    registry::runtime_kinds()
}

/// Whether `kind` is a registered external kind.
pub fn is_external(kind: &str) -> bool {
    registry::find_runtime(kind).is_some()
}

/// Octets of an 802.15.4 MPDU at most (aMaxPHYPacketSize, 2006 §6.4.1).
pub use crate::link::codec802154::MAX_MPDU_OCTETS;

/// Octets of the MAC header before a payload frame's payload.
const HEADER: usize = codec802154::MHR_OCTETS;

/// A raw payload of `payload_bits` bits (`payload` holds them in its first
/// ceil(bits / 8) octets, least significant bit first; the rest of the last octet zero) in an
/// 802.15.4 data frame: the MAC header of [`codec802154`] (PAN 0, broadcast destination,
/// source address `sensor`), the payload octets and the FCS. Priced as the network prices any
/// message: `payload_bits` payload bits and 8 x (11 + ceil(bits / 8)) frame bits
/// ([`codec802154::mpdu_bits_for_payload`]).
pub fn payload_message(payload: &[u8], payload_bits: u32, sensor: u16) -> Result<Message, String> {
    let octets = (payload_bits as usize).div_ceil(8);
    // aMaxPHYPacketSize: an MPDU holds at most 127 octets, 11 of them MAC header and FCS.
    // Fragmentation is not modelled, so a larger payload is refused rather than priced as one
    // frame no radio could send.
    let most = MAX_MPDU_OCTETS - HEADER - codec802154::FCS_OCTETS;
    if octets > most {
        return Err(format!(
            "a payload of {octets} octets ({payload_bits} bits) does not fit one IEEE 802.15.4 frame (at most {most} payload octets in its {MAX_MPDU_OCTETS}-octet MPDU); fragmentation is not priced: send fewer bits per message"
        ));
    }
    if payload.len() != octets {
        return Err(format!(
            "a payload of {payload_bits} bits needs {octets} octets, got {}",
            payload.len()
        ));
    }
    if !payload_bits.is_multiple_of(8) {
        let spare = payload[octets - 1] >> (payload_bits % 8);
        if spare != 0 {
            return Err(format!(
                "a payload of {payload_bits} bits has bits set beyond its last bit"
            ));
        }
    }
    let mut f = Vec::with_capacity(HEADER + octets + codec802154::FCS_OCTETS);
    f.extend_from_slice(&FRAME_CONTROL.to_le_bytes());
    f.push(0);
    f.extend_from_slice(&0u16.to_le_bytes());
    f.extend_from_slice(&BROADCAST.to_le_bytes());
    f.extend_from_slice(&sensor.to_le_bytes());
    f.extend_from_slice(payload);
    let fcs = crc16_kermit(&f);
    f.extend_from_slice(&fcs.to_le_bytes());
    Ok(Message::Frame {
        octets: f,
        payload_bits,
    })
}

/// The payload octets of a frame made by [`payload_message`]; `None` when the frame is too
/// short or its FCS does not match.
pub fn frame_payload(frame: &[u8]) -> Option<&[u8]> {
    let fcs = codec802154::FCS_OCTETS;
    if frame.len() < HEADER + fcs {
        return None;
    }
    let body = frame.len() - fcs;
    let received = u16::from_le_bytes([frame[body], frame[body + 1]]);
    (crc16_kermit(&frame[..body]) == received).then(|| &frame[HEADER..body])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scheme::registry;
    use std::sync::Arc;

    #[test]
    fn payload_frames_are_priced_as_any_message() {
        let m = payload_message(&[0b101], 3, 2).unwrap();
        assert_eq!(m.bits(), 3);
        assert_eq!(m.frame_bits(), codec802154::mpdu_bits_for_payload(3));
        let Message::Frame { octets, .. } = &m else {
            panic!("a frame")
        };
        assert_eq!(frame_payload(octets), Some(&[0b101u8][..]));
        let mut bad = octets.clone();
        bad[HEADER] ^= 1;
        assert_eq!(frame_payload(&bad), None);
        assert!(payload_message(&[0b1000], 3, 0).is_err());
        assert!(payload_message(&[1, 2], 3, 0).is_err());
        // 116 payload octets fill a 127-octet MPDU; one more does not fit any 802.15.4 frame.
        let full = payload_message(&[0; 116], 8 * 116, 0).unwrap();
        assert_eq!(full.frame_bits(), 8 * 127);
        let e = payload_message(&[0; 1000], 8000, 0).unwrap_err();
        assert!(
            e.contains("1000 octets") && e.contains("does not fit"),
            "{e}"
        );
        assert!(payload_message(&[0; 117], 8 * 117, 0).is_err());
    }

    const SYSTEM: &str = r#"
name = "t"
trials = 4
steps = 20
seed = 3
[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1
[prior]
mean = [0.0, 1.0]
cov_diag = [1.0, 1.0]
[[sensors]]
H = [[1.0, 0.0]]
R = [[1.0]]
[[sensors]]
H = [[0.0, 1.0]]
R = [[2.0]]
"#;

    /// A kind registered at run time runs in scenarios beside the built-in ones, on the same
    /// data, listed or in an `every_scheme` arena (after the built-in kinds).
    #[test]
    fn a_registered_kind_runs_beside_the_built_ins() {
        let kind = "test-external-sod";
        let builder: Builder = Arc::new(|table, cx| {
            (registry::find("send-on-delta").expect("built-in").build)(table, cx)
        });
        register(Declaration {
            kind: kind.into(),
            label: "External SOD".into(),
            summary: "send-on-delta, registered at run time".into(),
            params: vec![("delta".into(), "1.0".into(), String::new())],
            knob: Some(Knob::threshold("delta")),
            example: "delta = 1.0".into(),
            builder,
        })
        .unwrap();
        assert_eq!(registry::find(kind).unwrap().knob.unwrap().name, "delta");
        let listed = format!(
            "{SYSTEM}[[schemes]]\nkind = \"send-on-delta\"\ndelta = 0.5\n[[schemes]]\nkind = \"{kind}\"\ndelta = 0.5\n"
        );
        let exp = crate::scenario::build::load(&listed, "t.toml").unwrap();
        let sums = crate::engine::runner::run(&exp, Default::default(), &|_| {}).unwrap();
        let s = crate::metrics::results::summarize(&exp, &sums);
        let (a, b) = (&s.schemes[0], &s.schemes[1]);
        assert_eq!(b.name, "External SOD");
        assert_eq!(a.mse, b.mse);
        assert_eq!(a.bits_per_step, b.bits_per_step);
        let arena = format!(
            "{}[[schemes]]\nkind = \"{kind}\"\ndelta = 1.0\n",
            SYSTEM.replace("seed = 3\n", "seed = 3\nevery_scheme = true\n")
        );
        let exp = crate::scenario::build::load(&arena, "t.toml").unwrap();
        assert_eq!(exp.variants.last().unwrap().kind, kind);
        assert!(exp.variants.len() > 2);
        assert!(unregister(kind));
        assert!(registry::find(kind).is_none());
        assert!(crate::scenario::build::load(&listed, "t.toml").is_err());
    }

    #[test]
    fn built_in_names_are_refused() {
        let d = Declaration {
            kind: "send-on-delta".into(),
            label: "x".into(),
            summary: String::new(),
            params: vec![],
            knob: None,
            example: String::new(),
            builder: Arc::new(|_, _| Err(ParamError::whole("no"))),
        };
        assert!(register(d).unwrap_err().contains("built-in"));
    }
}
