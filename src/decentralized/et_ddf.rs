//! Event-triggered decentralized data fusion with implicit updates, after COHRINT's et-ddf
//! (Loefgren, Ahmed et al., FUSION 2019; the event-triggered measurement sharing of Dagan &
//! Ahmed's heterogeneous DDF): every node runs a Kalman filter on the whole state; a node with
//! a sensor shares each scalar element of its reading only when it is far from what its
//! neighbours can predict, and its silence is read as information, as the censoring schemes of
//! Zheng et al. read theirs.
//!
//! - **Shared filter.** Sensor node i keeps a filter Sᵢ that processes only what i has said about
//!   its own readings; each neighbour keeps an exact replica of it (same prior, same model, same
//!   messages), so both sides know ẑ = hₑ x̂_S, the element's prediction, without sending it.
//! - **Trigger** (per element e of z, in order): send zₑ when |zₑ − hₑ x̂_S| > δ; otherwise say
//!   nothing. δ = 0 sends every element (almost surely): each node is then the Kalman filter of
//!   its closed neighbourhood's readings (tested).
//! - **Explicit update** of a sent element: the scalar Kalman update with (hₑ, Rₑₑ, zₑ), at the
//!   receiver's own filter and at the replica (and at Sᵢ).
//! - **Implicit update** of a silent element: the receiver knows zₑ ∈ [ẑ − δ, ẑ + δ]. Under its
//!   own prior N(x̂, P), zₑ ~ N(hₑx̂, s²), s² = hₑPhₑᵀ + Rₑₑ, and x given zₑ is Gaussian with
//!   gain K = Phₑᵀ/s²; so the exact first two moments of x given the band are
//!   x̂ + K(E[zₑ | band] − hₑx̂) and P − KKᵀ(s² − Var[zₑ | band]), the truncated normal's mean
//!   and variance ([`crate::stats::truncated_normal::truncated_standard`]). The replica (and Sᵢ)
//!   take the same update, whose band is centred on their own prediction (no mean shift).
//! - **Covariance intersection on demand**: a node whose tr(P) exceeds τ broadcasts its estimate
//!   as a request; every neighbour that heard a request answers once with its estimate and fuses
//!   the request's by CI ([`super::peer_fusion::intersect`]); the requester fuses the answers by
//!   CI. Nodes without sensors learn about the target only this way. Without τ, no CI.
//!
//! A step is four rounds: (0) readings' elements, (1) implicit and explicit updates, requests,
//! (2) answers, (3) the requester's fusion, then every filter predicts. Frames: the sent
//! elements as singles (with an 8-bit element mask when the sensor has more than one element);
//! an estimate n + n(n+1)/2 singles. Windows: one per sensor neighbour a step (it may speak),
//! with τ one per neighbour for requests, and a requester one per neighbour for the answers.
//!
//! **A lost frame is read as silence**: the receiver cannot tell a lost reading from an unsent
//! one, makes the implicit update instead of the explicit one, and its replica drifts from the
//! sender's shared filter (the bands it uses are then off). The drop-probability sweep of the
//! et-ddf study (`scripts/et-ddf-study.sh`) measures what this costs. Element-wise sharing needs
//! each sensor's R diagonal (independent elements); a correlated R is refused.
use super::peer_fusion::intersect;
use super::Model;
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};
use crate::stats::truncated_normal::truncated_standard;

/// Rounds a step takes.
pub const ROUNDS: usize = 4;

/// What an et-ddf node broadcasts.
#[derive(Debug, Clone, PartialEq)]
pub enum EtDdfMessage {
    /// The elements of its reading it sends, (element, value); `of` elements in all.
    Elements { of: usize, sent: Vec<(usize, f64)> },
    /// Its estimate, asking its neighbours for covariance intersection.
    Request(Gaussian),
    /// Its estimate, answering a request.
    Answer(Gaussian),
}

impl Payload for EtDdfMessage {
    fn mac_bits(&self) -> u64 {
        let bits = match self {
            EtDdfMessage::Elements { of, sent } => {
                BITS_PER_COMPONENT * sent.len() as u64 + if *of > 1 { 8 } else { 0 }
            }
            EtDdfMessage::Request(g) | EtDdfMessage::Answer(g) => {
                BITS_PER_COMPONENT * crate::network::estimate_reals(g.mean.len())
            }
        };
        mpdu_bits_for_payload(bits)
    }
}

/// A sensor's elements: per element its row hₑ (as a column) and variance Rₑₑ.
type Elements = Vec<(Vector, f64)>;

/// The elements of sensor (H, R), or an error when R is not diagonal and positive.
pub fn elements(h: &Matrix, r: &Matrix) -> Result<Elements, String> {
    let m = h.nrows();
    for i in 0..m {
        for j in 0..m {
            if i != j && r[(i, j)] != 0.0 {
                return Err("et-ddf shares a reading element by element and needs each sensor's R diagonal (independent elements)".into());
            }
        }
        if !(r[(i, i)] > 0.0 && r[(i, i)].is_finite()) {
            return Err("a sensor's R is not positive definite".into());
        }
    }
    Ok((0..m).map(|e| (h.row(e).transpose(), r[(e, e)])).collect())
}

/// The scalar Kalman update of `g` with element (h, r) and value `z`.
fn explicit(g: &mut Gaussian, (h, r): &(Vector, f64), z: f64) {
    let ph = &g.cov * h;
    let s2 = h.dot(&ph) + r;
    let k = &ph / s2;
    g.mean += &k * (z - h.dot(&g.mean));
    g.cov -= &k * ph.transpose();
    crate::linalg::symmetrize(&mut g.cov);
}

/// The moment-matched update of `g` knowing that element (h, r) lies in [lo, hi] (module docs).
fn implicit(g: &mut Gaussian, (h, r): &(Vector, f64), lo: f64, hi: f64) -> Result<(), String> {
    let ph = &g.cov * h;
    let s2 = h.dot(&ph) + r;
    let s = s2.sqrt();
    let predicted = h.dot(&g.mean);
    let t = truncated_standard((lo - predicted) / s, (hi - predicted) / s);
    if !(t.mean.is_finite() && t.var.is_finite()) {
        return Err("an implicit update's band has no probability under the node's prior".into());
    }
    let k = &ph / s2;
    g.mean += &k * (s * t.mean);
    g.cov -= &k * k.transpose() * (s2 - s2 * t.var);
    crate::linalg::symmetrize(&mut g.cov);
    Ok(())
}

/// What a node says about its reading: updates its shared filter `shared` element by element
/// and returns the elements sent.
fn speak(
    shared: &mut Gaussian,
    elements: &Elements,
    z: &Vector,
    delta: f64,
) -> Result<Vec<(usize, f64)>, String> {
    let mut sent = Vec::new();
    for (e, el) in elements.iter().enumerate() {
        let predicted = el.0.dot(&shared.mean);
        if (z[e] - predicted).abs() > delta {
            explicit(shared, el, z[e]);
            sent.push((e, z[e]));
        } else {
            implicit(shared, el, predicted - delta, predicted + delta)?;
        }
    }
    Ok(sent)
}

/// What a neighbour reads from a sensor node's message (`None`: silence or a lost frame):
/// updates its own filter `mine` and its replica of the sender's shared filter.
fn listen(
    mine: &mut Gaussian,
    replica: &mut Gaussian,
    elements: &Elements,
    sent: Option<&[(usize, f64)]>,
    delta: f64,
) -> Result<(), String> {
    for (e, el) in elements.iter().enumerate() {
        match sent.and_then(|s| s.iter().find(|(i, _)| *i == e)) {
            Some(&(_, z)) => {
                explicit(mine, el, z);
                explicit(replica, el, z);
            }
            None => {
                let predicted = el.0.dot(&replica.mean);
                let (lo, hi) = (predicted - delta, predicted + delta);
                implicit(mine, el, lo, hi)?;
                implicit(replica, el, lo, hi)?;
            }
        }
    }
    Ok(())
}

/// One et-ddf node.
pub struct EtDdfNode {
    model: Model,
    delta: f64,
    tau: Option<f64>,
    /// Its own sensor's elements and shared filter, if it has a sensor.
    own: Option<(Elements, Gaussian)>,
    /// Per sensor neighbour: (node, its elements, the replica of its shared filter).
    replicas: Vec<(usize, Elements, Gaussian)>,
    neighbours: Vec<usize>,
    /// The node's filter: the step's prior, then its estimate.
    filter: Gaussian,
    estimate: Gaussian,
    requested: bool,
}

impl EtDdfNode {
    /// A node with neighbours `neighbours`, `sensors[j]` the elements of node j's sensor (if
    /// any; node `me`'s own among them), every filter from `prior`.
    pub fn new(
        model: Model,
        prior: &Gaussian,
        sensors: &[Option<Elements>],
        me: usize,
        neighbours: Vec<usize>,
        (delta, tau): (f64, Option<f64>),
    ) -> Self {
        let replicas = neighbours
            .iter()
            .filter_map(|&j| sensors[j].clone().map(|e| (j, e, prior.clone())))
            .collect();
        Self {
            model,
            delta,
            tau,
            own: sensors[me].clone().map(|e| (e, prior.clone())),
            replicas,
            neighbours,
            filter: prior.clone(),
            estimate: prior.clone(),
            requested: false,
        }
    }

    /// Estimates of `inbox` sent at step `k` that `pick` accepts.
    fn estimates(
        inbox: &[Envelope<EtDdfMessage>],
        k: usize,
        pick: fn(&EtDdfMessage) -> Option<&Gaussian>,
    ) -> impl Iterator<Item = &Gaussian> {
        inbox
            .iter()
            .filter(move |e| e.sent == k)
            .filter_map(move |e| pick(&e.payload))
    }

    fn fuse_all<'a>(&mut self, others: impl Iterator<Item = &'a Gaussian>) -> Result<(), String> {
        for g in others {
            self.filter = intersect(&self.filter, g)?;
        }
        Ok(())
    }

    /// The step's end: the estimate kept, every filter predicted.
    fn predict(&mut self) {
        self.estimate = self.filter.clone();
        self.filter = self.model.predict(&self.filter);
        if let Some((_, s)) = &mut self.own {
            *s = self.model.predict(s);
        }
        for (_, _, r) in &mut self.replicas {
            *r = self.model.predict(r);
        }
    }
}

impl NetworkNode<EtDdfMessage> for EtDdfNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<EtDdfMessage>],
        out: &mut Outbox<EtDdfMessage>,
    ) -> Result<(), String> {
        let k = at.k;
        match at.round {
            0 => {
                self.requested = false;
                if let (Some((elements, shared)), Some(z)) = (&mut self.own, at.reading) {
                    let sent = speak(shared, elements, z, self.delta)?;
                    for (e, el) in elements.iter().enumerate() {
                        explicit(&mut self.filter, el, z[e]);
                    }
                    if !sent.is_empty() {
                        let of = elements.len();
                        out.send(Address::Neighbours, EtDdfMessage::Elements { of, sent });
                    }
                }
            }
            1 => {
                for (j, elements, replica) in &mut self.replicas {
                    let sent = super::heard(inbox, *j, k).and_then(|m| match m {
                        EtDdfMessage::Elements { sent, .. } => Some(sent.as_slice()),
                        _ => None,
                    });
                    listen(&mut self.filter, replica, elements, sent, self.delta)?;
                }
                if self.tau.is_some_and(|t| self.filter.cov.trace() > t) {
                    self.requested = true;
                    out.send(
                        Address::Neighbours,
                        EtDdfMessage::Request(self.filter.clone()),
                    );
                }
            }
            2 => {
                let pick: fn(&EtDdfMessage) -> Option<&Gaussian> = |m| match m {
                    EtDdfMessage::Request(g) => Some(g),
                    _ => None,
                };
                if Self::estimates(inbox, k, pick).next().is_some() {
                    out.send(
                        Address::Neighbours,
                        EtDdfMessage::Answer(self.filter.clone()),
                    );
                    self.fuse_all(Self::estimates(inbox, k, pick))?;
                }
            }
            _ => {
                if self.requested {
                    let pick: fn(&EtDdfMessage) -> Option<&Gaussian> = |m| match m {
                        EtDdfMessage::Answer(g) => Some(g),
                        _ => None,
                    };
                    self.fuse_all(Self::estimates(inbox, k, pick))?;
                }
                self.predict();
            }
        }
        Ok(())
    }

    /// One window per sensor neighbour; with τ one per neighbour for requests, and for a
    /// requester one per neighbour for the answers.
    fn windows(&self, _k: usize) -> u64 {
        let d = self.neighbours.len();
        let requests = if self.tau.is_some() { d } else { 0 };
        let answers = if self.requested { d } else { 0 };
        (self.replicas.len() + requests + answers) as u64
    }

    fn estimate(&self) -> Option<&Gaussian> {
        Some(&self.estimate)
    }
}

#[cfg(test)]
mod tests;
