//! One trial of a decentralized scheme on a network's graph: the scheme as configured from a
//! scenario ([`Peers`]: which scheme, its knobs, the model every node knows), its nodes built on
//! the graph (weights, neighbours, the sensors of the sensor nodes), and the graph driver
//! ([`GraphDriver`]) running them step by step on a trial's readings. Every node of the graph
//! runs the filter (a relay or the sink as a node without a sensor); after each step the
//! recorder gets every node's estimate and every node's counters.
use super::channel_filter::{self, ChannelFilterNode};
use super::consensus::{ConsensusNode, Fusion};
use super::diffusion::{DiffusionNode, Order};
use super::kalman_consensus::KalmanConsensusNode;
use super::peer_fusion::{self, PeerFusionNode, Rule};
use super::weights::{WeightRule, Weights};
use super::Model;
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::network::graph::driver::GraphDriver;
use crate::network::graph::{NetworkNode, Payload};
use crate::network::topology::{NodeKind, Topology};

/// Which decentralized scheme, with its knobs.
#[derive(Debug, Clone, PartialEq)]
pub enum PeerKind {
    /// The consensus family ([`super::consensus`]): `omega` `None` is ω = N, the number of
    /// nodes of the graph it runs on.
    Consensus {
        fusion: FusionKind,
        weights: WeightRule,
        iterations: usize,
        omega: Option<f64>,
    },
    /// Olfati-Saber's Kalman consensus filter ([`super::kalman_consensus`]); `gamma` `None` is
    /// 1 / (1 + Δ), Δ the graph's largest degree: the pull's matrix Pᵢ / (1 + ‖Pᵢ‖_F) has norm
    /// below 1, so the consensus part I − γ(·)L has its eigenvalues in (1 − 2γΔ, 1] and γ < 1/Δ
    /// keeps it from overshooting on any graph (our default; the paper leaves γ to the user).
    KalmanConsensus { gamma: Option<f64> },
    /// The diffusion Kalman filter ([`super::diffusion`]), event-triggered with a threshold.
    Diffusion {
        order: Order,
        weights: WeightRule,
        threshold: Option<f64>,
    },
    /// Peer-to-peer fusion of estimates ([`super::peer_fusion`]).
    PeerFusion(Rule),
    /// The channel filter on a tree ([`super::channel_filter`]).
    ChannelFilter,
    /// Event-triggered sharing of reading elements with implicit updates, CI on demand
    /// ([`super::et_ddf`]): trigger `delta` (measurement units), CI when tr(P) > `tau`.
    EventTriggered { delta: f64, tau: Option<f64> },
}

/// A member of the consensus family, before ω is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionKind {
    Information,
    Measurements,
    Hybrid,
}

/// A decentralized scheme as a scenario configures it: the model every node knows, the prior
/// of x₀ every node starts from, and the (H, R) of each sensor (sensor i at node i).
#[derive(Debug, Clone)]
pub struct Peers {
    pub kind: PeerKind,
    pub model: Model,
    pub prior: Gaussian,
    pub sensors: Vec<(Matrix, Matrix)>,
}

/// What a trial runs on.
#[derive(Debug, Clone, Copy)]
pub struct PeerTrial<'a> {
    pub net: &'a Topology,
    /// `measurements[k - 1][i]`: sensor i's reading at step k.
    pub measurements: &'a [Vec<Vector>],
    /// The run's seed and the trial: the links' fates ([`crate::network::graph::fates`]).
    pub seed: u64,
    pub trial: u64,
}

/// Gets step k's estimates of every node and every node's counters of the step.
pub type Recorder<'r> = super::consensus::lockstep::Record<'r>;

/// A node's own weight and its neighbours' (node, weight).
type NodeWeights = (f64, Vec<(usize, f64)>);

/// Most consensus iterations a step (each one a broadcast of every node).
pub const MAX_ITERATIONS: usize = 10_000;

/// The largest MAC payload of one 802.15.4 frame (116 octets).
pub use crate::link::codec802154::MAX_PAYLOAD_OCTETS;

impl Peers {
    /// Whether the scheme can run on `net`: the channel filter needs a tree of lossless links;
    /// weights given by hand must fit the graph. An error names the field.
    pub fn check(&self, net: &Topology) -> Result<(), String> {
        let singles = self.largest_message();
        let octets = 4 * singles;
        let room = MAX_PAYLOAD_OCTETS - net.security.overhead_octets();
        if octets > room {
            let secured = match net.security.is_secured() {
                true => format!(", less {} of security", net.security.overhead_octets()),
                false => String::new(),
            };
            return Err(format!(
                "a message carries {singles} singles ({octets} octets), more than one 802.15.4 frame holds ({room} octets of payload{secured}); splitting a message across frames is not built yet"
            ));
        }
        match &self.kind {
            PeerKind::ChannelFilter => channel_filter::check_network(net),
            PeerKind::Consensus { weights, .. } | PeerKind::Diffusion { weights, .. } => {
                Weights::new(weights, net.nodes.len(), &net.edges()).map(|_| ())
            }
            PeerKind::EventTriggered { .. } => self
                .sensors
                .iter()
                .try_for_each(|(h, r)| super::et_ddf::elements(h, r).map(|_| ())),
            _ => Ok(()),
        }
    }

    /// Singles in the scheme's largest message (its state of dimension n, its sensors'
    /// readings of dimension m): a pair n + n(n+1)/2 (the matrix symmetric), a vector n.
    fn largest_message(&self) -> usize {
        let n = self.model.a.nrows();
        let m = self
            .sensors
            .iter()
            .map(|(h, _)| h.nrows())
            .max()
            .unwrap_or(0);
        let pair = n + n * (n + 1) / 2;
        match &self.kind {
            PeerKind::Consensus {
                fusion: FusionKind::Hybrid,
                ..
            } => 2 * pair,
            PeerKind::Consensus { .. } | PeerKind::PeerFusion(_) | PeerKind::ChannelFilter => pair,
            PeerKind::KalmanConsensus { .. } => n,
            PeerKind::Diffusion {
                order: Order::AdaptThenCombine,
                ..
            } => n.max(m),
            PeerKind::Diffusion { .. } => n + m,
            // Elements are singles (with a mask octet); CI requests carry an estimate.
            PeerKind::EventTriggered { .. } => pair.max(m + 1),
        }
    }

    /// Rounds a step takes.
    pub fn rounds(&self) -> usize {
        match &self.kind {
            PeerKind::Consensus { iterations, .. } => ConsensusNode::rounds(*iterations),
            PeerKind::KalmanConsensus { .. } => super::kalman_consensus::ROUNDS,
            PeerKind::Diffusion { order, .. } => DiffusionNode::rounds(*order),
            PeerKind::PeerFusion(_) => peer_fusion::ROUNDS,
            PeerKind::ChannelFilter => channel_filter::ROUNDS,
            PeerKind::EventTriggered { .. } => super::et_ddf::ROUNDS,
        }
    }

    /// The sensor of node `node` of `net`, if it is a sensor node.
    fn sensor_of(&self, net: &Topology, node: usize) -> Option<(&Matrix, &Matrix)> {
        match net.nodes[node].kind {
            NodeKind::Sensor(i) => self.sensors.get(i).map(|(h, r)| (h, r)),
            _ => None,
        }
    }

    /// One trial: the nodes on `t.net`, run over every step of `t.measurements`, each step's
    /// estimates and counters to `record`.
    pub fn run_trial(&self, t: &PeerTrial, record: &mut Recorder) -> Result<(), String> {
        let net = t.net;
        let n = net.nodes.len();
        let neighbours: Vec<Vec<usize>> = (0..n).map(|i| net.neighbours(i)).collect();
        let weighted = |rule: &WeightRule| -> Result<Vec<NodeWeights>, String> {
            let w = Weights::new(rule, n, &net.edges())?;
            Ok((0..n)
                .map(|i| {
                    let others = neighbours[i].iter().map(|&j| (j, w.get(i, j))).collect();
                    (w.get(i, i), others)
                })
                .collect())
        };
        // The scenario's prior is of x₀; a node's filter starts each step from its prediction
        // (the nodes correct first, then predict), so the first is x₁⁻ = A x₀ + w.
        let (model, prior) = (&self.model, &self.model.predict(&self.prior));
        match &self.kind {
            PeerKind::Consensus {
                fusion,
                weights,
                iterations,
                omega,
            } => {
                let omega = omega.unwrap_or(n as f64);
                let fusion = match fusion {
                    FusionKind::Information => Fusion::Information,
                    FusionKind::Measurements => Fusion::Measurements { omega },
                    FusionKind::Hybrid => Fusion::Hybrid { omega },
                };
                let mut nodes = weighted(weights)?
                    .into_iter()
                    .enumerate()
                    .map(|(i, (own, others))| {
                        let s = self.sensor_of(net, i);
                        ConsensusNode::new(
                            fusion,
                            model.clone(),
                            prior,
                            s,
                            own,
                            others,
                            *iterations,
                        )
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                // Lossless links: the lock-step loop, the driver's numbers without its envelopes.
                if super::consensus::lockstep::applies(net) {
                    return super::consensus::lockstep::run(
                        net,
                        t.measurements,
                        &mut nodes,
                        record,
                    );
                }
                drive(t, self.rounds(), boxed(nodes), record)
            }
            PeerKind::KalmanConsensus { gamma } => {
                let degree = neighbours.iter().map(Vec::len).max().unwrap_or(0);
                let gamma = gamma.unwrap_or(1.0 / (1.0 + degree as f64));
                let nodes = (0..n)
                    .map(|i| {
                        let s = self.sensor_of(net, i);
                        KalmanConsensusNode::new(
                            model.clone(),
                            prior,
                            s,
                            gamma,
                            neighbours[i].clone(),
                        )
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                drive(t, self.rounds(), boxed(nodes), record)
            }
            PeerKind::Diffusion {
                order,
                weights,
                threshold,
            } => {
                let sensors: Vec<Option<(Matrix, Matrix)>> = (0..n)
                    .map(|i| self.sensor_of(net, i).map(|(h, r)| (h.clone(), r.clone())))
                    .collect();
                let nodes = weighted(weights)?
                    .into_iter()
                    .enumerate()
                    .map(|(i, (own, others))| {
                        let node = DiffusionNode::new(
                            *order,
                            model.clone(),
                            prior,
                            &sensors,
                            i,
                            own,
                            others,
                        )?;
                        match threshold {
                            Some(tau) => node.triggered(*tau),
                            None => Ok(node),
                        }
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                drive(t, self.rounds(), boxed(nodes), record)
            }
            PeerKind::PeerFusion(rule) => {
                let nodes = (0..n)
                    .map(|i| {
                        let s = self.sensor_of(net, i);
                        PeerFusionNode::new(*rule, model.clone(), prior, s, neighbours[i].clone())
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                drive(t, self.rounds(), boxed(nodes), record)
            }
            PeerKind::EventTriggered { delta, tau } => {
                let elements = (0..n)
                    .map(|i| {
                        self.sensor_of(net, i)
                            .map(|(h, r)| super::et_ddf::elements(h, r))
                            .transpose()
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let nodes = (0..n)
                    .map(|i| {
                        let neighbours = neighbours[i].clone();
                        let params = (*delta, *tau);
                        super::et_ddf::EtDdfNode::new(
                            model.clone(),
                            prior,
                            &elements,
                            i,
                            neighbours,
                            params,
                        )
                    })
                    .collect();
                drive(t, self.rounds(), boxed(nodes), record)
            }
            PeerKind::ChannelFilter => {
                channel_filter::check_network(net)?;
                let nodes = (0..n)
                    .map(|i| {
                        let s = self.sensor_of(net, i);
                        ChannelFilterNode::new(model.clone(), prior, s, neighbours[i].clone())
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                drive(t, self.rounds(), boxed(nodes), record)
            }
        }
    }
}

/// The nodes as the driver takes them.
fn boxed<P, N: NetworkNode<P> + 'static>(nodes: Vec<N>) -> Vec<Box<dyn NetworkNode<P>>> {
    nodes
        .into_iter()
        .map(|n| Box::new(n) as Box<dyn NetworkNode<P>>)
        .collect()
}

/// Runs `nodes` (`rounds` rounds a step) on the trial's readings, recording each step.
fn drive<P: Payload + Clone>(
    t: &PeerTrial,
    rounds: usize,
    mut nodes: Vec<Box<dyn NetworkNode<P>>>,
    record: &mut Recorder,
) -> Result<(), String> {
    let steps = t.measurements.len();
    let mut driver = GraphDriver::new(t.net, rounds, steps, t.seed, t.trial);
    let sensors = t.net.sensors();
    let mut readings: Vec<Option<&Vector>> = Vec::with_capacity(sensors);
    for (j, z) in t.measurements.iter().enumerate() {
        readings.clear();
        readings.extend((0..sensors).map(|i| z.get(i)));
        driver.step(j + 1, &mut nodes, &readings)?;
        let estimates = nodes
            .iter()
            .enumerate()
            .map(|(x, node)| {
                node.estimate()
                    .ok_or_else(|| format!("node {} keeps no estimate", t.net.nodes[x].name))
            })
            .collect::<Result<Vec<&Gaussian>, String>>()?;
        record(j + 1, &estimates, driver.counts(), None)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decentralized::fixture::ring;

    fn peers(n: usize, kind: PeerKind) -> Peers {
        let i = Matrix::identity(n, n);
        let mut h = Matrix::zeros(1, n);
        h[(0, 0)] = 1.0;
        Peers {
            kind,
            model: Model {
                a: i.clone(),
                q: i.clone(),
            },
            prior: Gaussian::new(crate::linalg::Vector::zeros(n), i),
            sensors: vec![(h, Matrix::identity(1, 1)); 3],
        }
    }

    /// A 6-state pair is 27 singles, 108 octets: one frame; the hybrid's two pairs, 216
    /// octets, are not, and are refused rather than priced as one frame.
    #[test]
    fn a_message_larger_than_a_frame_is_refused() {
        let net = ring("kind = \"ideal\"");
        let consensus = |fusion| PeerKind::Consensus {
            fusion,
            weights: WeightRule::MetropolisHastings,
            iterations: 1,
            omega: None,
        };
        assert!(peers(6, consensus(FusionKind::Information))
            .check(&net)
            .is_ok());
        let e = peers(6, consensus(FusionKind::Hybrid))
            .check(&net)
            .unwrap_err();
        assert!(e.contains("54 singles (216 octets)"), "{e}");
        assert!(peers(4, consensus(FusionKind::Hybrid)).check(&net).is_ok());
    }
}
