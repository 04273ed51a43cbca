//! Metrics as mergeable sums, the summaries computed from them, and the bounds no scheme
//! can beat.
pub mod energy;
pub mod estimators;
mod failed;
pub mod finite;
pub mod floor;
pub mod link;
pub mod network;
pub mod notes;
pub mod pcrb;
pub mod per_step_csv;
pub mod precision;
pub mod results;
pub mod sums;

pub use failed::summary_json;
pub use sums::*;
