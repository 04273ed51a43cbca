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
//!
//! **Loss-aware center (beyond the published rule).** Under a lossy link the sensor's reference
//! (its last *sent* value) and the center's (its last *received* value) part after a lost
//! send, and the center cannot know the sensor's: the sensor keeps its last sent value as
//! reference (no acknowledgement; the rule is unchanged), and the center's band stays around
//! its last received value (it has nothing to widen it with). With `link_loss` = p > 0 the
//! center carries per sensor the probability q that the two references are still the same,
//! and reads "nothing arrived" as the mixture of the uniform reading (weight ∝ q P_in, P_in the
//! predictive probability of the band), the prior conditioned on the reading outside the band
//! (sent and lost, weight ∝ q p (1 - P_in)) and no information (stale reference), moment-matched
//! ([`loss_aware::SendOnDeltaMixture`], where the weights and approximations are written out);
//! the received measurements are fused first, then each silence in sensor order. With
//! `silence = "ignore"` a silence is no measurement already, which a loss does not make wrong:
//! `link_loss` changes nothing there.
use super::{check_inbox, loss_aware, nonnegative, received_measurement, Evidence, Fusion};
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

/// Sensor side: remembers the last measurement it sent. A step allocates only the message it
/// sends once its buffers have the measurement's dimension (the scheme makes them so).
#[derive(Debug, Clone)]
pub struct SendOnDeltaSensor {
    delta: f64,
    /// The last measurement sent, valid when `sent`.
    last_sent: Vector,
    sent: bool,
    /// z_k - z_last.
    diff: Vector,
}

impl SendOnDeltaSensor {
    pub fn new(delta: f64) -> Result<Self, SchemeError> {
        Ok(Self {
            delta: nonnegative("delta", delta)?,
            last_sent: Vector::zeros(0),
            sent: false,
            diff: Vector::zeros(0),
        })
    }

    /// The buffers made for measurements of dimension `m` now rather than at the first step.
    fn with_dim(mut self, m: usize) -> Self {
        self.last_sent = Vector::zeros(m);
        self.diff = Vector::zeros(m);
        self
    }
}

/// `dst = src`, in `dst`'s storage when it has `src`'s dimension.
fn assign(dst: &mut Vector, src: &Vector) {
    if dst.len() == src.len() {
        dst.copy_from(src);
    } else {
        *dst = src.clone();
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
        let send = !self.sent || {
            // (z - z_last).amax(), the difference in the buffer.
            assign(&mut self.diff, z);
            self.diff -= &self.last_sent;
            self.diff.amax() > self.delta
        };
        if send {
            assign(&mut self.last_sent, z);
            self.sent = true;
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Fusion side: a KF that remembers every sensor's last received measurement. A step
/// allocates nothing (linear sensors): the measurements are remembered and the prediction
/// formed in buffers, and the uniform silence noise is fixed, so [`Fusion`] inverts it once.
#[derive(Debug, Clone)]
pub struct SendOnDeltaCenter {
    system: Arc<System>,
    delta: f64,
    silence: SilenceModel,
    /// Per sensor, the last received measurement, valid when `received`.
    last_received: Vec<Vector>,
    received: Vec<bool>,
    /// Per sensor, [`uniform_noise`](Self::uniform_noise).
    uniform: Vec<Matrix>,
    est: Gaussian,
    /// `kf::predict` of the estimate, per step.
    pred: Gaussian,
    predict_work: kf::PredictWork,
    fusion: Fusion,
    /// The fused estimate of a step, swapped into `est` when the step succeeds.
    out: Gaussian,
    /// The loss-aware reading (uniform model, p > 0) and, per sensor, the probability q that
    /// its reference is the last received value; `None`: the published center.
    loss: Option<(Vec<loss_aware::SendOnDeltaMixture>, Vec<f64>)>,
}

impl SendOnDeltaCenter {
    pub fn new(
        system: Arc<System>,
        delta: f64,
        silence: SilenceModel,
    ) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        let est = system.prior.clone();
        let n = est.dim();
        let mut center = Self {
            last_received: system
                .sensors
                .iter()
                .map(|s| Vector::zeros(s.meas_dim()))
                .collect(),
            received: vec![false; system.n_sensors()],
            uniform: Vec::new(),
            fusion: Fusion::new(&system),
            pred: est.clone(),
            out: est.clone(),
            predict_work: kf::PredictWork::new(n),
            system,
            delta,
            silence,
            est,
            loss: None,
        };
        center.uniform = (0..center.system.n_sensors())
            .map(|i| center.uniform_noise(i))
            .collect();
        Ok(center)
    }

    /// The loss-aware center (module note); `None` or 0, or `silence = "ignore"`: the published
    /// one.
    pub fn with_link_loss(mut self, link_loss: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        let n = self.system.n_sensors();
        let ps = loss_aware::effective_link_loss(link_loss, n)?;
        self.loss = ps
            .filter(|_| self.silence == SilenceModel::Uniform)
            .map(|ps| {
                let delta = self.delta;
                let mixtures = ps
                    .into_iter()
                    .map(|p| loss_aware::SendOnDeltaMixture { delta, p })
                    .collect();
                (mixtures, vec![1.0; n])
            });
        Ok(self)
    }

    /// The loss-aware step after the prediction and the inbox's bookkeeping: the received
    /// measurements in information form, then each silence's mixture update, and q.
    fn step_loss_aware(
        &mut self,
        inbox: &[Received],
        mixtures: &[loss_aware::SendOnDeltaMixture],
        q: &mut [f64],
    ) -> Result<(), SchemeError> {
        self.fusion
            .fuse_received(&self.system, &self.pred, inbox, &mut self.out)?;
        // The new q of every sensor, committed only when the step succeeds.
        let mut q_next = q.to_vec();
        for (i, msg) in inbox.iter().enumerate() {
            match msg {
                Received::Measurement(_) => q_next[i] = 1.0,
                Received::Silent if self.received[i] => {
                    let sensor = self.system.sensors[i].as_ref();
                    let u = mixtures[i].update(
                        sensor,
                        &self.out,
                        &self.last_received[i],
                        &self.uniform[i],
                        q[i],
                    )?;
                    self.out = u.estimate;
                    q_next[i] = u.weight;
                }
                _ => {}
            }
        }
        q.copy_from_slice(&q_next);
        std::mem::swap(&mut self.est, &mut self.out);
        Ok(())
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
        let t = &self.system.transition;
        kf::predict_into(t, &self.est, &mut self.pred, &mut self.predict_work);
        // The inbox first (its errors before the fusion's; what arrived is remembered even
        // if the step then fails). A silent sensor's z_last is from an earlier step.
        for (i, msg) in inbox.iter().enumerate() {
            if let Some(z) = received_measurement(i, msg)? {
                assign(&mut self.last_received[i], z);
                self.received[i] = true;
            }
        }
        if let Some((mixtures, mut q)) = self.loss.take() {
            let r = self.step_loss_aware(inbox, &mixtures, &mut q);
            self.loss = Some((mixtures, q));
            return r;
        }
        self.fusion.start(&self.pred)?;
        for (i, msg) in inbox.iter().enumerate() {
            let evidence = match (received_measurement(i, msg)?, msg) {
                (Some(z), _) => Evidence::Measurement(z),
                (None, Received::Silent)
                    if self.silence == SilenceModel::Uniform && self.received[i] =>
                {
                    Evidence::Pseudo {
                        z: &self.last_received[i],
                        r: &self.uniform[i],
                    }
                }
                (None, _) => Evidence::Nothing,
            };
            self.fusion.add(&self.system, i, evidence)?;
        }
        self.fusion.finish(&mut self.out)?;
        std::mem::swap(&mut self.est, &mut self.out);
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
    /// The loss probability a loss-aware center assumes (`None`: the published center).
    link_loss: Option<Vec<f64>>,
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
            link_loss: None,
        })
    }

    /// The loss-aware center ([`SendOnDeltaCenter::with_link_loss`]); `None` or 0: the
    /// published one.
    pub fn with_link_loss(mut self, link_loss: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        self.link_loss = loss_aware::effective_link_loss(link_loss, self.system.n_sensors())?;
        Ok(self)
    }
}

impl Scheme for SendOnDeltaScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = self
            .system
            .sensors
            .iter()
            .map(|s| {
                SendOnDeltaSensor::new(self.delta)
                    .map(|node| Box::new(node.with_dim(s.meas_dim())) as Box<dyn SensorNode>)
            })
            .collect::<Result<_, _>>()?;
        Ok(SchemeInstance {
            sensors,
            center: Box::new(
                SendOnDeltaCenter::new(self.system.clone(), self.delta, self.silence)?
                    .with_link_loss(self.link_loss.clone())?,
            ),
        })
    }
}
