//! Scenario files, the Monte Carlo runner, metrics, outputs (CSV/JSON/SVG) and the paper
//! reports. The simulator owns the only time loop.
pub mod build;
pub mod builtin;
pub mod metrics;
pub mod plot;
pub mod report;
pub mod results;
pub mod runner;
pub mod scenario;
pub mod tables;
