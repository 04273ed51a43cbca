//! Sensor node of seed 000: a local KF/EKF and a send decision (NIS censoring (4)/(31), the
//! KL rule (24), random selection, or all-send). The local filter always processes the
//! sensor's own measurement; only what is sent depends on the rule.
use super::censoring::{kl_divergence, kl_threshold_for_nis, nis};
use super::FeedbackMode;
use crate::filter::{kf, Gaussian};
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::link::{Message, Transmission};
use crate::model::{LinearTransition, MeasurementModel};
use crate::scheme::{Feedback, SchemeError, SensorNode};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// Which measurements a sensor sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SendRule {
    /// NIS >= eta (seed 000 eq. (4), (31)).
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
    rule: SendRule,
    feedback: FeedbackMode,
    /// Local filter after the last update.
    local: Gaussian,
    last: Option<Decision>,
}

/// Reference point and covariance of the innovation of step k: the local prediction
/// (no feedback), the global prediction with the local covariance (CFwMD, Prop. 1/4/7) or the
/// global prediction and covariance (CFwMD2, Prop. 2/5/8).
pub fn innovation_reference(
    mode: FeedbackMode,
    local_prediction: &Gaussian,
    feedback: Option<&Feedback>,
) -> Result<(Vector, Matrix), SchemeError> {
    let global = || match feedback {
        Some(Feedback::Prediction { mean, cov }) => Ok((mean, cov)),
        _ => Err(SchemeError::Unsupported(
            "this censoring mode needs the fused prediction fed back".into(),
        )),
    };
    Ok(match mode {
        FeedbackMode::None => (local_prediction.mean.clone(), local_prediction.cov.clone()),
        FeedbackMode::Prediction => (global()?.0.clone(), local_prediction.cov.clone()),
        FeedbackMode::PredictionAndCovariance => {
            let (m, c) = global()?;
            let c = c.clone().ok_or_else(|| {
                SchemeError::Unsupported("CFwMD2 needs the fed-back covariance".into())
            })?;
            (m.clone(), c)
        }
    })
}

/// Covariance-only local update linearized at `x_ref` (the EKF linearizes at the fed-back
/// estimate in feedback systems, Remark 3), Joseph form; returns (P_{k|k}, gain, S).
pub fn local_covariance_update(
    sensor: &dyn MeasurementModel,
    p_pred: &Matrix,
    x_ref: &Vector,
) -> Result<(Matrix, Matrix, Matrix), SchemeError> {
    let h = sensor.jacobian(x_ref);
    let mut s = &h * p_pred * h.transpose() + sensor.noise_cov();
    symmetrize(&mut s);
    let chol = cholesky(&s).map_err(|source| SchemeError::Matrix {
        what: "local innovation covariance",
        source,
    })?;
    let gain = chol.solve(&(&h * p_pred)).transpose();
    let n = p_pred.nrows();
    let i_kh = Matrix::identity(n, n) - &gain * &h;
    let mut p = &i_kh * p_pred * i_kh.transpose() + &gain * sensor.noise_cov() * gain.transpose();
    symmetrize(&mut p);
    Ok((p, gain, s))
}

impl CensoringSensor {
    pub fn new(
        index: usize,
        sensor: Arc<dyn MeasurementModel>,
        transition: Arc<LinearTransition>,
        prior: Gaussian,
        rule: SendRule,
        feedback: FeedbackMode,
    ) -> Self {
        Self {
            index,
            sensor,
            transition,
            rule,
            feedback,
            local: prior,
            last: None,
        }
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
        _k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        kf::check_measurement(self.sensor.as_ref(), z)?;
        let pred = kf::predict(&self.transition, &self.local);
        let (x_ref, p_ref) = innovation_reference(self.feedback, &pred, feedback)?;
        let h = self.sensor.jacobian(&x_ref);
        let nu = z - self.sensor.predict(&x_ref);
        let mut s = &h * &p_ref * h.transpose() + self.sensor.noise_cov();
        symmetrize(&mut s);
        let nis_value = nis(&nu, &s)?;
        let u: f64 = rng.random();
        // Local filter: covariance linearized at the reference point, mean from it.
        let (p_post, gain, s_local) =
            local_covariance_update(self.sensor.as_ref(), &pred.cov, &x_ref)?;
        let nu_local = z - self.sensor.predict(&x_ref);
        let posterior = Gaussian::new(&x_ref + &gain * &nu_local, p_post);
        let send = match self.rule {
            SendRule::Nis { eta } => nis_value >= eta,
            SendRule::KlDivergence { eta } => {
                if z.len() != 1 || self.feedback != FeedbackMode::None {
                    return Err(SchemeError::Unsupported(
                        "the KL rule (24) is defined for scalar measurements and the sensor's own prediction".into(),
                    ));
                }
                let prior = Gaussian::new(x_ref.clone(), pred.cov.clone());
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
        self.local = posterior;
        self.last = Some(Decision {
            send,
            nis: nis_value,
            s,
        });
        Ok(if send {
            Transmission::Send(Message::Measurement(z.clone()))
        } else {
            Transmission::Silent
        })
    }
}
