//! Estimation without a center: every node runs a filter and talks only with its neighbours
//! over the network's graph ([`crate::network::graph`]), each exchange a real frame priced per
//! edge. One module per scheme, each citing its paper's equations.
pub mod consensus;
pub mod weights;
