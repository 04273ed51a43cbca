//! The Monte Carlo engine: the trial loop ([`trial`], with the seeding rule of [`seeding`]), runs in blocks with checkpoints and shards,
//! the trial-0 trace, replay of recorded data and calibration to bit budgets.
pub mod calibrate;
pub mod durable;
pub mod link_layer;
pub mod replay;
pub mod run;
pub mod runner;
pub mod seeding;
pub mod trace;
pub mod trial;
