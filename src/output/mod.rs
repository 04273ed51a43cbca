//! What a run writes: the atomic output folder, CSV/JSON, SVG plots, HTML and paper
//! reports, arena tables.
pub mod arena;
pub mod arena_files;
pub mod durable;
pub mod energy_front;
pub mod folder;
pub mod html;
pub mod network_map;
pub mod notes;
pub mod plot;
pub mod report;
pub mod run;
pub mod run_files;
pub mod tables;

pub use folder::*;
