//! Scenario-file parameters of the event-triggered baselines. Each kind has one knob:
//! `delta` (innovation trigger, send-on-delta) or `tau` (stochastic triggers); all send less
//! as it grows and send everything at 0.
use super::{
    InnovationTriggerScheme, SendOnDeltaScheme, SilenceModel, StochasticTrigger,
    StochasticTriggerScheme, TriggerLoop,
};
use crate::scheme::link_loss::LinkLoss;
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
    /// Loss-aware fusion: each link's loss probability the center assumes (absent: published).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_loss: Option<LinkLoss>,
}

impl SchemeParams for InnovationTriggerParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(
            InnovationTriggerScheme::new(cx.system.clone(), self.delta)?
                .with_link_loss(per_sensor(&self.link_loss, cx)?)?,
        ))
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
    /// Loss-aware fusion: each link's loss probability the center assumes (absent: published).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_loss: Option<LinkLoss>,
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
    Ok(Box::new(
        StochasticTriggerScheme::new(cx.system.clone(), p.trigger(cx, kind)?)
            .with_link_loss(per_sensor(&p.link_loss, cx)?)?,
    ))
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
    /// Loss-aware fusion: each link's loss probability the center assumes (absent: published).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_loss: Option<LinkLoss>,
}

impl SchemeParams for SendOnDeltaParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(
            SendOnDeltaScheme::new(cx.system.clone(), self.delta, self.silence)?
                .with_link_loss(per_sensor(&self.link_loss, cx)?)?,
        ))
    }
}

/// Each sensor's loss probability from a written `link_loss`.
fn per_sensor(
    link_loss: &Option<LinkLoss>,
    cx: &BuildContext,
) -> Result<Option<Vec<f64>>, ParamError> {
    Ok(link_loss.as_ref().map(|l| l.per_sensor(cx)).transpose()?)
}

/// `link_loss` of every event-triggered kind.
const fn link_loss(meaning: &'static str) -> ParamDoc {
    ParamDoc {
        name: "link_loss",
        values: crate::scheme::link_loss::VALUES,
        default: "none",
        meaning,
    }
}

const TAU: ParamDoc = ParamDoc {
    name: "tau",
    values: "number >= 0",
    default: "none",
    meaning: "Y_i = R_i^-1 / tau^2 (tau = 0: always send); give `tau` or `Y`",
};

const LINK_LOSS_STOCHASTIC: ParamDoc = link_loss(
    "loss-aware fusion (beyond the paper): the loss probability p the center assumes; nothing arriving has likelihood p + (1 - p) exp(-u^T Y u / 2), the posterior mixture moment-matched to one Gaussian; absent or 0: published",
);

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
    params: &[
        ParamDoc {
            name: "delta",
            values: "number >= 0",
            default: "required",
            meaning: "threshold on the largest whitened innovation component (0: always send)",
        },
        link_loss("loss-aware fusion (beyond the paper): the loss probability p the center assumes; nothing arriving is {||eps||_inf <= delta} or {sent and lost}, Theorem 2's beta replaced by 1 - v_p, v_p = (P_in v + p E[eps^2 1{out}]) / (P_in + p P_out); absent or 0: published"),
    ],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<InnovationTriggerParams>,
    example: "delta = 1.0",
    missing_packet: "a missing packet is a silence: the published center updates with the trigger's information that the innovation stayed below delta (Wu et al. 2013), which a loss makes wrong; with link_loss = p the whitened innovation's variance given nothing arrived mixes the in-band and the lost out-of-band moments",
};

pub const STOCHASTIC_OPEN: SchemeEntry = SchemeEntry {
    kind: "stochastic-trigger-open",
    label: "Stochastic trigger, open loop (Han 2015)",
    summary: "Han et al., IEEE TAC 2015: silent iff zeta <= exp(-z^T Y z / 2), exact MMSE KF with silence noise R + Y^-1 (Theorem 1); no feedback",
    params: &[TAU, Y, LINK_LOSS_STOCHASTIC],
    knob: Some(registry::Knob::threshold("tau")),
    applies: registry::Applies::Any,
    build: build_open,
    example: "tau = 1.0",
    missing_packet: "a missing packet is a silence: the published center updates with the stochastic trigger's likelihood of not sending (Han et al. 2015), which a loss makes wrong; with link_loss = p the likelihood is p + (1 - p) exp(-u^T Y u / 2), a two-Gaussian mixture moment-matched to one",
};

pub const STOCHASTIC_CLOSED: SchemeEntry = SchemeEntry {
    kind: "stochastic-trigger-closed",
    label: "Stochastic trigger, closed loop (Han 2015)",
    summary: "Han et al., IEEE TAC 2015: silent iff zeta <= exp(-nu^T Y nu / 2) on the innovation, exact MMSE KF (Theorem 2); center feeds back x^-",
    params: &[TAU, Y, LINK_LOSS_STOCHASTIC],
    knob: Some(registry::Knob::threshold("tau")),
    applies: registry::Applies::Any,
    build: build_closed,
    example: "tau = 1.0",
    missing_packet: "a missing packet is a silence: the published center updates with the stochastic trigger's likelihood of not sending (Han et al. 2015), which a loss makes wrong; with link_loss = p the likelihood is p + (1 - p) exp(-u^T Y u / 2), a two-Gaussian mixture moment-matched to one",
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
        link_loss("loss-aware fusion (uniform silences): the loss probability p the center assumes; nothing arriving mixes the uniform reading (the sensor's reference is still the last received value and z in its band), z outside the band and lost, and no information (stale reference); absent or 0: published; no effect with silence = ignore"),
    ],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<SendOnDeltaParams>,
    example: "delta = 1.0",
    missing_packet: "a missing packet is a silence: the published center treats the reading as within delta of the last one it received, which a loss makes wrong (silence = ignore is not); with link_loss = p it mixes that reading with outside-the-band-and-lost and reference-gone-stale, weighted by the probability that the sensor's reference is still the last received value",
};
