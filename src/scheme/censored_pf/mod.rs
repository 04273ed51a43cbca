//! Zheng, Niu and Varshney (2014), "Sequential Bayesian Estimation With Censored Data for
//! Multi-Sensor Systems": sensors run a local KF/EKF and send their measurement only when its
//! normalized innovation squared passes the threshold eta = chi^2(l/N) (eq. (4), (8), (31),
//! (43)); the fusion center runs a particle filter whose weights use the full likelihood of
//! the received measurements and of the silences (CFwMD: eq. (9), (15), (33), (39), (44),
//! (45); without feedback Prop. 3 / 6 with (21)-(23)), or the simple likelihood that ignores
//! silences (CFoMD). Random selection and all-send are the baselines.
//!
//! The sensor side ([`CensoringSensor`]) and the fusion side ([`CensoredPfCenter`]) are
//! separate pieces; a scheme builds a matched set:
//!
//! ```
//! use hushfuse::filter::particle::{ResamplePolicy, Resampling};
//! use hushfuse::filter::Gaussian;
//! use hushfuse::linalg::{Matrix, Vector};
//! use hushfuse::link::Received;
//! use hushfuse::model::{presets, LinearSensor, MeasurementModel};
//! use hushfuse::scheme::censored_pf::*;
//! use hushfuse::scheme::{Scheme, System};
//! use rand::SeedableRng;
//! use std::sync::Arc;
//!
//! // Two position sensors (r = 1) on a 1-D constant-velocity target.
//! let h = Matrix::from_row_slice(1, 2, &[1.0, 0.0]);
//! let sensors: Vec<Arc<dyn MeasurementModel>> = (0..2)
//!     .map(|_| {
//!         let s = LinearSensor::new(h.clone(), Matrix::from_element(1, 1, 1.0)).unwrap();
//!         Arc::new(s) as Arc<dyn MeasurementModel>
//!     })
//!     .collect();
//! let system = Arc::new(System {
//!     transition: presets::constant_velocity_1d_discrete(1.0, 0.01).unwrap(),
//!     sensors,
//!     prior: Gaussian::new(Vector::from_vec(vec![0.0, 10.0]), Matrix::identity(2, 2)),
//! });
//! // On average l = 1 of the N = 2 sensors talks (eta = chi^2_1 quantile of eq. (8)), and
//! // the fused prediction is fed back. Sensors and center share this one protocol.
//! let protocol = Protocol::for_target(Policy::Nis, Some(1.0), FeedbackMode::Prediction, &system)?;
//! let options = PfOptions {
//!     particles: 500,
//!     fusion: Fusion::Full, // CFwMD: silences are data
//!     resampling: Resampling::Systematic,
//!     resample_policy: ResamplePolicy::Always,
//!     band: BandMethod::Exact,
//!     prop3_samples: 200,
//!     link_loss: 0.0, // the published likelihood: every missing packet is a silence
//! };
//! let scheme = CensoredPfScheme::new(system, protocol, options)?.with_horizon(20)?;
//! let mut inst = scheme.build_with_seed(1)?;
//! let mut coins = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(2);
//! let mut feedback = inst.center.feedback();
//! for k in 1..=20 {
//!     let z = Vector::from_vec(vec![10.0 * k as f64]); // the target moves 10 per step
//!     // Each sensor sends z or stays silent; the fusion center hears both.
//!     let mut inbox = Vec::new();
//!     for sensor in inst.sensors.iter_mut() {
//!         inbox.push(Received::from(sensor.step(k, &z, feedback.as_ref(), &mut coins)?));
//!     }
//!     inst.center.step(k, &inbox)?;
//!     feedback = inst.center.feedback();
//! }
//! assert!((inst.center.estimate().mean[0] - 200.0).abs() < 3.0);
//! # Ok::<(), hushfuse::scheme::SchemeError>(())
//! ```
pub mod censoring;
pub mod center;
pub mod exact;
pub mod local_plan;
pub mod params;
pub mod sensor;

pub use center::CensoredPfCenter;
pub use local_plan::LocalPlan;
pub use sensor::{CensoringSensor, SendRule};

use crate::filter::particle::{ResamplePolicy, Resampling};
use crate::scheme::{Scheme, SchemeError, SchemeInstance, SensorNode, System};
use std::sync::Arc;

/// What the fusion center feeds back before each step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FeedbackMode {
    /// Nothing: sensors censor against their own KF prediction (Prop. 3 / 6).
    None,
    /// The fused prediction x_{k|k-1} (CFwMD, Prop. 1 / 4 / 7).
    Prediction,
    /// The fused prediction and its covariance (CFwMD2, Prop. 2 / 5 / 8).
    #[serde(rename = "prediction-covariance")]
    PredictionAndCovariance,
}

/// Which likelihood the particle filter uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Fusion {
    /// Received measurements and silences (CFwMD).
    Full,
    /// Received measurements only (CFoMD; also random selection and all-send).
    Simple,
    /// CFwMD-exact (no feedback, linear sensors): particles carry copies of every sensor's
    /// local KF and condition on what each copy would have sent ([`exact`]).
    Exact,
}

/// How the probability that a vector innovation stayed inside the ellipsoid is computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BandMethod {
    /// Exact generalized chi-square CDF (deterministic).
    Exact,
    /// The paper's counting of `samples` Monte Carlo draws (Section VII-B).
    MonteCarlo { samples: usize },
}

/// Which send rule the sensors follow, as named in scenario files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Policy {
    /// Censoring by the normalized innovation squared (eq. (4), (31)).
    Nis,
    /// Censoring by the KL divergence (eq. (24)), scalar measurements.
    Kl,
    /// Random selection with probability l / N.
    Random,
    /// Every sensor sends every measurement.
    All,
}

/// What the sensors and the fusion center agree on: the send rule (with its threshold eta)
/// and what is fed back. Both sides take it from here, so they cannot disagree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Protocol {
    rule: SendRule,
    feedback: FeedbackMode,
}

impl Protocol {
    /// A protocol from an explicit rule. The KL rule (24) is defined for scalar measurements
    /// censored against the local prediction, so it needs `FeedbackMode::None`.
    pub fn new(rule: SendRule, feedback: FeedbackMode) -> Result<Self, SchemeError> {
        match rule {
            SendRule::Nis { eta } | SendRule::KlDivergence { eta }
                if !(eta.is_finite() && eta >= 0.0) =>
            {
                return Err(SchemeError::Invalid {
                    field: "l",
                    message: format!("the censoring threshold eta must be finite and >= 0, got {eta}"),
                })
            }
            SendRule::Random { p } if !(0.0..=1.0).contains(&p) => {
                return Err(SchemeError::Invalid {
                    field: "l",
                    message: format!("the send probability l/N must be in [0, 1], got {p}"),
                })
            }
            SendRule::KlDivergence { .. } if feedback != FeedbackMode::None => {
                return Err(SchemeError::Invalid {
                    field: "feedback",
                    message: "the KL rule (24) censors against the local prediction: it needs feedback = \"none\"".into(),
                })
            }
            _ => {}
        }
        Ok(Self { rule, feedback })
    }

    /// The protocol that makes on average `l` of the N sensors send per step: eta from the
    /// chi-square quantile of eq. (8) / (32) for censoring, probability l / N for random
    /// selection. The one place where l becomes a threshold.
    pub fn for_target(
        policy: Policy,
        l: Option<f64>,
        feedback: FeedbackMode,
        system: &System,
    ) -> Result<Self, SchemeError> {
        let n = system.n_sensors();
        let need_l = || -> Result<f64, SchemeError> {
            let l = l.ok_or_else(|| SchemeError::Invalid {
                field: "l",
                message: format!(
                    "policy {policy:?} needs `l`, the average number of sensors sending per step"
                ),
            })?;
            if !(l > 0.0 && l <= n as f64) {
                return Err(SchemeError::Invalid {
                    field: "l",
                    message: format!("expected l in (0, N = {n}], got {l}"),
                });
            }
            Ok(l)
        };
        let eta = || -> Result<f64, SchemeError> {
            let dims: Vec<usize> = system.sensors.iter().map(|s| s.meas_dim()).collect();
            if dims.iter().any(|&m| m != dims[0]) {
                return Err(SchemeError::Unsupported(
                    "censoring with one threshold needs sensors of equal measurement dimension (eq. (32))".into(),
                ));
            }
            censoring::nis_threshold(dims[0], need_l()?, n).map_err(|e| SchemeError::Invalid {
                field: "l",
                message: e.to_string(),
            })
        };
        let rule = match policy {
            Policy::Nis => SendRule::Nis { eta: eta()? },
            Policy::Kl => SendRule::KlDivergence { eta: eta()? },
            Policy::Random => SendRule::Random {
                p: need_l()? / n as f64,
            },
            Policy::All => {
                if l.is_some() {
                    return Err(SchemeError::Invalid {
                        field: "l",
                        message: "policy \"all\" sends everything; remove `l`".into(),
                    });
                }
                SendRule::All
            }
        };
        Self::new(rule, feedback)
    }

    pub fn rule(&self) -> SendRule {
        self.rule
    }

    pub fn feedback(&self) -> FeedbackMode {
        self.feedback
    }

    /// The censoring threshold when sensors censor by NIS or KL; `None` for random selection
    /// and all-send (their silences carry no information).
    pub fn eta(&self) -> Option<f64> {
        match self.rule {
            SendRule::Nis { eta } | SendRule::KlDivergence { eta } => Some(eta),
            SendRule::Random { .. } | SendRule::All => None,
        }
    }
}

/// Options of the particle-filter fusion center (what only the center needs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PfOptions {
    pub particles: usize,
    pub fusion: Fusion,
    pub resampling: Resampling,
    pub resample_policy: ResamplePolicy,
    pub band: BandMethod,
    /// Monte Carlo draws for the Prop. 3 / 6 integral (at least 1).
    pub prop3_samples: usize,
    /// Probability that the center assumes the link lost a packet (loss-aware fusion of
    /// silences, in [0, 1)); 0: the published likelihood, which reads every missing packet
    /// as a silence.
    pub link_loss: f64,
}

/// Zheng et al.'s (2014) scheme: censoring sensors + particle-filter fusion center.
#[derive(Debug, Clone)]
pub struct CensoredPfScheme {
    system: Arc<System>,
    transition: Arc<crate::model::LinearTransition>,
    protocol: Protocol,
    options: PfOptions,
    /// The linear sensors' local covariances for the horizon, shared by every instance.
    plan: Option<Arc<LocalPlan>>,
    /// Each sensor's assumed loss probability, where they differ (else `options.link_loss`).
    link_losses: Option<Arc<[f64]>>,
}

impl CensoredPfScheme {
    /// Checks what the paper supports: the full likelihood without feedback needs linear
    /// sensors (Remark 4 (III)); the KL rule needs scalar measurements.
    pub fn new(
        system: Arc<System>,
        protocol: Protocol,
        options: PfOptions,
    ) -> Result<Self, SchemeError> {
        if options.particles == 0 {
            return Err(SchemeError::Invalid {
                field: "particles",
                message: "expected at least 1 particle".into(),
            });
        }
        if options.prop3_samples == 0 {
            return Err(SchemeError::Invalid {
                field: "prop3_samples",
                message: "expected at least 1 draw".into(),
            });
        }
        if let BandMethod::MonteCarlo { samples: 0 } = options.band {
            return Err(SchemeError::Invalid {
                field: "band_samples",
                message: "expected a positive number of draws".into(),
            });
        }
        let rule = protocol.rule();
        let censoring = protocol.eta().is_some();
        if options.fusion == Fusion::Full
            && protocol.feedback() == FeedbackMode::None
            && censoring
            && system.sensors.iter().any(|s| s.as_linear().is_none())
        {
            return Err(SchemeError::Unsupported(
                "the full likelihood without feedback needs linear sensors (Zheng et al. (2014), Remark 4 (III)); use feedback or fusion = \"simple\"".into(),
            ));
        }
        if options.fusion == Fusion::Exact {
            if protocol.feedback() != FeedbackMode::None || !censoring {
                return Err(SchemeError::Unsupported(
                    "CFwMD-exact is for censoring sensors without feedback (feedback = \"none\")"
                        .into(),
                ));
            }
            if options.link_loss > 0.0 {
                return Err(SchemeError::Unsupported(
                    "CFwMD-exact has no loss-aware likelihood: `link_loss` needs fusion = \"full\" or \"simple\"".into(),
                ));
            }
            if system.sensors.iter().any(|s| s.as_linear().is_none()) {
                return Err(SchemeError::Unsupported(
                    "CFwMD-exact needs linear sensors: an EKF's gain depends on its own estimate, which the fusion center would have to carry per particle".into(),
                ));
            }
        }
        if let SendRule::KlDivergence { .. } = rule {
            if protocol.feedback() != FeedbackMode::None
                || system.sensors.iter().any(|s| s.meas_dim() != 1)
            {
                return Err(SchemeError::Unsupported(
                    "the KL rule (24) is defined for scalar measurements censored against the local prediction (no feedback)".into(),
                ));
            }
        }
        Ok(Self {
            transition: Arc::new(system.transition.clone()),
            system,
            protocol,
            options,
            plan: None,
            link_losses: None,
        })
    }

    /// Precomputes the linear sensors' local covariances for `horizon` steps, shared by the
    /// sensors and the fusion center of every instance (the same numbers; a speed-up only).
    /// Instances then refuse to run past the horizon unless the covariances converged.
    pub fn with_horizon(mut self, horizon: usize) -> Result<Self, SchemeError> {
        self.plan = Some(Arc::new(LocalPlan::new(&self.system, horizon)?));
        Ok(self)
    }

    /// Loss-aware fusion with each sensor's own loss probability (in [0, 1), one per sensor)
    /// in place of `options.link_loss` for all. The exact fusion (`Fusion::Exact`) does not
    /// read losses: refused there unless every one is 0.
    pub fn with_link_losses(mut self, per_sensor: Vec<f64>) -> Result<Self, SchemeError> {
        let ps = crate::scheme::event_triggered::loss_aware::effective_link_loss(
            Some(per_sensor),
            self.system.n_sensors(),
        )?;
        if ps.is_some() && self.options.fusion == Fusion::Exact {
            return Err(SchemeError::Unsupported(
                "CFwMD-exact has no loss-aware likelihood: `link_loss` needs fusion = \"full\" or \"simple\"".into(),
            ));
        }
        self.link_losses = ps.map(Arc::from);
        Ok(self)
    }
}

impl Scheme for CensoredPfScheme {
    fn keeps_step_plan(&self) -> bool {
        self.plan.is_some()
    }

    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        self.build_with_seed(0)
    }

    /// The cloud (state, weights, resampling scratch) and one likelihood pass per sensor; the
    /// exact fusion carries a copy of every sensor's filter per particle.
    fn footprint(&self) -> Option<crate::scheme::Footprint> {
        let n = self.system.state_dim() as f64;
        let sensors = self.system.n_sensors() as f64;
        let per_particle = match self.options.fusion {
            Fusion::Exact => n * (sensors + 1.0),
            _ => n,
        };
        let p = self.options.particles as f64;
        Some(crate::scheme::Footprint {
            bytes: p * 8.0 * (3.0 * per_particle + sensors + 4.0),
            flops_per_step: p * (per_particle * per_particle + 20.0 * sensors),
        })
    }

    fn build_with_seed(&self, seed: u64) -> Result<SchemeInstance, SchemeError> {
        let sensors = self
            .system
            .sensors
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let sensor = CensoringSensor::new(
                    i,
                    s.clone(),
                    self.transition.clone(),
                    self.system.prior.clone(),
                    self.protocol,
                );
                Box::new(match &self.plan {
                    Some(plan) => sensor.with_plan(plan.clone()),
                    None => sensor,
                }) as Box<dyn SensorNode>
            })
            .collect();
        let center: Box<dyn crate::scheme::FusionCenter> = match self.options.fusion {
            Fusion::Exact => Box::new(exact::ExactCensoredCenter::new(
                self.system.clone(),
                self.protocol,
                self.options,
                seed,
            )?),
            _ => {
                let center =
                    CensoredPfCenter::new(self.system.clone(), self.protocol, self.options, seed)?;
                let center = match &self.link_losses {
                    Some(ps) => center.with_link_losses(ps),
                    None => center,
                };
                Box::new(match &self.plan {
                    Some(plan) => center.with_plan(plan.clone()),
                    None => center,
                })
            }
        };
        Ok(SchemeInstance { sensors, center })
    }
}

#[cfg(test)]
mod tests;
