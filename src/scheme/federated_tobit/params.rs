//! Scenario-file parameters of Geng et al.'s schemes.
use super::{FederatedTobitScheme, Fusion, RoundRobinKfScheme};
use crate::filter::tobit::{LambdaSign, ThetaDenominator, Thresholds, TobitOptions};
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// A number for every sensor, or a list with one per sensor.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum PerSensor {
    All(f64),
    Each(Vec<f64>),
}

impl PerSensor {
    pub fn expand(&self, field: &str, p: usize) -> Result<Vec<f64>, ParamError> {
        match self {
            PerSensor::All(v) => Ok(vec![*v; p]),
            PerSensor::Each(v) if v.len() == p => Ok(v.clone()),
            PerSensor::Each(v) => Err(ParamError::at(
                field,
                format!(
                    "expected one number or {p} (one per sensor), got {}",
                    v.len()
                ),
            )),
        }
    }
}

/// `theta_denominator`: what divides `tau - zeta` in the theta of (14)-(15) (`sqrt-r`, or `r`
/// as printed after (11)); the censoring probabilities (9) divide by `sqrt(R)` either way.
#[derive(Debug, Clone, Copy, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum ThetaDenominatorParam {
    #[default]
    SqrtR,
    R,
}

/// `lambda_sign`.
#[derive(Debug, Clone, Copy, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum LambdaSignParam {
    #[default]
    Minus,
    Plus,
}

/// `fusion`.
#[derive(Debug, Clone, Copy, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum FusionParam {
    #[default]
    Federated,
    Local,
    LocalInLoop,
}

/// `federated-tobit`.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FtkfParams {
    /// Symmetric region `[-tau, tau]` for every sensor (exclusive with `tau_l`/`tau_r`).
    #[serde(default)]
    pub tau: Option<f64>,
    #[serde(default)]
    pub tau_l: Option<PerSensor>,
    #[serde(default)]
    pub tau_r: Option<PerSensor>,
    #[serde(default)]
    pub noise_var: Option<PerSensor>,
    #[serde(default)]
    pub sharing: Option<Vec<f64>>,
    #[serde(default)]
    pub fusion: FusionParam,
    /// 1-based sensor number for `fusion = "local"` / `"local-in-loop"` (the paper's S1, S2).
    #[serde(default)]
    pub local: Option<usize>,
    #[serde(default = "yes")]
    pub bias_model: bool,
    #[serde(default)]
    pub bias_states: Vec<usize>,
    #[serde(default)]
    pub theta_denominator: ThetaDenominatorParam,
    #[serde(default)]
    pub lambda_sign: LambdaSignParam,
    /// Sensors granted per step (the bandwidth knob; 1: the paper's round-robin).
    #[serde(default = "one")]
    pub granted: f64,
}

fn yes() -> bool {
    true
}

pub(crate) fn one() -> f64 {
    1.0
}

/// The censoring region of every sensor from `tau` (symmetric, for all) or `tau_l` / `tau_r`
/// (each a number for all or one per sensor; a side not given is not censored). Shared by
/// `federated-tobit` and `tobit-pf`, so both read a file the same way.
pub fn region(
    tau: Option<f64>,
    tau_l: &Option<PerSensor>,
    tau_r: &Option<PerSensor>,
    p: usize,
) -> Result<(Vec<f64>, Vec<f64>), ParamError> {
    match (tau, tau_l, tau_r) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => Err(ParamError::whole(
            "give `tau` (region [-tau, tau]) or `tau_l`/`tau_r`, not both",
        )),
        (Some(t), None, None) => {
            if t.is_nan() || t <= 0.0 {
                return Err(ParamError::at("tau", format!("expected tau > 0, got {t}")));
            }
            Ok((vec![-t; p], vec![t; p]))
        }
        (None, l, r) => Ok((
            l.as_ref()
                .map_or(Ok(vec![f64::NEG_INFINITY; p]), |v| v.expand("tau_l", p))?,
            r.as_ref()
                .map_or(Ok(vec![f64::INFINITY; p]), |v| v.expand("tau_r", p))?,
        )),
    }
}

pub(crate) fn noise_var(nv: &Option<PerSensor>, p: usize) -> Result<Option<Vec<f64>>, ParamError> {
    nv.as_ref().map(|v| v.expand("noise_var", p)).transpose()
}

impl SchemeParams for FtkfParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let p = cx.system.n_sensors();
        let (lo, hi) = region(self.tau, &self.tau_l, &self.tau_r, p)?;
        let thresholds = lo
            .iter()
            .zip(&hi)
            .enumerate()
            .map(|(i, (&l, &h))| {
                Thresholds::new(l, h).ok_or_else(|| {
                    ParamError::at(
                        "tau_l",
                        format!("sensor {}: expected tau_l < tau_r, got {l} and {h}", i + 1),
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let local = |field_needed: bool| -> Result<usize, ParamError> {
            match self.local {
                Some(m) if m >= 1 => Ok(m - 1),
                Some(m) => Err(ParamError::at(
                    "local",
                    format!("sensors are numbered from 1, got {m}"),
                )),
                None if field_needed => Err(ParamError::at(
                    "local",
                    "`fusion = \"local\"` needs `local = m` (1-based sensor number)",
                )),
                None => Ok(0),
            }
        };
        let fusion = match self.fusion {
            FusionParam::Federated => {
                if self.local.is_some() {
                    return Err(ParamError::at(
                        "local",
                        "`local` only applies to fusion = \"local\" or \"local-in-loop\"",
                    ));
                }
                Fusion::Federated
            }
            FusionParam::Local => Fusion::Local(local(true)?),
            FusionParam::LocalInLoop => Fusion::LocalInLoop(local(true)?),
        };
        let bias_blind =
            match (self.bias_model, self.bias_states.is_empty()) {
                (true, _) => None,
                (false, false) => Some(self.bias_states.clone()),
                (false, true) => return Err(ParamError::at(
                    "bias_states",
                    "`bias_model = false` needs the bias's state indices, e.g. bias_states = [2]",
                )),
            };
        let opts = TobitOptions {
            theta_denominator: match self.theta_denominator {
                ThetaDenominatorParam::SqrtR => ThetaDenominator::SqrtR,
                ThetaDenominatorParam::R => ThetaDenominator::R,
            },
            lambda_sign: match self.lambda_sign {
                LambdaSignParam::Minus => LambdaSign::Minus,
                LambdaSignParam::Plus => LambdaSign::Plus,
            },
        };
        Ok(Box::new(
            FederatedTobitScheme::new(
                cx.system.clone(),
                thresholds,
                noise_var(&self.noise_var, p)?,
                self.sharing.clone(),
                fusion,
                bias_blind,
                opts,
            )?
            .with_granted(self.granted)?,
        ))
    }
}

/// `round-robin-kf`.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RoundRobinKfParams {
    #[serde(default)]
    pub noise_var: Option<PerSensor>,
    /// Sensors granted per step (the bandwidth knob; 1: the paper's round-robin).
    #[serde(default = "one")]
    pub granted: f64,
}

impl SchemeParams for RoundRobinKfParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let p = cx.system.n_sensors();
        Ok(Box::new(
            RoundRobinKfScheme::new(cx.system.clone(), noise_var(&self.noise_var, p)?)?
                .with_granted(self.granted)?,
        ))
    }
}

const NOISE_VAR: ParamDoc = ParamDoc {
    name: "noise_var",
    values: "number or list (one per sensor), >= R",
    default: "sensor R",
    meaning: "run at this noise variance: the sensor adds N(0, noise_var - R), the same for every variant",
};

/// `granted`, the bandwidth knob of Geng et al.'s three schemes.
pub(crate) const GRANTED: ParamDoc = ParamDoc {
    name: "granted",
    values: "number in (0, N]",
    default: "1",
    meaning: "sensors granted per step: the round-robin token of eq. (5) moves on by this many sensors a step (slots floor((k-1) g)..floor(k g) - 1, mod N, send at step k); 1 is the paper's protocol, N every sensor every step, 1/T one sensor every T steps; 32 granted payload bits per step",
};

/// The knob `granted` on `[0.01, N]`: bits per step grow with it (32 per granted sensor).
pub(crate) const GRANTED_KNOB: registry::Knob = registry::Knob::rising(
    "granted",
    registry::Bound::Fixed(0.01),
    registry::Bound::PerSensor(1.0),
);

pub const ENTRY: SchemeEntry = SchemeEntry {
    kind: "federated-tobit",
    label: "FTKF-DB",
    summary:
        "Geng et al.: round-robin (one 32-bit reading per step; `granted` per step with the knob), zero-order hold and two-sided \
              censoring (6) at the center, local Tobit KFs (Theorem 1) fused federatedly with \
              reset (Theorem 2); estimator -> center is co-located (not counted)",
    params: &[
        ParamDoc {
            name: "tau",
            values: "number > 0",
            default: "none",
            meaning: "censoring region [-tau, tau] for every sensor",
        },
        ParamDoc {
            name: "tau_l",
            values: "number or list (one per sensor)",
            default: "-inf",
            meaning: "left censoring thresholds of eq. (6) (instead of tau)",
        },
        ParamDoc {
            name: "tau_r",
            values: "number or list (one per sensor)",
            default: "+inf",
            meaning: "right censoring thresholds of eq. (6) (instead of tau)",
        },
        NOISE_VAR,
        ParamDoc {
            name: "sharing",
            values: "list of p numbers > 0, sum 1",
            default: "1/p each",
            meaning: "information-sharing coefficients epsilon_m of (27)",
        },
        ParamDoc {
            name: "fusion",
            values: "\"federated\" | \"local\" | \"local-in-loop\"",
            default: "federated",
            meaning:
                "fused (26); one local filter alone (eps = 1, no reset); or local m inside the loop",
        },
        ParamDoc {
            name: "local",
            values: "integer 1..=p",
            default: "required for local",
            meaning: "which sensor's local filter (LTKF-DB-S<m>)",
        },
        ParamDoc {
            name: "bias_model",
            values: "true | false",
            default: "true",
            meaning: "false: the paper's FTKF, filter on x only; bias gets its open-loop prior",
        },
        ParamDoc {
            name: "bias_states",
            values: "list of state indices",
            default: "[]",
            meaning: "the bias states dropped when bias_model = false",
        },
        ParamDoc {
            name: "theta_denominator",
            values: "\"sqrt-r\" | \"r\"",
            default: "sqrt-r",
            meaning: "theta of lambda (14) and varphi (15): (tau - zeta)/sqrt(R) (correct) or /R (as printed); the censoring probabilities (9) use sqrt(R) under both, as printed",
        },
        ParamDoc {
            name: "lambda_sign",
            values: "\"minus\" | \"plus\"",
            default: "minus",
            meaning: "sign of the lambda term of (23): minus as (12) requires, plus as printed",
        },
        GRANTED,
    ],
    knob: Some(GRANTED_KNOB),
    applies: registry::Applies::ScalarLinearSensors,
    build: registry::parse_and_build::<FtkfParams>,
    example: "tau = 5.0",
    missing_packet: "a missing reading keeps the zero-order hold (Geng et al., eq. (4), as published): the last reading that arrived stays held and, held, is not fused again (that sensor's local filter only predicts); a scheduled sensor always sends, so nothing arriving is a loss, which carries no information: the exact reading of a loss too",
};

pub const ROUND_ROBIN_KF: SchemeEntry = SchemeEntry {
    kind: "round-robin-kf",
    label: "Round-robin KF (uncensored)",
    summary: "information bound of Geng et al.: KF on the same round-robin schedule with the \
              uncensored readings",
    params: &[NOISE_VAR, GRANTED],
    knob: Some(GRANTED_KNOB),
    applies: registry::Applies::ScalarLinearSensors,
    build: registry::parse_and_build::<RoundRobinKfParams>,
    example: "",
    missing_packet: "a missing reading keeps the zero-order hold: the last reading that arrived stays held and is not fused again (a scheduled sensor always sends, so nothing arriving is a loss, which carries no information)",
};
