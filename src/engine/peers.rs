//! The engine's loop for a decentralized scheme ([`crate::decentralized::trial`]): its nodes run
//! on the network's graph on the trial's readings, and every step's estimates (all nodes) go
//! to the variant's sums as the mean over the nodes, each node's own beside
//! ([`crate::metrics::TrialState::record_estimators`]), with every node's counters.
use crate::decentralized::trial::{PeerTrial, Peers};
use crate::engine::link_layer::Link;
use crate::link::codec802154::{FCS_OCTETS, MHR_OCTETS};
use crate::metrics::{Sums, TrialFailure};
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::tally::NodeCounts;
use crate::network::Traffic;
use crate::scenario::draw::TrialData;
use crate::scenario::experiment::Experiment;

/// A step's traffic over the whole network from every node's counters: frames on air (every
/// node's, each a broadcast or an attempt), their MAC frame bits and their payload bits.
pub fn traffic(counts: &[NodeCounts]) -> Traffic {
    let (frames, ppdu) = counts
        .iter()
        .map(crate::network::topology::tally::sent)
        .fold((0, 0), |(f, b), (x, y)| (f + x, b + y));
    let frame_bits = ppdu - frames * PHY_OVERHEAD_BITS;
    Traffic {
        messages: frames,
        frame_bits,
        bits: frame_bits - frames * 8 * (MHR_OCTETS + FCS_OCTETS) as u64,
        ..Traffic::default()
    }
}

/// What each sensor node did in a step, as the engine's loop reports a sensor: sent (it put a
/// frame on air) or silent.
pub fn links(counts: &[NodeCounts], sensors: usize) -> Vec<Link> {
    counts[..sensors]
        .iter()
        .map(|c| match crate::network::topology::tally::frames(c).0 {
            0 => Link::Silent,
            _ => Link::Sent,
        })
        .collect()
}

/// Each sensor node's payload bits on air in a step ([`traffic`] of its counters alone).
pub fn sensor_bits(counts: &[NodeCounts], sensors: usize) -> Vec<u64> {
    counts[..sensors]
        .iter()
        .map(|c| traffic(std::slice::from_ref(c)).bits)
        .collect()
}

/// Runs decentralized variant `v` (`peers`) of trial `trial` on `measurements`, calling `f`
/// after every step with (k, every node's estimate, every node's counters). Recorded data with
/// holes (`available` not all true) is refused: a node without its reading is not built yet.
pub fn run_steps(
    exp: &Experiment,
    v: usize,
    peers: &Peers,
    measurements: &[Vec<crate::linalg::Vector>],
    (trial, available): (usize, Option<&[Vec<bool>]>),
    f: &mut crate::decentralized::trial::Recorder,
) -> Result<(), String> {
    if available.is_some_and(|a| a.iter().any(|row| row.iter().any(|&b| !b))) {
        return Err(
            "a decentralized scheme needs every sensor's reading at every step (recorded data with holes is not supported for it yet)".into(),
        );
    }
    let net = exp
        .graph_of(&exp.variants[v])
        .expect("a decentralized scheme has a graph");
    let t = PeerTrial {
        net: &net,
        measurements,
        seed: exp.seed,
        trial: trial as u64,
    };
    peers.run_trial(&t, f)
}

/// One trial of decentralized variant `v` (`peers`) on `data`, into `sums`; a failed trial is
/// recorded as the variant's failure, as the engine's loop does.
pub fn run_variant(
    exp: &Experiment,
    trial: usize,
    v: usize,
    peers: &Peers,
    data: &TrialData,
    sums: &mut Sums,
) {
    let label = &exp.curves[exp.variants[v].curve].label;
    let mut obs = sums.trial(&exp.groups, exp.steady_from);
    let mut failed_at = 0;
    let outcome = run_steps(
        exp,
        v,
        peers,
        &data.measurements,
        (trial, None),
        &mut |k, estimates, counts, factors| {
            failed_at = k;
            record(
                &mut obs,
                k,
                &data.truth[k - 1],
                (estimates, factors),
                counts,
            )
        },
    );
    match outcome {
        Ok(()) => obs.finish(),
        Err(message) => sums.record_failure(TrialFailure {
            trial,
            step: failed_at,
            message: format!("scheme {label}, trial {trial}: {message}"),
        }),
    }
}

/// Step `k` of a decentralized scheme into a trial's metrics: the nodes' estimates against
/// `truth` (with their covariances' NEES factors where the loop has them), and every node's
/// counters.
pub fn record(
    obs: &mut crate::metrics::TrialObserver,
    k: usize,
    truth: &crate::linalg::Vector,
    (estimates, factors): (&[&crate::filter::Gaussian], Option<&[f64]>),
    counts: &[NodeCounts],
) -> Result<(), String> {
    obs.record_estimators(k, truth, (estimates, factors), traffic(counts))
        .map_err(|e| format!("a node's covariance is not positive definite ({e})"))?;
    obs.record_nodes(k, counts);
    Ok(())
}
