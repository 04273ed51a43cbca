//! The energy a scheme's traffic costs the sensors' radios, for `summary.json`: the model of
//! [`crate::network::radio`] applied to the run's summed counters. Energy is linear in them, so
//! the mean energy per step is the energy of the mean counters and nothing is computed per
//! trial or per step while the run goes.
use crate::metrics::{Layout, Sums};
use crate::network::radio::{Activity, EnergyParts, RadioSpec};
use crate::network::Traffic;
use crate::scenario::build::{Experiment, Variant};
use serde::{Deserialize, Serialize};

/// A scheme variant's radio energy (means over trials and steps).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(default)]
pub struct EnergySummary {
    /// Energy of all sensors' radios per step, µJ: data frames, acknowledgements, feedback,
    /// sleep.
    pub energy_per_step_uj: f64,
    /// The same per sensor: the average sensor's energy per step, µJ.
    pub energy_per_sensor_step_uj: f64,
    /// `energy_per_step_uj` by part: `tx` (data frames), `ack` (waiting for and receiving
    /// acknowledgements), `downlink` (listening for and receiving feedback), `sleep`.
    pub energy_parts_per_step_uj: EnergyParts,
    /// Days the average sensor lasts on the `[radio]` battery; absent when it spends nothing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lifetime_days: Option<f64>,
}

/// The run's counters summed over trials and steps, as one [`Traffic`] (the sums of integer
/// counts are exact in double precision up to 2^53).
pub fn total_traffic(sums: &Sums) -> Traffic {
    let column =
        |f: usize| -> u64 { (0..sums.steps).map(|k| sums.at(k, f)).sum::<f64>().round() as u64 };
    // The link's counters (LINK_COUNTERS order): empty rows for a link that did nothing.
    let link = |c: usize| -> u64 { sums.link.iter().map(|r| r[c]).sum() };
    Traffic {
        messages: column(Layout::MESSAGES),
        bits: column(Layout::BITS),
        frame_bits: column(Layout::FRAME_BITS),
        downlink_bits: column(Layout::DOWNLINK_BITS),
        lost: link(0),
        late: link(1),
        dropped_late: link(2),
        downlink_lost: link(3),
        retransmissions: link(4),
        duplicates: link(5),
        ack_frames: link(6),
        ack_bits: link(7),
        // Totals have no per-step sensor sets (Sums::sensors keeps the per-sensor counts).
        senders: 0,
        scheduled: 0,
    }
}

/// The energy summary of variant `v` of `exp` from its `sums`, priced with the scenario's
/// `[radio]`: its senders wait for acknowledgements when any of its links has `arq` (a
/// scenario where only some sensors have it is charged as if all had: the sums do not keep
/// attempts per sensor).
pub fn of_variant(exp: &Experiment, v: &Variant, sums: &Sums) -> EnergySummary {
    let arq = v
        .channel
        .as_ref()
        .is_some_and(|c| c.iter().any(|l| l.arq.is_some()));
    summarize(&exp.radio, sums, exp.trials, exp.system.n_sensors(), arq)
}

/// The energy summary of a variant's `sums` over `trials` trials, with `sensors` sensors whose
/// senders wait for acknowledgements when `arq`. The sensors listen for feedback every step
/// when the scheme sent any in the run (see [`crate::network::radio`]).
pub fn summarize(
    radio: &RadioSpec,
    sums: &Sums,
    trials: usize,
    sensors: usize,
    arq: bool,
) -> EnergySummary {
    let total = total_traffic(sums);
    let listen = total.downlink_bits > 0;
    let slots = (trials * sums.steps) as u64;
    let parts = radio
        .energy(&Activity::of(&total, sensors, slots, arq, listen))
        .per(slots.max(1) as f64);
    let per_step = parts.total();
    let per_sensor = per_step / sensors.max(1) as f64;
    EnergySummary {
        energy_per_step_uj: per_step,
        energy_per_sensor_step_uj: per_sensor,
        energy_parts_per_step_uj: parts,
        lifetime_days: radio.lifetime_days(per_sensor),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::LINK_FIELDS;

    /// Sums of 2 trials × 3 steps in which one of 2 sensors sends one 19-octet MPDU at every
    /// step (measured traffic only), by hand: 51.7824 µJ of TX a frame (see
    /// `network::radio`'s tests), one frame a step; asleep (2 s − 992 µs) × 0.06 mW a step =
    /// 119.94048 µJ; per step 171.72288 µJ, per sensor 85.86144 µJ; lifetime 27 000 J /
    /// 85.86144 µW = 314 460 134.9 s = 3639.5849 days.
    #[test]
    fn energy_from_the_sums() {
        let mut sums = Sums::new(0, 3, 1);
        let w = sums.layout().width();
        for k in 0..3 {
            sums.per_step[k * w + Layout::MESSAGES] = 2.0;
            sums.per_step[k * w + Layout::BITS] = 2.0 * 64.0;
            sums.per_step[k * w + Layout::FRAME_BITS] = 2.0 * 152.0;
        }
        sums.trials = 2;
        let e = summarize(&RadioSpec::default(), &sums, 2, 2, false);
        assert!((e.energy_per_step_uj - 171.72288).abs() < 1e-9, "{e:?}");
        assert!((e.energy_per_sensor_step_uj - 85.86144).abs() < 1e-9);
        assert!((e.lifetime_days.unwrap() - 3639.5849).abs() < 1e-4, "{e:?}");
        // ARQ counters: 6 retransmissions (every frame sent twice), 6 ACKs heard.
        sums.link = vec![[0; LINK_FIELDS]; 3];
        for r in &mut sums.link {
            (r[4], r[6], r[7]) = (2, 2, 176);
        }
        let t = total_traffic(&sums);
        assert_eq!((t.messages, t.retransmissions, t.ack_frames), (6, 6, 6));
        let arq = summarize(&RadioSpec::default(), &sums, 2, 2, true);
        // Per step one more frame (frame bits stay those of the sums: here the same 152) and
        // one heard ACK and one unheard wait: (544 + 864) µs × 56.4 mW = 79.4112 µJ.
        assert!((arq.energy_parts_per_step_uj.ack - 79.4112).abs() < 1e-9);
    }
}
