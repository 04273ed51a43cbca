//! Scenario-file parameters of the estimate-fusion baselines: one knob, `delta`.
use super::{EstimateFusionScheme, FusionRule};
use crate::scheme::registry::{self, BuildContext, ParamDoc, ParamError, SchemeEntry};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// `ci-fusion` / `naive-fusion`.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EstimateFusionParams {
    /// Event threshold on the Mahalanobis distance between the local estimate and the
    /// center's copy of it (0: send every step).
    #[serde(default)]
    pub delta: f64,
}

impl EstimateFusionParams {
    pub fn build_with(
        &self,
        cx: &BuildContext,
        rule: FusionRule,
    ) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(EstimateFusionScheme::new(
            cx.system.clone(),
            rule,
            self.delta,
        )?))
    }
}

fn build_ci(table: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    registry::parse::<EstimateFusionParams>(table)?
        .build_with(cx, FusionRule::CovarianceIntersection)
}

fn build_naive(table: toml::Table, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
    registry::parse::<EstimateFusionParams>(table)?.build_with(cx, FusionRule::NaiveSum)
}

const DELTA: ParamDoc = ParamDoc {
    name: "delta",
    values: "number >= 0",
    default: "0",
    meaning: "send when (x - x_copy)^T P^-1 (x - x_copy) > delta^2, x_copy the center's predicted copy (0: every step)",
};

pub const CI: SchemeEntry = SchemeEntry {
    kind: "ci-fusion",
    label: "Local KFs + covariance intersection",
    summary: "sensors run local KFs and send x (and P for nonlinear sensors); covariance intersection with the trace-minimizing weights (Julier & Uhlmann 1997)",
    params: &[DELTA],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: build_ci,
    example: "",
    missing_packet: "a missing estimate: the center predicts that sensor's last estimate forward",
};

pub const NAIVE: SchemeEntry = SchemeEntry {
    kind: "naive-fusion",
    label: "Local KFs + naive information sum",
    summary: "sensors run local KFs and send x (and P for nonlinear sensors); the center adds their informations as if independent (overconfident)",
    params: &[DELTA],
    knob: Some(registry::Knob::threshold("delta")),
    applies: registry::Applies::Any,
    build: build_naive,
    example: "",
    missing_packet: "a missing estimate: the center predicts that sensor's last estimate forward",
};
