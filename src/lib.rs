//! hushfuse: multi-sensor state estimation under bandwidth limits.
pub mod link;
pub mod stats;
