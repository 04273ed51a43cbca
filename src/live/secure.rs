//! One end of a secured live link (issue 41): what a node or the center does to every datagram
//! it sends and receives when the scenario sets a `[security]` level.
//!
//! Two layers, both AES-CCM* under the key of the sensor concerned:
//!
//! - **The 802.15.4 frame** (a reading, an estimate, a codec's frame, the feedback) is secured
//!   as the standard says ([`SecureEnd::seal_frame`], [`SecureEnd::open_frame`]): auxiliary
//!   security header, MIC, encryption at the `enc-` levels. These are the octets a radio sends
//!   and the simulation prices.
//! - **The envelope** of every datagram ([`super::wire`]: who, which step, "done", "hello",
//!   catch-up) gets a MIC of its own ([`SecureEnd::seal_datagram`]): the envelope stands for
//!   what a deployment's MAC and schedule tell for free, but in a live run it travels beside
//!   the radio frame, and a forged "done, no reading" would change an estimate as surely as a
//!   forged reading. Sealed: the datagram, then the sender's frame counter (4 octets, little
//!   endian), then a MIC of the level's length over both. Not priced: it is not on air in a
//!   deployment.
//!
//! Both layers take their counters from the sender's one [`CounterStore`] (never a counter
//! twice under one key); their nonces cannot meet, since the envelope's sets the top bit of the
//! nonce's level octet, which an 802.15.4 nonce never does. The receiver keeps the highest
//! counter accepted per sender for each layer (the replay check) and saves them to a file
//! beside the key ([`LiveKeys::seen_path`]) once per step, so a restarted center or node, or a
//! new run under the same key, refuses what was captured before.
//!
//! With `secure_feedback = false` the downlink (announcements, feedback, the end of the run)
//! goes unsecured, as the scenario asked: the nodes then trust any announcement.
//!
//! Keys: sensor i's frames, and the center's to sensor i, are secured under
//! `KeyRing::for_sensor(i)` (the sensor's own key, else the network key). Addresses: the center
//! is short address 0, sensor i is i + 1, and each one's EUI-64 (the nonce's source) is
//! [`eui64`] of it. What each end dropped it counts by kind ([`Dropped`]), for `live.log`.
use crate::link::security::ccm_star::{eui64, nonce, open, seal, secure, unseal, SecurityError};
use crate::link::security::counter::CounterStore;
use crate::link::security::keys::{FrameCounters, KeyRing};
use crate::link::security::SecuritySpec;
use std::path::{Path, PathBuf};

/// Frames dropped, by why.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Too short for the security fields the network uses.
    pub truncated: u64,
    /// FCS wrong (corrupted on the way).
    pub bad_fcs: u64,
    /// Not secured, or secured at another level or key identifier.
    pub unsecured: u64,
    /// MIC wrong: forged, altered with the FCS fixed, or under another key.
    pub forged: u64,
    /// MIC right but the counter not above the last accepted from that sender.
    pub replayed: u64,
}

impl Dropped {
    /// Every kind with its count, for a log line.
    pub fn kinds(&self) -> [(&'static str, u64); 5] {
        [
            ("truncated", self.truncated),
            ("bad_fcs", self.bad_fcs),
            ("unsecured", self.unsecured),
            ("forged", self.forged),
            ("replayed", self.replayed),
        ]
    }

    pub fn total(&self) -> u64 {
        self.kinds().iter().map(|(_, n)| n).sum()
    }
}

/// Why [`SecureEnd::open_frame`] or [`SecureEnd::open_datagram`] dropped what it was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    Security(SecurityError),
    Replayed { counter: u32, last: u32 },
}

/// The top bit of the nonce's last octet: set for an envelope's MIC, never by 802.15.4.
const ENVELOPE_NONCE: u8 = 0x80;
/// Octets of the frame counter after a sealed datagram.
const COUNTER_OCTETS: usize = 4;

/// Octets a sealed datagram carries after the envelope: the counter and the MIC.
pub fn seal_octets(spec: &SecuritySpec) -> usize {
    COUNTER_OCTETS + spec.level.mic_octets()
}

/// The datagram inside sealed `octets`, unverified: what a relay (the channel proxy) or a
/// node deciding whether a reading is due may read, and nothing more. `octets` itself when too
/// short.
pub fn unsealed_part<'o>(octets: &'o [u8], spec: &SecuritySpec) -> &'o [u8] {
    &octets[..octets.len().saturating_sub(seal_octets(spec))]
}

/// A node's or the center's end of the secured link.
#[derive(Debug)]
pub struct SecureEnd {
    spec: SecuritySpec,
    keys: KeyRing,
    /// This end's short address (its EUI-64 is the nonce's source of what it sends).
    address: u16,
    counters: CounterStore,
    /// Highest counters accepted, per sender: of 802.15.4 frames, of envelopes.
    frames: FrameCounters,
    envelopes: FrameCounters,
    dropped: Dropped,
    /// Where the accepted counters are saved ([`SecureEnd::save_seen`]), if anywhere.
    seen: Option<PathBuf>,
    /// Whether the 802.15.4 frames' counters are saved too: at the center, yes; at a node,
    /// no: the center sends the steps a restarted node missed again with their feedback frames
    /// as first secured (older counters), which the node must take again. Its envelopes'
    /// counters, saved, still refuse a replayed announcement.
    persist_frames: bool,
    /// When the accepted counters were last saved.
    saved_at: Option<std::time::Instant>,
}

/// How often [`SecureEnd::save_seen`] writes, unless forced: a file write per datagram would
/// cost more than the run.
const SAVE_EVERY: std::time::Duration = std::time::Duration::from_millis(500);

impl SecureEnd {
    /// The end at short `address` securing at `spec` with `keys`, its own counters in
    /// `counters`.
    pub fn new(spec: SecuritySpec, keys: KeyRing, address: u16, counters: CounterStore) -> Self {
        SecureEnd {
            spec,
            keys,
            address,
            counters,
            frames: FrameCounters::default(),
            envelopes: FrameCounters::default(),
            dropped: Dropped::default(),
            seen: None,
            persist_frames: address == super::wire::CENTER_ADDRESS,
            saved_at: None,
        }
    }

    /// The security the end applies.
    pub fn spec(&self) -> &SecuritySpec {
        &self.spec
    }

    /// Whether what the center sends down is secured (`secure_feedback`).
    pub fn secures_downlink(&self) -> bool {
        self.spec.secure_feedback
    }

    fn key(&self, sensor: usize) -> Result<&crate::link::security::keys::Key, String> {
        self.keys
            .for_sensor(sensor)
            .ok_or_else(|| format!("no key for sensor {sensor}"))
    }

    /// `mpdu` secured under sensor `sensor`'s key (the sender's own for a node, the recipient's
    /// for the center's feedback) with this end's next frame counter.
    pub fn seal_frame(&mut self, mpdu: &[u8], sensor: usize) -> Result<Vec<u8>, String> {
        let counter = self.counters.take()?;
        let key = self.key(sensor)?;
        secure(mpdu, &self.spec, key, eui64(self.address), counter).map_err(|e| e.to_string())
    }

    /// The unsecured MPDU of `frame` from short address `from` under sensor `sensor`'s key, if
    /// it verifies and is not a replay; else the reason, counted.
    pub fn open_frame(
        &mut self,
        frame: &[u8],
        from: u16,
        sensor: usize,
    ) -> Result<Vec<u8>, Refused> {
        let Some(key) = self.keys.for_sensor(sensor) else {
            self.dropped.forged += 1;
            return Err(Refused::Security(SecurityError::Forged));
        };
        let opened = match open(frame, &self.spec, key, eui64(from)) {
            Ok(o) => o,
            Err(e) => {
                match e {
                    SecurityError::Truncated(_) => self.dropped.truncated += 1,
                    SecurityError::BadFcs => self.dropped.bad_fcs += 1,
                    SecurityError::Unsecured
                    | SecurityError::WrongSecurity
                    | SecurityError::Unsupported
                    | SecurityError::TooLong(_) => self.dropped.unsecured += 1,
                    SecurityError::Forged => self.dropped.forged += 1,
                }
                return Err(Refused::Security(e));
            }
        };
        Self::fresh(&mut self.frames, &mut self.dropped, from, opened.counter)?;
        Ok(opened.frame)
    }

    /// The replay check: accepts `counter` from `from` in `table` if it is above the last.
    fn fresh(
        table: &mut FrameCounters,
        dropped: &mut Dropped,
        from: u16,
        counter: u32,
    ) -> Result<(), Refused> {
        if !table.is_fresh(from, counter) {
            dropped.replayed += 1;
            let last = table.last(from).unwrap_or(0);
            return Err(Refused::Replayed { counter, last });
        }
        table.accept(from, counter);
        Ok(())
    }

    /// The nonce of an envelope's MIC.
    fn envelope_nonce(&self, source: u16, counter: u32) -> [u8; 13] {
        let mut n = nonce(eui64(source), counter, self.spec.level);
        n[12] |= ENVELOPE_NONCE;
        n
    }

    /// `datagram` sealed under sensor `sensor`'s key: the datagram, this end's next frame
    /// counter, the MIC over both.
    pub fn seal_datagram(&mut self, datagram: &[u8], sensor: usize) -> Result<Vec<u8>, String> {
        let counter = self.counters.take()?;
        let nonce = self.envelope_nonce(self.address, counter);
        let mut out = Vec::with_capacity(datagram.len() + seal_octets(&self.spec));
        out.extend_from_slice(datagram);
        out.extend_from_slice(&counter.to_le_bytes());
        let mic = seal(self.key(sensor)?, &nonce, self.spec.level, &out, &mut []);
        out.extend_from_slice(&mic);
        Ok(out)
    }

    /// The datagram inside sealed `octets` from short address `from`, if its MIC verifies
    /// under sensor `sensor`'s key and its counter is fresh; else the reason, counted.
    pub fn open_datagram<'o>(
        &mut self,
        octets: &'o [u8],
        from: u16,
        sensor: usize,
    ) -> Result<&'o [u8], Refused> {
        let mic_octets = self.spec.level.mic_octets();
        if octets.len() < COUNTER_OCTETS + mic_octets {
            self.dropped.truncated += 1;
            return Err(Refused::Security(SecurityError::Truncated(octets.len())));
        }
        let (signed, mic) = octets.split_at(octets.len() - mic_octets);
        let (datagram, c) = signed.split_at(signed.len() - COUNTER_OCTETS);
        let counter = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        let nonce = self.envelope_nonce(from, counter);
        let verified = self
            .keys
            .for_sensor(sensor)
            .is_some_and(|key| unseal(key, &nonce, self.spec.level, signed, &mut [], mic).is_ok());
        if !verified {
            self.dropped.forged += 1;
            return Err(Refused::Security(SecurityError::Forged));
        }
        Self::fresh(&mut self.envelopes, &mut self.dropped, from, counter)?;
        Ok(datagram)
    }

    /// What this end dropped so far.
    pub fn dropped(&self) -> Dropped {
        self.dropped
    }

    /// The highest frame counter accepted from `from`.
    pub fn last_accepted(&self, from: u16) -> Option<u32> {
        self.frames.last(from)
    }

    /// Restores the highest frame counter accepted from `from`: frames at or below it are
    /// replays from then on.
    pub fn restore_accepted(&mut self, from: u16, counter: u32) {
        self.frames.accept(from, counter);
    }

    /// Keeps the accepted counters in `path` from now on, starting from what it holds (a
    /// missing file is an end that has accepted nothing yet under this key).
    pub fn remember_in(&mut self, path: &Path) -> Result<(), String> {
        let shown = path.display();
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let mut lines = text.lines();
                if lines.next() != Some(SEEN_HEADER) {
                    return Err(format!(
                        "{shown}: not a file of accepted frame counters (expected \"{SEEN_HEADER}\")"
                    ));
                }
                for (n, line) in lines.enumerate() {
                    let bad = || {
                        format!("{shown}, line {}: expected \"frame|envelope ADDRESS COUNTER\", got {line:?}", n + 2)
                    };
                    let f: Vec<&str> = line.split_whitespace().collect();
                    let [layer, source, counter] = f[..] else {
                        return Err(bad());
                    };
                    let source: u16 = source.parse().map_err(|_| bad())?;
                    let counter: u32 = counter.parse().map_err(|_| bad())?;
                    match layer {
                        "frame" if self.persist_frames => self.frames.accept(source, counter),
                        "frame" => {}
                        "envelope" => self.envelopes.accept(source, counter),
                        _ => return Err(bad()),
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(format!("{shown}: cannot read it: {e}")),
        }
        self.seen = Some(path.to_path_buf());
        Ok(())
    }

    /// Saves the accepted counters where [`SecureEnd::remember_in`] said (a temporary file
    /// renamed over the old one: a crash leaves one or the other, whole), at most every
    /// half a second unless `force` (the end of a run).
    ///
    /// What a lag costs: after a crash, a datagram of the crashed run's last half second may
    /// be taken once more by a restarted end. Within one run that is harmless: the envelope's
    /// MIC binds the datagram to its variant and step, so a replay can only bring a genuine
    /// datagram into its own step, as a retransmission would (and a copy of what is already
    /// there is a duplicate). Across runs under one key it is the window a new run leaves
    /// open; `hushfuse live` makes a fresh key for every run.
    pub fn save_seen(&mut self, force: bool) -> Result<(), String> {
        let Some(path) = &self.seen else {
            return Ok(());
        };
        let now = std::time::Instant::now();
        if !force
            && self
                .saved_at
                .is_some_and(|t| now.duration_since(t) < SAVE_EVERY)
        {
            return Ok(());
        }
        self.saved_at = Some(now);
        let mut text = format!("{SEEN_HEADER}\n");
        let frames = FrameCounters::default();
        let frames = if self.persist_frames {
            &self.frames
        } else {
            &frames
        };
        for (layer, table) in [("frame", frames), ("envelope", &self.envelopes)] {
            for (s, c) in table.entries() {
                text.push_str(&format!("{layer} {s} {c}\n"));
            }
        }
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        std::fs::write(&tmp, text)
            .and_then(|_| std::fs::rename(&tmp, path))
            .map_err(|e| format!("{}: cannot write it: {e}", path.display()))
    }
}

/// First line of a file of accepted counters.
const SEEN_HEADER: &str = "hushfuse accepted frame counters v1";

/// A live run's key file and the state kept beside it: each end's frame counters
/// (`KEY.counter-A`, A its short address) and the counters it accepted (`KEY.seen-A`).
#[derive(Debug, Clone)]
pub struct LiveKeys {
    pub spec: SecuritySpec,
    pub keys: KeyRing,
    pub path: PathBuf,
}

impl LiveKeys {
    /// The key file at `path` for a run of `sensors` sensors at `spec` (refused as
    /// [`KeyRing::load`] says).
    pub fn load(path: &Path, spec: SecuritySpec, sensors: usize) -> Result<Self, String> {
        Ok(LiveKeys {
            spec,
            keys: KeyRing::load(path, sensors)?,
            path: path.to_path_buf(),
        })
    }

    fn beside(key: &Path, what: &str, address: u16) -> PathBuf {
        let mut name = key.as_os_str().to_owned();
        name.push(format!(".{what}-{address}"));
        PathBuf::from(name)
    }

    /// The frame counter file of the end at short `address`.
    pub fn counter_path(&self, address: u16) -> PathBuf {
        Self::beside(&self.path, "counter", address)
    }

    /// The accepted-counters file of the end at short `address`.
    pub fn seen_path(&self, address: u16) -> PathBuf {
        Self::beside(&self.path, "seen", address)
    }

    /// The end at short `address`: its counters continued from its file (refused when
    /// missing: see [`CounterStore::open`]), its accepted counters from its file.
    pub fn end(&self, address: u16) -> Result<SecureEnd, String> {
        let counters = CounterStore::open(&self.counter_path(address)).map_err(|e| {
            format!("{e}; a key's counter files are made with it (`hushfuse keygen`), and copied with it to the node that uses them")
        })?;
        let mut end = SecureEnd::new(self.spec, self.keys.clone(), address, counters);
        end.remember_in(&self.seen_path(address))?;
        Ok(end)
    }

    /// A fresh network key at `path` (owner-only, refused if the file exists) and the frame
    /// counter files, from 0, of the center and of `sensors` sensors beside it.
    pub fn create(path: &Path, sensors: usize) -> Result<(), String> {
        KeyRing::write_fresh(path)?;
        for address in 0..=sensors {
            let a = u16::try_from(address).map_err(|_| format!("{sensors} sensors"))?;
            CounterStore::create(&Self::beside(path, "counter", a))?;
        }
        Ok(())
    }

    /// Removes the key at `path` and everything kept beside it (a run that makes a fresh key
    /// in its folder replaces the last one's).
    pub fn remove(path: &Path) -> Result<(), String> {
        let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
            return Ok(());
        };
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let prefix = format!("{}.", name.to_string_lossy());
        let Ok(entries) = std::fs::read_dir(dir) else {
            return Ok(());
        };
        for e in entries.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if n == name.to_string_lossy() || n.starts_with(&prefix) {
                std::fs::remove_file(e.path())
                    .map_err(|err| format!("cannot remove {}: {err}", e.path().display()))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::security::ccm_star::nonce;
    use crate::link::security::keys::Key;
    use crate::link::security::{KeyIdMode, SecurityLevel};
    use crate::live::wire::{f32_payload, mpdu, sensor_address, CENTER_ADDRESS};

    fn spec() -> SecuritySpec {
        SecuritySpec {
            level: SecurityLevel::EncMic64,
            key_id_mode: KeyIdMode::Index,
            secure_feedback: true,
        }
    }

    fn end(dir: &std::path::Path, name: &str, address: u16, keys: &KeyRing) -> SecureEnd {
        let counters = CounterStore::create(&dir.join(name)).unwrap();
        SecureEnd::new(spec(), keys.clone(), address, counters)
    }

    /// A node's readings reach the center; a replay, a bit flip, a frame under another key, an
    /// unsecured frame and a truncated one are dropped and counted by kind; the center's
    /// feedback reaches the node, and forged feedback does not.
    #[test]
    fn frames_cross_and_attacks_are_counted_by_kind() {
        let dir = tempfile::tempdir().unwrap();
        let keys = KeyRing::network(Key::new([0x42; 16]));
        let mut node = end(dir.path(), "node", sensor_address(0), &keys);
        let mut center = end(dir.path(), "center", CENTER_ADDRESS, &keys);
        let reading = mpdu(1, CENTER_ADDRESS, sensor_address(0), &f32_payload([1.5])).unwrap();
        let sealed = node.seal_frame(&reading, 0).unwrap();
        let from = sensor_address(0);
        assert_eq!(center.open_frame(&sealed, from, 0).unwrap(), reading);
        assert!(matches!(
            center.open_frame(&sealed, from, 0),
            Err(Refused::Replayed {
                counter: 0,
                last: 0
            })
        ));
        let mut flipped = node.seal_frame(&reading, 0).unwrap();
        flipped[12] ^= 0x01;
        assert!(center.open_frame(&flipped, from, 0).is_err());
        let attacker_keys = KeyRing::network(Key::new([0x43; 16]));
        let mut attacker = end(dir.path(), "attacker", sensor_address(0), &attacker_keys);
        let forged = attacker.seal_frame(&reading, 0).unwrap();
        assert_eq!(
            center.open_frame(&forged, from, 0),
            Err(Refused::Security(SecurityError::Forged))
        );
        assert!(center.open_frame(&reading, from, 0).is_err());
        assert!(center.open_frame(&sealed[..3], from, 0).is_err());
        let d = center.dropped();
        assert_eq!(
            (d.replayed, d.bad_fcs, d.forged, d.unsecured, d.truncated),
            (1, 1, 1, 1, 1)
        );
        assert_eq!(d.total(), 5);
        // A fresh frame after all that still gets through, and the counter moved on.
        let next = node.seal_frame(&reading, 0).unwrap();
        assert!(center.open_frame(&next, from, 0).is_ok());
        assert_eq!(center.last_accepted(from), Some(2));

        let feedback = mpdu(
            1,
            sensor_address(0),
            CENTER_ADDRESS,
            &f32_payload([0.1, 0.2]),
        )
        .unwrap();
        let sealed = center.seal_frame(&feedback, 0).unwrap();
        assert_eq!(
            node.open_frame(&sealed, CENTER_ADDRESS, 0).unwrap(),
            feedback
        );
        let forged = attacker.seal_frame(&feedback, 0).unwrap();
        assert!(node.open_frame(&forged, CENTER_ADDRESS, 0).is_err());
        assert_eq!(node.dropped().forged, 1);
    }

    /// A restarted center that restores the counters it accepted refuses the old frames; one
    /// that did not would take them (why the journal must keep them).
    #[test]
    fn a_restarted_center_refuses_replays_once_it_restores_its_counters() {
        let dir = tempfile::tempdir().unwrap();
        let keys = KeyRing::network(Key::new([7; 16]));
        let mut node = end(dir.path(), "node", sensor_address(2), &keys);
        let mut center = end(dir.path(), "center", CENTER_ADDRESS, &keys);
        let reading = mpdu(3, CENTER_ADDRESS, sensor_address(2), &f32_payload([4.0])).unwrap();
        let captured: Vec<Vec<u8>> = (0..3)
            .map(|_| node.seal_frame(&reading, 2).unwrap())
            .collect();
        for f in &captured {
            center.open_frame(f, sensor_address(2), 2).unwrap();
        }
        let last = center.last_accepted(sensor_address(2)).unwrap();
        let counters = CounterStore::open(&dir.path().join("center")).unwrap();
        let mut restarted = SecureEnd::new(spec(), keys.clone(), CENTER_ADDRESS, counters);
        assert!(restarted
            .open_frame(&captured[0], sensor_address(2), 2)
            .is_ok());
        let counters = CounterStore::open(&dir.path().join("center")).unwrap();
        let mut restored = SecureEnd::new(spec(), keys, CENTER_ADDRESS, counters);
        restored.restore_accepted(sensor_address(2), last);
        for f in &captured {
            assert!(matches!(
                restored.open_frame(f, sensor_address(2), 2),
                Err(Refused::Replayed { .. })
            ));
        }
    }

    /// An envelope sealed by a node opens at the center to the same octets; a replay, a bit
    /// flip anywhere, another key and a cut datagram are refused and counted by kind.
    #[test]
    fn sealed_datagrams_open_once_and_only_whole() {
        let dir = tempfile::tempdir().unwrap();
        let keys = KeyRing::network(Key::new([0x11; 16]));
        let mut node = end(dir.path(), "node", sensor_address(1), &keys);
        let mut center = end(dir.path(), "center", CENTER_ADDRESS, &keys);
        let d = crate::live::wire::Datagram::new(crate::live::wire::Kind::Done, 1, 0, 3).encode();
        let sealed = node.seal_datagram(&d, 1).unwrap();
        assert_eq!(sealed.len(), d.len() + seal_octets(&spec()));
        assert_eq!(unsealed_part(&sealed, &spec()), &d[..]);
        let from = sensor_address(1);
        assert_eq!(center.open_datagram(&sealed, from, 1).unwrap(), &d[..]);
        assert!(matches!(
            center.open_datagram(&sealed, from, 1),
            Err(Refused::Replayed { .. })
        ));
        for at in 0..sealed.len() {
            let fresh = node.seal_datagram(&d, 1).unwrap();
            let mut flipped = fresh.clone();
            flipped[at] ^= 0x10;
            assert_eq!(
                center.open_datagram(&flipped, from, 1),
                Err(Refused::Security(SecurityError::Forged)),
                "a flip at octet {at}"
            );
        }
        let mut other = end(
            dir.path(),
            "other",
            sensor_address(1),
            &KeyRing::network(Key::new([0x12; 16])),
        );
        assert!(center
            .open_datagram(&other.seal_datagram(&d, 1).unwrap(), from, 1)
            .is_err());
        assert!(center.open_datagram(&sealed[..5], from, 1).is_err());
        let dropped = center.dropped();
        assert_eq!(
            (dropped.replayed, dropped.forged, dropped.truncated),
            (1, sealed.len() as u64 + 1, 1)
        );
        // The envelope's nonce is apart from a frame's: the same counter under the same key
        // gives another MIC than an 802.15.4 frame's would.
        let n = node.envelope_nonce(sensor_address(1), 7);
        assert_eq!(n[12] & 0x7f, spec().level.code());
        assert_ne!(n, nonce(eui64(sensor_address(1)), 7, spec().level));
    }

    /// Saved and restored, the center refuses both layers' old counters; a node keeps only
    /// the envelopes' (the center re-sends old feedback frames to a node that catches up).
    #[test]
    fn accepted_counters_survive_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let keys = KeyRing::network(Key::new([0x21; 16]));
        let mut node = end(dir.path(), "node", sensor_address(0), &keys);
        let mut center = end(dir.path(), "center", CENTER_ADDRESS, &keys);
        let seen = dir.path().join("center.seen");
        center.remember_in(&seen).unwrap();
        let reading = mpdu(1, CENTER_ADDRESS, sensor_address(0), &f32_payload([1.0])).unwrap();
        let frame = node.seal_frame(&reading, 0).unwrap();
        let d = crate::live::wire::Datagram::new(crate::live::wire::Kind::Done, 0, 0, 1).encode();
        let sealed = node.seal_datagram(&d, 0).unwrap();
        let from = sensor_address(0);
        center.open_frame(&frame, from, 0).unwrap();
        center.open_datagram(&sealed, from, 0).unwrap();
        center.save_seen(true).unwrap();
        let counters = CounterStore::open(&dir.path().join("center")).unwrap();
        let mut restarted = SecureEnd::new(spec(), keys.clone(), CENTER_ADDRESS, counters);
        restarted.remember_in(&seen).unwrap();
        assert!(matches!(
            restarted.open_frame(&frame, from, 0),
            Err(Refused::Replayed { .. })
        ));
        assert!(matches!(
            restarted.open_datagram(&sealed, from, 0),
            Err(Refused::Replayed { .. })
        ));

        let node_seen = dir.path().join("node.seen");
        node.remember_in(&node_seen).unwrap();
        let feedback = mpdu(1, sensor_address(0), CENTER_ADDRESS, &f32_payload([0.5])).unwrap();
        let fb = center.seal_frame(&feedback, 0).unwrap();
        let announce = center.seal_datagram(&d, 0).unwrap();
        node.open_frame(&fb, CENTER_ADDRESS, 0).unwrap();
        node.open_datagram(&announce, CENTER_ADDRESS, 0).unwrap();
        node.save_seen(true).unwrap();
        let counters = CounterStore::open(&dir.path().join("node")).unwrap();
        let mut again = SecureEnd::new(spec(), keys, sensor_address(0), counters);
        again.remember_in(&node_seen).unwrap();
        assert!(again.open_frame(&fb, CENTER_ADDRESS, 0).is_ok());
        assert!(matches!(
            again.open_datagram(&announce, CENTER_ADDRESS, 0),
            Err(Refused::Replayed { .. })
        ));
        // A file that is not one is refused, naming it.
        std::fs::write(&node_seen, "junk\n").unwrap();
        let e = again.remember_in(&node_seen).unwrap_err();
        assert!(e.contains("node.seen"), "{e}");
    }
}
