//! Bootstrap particle filter machinery: a particle cloud, linear-Gaussian propagation, weight
//! normalization, estimates and resampling — the fusion center of Zheng, Niu and
//! Varshney (2014), Algorithm 1 steps (A1.3)–(A1.6). Schemes compute their own likelihood (received
//! measurements and the censoring bands of silent sensors) and add it to
//! [`ParticleCloud::log_weights_mut`]; everything else lives here.
//!
//! This is the hot path of the project (10^3–10^4 particles, thousands of trials), so the
//! layout and the loops are chosen for speed:
//! - particles are stored structure-of-arrays, component-major: component `j` of all particles
//!   is one contiguous slice, so per-particle arithmetic is a loop over plain slices that the
//!   compiler vectorizes;
//! - every buffer (states, log-weights, normalized weights, normal draws, ancestor indices) is
//!   owned by the cloud and sized at construction: no step allocates;
//! - normal draws are made in blocks of `n` into a scratch slice (a 1024-layer ziggurat,
//!   [`crate::stats::normal_block`]) and then applied to the state
//!   components with `axpy` loops;
//! - the exponential in the normalization is a branch-free polynomial that vectorizes (the
//!   libm `exp` is an opaque call per particle).
//!
//! Each function does one step; the caller owns the time loop and the random number generator,
//! so the same seed gives bit-identical clouds.
//!
//! The code is split by what it is: [`ParticleCloud`] and [`ParticleTransition`] with the
//! per-step operations in `cloud`, the vectorized slice loops they are made of in `lanes`, and
//! the four resampling schemes in `resample`. This module holds what they share (the error
//! type and the resampling choices) and re-exports the public types, so every item keeps its
//! path `filter::particle::X`.
mod cloud;
mod lanes;
mod resample;

pub use cloud::{ParticleCloud, ParticleTransition, StateView};

use crate::linalg::LinalgError;

/// Why a particle-filter operation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParticleError {
    #[error("a particle cloud needs at least one particle and one state component")]
    Empty,
    #[error("{what}: expected dimension {expected}, got {got}")]
    Dimension {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what}: {source}")]
    Matrix {
        what: &'static str,
        source: LinalgError,
    },
    /// Every particle has zero weight (all log-weights `-inf`), or a log-weight is NaN or
    /// `+inf`: the posterior cannot be represented and the caller must decide (re-initialize,
    /// skip the update, ...).
    #[error("particle weights are degenerate: no finite positive total (all -inf, NaN or +inf)")]
    DegenerateWeights,
    #[error("ESS threshold must be a fraction in [0, 1], got {0}")]
    Threshold(f64),
    #[error("particle index {index} out of range for {len} particles")]
    Index { index: usize, len: usize },
}

/// How to draw the `n` ancestor indices from the normalized weights. All four are unbiased
/// (each particle's expected number of copies is `n w_i`) and produce sorted indices, so the
/// gather that follows reads memory in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Resampling {
    /// One uniform `u`, positions `(k + u) / n`: copies are `floor(n w_i)` or `ceil(n w_i)`;
    /// the lowest-variance choice and the cheapest (one branch-free pass).
    #[default]
    Systematic,
    /// One uniform per stratum, positions `(k + u_k) / n`: copies differ from `n w_i` by less
    /// than 2.
    Stratified,
    /// `floor(n w_i)` deterministic copies, the remaining `n - sum floor(n w_i)` drawn
    /// multinomially from the fractional parts.
    Residual,
    /// `n` independent draws (the textbook bootstrap filter), done in O(n) through sorted
    /// uniforms generated as normalized cumulative sums of exponential spacings.
    Multinomial,
}

/// When to resample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ResamplePolicy {
    /// Every step, as in Zheng et al.'s (2014) Algorithm 1 (A1.6).
    #[default]
    Always,
    /// Only when the effective sample size falls below `fraction * n` (a common choice is
    /// 0.5): resampling adds Monte Carlo noise, so it is done only when the weights degenerate.
    EssBelow(f64),
}

/// Helpers shared by the tests of the submodules.
#[cfg(test)]
mod test_support {
    use super::Resampling;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    pub(super) fn rng(seed: u64) -> Xoshiro256PlusPlus {
        Xoshiro256PlusPlus::seed_from_u64(seed)
    }

    pub(super) const ALL_SCHEMES: [Resampling; 4] = [
        Resampling::Systematic,
        Resampling::Stratified,
        Resampling::Residual,
        Resampling::Multinomial,
    ];
}
