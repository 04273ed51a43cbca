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

pub mod params;

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
    /// `rate` in (0, 1]: the probability that each measurement is forwarded.
    pub fn new(system: Arc<System>, rate: f64) -> Result<Self, SchemeError> {
        if !(rate > 0.0 && rate <= 1.0) {
            return Err(SchemeError::Invalid {
                field: "rate",
                message: format!("expected a rate in (0, 1], got {rate}"),
            });
        }
        Ok(Self { system, rate })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::{matrix_from_rows, relative_difference, Matrix};
    use crate::model::{presets, LinearSensor, MeasurementModel};

    /// A linear sensor that hides its linearity, so filters take the EKF path (Jacobian at
    /// the prediction, sequential updates).
    #[derive(Debug)]
    struct Opaque(LinearSensor);
    impl MeasurementModel for Opaque {
        fn state_dim(&self) -> usize {
            self.0.state_dim()
        }
        fn meas_dim(&self) -> usize {
            self.0.meas_dim()
        }
        fn predict(&self, x: &Vector) -> Vector {
            self.0.predict(x)
        }
        fn jacobian(&self, x: &Vector) -> Matrix {
            self.0.jacobian(x)
        }
        fn noise_cov(&self) -> &Matrix {
            self.0.noise_cov()
        }
        fn noise_sqrt(&self) -> &Matrix {
            self.0.noise_sqrt()
        }
    }

    /// The EKF on a linear model equals the KF (information-form fusion).
    #[test]
    fn ekf_on_a_linear_model_equals_the_kf() {
        let transition = presets::constant_velocity_2d(0.5, 1.0).unwrap();
        let a = LinearSensor::new(
            matrix_from_rows(&[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]]),
            Matrix::identity(2, 2) * 2.0,
        )
        .unwrap();
        let b = LinearSensor::new(
            matrix_from_rows(&[vec![0.3, 1.0, 0.0, 0.2]]),
            Matrix::from_element(1, 1, 0.5),
        )
        .unwrap();
        let prior = Gaussian::new(
            Vector::from_vec(vec![1.0, 0.0, -1.0, 0.5]),
            Matrix::identity(4, 4) * 3.0,
        );
        let linear = Arc::new(System {
            transition: transition.clone(),
            sensors: vec![Arc::new(a.clone()), Arc::new(b.clone())],
            prior: prior.clone(),
        });
        let opaque = Arc::new(System {
            transition,
            sensors: vec![Arc::new(Opaque(a)), Arc::new(Opaque(b))],
            prior,
        });
        let mut kf = CentralizedKf::new(linear);
        let mut ekf = CentralizedKf::new(opaque);
        for k in 1..=30 {
            let t = k as f64;
            let inbox = vec![
                Received::Measurement(Vector::from_vec(vec![t.sin(), 0.5 * t])),
                if k % 3 == 0 {
                    Received::Silent
                } else {
                    Received::Measurement(Vector::from_element(1, 0.1 * t))
                },
            ];
            kf.step(k, &inbox).unwrap();
            ekf.step(k, &inbox).unwrap();
            assert!(relative_difference(&kf.estimate().cov, &ekf.estimate().cov) < 1e-10);
            assert!((&kf.estimate().mean - &ekf.estimate().mean).amax() < 1e-9);
        }
    }
}
