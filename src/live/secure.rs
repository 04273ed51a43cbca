//! One end of a secured live link (issue 41): what a node or the center does to every MPDU it
//! sends and receives when the scenario sets a `[security]` level. It seals outgoing frames with
//! the next counter of its own [`CounterStore`] and opens incoming ones: FCS, security fields,
//! MIC under the key of the sensor concerned, then the replay check against the highest counter
//! accepted from that sender. What it drops it counts by kind ([`Dropped`]), for `live.log`.
//!
//! Keys: sensor i's frames, and the center's feedback to sensor i, are secured under
//! `KeyRing::for_sensor(i)` (the sensor's own key, else the network key). Addresses: the center
//! is short address 0, sensor i is i + 1, and each one's EUI-64 (the nonce's source) is
//! [`eui64`] of it.
//!
//! Not wired into the processes yet: `center`, `node` and `live` refuse a secured scenario
//! (`live::check_live`) until they call this.
use crate::link::security::ccm_star::{eui64, open, secure, SecurityError};
use crate::link::security::counter::CounterStore;
use crate::link::security::keys::{FrameCounters, KeyRing};
use crate::link::security::SecuritySpec;

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

/// Why [`SecureEnd::open_frame`] dropped a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    Security(SecurityError),
    Replayed { counter: u32, last: u32 },
}

/// A node's or the center's end of the secured link.
#[derive(Debug)]
pub struct SecureEnd {
    spec: SecuritySpec,
    keys: KeyRing,
    /// This end's short address (its EUI-64 is the nonce's source of what it sends).
    address: u16,
    counters: CounterStore,
    accepted: FrameCounters,
    dropped: Dropped,
}

impl SecureEnd {
    /// The end at short `address` securing at `spec` with `keys`, its own counters in
    /// `counters`.
    pub fn new(spec: SecuritySpec, keys: KeyRing, address: u16, counters: CounterStore) -> Self {
        SecureEnd {
            spec,
            keys,
            address,
            counters,
            accepted: FrameCounters::default(),
            dropped: Dropped::default(),
        }
    }

    /// `mpdu` secured under sensor `sensor`'s key (the sender's own for a node, the recipient's
    /// for the center's feedback) with this end's next frame counter.
    pub fn seal_frame(&mut self, mpdu: &[u8], sensor: usize) -> Result<Vec<u8>, String> {
        let key = self
            .keys
            .for_sensor(sensor)
            .ok_or_else(|| format!("no key for sensor {sensor}"))?;
        let counter = self.counters.take()?;
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
        if !self.accepted.is_fresh(from, opened.counter) {
            self.dropped.replayed += 1;
            let last = self.accepted.last(from).unwrap_or(0);
            return Err(Refused::Replayed {
                counter: opened.counter,
                last,
            });
        }
        self.accepted.accept(from, opened.counter);
        Ok(opened.frame)
    }

    /// What this end dropped so far.
    pub fn dropped(&self) -> Dropped {
        self.dropped
    }

    /// The highest counter accepted from `from` (for a journal that must keep it across a
    /// restart).
    pub fn last_accepted(&self, from: u16) -> Option<u32> {
        self.accepted.last(from)
    }

    /// Restores the highest counter accepted from `from` (a restarted center, from its
    /// journal): frames at or below it are replays from then on.
    pub fn restore_accepted(&mut self, from: u16, counter: u32) {
        self.accepted.accept(from, counter);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
}
