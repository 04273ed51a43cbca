//! A validated experiment: the system, the schemes' variants and the run's size, ready to run.
use crate::filter::Gaussian;
use crate::network::channel::ChannelSpec;
use crate::network::topology::Topology;
use crate::scenario::file::{FrontierSpec, PaperSpec, Params};
use crate::scheme::{Scheme, System};
use std::sync::Arc;

/// One scheme at one sweep point, ready to run.
#[derive(Debug)]
pub struct Variant {
    /// Index of the scheme entry in the file (a curve).
    pub curve: usize,
    /// Parameters of this point, as written (kind-specific numbers).
    pub params: Params,
    /// The scheme's `kind`, as registered.
    pub kind: &'static str,
    pub scheme: Box<dyn Scheme>,
    /// Each sensor's link for this variant: the entry's own `channel` (the same for every
    /// sensor), else the scenario's `[channel]` and the sensors' own; `None`: every link is
    /// ideal (the engine then runs exactly as without a channel).
    pub channel: Option<Arc<Vec<ChannelSpec>>>,
    /// Bits of the sequence number carried by every packet (`sequence_bits`, 0..=32; 0: none).
    /// Their bits are counted; what the link layer does with them is its own.
    pub sequence_bits: u32,
}

impl Variant {
    /// The one-hop star of this variant's links over `sensors` sensors (ideal where it has
    /// none), as a graph: sensor i linked to the sink over its channel.
    pub fn star(&self, sensors: usize) -> Topology {
        match self.channel.as_deref() {
            Some(channels) => Topology::star(channels),
            None => Topology::star(&vec![ChannelSpec::default(); sensors]),
        }
    }

    /// Whether the relays of `network` sum this variant's reports
    /// ([`crate::network::aggregate`]): a multi-hop network that aggregates, and a scheme whose
    /// reports may be summed.
    pub fn aggregated(&self, network: Option<&crate::network::topology::Topology>) -> bool {
        network.is_some_and(|n| n.aggregate) && self.scheme.aggregable()
    }
}

/// One `[[schemes]]` entry: a curve of one or more variants.
#[derive(Debug, Clone)]
pub struct Curve {
    pub label: String,
    pub kind: String,
    /// Names of the swept parameters (empty when not swept).
    pub swept: Vec<String>,
    pub frontier: Option<FrontierSpec>,
    /// What differs on this row from the others (`note = "..."`, e.g. a sensor the other
    /// schemes do not have): printed under the tables and kept in `summary.json`.
    pub note: Option<String>,
}

/// A validated experiment.
#[derive(Debug)]
pub struct Experiment {
    pub name: String,
    pub description: String,
    pub source: String,
    pub system: Arc<System>,
    /// Distribution of the true x_0 (the filters' prior unless the file says otherwise).
    pub initial_truth: Gaussian,
    pub groups: Vec<(String, Vec<usize>)>,
    pub curves: Vec<Curve>,
    pub variants: Vec<Variant>,
    pub trials: usize,
    pub steps: usize,
    pub seed: u64,
    /// First step (1-based) of the steady-state averages.
    pub steady_from: usize,
    pub paper: Option<PaperSpec>,
    /// Each sensor's link model from the scenario's `[channel]` and the sensors' own; `None`:
    /// every link is ideal. A scheme entry's own `channel` replaces it for that entry's variants:
    /// the engine reads [`Variant::channel`].
    pub channel: Option<Vec<ChannelSpec>>,
    /// The sensors' radio and battery (`[radio]`, validated; absent: the CC2420's values):
    /// what the summary prices the traffic with.
    pub radio: crate::network::radio::RadioSpec,
    /// The multi-hop network (`[network]`), whose sink is every scheme's center; `None` for
    /// the one-hop star (no `[network]`, or `edges = "star"` without links of its own).
    pub network: Option<Arc<crate::network::topology::Topology>>,
    /// How real numbers cross the network (`reals`; singles by default).
    pub reals: crate::link::Reals,
    /// The frames' 802.15.4 security (`[security]`; none by default): what each data frame and
    /// the step's feedback frame add on air.
    pub security: crate::link::security::SecuritySpec,
}

impl Experiment {
    /// The one-hop star of variant `v`'s sensor links ([`Variant::star`]) with the run's
    /// security.
    pub fn star_of(&self, v: &Variant) -> Topology {
        let mut star = v.star(self.system.n_sensors());
        star.security = self.security;
        star
    }

    /// The graph variant `v` runs on: the scenario's `[network]`; without one, for a
    /// decentralized scheme the star of its sensors' links (the sink a node without a sensor),
    /// for a center scheme `None` (the engine's one-hop star).
    pub fn graph_of(&self, v: &Variant) -> Option<std::borrow::Cow<'_, Topology>> {
        match (&self.network, v.scheme.peers()) {
            (Some(net), _) => Some(std::borrow::Cow::Borrowed(net.as_ref())),
            (None, Some(_)) => Some(std::borrow::Cow::Owned(self.star_of(v))),
            (None, None) => None,
        }
    }

    /// The radios that run on a battery: the sensors on a star; over a multi-hop network also
    /// the relays (and the sink unless it is on mains). What the energy axis counts.
    pub fn battery_radios(&self) -> usize {
        match &self.network {
            None => self.system.n_sensors(),
            Some(net) => net.nodes.len() - usize::from(net.sink_mains),
        }
    }
}
