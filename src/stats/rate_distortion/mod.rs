//! A floor no scheme can beat: the sequential (causal) rate–distortion function of a
//! Gauss–Markov source, the smallest steady-state mean squared error that **any** causal
//! scheme — any quantizer, any trigger, any entropy or variable-length code, any decoder —
//! reaches when it sends `R` bits per step on average. A scheme's measured MSE drawn against
//! its entropy-coded rate (bits per step) can be compared with this curve directly; a point
//! below it is a bug.
//!
//! Rates are in **bits per time step** throughout; distortion is the steady-state mean squared
//! error `E|x_k − y_k|²` (the trace of the error covariance for vectors), where `y_k` is any
//! estimate the receiver forms from what it received up to step `k`.
//!
//! # Scalar, fully observed ([`scalar::distortion`], [`scalar::rate`])
//! For `x' = a x + w`, `w ~ N(0, W)` with the encoder seeing `x`:
//!
//! `D(R) = W / (2^{2R} − a²)` for `R > log2|a|` (and `R >= 0`),
//!
//! infinite below (the data-rate theorem: an unstable source needs more than `log2|a|` bits
//! per step to be tracked at all), and `R(D) = ½ log2(a² + W / D)`. Reason: in steady state the
//! receiver's error variance `D` grows to the prior `a² D + W` before the next message, and a
//! message of `R` bits shrinks a Gaussian variance by at most `2^{2R}`, so
//! `D >= (a² D + W) / 2^{2R}`. Tatikonda, Sahai, Mitter, "Stochastic linear control over a
//! communication channel", IEEE TAC 49(9), 2004.
//!
//! # Scalar with a noisy sensor ([`scalar::noisy_distortion`])
//! If the encoder sees only `z = h x + v`, `v ~ N(0, V)`, let `x̂_k = E[x_k | z_1..z_k]` be the
//! Kalman estimate (all data, no rate limit), with steady prior variance `M` and posterior `P`.
//! Any receiver estimate `y_k` is a function of the data (through the messages), and the
//! Kalman error `x_k − x̂_k` is orthogonal to every function of the data, so
//!
//! `E|x − y|² = E|x − x̂|² + E|x̂ − y|² = P + E|x̂ − y|²`.
//!
//! The estimate is itself Gauss–Markov: `x̂' = a x̂ + K ν` with gain `K = M h / S` and
//! innovation `ν` white of variance `S = h² M + V`, so its driving variance is
//! `K² S = M² h² / S = M − P`. The encoder can compute `x̂` (it sees `z`), so the second term
//! is the fully observed floor of that process:
//!
//! `D_noisy(R) = P + (M − P) / (2^{2R} − a²)`,
//!
//! which tends to `P` (the all-data Kalman error) as `R → ∞` and is never below it.
//!
//! # Vector ([`sdp::floor_mse`], [`sdp::rate`], [`noisy::floor_mse_noisy`])
//! For `x' = A x + w`, `w ~ N(0, W)`, `W ≻ 0`, the stationary sequential rate–distortion
//! function is the value of a log-det semidefinite program over the receiver's error
//! covariance `P` (the derivation and the cone form are in [`sdp`]):
//!
//! minimize `trace(P)` subject to `½ log det(A P Aᵀ + W) − ½ log det P <= R · ln 2`,
//! `P ⪯ A P Aᵀ + W`,
//!
//! made convex with an auxiliary `Π` (Tanaka, Kim, Parrilo, Mitter, "Semidefinite programming
//! approach to Gaussian sequential rate-distortion trade-offs", IEEE TAC 62(4), 2017,
//! arXiv:1411.7632). We solve it with Clarabel (PSD and exponential cones) rather than a solver
//! of our own. On a 1×1 system it reduces to the scalar closed form. With a noisy linear
//! sensor set `z = H x + v` the same orthogonality split gives `trace(P_kf)` plus the floor of
//! the Kalman estimate process, whose driving covariance is `K S Kᵀ = M − P_kf`.
//!
//! The floor is finite only above `Σ max(0, log2|λ_i(A)|)` bits per step; below it (and for a
//! negative rate) the functions return [`FloorError::RateTooLow`] rather than a number.
pub mod conic;
pub mod noisy;
pub mod scalar;
pub mod sdp;

pub use noisy::{floor_mse_noisy, kalman_steady_state, KalmanSteadyState};
pub use sdp::{floor_covariance, floor_mse, floor_point, min_rate, rate, stationary_covariance};

/// Why a floor could not be given.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FloorError {
    /// The rate is negative, or at or below the data-rate minimum: the floor is infinite.
    #[error(
        "rate {rate} bits/step is at or below {min} bits/step: no scheme keeps the error bounded"
    )]
    RateTooLow { rate: f64, min: f64 },
    /// Shapes, non-finite entries, a covariance that is not positive definite, a Kalman filter
    /// without steady state.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// The conic solver did not reach a solution.
    #[error("conic solver failed: {0}")]
    Solver(String),
}
