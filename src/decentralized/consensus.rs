//! The consensus family: every node corrects with its own measurement and runs L consensus
//! iterations a step with its neighbours, in information form (Ω = P⁻¹, q = P⁻¹x̂). Notation of
//! the digest (`../shared/notes/decentralized.md` §1): Uᵢ = HᵢᵀRᵢ⁻¹Hᵢ, uᵢ = HᵢᵀRᵢ⁻¹zᵢ; a node
//! without a sensor (a relay, a naive node) has Uᵢ = 0, uᵢ = 0; consensus with weights π
//! ([`super::weights`]) is ξᵢ ← Σⱼ πᵢⱼ ξⱼ over i and its neighbours.
//!
//! - **Consensus on information (CI)**, Battistelli & Chisci, "Kullback–Leibler average,
//!   consensus on probability densities, and distributed state estimation with guaranteed
//!   stability", Automatica 50(3), 2014, Table 1: correct, Ωᵢ = Ωᵢ⁻ + Uᵢ, qᵢ = qᵢ⁻ + uᵢ; L
//!   consensus iterations on (Ωᵢ, qᵢ) (the weighted Kullback–Leibler average of the Gaussians,
//!   covariance intersection with weights π: consistent for any L ≥ 1); predict. As L grows
//!   with equal priors: Ω⁻ + (1/N) Σ Uᵢ, the Kalman filter with every Rᵢ multiplied by N.
//! - **Consensus on measurements (CM)** and the **hybrid (HCMCI)**, Battistelli, Chisci, Mugnai,
//!   Farina, Graziano, "Consensus-based linear and nonlinear filtering", IEEE TAC 60(5), 2015,
//!   Table I: L consensus iterations on the novel information (Uᵢ, uᵢ), and for the hybrid on the
//!   prior (Ωᵢ⁻, qᵢ⁻) too; correct with Ωᵢ = Ωᵢ⁻⁽ᴸ⁾ + ωᵢ Uᵢ⁽ᴸ⁾, qᵢ = qᵢ⁻⁽ᴸ⁾ + ωᵢ uᵢ⁽ᴸ⁾ (CM:
//!   Ωᵢ⁻⁽ᴸ⁾ = Ωᵢ⁻). With ω = N, L → ∞ and equal priors both give the all-data Kalman filter. By
//!   linearity the hybrid with ω = 1 is CI exactly (tested).
//! - **Information-weighted consensus filter (ICF)**, Kamal, Farrell, Roy-Chowdhury, "Information
//!   weighted consensus filters and their application in distributed camera networks", IEEE TAC
//!   58(12), 2013, Algorithm 1: Vᵢ = Jᵢ⁻/N + Uᵢ, vᵢ = Jᵢ⁻x̂ᵢ⁻/N + uᵢ; K iterations
//!   vᵢ ← vᵢ + ε Σⱼ (vⱼ − vᵢ) (weights I − εL, ε < 1/Δ_max: [`super::weights::WeightRule::MaxDegree`]);
//!   Jᵢ⁺ = N Vᵢ, x̂ᵢ⁺ = Vᵢ⁻¹vᵢ. That is the hybrid with ω = N and those weights (derived:
//!   N·avg(J⁻/N + U) = avg(J⁻) + N·avg(U)), built as such ([`Fusion::information_weighted`]).
//!
//! On the graph ([`crate::network::graph`]) a step is L + 1 rounds: round 0 forms the pairs and
//! broadcasts them (one frame: one pair of n + n(n+1)/2 singles for CI and CM, two for the
//! hybrid), round l combines what arrived from the neighbours and broadcasts again until the
//! L-th combination, then corrects (CM, hybrid), and predicts. A neighbour's pair that did not
//! arrive (a lost broadcast) is replaced by the node's own: its weight goes to the node (the row
//! stays stochastic, so CI's result is still a Kullback–Leibler average and stays consistent; the
//! network average drifts, as one-way drops do, Kar & Moura 2009).
use super::spd_inverse as inverse;
use super::{sensor_information, Model, SensorInformation};
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};

/// An information pair (Ω, q).
pub type Pair = (Matrix, Vector);

/// What a node broadcasts: its pairs after `iteration` combinations (one, or the hybrid's
/// prior and novel pairs).
#[derive(Debug, Clone, PartialEq)]
pub struct InformationPairs {
    pub iteration: usize,
    pub pairs: Vec<Pair>,
}

impl Payload for InformationPairs {
    /// n + n(n+1)/2 singles a pair (the matrix is symmetric), in one MAC frame.
    fn mac_bits(&self) -> u64 {
        let n = self.pairs.first().map_or(0, |p| p.1.len());
        InformationPairs::frame_bits(self.pairs.len(), n)
    }
}

impl InformationPairs {
    /// MAC bits of the frame that carries `pairs` pairs of an `n`-dimensional state.
    pub fn frame_bits(pairs: usize, n: usize) -> u64 {
        let (pairs, n) = (pairs as u64, n as u64);
        mpdu_bits_for_payload(BITS_PER_COMPONENT * pairs * (n + n * (n + 1) / 2))
    }
}

/// Which member of the family a node runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fusion {
    /// CI: consensus on the corrected pair.
    Information,
    /// CM: consensus on the novel information only, then Ωᵢ⁻ + ω U⁽ᴸ⁾.
    Measurements { omega: f64 },
    /// HCMCI: consensus on the prior and the novel information, then Ω⁻⁽ᴸ⁾ + ω U⁽ᴸ⁾.
    Hybrid { omega: f64 },
}

impl Fusion {
    /// Kamal et al.'s ICF on a network of `n` nodes: the hybrid with ω = N (run it with
    /// max-degree weights, its ε-Laplacian iteration).
    pub fn information_weighted(n: usize) -> Self {
        Fusion::Hybrid { omega: n as f64 }
    }
}

/// One node's filter.
pub struct ConsensusNode {
    model: Model,
    /// (Hᵀ R⁻¹, Hᵀ R⁻¹ H) of the node's sensor, if it has one.
    sensor: Option<SensorInformation>,
    /// πᵢᵢ and (j, πᵢⱼ) for every neighbour j.
    own_weight: f64,
    neighbours: Vec<(usize, f64)>,
    iterations: usize,
    fusion: Fusion,
    /// (Ωᵢ⁻, qᵢ⁻) of the step.
    prior: Pair,
    /// What the consensus runs on during the step: the corrected pair (CI), the novel pair
    /// (CM), or the prior and the novel pair (hybrid).
    pairs: Vec<Pair>,
    /// The previous iteration's pairs, reused as the next one's work space.
    spare: Vec<Pair>,
    estimate: Gaussian,
    /// Work space of [`ConsensusNode::predict`] and [`ConsensusNode::start`], kept from step
    /// to step (nothing allocated once sized): a factor, A P, the prediction, Aᵀ, Hᵀ R⁻¹ z.
    work: Work,
}

/// A node's work space ([`ConsensusNode::predict`]).
struct Work {
    factor: Matrix,
    ap: Matrix,
    predicted: Gaussian,
    a_t: Matrix,
    novel_q: Vector,
}

impl ConsensusNode {
    /// Node running `fusion` with prior `prior`, sensor (H, R) if any, consensus weights
    /// `own_weight` and `neighbours` (node, weight) summing to 1, and `iterations` = L consensus
    /// steps a step.
    pub fn new(
        fusion: Fusion,
        model: Model,
        prior: &Gaussian,
        sensor: Option<(&Matrix, &Matrix)>,
        own_weight: f64,
        neighbours: Vec<(usize, f64)>,
        iterations: usize,
    ) -> Result<Self, String> {
        let omega = inverse(&prior.cov).ok_or("the prior covariance is not positive definite")?;
        let q = &omega * &prior.mean;
        let sensor = sensor_information(sensor)?;
        let n = q.len();
        let work = Work {
            factor: Matrix::zeros(n, n),
            ap: Matrix::zeros(n, n),
            predicted: prior.clone(),
            a_t: model.a.transpose(),
            novel_q: Vector::zeros(n),
        };
        Ok(Self {
            work,
            model,
            sensor,
            own_weight,
            neighbours,
            iterations,
            fusion,
            pairs: Vec::new(),
            spare: Vec::new(),
            prior: (omega, q),
            estimate: prior.clone(),
        })
    }

    /// How many pairs the node broadcasts: the hybrid's prior and novel pair, else one.
    pub fn pair_count(&self) -> usize {
        match self.fusion {
            Fusion::Hybrid { .. } => 2,
            _ => 1,
        }
    }

    /// Rounds a step takes: the correction, then one per consensus iteration.
    pub fn rounds(iterations: usize) -> usize {
        iterations + 1
    }

    /// One consensus iteration on what arrived (iteration `l − 1`'s pairs of this step), into
    /// the node's spare pairs (kept from iteration to iteration: nothing allocated once their
    /// shapes are set).
    fn combine(&mut self, k: usize, l: usize, inbox: &[Envelope<InformationPairs>]) {
        let mut mixed = std::mem::take(&mut self.spare);
        mixed.truncate(self.pairs.len());
        for (i, (m, v)) in self.pairs.iter().enumerate() {
            match mixed.get_mut(i) {
                Some((mm, mv)) if mm.shape() == m.shape() && mv.len() == v.len() => {
                    mm.copy_from(m);
                    mv.copy_from(v);
                }
                Some(slot) => *slot = (m.clone(), v.clone()),
                None => mixed.push((m.clone(), v.clone())),
            }
        }
        for (m, v) in &mut mixed {
            *m *= self.own_weight;
            *v *= self.own_weight;
        }
        for &(j, w) in &self.neighbours {
            let got = inbox
                .iter()
                .find(|e| e.source == j && e.sent == k && e.payload.iteration == l - 1);
            // Lost: the node's own pairs in its place.
            let theirs = got.map_or(&self.pairs, |e| &e.payload.pairs);
            for ((m, v), (tm, tv)) in mixed.iter_mut().zip(theirs) {
                add_scaled(m.as_mut_slice(), tm.as_slice(), w);
                add_scaled(v.as_mut_slice(), tv.as_slice(), w);
            }
        }
        self.spare = std::mem::replace(&mut self.pairs, mixed);
    }

    /// The pairs the consensus starts from at step `k` with reading `z`. Consensus on
    /// information writes into the pair it kept (the same sums as `omega + U`, `q + Hᵀ R⁻¹ z`,
    /// a missing reading adding zeros, without allocating).
    fn start(&mut self, z: Option<&Vector>) {
        if self.fusion == Fusion::Information && self.pairs.len() == 1 {
            let (omega, q) = &self.prior;
            let (m, v) = &mut self.pairs[0];
            m.copy_from(omega);
            v.copy_from(q);
            match (&self.sensor, z) {
                (Some((ht_rinv, u)), Some(z)) => {
                    *m += u;
                    ht_rinv.mul_to(z, &mut self.work.novel_q);
                    *v += &self.work.novel_q;
                }
                _ => {
                    m.iter_mut().for_each(|x| *x += 0.0);
                    v.iter_mut().for_each(|x| *x += 0.0);
                }
            }
            return;
        }
        let (omega, q) = &self.prior;
        let n = q.len();
        let novel = match (&self.sensor, z) {
            (Some((ht_rinv, u)), Some(z)) => (u.clone(), ht_rinv * z),
            _ => (Matrix::zeros(n, n), Vector::zeros(n)),
        };
        self.pairs = match self.fusion {
            Fusion::Information => vec![(omega + &novel.0, q + &novel.1)],
            Fusion::Measurements { .. } => vec![novel],
            Fusion::Hybrid { .. } => vec![(omega.clone(), q.clone()), novel],
        };
    }

    /// The corrected pair after the consensus, for the members that combine two pairs (consensus
    /// on information's is its pair).
    fn corrected_other(&self) -> Pair {
        match self.fusion {
            Fusion::Information => self.pairs[0].clone(),
            Fusion::Measurements { omega } => {
                let (m, v) = &self.pairs[0];
                (&self.prior.0 + m * omega, &self.prior.1 + v * omega)
            }
            Fusion::Hybrid { omega } => {
                let ((pm, pv), (m, v)) = (&self.pairs[0], &self.pairs[1]);
                (pm + m * omega, pv + v * omega)
            }
        }
    }

    /// The estimate from the corrected pair, then the prediction to the next step's prior:
    /// P = Ω⁻¹, x̂ = P q, P⁻ = A P Aᵀ + Q, x̂⁻ = A x̂, Ω⁻ = (P⁻)⁻¹, q⁻ = Ω⁻ x̂⁻, each into the
    /// node's kept matrices (the same operations as the allocating forms, hence the same bits).
    fn predict(&mut self) -> Result<(), String> {
        let corrected = match self.fusion {
            Fusion::Information => None,
            _ => Some(self.corrected_other()),
        };
        let w = &mut self.work;
        let est = &mut self.estimate;
        let fail = |m: &str| m.to_string();
        {
            let (omega, q) = match &corrected {
                None => (&self.pairs[0].0, &self.pairs[0].1),
                Some((m, v)) => (m, v),
            };
            crate::linalg::spd_inverse_small_into(omega, &mut est.cov, &mut w.factor)
                .map_err(|_| fail("the fused information is not positive definite"))?;
            est.cov.mul_to(q, &mut est.mean);
        }
        self.model.a.mul_to(&est.cov, &mut w.ap);
        w.ap.mul_to(&w.a_t, &mut w.predicted.cov);
        w.predicted.cov += &self.model.q;
        self.model.a.mul_to(&est.mean, &mut w.predicted.mean);
        let (omega_pred, q_pred) = &mut self.prior;
        crate::linalg::spd_inverse_small_into(&w.predicted.cov, omega_pred, &mut w.factor)
            .map_err(|_| fail("the predicted covariance is singular"))?;
        omega_pred.mul_to(&w.predicted.mean, q_pred);
        Ok(())
    }

    fn broadcast(&self, iteration: usize, out: &mut Outbox<InformationPairs>) {
        let pairs = self.pairs.clone();
        out.send(Address::Neighbours, InformationPairs { iteration, pairs });
    }
}

/// `a += b w`, element by element: the same numbers as nalgebra's `a + b * w`, in place.
fn add_scaled(a: &mut [f64], b: &[f64], w: f64) {
    for (x, y) in a.iter_mut().zip(b) {
        *x += y * w;
    }
}

impl NetworkNode<InformationPairs> for ConsensusNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<InformationPairs>],
        out: &mut Outbox<InformationPairs>,
    ) -> Result<(), String> {
        if at.round == 0 {
            self.start(at.reading);
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

    /// The estimate after the step's correction (the filtered one, before prediction).
    fn estimate(&self) -> Option<&Gaussian> {
        Some(&self.estimate)
    }
}

pub mod lockstep;
mod mixing;
mod split;
#[cfg(test)]
mod tests;
