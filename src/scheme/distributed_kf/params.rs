//! Scenario-file parameters of Dormann et al.'s schemes.
use super::DistributedKfScheme;
use crate::linalg::Matrix;
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// `dkf`: no parameters.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FullRateParams {}

impl SchemeParams for FullRateParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(DistributedKfScheme::full_rate(
            cx.system.clone(),
            cx.steps,
        )?))
    }
}

/// `dkf-alg1-random`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Alg1RandomParams {
    pub rate: f64,
}

impl SchemeParams for Alg1RandomParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(DistributedKfScheme::alg1_random(
            cx.system.clone(),
            cx.steps,
            self.rate,
        )?))
    }
}

/// `dkf-alg1-event`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Alg1EventParams {
    pub alpha: f64,
}

impl SchemeParams for Alg1EventParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        Ok(Box::new(DistributedKfScheme::alg1_event(
            cx.system.clone(),
            cx.steps,
            self.alpha,
        )?))
    }
}

/// `dkf-alg2-event`: the bound as `b` (B = b I) or as the matrix `B`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Alg2EventParams {
    pub alpha: f64,
    #[serde(default)]
    pub b: Option<f64>,
    #[serde(default, rename = "B")]
    pub b_matrix: Option<Vec<Vec<f64>>>,
    /// Loss-aware center (beyond the paper): a sensor silent twice or more may have been
    /// lost, so its extrapolation is inflated by B plus its computed second moment.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub loss_aware: bool,
}

impl SchemeParams for Alg2EventParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let n = cx.system.state_dim();
        let b = match (self.b, &self.b_matrix) {
            (Some(b), None) => {
                if !(b.is_finite() && b > 0.0) {
                    return Err(ParamError::at(
                        "b",
                        format!("expected a positive number (B = b I), got {b}"),
                    ));
                }
                Matrix::identity(n, n) * b
            }
            (None, Some(rows)) => registry::matrix_param("B", rows)?,
            _ => {
                return Err(ParamError::whole(
                    "give exactly one of `b` (B = b I) and `B`",
                ))
            }
        };
        Ok(Box::new(
            DistributedKfScheme::alg2_event(cx.system.clone(), cx.steps, self.alpha, b)?
                .with_loss_aware(self.loss_aware),
        ))
    }
}

const ALPHA: ParamDoc = ParamDoc {
    name: "alpha",
    values: "number >= 0",
    default: "required",
    meaning: "event threshold on the norm of the estimate change",
};

pub const FULL_RATE: SchemeEntry = SchemeEntry {
    kind: "dkf",
    label: "Globalized DKF (full rate)",
    summary: "globalized distributed KF, every sensor sends its estimate every step (Dormann et al., Section II)",
    params: &[],
    knob: None,
    applies: registry::Applies::LinearSensors,
    build: registry::parse_and_build::<FullRateParams>,
    example: "",
    missing_packet: "a missing estimate is an omission (Dormann et al.): the center uses its prediction of the local estimate (Alg. 1, eq. (10)-(11), exact when the previous estimate arrived); a second one missing in a row can only be a loss: the center then uses the debiased extrapolation of the last estimate to arrive (Section IV) and inflates the covariance by that extrapolation's computed second moment",
};

pub const ALG1_RANDOM: SchemeEntry = SchemeEntry {
    kind: "dkf-alg1-random",
    label: "Algorithm 1 (random)",
    summary: "Algorithm 1 (eq. (10)-(11)): a sensor silent at k-1 must send, otherwise sends with p = 2 - 1/rate",
    params: &[ParamDoc {
        name: "rate",
        values: "number in [0.5, 1]",
        default: "required",
        meaning: "average communication rate",
    }],
    knob: Some(registry::Knob::rising(
        "rate",
        registry::Bound::Fixed(0.5),
        registry::Bound::Fixed(1.0),
    )),
    applies: registry::Applies::LinearSensors,
    build: registry::parse_and_build::<Alg1RandomParams>,
    example: "rate = 0.75",
    missing_packet: "a missing estimate is an omission: the center predicts the local estimate (Alg. 1, exact after an estimate that arrived); random omissions carry no information, so a loss misleads nothing; a second one missing in a row is a loss: debiased extrapolation of the last estimate to arrive, covariance inflated by its computed second moment (exact for one such sensor)",
};

pub const ALG1_EVENT: SchemeEntry = SchemeEntry {
    kind: "dkf-alg1-event",
    label: "Algorithm 1 (event-based)",
    summary: "Algorithm 1 with the event test (12) on the standard local KF (Dormann et al.)",
    params: &[ALPHA],
    knob: Some(registry::Knob::threshold("alpha")),
    applies: registry::Applies::LinearSensors,
    build: registry::parse_and_build::<Alg1EventParams>,
    example: "alpha = 0.3",
    missing_packet: "a missing estimate is an omission: the center predicts the local estimate (Alg. 1), which with event-based omission assumes the local estimate stayed close; a loss breaks that assumption, and the sensor (no acknowledgement) may omit the next one too; a second one missing in a row is a loss: debiased extrapolation of the last estimate to arrive, covariance inflated by its computed second moment",
};

pub const ALG2_EVENT: SchemeEntry = SchemeEntry {
    kind: "dkf-alg2-event",
    label: "Algorithm 2 (event-based)",
    summary: "Algorithm 2 (Section IV): test (13), debiasing (14), inflated covariance; needs an invertible F",
    params: &[
        ALPHA,
        ParamDoc {
            name: "b",
            values: "number > 0",
            default: "none",
            meaning: "the bound B = b I (give `b` or `B`)",
        },
        ParamDoc {
            name: "B",
            values: "n x n SPD matrix",
            default: "none",
            meaning: "the bound B as a matrix (give `b` or `B`)",
        },
        ParamDoc {
            name: "loss_aware",
            values: "true | false",
            default: "false",
            meaning: "loss-aware fusion (beyond the paper): a sensor silent twice or more may have been lost, so its extrapolation is inflated by B plus its computed second moment; false: Algorithm 2's B alone",
        },
    ],
    knob: Some(registry::Knob::threshold("alpha")),
    applies: registry::Applies::LinearSensors,
    build: registry::parse_and_build::<Alg2EventParams>,
    example: "alpha = 0.4\nb = 10.0",
    missing_packet: "a missing estimate is an omission: the center predicts the local estimate (debiased) and inflates its covariance by the event bound (Alg. 2), which assumes the sensor's test bounded it; a loss breaks that (the sensor, without acknowledgement, bounds against the estimate it sent); with loss_aware = true the inflation is B plus the extrapolation's computed second moment",
};
