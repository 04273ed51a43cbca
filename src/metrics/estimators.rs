//! A decentralized scheme's share of `summary.json`: every node estimates, so beside the
//! scheme's row (the mean over its nodes) each node's steady-state MSE and ANEES with their
//! Monte Carlo standard errors, its radio's energy, the worst node, and how far the nodes'
//! estimates are apart (the disagreement). From [`Sums::estimators`] and
//! [`Sums::disagreement`], per-trial values summed over trials (so they merge across threads,
//! checkpoints and shards like every other sum).
use crate::metrics::energy::EnergySummary;
use crate::metrics::network::NetworkSummary;
use crate::metrics::Sums;
use crate::network::topology::Topology;
use serde::{Deserialize, Serialize};

/// One node's estimate.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct EstimatorSummary {
    pub node: String,
    /// Steady-state mean squared error (all components) and its standard error.
    pub steady_mse: f64,
    pub steady_mse_se: f64,
    /// Steady-state mean NEES / state dimension and its standard error.
    pub anees: f64,
    pub anees_se: f64,
    /// Its radio's energy per step, µJ (as in `network.nodes`).
    pub energy_per_step_uj: f64,
}

/// Every node of a decentralized scheme.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct EstimatorsSummary {
    pub nodes: Vec<EstimatorSummary>,
    /// The node with the largest steady-state MSE.
    pub worst: EstimatorSummary,
    /// Steady-state mean over steps of (1/M) Σᵢ ‖x̂ᵢ − x̄‖² (x̄ the nodes' mean estimate): 0 when
    /// every node holds the same estimate. With its standard error.
    pub disagreement: f64,
    pub disagreement_se: f64,
}

/// A variant's energy, its network (over a `[network]`, or the graph a decentralized scheme
/// runs on) and its estimators ([`summarize`]).
pub fn of_variant(
    exp: &crate::scenario::build::Experiment,
    v: &crate::scenario::build::Variant,
    sums: &Sums,
) -> (
    EnergySummary,
    Option<NetworkSummary>,
    Option<EstimatorsSummary>,
) {
    let (energy, network) = crate::metrics::network::energy_and_network(exp, v, sums);
    let dim = exp.system.state_dim();
    let estimators = exp
        .graph_of(v)
        .and_then(|net| summarize(&net, sums, dim, network.as_ref()));
    (energy, network, estimators)
}

/// The estimators of a variant's `sums` on `net` (its nodes in order), `None` for a scheme with
/// one estimate; `network` gives each node's energy.
pub fn summarize(
    net: &Topology,
    sums: &Sums,
    state_dim: usize,
    network: Option<&NetworkSummary>,
) -> Option<EstimatorsSummary> {
    if sums.estimators.is_empty() {
        return None;
    }
    let n = state_dim.max(1) as f64;
    let nodes: Vec<EstimatorSummary> = sums
        .estimators
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let (mse, mse_se) = e.mse.mean_se(sums.trials);
            let (nees, nees_se) = e.nees.mean_se(sums.trials);
            EstimatorSummary {
                node: net.nodes.get(i).map_or(format!("#{i}"), |x| x.name.clone()),
                steady_mse: mse,
                steady_mse_se: mse_se,
                anees: nees / n,
                anees_se: nees_se / n,
                energy_per_step_uj: network
                    .and_then(|w| w.nodes.get(i))
                    .map_or(f64::NAN, |x| x.energy_per_step_uj),
            }
        })
        .collect();
    let worst = nodes
        .iter()
        .max_by(|a, b| a.steady_mse.total_cmp(&b.steady_mse))
        .cloned()
        .expect("not empty");
    let (disagreement, disagreement_se) = sums.disagreement.mean_se(sums.trials);
    Some(EstimatorsSummary {
        nodes,
        worst,
        disagreement,
        disagreement_se,
    })
}
