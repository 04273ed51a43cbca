//! Scenario-file parameters of the exact Tobit particle filter (`kind = "tobit-pf"`). The
//! threshold names `tau_l` / `tau_r` are the federated Tobit KF's too.
use super::{TobitPfOptions, TobitPfScheme, MAX_PARTICLES};
use crate::filter::particle::{ResamplePolicy, Resampling};
use crate::scheme::federated_tobit::params::{
    noise_var, one, region, PerSensor, GRANTED, GRANTED_KNOB,
};
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// `tobit-pf`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TobitPfParams {
    /// Symmetric region `[-tau, tau]` for every sensor (exclusive with `tau_l`/`tau_r`).
    #[serde(default)]
    pub tau: Option<f64>,
    /// Left-censoring thresholds (eq. (6)); default none.
    #[serde(default)]
    pub tau_l: Option<PerSensor>,
    /// Right-censoring thresholds (eq. (6)); default none.
    #[serde(default)]
    pub tau_r: Option<PerSensor>,
    /// Noise variance the sensors run at (as the federated Tobit KF's `noise_var`).
    #[serde(default)]
    pub noise_var: Option<PerSensor>,
    #[serde(default = "default_particles")]
    pub particles: usize,
    #[serde(default)]
    pub resampling: Resampling,
    /// Resample only when ESS < ess_threshold * particles (default: every step).
    #[serde(default)]
    pub ess_threshold: Option<f64>,
    /// Sensors granted per step (the bandwidth knob; 1: the paper's round-robin).
    #[serde(default = "one")]
    pub granted: f64,
}

fn default_particles() -> usize {
    TobitPfOptions::default().particles
}

impl TobitPfParams {
    /// The fusion center's options (range checks are the scheme constructor's).
    pub fn options(&self) -> TobitPfOptions {
        TobitPfOptions {
            particles: self.particles,
            resampling: self.resampling,
            resample_policy: match self.ess_threshold {
                None => ResamplePolicy::Always,
                Some(t) => ResamplePolicy::EssBelow(t),
            },
        }
    }
}

impl SchemeParams for TobitPfParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let n = cx.system.n_sensors();
        let (tau_l, tau_r) = region(self.tau, &self.tau_l, &self.tau_r, n)?;
        if self.particles > MAX_PARTICLES {
            // Checked here too so the message names the limit before any allocation.
            return Err(ParamError::at(
                "particles",
                format!("at most {MAX_PARTICLES} particles, got {}", self.particles),
            ));
        }
        let scheme = match noise_var(&self.noise_var, n)? {
            None => TobitPfScheme::new(cx.system.clone(), &tau_l, &tau_r, self.options())?,
            Some(v) => TobitPfScheme::with_noise_var(
                cx.system.clone(),
                &v,
                &tau_l,
                &tau_r,
                self.options(),
            )?,
        };
        Ok(Box::new(scheme.with_granted(self.granted)?))
    }
}

pub const ENTRY: SchemeEntry = SchemeEntry {
    kind: "tobit-pf",
    label: "Exact Tobit PF",
    summary: "Geng et al., beyond the paper: round-robin raw measurements censored two-sided at the center (eq. (6)); bootstrap particle filter on the augmented state with the exact Tobit likelihood, the Bayes-optimal reference for the Tobit KF",
    params: &[
        ParamDoc {
            name: "tau",
            values: "number > 0",
            default: "none",
            meaning: "censoring region [-tau, tau] for every sensor (instead of tau_l, tau_r)",
        },
        ParamDoc {
            name: "tau_l",
            values: "number or list (one per sensor)",
            default: "-inf",
            meaning: "left-censoring thresholds (z <= tau_l reads tau_l); -inf for none; a number applies to every sensor",
        },
        ParamDoc {
            name: "tau_r",
            values: "number or list (one per sensor)",
            default: "+inf",
            meaning: "right-censoring thresholds (z >= tau_r reads tau_r), each above its tau_l; inf for none",
        },
        ParamDoc {
            name: "noise_var",
            values: "number or list (one per sensor), >= R",
            default: "sensor R",
            meaning: "run at this noise variance: the sensor adds the same N(0, noise_var - R) as federated-tobit's",
        },
        ParamDoc {
            name: "particles",
            values: "integer in 1..=10^7",
            default: "2000",
            meaning: "particles of the fusion center",
        },
        registry::RESAMPLING,
        registry::ESS_THRESHOLD,
        GRANTED,
    ],
    knob: Some(GRANTED_KNOB),
    applies: registry::Applies::ScalarLinearSensors,
    build: registry::parse_and_build::<TobitPfParams>,
    example: "tau = 5.0\nparticles = 200",
    missing_packet: "a missing reading (a lost packet arrives as a silence) is skipped, no likelihood term: under round-robin a scheduled sensor always sends, so P(silent | x) = 0 and nothing arriving has the constant likelihood p (the link's loss), which carries no information; the held value is not weighed again",
};
