//! The Kalman consensus filter: Olfati-Saber, "Kalman-consensus filter: optimality, stability,
//! and performance", IEEE CDC 2009, Algorithm 1. Every node i keeps its prediction x̄ᵢ and its
//! covariance Pᵢ, broadcasts x̄ᵢ, and with its neighbours' x̄ⱼ updates
//!
//!   x̂ᵢ = x̄ᵢ + Kᵢ(zᵢ − Hᵢx̄ᵢ) + Cᵢ Σⱼ (x̄ⱼ − x̄ᵢ),
//!   Kᵢ = PᵢHᵢᵀ(Rᵢ + HᵢPᵢHᵢᵀ)⁻¹,  Cᵢ = γ Pᵢ / (1 + ‖Pᵢ‖_F),
//!   Mᵢ = (I − KᵢHᵢ)Pᵢ(I − KᵢHᵢ)ᵀ + KᵢRᵢKᵢᵀ,  Pᵢ ← AMᵢAᵀ + Q,  x̄ᵢ ← Ax̂ᵢ,
//!
//! with the consensus gain γ > 0 (the paper's ε). The covariance ignores the consensus term and
//! the neighbours' correlations: the filter is not optimal on a sparse graph (the digest's §1.2),
//! and a node without a sensor (Kᵢ = 0) is pulled only by its neighbours. γ = 0 or no neighbour
//! gives each node's local Kalman filter (tested).
//!
//! On the graph a step is two rounds: (0) broadcast x̄ᵢ (n singles); (1) update with the
//! neighbours' predictions that arrived (a lost one is left out of the sum), then predict.
use super::spd_inverse as inverse;
use super::{heard, Model};
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};

/// A node's broadcast prediction x̄ᵢ.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction(pub Vector);

impl Payload for Prediction {
    fn mac_bits(&self) -> u64 {
        mpdu_bits_for_payload(BITS_PER_COMPONENT * self.0.len() as u64)
    }
}

/// Rounds a step takes.
pub const ROUNDS: usize = 2;

/// One node of the Kalman consensus filter.
pub struct KalmanConsensusNode {
    model: Model,
    sensor: Option<(Matrix, Matrix)>,
    gamma: f64,
    neighbours: Vec<usize>,
    /// x̄ᵢ, Pᵢ.
    prior: Gaussian,
    estimate: Gaussian,
}

impl KalmanConsensusNode {
    /// Node with prior `prior`, sensor (H, R) if any, consensus gain `gamma` ≥ 0 and its
    /// `neighbours`.
    pub fn new(
        model: Model,
        prior: &Gaussian,
        sensor: Option<(&Matrix, &Matrix)>,
        gamma: f64,
        neighbours: Vec<usize>,
    ) -> Result<Self, String> {
        if !(gamma.is_finite() && gamma >= 0.0) {
            return Err(format!("gamma = {gamma} must be a finite gain ≥ 0"));
        }
        Ok(Self {
            model,
            sensor: sensor.map(|(h, r)| (h.clone(), r.clone())),
            gamma,
            neighbours,
            prior: prior.clone(),
            estimate: prior.clone(),
        })
    }

    /// The update with reading `z` and the neighbours' predictions `others`.
    fn update(&self, z: Option<&Vector>, others: &[&Vector]) -> Result<Gaussian, String> {
        let (xb, p) = (&self.prior.mean, &self.prior.cov);
        let n = xb.len();
        let (mut x, m) = match (&self.sensor, z) {
            (Some((h, r)), Some(z)) => {
                let s = r + h * p * h.transpose();
                let k = p * h.transpose() * inverse(&s).ok_or("the innovation is singular")?;
                let i_kh = Matrix::identity(n, n) - &k * h;
                let m = &i_kh * p * i_kh.transpose() + &k * r * k.transpose();
                (xb + &k * (z - h * xb), m)
            }
            _ => (xb.clone(), p.clone()),
        };
        if !others.is_empty() && self.gamma > 0.0 {
            let c = p * (self.gamma / (1.0 + p.norm()));
            let mut pull = Vector::zeros(n);
            for o in others {
                pull += *o - xb;
            }
            x += c * pull;
        }
        Ok(Gaussian::new(x, m))
    }
}

impl NetworkNode<Prediction> for KalmanConsensusNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<Prediction>],
        out: &mut Outbox<Prediction>,
    ) -> Result<(), String> {
        if at.round == 0 {
            out.send(Address::Neighbours, Prediction(self.prior.mean.clone()));
            return Ok(());
        }
        let others: Vec<&Vector> = self
            .neighbours
            .iter()
            .filter_map(|&j| heard(inbox, j, at.k).map(|p| &p.0))
            .collect();
        self.estimate = self.update(at.reading, &others)?;
        self.prior = self.model.predict(&self.estimate);
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
