//! Statistics that the censoring and quantization schemes need and no crate gives in the form
//! we need: normal tails accurate to |x| = 40 in log space, band probabilities, chi-square
//! quantiles, quadratic-form (generalized chi-square) probabilities, Lloyd-Max quantizers; and
//! the rate–distortion floor that no bandwidth-limited scheme can beat.
pub mod band_kernel;
pub mod chi2;
pub mod lloyd_max;
pub mod normal;
pub mod normal_block;
pub mod normal_lanes;
pub mod quadform;
pub mod quadform2d;
pub mod rate_distortion;
pub mod seeding;
pub mod truncated_normal;
