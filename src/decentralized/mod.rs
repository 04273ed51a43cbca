//! Estimation without a center: every node runs a filter and talks only with its neighbours
//! over the network's graph ([`crate::network::graph`]), each exchange a real frame priced per
//! edge. One module per scheme, each citing its paper's equations.
pub mod channel_filter;
pub mod consensus;
pub mod diffusion;
pub mod et_ddf;
#[cfg(test)]
mod fixture;
pub mod kalman_consensus;
pub mod peer_fusion;
pub mod trial;
pub mod weights;

use crate::filter::Gaussian;
use crate::linalg::Matrix;
use crate::network::graph::Envelope;

/// The linear model every node knows: x' = A x + w, w ~ N(0, Q).
#[derive(Debug, Clone)]
pub struct Model {
    pub a: Matrix,
    pub q: Matrix,
}

impl Model {
    /// The prediction of `g` one step ahead: (A x̂, A P Aᵀ + Q).
    pub fn predict(&self, g: &Gaussian) -> Gaussian {
        Gaussian::new(
            &self.a * &g.mean,
            &self.a * &g.cov * self.a.transpose() + &self.q,
        )
    }
}

/// A sensor in information form: (HᵀR⁻¹, HᵀR⁻¹H), so that a reading z adds (HᵀR⁻¹H, HᵀR⁻¹z).
pub type SensorInformation = (Matrix, Matrix);

/// The information form of the sensor (H, R), if there is one; an R that is not positive
/// definite is an error.
pub fn sensor_information(
    sensor: Option<(&Matrix, &Matrix)>,
) -> Result<Option<SensorInformation>, String> {
    sensor
        .map(|(h, r)| {
            let r_inv = spd_inverse(r).ok_or("a sensor's R is not positive definite")?;
            let ht_rinv = h.transpose() * r_inv;
            let u = &ht_rinv * h;
            Ok((ht_rinv, u))
        })
        .transpose()
}

/// The message of node `j` sent at step `k` in `inbox` (a later one of a step, a delayed one of
/// an earlier step are not it).
pub(crate) fn heard<P>(inbox: &[Envelope<P>], j: usize, k: usize) -> Option<&P> {
    inbox
        .iter()
        .find(|e| e.source == j && e.sent == k)
        .map(|e| &e.payload)
}

/// The inverse of a symmetric positive definite matrix ([`crate::linalg::spd_inverse`]), or
/// `None` (each caller says which matrix it was).
pub(crate) fn spd_inverse(m: &Matrix) -> Option<Matrix> {
    crate::linalg::spd_inverse(m).ok()
}
