//! What the traffic costs a battery-powered IEEE 802.15.4 node: the energy its radio spends on
//! the frames it sends (lost ones too), on waiting for acknowledgements, on listening for the
//! fusion center's feedback and asleep, and how long a battery lasts at that rate. The `[radio]`
//! table of a scenario ([`RadioSpec`]); the defaults are the Texas Instruments (Chipcon) CC2420
//! transceiver's, datasheet SWRS041c ("CC2420 2.4 GHz IEEE 802.15.4 / ZigBee-ready RF
//! Transceiver"), Key Features and Electrical Specifications.
//!
//! # The model
//!
//! Energy is power times time, with the power of a state `P = V I` (supply voltage times the
//! datasheet's current of that state) and the time of a frame its bits on air over the bit rate
//! (250 kb/s: 4 µs a bit). In milliwatts and microseconds `P t` is in nanojoules; everything
//! here is reported in microjoules. Per step, over all sensors:
//!
//! * **Data frames** (every attempt, arrived or lost: the radio paid for each). A frame on air
//!   is its whole PPDU: the MAC frame that [`Traffic::frame_bits`] counts (MAC header, payload,
//!   FCS) plus the PHY synchronization header and PHR it does not count (preamble 4, SFD 1, PHR
//!   1 octet = [`PHY_OVERHEAD_BITS`], IEEE 802.15.4-2006 §6.3). Each attempt costs
//!   `P_tx (b / R + t_ta)`: its airtime and one RX→TX turnaround `t_ta` before it (12 symbol
//!   periods = 192 µs, the CC2420's turnaround and the standard's `aTurnaroundTime`, §6.4.1;
//!   after the clear channel assessment the radio switches from receive to transmit). The
//!   datasheet gives no current for the turnaround; it is charged at the TX current.
//! * **Acknowledgements** (only with `arq`): after each attempt the sender listens (RX current)
//!   for the acknowledgement. An attempt whose ACK it hears costs `t_ta` (the receiver sends the
//!   ACK `aTurnaroundTime` after the frame, §7.5.6.4.2) plus the ACK's 88 bits on air
//!   ([`ACK_PPDU_BITS`]); an attempt whose ACK it does not hear (data or ACK lost) costs the
//!   whole wait `macAckWaitDuration` (54 symbols = 864 µs at 2.4 GHz, §7.4.2 Table 86: a backoff
//!   period 20 + turnaround 12 + SHR 10 + ACK frame 6 × 2 symbols). The ACKs heard are the
//!   messages delivered by ARQ, one each: `ack_frames − duplicates` of [`Traffic`] (every ACK
//!   after a packet's first acknowledges a duplicate, i.e. the one before it was lost). This is
//!   exact unless a delivered packet ran out of retries with all its ACKs lost; such a packet
//!   is charged `t_ta + 352 µs` of waiting instead of 864 µs. A scenario where only some
//!   sensors have `arq` is charged as if all had (the sums keep no attempts per sensor).
//! * **Feedback** (only for a scheme that sends any: a run whose `downlink_bits` are not all
//!   zero): every sensor listens every step, because it cannot know whether the center has
//!   something for it (a sensor of Zhang et al. learns from the feedback whether it is
//!   activated). It keeps its receiver on for the listen window `listen_us` (a guard time for
//!   the clocks' drift and the receiver's start-up before the frame) and then receives the
//!   step's feedback frame: PHY header, MAC header and FCS (17 octets, [`DOWNLINK_OVERHEAD_BITS`])
//!   around the step's whole feedback payload `downlink_bits`. One frame carries all of it and
//!   every sensor hears all of it: exact for a broadcast prediction (Zheng et al.), and for
//!   per-sensor references (Zhang et al.) what a sensor pays that listens through the downlink
//!   slot (the simulator too hands every sensor the whole feedback). Feedback is whole 32-bit
//!   numbers, so whole octets. A payload above 116 octets (802.15.4's 127-octet limit less the
//!   11 octets of MAC header and FCS) would need more frames, whose overhead is not counted;
//!   the largest feedback of the built-in schemes (a prediction of a 6-dimensional state with
//!   its covariance, 27 numbers = 108 octets) fits one.
//! * **Sleep**: the rest of each step (`step_seconds` less the time the radio was active) at the
//!   sleep current (the CC2420's power-down mode, 20 µA, crystal oscillator off).
//!
//! Every term is linear in the counters of [`Traffic`] (frames, frame bits, ACKs, downlink
//! bits) and in the number of sensor-steps, so the energy of a whole run is the energy of its
//! summed counters ([`Activity::of`] of a total over many steps): the Monte Carlo sums already
//! hold everything it needs.
//!
//! **Left out**: the microcontroller and the sensor itself; the energy of waking up (crystal
//! start-up); the clear channel assessment and random backoff of unslotted CSMA-CA before each
//! frame (at least 8 symbols of RX per attempt, more under contention); collisions; the fusion
//! center's own energy (it sends the ACKs and the feedback; assumed mains-powered); the battery's
//! self-discharge, its voltage drop as it empties and its cut-off voltage.
//!
//! **Supply voltage**: 3.0 V, the nominal voltage of two AA cells in series, the battery of the
//! default lifetime (the CC2420 runs from 2.1–3.6 V through its internal regulator, so its
//! currents hardly depend on the supply and the energy drawn from the battery is `V_batt I`).
//! The same voltage turns the battery's capacity into energy: `C [mAh] × 3.6 C/mAh × V`.
use serde::{Deserialize, Serialize};

use crate::link::codec802154::{
    ACK_PPDU_BITS, FCS_OCTETS, MHR_OCTETS, PHR_OCTETS, PREAMBLE_OCTETS, SFD_OCTETS,
};
use crate::network::Traffic;

/// Bits of the PHY synchronization header and PHR that a data frame's MAC bits
/// ([`Traffic::frame_bits`]) leave out: preamble 4 + SFD 1 + PHR 1 octets = 48 bits.
pub const PHY_OVERHEAD_BITS: u64 = 8 * (PREAMBLE_OCTETS + SFD_OCTETS + PHR_OCTETS) as u64;

/// Bits of a feedback frame around its payload: the PHY overhead and the MAC header and FCS of
/// [`crate::link::codec802154`] (9 + 2 octets): 17 octets = 136 bits.
pub const DOWNLINK_OVERHEAD_BITS: u64 = PHY_OVERHEAD_BITS + 8 * (MHR_OCTETS + FCS_OCTETS) as u64;

/// The `[radio]` table of a scenario: the radio's currents and timings, the step's duration
/// and the battery. Every key is optional; absent keys take the CC2420's values.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct RadioSpec {
    /// Supply (battery) voltage, V. Default 3.0: two AA cells (see the module documentation).
    pub supply_v: f64,
    /// Current while transmitting, mA. Default 17.4: the CC2420 at 0 dBm output power.
    pub tx_ma: f64,
    /// Current while receiving or listening, mA. Default 18.8: the CC2420's receive mode (the
    /// same whether a frame is coming in or not).
    pub rx_ma: f64,
    /// Current while asleep, mA. Default 0.02: the CC2420's power-down mode (20 µA).
    pub sleep_ma: f64,
    /// Bit rate on air, kb/s. Default 250: 802.15.4 at 2.4 GHz (O-QPSK, 62.5 ksymbol/s).
    pub bit_rate_kbps: f64,
    /// Turnaround between receive and transmit, µs. Default 192: 12 symbol periods.
    pub turnaround_us: f64,
    /// With `arq`: how long a sender waits for an acknowledgement it does not hear, µs. Default
    /// 864: `macAckWaitDuration` at 2.4 GHz (54 symbols). At least the turnaround plus an ACK's
    /// 352 µs on air (at 250 kb/s).
    pub ack_wait_us: f64,
    /// For a scheme with feedback: how long a sensor listens each step before the feedback
    /// frame, µs. Default 1000: an assumed guard time, not a datasheet value (two ±40 ppm
    /// clocks drift apart by at most 80 µs over a 1 s step, plus 192 µs of receiver start-up,
    /// rounded up generously); set it to your MAC's.
    pub listen_us: f64,
    /// Duration of one filter step, s (default 1): the time the sleep current runs against and
    /// the clock of the lifetime.
    pub step_seconds: f64,
    /// Battery capacity, mAh, at `supply_v`. Default 2500: two alkaline AA cells in series.
    pub battery_mah: f64,
}

impl Default for RadioSpec {
    fn default() -> Self {
        RadioSpec {
            supply_v: 3.0,
            tx_ma: 17.4,
            rx_ma: 18.8,
            sleep_ma: 0.02,
            bit_rate_kbps: 250.0,
            turnaround_us: 192.0,
            ack_wait_us: 864.0,
            listen_us: 1000.0,
            step_seconds: 1.0,
            battery_mah: 2500.0,
        }
    }
}

/// A `[radio]` value out of range: the key and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct RadioError {
    /// The key of `[radio]`, e.g. `tx_ma`.
    pub key: &'static str,
    /// What was expected and what was found.
    pub message: String,
}

/// What the radios of all sensors did over some steps (one step, or a whole run's sums):
/// counts, so that means over trials and steps are allowed. See the module documentation for
/// what each costs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Activity {
    /// Sensor-steps covered (sensors × steps): the time the sleep current runs against.
    pub sensor_steps: f64,
    /// Data frames on air, every attempt.
    pub frames: f64,
    /// Their bits on air, PHY header included.
    pub frame_ppdu_bits: f64,
    /// Attempts followed by a wait for an acknowledgement (with `arq`: every attempt).
    pub ack_waits: f64,
    /// Of those, the ones whose acknowledgement the sender heard.
    pub acks_heard: f64,
    /// Sensor-steps spent listening for the feedback.
    pub listens: f64,
    /// Feedback bits on air that the listening sensors received, PHY and MAC overhead included.
    pub downlink_rx_bits: f64,
    /// A multi-hop network's node ([`crate::network::topology::tally`]): data frames' bits it
    /// received (PHY header included); 0 for a star's sensors.
    pub rx_ppdu_bits: f64,
    /// Acknowledgements it sent for them (`arq`).
    pub acks_sent: f64,
    /// Feedback frames it sent down the tree, and their bits on air.
    pub downlink_tx_frames: f64,
    pub downlink_tx_bits: f64,
}

impl Activity {
    /// The activity of `traffic` sent by `sensors` sensors over `steps` steps (one step's
    /// [`Traffic`], or the sum of many steps' counters). `arq`: whether the senders wait for
    /// acknowledgements; `listen`: whether the sensors listen for feedback every step (a scheme
    /// that sends feedback).
    pub fn of(traffic: &Traffic, sensors: usize, steps: u64, arq: bool, listen: bool) -> Self {
        let n = sensors as f64;
        let sensor_steps = n * steps as f64;
        let frames = (traffic.messages + traffic.retransmissions) as f64;
        let listens = if listen { sensor_steps } else { 0.0 };
        Activity {
            sensor_steps,
            frames,
            frame_ppdu_bits: traffic.frame_bits as f64 + frames * PHY_OVERHEAD_BITS as f64,
            ack_waits: if arq { frames } else { 0.0 },
            acks_heard: if arq {
                traffic.ack_frames.saturating_sub(traffic.duplicates) as f64
            } else {
                0.0
            },
            listens,
            // Every listener receives the step's frame: its overhead and the whole payload.
            downlink_rx_bits: if listen {
                listens * DOWNLINK_OVERHEAD_BITS as f64 + n * traffic.downlink_bits as f64
            } else {
                0.0
            },
            ..Activity::default()
        }
    }
}

/// Energy of some activity by what it was spent on, µJ.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EnergyParts {
    /// Data frames: airtime and turnaround at the TX current.
    pub tx: f64,
    /// Waiting for and receiving acknowledgements (`arq`).
    pub ack: f64,
    /// Listening for and receiving the feedback.
    pub downlink: f64,
    /// The rest of the time, asleep.
    pub sleep: f64,
    /// A multi-hop network's node: receiving the frames it forwards or sinks, acknowledging
    /// them, sending the feedback down (absent, 0, for a star's sensors).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub relay: f64,
}

impl std::ops::Add for EnergyParts {
    type Output = EnergyParts;

    /// Part by part: the energy of two radios, or of two spells of one.
    fn add(self, o: EnergyParts) -> EnergyParts {
        EnergyParts {
            tx: self.tx + o.tx,
            ack: self.ack + o.ack,
            downlink: self.downlink + o.downlink,
            sleep: self.sleep + o.sleep,
            relay: self.relay + o.relay,
        }
    }
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl EnergyParts {
    /// All of it.
    pub fn total(&self) -> f64 {
        self.tx + self.ack + self.downlink + self.sleep + self.relay
    }

    /// Every part divided by `d` (a total over a run into a mean per step).
    pub fn per(&self, d: f64) -> Self {
        EnergyParts {
            tx: self.tx / d,
            ack: self.ack / d,
            downlink: self.downlink / d,
            sleep: self.sleep / d,
            relay: self.relay / d,
        }
    }
}

impl RadioSpec {
    /// Checks every value: finite, positive where a zero makes no sense (voltage, currents of
    /// TX and RX, bit rate, step, battery), non-negative for the others, and an ACK wait long
    /// enough for a heard ACK.
    pub fn validate(&self) -> Result<(), RadioError> {
        let positive = [
            ("supply_v", self.supply_v),
            ("tx_ma", self.tx_ma),
            ("rx_ma", self.rx_ma),
            ("bit_rate_kbps", self.bit_rate_kbps),
            ("step_seconds", self.step_seconds),
            ("battery_mah", self.battery_mah),
        ];
        let non_negative = [
            ("sleep_ma", self.sleep_ma),
            ("turnaround_us", self.turnaround_us),
            ("ack_wait_us", self.ack_wait_us),
            ("listen_us", self.listen_us),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(RadioError {
                    key,
                    message: format!("expected a finite number > 0, got {v}"),
                });
            }
        }
        for (key, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(RadioError {
                    key,
                    message: format!("expected a finite number >= 0, got {v}"),
                });
            }
        }
        let heard = self.turnaround_us + self.airtime_us(ACK_PPDU_BITS as f64);
        if self.ack_wait_us < heard {
            return Err(RadioError {
                key: "ack_wait_us",
                message: format!(
                    "expected at least turnaround_us + an ACK's {ACK_PPDU_BITS} bits on air = {heard} µs (the wait covers a heard ACK), got {}",
                    self.ack_wait_us
                ),
            });
        }
        Ok(())
    }

    /// Transmit power, mW.
    pub fn tx_mw(&self) -> f64 {
        self.supply_v * self.tx_ma
    }

    /// Receive (and listen) power, mW.
    pub fn rx_mw(&self) -> f64 {
        self.supply_v * self.rx_ma
    }

    /// Sleep power, mW.
    pub fn sleep_mw(&self) -> f64 {
        self.supply_v * self.sleep_ma
    }

    /// Time `bits` take on air, µs (kb/s = bits per ms).
    pub fn airtime_us(&self, bits: f64) -> f64 {
        1000.0 * bits / self.bit_rate_kbps
    }

    /// Energy of sending one frame of `ppdu_bits` bits on air (PHY header included), µJ: its
    /// airtime and one turnaround at the TX current.
    pub fn frame_tx_uj(&self, ppdu_bits: f64) -> f64 {
        self.tx_mw() * (self.airtime_us(ppdu_bits) + self.turnaround_us) / 1000.0
    }

    /// Energy of receiving `bits` bits on air, µJ.
    pub fn rx_uj(&self, bits: f64) -> f64 {
        self.rx_mw() * self.airtime_us(bits) / 1000.0
    }

    /// Energy of `a`, µJ, by part; sleep fills what the other parts leave of
    /// `a.sensor_steps × step_seconds` (never below 0).
    pub fn energy(&self, a: &Activity) -> EnergyParts {
        let tx_us = self.airtime_us(a.frame_ppdu_bits) + a.frames * self.turnaround_us;
        let heard_us = self.turnaround_us + self.airtime_us(ACK_PPDU_BITS as f64);
        let ack_us = a.acks_heard * heard_us + (a.ack_waits - a.acks_heard) * self.ack_wait_us;
        let down_us = a.listens * self.listen_us + self.airtime_us(a.downlink_rx_bits);
        // A network node's receiving side: the frames in, the ACKs and the feedback out.
        let relay_rx_us = self.airtime_us(a.rx_ppdu_bits);
        let relay_tx_us = a.acks_sent * heard_us
            + self.airtime_us(a.downlink_tx_bits)
            + a.downlink_tx_frames * self.turnaround_us;
        let asleep_us = (a.sensor_steps * self.step_seconds * 1e6
            - tx_us
            - ack_us
            - down_us
            - relay_rx_us
            - relay_tx_us)
            .max(0.0);
        EnergyParts {
            tx: self.tx_mw() * tx_us / 1000.0,
            ack: self.rx_mw() * ack_us / 1000.0,
            downlink: self.rx_mw() * down_us / 1000.0,
            sleep: self.sleep_mw() * asleep_us / 1000.0,
            relay: (self.rx_mw() * relay_rx_us + self.tx_mw() * relay_tx_us) / 1000.0,
        }
    }

    /// Energy of one step's `traffic` from `sensors` sensors, µJ (see [`Activity::of`]).
    pub fn step_energy(&self, traffic: &Traffic, sensors: usize, arq: bool, listen: bool) -> f64 {
        self.energy(&Activity::of(traffic, sensors, 1, arq, listen))
            .total()
    }

    /// What `sensors` sensors spend in a step when none of them turns its radio on, µJ: the
    /// least any scheme spends per step (the radio's every other state draws more than sleep).
    pub fn asleep_step_uj(&self, sensors: usize) -> f64 {
        sensors as f64 * self.sleep_mw() * self.step_seconds * 1000.0
    }

    /// Energy the battery holds, J: capacity × 3.6 C/mAh × voltage.
    pub fn battery_joules(&self) -> f64 {
        self.battery_mah * 3.6 * self.supply_v
    }

    /// Days a sensor lasts on the battery when it spends `uj_per_step` µJ a step (one step
    /// every `step_seconds`); `None` when it spends nothing (or a number that is not one).
    pub fn lifetime_days(&self, uj_per_step: f64) -> Option<f64> {
        let watts = uj_per_step * 1e-6 / self.step_seconds;
        (watts.is_finite() && watts > 0.0).then(|| self.battery_joules() / watts / 86_400.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    /// CC2420 defaults, by hand: P_tx = 3.0 V × 17.4 mA = 52.2 mW. The frame of one 8-octet
    /// measurement (two 32-bit numbers) is a 19-octet MPDU (9 MHR + 8 + 2 FCS) and a 25-octet
    /// PPDU (+ 4 preamble, 1 SFD, 1 PHR) = 200 bits = 800 µs at 250 kb/s; with the 192 µs
    /// turnaround, 992 µs × 52.2 mW = 51 782.4 nJ = 51.7824 µJ. A codec's 12-octet MPDU
    /// (18-octet PPDU, 144 bits, 576 µs): 768 µs × 52.2 mW = 40.0896 µJ.
    #[test]
    fn energy_of_a_frame_by_hand() {
        let r = RadioSpec::default();
        assert!(close(r.tx_mw(), 52.2));
        assert!(close(r.frame_tx_uj(200.0), 51.7824));
        assert!(close(r.frame_tx_uj(144.0), 40.0896));
        // Receiving an ACK's 88 bits: 352 µs × 3.0 V × 18.8 mA (56.4 mW) = 19.8528 µJ.
        assert!(close(r.rx_uj(88.0), 19.8528));
        // Through Traffic: one measurement, no ARQ, no feedback, sleep for the rest of the 1 s
        // step: (1e6 − 992) µs × 0.06 mW = 59 940.48 nJ; total 51.7824 + 59.94048 µJ.
        let t = Traffic {
            messages: 1,
            bits: 64,
            frame_bits: 8 * 19,
            ..Traffic::default()
        };
        let e = r.energy(&Activity::of(&t, 1, 1, false, false));
        assert!(close(e.tx, 51.7824) && close(e.sleep, 59.94048), "{e:?}");
        assert!(close(r.step_energy(&t, 1, false, false), 111.72288));
    }

    /// ARQ and feedback, by hand. Two attempts of a 12-octet MPDU (144 bits each on air), the
    /// second acknowledged and heard (ack_frames 1, no duplicate): TX 2 × 768 µs = 1536 µs;
    /// ACK part: one heard (192 + 352 µs) and one unheard wait (864 µs) = 1408 µs × 56.4 mW =
    /// 79.4112 µJ. Feedback to 2 sensors of a 64-bit payload: each listens 1000 µs and
    /// receives (136 + 64) bits = 800 µs: 2 × 1800 µs × 56.4 mW = 203.04 µJ.
    #[test]
    fn acknowledgements_and_feedback_by_hand() {
        let r = RadioSpec::default();
        let t = Traffic {
            messages: 1,
            frame_bits: 2 * 96,
            retransmissions: 1,
            ack_frames: 1,
            ack_bits: 88,
            downlink_bits: 64,
            ..Traffic::default()
        };
        let e = r.energy(&Activity::of(&t, 2, 1, true, true));
        assert!(close(e.tx, 2.0 * 40.0896), "{e:?}");
        assert!(close(e.ack, 79.4112), "{e:?}");
        assert!(close(e.downlink, 203.04), "{e:?}");
        // Asleep: 2 s of sensor time less 1536 + 1408 + 3600 µs, at 0.06 mW.
        assert!(close(
            e.sleep,
            0.06 * (2e6 - 1536.0 - 1408.0 - 3600.0) / 1000.0
        ));
        // Without ARQ and feedback the same frames cost only their TX part and sleep.
        let plain = r.energy(&Activity::of(&t, 2, 1, false, false));
        assert_eq!((plain.ack, plain.downlink), (0.0, 0.0));
    }

    /// Lifetime, by hand: 2500 mAh × 3.6 C/mAh × 3.0 V = 27 000 J. At 100 µJ per 1 s step
    /// (100 µW) that is 2.7e8 s = 3125 days; with the single measurement above (111.72288 µJ a
    /// step, 111.72288 µW) 27 000 J / 111.72288e-6 W = 241 669 387.7 s = 2797.0994 days.
    #[test]
    fn lifetime_by_hand() {
        let r = RadioSpec::default();
        assert!(close(r.battery_joules(), 27_000.0));
        assert!(close(r.lifetime_days(100.0).unwrap(), 3125.0));
        let days = r.lifetime_days(111.72288).unwrap();
        assert!((days - 2797.0994).abs() < 1e-4, "{days}");
        // A 10 s step stretches it tenfold; nothing spent, no number.
        let slow = RadioSpec {
            step_seconds: 10.0,
            ..r
        };
        assert!(close(slow.lifetime_days(100.0).unwrap(), 31_250.0));
        assert_eq!(r.lifetime_days(0.0), None);
    }

    /// Doubling the TX current doubles the TX part and nothing else.
    #[test]
    fn tx_current_scales_the_tx_part() {
        let t = Traffic {
            messages: 3,
            frame_bits: 3 * 152,
            downlink_bits: 96,
            ..Traffic::default()
        };
        let a = Activity::of(&t, 4, 1, false, true);
        let base = RadioSpec::default().energy(&a);
        let doubled = RadioSpec {
            tx_ma: 34.8,
            ..RadioSpec::default()
        }
        .energy(&a);
        assert!(close(doubled.tx, 2.0 * base.tx));
        assert_eq!(
            (doubled.ack, doubled.downlink, doubled.sleep),
            (base.ack, base.downlink, base.sleep)
        );
    }

    #[test]
    fn bad_values_name_their_key() {
        let bad = |r: RadioSpec| r.validate().unwrap_err();
        let e = bad(RadioSpec {
            tx_ma: -1.0,
            ..RadioSpec::default()
        });
        assert_eq!(e.key, "tx_ma");
        assert!(e.message.contains("> 0"), "{e}");
        assert_eq!(
            bad(RadioSpec {
                listen_us: f64::NAN,
                ..RadioSpec::default()
            })
            .key,
            "listen_us"
        );
        assert_eq!(
            bad(RadioSpec {
                ack_wait_us: 500.0,
                ..RadioSpec::default()
            })
            .key,
            "ack_wait_us"
        );
        assert!(RadioSpec::default().validate().is_ok());
    }
}
