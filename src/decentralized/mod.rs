//! Estimation without a center: every node runs a filter and talks only with its neighbours
//! over the network's graph ([`crate::network::graph`]), each exchange a real frame priced per
//! edge. One module per scheme, each citing its paper's equations.
pub mod channel_filter;
pub mod consensus;
pub mod diffusion;
#[cfg(test)]
mod fixture;
pub mod kalman_consensus;
pub mod peer_fusion;
pub mod weights;

use crate::linalg::Matrix;

/// The inverse of a symmetric positive definite matrix (by its Cholesky factor), or `None`.
pub(crate) fn spd_inverse(m: &Matrix) -> Option<Matrix> {
    m.clone().cholesky().map(|c| c.inverse())
}
