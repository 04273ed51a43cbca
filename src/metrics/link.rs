//! What the link did to a scheme's messages, for `summary.json` and `per_step.csv`: per step
//! (means over trials) the messages sent, delivered in time, lost, late (fused on arrival) and
//! dropped as too late, the feedback packets the downlink lost, and with retransmission (`arq`)
//! the retransmissions, duplicates and acknowledgements. Only with a `[channel]`.
use crate::metrics::Sums;
use serde::{Deserialize, Serialize};

/// The link's counts of one scheme variant. A lost or late message was sent: it is in
/// `sent` and in the scheme's bits and frames.
///
/// `sent` counts packets, the sensors' decisions to send (the scheme's rate); with ARQ a
/// packet goes on air up to 1 + `max_retries` times, and the attempts after the first are
/// `retransmissions` (each in the scheme's payload and frame bits, since each was sent). An
/// attempt that arrived after the packet had already arrived (its acknowledgement was lost)
/// is a duplicate, discarded by the center. `ack_frames` are the center's acknowledgements,
/// one per attempt that arrived, and `ack_bits` their bits on air (88 each: the 5-octet
/// 802.15.4 ACK frame with PHY synchronization header and PHR); they are not in the
/// scheme's `downlink_bits`, which stay its feedback.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct LinkSummary {
    /// Per step, means over trials.
    pub sent_per_step: Vec<f64>,
    pub delivered_per_step: Vec<f64>,
    pub lost_per_step: Vec<f64>,
    /// Delivered late, within the horizon: fused when they arrived.
    pub late_per_step: Vec<f64>,
    /// Later than the horizon: dropped.
    pub dropped_late_per_step: Vec<f64>,
    pub downlink_lost_per_step: Vec<f64>,
    pub retransmissions_per_step: Vec<f64>,
    pub duplicates_per_step: Vec<f64>,
    pub ack_frames_per_step: Vec<f64>,
    pub ack_bits_per_step: Vec<f64>,
    /// Time averages of the per-step means.
    pub sent: f64,
    pub delivered: f64,
    pub lost: f64,
    pub late: f64,
    pub dropped_late: f64,
    pub downlink_lost: f64,
    pub retransmissions: f64,
    pub duplicates: f64,
    pub ack_frames: f64,
    pub ack_bits: f64,
    /// Lost / sent over the whole run; `None` (null) when nothing was sent: no packets, not a
    /// non-finite result.
    pub loss_fraction: Option<f64>,
}

/// The link summary of `sums` (`sent_per_step`: the scheme's mean messages per step).
pub fn summarize(sums: &Sums, trials: usize, sent_per_step: Vec<f64>) -> LinkSummary {
    let steps = sent_per_step.len();
    let column = |c: usize| -> Vec<f64> {
        (0..steps)
            .map(|k| sums.link.get(k).map_or(0.0, |r| r[c] as f64) / trials as f64)
            .collect()
    };
    let [lost, late, dropped, downlink_lost, retransmissions, duplicates, ack_frames, ack_bits] =
        std::array::from_fn(column);
    // Delivered in time: neither lost nor late nor dropped.
    let delivered: Vec<f64> = (0..steps)
        .map(|k| sent_per_step[k] - lost[k] - late[k] - dropped[k])
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / steps.max(1) as f64;
    let (sent_mean, lost_mean) = (mean(&sent_per_step), mean(&lost));
    LinkSummary {
        sent: sent_mean,
        delivered: mean(&delivered),
        lost: lost_mean,
        late: mean(&late),
        dropped_late: mean(&dropped),
        downlink_lost: mean(&downlink_lost),
        retransmissions: mean(&retransmissions),
        duplicates: mean(&duplicates),
        ack_frames: mean(&ack_frames),
        ack_bits: mean(&ack_bits),
        loss_fraction: (sent_mean > 0.0).then(|| lost_mean / sent_mean),
        sent_per_step,
        delivered_per_step: delivered,
        lost_per_step: lost,
        late_per_step: late,
        dropped_late_per_step: dropped,
        downlink_lost_per_step: downlink_lost,
        retransmissions_per_step: retransmissions,
        duplicates_per_step: duplicates,
        ack_frames_per_step: ack_frames,
        ack_bits_per_step: ack_bits,
    }
}

/// The extra header of `per_step.csv` when the scenario has a link.
pub const CSV_HEADER: &str = ",sent,delivered,lost,late,dropped_late,downlink_lost,retransmissions,duplicates,ack_frames,ack_bits";

/// Step `k`'s (0-based) extra fields of `per_step.csv`.
pub fn csv_fields(l: &LinkSummary, k: usize) -> String {
    format!(
        ",{},{},{},{},{},{},{},{},{},{}",
        l.sent_per_step[k],
        l.delivered_per_step[k],
        l.lost_per_step[k],
        l.late_per_step[k],
        l.dropped_late_per_step[k],
        l.downlink_lost_per_step[k],
        l.retransmissions_per_step[k],
        l.duplicates_per_step[k],
        l.ack_frames_per_step[k],
        l.ack_bits_per_step[k]
    )
}
