//! Peer-to-peer fusion of estimates: every node runs its own Kalman filter on its own
//! measurement, broadcasts its estimate (x̂, P), and fuses what its neighbours sent.
//!
//! - **Covariance intersection** (Julier & Uhlmann, "A non-divergent estimation algorithm in the
//!   presence of unknown correlations", ACC 1997, eqs. (7)–(8)): P⁻¹ = ωA⁻¹ + (1 − ω)B⁻¹,
//!   x̂ = P(ωA⁻¹a + (1 − ω)B⁻¹b), ω ∈ [0, 1] minimizing det P (golden-section search on a product of scalars, [`intersect`]). Consistent
//!   whatever the cross-covariance of the two, so the peers' shared history (their common prior,
//!   each other's fused estimates) is never counted twice; several neighbours are folded in one
//!   after another, each fold consistent.
//! - **Inverse covariance intersection** (Noack, Sijs, Reinhardt, Hanebeck, "Decentralized data
//!   fusion with inverse covariance intersection", Automatica 79, 2017, Theorem 2):
//!   P⁻¹ = A⁻¹ + B⁻¹ − (ωA + (1 − ω)B)⁻¹, x̂ = Ka + Lb with K = P(A⁻¹ − ω(ωA + (1 − ω)B)⁻¹),
//!   L = P(B⁻¹ − (1 − ω)(ωA + (1 − ω)B)⁻¹), ω minimizing det P: consistent when the two share
//!   unknown common information (not for arbitrary correlation), and tighter than CI there.
//! - **Naive fusion**, kept as the counterexample: the estimates fused as if independent,
//!   P⁻¹ = Σ Pᵢ⁻¹, x̂ = P Σ Pᵢ⁻¹x̂ᵢ. On any graph with a loop (or any exchange repeated over
//!   steps) the common information is counted again at every fusion: the covariance shrinks far
//!   below the error (data incest), and the tests show its NEES running away.
//!
//! On the graph a step is two rounds: (0) predict-corrected local estimate, broadcast (x̂, P) in
//! one frame (n + n(n+1)/2 singles); (1) fuse with what arrived (a lost estimate is left out),
//! then predict.
use super::spd_inverse as inverse;
use super::{heard, sensor_information, Model, SensorInformation};
use crate::filter::Gaussian;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::message::BITS_PER_COMPONENT;
use crate::network::graph::{Address, Envelope, NetworkNode, Outbox, Payload, Round};

/// How a node fuses its neighbours' estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    CovarianceIntersection,
    InverseCovarianceIntersection,
    /// Independent fusion: inconsistent on loops (the counterexample).
    Naive,
}

/// A node's broadcast estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate(pub Gaussian);

impl Payload for Estimate {
    /// n + n(n+1)/2 singles (P is symmetric).
    fn mac_bits(&self) -> u64 {
        let n = self.0.mean.len() as u64;
        mpdu_bits_for_payload(BITS_PER_COMPONENT * (n + n * (n + 1) / 2))
    }
}

/// One peer.
pub struct PeerFusionNode {
    rule: Rule,
    model: Model,
    sensor: Option<SensorInformation>,
    neighbours: Vec<usize>,
    prior: Gaussian,
    local: Gaussian,
    estimate: Gaussian,
}

/// Rounds a step takes.
pub const ROUNDS: usize = 2;

impl PeerFusionNode {
    pub fn new(
        rule: Rule,
        model: Model,
        prior: &Gaussian,
        sensor: Option<(&Matrix, &Matrix)>,
        neighbours: Vec<usize>,
    ) -> Result<Self, String> {
        let sensor = sensor_information(sensor)?;
        Ok(Self {
            rule,
            model,
            sensor,
            neighbours,
            prior: prior.clone(),
            local: prior.clone(),
            estimate: prior.clone(),
        })
    }

    /// The local Kalman update of the prior with reading `z`.
    fn correct(&self, z: Option<&Vector>) -> Result<Gaussian, String> {
        let (Some((ht_rinv, u)), Some(z)) = (&self.sensor, z) else {
            return Ok(self.prior.clone());
        };
        let omega = inverse(&self.prior.cov).ok_or("the prior is not positive definite")?;
        let q = &omega * &self.prior.mean + ht_rinv * z;
        let cov = inverse(&(omega + u)).ok_or("the corrected information is singular")?;
        Ok(Gaussian::new(&cov * q, cov))
    }

    fn fuse(&self, others: &[&Gaussian]) -> Result<Gaussian, String> {
        match self.rule {
            Rule::CovarianceIntersection => others
                .iter()
                .try_fold(self.local.clone(), |a, b| intersect(&a, b)),
            Rule::InverseCovarianceIntersection => others
                .iter()
                .try_fold(self.local.clone(), |a, b| inverse_intersect(&a, b)),
            Rule::Naive => {
                let mut omega = Matrix::zeros(self.local.cov.nrows(), self.local.cov.ncols());
                let mut q = Vector::zeros(self.local.mean.len());
                for g in std::iter::once(&&self.local).chain(others) {
                    let inv = inverse(&g.cov).ok_or("an estimate is not positive definite")?;
                    q += &inv * &g.mean;
                    omega += inv;
                }
                let cov = inverse(&omega).ok_or("the fused information is singular")?;
                Ok(Gaussian::new(&cov * q, cov))
            }
        }
    }
}

/// The ω in [0, 1] maximizing `score` (golden section, then the ends: one estimate alone may
/// be best). The scores here (det P⁻¹ of CI and ICI) are unimodal in ω.
fn best_omega(score: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (score(x1), score(x2));
    for _ in 0..60 {
        if f1 > f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - g * (hi - lo);
            f1 = score(x1);
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + g * (hi - lo);
            f2 = score(x2);
        }
    }
    let mut w = (lo + hi) / 2.0;
    for end in [0.0, 1.0] {
        if score(end) >= score(w) {
            w = end;
        }
    }
    w
}

/// The eigenvalues of `base⁻¹ x` for symmetric positive definite `x` and `base` (those of
/// `L⁻¹ x L⁻ᵀ`, `base = L Lᵀ`): positive reals, which turn the determinants of the fusion
/// rules' matrix pencils into products of scalars.
fn relative_eigenvalues(x: &Matrix, base: &Matrix) -> Result<Vector, String> {
    let l = crate::linalg::cholesky(base)
        .map_err(|_| "an estimate is not positive definite")?
        .l();
    let lx = l
        .solve_lower_triangular(x)
        .ok_or("an estimate is not positive definite")?;
    let m = l
        .solve_lower_triangular(&lx.transpose())
        .ok_or("an estimate is not positive definite")?;
    Ok(m.symmetric_eigenvalues())
}

/// Covariance intersection of `a` and `b` with ω minimizing det P. With μᵢ the eigenvalues of
/// A⁻¹B, det(ωA⁻¹ + (1 − ω)B⁻¹) = det B⁻¹ · Πᵢ (1 + ω(μᵢ − 1)): the search scores the product,
/// n multiplications, rather than a determinant per trial ω.
pub fn intersect(a: &Gaussian, b: &Gaussian) -> Result<Gaussian, String> {
    let mu = relative_eigenvalues(&b.cov, &a.cov)?;
    let w = best_omega(|w| mu.iter().map(|m| 1.0 + w * (m - 1.0)).product());
    intersect_at(a, b, w)
}

/// Covariance intersection of `a` and `b` at a given ω.
pub fn intersect_at(a: &Gaussian, b: &Gaussian, w: f64) -> Result<Gaussian, String> {
    let ia = inverse(&a.cov).ok_or("an estimate is not positive definite")?;
    let ib = inverse(&b.cov).ok_or("an estimate is not positive definite")?;
    let cov = inverse(&(&ia * w + &ib * (1.0 - w))).ok_or("the intersection is singular")?;
    let mean = &cov * (&ia * &a.mean * w + &ib * &b.mean * (1.0 - w));
    Ok(Gaussian::new(mean, cov))
}

/// Inverse covariance intersection of `a` and `b` with ω minimizing det P. With λᵢ the
/// eigenvalues of B⁻¹A and T with A = TΛTᵀ, B = TTᵀ, the fused information
/// A⁻¹ + B⁻¹ − (ωA + (1 − ω)B)⁻¹ is T⁻ᵀ diag(1/λᵢ + 1 − 1/(1 + ω(λᵢ − 1))) T⁻¹: its determinant
/// is det T⁻² times the product of those n scalars, which the search scores.
pub fn inverse_intersect(a: &Gaussian, b: &Gaussian) -> Result<Gaussian, String> {
    let lambda = relative_eigenvalues(&a.cov, &b.cov)?;
    let w = best_omega(|w| {
        lambda
            .iter()
            .map(|l| 1.0 / l + 1.0 - 1.0 / (1.0 + w * (l - 1.0)))
            .product()
    });
    inverse_intersect_at(a, b, w)
}

/// Inverse covariance intersection of `a` and `b` at a given ω.
pub fn inverse_intersect_at(a: &Gaussian, b: &Gaussian, w: f64) -> Result<Gaussian, String> {
    let ia = inverse(&a.cov).ok_or("an estimate is not positive definite")?;
    let ib = inverse(&b.cov).ok_or("an estimate is not positive definite")?;
    let mix = inverse(&(&a.cov * w + &b.cov * (1.0 - w))).ok_or("ωA + (1 − ω)B is singular")?;
    let cov = inverse(&(&ia + &ib - &mix)).ok_or("the inverse intersection is singular")?;
    let k = &cov * (&ia - &mix * w);
    let l = &cov * (&ib - &mix * (1.0 - w));
    Ok(Gaussian::new(k * &a.mean + l * &b.mean, cov))
}

impl NetworkNode<Estimate> for PeerFusionNode {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<Estimate>],
        out: &mut Outbox<Estimate>,
    ) -> Result<(), String> {
        if at.round == 0 {
            self.local = self.correct(at.reading)?;
            out.send(Address::Neighbours, Estimate(self.local.clone()));
            return Ok(());
        }
        let others: Vec<&Gaussian> = self
            .neighbours
            .iter()
            .filter_map(|&j| heard(inbox, j, at.k).map(|e| &e.0))
            .collect();
        self.estimate = self.fuse(&others)?;
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
