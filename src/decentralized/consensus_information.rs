//! Consensus on information (CI): Battistelli & Chisci, "Kullback–Leibler average, consensus on
//! probability densities, and distributed state estimation with guaranteed stability",
//! Automatica 50(3), 2014, Table 1 (the distributed filter run at every node i):
//!
//! 1. correction with the node's own measurement, in information form:
//!    Ωᵢ = Ωᵢ⁻ + HᵢᵀRᵢ⁻¹Hᵢ, qᵢ = qᵢ⁻ + HᵢᵀRᵢ⁻¹zᵢ (a node without a sensor adds nothing);
//! 2. L consensus iterations on the pair, Ωᵢ ← Σⱼ πᵢⱼ Ωⱼ, qᵢ ← Σⱼ πᵢⱼ qⱼ over i and its neighbours
//!    (the weighted Kullback–Leibler average of the Gaussians, i.e. covariance intersection with
//!    weights π: consistent for any L ≥ 1);
//! 3. prediction: x̂ᵢ = Ωᵢ⁻¹qᵢ, Pᵢ⁻ = A Ωᵢ⁻¹ Aᵀ + Q, Ωᵢ⁻ = (Pᵢ⁻)⁻¹, qᵢ⁻ = Ωᵢ⁻ A x̂ᵢ.
//!
//! As L grows with equal priors every node reaches Ω⁻ + (1/N) Σᵢ Uᵢ: the Kalman filter with every
//! Rᵢ multiplied by N (conservative, consistent, suboptimal; the digest's §1.4, checked in the
//! tests below). With L = 0 every node is its local Kalman filter.
//!
//! On the graph ([`crate::network::graph`]) a step is L + 1 rounds: round 0 corrects and
//! broadcasts the pair (one frame, n + n(n+1)/2 singles), round l combines what arrived from the
//! neighbours and broadcasts again until the L-th combination, then predicts. A neighbour's pair
//! that did not arrive (a lost broadcast) is replaced by the node's own: its weight goes to the
//! node (the row stays stochastic, so the result is still a Kullback–Leibler average and stays
//! consistent; the network average drifts, as one-way drops do, Kar & Moura 2009).
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};

/// What a node broadcasts: its information pair after `iteration` combinations.
#[derive(Debug, Clone, PartialEq)]
pub struct InformationPair {
    pub iteration: usize,
    pub matrix: Matrix,
    pub vector: Vector,
}

impl Payload for InformationPair {
    /// n + n(n+1)/2 singles (the matrix is symmetric), in one MAC frame.
    fn mac_bits(&self) -> u64 {
        let n = self.vector.len() as u64;
        mpdu_bits_for_payload(BITS_PER_COMPONENT * (n + n * (n + 1) / 2))
    }
}

/// The linear model every node knows: x' = A x + w, w ~ N(0, Q).
#[derive(Debug, Clone)]
pub struct Model {
    pub a: Matrix,
    pub q: Matrix,
}

/// One node's filter.
pub struct ConsensusOnInformation {
    model: Model,
    /// (Hᵀ R⁻¹, Hᵀ R⁻¹ H) of the node's sensor, if it has one.
    sensor: Option<(Matrix, Matrix)>,
    /// πᵢᵢ and (j, πᵢⱼ) for every neighbour j.
    own_weight: f64,
    neighbours: Vec<(usize, f64)>,
    iterations: usize,
    /// (Ωᵢ⁻, qᵢ⁻) before the step's correction; (Ωᵢ, qᵢ) during it.
    prior: (Matrix, Vector),
    pair: (Matrix, Vector),
    estimate: Gaussian,
}

impl ConsensusOnInformation {
    /// Node with prior `prior`, sensor (H, R) if any, consensus weights `own_weight` and
    /// `neighbours` (node, weight) summing to 1, and `iterations` = L consensus steps a step.
    pub fn new(
        model: Model,
        prior: &Gaussian,
        sensor: Option<(&Matrix, &Matrix)>,
        own_weight: f64,
        neighbours: Vec<(usize, f64)>,
        iterations: usize,
    ) -> Result<Self, String> {
        let omega = inverse(&prior.cov).ok_or("the prior covariance is not positive definite")?;
        let q = &omega * &prior.mean;
        let sensor = match sensor {
            Some((h, r)) => {
                let r_inv = inverse(r).ok_or("a sensor's R is not positive definite")?;
                let ht_rinv = h.transpose() * r_inv;
                let u = &ht_rinv * h;
                Some((ht_rinv, u))
            }
            None => None,
        };
        Ok(Self {
            model,
            sensor,
            own_weight,
            neighbours,
            iterations,
            pair: (omega.clone(), q.clone()),
            prior: (omega, q),
            estimate: prior.clone(),
        })
    }

    /// Rounds a step takes: the correction, then one per consensus iteration.
    pub fn rounds(iterations: usize) -> usize {
        iterations + 1
    }

    /// One consensus iteration on what arrived (iteration `l − 1`'s pairs of this step).
    fn combine(&mut self, k: usize, l: usize, inbox: &[Envelope<InformationPair>]) {
        let (own_m, own_v) = &self.pair;
        let mut m = own_m * self.own_weight;
        let mut v = own_v * self.own_weight;
        for &(j, w) in &self.neighbours {
            let got = inbox
                .iter()
                .find(|e| e.source == j && e.sent == k && e.payload.iteration == l - 1);
            match got {
                Some(e) => {
                    m += &e.payload.matrix * w;
                    v += &e.payload.vector * w;
                }
                // Lost: the node's own pair in its place.
                None => {
                    m += own_m * w;
                    v += own_v * w;
                }
            }
        }
        self.pair = (m, v);
    }

    /// The estimate from the pair, then the prediction to the next step's prior.
    fn predict(&mut self) -> Result<(), String> {
        let (omega, q) = &self.pair;
        let p = inverse(omega).ok_or("the fused information is not positive definite")?;
        let mean = &p * q;
        let a = &self.model.a;
        let p_pred = a * &p * a.transpose() + &self.model.q;
        let omega_pred = inverse(&p_pred).ok_or("the predicted covariance is singular")?;
        let q_pred = &omega_pred * (a * &mean);
        self.estimate = Gaussian::new(mean, p);
        self.prior = (omega_pred, q_pred);
        Ok(())
    }

    fn broadcast(&self, iteration: usize, out: &mut Outbox<InformationPair>) {
        out.send(
            Address::Neighbours,
            InformationPair {
                iteration,
                matrix: self.pair.0.clone(),
                vector: self.pair.1.clone(),
            },
        );
    }
}

impl NetworkNode<InformationPair> for ConsensusOnInformation {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<InformationPair>],
        out: &mut Outbox<InformationPair>,
    ) -> Result<(), String> {
        if at.round == 0 {
            let (omega, q) = &self.prior;
            self.pair = match (&self.sensor, at.reading) {
                (Some((ht_rinv, u)), Some(z)) => (omega + u, q + ht_rinv * z),
                _ => (omega.clone(), q.clone()),
            };
        } else {
            self.combine(at.k, at.round, inbox);
        }
        if at.round < self.iterations {
            self.broadcast(at.round, out);
            Ok(())
        } else {
            self.predict()
        }
    }

    /// One window per neighbour per iteration (each may send in its slot).
    fn windows(&self, _k: usize) -> u64 {
        (self.neighbours.len() * self.iterations) as u64
    }

    /// The estimate after the step's last combination (the filtered one, before prediction).
    fn estimate(&self) -> Option<&Gaussian> {
        Some(&self.estimate)
    }
}

/// The inverse of a symmetric positive definite matrix, or `None`.
fn inverse(m: &Matrix) -> Option<Matrix> {
    m.clone().cholesky().map(|c| c.inverse())
}

#[cfg(test)]
mod tests;
