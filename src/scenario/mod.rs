//! Scenario files: the format, validation, the built-ins, sweeps, resource limits and
//! their errors; `build` turns a file into an [`build::Experiment`].
pub mod build;
pub mod builtin;
pub mod channel;
pub mod classic;
pub mod draw;
pub mod error;
pub mod every_scheme;
pub mod experiment;
pub mod file;
pub mod intermittent;
pub mod limits;
pub mod lossy;
pub mod paper_check;
pub mod scheme_link;
pub mod schemes;
pub mod sweep;
pub mod system;

pub use file::*;
