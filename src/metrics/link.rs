//! What the link did to a scheme's messages, for `summary.json` and `per_step.csv`: per step
//! (means over trials) the messages sent, delivered in time, lost, late (fused on arrival) and
//! dropped as too late, and the feedback packets the downlink lost. Only with a `[channel]`.
use crate::metrics::Sums;
use serde::{Deserialize, Serialize};

/// The link's counts of one scheme variant. A lost or late message was sent: it is in
/// `sent` and in the scheme's bits and frames.
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
    /// Time averages of the per-step means.
    pub sent: f64,
    pub delivered: f64,
    pub lost: f64,
    pub late: f64,
    pub dropped_late: f64,
    pub downlink_lost: f64,
    /// Lost / sent over the whole run (NaN when nothing was sent).
    pub loss_fraction: f64,
}

/// The link summary of `sums` (`sent_per_step`: the scheme's mean messages per step).
pub fn summarize(sums: &Sums, trials: usize, sent_per_step: Vec<f64>) -> LinkSummary {
    let steps = sent_per_step.len();
    let column = |c: usize| -> Vec<f64> {
        (0..steps)
            .map(|k| sums.link.get(k).map_or(0.0, |r| r[c] as f64) / trials as f64)
            .collect()
    };
    let (lost, late, dropped, downlink_lost) = (column(0), column(1), column(2), column(3));
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
        loss_fraction: if sent_mean > 0.0 {
            lost_mean / sent_mean
        } else {
            f64::NAN
        },
        sent_per_step,
        delivered_per_step: delivered,
        lost_per_step: lost,
        late_per_step: late,
        dropped_late_per_step: dropped,
        downlink_lost_per_step: downlink_lost,
    }
}

/// The extra header of `per_step.csv` when the scenario has a link.
pub const CSV_HEADER: &str = ",sent,delivered,lost,late,dropped_late,downlink_lost";

/// Step `k`'s (0-based) extra fields of `per_step.csv`.
pub fn csv_fields(l: &LinkSummary, k: usize) -> String {
    format!(
        ",{},{},{},{},{},{}",
        l.sent_per_step[k],
        l.delivered_per_step[k],
        l.lost_per_step[k],
        l.late_per_step[k],
        l.dropped_late_per_step[k],
        l.downlink_lost_per_step[k]
    )
}
