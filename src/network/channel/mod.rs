//! The link model between sensors and the fusion center: which packets are lost and how late the
//! others arrive, with acknowledged retransmission (`arq`) if asked. The engine's link layer
//! (`crate::engine::link_layer`) applies it in the trial loop.
//!
//! - [`spec`]: the `[channel]` scenario keys and their validation;
//! - [`models`]: the link models registered (kind, keys, docs, per-step loss, long-run loss);
//! - [`fate`]: the fate of every (sensor, step) slot of a trial (with ARQ, its attempts and
//!   acknowledgements), drawn once from the link's own random stream so that every scheme meets
//!   the same losses;
//! - [`route`]: the fates of multi-hop routes, every hop drawn, added up per sensor;
//! - [`stability`]: the classical stability checks of Kalman filtering with intermittent
//!   observations (Sinopoli et al. 2004), used to sanity-check a scenario's link.
pub mod fate;
pub mod models;
mod parse;
pub mod route;
pub mod spec;
pub mod stability;

pub use fate::{Fate, FateTable};
pub use spec::{resolve, Arq, ChannelKind, ChannelSpec, Delay, DelayKind, GeometricDelay};
