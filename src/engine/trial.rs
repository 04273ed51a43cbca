//! The time loop of one trial of one scheme variant, written once: sense (every scheduled
//! sensor node steps on its measurement with its own coins of the variant), schedule (the scheme's
//! mask, and which readings a recording has), deliver (the network counts the bits and fills
//! the fusion center's inbox), fuse, feed back. The Monte Carlo runner, the trial-0 trace,
//! replay of recorded data and the report's error bands all run their trials here, seeded by
//! [`crate::stats::seeding`]; an [`Observer`] sees every fused step.
//!
//! A scheme's lockstep fast path ([`LockstepFastPath::run_trial_fast`], offered by
//! [`Scheme::fast_path`]) is a hook of this loop: taken when the observer can take its report
//! ([`Observer::fast_sink`]) and every reading exists, on an ideal link or one that only loses
//! packets (the fast path applies the losses, [`Losses`]), with the same numbers as the loop
//! (the bit-for-bit tests are in `tests/fast_paths.rs`).
use crate::engine::fusion_side::{self, FusionSide};
pub use crate::engine::link_layer::Link;
use crate::engine::link_layer::{self, FateCache, LinkLayer};
use crate::filter::Gaussian;
use crate::linalg::{LinalgError, Vector};
use crate::link::{Message, Received, Transmission};
use crate::network::channel::Fate;
use crate::network::{self, Schedule, Traffic};
use crate::scenario::experiment::Experiment;
#[cfg(doc)]
use crate::scheme::fast_path::LockstepFastPath;
use crate::scheme::fast_path::{BatchSink, FastTrialError, Losses, TrialCache};
#[cfg(doc)]
use crate::scheme::Scheme;
use crate::scheme::{SchemeError, SensorNode};
use crate::stats::seeding::coins;
use std::ops::{Deref, DerefMut};

/// One fused step, as an [`Observer`] sees it.
#[derive(Debug)]
pub struct StepOutput<'a> {
    /// The step, 1-based.
    pub k: usize,
    pub estimate: &'a Gaussian,
    /// Per sensor: sent, silent or not scheduled (empty unless [`Observer::needs_links`]).
    pub links: &'a [Link],
    /// Per sensor: the payload bits sent, sequence number included (empty unless
    /// [`Observer::needs_links`]).
    pub bits: &'a [u64],
    pub traffic: Traffic,
    /// Effective sample size of a particle filter's fusion center.
    pub ess: Option<f64>,
    /// Over a multi-hop network: what each node did this step (empty on a star).
    pub nodes: &'a [crate::network::topology::tally::NodeCounts],
}

/// Why an observer stopped the loop.
#[derive(Debug, Clone, PartialEq)]
pub enum ObserverError {
    /// The fused covariance could not be factored for the metrics.
    Covariance(LinalgError),
    /// Any other reason, in words.
    Message(String),
}

/// Why a trial's loop stopped, at which step (0: building the scheme).
#[derive(Debug, Clone, PartialEq)]
pub enum LoopError {
    Scheme {
        k: usize,
        source: SchemeError,
    },
    Covariance {
        k: usize,
        source: LinalgError,
    },
    Observer {
        k: usize,
        message: String,
    },
    /// What the caller of [`Trial::step`] passed does not fit the trial (a step out of order,
    /// a reading missing or of the wrong size).
    Input {
        k: usize,
        message: String,
    },
}

impl LoopError {
    /// The command line's words for a failure of scheme `label`:
    /// "scheme {label}, step {k}: …".
    pub fn describe(&self, label: &str) -> String {
        match self {
            LoopError::Scheme { k, source } => format!("scheme {label}, step {k}: {source}"),
            LoopError::Covariance { k, source } => format!(
                "scheme {label}, step {k}: fused covariance is not positive definite ({source})"
            ),
            LoopError::Observer { message, .. } => message.clone(),
            LoopError::Input { k, message } => format!("scheme {label}, step {k}: {message}"),
        }
    }
}

/// Sees the fused steps of a trial.
pub trait Observer {
    /// Whether [`StepOutput::links`] and [`StepOutput::bits`] are read (collecting them costs a
    /// little per sensor and step).
    fn needs_links(&self) -> bool {
        true
    }

    /// Fused step `s.k`.
    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError>;

    /// The observer as the sink of a scheme's fast path (which reports estimates and traffic,
    /// no links), or `None` when it needs what only the loop gives.
    fn fast_sink(&mut self) -> Option<&mut dyn BatchSink> {
        None
    }
}

/// Which trial, which variant, which coins, which readings.
#[derive(Debug, Clone, Copy)]
pub struct TrialSpec<'a> {
    pub trial: usize,
    /// The variant of the experiment.
    pub variant: usize,
    /// Its coin stream: [`crate::stats::seeding::coin_stream`] of the variant, or of 0 for a
    /// variant run alone as the only one of its experiment would be (calibration).
    pub stream: u64,
    /// Recorded data: `available[k - 1][i]` says whether sensor i has a reading at step k (one
    /// that has none is not scheduled). `None`: every reading exists.
    pub available: Option<&'a [Vec<bool>]>,
}

/// Work space of the loop, reused from variant to variant and trial to trial.
pub struct LoopBuffers {
    inbox: Vec<Received>,
    transmissions: Vec<Transmission>,
    links: Vec<Link>,
    bits: Vec<u64>,
    /// Work shared by the variants of one trial (fast paths).
    cache: TrialCache,
    /// (trial, address of its measurements) the cache belongs to: an identity only, never
    /// dereferenced.
    cache_of: Option<(usize, usize)>,
    /// The link's fates of the current trial, shared by its variants.
    fates: FateCache,
}

impl LoopBuffers {
    pub fn new(n_sensors: usize) -> Self {
        Self {
            inbox: Vec::with_capacity(n_sensors),
            transmissions: Vec::with_capacity(n_sensors),
            links: Vec::with_capacity(n_sensors),
            bits: Vec::with_capacity(n_sensors),
            cache: TrialCache::new(),
            cache_of: None,
            fates: FateCache::default(),
        }
    }

    /// The cache as a lockstep batch uses it: work space and data-independent entries only
    /// (a batch has no single trial the cache could belong to).
    pub(crate) fn batch_cache(&mut self) -> &mut TrialCache {
        &mut self.cache
    }

    /// The trial cache, emptied first when it belongs to another trial's data.
    pub(crate) fn cache_for(
        &mut self,
        trial: usize,
        measurements: &[Vec<Vector>],
    ) -> &mut TrialCache {
        let of = Some((trial, measurements.as_ptr() as usize));
        if self.cache_of != of {
            self.cache.clear();
            self.cache_of = of;
        }
        &mut self.cache
    }
}

/// Runs one trial of one variant on `measurements` (`measurements[k - 1][i]` = z_k^i),
/// reporting every fused step to `observer`: the scheme's fast path when it applies, else
/// [`Trial::step`] at every step.
pub fn run_trial(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    spec: TrialSpec,
    buffers: &mut LoopBuffers,
    observer: &mut dyn Observer,
) -> Result<(), LoopError> {
    let n_sensors = exp.system.n_sensors();
    let (mut coins, center_seed) = coins(exp.seed, spec.trial, spec.stream, n_sensors);
    if let Some(r) = fast_path(exp, measurements, spec, buffers, observer, &mut coins) {
        return r;
    }
    let with_links = observer.needs_links();
    let mut trial = Trial::with_coins(exp, spec, buffers, (coins, center_seed), with_links)?;
    for k in 1..=exp.steps {
        let out = trial.advance(k, &measurements[k - 1])?;
        observer.step(&out).map_err(|e| match e {
            ObserverError::Covariance(source) => LoopError::Covariance { k, source },
            ObserverError::Message(message) => LoopError::Observer { k, message },
        })?;
    }
    Ok(())
}

/// One trial of one variant, one step at a time: the one place where a step's rules live
/// (sense, schedule, deliver over the link, fuse, feed back). [`run_trial`] drives it for the
/// Monte Carlo runner, the trace, replay and the report's bands; a caller with readings that
/// arrive one step at a time (a Python loop, a live deployment) can drive it the same way.
///
/// It borrows the experiment and the work space (`E`, `B`), or holds them (an `Arc` and a
/// `Box`, for a caller that keeps the trial between calls, as Python's `hushfuse.Trial` does).
pub struct Trial<'a, E = &'a Experiment, B = &'a mut LoopBuffers>
where
    E: Deref<Target = Experiment>,
    B: DerefMut<Target = LoopBuffers>,
{
    exp: E,
    spec: TrialSpec<'a>,
    sensors: Vec<Box<dyn SensorNode>>,
    fusion: FusionSide,
    schedule: Schedule,
    coins: Vec<rand_xoshiro::Xoshiro256PlusPlus>,
    link: Option<LinkLayer>,
    with_links: bool,
    buffers: B,
    /// Steps taken.
    done: usize,
}

impl<'a, E, B> Trial<'a, E, B>
where
    E: Deref<Target = Experiment>,
    B: DerefMut<Target = LoopBuffers>,
{
    /// Trial `spec.trial` of variant `spec.variant` of `exp`, its scheme built and its link's
    /// fates drawn, before its first step; `with_links`: whether [`StepOutput::links`] and
    /// [`StepOutput::bits`] are filled.
    pub fn new(
        exp: E,
        spec: TrialSpec<'a>,
        buffers: B,
        with_links: bool,
    ) -> Result<Self, LoopError> {
        let coins = coins(exp.seed, spec.trial, spec.stream, exp.system.n_sensors());
        Self::with_coins(exp, spec, buffers, coins, with_links)
    }

    fn with_coins(
        exp: E,
        spec: TrialSpec<'a>,
        mut buffers: B,
        (coins, center_seed): (Vec<rand_xoshiro::Xoshiro256PlusPlus>, u64),
        with_links: bool,
    ) -> Result<Self, LoopError> {
        let (fusion, sensors) = FusionSide::with_seed(&exp, spec.variant, spec.trial, center_seed)
            .map_err(|source| LoopError::Scheme { k: 0, source })?;
        // The link's fates of this trial, from its own stream: every scheme meets the same ones;
        // the downlink carries what the center tells the sensors before the first measurement.
        let link = LinkLayer::new(
            &exp,
            spec.variant,
            spec.trial,
            fusion.feedback(),
            &mut buffers.fates,
        );
        let schedule = exp.variants[spec.variant].scheme.schedule();
        Ok(Self {
            exp,
            spec,
            schedule,
            sensors,
            fusion,
            coins,
            link,
            with_links,
            buffers,
            done: 0,
        })
    }

    /// Step `k` (1, 2, … in order; anything else is [`LoopError::Input`]) on the readings `readings[i]` = z_k^i: every scheduled
    /// sensor steps with its own coins and the feedback it holds, the link delivers (counting
    /// every bit and hop), the center fuses, and its feedback goes out for the next step.
    pub fn step(&mut self, k: usize, readings: &[Vector]) -> Result<StepOutput<'_>, LoopError> {
        if k != self.done + 1 {
            return Err(LoopError::Input {
                k,
                message: format!("steps come in order: step {} is next", self.done + 1),
            });
        }
        check_readings(&self.exp, k, self.spec.available, readings)?;
        self.done = k;
        self.advance(k, readings)
    }

    /// [`Trial::step`] on input known to fit (the runner's own data, in order): the step itself.
    fn advance(&mut self, k: usize, readings: &[Vector]) -> Result<StepOutput<'_>, LoopError> {
        let exp: &Experiment = &self.exp;
        let n_sensors = exp.system.n_sensors();
        let variant = &exp.variants[self.spec.variant];
        let (schedule, available) = (self.schedule, self.spec.available);
        let scheduled = |i: usize| {
            fusion_side::scheduled(
                schedule,
                k,
                i,
                n_sensors,
                available.is_none_or(|a| a[k - 1][i]),
            )
        };
        let link = &mut self.link;
        let downlink_lost = link
            .as_mut()
            .map_or(0, |l| l.downlink(k, self.fusion.feedback()));
        let LoopBuffers {
            inbox,
            transmissions,
            links,
            bits,
            ..
        } = &mut *self.buffers;
        transmissions.clear();
        links.clear();
        bits.clear();
        let mut scheduled_mask = 0u128;
        let mut doubles = Doubles::new(exp.reals);
        for (i, (node, rng)) in self.sensors.iter_mut().zip(&mut self.coins).enumerate() {
            let fb = match &link {
                Some(l) => l.feedback(i),
                None => self.fusion.feedback(),
            };
            let t = if scheduled(i) {
                scheduled_mask |= network::sensor_bit(i);
                node.step(k, &readings[i], fb, rng)
                    .map_err(|source| LoopError::Scheme { k, source })?
            } else {
                Transmission::Silent
            };
            doubles.record(&t);
            if self.with_links {
                let (link, b) = match &t {
                    _ if !scheduled(i) => (Link::NotScheduled, 0),
                    Transmission::Send(m) => {
                        let b = m.bits_with_sequence(variant.sequence_bits) + doubles.extra(m);
                        (link.as_ref().map_or(Link::Sent, |l| l.link(i, k)), b)
                    }
                    Transmission::Silent => (Link::Silent, 0),
                };
                links.push(link);
                bits.push(b);
            }
            transmissions.push(t);
        }
        let mut traffic = match link {
            Some(l) => l.deliver(k, transmissions.drain(..), inbox),
            None if variant.sequence_bits == 0 => network::deliver(transmissions.drain(..), inbox),
            // Ideal links (nothing goes missing, so the numbers reveal nothing): only their cost.
            None => network::deliver_sequenced(
                transmissions.drain(..),
                inbox,
                |_| Fate::default(),
                variant.sequence_bits,
            ),
        };
        let singles = exp.reals.is_f32();
        traffic.downlink_bits =
            self.fusion.feedback().map_or(0, |f| f.bits(n_sensors)) * if singles { 1 } else { 2 };
        // The sink's estimate going down the tree rides in the feedback's frame (a network's
        // reals are singles).
        if exp.network.as_ref().is_some_and(|n| n.broadcast_estimate) {
            traffic.downlink_bits += 32 * network::estimate_reals(exp.system.state_dim());
        }
        traffic.scheduled = scheduled_mask;
        if let Some(l) = link {
            l.uplink(k, inbox, &mut traffic);
            l.feedback_down(k, traffic.downlink_bits);
            traffic.downlink_lost = downlink_lost;
        }
        // After the feedback went down (the tally secures each hop's frame itself).
        // On a multi-hop network every hop's frame is secured: the nodes' counters have them.
        let hop_frames = link
            .as_ref()
            .map(|l| l.nodes())
            .filter(|nodes| !nodes.is_empty())
            .map(|nodes| {
                nodes
                    .iter()
                    .map(|c| network::topology::tally::sent(c).0)
                    .sum()
            });
        let frames = hop_frames.unwrap_or_else(|| traffic.star_frames());
        traffic.secure(&exp.security, frames);
        doubles.restore(inbox, &mut traffic);
        if schedule != Schedule::All || available.is_some() {
            for (i, r) in inbox.iter_mut().enumerate() {
                if !scheduled(i) {
                    *r = Received::NotScheduled;
                }
            }
        }
        let fusion = &mut self.fusion;
        match link {
            Some(l) => l
                .fuse(k, inbox, fusion, variant.scheme.as_ref())
                .map_err(|(k, source)| LoopError::Scheme { k, source })?,
            None => fusion
                .step(k, inbox)
                .map_err(|source| LoopError::Scheme { k, source })?,
        }
        Ok(StepOutput {
            k,
            estimate: fusion.estimate(),
            links,
            bits,
            traffic,
            ess: fusion.ess(),
            nodes: link.as_ref().map_or(&[], |l| l.nodes()),
        })
    }
}

/// Step `k`'s readings fit the trial: one per sensor of its dimension, where the sensor has
/// one; `k` within the run (the schedule and the link's fates are drawn for its steps).
fn check_readings(
    exp: &Experiment,
    k: usize,
    available: Option<&[Vec<bool>]>,
    readings: &[Vector],
) -> Result<(), LoopError> {
    let input = |message: String| Err(LoopError::Input { k, message });
    if k == 0 || k > exp.steps {
        return input(format!("steps run from 1 to {}", exp.steps));
    }
    if readings.len() != exp.system.n_sensors() {
        return input(format!(
            "{} readings for {} sensors",
            readings.len(),
            exp.system.n_sensors()
        ));
    }
    for (i, (z, s)) in readings.iter().zip(&exp.system.sensors).enumerate() {
        let present = available.is_none_or(|a| a[k - 1][i]);
        if present && z.len() != s.meas_dim() {
            return input(format!(
                "sensor {i}'s reading has {} components, the sensor measures {}",
                z.len(),
                s.meas_dim()
            ));
        }
    }
    Ok(())
}

/// The scheme's fast path for this trial, when it has one that applies: an ideal link, or one
/// that only loses packets (the fast path applies the losses); every reading present; reals
/// as singles (the fast paths deliver singles). Delays, retransmissions, sequence numbers and
/// doubles are the generic loop's. `None`: run the generic loop (nothing was drawn).
fn fast_path(
    exp: &Experiment,
    measurements: &[Vec<Vector>],
    spec: TrialSpec,
    buffers: &mut LoopBuffers,
    observer: &mut dyn Observer,
    coins: &mut [rand_xoshiro::Xoshiro256PlusPlus],
) -> Option<Result<(), LoopError>> {
    let variant = &exp.variants[spec.variant];
    let ideal = match link_layer::route(exp, variant, spec.available.is_none()) {
        link_layer::Route::Generic => return None,
        link_layer::Route::FastWithLosses => false,
        link_layer::Route::FastIdeal => true,
    };
    // One virtual call per trial: the scheme's hook, then its whole trial.
    let (fast, sink) = (variant.scheme.fast_path()?, observer.fast_sink()?);
    let uplink = match variant.channel.as_deref() {
        Some(specs) if !ideal => Some(buffers.fates.get(exp, specs, spec.trial, false)),
        _ => None,
    };
    let losses = uplink.as_deref().map(Losses::new);
    let cache = buffers.cache_for(spec.trial, measurements);
    let r = fast.run_trial_fast(measurements, exp.steps, losses.as_ref(), coins, cache, sink)?;
    Some(r.map_err(|e| match e {
        FastTrialError::Scheme { k, source } => LoopError::Scheme { k, source },
        FastTrialError::Sink { k, source } => LoopError::Covariance { k, source },
    }))
}

/// Reals sent as doubles (`reals = "f64"`) through one step: each message's reals as the
/// sensor sent them (the network layer delivers singles), and the bits beyond the singles'
/// count. Inert for singles.
struct Doubles {
    extra_per_real: u64,
    sent: Vec<Option<Vector>>,
    bits: u64,
}

impl Doubles {
    fn new(reals: crate::link::Reals) -> Self {
        Self {
            extra_per_real: reals.extra_bits(),
            sent: Vec::new(),
            bits: 0,
        }
    }

    /// The bits message `m` costs beyond its singles.
    fn extra(&self, m: &Message) -> u64 {
        real_count(m) * self.extra_per_real
    }

    /// The next sensor's transmission.
    fn record(&mut self, t: &Transmission) {
        if self.extra_per_real == 0 {
            return;
        }
        let reals = match t {
            Transmission::Send(m @ (Message::Measurement(v) | Message::Estimate(v))) => {
                self.bits += self.extra(m);
                Some(v.clone())
            }
            _ => None,
        };
        self.sent.push(reals);
    }

    /// What arrived as singles arrives as the doubles that were sent, and costs their bits.
    fn restore(&mut self, inbox: &mut [Received], traffic: &mut Traffic) {
        traffic.bits += self.bits;
        traffic.frame_bits += self.bits;
        for (r, exact) in inbox.iter_mut().zip(self.sent.drain(..)) {
            if let (Received::Measurement(v) | Received::Estimate(v), Some(exact)) = (r, exact) {
                *v = exact;
            }
        }
    }
}

/// Real components a message carries (measurements and estimates; a codec's frame has none).
fn real_count(m: &Message) -> u64 {
    match m {
        Message::Measurement(v) | Message::Estimate(v) => v.len() as u64,
        Message::Frame { .. } => 0,
    }
}
