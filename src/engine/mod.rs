//! The Monte Carlo engine: the trial loop ([`trial`], with the seeding rule of [`crate::stats::seeding`]), runs in blocks with checkpoints and shards,
//! the trial-0 trace, replay of recorded data and calibration to bit budgets.
pub mod calibrate;
pub mod fusion_side;
pub mod link_layer;
pub mod peers;
pub mod replay;
pub mod runner;
pub mod star_nodes;
/// The seeding rule lives below every layer that draws ([`crate::stats::seeding`]); kept here
/// under its old path for code written against it.
pub use crate::stats::seeding;
pub mod trace;
pub mod trial;
