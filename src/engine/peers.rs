//! The engine's loop for a decentralized scheme ([`crate::decentralized::trial`]): its nodes run
//! on the network's graph on the trial's readings, and every step's estimates (all nodes) go
//! to the variant's sums as the mean over the nodes, each node's own beside
//! ([`crate::metrics::TrialState::record_estimators`]), with every node's counters.
use crate::decentralized::trial::{PeerTrial, Peers};
use crate::link::codec802154::{FCS_OCTETS, MHR_OCTETS};
use crate::metrics::{Sums, TrialFailure};
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::tally::{NodeCounts, NODE_COUNTERS};
use crate::network::Traffic;
use crate::scenario::draw::TrialData;
use crate::scenario::experiment::Experiment;

/// A step's traffic over the whole network from every node's counters: frames on air (every
/// node's, each a broadcast or an attempt), their MAC frame bits and their payload bits.
pub fn traffic(counts: &[NodeCounts]) -> Traffic {
    let field = |name: &str| {
        NODE_COUNTERS
            .iter()
            .position(|c| *c == name)
            .expect("a counter")
    };
    let (tx, tx_bits) = (field("frames_sent"), field("frame_bits_sent"));
    let frames: u64 = counts.iter().map(|c| c[tx]).sum();
    let ppdu: u64 = counts.iter().map(|c| c[tx_bits]).sum();
    let frame_bits = ppdu - frames * PHY_OVERHEAD_BITS;
    Traffic {
        messages: frames,
        frame_bits,
        bits: frame_bits - frames * 8 * (MHR_OCTETS + FCS_OCTETS) as u64,
        ..Traffic::default()
    }
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
    let net = exp
        .graph_of(&exp.variants[v])
        .expect("a decentralized scheme has a graph");
    let mut obs = sums.trial(&exp.groups, exp.steady_from);
    let t = PeerTrial {
        net: &net,
        measurements: &data.measurements,
        seed: exp.seed,
        trial: trial as u64,
    };
    let mut failed_at = 0;
    let outcome = peers.run_trial(&t, &mut |k, estimates, counts| {
        failed_at = k;
        obs.record_estimators(k, &data.truth[k - 1], estimates, traffic(counts))
            .map_err(|e| format!("a node's covariance is not positive definite ({e})"))?;
        obs.record_nodes(k, counts);
        Ok(())
    });
    match outcome {
        Ok(()) => obs.finish(),
        Err(message) => sums.record_failure(TrialFailure {
            trial,
            step: failed_at,
            message: format!("scheme {label}, trial {trial}: {message}"),
        }),
    }
}
