//! Live runs: the sensor nodes and the fusion center as separate processes that exchange real
//! IEEE 802.15.4 frames in UDP datagrams (`hushfuse center`, `hushfuse node`, `hushfuse live`,
//! `hushfuse channel-proxy`).
//!
//! A live run is the engine's loop ([`crate::engine::trial`]) with the network replaced by
//! sockets: each node runs its scheme's sensor side on its readings with its own coins (the
//! coins of the same sensor in the simulation, [`crate::stats::seeding::sensor_coins`]),
//! and sends what the sensor sends as the frame a radio would send ([`wire`]); the center fuses
//! what arrives with the scheme's center and sends the feedback down. Every real number
//! crosses as the IEEE 754 single the simulation prices and delivers, so on an ideal link the
//! center's estimates are bit for bit those of `hushfuse replay` of the same readings
//! (`tests/live.rs`).
//!
//! # Protocol
//!
//! 1. Each node greets the center ([`wire::Kind::Hello`], with a fingerprint of the scenario,
//!    seed, steps and trial; a node of another run is refused) and greets again whenever it
//!    has heard nothing for a second, so that a restarted center finds its nodes again.
//! 2. For each variant (scheme) in order, for each step k, the center announces the step to
//!    every node, with the feedback frame of the scheme (if any). A node reads its reading of
//!    step k, runs its sensor, sends its frame if it sends one, then reports that it is done
//!    (and whether it had a reading: a sensor without one reaches the center as not scheduled,
//!    as in `hushfuse replay`).
//! 3. The center closes the step when every node has reported (lock step), or when the step's
//!    period is over (`--period`), and fuses. A node that did not report is a silence and is
//!    logged: the center cannot tell a dead node from a quiet one, as it cannot tell a lost
//!    packet from a silence.
//! 4. A node that finds it has missed steps (it was down, or restarted) asks for them and is
//!    sent their announcements again, marked as catch-up: it runs its sensor on them (its
//!    readings, its coins, the feedback the center sent) and sends nothing, so it continues
//!    with the state of a node whose packets of those steps were lost.
//! 5. The center writes every fused step to its journal and to `estimates.csv`, flushed, before
//!    it announces the next; a restarted center (`--resume`) re-fuses the journal, which gives
//!    the same estimates, and continues.
mod center;
mod driver;
mod folder;
mod local;
mod node;
pub mod proxy;
pub mod secure;
pub mod wire;

pub use center::{Accepted, Center, Dropped, SensorRecord, StepRecord};
pub use driver::{run_center, CenterOptions, CenterSink, Journal, Pace};
pub use folder::{LiveFolder, RunId, ESTIMATES, JOURNAL, LOG};
pub use local::run_local;
pub use node::{
    fingerprint, frame_datagram, run_node, BackgroundLines, Lines, Node, NodeOptions, Readings,
    Recorded, Reply,
};

use crate::scenario::experiment::Experiment;

/// Refuses what a live run cannot do exactly: sequence numbers (their bits would have to
/// travel in the frame, which the live frames do not carry), links that delay or
/// retransmit (the live link is the real one, or the proxy's losses), and lost feedback when
/// the feedback is secured (the proxy would have to alter a sealed datagram).
pub fn check_live(exp: &Experiment) -> Result<(), String> {
    if !exp.reals.is_f32() {
        return Err(
            "reals = \"f64\" is not supported in a live run: its frames carry singles".into(),
        );
    }
    if exp.network.is_some() {
        return Err("a multi-hop [network] is not supported in a live run yet: the live processes talk over the one-hop star (run it with `hushfuse run`)".into());
    }
    for v in &exp.variants {
        let label = &exp.curves[v.curve].label;
        if v.sequence_bits > 0 {
            return Err(format!(
                "scheme {label}: sequence_bits is not supported in a live run"
            ));
        }
        if let Some(specs) = v.channel.as_deref() {
            if specs
                .iter()
                .any(|s| !s.delay().is_zero() || s.arq.is_some())
            {
                return Err(format!(
                    "scheme {label}: its channel delays or retransmits packets; a live run takes links that only lose packets (the proxy applies them)"
                ));
            }
            let secured_down = exp.security.is_secured() && exp.security.secure_feedback;
            if secured_down && !specs.iter().all(|s| s.downlink_spec().is_lossless()) {
                return Err(format!(
                    "scheme {label}: its feedback link loses packets, and the feedback is secured: the channel proxy cannot take the feedback out of a sealed announcement (set secure_feedback = false in [security], or a lossless downlink)"
                ));
            }
        }
    }
    Ok(())
}
