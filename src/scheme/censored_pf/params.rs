//! Scenario-file parameters of Zheng et al.'s (2014) scheme. The send rule and its threshold come from
//! [`Protocol::for_target`], the only place where `l` becomes eta.
use super::{BandMethod, CensoredPfScheme, FeedbackMode, Fusion, PfOptions, Policy, Protocol};
use crate::filter::particle::{ResamplePolicy, Resampling};
use crate::scheme::link_loss::LinkLoss;
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// How the probability of a vector silence is computed, as written in files.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum BandName {
    /// The exact generalized chi-square probability.
    #[default]
    Exact,
    /// The paper's counting of `band_samples` Monte Carlo draws.
    MonteCarlo,
}

/// `censored-pf`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CensoredPfParams {
    #[serde(default = "default_policy")]
    pub policy: Policy,
    /// The average number of sensors sending per step (not for `all`).
    #[serde(default)]
    pub l: Option<f64>,
    #[serde(default = "default_feedback")]
    pub feedback: FeedbackMode,
    /// Default: `full` under censoring, `simple` otherwise.
    #[serde(default)]
    pub fusion: Option<Fusion>,
    #[serde(default = "default_particles")]
    pub particles: usize,
    #[serde(default)]
    pub resampling: Resampling,
    /// Resample only when ESS < ess_threshold * particles (default: every step).
    #[serde(default)]
    pub ess_threshold: Option<f64>,
    #[serde(default)]
    pub band: BandName,
    #[serde(default)]
    pub band_samples: Option<usize>,
    #[serde(default = "default_prop3_samples")]
    pub prop3_samples: usize,
    #[serde(default)]
    pub link_loss: Option<LinkLoss>,
}

fn default_policy() -> Policy {
    Policy::Nis
}
fn default_feedback() -> FeedbackMode {
    FeedbackMode::Prediction
}
fn default_particles() -> usize {
    1000
}
fn default_prop3_samples() -> usize {
    200
}

/// Most Monte Carlo draws per particle and silence (`band_samples`) or per step
/// (`prop3_samples`): beyond this the counting estimates cost more than any run can afford.
pub const MAX_SAMPLES: usize = 1_000_000;

/// Largest particle count a scenario may ask for: 10^7 particles of a 6-D state are about
/// 1 GB per fusion center and thread.
pub const MAX_PARTICLES: usize = 10_000_000;

impl CensoredPfParams {
    /// The protocol (send rule, eta, feedback) these parameters describe.
    pub fn protocol(&self, cx: &BuildContext) -> Result<Protocol, ParamError> {
        Ok(Protocol::for_target(
            self.policy,
            self.l,
            self.feedback,
            cx.system,
        )?)
    }

    /// The fusion center's options.
    pub fn options(&self, censoring: bool) -> Result<PfOptions, ParamError> {
        if self.particles > MAX_PARTICLES {
            return Err(ParamError::at(
                "particles",
                format!("at most {MAX_PARTICLES} particles, got {}", self.particles),
            ));
        }
        for (field, v) in [
            ("prop3_samples", Some(self.prop3_samples)),
            ("band_samples", self.band_samples),
        ] {
            if v.is_some_and(|v| v > MAX_SAMPLES) {
                return Err(ParamError::at(
                    field,
                    format!("at most {MAX_SAMPLES} draws, got {}", v.unwrap_or(0)),
                ));
            }
        }
        // One number for all sensors goes in the options; a list or "channel" is set per
        // sensor on the built scheme.
        let link_loss = match self.link_loss {
            Some(LinkLoss::All(p)) => crate::scheme::link_loss::check(p)?,
            _ => 0.0,
        };
        let resample_policy = match self.ess_threshold {
            None => ResamplePolicy::Always,
            Some(t) if (0.0..=1.0).contains(&t) => ResamplePolicy::EssBelow(t),
            Some(t) => {
                return Err(ParamError::at(
                    "ess_threshold",
                    format!("expected a fraction in [0, 1], got {t}"),
                ))
            }
        };
        let band = match (self.band, self.band_samples) {
            (BandName::Exact, None) => BandMethod::Exact,
            (BandName::Exact, Some(_)) => {
                return Err(ParamError::at(
                    "band_samples",
                    "only for band = \"monte-carlo\"",
                ))
            }
            (BandName::MonteCarlo, s) => BandMethod::MonteCarlo {
                samples: s.filter(|&s| s > 0).ok_or_else(|| {
                    ParamError::at("band_samples", "expected a positive number of draws")
                })?,
            },
        };
        Ok(PfOptions {
            particles: self.particles,
            fusion: self.fusion.unwrap_or(if censoring {
                Fusion::Full
            } else {
                Fusion::Simple
            }),
            resampling: self.resampling,
            resample_policy,
            band,
            prop3_samples: self.prop3_samples,
            link_loss,
        })
    }
}

impl SchemeParams for CensoredPfParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let protocol = self.protocol(cx)?;
        let options = self.options(protocol.eta().is_some())?;
        let mut scheme =
            CensoredPfScheme::new(cx.system.clone(), protocol, options)?.with_horizon(cx.steps)?;
        if let Some(l @ (LinkLoss::PerSensor(_) | LinkLoss::FromChannel(_))) = &self.link_loss {
            scheme = scheme.with_link_losses(l.per_sensor(cx)?)?;
        }
        Ok(Box::new(scheme))
    }
}

pub const ENTRY: SchemeEntry = SchemeEntry {
    kind: "censored-pf",
    label: "Censored PF",
    summary: "Zheng et al. (2014): local KF/EKF sensors send z when the NIS reaches eta = chi^2(l/N) (eq. (4)/(8)/(31)/(43)); particle-filter fusion center with the likelihood of silences",
    params: &[
        ParamDoc {
            name: "policy",
            values: "nis|kl|random|all",
            default: "nis",
            meaning: "nis: censoring by NIS (eq. (4)); kl: by the KL rule (eq. (24), scalar, needs feedback = \"none\"); random: send with probability l/N; all: always",
        },
        ParamDoc {
            name: "l",
            values: "number in (0, N]",
            default: "required*",
            meaning: "the average number of sensors sending per step (not for policy = \"all\")",
        },
        ParamDoc {
            name: "feedback",
            values: "none|prediction|prediction-covariance",
            default: "prediction",
            meaning: "what the center feeds back: nothing (Prop. 3/6), x_{k|k-1} (CFwMD), and P_{k|k-1} (CFwMD2)",
        },
        ParamDoc {
            name: "fusion",
            values: "full|simple|exact",
            default: "full*",
            meaning: "full: likelihood of silences (CFwMD; default under censoring); simple: ignore silences (CFoMD; default otherwise); exact: CFwMD-exact (needs feedback = \"none\", linear sensors)",
        },
        ParamDoc {
            name: "particles",
            values: "integer in 1..=10^7",
            default: "1000",
            meaning: "particles of the fusion center",
        },
        registry::RESAMPLING,
        registry::ESS_THRESHOLD,
        ParamDoc {
            name: "band",
            values: "exact|monte-carlo",
            default: "exact",
            meaning: "vector silences: exact generalized chi-square, or the paper's counting with band_samples",
        },
        ParamDoc {
            name: "band_samples",
            values: "integer in 1..=10^6",
            default: "required*",
            meaning: "draws of the counting estimate (band = \"monte-carlo\" only)",
        },
        ParamDoc {
            name: "prop3_samples",
            values: "integer in 1..=10^6",
            default: "200",
            meaning: "Monte Carlo draws of the Prop. 3 / 6 integral (no feedback)",
        },
        ParamDoc {
            name: "link_loss",
            values: crate::scheme::link_loss::VALUES,
            default: "0",
            meaning: "loss-aware fusion (beyond the paper): the loss probability the center assumes, so that nothing arriving has likelihood P(silent | x) + link_loss P(sent | x); 0: the published likelihood (a missing packet is a silence)",
        },
    ],
    knob: Some(registry::Knob::rising(
        "l",
        registry::Bound::PerSensor(1e-3),
        registry::Bound::PerSensor(1.0),
    )),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<CensoredPfParams>,
    example: "l = 1.0\nparticles = 200",
    missing_packet: "a missing packet is a silence: the published likelihood (CFwMD) reads it as an innovation inside the band; with link_loss = p the likelihood is P(silent | x) + p P(sent | x)",
};
