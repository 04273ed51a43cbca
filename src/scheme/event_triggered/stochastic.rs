//! Stochastic event triggers (Han, Mo, Wu, Weerakkody, Sinopoli, Shi, "Stochastic
//! event-triggered sensor schedule for remote state estimation", IEEE TAC 60(10), 2015).
//!
//! At each step the sensor draws ζ_k uniform on (0, 1] and stays silent (γ_k = 0) iff
//! ζ_k <= φ(·), with
//!
//! - **open loop** (their Section III-A): φ(z_k) = exp(-½ z_k^T Y z_k), on the measurement;
//! - **closed loop** (Section III-B): φ(ν_k) = exp(-½ ν_k^T Y ν_k), ν_k = z_k - C x̂_k^-, on
//!   the innovation against the estimator's prediction.
//!
//! A silence then has the likelihood ∫ N(z; Cx, R) φ(z) dz ∝ N(0; Cx, R + Y^{-1}) (open loop)
//! or ∝ N(C x̂^-; Cx, R + Y^{-1}) (closed loop): Gaussian in x, so the posterior stays
//! Gaussian and the KF with the silence read as the pseudo-measurement 0 (open loop) or
//! C x̂_k^- (closed loop) with noise R + Y^{-1} is the exact MMSE estimator (their Theorem 1,
//! open loop: x̂_k = x̂_k^- - P^- C^T (C P^- C^T + R + Y^{-1})^{-1} C x̂_k^- on silence;
//! Theorem 2, closed loop: x̂_k = x̂_k^-, and in both P_k = P^- - P^- C^T (C P^- C^T + R +
//! Y^{-1})^{-1} C P^-). With several sensors the silence likelihoods multiply (independent
//! noises and coins), so the fused filter stays exact for linear sensors; nonlinear sensors
//! are linearized at the prediction (then it is an EKF, not exact).
//!
//! **Knob.** Y_i = R_i^{-1} / τ² per sensor (or one matrix `Y` for all): τ is a threshold in
//! units of the sensor's noise standard deviation, the send rate falls as τ grows, τ = 0 is
//! "Y = ∞": always send, and R + Y^{-1} = (1 + τ²) R.
//!
//! **Feedback.** Open loop: none. Closed loop: the center feeds back x̂_k^- only (n reals,
//! downlink), since Y is fixed and the trigger needs no covariance. With one sensor a replica
//! of the estimator at the sensor would do without it (the paper's setting), not with N.
//!
//! The coin ζ_k comes from the `rng` given to [`SensorNode::step`] and is drawn at every step,
//! so the coin stream does not depend on the knob (common random numbers across knob values).
//!
//! **Loss-aware center (beyond the paper).** With `link_loss` = p > 0, P(nothing arrived | z) =
//! φ + p (1 - φ) = p + (1 - p) φ: the posterior is the two-component mixture of the prediction
//! (weight ∝ p) and the published silence update above (weight ∝ (1 - p) π, π the probability
//! of a silence given the past), with exact weights, moment-matched to one Gaussian
//! ([`loss_aware::stochastic_no_arrival`]). The received measurements are fused first (the
//! published information form), then each silence in sensor order. With τ = 0 a silence can
//! only be a loss (π = 0): the prediction, where the published center refuses it.
use super::{
    check_inbox, loss_aware, nonnegative, prediction_feedback, received_measurement, Evidence,
    Fusion,
};
use crate::filter::{kf, Gaussian};
use crate::linalg::{check_spd, spd_inverse, Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::scheme::{
    Feedback, FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System,
};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// Open loop (on z_k) or closed loop (on the innovation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerLoop {
    Open,
    Closed,
}

/// The trigger matrices every sensor and the center share: per sensor Y_i and the effective
/// silence noise R_i + Y_i^{-1}; `None` for Y = ∞ (always send).
#[derive(Debug, Clone, PartialEq)]
pub struct StochasticTrigger {
    pub kind: TriggerLoop,
    per_sensor: Option<Vec<(Matrix, Matrix)>>,
}

impl StochasticTrigger {
    /// Y_i = R_i^{-1} / τ² (τ >= 0; τ = 0 always sends).
    pub fn with_tau(system: &System, kind: TriggerLoop, tau: f64) -> Result<Self, SchemeError> {
        nonnegative("tau", tau)?;
        if tau == 0.0 {
            return Ok(Self {
                kind,
                per_sensor: None,
            });
        }
        let per_sensor = system
            .sensors
            .iter()
            .map(|s| {
                let r = s.noise_cov();
                let y = spd_inverse(r).map_err(|source| SchemeError::Matrix {
                    what: "sensor noise R",
                    source,
                })? / (tau * tau);
                Ok((y, r * (1.0 + tau * tau)))
            })
            .collect::<Result<_, SchemeError>>()?;
        Ok(Self {
            kind,
            per_sensor: Some(per_sensor),
        })
    }

    /// One symmetric positive definite Y for every sensor (all of Y's dimension).
    pub fn with_matrix(system: &System, kind: TriggerLoop, y: Matrix) -> Result<Self, SchemeError> {
        check_spd(&y).map_err(|e| SchemeError::Invalid {
            field: "Y",
            message: format!("Y must be symmetric positive definite: {e}"),
        })?;
        let y_inv = spd_inverse(&y).map_err(|e| SchemeError::Invalid {
            field: "Y",
            message: e.to_string(),
        })?;
        let per_sensor = system
            .sensors
            .iter()
            .enumerate()
            .map(|(i, s)| {
                if s.meas_dim() != y.nrows() {
                    return Err(SchemeError::Invalid {
                        field: "Y",
                        message: format!(
                            "Y is {}x{} but sensor {i} measures {} components",
                            y.nrows(),
                            y.ncols(),
                            s.meas_dim()
                        ),
                    });
                }
                Ok((y.clone(), s.noise_cov() + &y_inv))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            kind,
            per_sensor: Some(per_sensor),
        })
    }

    /// Y of sensor `i` (`None`: always send).
    pub fn y(&self, i: usize) -> Option<&Matrix> {
        self.per_sensor.as_ref().map(|p| &p[i].0)
    }

    /// R_i + Y_i^{-1}, the effective noise of a silence (`None`: silences do not happen).
    pub fn silence_noise(&self, i: usize) -> Option<&Matrix> {
        self.per_sensor.as_ref().map(|p| &p[i].1)
    }

    /// φ = exp(-½ u^T Y_i u): the probability of staying silent given u (0 for Y = ∞).
    pub fn silence_probability(&self, i: usize, u: &Vector) -> f64 {
        self.silence_probability_in(i, u, &mut Vector::zeros(u.len()))
    }

    /// [`silence_probability`](Self::silence_probability) with `Y u` formed in `yu` (sized as
    /// u): the product as nalgebra's (`fixed::gemv` is its kernel), then the dot product.
    fn silence_probability_in(&self, i: usize, u: &Vector, yu: &mut Vector) -> f64 {
        match self.y(i) {
            None => 0.0,
            Some(y) => {
                crate::linalg::fixed::gemv(yu, y, u);
                (-0.5 * u.dot(yu)).exp()
            }
        }
    }
}

/// Sensor side: one coin per step against φ of the measurement (open loop) or of the
/// innovation against the fed-back x̂_k^- (closed loop). A step allocates only the message it
/// sends (linear sensors): the innovation and `Y u` are formed in buffers.
#[derive(Debug, Clone)]
pub struct StochasticTriggerSensor {
    system: Arc<System>,
    index: usize,
    trigger: StochasticTrigger,
    /// ν_k (closed loop).
    nu: Vector,
    /// Y u.
    yu: Vector,
}

impl StochasticTriggerSensor {
    pub fn new(system: Arc<System>, index: usize, trigger: StochasticTrigger) -> Self {
        let m = system.sensors[index].meas_dim();
        Self {
            system,
            index,
            trigger,
            nu: Vector::zeros(m),
            yu: Vector::zeros(m),
        }
    }
}

impl SensorNode for StochasticTriggerSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        // ζ in (0, 1]: with Y = ∞ (φ = 0) the sensor always sends.
        let zeta = 1.0 - rng.random::<f64>();
        let u = match self.trigger.kind {
            TriggerLoop::Open => z,
            TriggerLoop::Closed => {
                let (mean, _) = prediction_feedback(self.index, feedback, false)?;
                let sensor = self.system.sensors[self.index].as_ref();
                match sensor.as_linear() {
                    // z - H x̂^- with H x̂^- as nalgebra's gemv.
                    Some(l) => {
                        crate::linalg::fixed::gemv(&mut self.nu, l.h(), mean);
                        assert_eq!(z.len(), self.nu.len(), "measurement dimension");
                        for (v, zi) in self.nu.iter_mut().zip(z.iter()) {
                            *v = zi - *v;
                        }
                    }
                    None => self.nu = z - sensor.predict(mean),
                }
                &self.nu
            }
        };
        if self.yu.len() != u.len() {
            self.yu = Vector::zeros(u.len());
        }
        if zeta
            <= self
                .trigger
                .silence_probability_in(self.index, u, &mut self.yu)
        {
            Ok(Transmission::Silent)
        } else {
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        }
    }
}

/// Fusion side: the exact MMSE estimator of Theorems 1 / 2, fused over sensors. A step
/// allocates nothing (linear sensors): the prediction and the pseudo-measurements are formed
/// in buffers, and the silence noise R_i + Y_i^{-1} is fixed, so [`Fusion`] inverts it once.
#[derive(Debug, Clone)]
pub struct StochasticTriggerCenter {
    system: Arc<System>,
    trigger: StochasticTrigger,
    est: Gaussian,
    /// `kf::predict` of the estimate, per step.
    pred: Gaussian,
    predict_work: kf::PredictWork,
    fusion: Fusion,
    /// The fused estimate of a step, swapped into `est` when the step succeeds.
    out: Gaussian,
    /// Per sensor, the pseudo-measurement of a silence: 0 (open loop) or C_i x̂_k^- (closed).
    pseudo: Vec<Vector>,
    /// The loss-aware center: the loss probability p > 0 and, per sensor, log det Y_i^{-1}
    /// (`None` for τ = 0); `None`: the published center.
    loss: Option<(Vec<f64>, Vec<Option<f64>>)>,
}

impl StochasticTriggerCenter {
    pub fn new(system: Arc<System>, trigger: StochasticTrigger) -> Self {
        let est = system.prior.clone();
        let n = est.dim();
        let pseudo = system
            .sensors
            .iter()
            .map(|s| Vector::zeros(s.meas_dim()))
            .collect();
        Self {
            fusion: Fusion::new(&system),
            pred: est.clone(),
            out: est.clone(),
            predict_work: kf::PredictWork::new(n),
            system,
            trigger,
            est,
            pseudo,
            loss: None,
        }
    }

    /// The loss-aware center (module note, [`loss_aware::stochastic_no_arrival`]); `None` or 0:
    /// the published one.
    pub fn with_link_loss(mut self, link_loss: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        self.loss = match loss_aware::effective_link_loss(link_loss, self.system.n_sensors())? {
            None => None,
            Some(p) => {
                let log_dets = (0..self.system.n_sensors())
                    .map(|i| self.trigger.y(i).map(loss_aware::log_det_y_inv).transpose())
                    .collect::<Result<_, _>>()?;
                Some((p, log_dets))
            }
        };
        Ok(self)
    }

    /// The loss-aware step after the prediction and the pseudo-measurements: the received
    /// measurements in information form, then each silence's mixture update.
    fn step_loss_aware(
        &mut self,
        inbox: &[Received],
        p: &[f64],
        log_dets: &[Option<f64>],
    ) -> Result<(), SchemeError> {
        self.fusion
            .fuse_received(&self.system, &self.pred, inbox, &mut self.out)?;
        for (i, msg) in inbox.iter().enumerate() {
            // τ = 0 always sends: nothing arriving is a loss, which says nothing.
            let (Received::Silent, Some(log_det), Some(noise)) =
                (msg, log_dets[i], self.trigger.silence_noise(i))
            else {
                continue;
            };
            let sensor = self.system.sensors[i].as_ref();
            self.out = loss_aware::stochastic_no_arrival(
                sensor,
                &self.out,
                &self.pseudo[i],
                noise,
                log_det,
                p[i],
            )?
            .estimate;
        }
        std::mem::swap(&mut self.est, &mut self.out);
        Ok(())
    }
}

impl FusionCenter for StochasticTriggerCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        check_inbox(&self.system, inbox)?;
        let t = &self.system.transition;
        kf::predict_into(t, &self.est, &mut self.pred, &mut self.predict_work);
        // The inbox first (its errors before the fusion's), and the closed loop's
        // pseudo-measurements.
        for (i, msg) in inbox.iter().enumerate() {
            received_measurement(i, msg)?;
            if !matches!(msg, Received::Silent) {
                continue;
            }
            if self.trigger.silence_noise(i).is_none() && self.loss.is_none() {
                return Err(SchemeError::Protocol {
                    sensor: i,
                    message: "silent although Y = infinity (tau = 0) always sends".into(),
                });
            }
            if self.trigger.kind == TriggerLoop::Closed {
                let sensor = self.system.sensors[i].as_ref();
                match sensor.as_linear() {
                    Some(l) => {
                        crate::linalg::fixed::gemv(&mut self.pseudo[i], l.h(), &self.pred.mean)
                    }
                    None => self.pseudo[i] = sensor.predict(&self.pred.mean),
                }
            }
        }
        if let Some((p, log_dets)) = self.loss.take() {
            let r = self.step_loss_aware(inbox, &p, &log_dets);
            self.loss = Some((p, log_dets));
            return r;
        }
        self.fusion.start(&self.pred)?;
        for (i, msg) in inbox.iter().enumerate() {
            let evidence = match (received_measurement(i, msg)?, msg) {
                (Some(z), _) => Evidence::Measurement(z),
                (None, Received::Silent) => Evidence::Pseudo {
                    z: &self.pseudo[i],
                    r: self.trigger.silence_noise(i).expect("checked"),
                },
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

    fn feedback(&self) -> Option<Feedback> {
        match self.trigger.kind {
            TriggerLoop::Open => None,
            TriggerLoop::Closed => Some(Feedback::Prediction {
                mean: self.system.transition.f() * &self.est.mean,
                cov: None,
            }),
        }
    }
}

/// The stochastic event-triggered scheme of Han et al. 2015.
#[derive(Debug, Clone)]
pub struct StochasticTriggerScheme {
    system: Arc<System>,
    trigger: StochasticTrigger,
    /// The loss probability a loss-aware center assumes (`None`: the published center).
    link_loss: Option<Vec<f64>>,
}

impl StochasticTriggerScheme {
    pub fn new(system: Arc<System>, trigger: StochasticTrigger) -> Self {
        Self {
            system,
            trigger,
            link_loss: None,
        }
    }

    /// The loss-aware center ([`StochasticTriggerCenter::with_link_loss`]); `None` or 0: the
    /// published one.
    pub fn with_link_loss(mut self, link_loss: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        self.link_loss = loss_aware::effective_link_loss(link_loss, self.system.n_sensors())?;
        Ok(self)
    }
}

impl Scheme for StochasticTriggerScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: (0..self.system.n_sensors())
                .map(|i| {
                    Box::new(StochasticTriggerSensor::new(
                        self.system.clone(),
                        i,
                        self.trigger.clone(),
                    )) as Box<dyn SensorNode>
                })
                .collect(),
            center: Box::new(
                StochasticTriggerCenter::new(self.system.clone(), self.trigger.clone())
                    .with_link_loss(self.link_loss.clone())?,
            ),
        })
    }
}
