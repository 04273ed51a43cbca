//! Send-on-delta (level crossing): a sensor sends z_k when `||z_k - z_last||_∞ > δ`, z_last
//! being the last measurement it sent (the first measurement is always sent). No feedback.
//!
//! The center knows, on silence, that z_k lies in the box z_last ± δ. Two readings:
//!
//! - [`SilenceModel::Ignore`]: silence is no measurement (the plain send-on-delta KF: it
//!   throws the box away, so it stays consistent but its prediction drifts while a sensor
//!   is quiet).
//! - [`SilenceModel::Uniform`] (default): z_last = z_k + u with u uniform on the box,
//!   independent of x_k and of the noise — the uniform quantization-noise model, variance
//!   δ²/3 per component — read as the pseudo-measurement z_last with noise R + (δ²/3) I. An
//!   approximation: u is in truth neither independent nor uniform, but it keeps the KF linear
//!   and stops the prediction from drifting while a sensor is quiet.
//!
//! The knob is δ; δ = 0 sends every (continuous) measurement.
use super::{check_inbox, fuse, nonnegative, received_measurement, Evidence};
use crate::filter::{kf, Gaussian};
use crate::linalg::{Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::scheme::{
    Feedback, FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System,
};
use rand::RngCore;
use std::sync::Arc;

/// How the center reads a silence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SilenceModel {
    /// No measurement.
    Ignore,
    /// The last sent measurement with the extra noise δ²/3 per component.
    #[default]
    Uniform,
}

/// Sensor side: remembers the last measurement it sent.
#[derive(Debug, Clone)]
pub struct SendOnDeltaSensor {
    delta: f64,
    last_sent: Option<Vector>,
}

impl SendOnDeltaSensor {
    pub fn new(delta: f64) -> Result<Self, SchemeError> {
        Ok(Self {
            delta: nonnegative("delta", delta)?,
            last_sent: None,
        })
    }
}

impl SensorNode for SendOnDeltaSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        _feedback: Option<&Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        let send = match &self.last_sent {
            None => true,
            Some(last) => (z - last).amax() > self.delta,
        };
        if send {
            self.last_sent = Some(z.clone());
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Fusion side: a KF that remembers every sensor's last received measurement.
#[derive(Debug, Clone)]
pub struct SendOnDeltaCenter {
    system: Arc<System>,
    delta: f64,
    silence: SilenceModel,
    last_received: Vec<Option<Vector>>,
    est: Gaussian,
}

impl SendOnDeltaCenter {
    pub fn new(
        system: Arc<System>,
        delta: f64,
        silence: SilenceModel,
    ) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        let est = system.prior.clone();
        Ok(Self {
            last_received: vec![None; system.n_sensors()],
            system,
            delta,
            silence,
            est,
        })
    }

    /// R + (δ²/3) I, the noise of the uniform reading of a silence of sensor `i`.
    pub fn uniform_noise(&self, i: usize) -> Matrix {
        let r = self.system.sensors[i].noise_cov();
        r + Matrix::identity(r.nrows(), r.ncols()) * (self.delta * self.delta / 3.0)
    }
}

impl FusionCenter for SendOnDeltaCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        check_inbox(&self.system, inbox)?;
        let pred = kf::predict(&self.system.transition, &self.est);
        let mut evidence = Vec::with_capacity(inbox.len());
        for (i, msg) in inbox.iter().enumerate() {
            evidence.push(match (received_measurement(i, msg)?, msg) {
                (Some(z), _) => {
                    self.last_received[i] = Some(z.clone());
                    Evidence::Measurement(z.clone())
                }
                (None, Received::Silent) => match (self.silence, &self.last_received[i]) {
                    (SilenceModel::Uniform, Some(last)) => Evidence::Pseudo {
                        z: last.clone(),
                        r: self.uniform_noise(i),
                    },
                    _ => Evidence::Nothing,
                },
                (None, _) => Evidence::Nothing,
            });
        }
        self.est = fuse(&self.system, pred, &evidence)?;
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
}

/// The send-on-delta scheme.
#[derive(Debug, Clone)]
pub struct SendOnDeltaScheme {
    system: Arc<System>,
    delta: f64,
    silence: SilenceModel,
}

impl SendOnDeltaScheme {
    /// `delta` >= 0 (0: send everything).
    pub fn new(
        system: Arc<System>,
        delta: f64,
        silence: SilenceModel,
    ) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        Ok(Self {
            system,
            delta,
            silence,
        })
    }
}

impl Scheme for SendOnDeltaScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = (0..self.system.n_sensors())
            .map(|_| SendOnDeltaSensor::new(self.delta).map(|s| Box::new(s) as Box<dyn SensorNode>))
            .collect::<Result<_, _>>()?;
        Ok(SchemeInstance {
            sensors,
            center: Box::new(SendOnDeltaCenter::new(
                self.system.clone(),
                self.delta,
                self.silence,
            )?),
        })
    }
}
