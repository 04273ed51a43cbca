//! A scheme is a sensor node + a fusion center + the network rule between them. One module per
//! paper; the simulator drives every scheme through the same loop on the same data.
pub mod censored_pf;
pub mod centralized;
pub mod decentralized;
pub mod distributed_kf;
pub mod estimate_fusion;
pub mod event_triggered;
pub mod external;
pub mod fast_path;
pub mod federated_tobit;
pub mod link_loss;
pub mod quantized_innovation;
pub mod registry;

/// Every scheme kind, in the order `hushfuse list-schemes` prints them: the one list of
/// schemes. Adding a scheme = its module (declared above) + one line here.
pub const SCHEMES: &[registry::SchemeEntry] = &[
    centralized::params::ALL,
    centralized::params::RANDOM,
    distributed_kf::params::FULL_RATE,
    distributed_kf::params::ALG1_RANDOM,
    distributed_kf::params::ALG1_EVENT,
    distributed_kf::params::ALG2_EVENT,
    quantized_innovation::params::ENTRY,
    censored_pf::params::ENTRY,
    federated_tobit::params::ENTRY,
    federated_tobit::params::ROUND_ROBIN_KF,
    federated_tobit::exact_pf::ENTRY,
    event_triggered::params::INNOVATION,
    event_triggered::params::STOCHASTIC_OPEN,
    event_triggered::params::STOCHASTIC_CLOSED,
    event_triggered::params::SEND_ON_DELTA,
    estimate_fusion::params::CI,
    estimate_fusion::params::NAIVE,
];

/// The decentralized schemes ([`crate::decentralized`]): every node of a `[network]`
/// estimates. Found by kind as [`SCHEMES`] are, but not run by `every_scheme` (they need a
/// network of their own).
pub const DECENTRALIZED: &[registry::SchemeEntry] = &[
    decentralized::params::CONSENSUS_INFORMATION,
    decentralized::params::CONSENSUS_MEASUREMENTS,
    decentralized::params::CONSENSUS_HYBRID,
    decentralized::params::INFORMATION_WEIGHTED,
    decentralized::params::KALMAN_CONSENSUS,
    decentralized::params::DIFFUSION,
    decentralized::params::PEER_CI,
    decentralized::params::PEER_ICI,
    decentralized::params::PEER_NAIVE,
    decentralized::params::CHANNEL_FILTER,
    decentralized::params::ET_DDF,
];

use crate::filter::{FilterError, Gaussian};
use crate::linalg::{LinalgError, Vector};
use crate::link::{Received, Transmission};
use crate::model::{LinearTransition, MeasurementModel};
use crate::network::Schedule;
use fast_path::LockstepFastPath;
use rand::RngCore;
use std::fmt::Debug;
use std::sync::Arc;

/// The system every scheme estimates: motion model, sensors and the prior of x_0.
#[derive(Debug, Clone)]
pub struct System {
    pub transition: LinearTransition,
    pub sensors: Vec<Arc<dyn MeasurementModel>>,
    pub prior: Gaussian,
}

impl System {
    /// Number of sensors.
    pub fn n_sensors(&self) -> usize {
        self.sensors.len()
    }
    /// State dimension.
    pub fn state_dim(&self) -> usize {
        self.transition.dim()
    }
}

/// What the fusion center sends back to sensors before they measure. Unused by schemes
/// without feedback. Its bits are counted as downlink traffic.
#[derive(Debug, Clone, PartialEq)]
pub enum Feedback {
    /// The fused prediction, with its covariance or not (Zheng et al.'s (2014) CFwMD / CFwMD2).
    Prediction {
        mean: Vector,
        cov: Option<crate::linalg::Matrix>,
    },
    /// Per sensor: the predicted measurement y_hat and the innovation standard deviation Delta
    /// of Zhang et al. (2016), eq. (2), for activated sensors; `None` for the others.
    InnovationReference(Vec<Option<InnovationReference>>),
}

/// Zhang et al. (2016), eq. (2): y_hat = h x_{k|k-1}, Delta = sqrt(h P h^T + R).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InnovationReference {
    pub y_hat: f64,
    pub delta: f64,
}

impl Feedback {
    /// Downlink bits, 32 per real number: a prediction is broadcast once to all sensors
    /// (the covariance as its n(n+1)/2 distinct entries); y_hat and Delta go to each
    /// activated sensor.
    pub fn bits(&self, _n_sensors: usize) -> u64 {
        let c = crate::link::BITS_PER_COMPONENT;
        match self {
            Feedback::Prediction { mean, cov } => {
                let n = mean.len() as u64;
                (n + cov.as_ref().map_or(0, |_| n * (n + 1) / 2)) * c
            }
            Feedback::InnovationReference(refs) => {
                refs.iter().filter(|r| r.is_some()).count() as u64 * 2 * c
            }
        }
    }

    /// The feedback as the sensors receive it: every real number as the single that
    /// [`Feedback::bits`] prices ([`crate::link::as_sent`]), as a downlink frame carries it.
    pub fn as_sent(&self) -> Feedback {
        self.clone().into_sent()
    }

    /// [`Feedback::as_sent`], rounding in place (no copy).
    pub fn into_sent(mut self) -> Feedback {
        use crate::link::{as_sent, round_as_sent};
        match &mut self {
            Feedback::Prediction { mean, cov } => {
                round_as_sent(mean.as_mut_slice());
                if let Some(c) = cov {
                    round_as_sent(c.as_mut_slice());
                }
            }
            Feedback::InnovationReference(refs) => {
                for r in refs.iter_mut().flatten() {
                    r.y_hat = as_sent(r.y_hat);
                    r.delta = as_sent(r.delta);
                }
            }
        }
        self
    }
}

/// Why a scheme could not be built or could not take a step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SchemeError {
    #[error(transparent)]
    Filter(#[from] FilterError),
    #[error("{what}: {source}")]
    Matrix {
        what: &'static str,
        source: LinalgError,
    },
    #[error("{0}")]
    Unsupported(String),
    /// A constructor argument out of its range; `field` is the parameter's name in scenario
    /// files, so the scenario layer can point at it.
    #[error("{message}")]
    Invalid {
        field: &'static str,
        message: String,
    },
    #[error("sensor {sensor}: {message}")]
    Protocol { sensor: usize, message: String },
    #[error(
        "step {k} is beyond the precomputed horizon {horizon} and the recursion had not converged"
    )]
    HorizonExceeded { k: usize, horizon: usize },
}

/// The sensor side of a scheme: local filtering and the decision what (if anything) to send.
/// It owns its local filter state and does one step per call.
pub trait SensorNode: Send {
    /// Processes measurement `z` of step `k` (k >= 1), with the fusion center's feedback of
    /// step k-1 if the scheme has feedback, and returns what the sensor transmits.
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError>;
}

/// The fusion side of a scheme: fuses what arrived and what the silences say.
pub trait FusionCenter: Send {
    /// Fuses the inbox of step `k` (one entry per sensor, in sensor order).
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError>;
    /// The fused estimate after the last step (the prior before the first).
    fn estimate(&self) -> &Gaussian;
    /// Feedback to the sensors for the next step, if the scheme has any.
    fn feedback(&self) -> Option<Feedback> {
        None
    }
    /// Effective sample size `1 / sum w_i^2` of the particle weights after the last step's
    /// update and before any resampling (so a cloud that collapses onto a few particles shows
    /// even if it is resampled at once). `None` for centers that are not particle filters.
    fn ess(&self) -> Option<f64> {
        None
    }
    /// Fuses step `k` from the information its sensors' reports add up to, summed inside the
    /// network ([`crate::network::aggregate`]: Σ H_i^T R_i^{-1} H_i and Σ H_i^T R_i^{-1} z_i over
    /// the reports that reached the sink; `None` when none did). Only the centers of schemes
    /// that are [`Scheme::aggregable`] take it.
    fn fuse_information(
        &mut self,
        k: usize,
        sum: Option<&crate::filter::information::Information>,
    ) -> Result<(), SchemeError> {
        let _ = (k, sum);
        Err(SchemeError::Unsupported(
            "this fusion center cannot fuse an aggregated information sum".into(),
        ))
    }
}

/// Fresh per-trial state of a scheme.
pub struct SchemeInstance {
    pub sensors: Vec<Box<dyn SensorNode>>,
    pub center: Box<dyn FusionCenter>,
}

/// A configured scheme: builds fresh sensor nodes and a fusion center for each trial.
pub trait Scheme: Send + Sync + Debug {
    fn build(&self) -> Result<SchemeInstance, SchemeError>;
    /// Like [`Scheme::build`], for fusion centers that draw random numbers (particle
    /// filters): they seed their own generator from `seed`, so results stay reproducible.
    fn build_with_seed(&self, seed: u64) -> Result<SchemeInstance, SchemeError> {
        let _ = seed;
        self.build()
    }
    /// Like [`Scheme::build_with_seed`], for trial `trial` of a run (the engine's call): schemes
    /// whose nodes want to know their trial (external schemes, for their error messages) take
    /// it here. By default [`Scheme::build_with_seed`].
    fn build_for_trial(&self, trial: usize, seed: u64) -> Result<SchemeInstance, SchemeError> {
        let _ = trial;
        self.build_with_seed(seed)
    }
    /// Whether the reports of this scheme may be summed inside a multi-hop network
    /// ([`crate::network::aggregate`]): raw measurements of linear sensors whose center needs
    /// only their information sum ([`FusionCenter::fuse_information`]). Reports whose silences or
    /// codes mean something are never merged.
    fn aggregable(&self) -> bool {
        false
    }
    /// Which sensors may talk at each step.
    fn schedule(&self) -> Schedule {
        Schedule::All
    }
    /// Whether the scheme keeps a plan of per-step matrices for the run's horizon, shared by its
    /// instances (the covariance recursions of the linear sensors, computed once for every
    /// trial): the memory estimate counts [`crate::scenario::limits::plans`] for it.
    fn keeps_step_plan(&self) -> bool {
        false
    }
    /// What one instance costs beyond the Kalman-filter baseline that the simulator assumes for
    /// every scheme (particles, banks of filters), so that runs that cannot fit are refused
    /// before they start. `None`: nothing beyond the baseline.
    fn footprint(&self) -> Option<Footprint> {
        None
    }
    /// The engine's hook for a lockstep fast path ([`LockstepFastPath`]); `None`: the engine
    /// runs the generic per-step loop. A scheme author never needs it.
    fn fast_path(&self) -> Option<&dyn LockstepFastPath> {
        None
    }
    /// A decentralized scheme: no sensor side and center to build; the engine runs its nodes
    /// on the network's graph ([`crate::decentralized::trial`]). `None` for a center scheme.
    fn peers(&self) -> Option<&crate::decentralized::trial::Peers> {
        None
    }
}

/// Rough resources of one scheme instance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Footprint {
    /// Bytes the instance holds while it runs.
    pub bytes: f64,
    /// Floating-point operations per time step.
    pub flops_per_step: f64,
}
