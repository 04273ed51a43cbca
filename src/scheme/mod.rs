//! A scheme is a sensor node + a fusion center + the network rule between them. One module per
//! paper; the simulator drives every scheme through the same loop on the same data.
pub mod centralized;
pub mod distributed_kf;

use crate::filter::{FilterError, Gaussian};
use crate::linalg::{LinalgError, Vector};
use crate::link::{Received, Transmission};
use crate::model::{LinearTransition, MeasurementModel};
use crate::network::Schedule;
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

/// What the fusion center sends back to sensors (seed 000's feedback modes, seed 003's
/// y_hat and Delta). Unused by schemes without feedback.
#[derive(Debug, Clone, PartialEq)]
pub struct Feedback {
    pub mean: Vector,
    pub cov: Option<crate::linalg::Matrix>,
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
}

/// Fresh per-trial state of a scheme.
pub struct SchemeInstance {
    pub sensors: Vec<Box<dyn SensorNode>>,
    pub center: Box<dyn FusionCenter>,
}

/// A configured scheme: builds fresh sensor nodes and a fusion center for each trial.
pub trait Scheme: Send + Sync + Debug {
    fn build(&self) -> Result<SchemeInstance, SchemeError>;
    /// Which sensors may talk at each step.
    fn schedule(&self) -> Schedule {
        Schedule::All
    }
}
