//! hushfuse: multi-sensor state estimation under bandwidth limits.
//!
//! Sensors decide whether and with how many bits to talk; a fusion center fuses what arrives
//! and what the silence says. Where each paper lives:
//! - seed 004 (Dormann, Noack, Hanebeck, distributed KF with omitted estimates):
//!   [`scheme::distributed_kf`];
//! - the baselines every scheme is measured against: [`scheme::centralized`].
//!
//! The simulator ([`sim`]) owns the only time loop; filters, sensor nodes and fusion centers do
//! one step per call and can be used on their own.
pub mod filter;
pub mod linalg;
pub mod link;
pub mod model;
pub mod network;
pub mod scheme;
pub mod sim;
pub mod stats;
