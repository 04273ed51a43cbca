//! The link between the sensors and the fusion center inside the trial loop
//! ([`crate::engine::trial`]), for a scenario with a `[channel]`: the fates of the trial's
//! slots ([`crate::network::channel`]), what each sensor last heard on the downlink, and the
//! packets in flight.
//!
//! A lost packet reaches the center as a silence (the center cannot tell the two apart) but
//! keeps its bits. A late packet is a silence at its own step too; when it arrives, `d` steps
//! later and within the horizon, the center is rebuilt and re-fuses every step from the first
//! with what has arrived by then in its place, so that its estimate is the in-order filter's
//! on the data it holds. That is exact for every center (the Kalman family gives the in-order
//! filter; a particle filter draws again from its own seed, so its draws up to the late
//! packet's step are the ones it made the first time). It costs a replay of the trial so far
//! per step with an arrival: fine for the delays a link has, not for long trials with many
//! late packets. A packet later than the horizon is dropped and counted.
//!
//! With retransmission (`arq`) a slot's fate already holds its attempts (drawn with the slot,
//! [`crate::network::channel::fate`]): the packet is lost only when every attempt was, every
//! attempt costs its bits and frame, and the acknowledgements, retries and duplicates are
//! counted ([`LinkLayer::deliver`]). The center fuses one copy, as without ARQ.
use crate::link::{Received, Transmission};
use crate::network::channel::{ChannelSpec, FateTable};
use crate::network::{self, Traffic};
use crate::scenario::experiment::{Experiment, Variant};
use crate::scheme::{Feedback, FusionCenter, Scheme, SchemeError};

/// Whether a variant runs as if its links were ideal: no channel, or one whose every link is
/// lossless ([`ChannelSpec::is_lossless`]: nothing lost, late or
/// retransmitted, in either direction). Its trials then take the fast paths, which give the
/// generic loop's numbers, and its link counters are all zero, as the generic loop would count
/// them; `summary.json` still has the `link` section of a scenario with a channel.
pub(crate) fn lossless(variant: &Variant) -> bool {
    variant
        .channel
        .as_deref()
        .is_none_or(|specs| specs.iter().all(|s| s.is_lossless()))
}

/// What one sensor did at one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// Sent, and the packet arrived.
    Sent,
    Silent,
    NotScheduled,
    /// Sent (its bits and frame were spent), and the link lost the packet: the fusion center
    /// saw a silence.
    Lost,
    /// Sent, and the link delivers it late: a silence at its step, fused when it arrives
    /// (within the horizon; dropped beyond it).
    Late,
}

/// A packet in flight: sent by `sensor` at step `sent`, fused at step `arrive`.
struct InFlight {
    arrive: usize,
    sent: usize,
    sensor: usize,
    message: Received,
}

/// One trial's link: its fates, the feedback each sensor holds, the packets in flight and
/// (with delays) every inbox fused so far.
pub(crate) struct LinkLayer {
    up: FateTable,
    /// `None` when every downlink is lossless: nothing to draw, every feedback arrives.
    down: Option<FateTable>,
    /// The last feedback that reached each sensor; one entry, shared by all, when every
    /// downlink is lossless (`down` is `None`).
    held: Vec<Option<Feedback>>,
    /// Steps a late packet may take and still be fused.
    horizon: usize,
    in_flight: Vec<InFlight>,
    /// The inbox of every step so far, late packets in their own step once they arrived.
    history: Vec<Vec<Received>>,
}

impl LinkLayer {
    /// The link of trial `trial` of variant `variant` of `exp` (`None` for an ideal one);
    /// `initial` is the center's feedback before the first step, which every sensor holds (it
    /// is made from the prior, which they know).
    ///
    /// A lossless channel (every link [`ChannelSpec::is_lossless`]) has no link layer either:
    /// it would change nothing and count nothing.
    pub(crate) fn new(
        exp: &Experiment,
        variant: usize,
        trial: usize,
        initial: &Option<Feedback>,
    ) -> Option<Self> {
        let specs = exp.variants[variant].channel.as_deref()?;
        if specs.iter().all(ChannelSpec::is_lossless) {
            return None;
        }
        let horizon = specs.iter().map(|s| s.delay().horizon()).max().unwrap_or(0);
        let down = (!specs.iter().all(|s| s.downlink_spec().is_lossless()))
            .then(|| FateTable::draw(specs, exp.steps, exp.seed, trial as u64, true));
        let holders = if down.is_some() { specs.len() } else { 1 };
        Some(Self {
            up: FateTable::draw(specs, exp.steps, exp.seed, trial as u64, false),
            down,
            held: vec![initial.clone(); holders],
            horizon: horizon as usize,
            in_flight: Vec::new(),
            history: Vec::new(),
        })
    }

    /// The feedback of step `k` goes out: each sensor whose downlink slot keeps it holds it.
    /// Returns the packets lost (only feedback that was sent can be lost).
    pub(crate) fn downlink(&mut self, k: usize, feedback: &Option<Feedback>) -> u64 {
        if k == 1 {
            return 0;
        }
        let mut lost = 0;
        for (i, h) in self.held.iter_mut().enumerate() {
            if self.down.as_ref().is_some_and(|d| d.get(i, k).lost) {
                lost += u64::from(feedback.is_some());
            } else {
                h.clone_from(feedback);
            }
        }
        lost
    }

    /// The feedback sensor `i` holds.
    pub(crate) fn feedback(&self, i: usize) -> Option<&Feedback> {
        match self.down {
            Some(_) => self.held[i].as_ref(),
            None => self.held[0].as_ref(),
        }
    }

    /// What became of sensor `i`'s packet sent at step `k`.
    pub(crate) fn link(&self, i: usize, k: usize) -> Link {
        let fate = self.up.get(i, k);
        if fate.lost {
            Link::Lost
        } else if fate.delay > 0 {
            Link::Late
        } else {
            Link::Sent
        }
    }

    /// Step `k`'s transmissions into `inbox`, counted with every attempt the link's fates give
    /// them ([`network::deliver_attempts`]); [`LinkLayer::uplink`] then applies the fates.
    pub(crate) fn deliver(
        &self,
        k: usize,
        transmissions: impl IntoIterator<Item = Transmission>,
        inbox: &mut Vec<Received>,
    ) -> Traffic {
        network::deliver_attempts(transmissions, inbox, |i| self.up.get(i, k))
    }

    /// Step `k`'s packets through the link: a lost or late one becomes a silence in `inbox`,
    /// counted in `traffic`; a late one within the horizon goes in flight.
    pub(crate) fn uplink(&mut self, k: usize, inbox: &mut [Received], traffic: &mut Traffic) {
        for (i, r) in inbox.iter_mut().enumerate() {
            if matches!(r, Received::Silent | Received::NotScheduled) {
                continue;
            }
            let fate = self.up.get(i, k);
            let delay = fate.delay as usize;
            if fate.lost {
                traffic.lost += 1;
            } else if delay == 0 {
                continue;
            } else if delay <= self.horizon {
                traffic.late += 1;
                self.in_flight.push(InFlight {
                    arrive: k + delay,
                    sent: k,
                    sensor: i,
                    message: r.clone(),
                });
            } else {
                traffic.dropped_late += 1;
            }
            *r = Received::Silent;
        }
    }

    /// Fuses step `k`'s `inbox` into `center`: directly, or, when late packets arrive at this
    /// step, by a center rebuilt from `scheme` (seeded with `center_seed`) that re-fuses every
    /// step with the arrivals in their own steps.
    pub(crate) fn fuse(
        &mut self,
        k: usize,
        inbox: &[Received],
        center: &mut Box<dyn FusionCenter>,
        scheme: &dyn Scheme,
        center_seed: u64,
    ) -> Result<(), (usize, SchemeError)> {
        let mut arrived = false;
        let mut i = 0;
        while i < self.in_flight.len() {
            if self.in_flight[i].arrive == k {
                let p = self.in_flight.swap_remove(i);
                self.history[p.sent - 1][p.sensor] = p.message;
                arrived = true;
            } else {
                i += 1;
            }
        }
        if arrived {
            let mut fresh = scheme
                .build_with_seed(center_seed)
                .map_err(|e| (0, e))?
                .center;
            for (j, past) in self.history.iter().enumerate() {
                fresh.step(j + 1, past).map_err(|e| (j + 1, e))?;
            }
            *center = fresh;
        }
        center.step(k, inbox).map_err(|e| (k, e))?;
        if self.horizon > 0 {
            self.history.push(inbox.to_vec());
        }
        Ok(())
    }
}
