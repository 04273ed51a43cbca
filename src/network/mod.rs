//! Delivery between sensors and the fusion center. The network wraps every transmission and
//! counts messages and bits, so no scheme can forget to count.
use crate::link::codec802154::ACK_PPDU_BITS;
use crate::link::{Received, Transmission};

pub mod aggregate;
pub mod channel;
pub mod graph;
pub mod radio;
pub mod topology;

use channel::Fate;

/// Counters of one delivery round (one time step).
///
/// With retransmission (`arq`), `messages` stays the packets the sensors decided to send (one
/// per sensor that sent: the scheme's rate), while `bits` and `frame_bits` count every attempt
/// (each went on air, and the radio paid for it); the attempts after the first are
/// `retransmissions`. The acknowledgements are the receiver's frames, counted apart
/// (`ack_frames`, `ack_bits`) and not in `downlink_bits`, which stays the scheme's feedback.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Traffic {
    /// Number of sensors that sent a message (packets, not attempts).
    pub messages: u64,
    /// Payload bits of those messages, once per attempt.
    pub bits: u64,
    /// Bits of the 802.15.4 MAC frames that carry them, once per attempt.
    pub frame_bits: u64,
    /// Bits the fusion center sent back to sensors (feedback).
    pub downlink_bits: u64,
    /// Messages sent (and counted above) that the link lost.
    pub lost: u64,
    /// Messages sent that the link delivers late, within the center's horizon (fused when
    /// they arrive).
    pub late: u64,
    /// Messages sent that the link delivers later than the horizon: dropped.
    pub dropped_late: u64,
    /// Feedback packets the downlink lost (one per sensor that missed this step's feedback).
    pub downlink_lost: u64,
    /// ARQ: attempts after the first, over all messages.
    pub retransmissions: u64,
    /// ARQ: attempts that arrived after the message had already arrived (their ACK was lost);
    /// the center discards them.
    pub duplicates: u64,
    /// ARQ: acknowledgment frames the center sent, one per attempt that arrived.
    pub ack_frames: u64,
    /// ARQ: bits of those acknowledgments on air, 802.15.4 PHY headers included
    /// ([`crate::link::codec802154::ACK_PPDU_BITS`] = 88 each).
    pub ack_bits: u64,
    /// Which sensors sent a message: bit i for sensor i ([`sensor_bit`]; sensors from
    /// [`MASKED_SENSORS`] on are not recorded). With [`Traffic::scheduled`] it gives each
    /// sensor's send probability, whose entropy a send-or-stay-silent decision carries
    /// (`r_eff_per_step` in `summary.json`).
    pub senders: u128,
    /// Which sensors were scheduled (allowed to send and with a reading): bit i for sensor i.
    pub scheduled: u128,
}

/// Sensors whose send decisions [`Traffic::senders`] records (the bits of a `u128`).
pub const MASKED_SENSORS: usize = 128;

impl Traffic {
    /// Data frames on air on the one-hop star: every message's every attempt.
    pub fn star_frames(&self) -> u64 {
        self.messages + self.retransmissions
    }

    /// 802.15.4 security's price (`[security]`, [`crate::link::security`]): each of the step's
    /// `data_frames` on air (every attempt; on a multi-hop network every hop's, from the
    /// nodes' counters; on the star [`Traffic::star_frames`]) carries the auxiliary security
    /// header and the MIC, and so does the step's one feedback frame when the feedback is
    /// secured. ACKs are never secured (2006 §7.2.2.3). The payload bits, hence R_eff, do not
    /// change: security adds no information. The engine's loop applies it to every step it
    /// outputs, the runner's sinks to the fast paths' steps.
    pub fn secure(&mut self, security: &crate::link::security::SecuritySpec, data_frames: u64) {
        if !security.is_secured() {
            return;
        }
        self.frame_bits += data_frames * security.overhead_bits();
        if self.downlink_bits > 0 {
            self.downlink_bits += security.feedback_overhead_bits();
        }
    }

    /// A frame of `payload_bits` in a MAC frame of `mac_bits` that met fate `f`: every attempt
    /// on air costs its bits, and its retries, duplicates and acknowledgements are counted.
    pub fn add_frames(&mut self, f: &Fate, payload_bits: u64, mac_bits: u64) {
        let attempts = u64::from(f.attempts());
        self.bits += attempts * payload_bits;
        self.frame_bits += attempts * mac_bits;
        self.retransmissions += u64::from(f.retries);
        self.duplicates += u64::from(f.duplicates());
        self.ack_frames += u64::from(f.acks);
        self.ack_bits += u64::from(f.acks) * ACK_PPDU_BITS;
    }
}

/// Reals of an estimate (or an information pair) of an `n`-dimensional state sent whole: the
/// vector and the n(n+1)/2 distinct entries of the symmetric matrix.
pub fn estimate_reals(n: usize) -> u64 {
    (n + n * (n + 1) / 2) as u64
}

/// Sensor `i`'s bit in [`Traffic::senders`] and [`Traffic::scheduled`]; 0 (not recorded) from
/// [`MASKED_SENSORS`] on.
pub fn sensor_bit(i: usize) -> u128 {
    if i < MASKED_SENSORS {
        1u128 << i
    } else {
        0
    }
}

/// The mask of sensors `0..n` (every sensor of `n`, up to [`MASKED_SENSORS`]).
pub fn all_sensors(n: usize) -> u128 {
    if n >= MASKED_SENSORS {
        u128::MAX
    } else {
        (1u128 << n) - 1
    }
}

/// Which sensors may talk at a step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Schedule {
    /// Every sensor may send at every step.
    #[default]
    All,
    /// Round-robin: at step k only sensor (k - 1) mod N may send (Geng et al.'s protocol,
    /// eq. (4)-(5): the token `h_k = mod(k - 1, N) + 1`).
    RoundRobin,
    /// Round-robin with `granted` sensor slots per step, `0 < granted <= N` (see
    /// [`Schedule::round_robin`]): the token of Geng et al.'s (5) moves on by `granted`
    /// sensors a step instead of one, so slots `floor((k - 1) g) .. floor(k g) - 1` (taken mod
    /// N) send at step k. `granted = 1` is [`Schedule::RoundRobin`], `granted = N` every
    /// sensor at every step, `granted = 1/T` one sensor every T steps.
    RoundRobinGranted(f64),
}

impl Schedule {
    /// Round-robin granting `granted` sensor slots per step: [`Schedule::RoundRobin`] (the
    /// paper's, one per step) at exactly 1, else [`Schedule::RoundRobinGranted`].
    pub fn round_robin(granted: f64) -> Self {
        if granted == 1.0 {
            Schedule::RoundRobin
        } else {
            Schedule::RoundRobinGranted(granted)
        }
    }

    /// Whether sensor `i` of `n` may send at step `k` (k starts at 1).
    pub fn allows(self, k: usize, i: usize, n: usize) -> bool {
        match self {
            Schedule::All => true,
            Schedule::RoundRobin => (k.saturating_sub(1)) % n.max(1) == i,
            Schedule::RoundRobinGranted(g) => {
                let n = n.max(1);
                // The token's slots of step k: [a, b), slot j is sensor j mod n.
                let a = (k.saturating_sub(1) as f64 * g).floor() as usize;
                let b = ((k as f64 * g).floor() as usize).max(a);
                b - a >= n || a + (i % n + n - a % n) % n < b
            }
        }
    }
}

/// Turns the sensors' transmissions into the fusion center's inbox and counts the traffic.
/// `inbox` is reused across steps so the loop does not allocate.
pub fn deliver(
    transmissions: impl IntoIterator<Item = Transmission>,
    inbox: &mut Vec<Received>,
) -> Traffic {
    inbox.clear();
    let mut traffic = Traffic::default();
    for (i, t) in transmissions.into_iter().enumerate() {
        if let Transmission::Send(m) = &t {
            traffic.senders |= sensor_bit(i);
            traffic.messages += 1;
            traffic.bits += m.bits();
            traffic.frame_bits += m.frame_bits();
        }
        inbox.push(t.into());
    }
    traffic
}

/// [`deliver`] over a link whose slot of sensor i has the fate `fate(i)`: a message that went on
/// air [`Fate::attempts`] times costs its bits and frame that many times, and its retries,
/// duplicates and acknowledgements are counted (see [`Traffic`]). Which messages the center
/// receives is the link layer's business; here every message is put in the inbox. With fates
/// of no retransmission (`arq` absent) the counts are [`deliver`]'s.
pub fn deliver_attempts(
    transmissions: impl IntoIterator<Item = Transmission>,
    inbox: &mut Vec<Received>,
    fate: impl Fn(usize) -> Fate,
) -> Traffic {
    deliver_sequenced(transmissions, inbox, fate, 0)
}

/// [`deliver_attempts`] with a `sequence_bits`-bit sequence number on every packet (the
/// scheme entry's `sequence_bits`): every attempt costs [`Message::bits_with_sequence`] payload
/// bits and the frame of that larger payload ([`Message::frame_bits_with_sequence`], which may
/// add an octet). This is the one place a sequence number is priced, whatever the scheme. With
/// 0 bits, [`deliver_attempts`]'s counts; with 0 bits and fates of no retransmission,
/// [`deliver`]'s.
///
/// [`Message::bits_with_sequence`]: crate::link::Message::bits_with_sequence
/// [`Message::frame_bits_with_sequence`]: crate::link::Message::frame_bits_with_sequence
pub fn deliver_sequenced(
    transmissions: impl IntoIterator<Item = Transmission>,
    inbox: &mut Vec<Received>,
    fate: impl Fn(usize) -> Fate,
    sequence_bits: u32,
) -> Traffic {
    inbox.clear();
    let mut traffic = Traffic::default();
    for (i, t) in transmissions.into_iter().enumerate() {
        if let Transmission::Send(m) = &t {
            traffic.senders |= sensor_bit(i);
            traffic.messages += 1;
            traffic.add_frames(
                &fate(i),
                m.bits_with_sequence(sequence_bits),
                m.frame_bits_with_sequence(sequence_bits),
            );
        }
        inbox.push(t.into());
    }
    traffic
}

/// What a remote estimator holds for one sensor after a step under a zero-order hold
/// (Geng et al., eq. (4)-(5)): a fresh value, the last one held over, or nothing yet.
#[derive(Debug, Clone, PartialEq)]
pub enum Held {
    /// Arrived at this step (it was counted as a transmission by [`deliver`]).
    Fresh(crate::linalg::Vector),
    /// The value that arrived at step `since`, held over (`age` = k - since >= 1 steps ago).
    /// Not a transmission: nothing crossed the network for it.
    Held {
        value: crate::linalg::Vector,
        since: usize,
        age: usize,
    },
    /// Nothing has arrived from this sensor yet (before its first transmission).
    Empty,
}

impl Held {
    /// The value the estimator sees (fresh or held), if any.
    pub fn value(&self) -> Option<&crate::linalg::Vector> {
        match self {
            Held::Fresh(v) | Held::Held { value: v, .. } => Some(v),
            Held::Empty => None,
        }
    }
    /// Whether the value arrived at this step.
    pub fn is_fresh(&self) -> bool {
        matches!(self, Held::Fresh(_))
    }
}

/// Zero-order hold at the receiving side of a network (Geng et al., eq. (4)): for each sensor, the
/// last measurement that arrived is held until the next one. It sits after [`deliver`], so
/// traffic is counted once, when a value arrives; a held value is never a new transmission.
/// Only [`Received::Measurement`] refreshes the hold; silences and unscheduled steps keep it.
#[derive(Debug, Clone, Default)]
pub struct ZeroOrderHold {
    last: Vec<Option<(crate::linalg::Vector, usize)>>,
    held: Vec<Held>,
}

impl ZeroOrderHold {
    /// A hold for `n` sensors, empty.
    pub fn new(n: usize) -> Self {
        Self {
            last: vec![None; n],
            held: vec![Held::Empty; n],
        }
    }

    /// Takes the inbox of step `k` and returns, per sensor, what the estimator holds.
    pub fn step(&mut self, k: usize, inbox: &[Received]) -> &[Held] {
        if self.last.len() != inbox.len() {
            *self = Self::new(inbox.len());
        }
        for (i, r) in inbox.iter().enumerate() {
            self.held[i] = match r {
                Received::Measurement(z) => {
                    self.last[i] = Some((z.clone(), k));
                    Held::Fresh(z.clone())
                }
                _ => match &self.last[i] {
                    Some((v, since)) => Held::Held {
                        value: v.clone(),
                        since: *since,
                        age: k - since,
                    },
                    None => Held::Empty,
                },
            };
        }
        &self.held
    }

    /// What the estimator held after the last step.
    pub fn current(&self) -> &[Held] {
        &self.held
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Vector;
    use crate::link::Message;

    #[test]
    fn counts_messages_and_bits() {
        let tx = vec![
            Transmission::Silent,
            Transmission::Send(Message::Measurement(Vector::zeros(2))),
            Transmission::Send(Message::Estimate(Vector::zeros(6))),
        ];
        let mut inbox = Vec::new();
        let t = deliver(tx, &mut inbox);
        assert_eq!(t.messages, 2);
        assert_eq!(t.bits, 64 + 192);
        // (9 + 2) octets of MAC header and footer around 8 and 24 payload octets.
        assert_eq!(t.frame_bits, 8 * (11 + 8) + 8 * (11 + 24));
        assert_eq!(inbox[0], Received::Silent);
    }

    #[test]
    fn every_attempt_is_counted() {
        let z = || Transmission::Send(Message::Measurement(Vector::zeros(1)));
        let fates = [
            // Through at the second attempt, ACK heard.
            Fate {
                retries: 1,
                acks: 1,
                ..Fate::default()
            },
            Fate::default(),
            // Three attempts arrived, the first two ACKs were lost: two duplicates.
            Fate {
                retries: 2,
                acks: 3,
                ..Fate::default()
            },
        ];
        let mut inbox = Vec::new();
        let t = deliver_attempts([z(), Transmission::Silent, z()], &mut inbox, |i| fates[i]);
        assert_eq!(t.messages, 2);
        // 2 + 3 attempts of 32 payload bits in a 15-octet frame (11 + 4).
        assert_eq!((t.bits, t.frame_bits), (5 * 32, 5 * 8 * 15));
        assert_eq!((t.retransmissions, t.duplicates, t.ack_frames), (3, 2, 4));
        assert_eq!(t.ack_bits, 4 * 88);
        // A 5-bit sequence number: 32 + 5 payload bits need a fifth payload octet.
        let s = deliver_sequenced(
            [z(), Transmission::Silent, z()],
            &mut inbox,
            |i| fates[i],
            5,
        );
        assert_eq!((s.bits, s.frame_bits), (5 * 37, 5 * 8 * 16));
        // An 8-bit one on 64 bits (8 octets): one octet more; on a codec's frame, its own octet.
        let m = Message::Measurement(Vector::zeros(2));
        assert_eq!(
            (m.bits_with_sequence(8), m.frame_bits_with_sequence(8)),
            (72, 8 * 20)
        );
        let f = Message::Frame {
            octets: vec![0; 12],
            payload_bits: 2,
        };
        assert_eq!(
            (f.bits_with_sequence(3), f.frame_bits_with_sequence(3)),
            (5, 8 * 13)
        );
        // No retransmission: deliver's counts.
        let plain = deliver_attempts([z(), Transmission::Silent], &mut inbox, |_| Fate::default());
        assert_eq!(plain, deliver([z(), Transmission::Silent], &mut inbox));
    }

    #[test]
    fn round_robin_lets_one_sensor_talk() {
        let s = Schedule::RoundRobin;
        assert!(s.allows(1, 0, 3) && s.allows(2, 1, 3) && s.allows(4, 0, 3));
        assert!(!s.allows(1, 1, 3));
    }

    #[test]
    fn zero_order_hold_holds_without_counting() {
        let s = Schedule::RoundRobin;
        let mut hold = ZeroOrderHold::new(2);
        let mut inbox = Vec::new();
        let mut sent = 0;
        for k in 1..=5 {
            let tx = (0..2).map(|i| {
                if s.allows(k, i, 2) {
                    Transmission::Send(Message::Measurement(Vector::from_element(1, k as f64)))
                } else {
                    Transmission::Silent
                }
            });
            sent += deliver(tx, &mut inbox).messages;
            for (i, r) in inbox.iter_mut().enumerate() {
                if !s.allows(k, i, 2) {
                    *r = Received::NotScheduled;
                }
            }
            let h = hold.step(k, &inbox).to_vec();
            let other = k % 2; // the sensor not scheduled at k
            assert!(h[1 - other].is_fresh());
            if k == 1 {
                assert_eq!(h[1], Held::Empty);
            } else {
                assert_eq!(
                    h[other],
                    Held::Held {
                        value: Vector::from_element(1, (k - 1) as f64),
                        since: k - 1,
                        age: 1
                    }
                );
            }
        }
        // One transmission per step: the held values were not counted.
        assert_eq!(sent, 5);
    }
}
