//! Scenario files, the Monte Carlo runner, metrics, outputs (CSV/JSON/SVG) and the paper
//! reports. The simulator owns the only time loop.
pub mod arena;
pub mod build;
pub mod builtin;
pub mod calibrate;
pub mod durable;
pub mod html;
pub mod limits;
pub mod metrics;
pub mod output;
pub mod paper_check;
pub mod pcrb;
pub mod plot;
pub mod replay;
pub mod report;
pub mod results;
pub mod runner;
pub mod scenario;
pub mod schemes;
pub mod sweep;
pub mod system;
pub mod tables;
pub mod trace;
