//! Sensor node of Zheng et al. (2014): a local KF/EKF and a send decision (NIS censoring (4)/(31), the
//! KL rule (24), random selection, or all-send). The local filter always processes the
//! sensor's own measurement; only what is sent depends on the rule.
use super::censoring::{kl_divergence, kl_threshold_for_nis, nis};
use super::local_plan::LocalPlan;
use super::FeedbackMode;
use crate::filter::{kf, Gaussian};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::link::{Message, Transmission};
use crate::model::{LinearTransition, MeasurementModel};
use crate::scheme::{Feedback, SchemeError, SensorNode};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// Which measurements a sensor sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SendRule {
    /// NIS >= eta (Zheng et al. (2014), eq. (4), (31)).
    Nis { eta: f64 },
    /// KL(prior || posterior) >= zeta_k (eq. (24)), with zeta_k mapped from eta by Theorem 1
    /// at every step (scalar measurements): the same decisions as `Nis { eta }`.
    KlDivergence { eta: f64 },
    /// Send with probability `p` = l / N, whatever the data (random selection, MCAR).
    Random { p: f64 },
    /// Always send.
    All,
}

/// What a sensor computed at one step, kept so that tests and the fusion center's replica
/// can compare.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub send: bool,
    pub nis: f64,
    /// Innovation covariance S used by the rule.
    pub s: Matrix,
}

/// One censoring sensor.
#[derive(Debug, Clone)]
pub struct CensoringSensor {
    index: usize,
    sensor: Arc<dyn MeasurementModel>,
    transition: Arc<LinearTransition>,
    /// Both from the scheme's [`super::Protocol`], which the fusion center shares.
    rule: SendRule,
    feedback: FeedbackMode,
    /// The shared local-covariance sequence (linear sensors), if the scheme computed one.
    plan: Option<Arc<LocalPlan>>,
    /// Local filter after the last update.
    local: Gaussian,
    last: Option<Decision>,
}

/// Reference point and covariance of the innovation of step k: the local prediction
/// (no feedback), the global prediction with the local covariance (CFwMD, Prop. 1/4/7) or the
/// global prediction and covariance (CFwMD2, Prop. 2/5/8).
pub fn innovation_reference<'a>(
    mode: FeedbackMode,
    local_mean: &'a Vector,
    local_cov: &'a Matrix,
    feedback: Option<&'a Feedback>,
) -> Result<(&'a Vector, &'a Matrix), SchemeError> {
    let global = || match feedback {
        Some(Feedback::Prediction { mean, cov }) => Ok((mean, cov)),
        _ => Err(SchemeError::Unsupported(
            "this censoring mode needs the fused prediction fed back".into(),
        )),
    };
    Ok(match mode {
        FeedbackMode::None => (local_mean, local_cov),
        FeedbackMode::Prediction => (global()?.0, local_cov),
        FeedbackMode::PredictionAndCovariance => {
            let (m, c) = global()?;
            let c = c.as_ref().ok_or_else(|| {
                SchemeError::Unsupported("CFwMD2 needs the fed-back covariance".into())
            })?;
            (m, c)
        }
    })
}

impl CensoringSensor {
    pub fn new(
        index: usize,
        sensor: Arc<dyn MeasurementModel>,
        transition: Arc<LinearTransition>,
        prior: Gaussian,
        protocol: super::Protocol,
    ) -> Self {
        Self {
            index,
            sensor,
            transition,
            rule: protocol.rule(),
            feedback: protocol.feedback(),
            plan: None,
            local: prior,
            last: None,
        }
    }

    /// Takes the local covariances from `plan` (the one computed for this sensor's system and
    /// prior) instead of computing them every step. The plan's step k is the covariance after
    /// k updates, so `step` must be called for k = 1, 2, 3, ... in order, as the simulator
    /// does.
    pub fn with_plan(mut self, plan: Arc<LocalPlan>) -> Self {
        self.plan = Some(plan);
        self
    }

    /// The sensor's index in the system.
    pub fn index(&self) -> usize {
        self.index
    }

    /// The decision of the last step.
    pub fn last_decision(&self) -> Option<&Decision> {
        self.last.as_ref()
    }

    /// The local filter after the last step.
    pub fn local(&self) -> &Gaussian {
        &self.local
    }
}

impl SensorNode for CensoringSensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        kf::check_measurement(self.sensor.as_ref(), z)?;
        // A linear sensor's covariances come from the shared plan (the same numbers, computed
        // once per scheme); otherwise they are computed here.
        let planned = match &self.plan {
            Some(plan) => plan.at(self.index, k)?,
            None => None,
        };
        let pred_mean = self.transition.f() * &self.local.mean;
        let computed_pred_cov;
        let pred_cov = match planned {
            Some(step) => &step.p_pred,
            None => {
                computed_pred_cov = kf::predict_cov(&self.transition, &self.local.cov);
                &computed_pred_cov
            }
        };
        let (x_ref, p_ref) = innovation_reference(self.feedback, &pred_mean, pred_cov, feedback)?;
        let nu = z - self.sensor.predict(x_ref);
        let computed_s;
        let s = match planned {
            Some(step) if self.feedback != FeedbackMode::PredictionAndCovariance => &step.s,
            _ => {
                let h = self.sensor.jacobian(x_ref);
                let mut s = &h * p_ref * h.transpose() + self.sensor.noise_cov();
                symmetrize(&mut s);
                computed_s = s;
                &computed_s
            }
        };
        let nis_value = nis(&nu, s)?;
        let u: f64 = rng.random();
        // Local filter: covariance linearized at the reference point, mean from it.
        let computed_update;
        let (p_post, gain, s_local) = match planned {
            Some(step) => (&step.p_post, &step.gain, &step.s),
            None => {
                computed_update = kf::update_cov(self.sensor.as_ref(), pred_cov, x_ref)?;
                (&computed_update.0, &computed_update.1, &computed_update.2)
            }
        };
        let post_mean = x_ref + gain * &nu;
        let send = match self.rule {
            SendRule::Nis { eta } => nis_value >= eta,
            SendRule::KlDivergence { eta } => {
                if z.len() != 1 || self.feedback != FeedbackMode::None {
                    return Err(SchemeError::Unsupported(
                        "the KL rule (24) is defined for scalar measurements and the sensor's own prediction".into(),
                    ));
                }
                let prior = Gaussian::new(x_ref.clone(), pred_cov.clone());
                let posterior = Gaussian::new(post_mean.clone(), p_post.clone());
                let zeta = kl_threshold_for_nis(
                    &prior,
                    &posterior.cov,
                    &gain.column(0).into_owned(),
                    s_local[(0, 0)],
                    eta,
                )?;
                kl_divergence(&prior, &posterior)? >= zeta
            }
            SendRule::Random { p } => u < p,
            SendRule::All => true,
        };
        self.local.mean = post_mean;
        self.local.cov.copy_from(p_post);
        self.last = Some(Decision {
            send,
            nis: nis_value,
            s: s.clone(),
        });
        Ok(if send {
            Transmission::Send(Message::Measurement(z.clone()))
        } else {
            Transmission::Silent
        })
    }
}
