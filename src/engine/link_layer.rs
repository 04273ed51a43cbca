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
//! counted (`LinkLayer::deliver`). The center fuses one copy, as without ARQ.
//!
//! # Sequence numbers
//!
//! With `sequence_bits = b > 0` (a scheme entry's key, [`Variant::sequence_bits`]) every packet
//! of sensor i carries the count of i's packets before it, mod 2^b; the network prices those
//! bits ([`network::deliver_sequenced`]). When a packet of i reaches the center (in time, or late
//! and fused), the center compares its number with that of i's previous packet to have arrived
//! (by sending order; before the first, the count starts at 0) and learns the gap: how many of
//! i's packets in between never arrived, mod 2^b, so a run of 2^b losses (or any multiple) is
//! invisible. It does not learn which of i's silent steps in between were the lost packets.
//!
//! The exact treatment would fuse a mixture: over every choice of `gap` (mod 2^b) of the silent
//! steps in between as the lost packets, the rest as real silences, each choice weighted by its
//! likelihood under the scheme's triggering rule — a number of hypotheses binomial in the length
//! of the gap, and a center of its own for each. This one is conservative instead: when the gap
//! is not 0, every step of i between the two arrivals that reached the center as a silence
//! becomes [`Received::NotScheduled`] (no information from i at that step, which every center
//! handles), and the center is rebuilt and re-fuses from the first step (the late packets'
//! machinery). It throws away the information of the real silences of a gap with a loss (their
//! "the reading was unremarkable"), never claims a silence that may have been a loss. When the
//! gap is 0 the silences in between are confirmed real silences and stay. Packets still missing
//! at the end of the trial are never revealed. A gap marked unknown stays so even if a late
//! packet inside it arrives afterwards (that packet itself is fused at its step). Cost: one
//! replay of the trial so far per step at which a gap is revealed, and the history of every
//! inbox is kept whenever sequence numbers are on.
use crate::engine::fusion_side::FusionSide;
use crate::link::{Received, Transmission};
use crate::network::aggregate::{self, Aggregation};
use crate::network::channel::route::{RouteFates, Routes};
use crate::network::channel::{ChannelSpec, FateTable};
use crate::network::topology::tally::{NodeCounts, Tally};
use crate::network::{self, Traffic};
use crate::scenario::experiment::{Experiment, Variant};
use crate::scheme::{Feedback, Scheme, SchemeError};
use std::sync::Arc;

/// Whether a variant's trials may take the fast paths as on an ideal link: its links are
/// [`lossless`] and its packets carry no sequence number (the fast paths count their own
/// traffic, without one; a variant with `sequence_bits > 0` runs the generic loop, whose numbers
/// are theirs otherwise). A link that only loses packets keeps them too ([`losses_only`]).
pub(crate) fn ideal(variant: &Variant) -> bool {
    variant.sequence_bits == 0 && lossless(variant)
}

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

/// Whether a variant's lossy link only loses packets: no delay, no retransmission, no sequence
/// numbers. Its trials may then take the fast paths, which apply the losses themselves
/// ([`crate::scheme::fast_path::Losses`]); a lossy downlink changes nothing for them (their
/// schemes send no feedback).
pub(crate) fn losses_only(variant: &Variant) -> bool {
    variant.sequence_bits == 0
        && variant
            .channel
            .as_deref()
            .is_some_and(|specs| specs.iter().all(|s| s.delay().is_zero() && s.arq.is_none()))
}

/// How a variant's trials may run: the one rule, asked by the runner (may a block batch?) and
/// by the trial loop (may this trial take the fast path?), so that the two cannot disagree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Route {
    /// The generic per-step loop: delays, retransmissions, sequence numbers, doubles
    /// (`reals = "f64"`: the fast paths deliver singles), or recorded readings with holes.
    Generic,
    /// A fast trial that applies the link's losses (the fast paths draw no fate of their own).
    FastWithLosses,
    /// A fast trial on an ideal link; a block of such trials may also run as a batch when the
    /// scheme's fast path batches.
    FastIdeal,
}

/// The [`Route`] of variant `variant` of `exp`; `every_reading` says whether every reading of
/// the trial is present (a replay with holes runs the generic loop).
pub(crate) fn route(exp: &Experiment, variant: &Variant, every_reading: bool) -> Route {
    // A multi-hop network counts every hop of every report: the generic loop's work.
    if !exp.reals.is_f32() || !every_reading || exp.network.is_some() {
        Route::Generic
    } else if ideal(variant) {
        Route::FastIdeal
    } else if losses_only(variant) {
        Route::FastWithLosses
    } else {
        Route::Generic
    }
}

/// The fate tables of one trial, shared by its variants whose links are the same: a table is a
/// function of the links, the trial and the experiment's seed and steps only
/// ([`FateTable::draw`]), so it is drawn once per trial rather than once per variant.
#[derive(Default)]
pub(crate) struct FateCache {
    /// (trial, seed, steps) of the tables.
    of: Option<(usize, u64, usize)>,
    /// (links, downlink?, table).
    tables: Vec<(Vec<ChannelSpec>, bool, Arc<FateTable>)>,
    /// The multi-hop network's fates (one network per experiment, shared by every variant).
    routes: Option<Arc<RouteFates>>,
}

impl FateCache {
    /// The uplink (`downlink = false`) or downlink table of `specs` in trial `trial` of `exp`.
    pub(crate) fn get(
        &mut self,
        exp: &Experiment,
        specs: &[ChannelSpec],
        trial: usize,
        downlink: bool,
    ) -> Arc<FateTable> {
        let of = Some((trial, exp.seed, exp.steps));
        self.renew(of);
        if let Some((_, _, t)) = self
            .tables
            .iter()
            .find(|(s, d, _)| *d == downlink && s.as_slice() == specs)
        {
            return t.clone();
        }
        let table = Arc::new(FateTable::draw(
            specs,
            exp.steps,
            exp.seed,
            trial as u64,
            downlink,
        ));
        self.tables.push((specs.to_vec(), downlink, table.clone()));
        table
    }

    /// Forgets the tables of another (trial, seed, steps).
    fn renew(&mut self, of: Option<(usize, u64, usize)>) {
        if self.of != of {
            self.tables.clear();
            self.routes = None;
            self.of = of;
        }
    }

    /// The fates of `routes` (the experiment's network) in trial `trial` of `exp`.
    fn routes(&mut self, exp: &Experiment, routes: &Routes, trial: usize) -> Arc<RouteFates> {
        self.renew(Some((trial, exp.seed, exp.steps)));
        self.routes
            .get_or_insert_with(|| {
                let net = exp.network.as_deref();
                let per_source = exp.variants.iter().any(|v| !v.aggregated(net));
                Arc::new(RouteFates::draw(
                    routes,
                    exp.steps,
                    exp.seed,
                    trial as u64,
                    per_source,
                ))
            })
            .clone()
    }
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
    /// The sensor's packets before this one (its sequence number is this mod 2^b).
    count: u64,
    message: Received,
}

/// What the sequence numbers tell the center (`sequence_bits > 0`).
struct Sequencing {
    /// 2^b.
    modulus: u64,
    /// Per sensor: packets sent so far.
    sent: Vec<u64>,
    /// Per sensor: the packets that arrived, as (step sent, count), in sending order.
    arrived: Vec<Vec<(usize, u64)>>,
    /// Packets arrived in time at the current step, as (sensor, step sent, count), read at
    /// the next [`LinkLayer::fuse`].
    pending: Vec<(usize, usize, u64)>,
}

impl Sequencing {
    fn new(bits: u32, sensors: usize) -> Option<Self> {
        (bits > 0).then(|| Self {
            modulus: 1u64 << bits.min(32),
            sent: vec![0; sensors],
            arrived: vec![Vec::new(); sensors],
            pending: Vec::new(),
        })
    }

    /// Sensor `i` sends a packet: its count.
    fn send(&mut self, i: usize) -> u64 {
        let c = self.sent[i];
        self.sent[i] += 1;
        c
    }

    /// Sensor `i`'s packet `count`, sent at step `sent`, arrives: the gap its number reveals
    /// since the previous arrival (mod 2^b), with that arrival's step (0 before the first).
    fn arrive(&mut self, i: usize, sent: usize, count: u64) -> (u64, usize) {
        let list = &mut self.arrived[i];
        let pos = list.partition_point(|&(s, _)| s < sent);
        let (from, lost) = match pos.checked_sub(1).map(|p| list[p]) {
            Some((s, c)) => (s, count - c - 1),
            None => (0, count),
        };
        list.insert(pos, (sent, count));
        (lost % self.modulus, from)
    }
}

/// One trial's link: its fates, the feedback each sensor holds, the packets in flight and
/// (with delays) every inbox fused so far.
pub(crate) struct LinkLayer {
    up: Arc<FateTable>,
    /// `None` when every downlink is lossless: nothing to draw, every feedback arrives.
    down: Option<Arc<FateTable>>,
    /// The last feedback that reached each sensor; one entry, shared by all, when every
    /// downlink is lossless (`down` is `None`).
    held: Vec<Option<Feedback>>,
    /// Steps a late packet may take and still be fused.
    horizon: usize,
    in_flight: Vec<InFlight>,
    /// The inbox of every step so far, late packets in their own step once they arrived
    /// (kept with delays or sequence numbers).
    history: Vec<Vec<Received>>,
    /// `None` without sequence numbers.
    sequencing: Option<Sequencing>,
    /// Bits of each packet's sequence number (0: none).
    sequence_bits: u32,
    /// Over a multi-hop network: every hop's fates and what each node did this step.
    hops: Option<Hops>,
}

/// A multi-hop network's share of the link: the routes, their fates, the nodes' counters.
struct Hops {
    routes: Routes,
    fates: Arc<RouteFates>,
    tally: Tally,
    /// For a variant whose relays sum its reports ([`crate::network::aggregate`]).
    aggregation: Option<Aggregation>,
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
        initial: Option<&Feedback>,
        fates: &mut FateCache,
    ) -> Option<Self> {
        if let Some(net) = &exp.network {
            let routes = net.routes();
            let route_fates = fates.routes(exp, &routes, trial);
            let horizon = (0..routes.senders.len())
                .map(|i| routes.horizon(i))
                .max()
                .unwrap_or(0)
                .min(exp.steps as u64) as usize;
            let v = &exp.variants[variant];
            // Summed reports reach the sink when every node of their route delivered its frame.
            let aggregation = v.aggregated(Some(net)).then(|| {
                let sensors = exp.system.sensors.iter().map(|s| {
                    let s = s
                        .as_linear()
                        .expect("an aggregable scheme's sensors are linear");
                    (s.ht_rinv().clone(), s.information().clone())
                });
                Aggregation::new(&routes, sensors.collect())
            });
            let up = match &aggregation {
                Some(_) => Arc::new(aggregate::composed(
                    &routes,
                    &route_fates.node_up,
                    exp.steps,
                )),
                None => route_fates.up.clone(),
            };
            let mut link = Self::with_fates(up, route_fates.down.clone(), horizon, v.sequence_bits);
            link.held = vec![initial.cloned(); link.held.len()];
            link.hops = Some(Hops {
                tally: Tally::new(net),
                routes,
                fates: route_fates,
                aggregation,
            });
            return Some(link);
        }
        let specs = exp.variants[variant].channel.as_deref()?;
        if specs.iter().all(ChannelSpec::is_lossless) {
            return None;
        }
        // A packet later than the run's last step never arrives: no longer horizon is needed.
        let horizon = specs
            .iter()
            .map(|s| s.delay().horizon() as usize)
            .max()
            .unwrap_or(0)
            .min(exp.steps);
        let down = (!specs.iter().all(|s| s.downlink_spec().is_lossless()))
            .then(|| fates.get(exp, specs, trial, true));
        let up = fates.get(exp, specs, trial, false);
        let mut link = Self::with_fates(up, down, horizon, exp.variants[variant].sequence_bits);
        link.held = vec![initial.cloned(); link.held.len()];
        Some(link)
    }

    /// A link of given fates (`down`: `None` when every downlink is lossless), every sensor
    /// holding no feedback yet.
    fn with_fates(
        up: Arc<FateTable>,
        down: Option<Arc<FateTable>>,
        horizon: usize,
        sequence_bits: u32,
    ) -> Self {
        let holders = if down.is_some() { up.sensors() } else { 1 };
        Self {
            sequencing: Sequencing::new(sequence_bits, up.sensors()),
            up,
            down,
            held: vec![None; holders],
            horizon,
            in_flight: Vec::new(),
            history: Vec::new(),
            sequence_bits,
            hops: None,
        }
    }

    /// The feedback of step `k` goes out: each sensor whose downlink slot keeps it holds it.
    /// Returns the packets lost (only feedback that was sent can be lost).
    pub(crate) fn downlink(&mut self, k: usize, feedback: Option<&Feedback>) -> u64 {
        if k == 1 {
            return 0;
        }
        let mut lost = 0;
        for (i, h) in self.held.iter_mut().enumerate() {
            if self.down.as_ref().is_some_and(|d| d.get(i, k).lost) {
                lost += u64::from(feedback.is_some());
            } else {
                match (h, feedback) {
                    (Some(h), Some(f)) => h.clone_from(f),
                    (h, f) => *h = f.cloned(),
                }
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
    ///
    /// Over a multi-hop network every hop of a report is counted ([`crate::network::Traffic`]'s
    /// bits are on air, summed over the hops) and each node's share goes to its counters
    /// ([`LinkLayer::nodes`]).
    pub(crate) fn deliver(
        &mut self,
        k: usize,
        transmissions: impl IntoIterator<Item = Transmission>,
        inbox: &mut Vec<Received>,
    ) -> Traffic {
        let bits = self.sequence_bits;
        let Some(hops) = &mut self.hops else {
            return network::deliver_sequenced(transmissions, inbox, |i| self.up.get(i, k), bits);
        };
        hops.tally.start_step();
        let (tally, fates, routes) = (&mut hops.tally, &hops.fates, &hops.routes);
        if let Some(agg) = &mut hops.aggregation {
            inbox.clear();
            let mut traffic = Traffic::default();
            for (i, t) in transmissions.into_iter().enumerate() {
                if let Transmission::Send(_) = t {
                    traffic.senders |= network::sensor_bit(i);
                    traffic.messages += 1;
                }
                inbox.push(t.into());
            }
            agg.deliver(k, inbox, routes, &fates.node_up, tally, &mut traffic);
            return traffic;
        }
        let mut i = 0;
        let counted = transmissions.into_iter().inspect(|t| {
            if let Transmission::Send(m) = t {
                tally.report(
                    routes,
                    fates.hops(i, k),
                    i,
                    m.frame_bits_with_sequence(bits),
                );
            }
            i += 1;
        });
        network::deliver_sequenced(counted, inbox, |i| fates.up.get(i, k), bits)
    }

    /// Over a multi-hop network: the feedback of step `k` (`payload_bits` on air, 0 for none)
    /// going down the tree, and every relay's listening.
    pub(crate) fn feedback_down(&mut self, k: usize, payload_bits: u64) {
        if let Some(h) = &mut self.hops {
            let (fates, routes) = (&h.fates, &h.routes);
            h.tally
                .feedback(routes, payload_bits, |n| fates.node_holds(routes, n, k));
        }
    }

    /// Over a multi-hop network: what every node did this step (empty on a star).
    pub(crate) fn nodes(&self) -> &[NodeCounts] {
        self.hops.as_ref().map_or(&[], |h| h.tally.counts())
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
            let count = self.sequencing.as_mut().map_or(0, |s| s.send(i));
            if fate.lost {
                traffic.lost += 1;
            } else if delay == 0 {
                if let Some(s) = &mut self.sequencing {
                    s.pending.push((i, k, count));
                }
                continue;
            } else if delay <= self.horizon {
                traffic.late += 1;
                self.in_flight.push(InFlight {
                    arrive: k + delay,
                    sent: k,
                    sensor: i,
                    count,
                    message: r.clone(),
                });
            } else {
                traffic.dropped_late += 1;
            }
            *r = Received::Silent;
        }
    }

    /// Fuses step `k`'s `inbox` into `center`: directly, or, when late packets arrive at this
    /// step or sequence numbers reveal a gap ([`LinkLayer::receive`]), by the center rebuilt
    /// from `scheme` ([`FusionSide::rebuild`]) through every step with the arrivals in their
    /// own steps and the unknown silences made [`Received::NotScheduled`].
    pub(crate) fn fuse(
        &mut self,
        k: usize,
        inbox: &[Received],
        fusion: &mut FusionSide,
        scheme: &dyn Scheme,
    ) -> Result<(), (usize, SchemeError)> {
        if let Some(agg) = self.hops.as_ref().and_then(|h| h.aggregation.as_ref()) {
            // No delays, no sequence numbers (checked at load): nothing to re-fuse.
            return fusion.fuse_information(k, agg.held()).map_err(|e| (k, e));
        }
        if self.receive(k).is_some() {
            fusion.rebuild(scheme, &self.history)?;
        }
        fusion.step(k, inbox).map_err(|e| (k, e))?;
        self.record(inbox);
        Ok(())
    }

    /// What reaches the center before it fuses step `k`: the late packets arriving at `k` go
    /// into their own steps of the history, and (with sequence numbers) every arrival of `k`,
    /// late or in time, is read for a gap, which makes the silences it covers unknown. Returns
    /// the first step of the history that changed, if any (the center must re-fuse from it).
    fn receive(&mut self, k: usize) -> Option<usize> {
        let mut first: Option<usize> = None;
        let mut i = 0;
        while i < self.in_flight.len() {
            if self.in_flight[i].arrive == k {
                let p = self.in_flight.swap_remove(i);
                self.history[p.sent - 1][p.sensor] = p.message;
                first = Some(first.map_or(p.sent, |f| f.min(p.sent)));
                if let Some(s) = &mut self.sequencing {
                    s.pending.push((p.sensor, p.sent, p.count));
                }
            } else {
                i += 1;
            }
        }
        let Some(s) = &mut self.sequencing else {
            return first;
        };
        let mut pending = std::mem::take(&mut s.pending);
        // In sending order, so that a late packet splits the gap before a later arrival's.
        pending.sort_unstable_by_key(|&(sensor, sent, _)| (sent, sensor));
        for &(sensor, sent, count) in &pending {
            let (gap, from) = s.arrive(sensor, sent, count);
            if gap == 0 {
                continue;
            }
            for step in from + 1..sent {
                let r = &mut self.history[step - 1][sensor];
                if *r == Received::Silent {
                    *r = Received::NotScheduled;
                    first = Some(first.map_or(step, |f| f.min(step)));
                }
            }
        }
        pending.clear();
        s.pending = pending;
        first
    }

    /// Keeps step's fused `inbox` in the history when late packets or sequence numbers may
    /// change it.
    fn record(&mut self, inbox: &[Received]) {
        if self.horizon > 0 || self.sequencing.is_some() {
            self.history.push(inbox.to_vec());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Vector;
    use crate::network::channel::Fate;

    /// One sensor over 7 steps that sends at every step but 5: its packets of steps 3 and 4 are
    /// lost, the rest arrive in time. Returns the history the center holds after step 7.
    fn history_with(sequence_bits: u32) -> Vec<Received> {
        let steps = 7;
        let fates = (1..=steps)
            .map(|k| Fate {
                lost: k == 3 || k == 4,
                ..Fate::default()
            })
            .collect();
        let up = FateTable::from_fates(1, steps, fates);
        let mut link = LinkLayer::with_fates(Arc::new(up), None, 0, sequence_bits);
        for k in 1..=steps {
            let mut inbox = vec![if k == 5 {
                Received::Silent
            } else {
                Received::Measurement(Vector::from_element(1, k as f64))
            }];
            let mut traffic = Traffic::default();
            link.uplink(k, &mut inbox, &mut traffic);
            let changed = link.receive(k);
            // Step 6's packet reveals the gap (when it can): re-fuse from step 3.
            let revealed = k == 6 && sequence_bits >= 2;
            assert_eq!(
                changed,
                revealed.then_some(3),
                "b = {sequence_bits}, k = {k}"
            );
            link.record(&inbox);
        }
        link.history.iter().map(|h| h[0].clone()).collect()
    }

    #[test]
    fn a_revealed_gap_makes_its_silences_unknown() {
        let z = |k: usize| Received::Measurement(Vector::from_element(1, k as f64));
        for b in [2, 3, 8, 32] {
            let h = history_with(b);
            assert_eq!(h[..2], [z(1), z(2)]);
            // Lost, lost, silent: the center cannot tell which, so none is information.
            assert_eq!(h[2..5], [const { Received::NotScheduled }; 3], "b = {b}");
            assert_eq!(h[5..], [z(6), z(7)]);
        }
        // b = 1: two losses wrap around to a gap of 0, the silences stay.
        let h = history_with(1);
        assert_eq!(h[2..5], [const { Received::Silent }; 3]);
        // No sequence numbers: no history kept (no delay either).
        assert!(history_with(0).is_empty());
    }

    #[test]
    fn a_gap_of_zero_confirms_the_silences() {
        // Silent at 2 and 3, nothing lost: the numbers of 1 and 4 are consecutive.
        let up = FateTable::from_fates(1, 4, vec![Fate::default(); 4]);
        let mut link = LinkLayer::with_fates(Arc::new(up), None, 0, 4);
        for k in 1..=4 {
            let mut inbox = vec![if k == 1 || k == 4 {
                Received::Measurement(Vector::zeros(1))
            } else {
                Received::Silent
            }];
            link.uplink(k, &mut inbox, &mut Traffic::default());
            assert_eq!(link.receive(k), None);
            link.record(&inbox);
        }
        assert_eq!(
            link.history[1..3],
            [vec![Received::Silent], vec![Received::Silent]]
        );
    }

    #[test]
    fn a_late_packet_is_read_in_sending_order() {
        // Packets of steps 1..=4; step 2's is 2 steps late (fused at 4) and step 3's is lost:
        // at step 4 the late packet of 2 (gap 0 after 1) and step 4's (gap 1 after 2) arrive,
        // so only step 3 becomes unknown.
        let fates = (1..=4)
            .map(|k| Fate {
                lost: k == 3,
                delay: if k == 2 { 2 } else { 0 },
                ..Fate::default()
            })
            .collect();
        let up = FateTable::from_fates(1, 4, fates);
        let mut link = LinkLayer::with_fates(Arc::new(up), None, 2, 8);
        let z = |k: usize| Received::Measurement(Vector::from_element(1, k as f64));
        for k in 1..=4 {
            let mut inbox = vec![z(k)];
            link.uplink(k, &mut inbox, &mut Traffic::default());
            assert_eq!(link.receive(k), (k == 4).then_some(2));
            link.record(&inbox);
        }
        let h: Vec<_> = link.history.iter().map(|h| h[0].clone()).collect();
        assert_eq!(h, [z(1), z(2), Received::NotScheduled, z(4)]);
    }
}
