//! Scenario-file parameters of the centralized baselines.
use super::CentralizedScheme;
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// `centralized-kf`: no parameters.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AllParams {}

impl SchemeParams for AllParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(CentralizedScheme::new(cx.system.clone(), 1.0)?))
    }
}

/// `centralized-kf-random`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RandomParams {
    /// Probability that each measurement is sent, in (0, 1].
    pub rate: f64,
}

impl SchemeParams for RandomParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(CentralizedScheme::new(
            cx.system.clone(),
            self.rate,
        )?))
    }
}

pub const ALL: SchemeEntry = SchemeEntry {
    kind: "centralized-kf",
    label: "Centralized KF (all data)",
    summary:
        "KF at the fusion center with every raw measurement (32 bits per component): the bound",
    params: &[],
    knob: None,
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<AllParams>,
    example: "",
    missing_packet: "a missing measurement is a step without it (time update only): with every sensor sending, a loss costs information but misleads nothing",
};

pub const RANDOM: SchemeEntry = SchemeEntry {
    kind: "centralized-kf-random",
    label: "Centralized KF (random)",
    summary:
        "each measurement sent with probability `rate`, otherwise lost (Dormann et al., Section V)",
    params: &[ParamDoc {
        name: "rate",
        values: "number in (0, 1]",
        default: "required",
        meaning: "probability that a sensor sends its measurement at a step",
    }],
    knob: Some(registry::Knob::rising(
        "rate",
        registry::Bound::Fixed(1e-3),
        registry::Bound::Fixed(1.0),
    )),
    applies: registry::Applies::Any,
    build: registry::parse_and_build::<RandomParams>,
    example: "rate = 0.5",
    missing_packet: "a missing measurement is a step without it (time update only); the random choice to send carries no information, so neither does a loss",
};
