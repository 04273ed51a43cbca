//! Scenario-file parameters of the event-triggered baselines. Each kind has one knob:
//! `delta` (innovation trigger, send-on-delta) or `tau` (stochastic triggers); all send less
//! as it grows and send everything at 0.
use super::{
    InnovationTriggerScheme, SendOnDeltaScheme, SilenceModel, StochasticTrigger,
    StochasticTriggerScheme, TriggerLoop,
};
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// `innovation-trigger-kf`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InnovationTriggerParams {
    /// Threshold on the largest whitened innovation component, >= 0.
    pub delta: f64,
}

impl SchemeParams for InnovationTriggerParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(InnovationTriggerScheme::new(
            cx.system.clone(),
            self.delta,
        )?))
    }
}

/// `stochastic-trigger-open` / `stochastic-trigger-closed`: exactly one of `tau`
/// (Y_i = R_i^{-1} / tau^2) and `Y`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StochasticTriggerParams {
    #[serde(default)]
    pub tau: Option<f64>,
    #[serde(default, rename = "Y")]
    pub y: Option<Vec<Vec<f64>>>,
}

impl StochasticTriggerParams {
    /// The trigger these parameters describe, for either loop.
    pub fn trigger(
        &self,
        cx: &BuildContext,
        kind: TriggerLoop,
    ) -> Result<StochasticTrigger, ParamError> {
        match (self.tau, &self.y) {
            (Some(tau), None) => Ok(StochasticTrigger::with_tau(cx.system, kind, tau)?),
            (None, Some(rows)) => Ok(StochasticTrigger::with_matrix(
                cx.system,
                kind,
                registry::matrix_param("Y", rows)?,
            )?),
            _ => Err(ParamError::whole(
                "give exactly one of `tau` (Y = R^-1 / tau^2) and `Y`",
            )),
        }
    }
}

fn build_stochastic(
    table: toml::Table,
    cx: &BuildContext,
    kind: TriggerLoop,
) -> Result<Box<dyn Scheme>, ParamError> {
    let p: StochasticTriggerParams = registry::parse(table)?;
    Ok(Box::new(StochasticTriggerScheme::new(
        cx.system.clone(),
        p.trigger(cx, kind)?,
    )))
}

fn build_open(table: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    build_stochastic(table, cx, TriggerLoop::Open)
}

fn build_closed(table: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    build_stochastic(table, cx, TriggerLoop::Closed)
}

/// `send-on-delta`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SendOnDeltaParams {
    pub delta: f64,
    #[serde(default)]
    pub silence: SilenceModel,
}

impl SchemeParams for SendOnDeltaParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(SendOnDeltaScheme::new(
            cx.system.clone(),
            self.delta,
            self.silence,
        )?))
    }
}

const TAU: ParamDoc = ParamDoc {
    name: "tau",
    values: "number >= 0",
    default: "none",
    meaning: "Y_i = R_i^-1 / tau^2 (tau = 0: always send); give `tau` or `Y`",
};

const Y: ParamDoc = ParamDoc {
    name: "Y",
    values: "m x m SPD matrix",
    default: "none",
    meaning: "one trigger matrix Y for every sensor (all of dimension m); give `tau` or `Y`",
};

pub const INNOVATION: SchemeEntry = SchemeEntry {
    kind: "innovation-trigger-kf",
    label: "Innovation trigger (Wu 2013)",
    summary: "Wu, Jia, Johansson, Shi, IEEE TAC 2013: send z when ||F^T (z - C x^-)||_inf > delta; silence through the Gaussian approximation of the truncated innovation (Theorem 2); center feeds back x^- and P^-",
    params: &[ParamDoc {
        name: "delta",
        values: "number >= 0",
        default: "required",
        meaning: "threshold on the largest whitened innovation component (0: always send)",
    }],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<InnovationTriggerParams>,
    example: "delta = 1.0",
    missing_packet: "a missing packet is a silence: the center updates with the trigger's information that the innovation stayed below delta (Wu et al. 2013), which a loss makes wrong",
};

pub const STOCHASTIC_OPEN: SchemeEntry = SchemeEntry {
    kind: "stochastic-trigger-open",
    label: "Stochastic trigger, open loop (Han 2015)",
    summary: "Han et al., IEEE TAC 2015: silent iff zeta <= exp(-z^T Y z / 2), exact MMSE KF with silence noise R + Y^-1 (Theorem 1); no feedback",
    params: &[TAU, Y],
    knob: Some(registry::Knob::threshold("tau")),
    applies: registry::Applies::Any,
    build: build_open,
    example: "tau = 1.0",
    missing_packet: "a missing packet is a silence: the center updates with the stochastic trigger's likelihood of not sending (Han et al. 2015), which a loss makes wrong",
};

pub const STOCHASTIC_CLOSED: SchemeEntry = SchemeEntry {
    kind: "stochastic-trigger-closed",
    label: "Stochastic trigger, closed loop (Han 2015)",
    summary: "Han et al., IEEE TAC 2015: silent iff zeta <= exp(-nu^T Y nu / 2) on the innovation, exact MMSE KF (Theorem 2); center feeds back x^-",
    params: &[TAU, Y],
    knob: Some(registry::Knob::threshold("tau")),
    applies: registry::Applies::Any,
    build: build_closed,
    example: "tau = 1.0",
    missing_packet: "a missing packet is a silence: the center updates with the stochastic trigger's likelihood of not sending (Han et al. 2015), which a loss makes wrong",
};

pub const SEND_ON_DELTA: SchemeEntry = SchemeEntry {
    kind: "send-on-delta",
    label: "Send-on-delta",
    summary: "send z when ||z - z_last_sent||_inf > delta; silence ignored or read as z_last with noise R + delta^2/3 I",
    params: &[
        ParamDoc {
            name: "delta",
            values: "number >= 0",
            default: "required",
            meaning: "change of the measurement, in any component, that triggers a send",
        },
        ParamDoc {
            name: "silence",
            values: "uniform|ignore",
            default: "uniform",
            meaning: "uniform: silence is z_last with extra noise delta^2/3; ignore: no measurement",
        },
    ],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<SendOnDeltaParams>,
    example: "delta = 1.0",
    missing_packet: "a missing packet is a silence: the center treats the reading as within delta of the last one it received, which a loss makes wrong",
};
