//! The diffusion Kalman filter: Cattivelli & Sayed, "Diffusion strategies for distributed
//! Kalman filtering and smoothing", IEEE TAC 55(9), 2010, Algorithm 1 (adapt-then-combine, the
//! "diffusion KF") and its combine-then-adapt form (§III-B). Node k with neighbourhood Jₖ (k and
//! its neighbours) and combination weights c_{l,k} (Σ_{l∈Jₖ} c_{l,k} = 1):
//!
//! - incremental (adapt) step: ψₖ = x̂ₖ⁻, Pₖ = Pₖ⁻; for every l ∈ Jₖ,
//!   ψₖ ← ψₖ + PₖHₗᵀ(Rₗ + HₗPₖHₗᵀ)⁻¹(yₗ − Hₗψₖ), Pₖ ← Pₖ − PₖHₗᵀ(Rₗ + HₗPₖHₗᵀ)⁻¹HₗPₖ; computed
//!   here in its information form (the same numbers in exact arithmetic):
//!   Pₖ = (Pₖ⁻⁻¹ + Σ_{l∈Jₖ} HₗᵀRₗ⁻¹Hₗ)⁻¹, ψₖ = Pₖ(Pₖ⁻⁻¹x̂ₖ⁻ + Σ_{l∈Jₖ} HₗᵀRₗ⁻¹yₗ);
//! - diffusion (combine) step: x̂ₖ = Σ_{l∈Jₖ} c_{l,k} ψₗ; the covariance Pₖ is **not** combined;
//! - prediction: x̂ₖ⁻ ← A x̂ₖ, Pₖ⁻ ← A Pₖ Aᵀ + Q.
//!
//! Combine-then-adapt combines the predicted estimates first (x̂ₖ⁻ ← Σ c_{l,k} x̂ₗ⁻) and then
//! adapts; its one exchange a step carries the prediction and the measurement together.
//!
//! Checks (the digest's §1.5, derived): on a complete graph with c = 1/N every ψ is the
//! all-data update, so adapt-then-combine is the all-data Kalman filter; with C = I each node is
//! the Kalman filter of its neighbourhood's measurements. Every node knows its neighbours'
//! (Hₗ, Rₗ), as the paper assumes, so a measurement crosses the air as its m singles.
//!
//! **Event-triggered** (Alanwar, Said, Mehta, Althoff, "Event-triggered diffusion Kalman
//! filters", ICCPS 2020, §IV): a node takes part in a step's exchanges only when its local
//! signal, the trace of its predicted covariance, exceeds a threshold τ; otherwise it neither
//! sends nor listens and adapts with its own measurement alone. τ = 0 is the untriggered filter
//! (tested); an unreachable τ leaves every node its local Kalman filter.
//!
//! On the graph: adapt-then-combine is three rounds (broadcast the measurement; adapt and
//! broadcast ψ, n singles; combine and predict), combine-then-adapt two (broadcast the
//! prediction and the measurement in one frame; combine, adapt and predict). A neighbour's
//! message that did not arrive leaves its measurement out of the adaptation and gives its weight
//! in the combination to the node itself.
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};

use super::spd_inverse as inverse;
use super::{sensor_information, Model, SensorInformation};

/// Adapt-then-combine (Algorithm 1) or combine-then-adapt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    AdaptThenCombine,
    CombineThenAdapt,
}

/// What a diffusion node broadcasts.
#[derive(Debug, Clone, PartialEq)]
pub enum DiffusionMessage {
    /// Its measurement (adapt-then-combine, round 0).
    Measurement(Vector),
    /// Its intermediate estimate ψ (adapt-then-combine, round 1).
    Intermediate(Vector),
    /// Its prediction and its measurement, if any (combine-then-adapt).
    Prediction(Vector, Option<Vector>),
}

impl Payload for DiffusionMessage {
    fn mac_bits(&self) -> u64 {
        let singles = match self {
            DiffusionMessage::Measurement(v) | DiffusionMessage::Intermediate(v) => v.len(),
            DiffusionMessage::Prediction(x, z) => x.len() + z.as_ref().map_or(0, |z| z.len()),
        };
        mpdu_bits_for_payload(BITS_PER_COMPONENT * singles as u64)
    }
}

/// One node of the diffusion Kalman filter.
pub struct DiffusionNode {
    order: Order,
    model: Model,
    /// Per node of the network: its sensor's information form, if it has one (a node uses its
    /// own and its neighbours').
    sensors: Vec<Option<SensorInformation>>,
    me: usize,
    /// c_{k,k} and (l, c_{l,k}) for every neighbour l.
    own_weight: f64,
    neighbours: Vec<(usize, f64)>,
    prior: Gaussian,
    /// ψ after the adaptation, with its covariance.
    adapted: Gaussian,
    /// The node's own reading of the step.
    reading: Option<Vector>,
    estimate: Gaussian,
    /// τ of the event trigger (`None`: always take part).
    threshold: Option<f64>,
    /// Whether the node takes part in the current step's exchanges.
    fired: bool,
}

impl DiffusionNode {
    /// Node `me` of a network whose nodes' sensors are `sensors` ((H, R) where a node has one),
    /// with prior `prior` and combination weights `own_weight`, `neighbours` (l, c_{l,me}).
    pub fn new(
        order: Order,
        model: Model,
        prior: &Gaussian,
        sensors: &[Option<(Matrix, Matrix)>],
        me: usize,
        own_weight: f64,
        neighbours: Vec<(usize, f64)>,
    ) -> Result<Self, String> {
        let sensors = sensors
            .iter()
            .map(|s| sensor_information(s.as_ref().map(|(h, r)| (h, r))))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            order,
            model,
            sensors,
            me,
            own_weight,
            neighbours,
            prior: prior.clone(),
            adapted: prior.clone(),
            reading: None,
            estimate: prior.clone(),
            threshold: None,
            fired: true,
        })
    }

    /// The event-triggered form: exchange only at steps where tr(P⁻) > `threshold` (≥ 0).
    pub fn triggered(mut self, threshold: f64) -> Result<Self, String> {
        if threshold.is_nan() || threshold < 0.0 {
            return Err(format!("threshold = {threshold} must be ≥ 0"));
        }
        self.threshold = Some(threshold);
        Ok(self)
    }

    /// Rounds a step takes.
    pub fn rounds(order: Order) -> usize {
        match order {
            Order::AdaptThenCombine => 3,
            Order::CombineThenAdapt => 2,
        }
    }

    /// The adaptation of `prior` with the measurements `readings` (node, z).
    fn adapt<'a>(
        &self,
        prior: &Gaussian,
        readings: impl Iterator<Item = (usize, &'a Vector)>,
    ) -> Result<Gaussian, String> {
        let mut omega = inverse(&prior.cov).ok_or("the prior is not positive definite")?;
        let mut q = &omega * &prior.mean;
        for (l, z) in readings {
            if let Some((ht_rinv, u)) = &self.sensors[l] {
                omega += u;
                q += ht_rinv * z;
            }
        }
        let cov = inverse(&omega).ok_or("the adapted information is not positive definite")?;
        Ok(Gaussian::new(&cov * q, cov))
    }

    /// Σ c_{l,k} of the vectors `mine` and the neighbours' `theirs(l)` (a missing one: mine).
    fn combine<'a>(&self, mine: &Vector, theirs: impl Fn(usize) -> Option<&'a Vector>) -> Vector {
        let mut x = mine * self.own_weight;
        for &(l, c) in &self.neighbours {
            x += theirs(l).unwrap_or(mine) * c;
        }
        x
    }

    fn predict(&mut self, estimate: Gaussian) {
        self.prior = self.model.predict(&estimate);
        self.estimate = estimate;
    }
}

/// The message of `inbox` from node `l` sent at step `k` that `pick` accepts.
fn from<'a, T>(
    inbox: &'a [Envelope<DiffusionMessage>],
    k: usize,
    l: usize,
    pick: impl Fn(&'a DiffusionMessage) -> Option<T>,
) -> Option<T> {
    inbox
        .iter()
        .filter(|e| e.source == l && e.sent == k)
        .find_map(|e| pick(&e.payload))
}

impl NetworkNode<DiffusionMessage> for DiffusionNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<DiffusionMessage>],
        out: &mut Outbox<DiffusionMessage>,
    ) -> Result<(), String> {
        let k = at.k;
        let own = self.sensors[self.me].as_ref().and(at.reading);
        if at.round == 0 {
            self.fired = self.threshold.is_none_or(|t| self.prior.cov.trace() > t);
        }
        if !self.fired {
            // Not triggered: no exchange, the node's own measurement only.
            if at.round == 0 {
                self.reading = own.cloned();
            }
            if at.round + 1 == Self::rounds(self.order) {
                let mine = self.reading.as_ref().map(|z| (self.me, z));
                let estimate = self.adapt(&self.prior, mine.into_iter())?;
                self.predict(estimate);
            }
            return Ok(());
        }
        match (self.order, at.round) {
            (Order::AdaptThenCombine, 0) => {
                self.reading = own.cloned();
                if let Some(z) = own {
                    out.send(
                        Address::Neighbours,
                        DiffusionMessage::Measurement(z.clone()),
                    );
                }
            }
            (Order::AdaptThenCombine, 1) => {
                let theirs = self.neighbours.iter().filter_map(|&(l, _)| {
                    from(inbox, k, l, |m| match m {
                        DiffusionMessage::Measurement(z) => Some((l, z)),
                        _ => None,
                    })
                });
                let mine = self.reading.as_ref().map(|z| (self.me, z));
                self.adapted = self.adapt(&self.prior, mine.into_iter().chain(theirs))?;
                let psi = self.adapted.mean.clone();
                out.send(Address::Neighbours, DiffusionMessage::Intermediate(psi));
            }
            (Order::AdaptThenCombine, _) => {
                let x = self.combine(&self.adapted.mean, |l| {
                    from(inbox, k, l, |m| match m {
                        DiffusionMessage::Intermediate(psi) => Some(psi),
                        _ => None,
                    })
                });
                let cov = self.adapted.cov.clone();
                self.predict(Gaussian::new(x, cov));
            }
            (Order::CombineThenAdapt, 0) => {
                self.reading = own.cloned();
                let message = DiffusionMessage::Prediction(self.prior.mean.clone(), own.cloned());
                out.send(Address::Neighbours, message);
            }
            (Order::CombineThenAdapt, _) => {
                let mean = self.combine(&self.prior.mean, |l| {
                    from(inbox, k, l, |m| match m {
                        DiffusionMessage::Prediction(x, _) => Some(x),
                        _ => None,
                    })
                });
                let combined = Gaussian::new(mean, self.prior.cov.clone());
                let theirs = self.neighbours.iter().filter_map(|&(l, _)| {
                    from(inbox, k, l, |m| match m {
                        DiffusionMessage::Prediction(_, Some(z)) => Some((l, z)),
                        _ => None,
                    })
                });
                let mine = self.reading.as_ref().map(|z| (self.me, z));
                let estimate = self.adapt(&combined, mine.into_iter().chain(theirs))?;
                self.predict(estimate);
            }
        }
        Ok(())
    }

    /// One window per neighbour per exchange it takes part in.
    fn windows(&self, _k: usize) -> u64 {
        let exchanges = match self.order {
            Order::AdaptThenCombine => 2,
            Order::CombineThenAdapt => 1,
        };
        (self.neighbours.len() * exchanges * usize::from(self.fired)) as u64
    }

    fn estimate(&self) -> Option<&Gaussian> {
        Some(&self.estimate)
    }
}

#[cfg(test)]
mod tests;
