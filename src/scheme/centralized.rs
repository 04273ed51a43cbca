//! Baselines: the centralized Kalman filter that receives raw measurements — all of them (the
//! bound every scheme is measured against), or each with probability `rate` (seed 004
//! Section V: a measurement not sent is lost for good).
use super::{FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System};
use crate::filter::information::Information;
use crate::filter::{kf, Gaussian};
use crate::linalg::Vector;
use crate::link::{Message, Received, Transmission};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// Sensor that forwards its raw measurement with probability `send_probability`.
#[derive(Debug, Clone)]
pub struct ForwardingSensor {
    send_probability: f64,
}

impl ForwardingSensor {
    /// `send_probability` = 1 forwards everything.
    pub fn new(send_probability: f64) -> Self {
        Self { send_probability }
    }
}

impl SensorNode for ForwardingSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        _feedback: Option<&super::Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        // Always draw, so the coin stream does not depend on the probability's value.
        let u: f64 = rng.random();
        if u < self.send_probability {
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Kalman filter on whatever measurements arrive. Linear sensors are fused in information
/// form, one sum per step (seed 004 Section II; eq. (8)-(9) for a subset); nonlinear sensors
/// by sequential EKF updates.
#[derive(Debug, Clone)]
pub struct CentralizedKf {
    system: Arc<System>,
    est: Gaussian,
}

impl CentralizedKf {
    pub fn new(system: Arc<System>) -> Self {
        let est = system.prior.clone();
        Self { system, est }
    }
}

impl FusionCenter for CentralizedKf {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let pred = kf::predict(&self.system.transition, &self.est);
        let all_linear = self.system.sensors.iter().all(|s| s.as_linear().is_some());
        if all_linear {
            let mut info = Information::from_gaussian(&pred)?;
            for (i, msg) in inbox.iter().enumerate() {
                if let Some(z) = measurement(i, msg)? {
                    let sensor = self.system.sensors[i].as_linear().expect("checked linear");
                    info.add_measurement(sensor, z)?;
                }
            }
            self.est = info.to_gaussian()?;
        } else {
            let mut e = pred;
            for (i, msg) in inbox.iter().enumerate() {
                if let Some(z) = measurement(i, msg)? {
                    e = kf::update(self.system.sensors[i].as_ref(), e, z)?;
                }
            }
            self.est = e;
        }
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
}

fn measurement(i: usize, msg: &Received) -> Result<Option<&Vector>, SchemeError> {
    match msg {
        Received::Measurement(z) => Ok(Some(z)),
        Received::Silent | Received::NotScheduled => Ok(None),
        other => Err(SchemeError::Protocol {
            sensor: i,
            message: format!("centralized KF expects measurements, got {other:?}"),
        }),
    }
}

/// Centralized KF whose sensors forward each measurement with probability `rate`
/// (`rate` = 1: the all-data bound).
#[derive(Debug, Clone)]
pub struct CentralizedScheme {
    system: Arc<System>,
    rate: f64,
}

impl CentralizedScheme {
    pub fn new(system: Arc<System>, rate: f64) -> Self {
        Self { system, rate }
    }
}

impl Scheme for CentralizedScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: (0..self.system.n_sensors())
                .map(|_| Box::new(ForwardingSensor::new(self.rate)) as Box<dyn SensorNode>)
                .collect(),
            center: Box::new(CentralizedKf::new(self.system.clone())),
        })
    }
}
