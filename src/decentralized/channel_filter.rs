//! The channel filter: Grime & Durrant-Whyte, "Data fusion in decentralized sensor networks",
//! Control Engineering Practice 2(5), 1994, §4 (information-form decentralized data fusion on
//! a tree). Every node keeps its information estimate (Y, y) and, for each link to a neighbour
//! j, a channel filter (Yᵢⱼ, yᵢⱼ): the information the two have in common. A step:
//!
//! 1. local update: (Y, y) ← (Y⁻ + HᵀR⁻¹H, y⁻ + HᵀR⁻¹z);
//! 2. every node broadcasts (Y, y); from each neighbour j it adds what j knows that it does
//!    not, (Yⱼ − Yᵢⱼ, yⱼ − yᵢⱼ), and the channel becomes what both now share,
//!    Yᵢⱼ ← Yᵢ(sent) + Yⱼ − Yᵢⱼ (the same at both ends);
//! 3. the estimate and every channel are predicted with the same model.
//!
//! Exact on a tree: no information reaches a node by two paths, and the common information is
//! subtracted once. Checks (derived, tested): the hub of a star is the all-data Kalman filter at
//! every step (every node one hop away, each channel equal to the leaf's fused estimate). On a
//! graph with a loop the same information arrives twice and is counted twice, so
//! [`check_network`] refuses loops; it also refuses lossy links (a lost broadcast leaves the two
//! copies of a channel different, and the estimate with them).
use super::consensus::Pair;
use super::spd_inverse as inverse;
use super::{heard, sensor_information, Model, SensorInformation};
use crate::filter::Gaussian;
use crate::linalg::Matrix;
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};
use crate::network::topology::Topology;

/// A node's broadcast information estimate (Y, y).
#[derive(Debug, Clone, PartialEq)]
pub struct InformationEstimate(pub Pair);

impl Payload for InformationEstimate {
    /// n + n(n+1)/2 singles (Y is symmetric).
    fn mac_bits(&self) -> u64 {
        let n = self.0 .1.len() as u64;
        mpdu_bits_for_payload(BITS_PER_COMPONENT * (n + n * (n + 1) / 2))
    }
}

/// Rounds a step takes.
pub const ROUNDS: usize = 2;

/// Whether the channel filter is exact on `net`: a tree of lossless links. An error names the
/// field and what is wrong.
pub fn check_network(net: &Topology) -> Result<(), String> {
    let (nodes, links) = (net.nodes.len(), net.links.len());
    if links + 1 != nodes {
        return Err(format!(
            "network.edges: the channel filter needs a tree, but {nodes} nodes have {links} links (a loop counts information twice)"
        ));
    }
    if let Some(l) = net.links.iter().find(|l| !l.channel.is_lossless()) {
        return Err(format!(
            "network.links: the channel filter needs lossless links (a lost exchange leaves the channel's two copies different); {} – {} is lossy",
            net.nodes[l.a].name, net.nodes[l.b].name
        ));
    }
    Ok(())
}

/// One node of the channel filter.
pub struct ChannelFilterNode {
    model: Model,
    sensor: Option<SensorInformation>,
    neighbours: Vec<usize>,
    /// (Y⁻, y⁻) before the step, (Y, y) during it.
    info: Pair,
    /// Per neighbour: the channel (Yᵢⱼ, yᵢⱼ).
    channels: Vec<Pair>,
    estimate: Gaussian,
}

impl ChannelFilterNode {
    /// Node with prior `prior` (every channel starts from it: the prior is what all share),
    /// sensor (H, R) if any, and its `neighbours`.
    pub fn new(
        model: Model,
        prior: &Gaussian,
        sensor: Option<(&Matrix, &Matrix)>,
        neighbours: Vec<usize>,
    ) -> Result<Self, String> {
        let y = inverse(&prior.cov).ok_or("the prior covariance is not positive definite")?;
        let info = (y.clone(), &y * &prior.mean);
        let sensor = sensor_information(sensor)?;
        Ok(Self {
            model,
            sensor,
            channels: vec![info.clone(); neighbours.len()],
            neighbours,
            info,
            estimate: prior.clone(),
        })
    }

    /// The prediction of an information pair with the model.
    fn predict(&self, (y, v): &Pair) -> Result<Pair, String> {
        let p = inverse(y).ok_or("an information matrix is not positive definite")?;
        let predicted = self.model.predict(&Gaussian::new(&p * v, p));
        let y = inverse(&predicted.cov).ok_or("a predicted covariance is singular")?;
        let v = &y * predicted.mean;
        Ok((y, v))
    }
}

impl NetworkNode<InformationEstimate> for ChannelFilterNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<InformationEstimate>],
        out: &mut Outbox<InformationEstimate>,
    ) -> Result<(), String> {
        if at.round == 0 {
            if let (Some((ht_rinv, u)), Some(z)) = (&self.sensor, at.reading) {
                self.info.0 += u;
                self.info.1 += ht_rinv * z;
            }
            out.send(Address::Neighbours, InformationEstimate(self.info.clone()));
            return Ok(());
        }
        let sent = self.info.clone();
        for (c, &j) in self.channels.iter_mut().zip(&self.neighbours) {
            let Some(InformationEstimate((yj, vj))) = heard(inbox, j, at.k) else {
                continue;
            };
            self.info.0 += yj - &c.0;
            self.info.1 += vj - &c.1;
            *c = (&sent.0 + yj - &c.0, &sent.1 + vj - &c.1);
        }
        let cov = inverse(&self.info.0).ok_or("the fused information is not positive definite")?;
        self.estimate = Gaussian::new(&cov * &self.info.1, cov);
        self.info = self.predict(&self.info)?;
        let channels = std::mem::take(&mut self.channels);
        self.channels = channels
            .iter()
            .map(|c| self.predict(c))
            .collect::<Result<_, _>>()?;
        Ok(())
    }

    fn windows(&self, _k: usize) -> u64 {
        self.neighbours.len() as u64
    }

    fn estimate(&self) -> Option<&Gaussian> {
        Some(&self.estimate)
    }
}

#[cfg(test)]
mod tests;
