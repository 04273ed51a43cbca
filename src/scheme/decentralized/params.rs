//! Scenario-file parameters of the decentralized schemes, and their registry entries. Each
//! entry builds a [`Peers`] from the scenario's linear model (every node knows A, Q, the prior
//! and the (H, R) of the sensors it hears); what depends on the graph (weights given by hand,
//! the channel filter's tree) is checked when the network is known
//! ([`crate::decentralized::trial::Peers::check`]).
use super::Decentralized;
use crate::decentralized::diffusion::Order;
use crate::decentralized::peer_fusion::Rule;
use crate::decentralized::trial::{FusionKind, PeerKind, Peers, MAX_ITERATIONS};
use crate::decentralized::weights::WeightRule;
use crate::decentralized::Model;
use crate::scheme::registry::{
    self, Applies, Bound, BuildContext, Direction, Knob, ParamDoc, ParamError, Scale, SchemeEntry,
};
use crate::scheme::Scheme;
use serde::Deserialize;

/// `weights`: a rule by name or the matrix by hand.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
enum WeightsParam {
    Rule(RuleName),
    Given(Vec<Vec<f64>>),
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
enum RuleName {
    Metropolis,
    MaxDegree,
}

impl WeightsParam {
    fn rule(self) -> WeightRule {
        match self {
            WeightsParam::Rule(RuleName::Metropolis) => WeightRule::MetropolisHastings,
            WeightsParam::Rule(RuleName::MaxDegree) => WeightRule::MaxDegree,
            WeightsParam::Given(w) => WeightRule::Given(w),
        }
    }
}

/// The consensus family's parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConsensusParams {
    /// Consensus iterations a step.
    #[serde(rename = "L")]
    iterations: usize,
    #[serde(default)]
    weights: Option<WeightsParam>,
    #[serde(default)]
    omega: Option<f64>,
}

/// Consensus on information and the ICF: no ω (CI runs on the corrected pair; the ICF has
/// ω = N by construction).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct IterationParams {
    #[serde(rename = "L")]
    iterations: usize,
    #[serde(default)]
    weights: Option<WeightsParam>,
}

/// `kalman-consensus`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct KalmanConsensusParams {
    #[serde(default)]
    gamma: Option<f64>,
}

/// `diffusion-kf`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct DiffusionParams {
    #[serde(default)]
    order: OrderName,
    #[serde(default)]
    weights: Option<WeightsParam>,
    #[serde(default)]
    threshold: Option<f64>,
}

#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum OrderName {
    #[default]
    Atc,
    Cta,
}

/// `et-ddf`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct EtDdfParams {
    delta: f64,
    #[serde(default)]
    tau: Option<f64>,
}

/// The schemes without parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

/// The model every node knows, from the scenario's system (linear sensors only).
fn peers(cx: &BuildContext, kind: PeerKind) -> Result<Box<dyn Scheme>, ParamError> {
    let system = cx.system;
    let sensors = system
        .sensors
        .iter()
        .enumerate()
        .map(|(i, s)| {
            s.as_linear()
                .map(|l| (l.h().clone(), s.noise_cov().clone()))
                .ok_or_else(|| {
                    ParamError::whole(format!(
                        "the decentralized schemes need linear sensors (z = H x + v); sensor {i} is not"
                    ))
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let model = Model {
        a: system.transition.f().clone(),
        q: system.transition.q().clone(),
    };
    Ok(Box::new(Decentralized(Peers {
        kind,
        model,
        prior: system.prior.clone(),
        sensors,
    })))
}

fn check_iterations(l: usize) -> Result<(), ParamError> {
    if l == 0 || l > MAX_ITERATIONS {
        return Err(ParamError::at(
            "L",
            format!(
                "L = {l}: expected 1..={MAX_ITERATIONS} consensus iterations a step (L = 0 is no consensus: each node its own filter)"
            ),
        ));
    }
    Ok(())
}

fn check_omega(omega: Option<f64>) -> Result<(), ParamError> {
    match omega {
        Some(w) if !(w.is_finite() && w > 0.0) => Err(ParamError::at(
            "omega",
            format!("omega = {w}: expected a positive number (default: the number of nodes N)"),
        )),
        _ => Ok(()),
    }
}

fn consensus(
    cx: &BuildContext,
    fusion: FusionKind,
    (iterations, weights, omega): (usize, Option<WeightsParam>, Option<f64>),
    default: RuleName,
) -> Result<Box<dyn Scheme>, ParamError> {
    check_iterations(iterations)?;
    check_omega(omega)?;
    let weights = weights.unwrap_or(WeightsParam::Rule(default)).rule();
    peers(
        cx,
        PeerKind::Consensus {
            fusion,
            weights,
            iterations,
            omega,
        },
    )
}

fn build_ci(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: IterationParams = registry::parse(t)?;
    let knobs = (p.iterations, p.weights, None);
    consensus(cx, FusionKind::Information, knobs, RuleName::Metropolis)
}

fn build_cm(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: ConsensusParams = registry::parse(t)?;
    let knobs = (p.iterations, p.weights, p.omega);
    consensus(cx, FusionKind::Measurements, knobs, RuleName::Metropolis)
}

fn build_hybrid(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: ConsensusParams = registry::parse(t)?;
    let knobs = (p.iterations, p.weights, p.omega);
    consensus(cx, FusionKind::Hybrid, knobs, RuleName::Metropolis)
}

/// Kamal et al.'s ICF: the hybrid with ω = N ([`crate::decentralized::consensus::Fusion::information_weighted`]) on max-degree
/// weights by default.
fn build_icf(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: IterationParams = registry::parse(t)?;
    let knobs = (p.iterations, p.weights, None);
    consensus(cx, FusionKind::Hybrid, knobs, RuleName::MaxDegree)
}

fn build_kcf(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: KalmanConsensusParams = registry::parse(t)?;
    if let Some(g) = p.gamma.filter(|g| !(g.is_finite() && *g >= 0.0)) {
        return Err(ParamError::at(
            "gamma",
            format!("gamma = {g}: expected a finite gain >= 0"),
        ));
    }
    peers(cx, PeerKind::KalmanConsensus { gamma: p.gamma })
}

fn build_diffusion(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: DiffusionParams = registry::parse(t)?;
    if let Some(tau) = p.threshold {
        if !(tau.is_finite() && tau >= 0.0) {
            return Err(ParamError::at(
                "threshold",
                format!("threshold = {tau}: expected a finite number >= 0"),
            ));
        }
    }
    let order = match p.order {
        OrderName::Atc => Order::AdaptThenCombine,
        OrderName::Cta => Order::CombineThenAdapt,
    };
    let weights = p
        .weights
        .unwrap_or(WeightsParam::Rule(RuleName::Metropolis))
        .rule();
    peers(
        cx,
        PeerKind::Diffusion {
            order,
            weights,
            threshold: p.threshold,
        },
    )
}

fn build_et_ddf(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    let p: EtDdfParams = registry::parse(t)?;
    if !(p.delta.is_finite() && p.delta >= 0.0) {
        let d = p.delta;
        return Err(ParamError::at(
            "delta",
            format!("delta = {d}: expected a finite number >= 0"),
        ));
    }
    if let Some(tau) = p.tau.filter(|t| !(t.is_finite() && *t >= 0.0)) {
        return Err(ParamError::at(
            "tau",
            format!("tau = {tau}: expected a finite number >= 0"),
        ));
    }
    peers(
        cx,
        PeerKind::EventTriggered {
            delta: p.delta,
            tau: p.tau,
        },
    )
}

fn no_params(
    t: toml::Table,
    cx: &BuildContext,
    kind: PeerKind,
) -> Result<Box<dyn Scheme>, ParamError> {
    let _: NoParams = registry::parse(t)?;
    peers(cx, kind)
}

fn build_peer_ci(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    no_params(t, cx, PeerKind::PeerFusion(Rule::CovarianceIntersection))
}

fn build_peer_ici(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    no_params(
        t,
        cx,
        PeerKind::PeerFusion(Rule::InverseCovarianceIntersection),
    )
}

fn build_peer_naive(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    no_params(t, cx, PeerKind::PeerFusion(Rule::Naive))
}

fn build_channel_filter(t: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    no_params(t, cx, PeerKind::ChannelFilter)
}

const L: ParamDoc = ParamDoc {
    name: "L",
    values: "integer in 1..=10000",
    default: "required",
    meaning: "consensus iterations a step (each one broadcast of every node)",
};

const WEIGHTS: ParamDoc = ParamDoc {
    name: "weights",
    values: "\"metropolis\" | \"max-degree\" | [[w_ij, ...], ...]",
    default: "\"metropolis\"",
    meaning: "consensus weights: Metropolis-Hastings, max-degree, or a symmetric doubly stochastic matrix on the graph's edges (nodes in order s0.., r0.., sink)",
};

const WEIGHTS_MAX_DEGREE: ParamDoc = ParamDoc {
    default: "\"max-degree\"",
    ..WEIGHTS
};

const OMEGA: ParamDoc = ParamDoc {
    name: "omega",
    values: "number > 0",
    default: "N (the number of nodes)",
    meaning: "the weight of the consensus on the novel information in the correction",
};

/// The consensus iterations as the bandwidth knob: more iterations, more frames.
const ITERATIONS: Knob = Knob {
    name: "L",
    lo: Bound::Fixed(1.0),
    hi: Bound::Fixed(1000.0),
    scale: Scale::Linear,
    integer: true,
    grows: Direction::MoreBits,
};

const MISSING: &str = "a neighbour's broadcast that did not arrive: the node's own value takes its weight (the row stays stochastic)";

pub const CONSENSUS_INFORMATION: SchemeEntry = SchemeEntry {
    kind: "consensus-information",
    label: "Consensus on information (Battistelli & Chisci)",
    summary: "every node corrects with its reading, then L consensus iterations on the information pair (Omega, q) with its neighbours; consistent for any L (Battistelli & Chisci, Automatica 2014)",
    params: &[L, WEIGHTS],
    knob: Some(ITERATIONS),
    applies: Applies::LinearSensors,
    build: build_ci,
    example: "L = 5",
    missing_packet: MISSING,
};

pub const CONSENSUS_MEASUREMENTS: SchemeEntry = SchemeEntry {
    kind: "consensus-measurements",
    label: "Consensus on measurements (Battistelli et al.)",
    summary: "L consensus iterations on the novel information (U, u), then Omega = Omega- + omega U; the all-data KF as L grows with omega = N (Battistelli et al., IEEE TAC 2015)",
    params: &[L, WEIGHTS, OMEGA],
    knob: Some(ITERATIONS),
    applies: Applies::LinearSensors,
    build: build_cm,
    example: "L = 5",
    missing_packet: MISSING,
};

pub const CONSENSUS_HYBRID: SchemeEntry = SchemeEntry {
    kind: "consensus-hybrid",
    label: "Hybrid consensus HCMCI (Battistelli et al.)",
    summary: "L consensus iterations on the prior and on the novel information, then Omega = Omega-(L) + omega U(L) (Battistelli et al., IEEE TAC 2015)",
    params: &[L, WEIGHTS, OMEGA],
    knob: Some(ITERATIONS),
    applies: Applies::LinearSensors,
    build: build_hybrid,
    example: "L = 5",
    missing_packet: MISSING,
};

pub const INFORMATION_WEIGHTED: SchemeEntry = SchemeEntry {
    kind: "information-weighted-consensus",
    label: "Information-weighted consensus ICF (Kamal et al.)",
    summary: "Kamal, Farrell & Roy-Chowdhury's ICF (IEEE TAC 2013): consensus on J-/N + U, scaled back by N; the hybrid with omega = N on max-degree weights",
    params: &[L, WEIGHTS_MAX_DEGREE],
    knob: Some(ITERATIONS),
    applies: Applies::LinearSensors,
    build: build_icf,
    example: "L = 5",
    missing_packet: MISSING,
};

pub const KALMAN_CONSENSUS: SchemeEntry = SchemeEntry {
    kind: "kalman-consensus",
    label: "Kalman consensus filter (Olfati-Saber)",
    summary: "each node's Kalman update plus a pull gamma P / (1 + ||P||) toward its neighbours' predictions, one exchange a step (Olfati-Saber, CDC 2009)",
    params: &[ParamDoc {
        name: "gamma",
        values: "number >= 0",
        default: "1 / (1 + max degree)",
        meaning: "consensus gain (below 1 / max degree the pull cannot overshoot)",
    }],
    knob: None,
    applies: Applies::LinearSensors,
    build: build_kcf,
    example: "",
    missing_packet: "a neighbour's prediction that did not arrive is left out of the pull",
};

pub const DIFFUSION: SchemeEntry = SchemeEntry {
    kind: "diffusion-kf",
    label: "Diffusion KF (Cattivelli & Sayed)",
    summary: "adapt with the neighbourhood's measurements, combine the neighbours' estimates (Cattivelli & Sayed, IEEE TAC 2010); with a threshold, event-triggered on tr(P-) (Alanwar et al., ICCPS 2020)",
    params: &[
        ParamDoc {
            name: "order",
            values: "\"atc\" | \"cta\"",
            default: "\"atc\"",
            meaning: "adapt-then-combine (3 rounds, 2 exchanges) or combine-then-adapt (2 rounds, 1 exchange)",
        },
        WEIGHTS,
        ParamDoc {
            name: "threshold",
            values: "number >= 0",
            default: "none (always exchange)",
            meaning: "a node exchanges only at steps where tr(P-) > threshold",
        },
    ],
    knob: Some(Knob::threshold("threshold")),
    applies: Applies::LinearSensors,
    build: build_diffusion,
    example: "",
    missing_packet: "a neighbour's message that did not arrive: its measurement is left out, its weight goes to the node itself",
};

pub const ET_DDF: SchemeEntry = SchemeEntry {
    kind: "et-ddf",
    label: "Event-triggered DDF (et-ddf, Loefgren & Ahmed)",
    summary: "every node runs a KF; a sensor shares a reading element only when it is more than delta from what its neighbours predict, and the neighbours read its silence by an implicit (truncated-Gaussian) update; covariance intersection with the neighbours when tr(P) > tau (COHRINT's et-ddf; Dagan & Ahmed)",
    params: &[
        ParamDoc {
            name: "delta",
            values: "number >= 0 (measurement units)",
            default: "required",
            meaning: "send an element when |z - h x_shared| > delta (0: send every element)",
        },
        ParamDoc {
            name: "tau",
            values: "number >= 0",
            default: "none (no covariance intersection)",
            meaning: "a node whose tr(P) exceeds tau asks its neighbours for covariance intersection",
        },
    ],
    knob: Some(Knob::threshold("delta")),
    applies: Applies::LinearSensors,
    build: build_et_ddf,
    example: "delta = 1.0",
    missing_packet: "a lost frame is read as silence: the implicit update instead of the explicit one, and the receiver's replica of the sender's shared filter drifts",
};

const PEER_MISSING: &str = "a neighbour's estimate that did not arrive is left out of the fusion";

pub const PEER_CI: SchemeEntry = SchemeEntry {
    kind: "peer-ci",
    label: "Peers + covariance intersection (Julier & Uhlmann)",
    summary: "every node runs its local KF and fuses its neighbours' broadcast estimates by covariance intersection (determinant-minimizing weights): consistent on any graph",
    params: &[],
    knob: None,
    applies: Applies::LinearSensors,
    build: build_peer_ci,
    example: "",
    missing_packet: PEER_MISSING,
};

pub const PEER_ICI: SchemeEntry = SchemeEntry {
    kind: "peer-inverse-ci",
    label: "Peers + inverse covariance intersection (Noack et al.)",
    summary: "as peer-ci with inverse covariance intersection (Noack et al., 2017): less conservative, consistent on any graph",
    params: &[],
    knob: None,
    applies: Applies::LinearSensors,
    build: build_peer_ici,
    example: "",
    missing_packet: PEER_MISSING,
};

pub const PEER_NAIVE: SchemeEntry = SchemeEntry {
    kind: "peer-naive",
    label: "Peers + naive fusion (data incest)",
    summary: "as peer-ci adding the neighbours' informations as if independent: overconfident on graphs with loops (the counterexample)",
    params: &[],
    knob: None,
    applies: Applies::LinearSensors,
    build: build_peer_naive,
    example: "",
    missing_packet: PEER_MISSING,
};

pub const CHANNEL_FILTER: SchemeEntry = SchemeEntry {
    kind: "channel-filter",
    label: "Channel filter (Grime & Durrant-Whyte)",
    summary: "information filters on a tree that subtract what each link already carried (Grime & Durrant-Whyte 1994): the all-data KF on a tree of lossless links",
    params: &[],
    knob: None,
    applies: Applies::LinearSensors,
    build: build_channel_filter,
    example: "",
    missing_packet: "refused: the channel filter needs lossless links",
};
