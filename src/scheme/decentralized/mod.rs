//! The decentralized schemes ([`crate::decentralized`]) as scenario files name them: every node
//! of the network's graph runs a filter and talks only with its neighbours, so there is no
//! sensor side and fusion center to build; the engine runs them on the graph instead
//! ([`Scheme::peers`]). Their entries ([`params`]) are listed apart from the center schemes
//! (`crate::scheme::DECENTRALIZED`): `every_scheme` does not add them to a star's arena.
pub mod params;

use super::{Scheme, SchemeError, SchemeInstance};
use crate::decentralized::trial::Peers;

/// A decentralized scheme: runs on the nodes of the graph, never as a sensor side and a center.
#[derive(Debug)]
pub struct Decentralized(pub Peers);

impl Scheme for Decentralized {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Err(SchemeError::Unsupported(
            "a decentralized scheme has no fusion center: it runs on the nodes of the network's graph".into(),
        ))
    }

    fn peers(&self) -> Option<&Peers> {
        Some(&self.0)
    }
}
