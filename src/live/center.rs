//! The fusion side of a live run, without sockets: [`Center`] announces each step, takes the
//! datagrams that arrive, and at the step's end fuses the inbox they make with the scheme's
//! own [`crate::scheme::FusionCenter`] through the engine's [`FusionSide`], the half of a step
//! the engine's loop ([`crate::engine::trial`]) runs for a simulated one: a frame that arrived is its message, a sensor that reported no
//! frame is a silence, one that had no reading or was not scheduled is
//! [`Received::NotScheduled`]. A sensor that did not report by the step's end is a silence too
//! (the center cannot tell a dead node from a quiet one, as it cannot tell a lost packet from
//! a silence) and is logged. [`super::run_center`] drives it over UDP.
use super::secure::{self, SecureEnd};
use super::wire::{self, Datagram, Kind, MessageKind, DONE_READING, HELLO_FRESH, STEP_CATCH_UP};
use crate::engine::fusion_side::FusionSide;
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::link::Received;
use crate::scenario::experiment::Experiment;
use crate::scheme::SchemeError;
use crate::stats::seeding;

/// Counts of datagrams that were not used, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Not a datagram of ours, or its envelope is corrupt (CRC, length).
    pub corrupt: u64,
    /// A frame whose 802.15.4 frame check sequence (or header) is wrong.
    pub bad_frame: u64,
    /// Of a step or variant other than the current one (late, or replayed).
    pub stale: u64,
    /// A second copy of a frame or report already taken at this step.
    pub duplicate: u64,
    /// From a sensor index the scenario does not have.
    pub unknown_sensor: u64,
    /// A well-formed frame whose content the center cannot use: a reading or estimate that is
    /// not finite, an envelope that claims other payload bits than the frame carries, or a
    /// message the scheme refuses (an estimate where it fuses readings, a codec frame of another
    /// scheme). Dropped, and the step fused without it: a forged frame never stops the center.
    pub rejected: u64,
}

/// Whether a sensor's entry of an inbox is a message that arrived.
fn carries_message(r: &Received) -> bool {
    matches!(
        r,
        Received::Measurement(_) | Received::Estimate(_) | Received::Frame(_)
    )
}

/// Why a frame is not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unusable {
    /// Its 802.15.4 frame (or message kind) is malformed: [`Dropped::bad_frame`].
    Corrupt,
    /// Well-formed, but its content is not usable: [`Dropped::rejected`].
    Content,
    /// Its security does not verify: counted by the [`SecureEnd`].
    Security,
}

/// What became of one sensor at a fused step, as `estimates.csv` says it.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorRecord {
    /// `sent`, `silent`, `not_scheduled`, `missing` (no reading) or `no_report`.
    pub link: &'static str,
    /// Payload bits of the frame that arrived.
    pub bits: u64,
}

/// One fused step.
#[derive(Debug, Clone)]
pub struct StepRecord {
    pub variant: usize,
    pub k: usize,
    pub inbox: Vec<Received>,
    pub sensors: Vec<SensorRecord>,
    pub estimate: Gaussian,
    /// Payload bits that arrived at this step.
    pub bits: u64,
}

/// What the driver must do after a datagram.
#[derive(Debug, Default)]
pub struct Accepted {
    /// A node greeted the center: its sensor, and whether it has just started.
    pub hello: Option<(usize, bool)>,
    /// Datagrams for the sender (catch-up steps, the current step, a refusal).
    pub replies: Vec<Vec<u8>>,
}

/// The sensors' reports of the current step.
struct Pending {
    /// The message that arrived from each sensor, with its payload bits.
    frames: Vec<Option<(Received, u64)>>,
    /// Each sensor's report: `Some(had a reading)`.
    done: Vec<Option<bool>>,
    /// Sensors that missed a step and have sent nothing since: a step does not wait for them
    /// (a dead node would otherwise cost every step the whole timeout).
    away: Vec<bool>,
}

/// The center of a live run of trial `trial` of `exp`, over the variants `variants` in order.
pub struct Center<'a> {
    exp: &'a Experiment,
    trial: usize,
    fingerprint: [u8; 8],
    variants: Vec<usize>,
    /// Position in `variants`.
    at: usize,
    /// Step being collected (1-based); `exp.steps + 1` when the variant is done.
    k: usize,
    /// The current variant's center (the engine's [`FusionSide`]: built, stepped and rebuilt
    /// as in a simulated run).
    fusion: Option<FusionSide>,
    /// Per step of the current variant, per sensor, the step announcement sent (for nodes that
    /// catch up).
    announced: Vec<Vec<Vec<u8>>>,
    pending: Pending,
    /// The inboxes fused so far in the current variant: a step whose fusion refused a frame is
    /// fused again without it on a center rebuilt from them ([`Center::rebuild`]).
    history: Vec<Vec<Received>>,
    pub dropped: Dropped,
    /// The center's end of the secured link, when the scenario secures its frames.
    secure: Option<SecureEnd>,
}

/// Refuses a secured scenario without the run's keys, and keys for an unsecured one.
pub(super) fn check_keys(exp: &Experiment, secure: Option<&SecureEnd>) -> Result<(), String> {
    match (exp.security.is_secured(), secure.is_some()) {
        (true, false) => Err(format!(
            "the scenario secures its frames ([security] level = \"{}\"): give the run's key file (--key FILE; `hushfuse keygen` makes one, `hushfuse live` makes its own)",
            exp.security.level.name()
        )),
        (false, true) => Err("a key file was given, but the scenario has no [security] level: its frames go unsecured".into()),
        _ => Ok(()),
    }
}

impl<'a> Center<'a> {
    pub fn new(
        exp: &'a Experiment,
        trial: usize,
        fingerprint: [u8; 8],
        variants: Vec<usize>,
        secure: Option<SecureEnd>,
    ) -> Result<Self, String> {
        super::check_live(exp)?;
        check_keys(exp, secure.as_ref())?;
        if variants.is_empty() {
            return Err("no scheme to run".into());
        }
        let n = exp.system.n_sensors();
        let mut c = Self {
            exp,
            trial,
            fingerprint,
            variants,
            at: 0,
            k: 1,
            fusion: None,
            announced: Vec::new(),
            pending: Pending {
                frames: vec![None; n],
                done: vec![None; n],
                away: vec![false; n],
            },
            history: Vec::new(),
            dropped: Dropped::default(),
            secure,
        };
        c.start_variant()?;
        Ok(c)
    }

    fn start_variant(&mut self) -> Result<(), String> {
        let v = self.variants[self.at];
        let (fusion, _sensors) = FusionSide::new(self.exp, v, self.trial, seeding::coin_stream(v))
            .map_err(|e| format!("scheme {}: cannot build it: {e}", self.label(v)))?;
        self.fusion = Some(fusion);
        self.k = 1;
        self.announced.clear();
        self.history.clear();
        Ok(())
    }

    /// The current variant's center built afresh and brought through the steps fused so far
    /// (the same estimates: a particle filter draws again from its own seed).
    fn rebuild(&mut self) -> Result<(), String> {
        let v = self.variants[self.at];
        let fusion = self.fusion.as_mut().expect("a variant is running");
        fusion
            .rebuild(self.exp.variants[v].scheme.as_ref(), &self.history)
            .map_err(|(j, e)| match j {
                0 => format!("scheme {}: cannot build it: {e}", self.label(v)),
                j => format!("scheme {}, step {j}: {e}", self.label(v)),
            })
    }

    /// The label of variant `v`.
    pub fn label(&self, v: usize) -> &str {
        &self.exp.curves[self.exp.variants[v].curve].label
    }

    /// Whether every variant has run.
    pub fn finished(&self) -> bool {
        self.at >= self.variants.len()
    }

    /// (variant, step) being collected.
    pub fn position(&self) -> (usize, usize) {
        (self.variants[self.at.min(self.variants.len() - 1)], self.k)
    }

    /// The current estimate (the prior before the first step).
    pub fn estimate(&self) -> Option<&Gaussian> {
        self.fusion.as_ref().map(FusionSide::estimate)
    }

    /// The announcements of the current step, one per sensor: the step and the feedback each
    /// sensor is sent (sealed afresh at each call in a secured run: a node refuses an
    /// envelope's counter twice).
    pub fn announce(&mut self) -> Result<Vec<Vec<u8>>, String> {
        let k = self.position().1;
        self.make_announcements()?;
        (0..self.sensors())
            .map(|i| {
                let d = self.announced[k - 1][i].clone();
                self.seal_down(&d, i)
            })
            .collect()
    }

    /// The current step's announcement to sensor `i` alone, sealed afresh (sent again to a
    /// node that has not reported).
    pub fn announcement(&mut self, i: usize) -> Result<Vec<u8>, String> {
        let k = self.position().1;
        self.make_announcements()?;
        let d = self.announced[k - 1][i].clone();
        self.seal_down(&d, i)
    }

    /// The datagram that ends the run, for sensor `i`.
    pub fn end_datagram(&mut self, i: usize) -> Result<Vec<u8>, String> {
        self.seal_down(&Datagram::new(Kind::End, i, 0, 0).encode(), i)
    }

    /// A datagram to sensor `i` as it goes down: sealed when the downlink is secured.
    fn seal_down(&mut self, datagram: &[u8], i: usize) -> Result<Vec<u8>, String> {
        match self.secure.as_mut() {
            Some(end) if end.secures_downlink() => end.seal_datagram(datagram, i),
            _ => Ok(datagram.to_vec()),
        }
    }

    /// What the center's end of the secured link dropped (`None`: the run is not secured).
    pub fn security_dropped(&self) -> Option<secure::Dropped> {
        self.secure.as_ref().map(SecureEnd::dropped)
    }

    /// Saves the frame counters accepted so far beside the key (a restarted center refuses
    /// what it took before): at most twice a second, unless `force` (the end of the run); call
    /// once a fused step is journaled ([`SecureEnd::save_seen`]).
    pub fn save_seen(&mut self, force: bool) -> Result<(), String> {
        self.secure
            .as_mut()
            .map_or(Ok(()), |end| end.save_seen(force))
    }

    /// Makes the current step's announcements (unsealed envelopes; the feedback frame inside
    /// is secured once, as a radio would send it), if not made yet.
    fn make_announcements(&mut self) -> Result<(), String> {
        let (v, k) = self.position();
        if self.announced.len() < k {
            let n = self.exp.system.n_sensors();
            let mut all = Vec::with_capacity(n);
            for i in 0..n {
                let mut d = Datagram::new(Kind::Step, i, v, k);
                if let Some(fb) = self.fusion.as_ref().and_then(FusionSide::feedback) {
                    match wire::feedback_frame(fb, i, k).map_err(|e| {
                        format!("scheme {}: feedback cannot be sent: {e}", self.label(v))
                    })? {
                        Some((flags, frame)) => {
                            d.flags = flags;
                            d.body = match self.secure.as_mut() {
                                Some(end) if end.secures_downlink() => end.seal_frame(&frame, i)?,
                                _ => frame,
                            };
                        }
                        // An innovation reference with nothing for sensor i.
                        None => d.flags = wire::STEP_REFERENCE,
                    }
                }
                all.push(d.encode());
            }
            self.announced.push(all);
        }
        // Every step before k was announced (by the driver, or by `fuse` on a resume).
        if self.announced.len() < k {
            return Err(format!(
                "step {k} announced before step {}",
                self.announced.len() + 1
            ));
        }
        Ok(())
    }

    /// The scenario's number of sensors.
    pub fn sensors(&self) -> usize {
        self.pending.done.len()
    }

    /// Whether every sensor has reported the current step, but those that are away (they
    /// missed a step and have sent nothing since).
    pub fn complete(&self) -> bool {
        let p = &self.pending;
        p.done
            .iter()
            .zip(&p.away)
            .all(|(d, &away)| d.is_some() || away)
    }

    /// Sensors that have reported the current step.
    pub fn heard(&self) -> usize {
        self.pending.done.iter().filter(|d| d.is_some()).count()
    }

    /// Sensors that have not reported the current step.
    pub fn missing(&self) -> Vec<usize> {
        (0..self.pending.done.len())
            .filter(|&i| self.pending.done[i].is_none())
            .collect()
    }

    /// Takes one datagram from a node.
    pub fn accept(&mut self, octets: &[u8]) -> Accepted {
        let opened;
        let octets = match self.secure.as_mut() {
            None => octets,
            Some(end) => {
                // The sender's index picks the key; the MIC then vouches for it.
                let inner = secure::unsealed_part(octets, end.spec());
                let Some(i) = wire::sensor_field(inner) else {
                    self.dropped.corrupt += 1;
                    return Accepted::default();
                };
                if i >= self.exp.system.n_sensors() {
                    self.dropped.unknown_sensor += 1;
                    return Accepted::default();
                }
                match end.open_datagram(octets, wire::sensor_address(i), i) {
                    Ok(inner) => {
                        opened = inner;
                        opened
                    }
                    Err(_) => return Accepted::default(),
                }
            }
        };
        let Ok(d) = Datagram::decode(octets) else {
            self.dropped.corrupt += 1;
            return Accepted::default();
        };
        let i = usize::from(d.sensor);
        if i >= self.exp.system.n_sensors() {
            self.dropped.unknown_sensor += 1;
            return Accepted::default();
        }
        // Whatever it says, the sensor is back.
        self.pending.away[i] = false;
        match d.kind {
            Kind::Hello => self.hello(i, &d),
            Kind::CatchUp => self.catch_up(i, &d),
            Kind::Frame | Kind::Done if self.finished() => {
                self.dropped.stale += 1;
                Accepted::default()
            }
            Kind::Frame | Kind::Done => {
                let (v, k) = self.position();
                // A corrupt frame is counted as such whichever step it claims.
                let frame = (d.kind == Kind::Frame).then(|| self.read_frame(i, &d));
                if let Some(Err(why)) = frame {
                    match why {
                        Unusable::Corrupt => self.dropped.bad_frame += 1,
                        Unusable::Content => self.dropped.rejected += 1,
                        Unusable::Security => {}
                    }
                } else if usize::from(d.variant) != v || d.step as usize != k {
                    self.dropped.stale += 1;
                } else if d.kind == Kind::Done {
                    match self.pending.done[i] {
                        Some(_) => self.dropped.duplicate += 1,
                        None => self.pending.done[i] = Some(d.flags & DONE_READING != 0),
                    }
                } else if self.pending.frames[i].is_some() {
                    self.dropped.duplicate += 1;
                } else if let Some(Ok((r, bits))) = frame {
                    self.pending.frames[i] = Some((r, bits));
                }
                Accepted::default()
            }
            _ => {
                self.dropped.corrupt += 1;
                Accepted::default()
            }
        }
    }

    fn hello(&mut self, i: usize, d: &Datagram) -> Accepted {
        if d.body != self.fingerprint {
            let mut x = Datagram::new(Kind::Reject, i, 0, 0);
            x.body = b"it runs another scenario, seed, number of steps or trial than the center"
                .to_vec();
            return Accepted {
                hello: None,
                replies: self.seal_down(&x.encode(), i).into_iter().collect(),
            };
        }
        let mut replies = Vec::new();
        // Once the current step is out (not while the driver waits for the first greetings,
        // when it announces to every node at once), a node that greets gets it.
        if !self.finished() && self.announced.len() >= self.k {
            if let Ok(d) = self.announcement(i) {
                replies.push(d);
            }
        }
        Accepted {
            hello: Some((i, d.flags & HELLO_FRESH != 0)),
            replies,
        }
    }

    /// A node that has done variant `d.variant` up to step `d.step` is sent the steps since,
    /// marked as catch-up, then the current one.
    fn catch_up(&mut self, i: usize, d: &Datagram) -> Accepted {
        let (v, k) = self.position();
        if self.finished() || usize::from(d.variant) != v || d.step as usize >= k {
            return Accepted::default();
        }
        let missed: Vec<Vec<u8>> = (d.step as usize + 1..k)
            .filter_map(|j| self.announced.get(j - 1))
            .map(|all| {
                let mut s = Datagram::decode(&all[i]).expect("our own datagram");
                s.flags |= STEP_CATCH_UP;
                s.encode()
            })
            .collect();
        let mut replies: Vec<Vec<u8>> = missed
            .iter()
            .filter_map(|m| self.seal_down(m, i).ok())
            .collect();
        if let Ok(d) = self.announcement(i) {
            replies.push(d);
        }
        Accepted {
            hello: None,
            replies,
        }
    }

    /// The message of a [`Kind::Frame`] and the payload bits that arrived in it (what is
    /// counted, never the envelope's claim, which must agree with it), or why it is unusable.
    fn read_frame(&mut self, i: usize, d: &Datagram) -> Result<(Received, u64), Unusable> {
        let src = wire::sensor_address(i);
        // Secured: the frame as the radio sent it is opened (verified, not a replay) first.
        let body = match self.secure.as_mut() {
            Some(end) => end
                .open_frame(&d.body, src, i)
                .map_err(|_| Unusable::Security)?,
            None => d.body.clone(),
        };
        let payload =
            wire::check_mpdu(&body, src, wire::CENTER_ADDRESS).map_err(|_| Unusable::Corrupt)?;
        let sys = &self.exp.system;
        let reals = |dim: usize| -> Result<Vector, Unusable> {
            let v = wire::read_f32s(payload, dim).map_err(|_| Unusable::Corrupt)?;
            match v.iter().all(|x| x.is_finite()) {
                true => Ok(Vector::from_vec(v)),
                false => Err(Unusable::Content),
            }
        };
        let claimed = u64::from(d.aux);
        let (r, bits) = match MessageKind::from_code(d.flags).ok_or(Unusable::Corrupt)? {
            MessageKind::Measurement => {
                let z = reals(sys.sensors[i].meas_dim())?;
                let bits = 32 * z.len() as u64;
                (Received::Measurement(z), bits)
            }
            MessageKind::Estimate => {
                let x = reals(sys.state_dim())?;
                let bits = 32 * x.len() as u64;
                (Received::Estimate(x), bits)
            }
            // A codec's payload bits need not fill its octets: the claim must fit the frame
            // exactly (the MAC frame of that many payload bits is the frame that arrived).
            MessageKind::Codec => {
                let fits = claimed > 0
                    && crate::link::codec802154::mpdu_bits_for_payload(claimed)
                        == 8 * body.len() as u64;
                if !fits {
                    return Err(Unusable::Content);
                }
                (Received::Frame(body.clone()), claimed)
            }
        };
        if claimed != bits {
            return Err(Unusable::Content);
        }
        Ok((r, bits))
    }

    /// Ends the current step: fuses what arrived, readies the next step (or variant).
    pub fn close(&mut self) -> Result<StepRecord, String> {
        let (v, k) = self.position();
        let n = self.exp.system.n_sensors();
        let schedule = self.exp.variants[v].scheme.schedule();
        let mut inbox = Vec::with_capacity(n);
        let mut sensors = Vec::with_capacity(n);
        for i in 0..n {
            let frame = self.pending.frames[i].take();
            let done = self.pending.done[i].take();
            self.pending.away[i] = done.is_none();
            let (r, rec) = match (done, frame) {
                (Some(false), _) => (Received::NotScheduled, ("missing", 0)),
                _ if !schedule.allows(k, i, n) => (Received::NotScheduled, ("not_scheduled", 0)),
                (_, Some((r, bits))) => (r, ("sent", bits)),
                (Some(true), None) => (Received::Silent, ("silent", 0)),
                (None, None) => (Received::Silent, ("no_report", 0)),
            };
            inbox.push(r);
            sensors.push(SensorRecord {
                link: rec.0,
                bits: rec.1,
            });
        }
        self.fuse_from(v, k, inbox, sensors, true)
    }

    /// Fuses step `k` of variant `v` on `inbox` (the current step), as [`Center::close`] or a
    /// resumed center does.
    pub fn fuse(
        &mut self,
        v: usize,
        k: usize,
        inbox: Vec<Received>,
        sensors: Vec<SensorRecord>,
    ) -> Result<StepRecord, String> {
        self.fuse_from(v, k, inbox, sensors, false)
    }

    /// [`Center::fuse`]; `from_network`: the inbox was made of datagrams, and a frame the
    /// scheme refuses ([`SchemeError::Protocol`], naming its sensor) is dropped, counted in
    /// [`Dropped::rejected`], and the step fused without it (a journal's inbox was fused once
    /// already: a refusal there is an error).
    fn fuse_from(
        &mut self,
        v: usize,
        k: usize,
        mut inbox: Vec<Received>,
        mut sensors: Vec<SensorRecord>,
        from_network: bool,
    ) -> Result<StepRecord, String> {
        if self.finished() || (v, k) != self.position() {
            return Err(format!(
                "step {k} of variant {v} is not the one the center is at ({:?})",
                self.position()
            ));
        }
        // The step's announcement (its feedback), kept for nodes that catch up: a resumed center
        // fuses its journal without announcing.
        self.make_announcements()?;
        let label = self.label(v).to_string();
        loop {
            let fusion = self.fusion.as_mut().expect("a variant is running");
            match fusion.step(k, &inbox) {
                Ok(()) => break,
                Err(SchemeError::Protocol { sensor, .. })
                    if from_network && inbox.get(sensor).is_some_and(carries_message) =>
                {
                    // The center may have changed before it refused: build it again.
                    self.dropped.rejected += 1;
                    inbox[sensor] = Received::Silent;
                    sensors[sensor] = SensorRecord {
                        link: "rejected",
                        bits: 0,
                    };
                    self.rebuild()?;
                }
                Err(e) => return Err(format!("scheme {label}, step {k}: {e}")),
            }
        }
        self.history.push(inbox.clone());
        let estimate = self.estimate().expect("a variant is running").clone();
        let bits = sensors.iter().map(|s| s.bits).sum();
        let record = StepRecord {
            variant: v,
            k,
            inbox,
            sensors,
            estimate,
            bits,
        };
        self.k += 1;
        if self.k > self.exp.steps {
            self.at += 1;
            if !self.finished() {
                self.start_variant()?;
            }
        }
        Ok(record)
    }
}

#[cfg(test)]
mod tests {
    use super::super::node::{frame_datagram, Node, Recorded};
    use super::super::wire::{Datagram, Kind};
    use super::*;
    use crate::link::Message;

    fn exp() -> Experiment {
        let text = crate::scenario::builtin::get("arena-1d").unwrap();
        crate::engine::replay::load_experiment(text, "arena-1d", 5, None, &Default::default())
            .unwrap()
            .0
    }

    fn sod(exp: &Experiment) -> usize {
        (0..exp.variants.len())
            .find(|&v| exp.curves[exp.variants[v].curve].label == "Send-on-delta")
            .unwrap()
    }

    /// One step of send-on-delta by hand: a frame, a duplicate, a stale frame, a frame with a
    /// bad FCS, random octets, a silent sensor, one without a reading, one that never reports.
    #[test]
    fn a_step_takes_what_arrived_and_drops_the_rest() {
        let exp = exp();
        let v = sod(&exp);
        let mut c = Center::new(&exp, 0, [0; 8], vec![v], None).unwrap();
        assert_eq!(c.announce().unwrap().len(), 4);
        let z = |x: f64| Message::Measurement(Vector::from_vec(vec![x]));
        let done = |i: usize, k: usize, reading: bool| {
            let mut d = Datagram::new(Kind::Done, i, v, k);
            d.flags = u8::from(reading);
            d.encode()
        };
        let frame = frame_datagram(&z(0.1), 0, v, 1).unwrap();
        assert!(c.accept(&frame).replies.is_empty());
        c.accept(&frame);
        c.accept(&frame_datagram(&z(9.0), 0, v, 2).unwrap());
        let mut bad = Datagram::decode(&frame_datagram(&z(5.0), 1, v, 1).unwrap()).unwrap();
        bad.body[12] ^= 1;
        c.accept(&bad.encode());
        c.accept(b"random octets, not a datagram");
        c.accept(&frame[..frame.len() - 1]);
        c.accept(&done(0, 1, true));
        c.accept(&done(1, 1, true));
        c.accept(&done(2, 1, false));
        assert!(!c.complete());
        assert_eq!(c.missing(), vec![3]);
        let r = c.close().unwrap();
        assert_eq!(
            r.inbox,
            vec![
                Received::Measurement(Vector::from_vec(vec![f64::from(0.1f32)])),
                Received::Silent,
                Received::NotScheduled,
                Received::Silent,
            ]
        );
        let links: Vec<_> = r.sensors.iter().map(|s| (s.link, s.bits)).collect();
        assert_eq!(
            links,
            vec![
                ("sent", 32),
                ("silent", 0),
                ("missing", 0),
                ("no_report", 0)
            ]
        );
        assert_eq!(
            c.dropped,
            Dropped {
                corrupt: 2,
                bad_frame: 1,
                stale: 1,
                duplicate: 1,
                unknown_sensor: 0,
                rejected: 0
            }
        );
        assert_eq!(c.position(), (v, 2));
        // Sensor 3 is away: step 2 is complete without it, until it says anything.
        for i in 0..3 {
            c.accept(&done(i, 2, true));
        }
        assert!(c.complete());
        c.accept(&done(3, 1, true)); // stale, but it is back
        assert!(!c.complete());
        assert_eq!(c.missing(), vec![3]);
    }

    /// Forged frames of the current step that pass the FCS never stop the center: a NaN or
    /// infinite reading, an envelope that claims 0 or 65535 payload bits, are dropped on
    /// arrival (the honest frame after them is taken); an estimate where the scheme fuses
    /// readings, or another scheme's codec frame, is refused by the scheme at fusion and the
    /// step is fused without it, on a rebuilt center, as a run without that frame would be.
    #[test]
    fn forged_frames_are_rejected_and_the_center_fuses_on() {
        let exp = exp();
        let v = sod(&exp);
        let qi = (0..exp.variants.len())
            .find(|&v| exp.variants[v].kind == "quantized-innovation")
            .unwrap();
        let done = |i: usize, k: usize| {
            let mut d = Datagram::new(Kind::Done, i, v, k);
            d.flags = 1;
            d.encode()
        };
        let z = |x: f64| Message::Measurement(Vector::from_vec(vec![x]));
        // Reference: a center fed only honest frames.
        let mut clean = Center::new(&exp, 0, [0; 8], vec![v], None).unwrap();
        let mut c = Center::new(&exp, 0, [0; 8], vec![v], None).unwrap();
        for k in 1..=3 {
            clean.announce().unwrap();
            c.announce().unwrap();
            let honest = frame_datagram(&z(0.5 * k as f64), 0, v, k).unwrap();
            let mut forged = Vec::new();
            for bad in [f64::NAN, f64::INFINITY] {
                let mut d = Datagram::decode(&frame_datagram(&z(1.0), 0, v, k).unwrap()).unwrap();
                let at = d.body.len() - 6; // the payload's single, before the FCS
                d.body[at..at + 4].copy_from_slice(&(bad as f32).to_le_bytes());
                let fcs = crate::link::codec802154::crc16_kermit(&d.body[..d.body.len() - 2]);
                let n = d.body.len();
                d.body[n - 2..].copy_from_slice(&fcs.to_le_bytes());
                forged.push(d.encode());
            }
            for claim in [0u16, 65535] {
                let mut d = Datagram::decode(&honest).unwrap();
                d.aux = claim;
                forged.push(d.encode());
            }
            for f in &forged {
                c.accept(f);
            }
            c.accept(&honest);
            clean.accept(&honest);
            // Sensor 1: an estimate at step 2, a frame of the quantized scheme at step 3.
            let foreign = match k {
                2 => Some(Message::Estimate(Vector::from_vec(vec![1.0, 2.0]))),
                3 => {
                    let mut inst = exp.variants[qi].scheme.build().unwrap();
                    let mut rng = crate::stats::seeding::sensor_coins(1, 0, 0, 1);
                    let fb = inst.center.feedback();
                    match inst.sensors[1].step(
                        1,
                        &Vector::from_vec(vec![5.0]),
                        fb.as_ref(),
                        &mut rng,
                    ) {
                        Ok(crate::link::Transmission::Send(m)) => Some(m),
                        other => panic!("the quantized sensor sends: {other:?}"),
                    }
                }
                _ => None,
            };
            if let Some(m) = foreign {
                let mut d = Datagram::decode(&frame_datagram(&m, 1, v, k).unwrap()).unwrap();
                d.variant = v as u16;
                c.accept(&d.encode());
            }
            for i in 0..4 {
                c.accept(&done(i, k));
                clean.accept(&done(i, k));
            }
            let (r, want) = (c.close().unwrap(), clean.close().unwrap());
            assert_eq!(r.estimate, want.estimate, "step {k}");
            assert_eq!(
                r.sensors[0],
                SensorRecord {
                    link: "sent",
                    bits: 32
                }
            );
            let expected_link = if k >= 2 { "rejected" } else { "silent" };
            assert_eq!(r.sensors[1].link, expected_link, "step {k}");
        }
        assert_eq!(c.dropped.rejected, 3 * 4 + 2, "{:?}", c.dropped);
        assert_eq!(c.dropped.bad_frame, 0);
    }

    /// A node that greets in the middle of a variant, fresh, asks for the steps it missed and
    /// gets them as catch-up (it sends nothing for them), then the current step.
    #[test]
    fn a_fresh_node_catches_up_silently() {
        let exp = exp();
        let v = sod(&exp);
        let fp = [7; 8];
        let mut c = Center::new(&exp, 0, fp, vec![v], None).unwrap();
        for _ in 0..3 {
            c.announce().unwrap();
            c.close().unwrap();
        }
        let readings = (1..=5)
            .map(|k| Some(Vector::from_vec(vec![k as f64])))
            .collect();
        let mut node = Node::new(&exp, 1, 0, Box::new(Recorded(readings)), None).unwrap();
        c.announce().unwrap();
        let hello = c.accept(&node.hello(fp).unwrap());
        assert_eq!(hello.hello, Some((1, true)));
        let ask = node.handle(&hello.replies[0]).unwrap().datagrams;
        assert_eq!(Datagram::decode(&ask[0]).unwrap().kind, Kind::CatchUp);
        let steps = c.accept(&ask[0]).replies;
        assert_eq!(steps.len(), 4, "steps 1-3 as catch-up, then step 4");
        for s in &steps[..3] {
            assert!(node.handle(s).unwrap().datagrams.is_empty());
        }
        let sent = node.handle(&steps[3]).unwrap().datagrams;
        let kinds: Vec<Kind> = sent
            .iter()
            .map(|d| Datagram::decode(d).unwrap().kind)
            .collect();
        assert_eq!(*kinds.last().unwrap(), Kind::Done);
        // A center resumed from its journal at step 4 serves the catch-up as well.
        let mut resumed = Center::new(&exp, 0, fp, vec![v], None).unwrap();
        for k in 1..=3 {
            resumed
                .fuse(v, k, vec![Received::Silent; 4], Vec::new())
                .unwrap();
        }
        let mut fresh = Node::new(&exp, 1, 0, Box::new(Recorded(vec![None; 5])), None).unwrap();
        let hello = resumed.accept(&fresh.hello(fp).unwrap());
        assert!(hello.replies.is_empty(), "step 4 not yet announced");
        resumed.announce().unwrap();
        let ask = Datagram::new(Kind::CatchUp, 1, v, 0).encode();
        assert_eq!(resumed.accept(&ask).replies.len(), 4);
        // Another run's node is refused.
        let other = c.accept(&node.hello([8; 8]).unwrap());
        assert_eq!(other.hello, None);
        assert!(node
            .handle(&other.replies[0])
            .unwrap_err()
            .contains("refused"));
    }
}
