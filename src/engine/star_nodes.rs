//! The star's schemes as network nodes ([`crate::network::graph`]): every sensor a
//! [`StarSensor`] (its scheme's sensor node, its coins, the feedback it last heard), every relay
//! a pass-through (the driver relays), the sink a [`StarSink`] (the scheme's fusion side). Run by
//! the graph driver they give the engine's trial loop ([`crate::engine::trial::Trial`]) bit for
//! bit: the same estimates, and over a multi-hop network the same per-node counters
//! (`tests/graph_driver.rs`). That is what makes the driver the one model of delivery the
//! decentralized schemes build on, and this the proof that the graph and the star agree.
//!
//! Three rounds per step: (0) the sink sends its feedback of the last step down the tree (at the
//! first step, the one made from the prior, which the sensors already hold); (1) each scheduled
//! sensor with a reading steps on it with the feedback it holds and sends its report to the sink;
//! (2) the sink fuses what arrived: a report that did not arrive is a silence (no sequence
//! numbers), an unscheduled sensor is not scheduled.
//!
//! What the engine's link layer does beyond this is refused with a clear error: sequence numbers,
//! late packets and the re-fusion they need, doubles on air (`reals = "f64"`), relays that sum
//! the information of aggregable schemes.
use crate::engine::fusion_side::{scheduled, FusionSide};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::link::{Message, Received, Transmission};
use crate::network::graph::driver::GraphDriver;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};
use crate::network::radio::{DOWNLINK_OVERHEAD_BITS, PHY_OVERHEAD_BITS};
use crate::network::topology::tally::NodeCounts;
use crate::network::topology::{NodeKind, Topology};
use crate::network::Schedule;
use crate::scenario::experiment::Experiment;
use crate::scheme::{Feedback, SensorNode};
use crate::stats::seeding::coins;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Rounds of a star step: feedback down, sense and report, fuse.
pub const STAR_ROUNDS: usize = 3;

/// A star's nodes, in the network's node order.
pub type StarNodes = Vec<Box<dyn NetworkNode<StarPayload>>>;

/// What the star's nodes send.
#[derive(Debug, Clone, PartialEq)]
pub enum StarPayload {
    /// A sensor's report to the sink.
    Report(Message),
    /// The sink's feedback, `bits` of payload.
    Feedback { feedback: Feedback, bits: u64 },
}

impl Payload for StarPayload {
    fn mac_bits(&self) -> u64 {
        match self {
            StarPayload::Report(m) => m.frame_bits_with_sequence(0),
            StarPayload::Feedback { bits, .. } => DOWNLINK_OVERHEAD_BITS - PHY_OVERHEAD_BITS + bits,
        }
    }
}

/// A sensor of a star scheme.
pub struct StarSensor {
    i: usize,
    sensors: usize,
    sink: usize,
    node: Box<dyn SensorNode>,
    coins: Xoshiro256PlusPlus,
    held: Option<Feedback>,
    schedule: Schedule,
    windows: u64,
}

impl NetworkNode<StarPayload> for StarSensor {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<StarPayload>],
        out: &mut Outbox<StarPayload>,
    ) -> Result<(), String> {
        if at.round != 1 {
            return Ok(());
        }
        for env in inbox {
            if let StarPayload::Feedback { feedback, .. } = &env.payload {
                self.held = Some(feedback.clone());
            }
        }
        let Some(z) = at.reading else {
            return Ok(());
        };
        if scheduled(self.schedule, at.k, self.i, self.sensors, true) {
            let t = self
                .node
                .step(at.k, z, self.held.as_ref(), &mut self.coins)
                .map_err(|e| e.to_string())?;
            if let Transmission::Send(m) = t {
                out.send(Address::Node(self.sink), StarPayload::Report(m));
            }
        }
        Ok(())
    }

    fn windows(&self, _k: usize) -> u64 {
        self.windows
    }
}

/// A relay: the driver forwards what crosses it; it only listens.
pub struct StarRelay {
    windows: u64,
}

impl NetworkNode<StarPayload> for StarRelay {
    fn round(
        &mut self,
        _at: Round,
        _inbox: &[Envelope<StarPayload>],
        _out: &mut Outbox<StarPayload>,
    ) -> Result<(), String> {
        Ok(())
    }

    fn windows(&self, _k: usize) -> u64 {
        self.windows
    }
}

/// The sink: the scheme's fusion side.
pub struct StarSink {
    fusion: FusionSide,
    sensors: usize,
    schedule: Schedule,
    windows: u64,
    inbox: Vec<Received>,
}

impl NetworkNode<StarPayload> for StarSink {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<StarPayload>],
        out: &mut Outbox<StarPayload>,
    ) -> Result<(), String> {
        match at.round {
            0 => {
                if let Some(f) = self.fusion.feedback() {
                    let bits = f.bits(self.sensors);
                    let feedback = f.clone();
                    out.send(Address::Down, StarPayload::Feedback { feedback, bits });
                }
            }
            2 => {
                self.inbox.clear();
                self.inbox.resize(self.sensors, Received::Silent);
                for env in inbox {
                    if let StarPayload::Report(m) = &env.payload {
                        self.inbox[env.source] = Transmission::Send(m.clone()).into();
                    }
                }
                for (i, r) in self.inbox.iter_mut().enumerate() {
                    if !scheduled(self.schedule, at.k, i, self.sensors, true) {
                        *r = Received::NotScheduled;
                    }
                }
                self.fusion
                    .step(at.k, &self.inbox)
                    .map_err(|e| e.to_string())?;
            }
            _ => {}
        }
        Ok(())
    }

    fn windows(&self, _k: usize) -> u64 {
        self.windows
    }

    fn estimate(&self) -> Option<&Gaussian> {
        Some(self.fusion.estimate())
    }
}

/// The network of variant `variant` of `exp` (its `[network]`, or the star of its per-sensor
/// channels) and its nodes for trial `trial` with coin stream `stream`, in the network's node
/// order (sensors, relays, sink).
pub fn star_nodes(
    exp: &Experiment,
    variant: usize,
    trial: usize,
    stream: u64,
) -> Result<(Topology, StarNodes), String> {
    let v = &exp.variants[variant];
    let n = exp.system.n_sensors();
    let net = match &exp.network {
        Some(net) => (**net).clone(),
        None => exp.star_of(v),
    };
    if !exp.reals.is_f32() {
        return Err("the graph's star nodes send singles: reals = \"f64\" is not supported".into());
    }
    if v.sequence_bits > 0 {
        return Err("the graph's star nodes send no sequence numbers (sequence_bits > 0)".into());
    }
    if net.links.iter().any(|l| !l.channel.delay().is_zero()) {
        return Err(
            "the graph's star nodes do not re-fuse late packets (a link has a delay)".into(),
        );
    }
    if v.aggregated(exp.network.as_deref()) {
        return Err(
            "the graph's star nodes forward per source (relays that sum are not built)".into(),
        );
    }
    let (coins, center_seed) = coins(exp.seed, trial, stream, n);
    let (fusion, sensors) =
        FusionSide::with_seed(exp, variant, trial, center_seed).map_err(|e| e.to_string())?;
    let schedule = v.scheme.schedule();
    let sink = net.sink_for("a center scheme")?;
    // Every sensor holds the feedback made from the prior before the first step (it knows it).
    let initial = fusion.feedback().cloned();
    let listens_feedback = initial.is_some();
    let windows =
        |node: usize| net.children(node) as u64 + u64::from(listens_feedback && node != sink);
    let mut sensors = sensors.into_iter().zip(coins);
    let mut nodes: StarNodes = Vec::with_capacity(net.nodes.len());
    let mut fusion = Some(fusion);
    for (x, node) in net.nodes.iter().enumerate() {
        nodes.push(match node.kind {
            NodeKind::Sensor(i) => {
                let (node, coins) = sensors.next().ok_or("more sensor nodes than sensors")?;
                Box::new(StarSensor {
                    i,
                    sensors: n,
                    sink,
                    node,
                    coins,
                    held: initial.clone(),
                    schedule,
                    windows: windows(x),
                })
            }
            NodeKind::Relay(_) => Box::new(StarRelay {
                windows: windows(x),
            }),
            NodeKind::Sink => Box::new(StarSink {
                fusion: fusion.take().ok_or("more than one sink")?,
                sensors: n,
                schedule,
                windows: windows(x),
                inbox: Vec::with_capacity(n),
            }),
        });
    }
    Ok((net, nodes))
}

/// One trial of variant `variant` of `exp` on `measurements` (`measurements[k - 1][i]` =
/// z_k^i) run by the graph driver: the sink's estimate and every node's counters after each
/// step.
pub fn run_star_trial(
    exp: &Experiment,
    variant: usize,
    trial: usize,
    stream: u64,
    measurements: &[Vec<Vector>],
) -> Result<Vec<(Gaussian, Vec<NodeCounts>)>, String> {
    let (net, mut nodes) = star_nodes(exp, variant, trial, stream)?;
    let mut driver = GraphDriver::new(&net, STAR_ROUNDS, exp.steps, exp.seed, trial as u64);
    let sink = net.sink_for("a center scheme")?;
    let mut steps = Vec::with_capacity(measurements.len());
    for (j, readings) in measurements.iter().enumerate() {
        let readings: Vec<Option<&Vector>> = readings.iter().map(Some).collect();
        driver.step(j + 1, &mut nodes, &readings)?;
        let estimate = nodes[sink].estimate().expect("the sink estimates").clone();
        steps.push((estimate, driver.counts().to_vec()));
    }
    Ok(steps)
}
