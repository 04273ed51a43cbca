//! Scenario-file parameters of Zhang et al.'s (2016) scheme.
use super::{Activation, QuantizedInnovationScheme, QuantizerChoice};
use crate::scheme::registry::{
    self, BuildContext, ParamDoc, ParamError, SchemeEntry, SchemeParams,
};
use crate::scheme::Scheme;
use serde::{Deserialize, Serialize};

/// The quantizer family, as written in files.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum QuantizerKind {
    /// Zhang et al.'s (2016) 4l + 1 levels with the dynamic strategy (needs `bits`, takes `flag_zone`).
    Zhang,
    /// You et al.: 2^c + 1 Lloyd-Max levels (needs `bits`).
    You,
    /// Msechu et al.: 2^c Lloyd-Max levels (needs `bits`; 1 bit is SOI-KF's sign).
    Msechu,
    /// SOI-KF's sign of the innovation (= `msechu` with 1 bit).
    Sign,
    /// Any number of Lloyd-Max levels (needs `levels`).
    LloydMax,
    /// 32-bit measurements and an EKF.
    Analog,
}

/// `quantized-innovation`.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QuantizedParams {
    pub quantizer: QuantizerKind,
    #[serde(default)]
    pub bits: Option<u8>,
    #[serde(default)]
    pub levels: Option<usize>,
    #[serde(default)]
    pub flag_zone: Option<bool>,
    /// Activate the `activate` sensors nearest to the predicted position (default: all).
    #[serde(default)]
    pub activate: Option<usize>,
}

impl QuantizedParams {
    /// The quantizer these parameters name, with every combination checked.
    pub fn choice(&self) -> Result<QuantizerChoice, ParamError> {
        let name = serde_name(self.quantizer);
        let need_bits = || {
            self.bits
                .ok_or_else(|| ParamError::at("bits", format!("quantizer {name:?} needs `bits`")))
        };
        let unused = |field: &str, present: bool| {
            if present {
                Err(ParamError::at(
                    field,
                    format!("not a parameter of quantizer {name:?}"),
                ))
            } else {
                Ok(())
            }
        };
        Ok(match self.quantizer {
            QuantizerKind::Zhang => {
                unused("levels", self.levels.is_some())?;
                QuantizerChoice::Zhang {
                    bits: need_bits()?,
                    flag_zone: self.flag_zone.unwrap_or(true),
                }
            }
            QuantizerKind::You | QuantizerKind::Msechu | QuantizerKind::Sign => {
                unused("levels", self.levels.is_some())?;
                unused("flag_zone", self.flag_zone.is_some())?;
                match self.quantizer {
                    QuantizerKind::You => QuantizerChoice::You { bits: need_bits()? },
                    QuantizerKind::Msechu => QuantizerChoice::Msechu { bits: need_bits()? },
                    _ => {
                        unused("bits", self.bits.is_some())?;
                        QuantizerChoice::Msechu { bits: 1 }
                    }
                }
            }
            QuantizerKind::LloydMax => {
                unused("bits", self.bits.is_some())?;
                unused("flag_zone", self.flag_zone.is_some())?;
                QuantizerChoice::LloydMax {
                    levels: self.levels.ok_or_else(|| {
                        ParamError::at("levels", "quantizer \"lloyd-max\" needs `levels`")
                    })?,
                }
            }
            QuantizerKind::Analog => {
                unused("bits", self.bits.is_some())?;
                unused("levels", self.levels.is_some())?;
                unused("flag_zone", self.flag_zone.is_some())?;
                QuantizerChoice::Analog
            }
        })
    }
}

fn serde_name(k: QuantizerKind) -> &'static str {
    match k {
        QuantizerKind::Zhang => "zhang",
        QuantizerKind::You => "you",
        QuantizerKind::Msechu => "msechu",
        QuantizerKind::Sign => "sign",
        QuantizerKind::LloydMax => "lloyd-max",
        QuantizerKind::Analog => "analog",
    }
}

impl SchemeParams for QuantizedParams {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError> {
        let choice = self.choice()?;
        let system = cx.system;
        let activation = match self.activate {
            None => Activation::All,
            Some(count) => {
                if count == 0 || count > system.n_sensors() {
                    return Err(ParamError::at(
                        "activate",
                        format!("expected 1..={} sensors, got {count}", system.n_sensors()),
                    ));
                }
                let indices = system.sensors[0].target_indices().ok_or_else(|| {
                    ParamError::at(
                        "activate",
                        "nearest-sensor activation needs placed (range or rss) sensors",
                    )
                })?;
                Activation::Nearest { count, indices }
            }
        };
        Ok(Box::new(QuantizedInnovationScheme::new(
            system.clone(),
            &choice,
            activation,
        )?))
    }
}

pub const ENTRY: SchemeEntry = SchemeEntry {
    kind: "quantized-innovation",
    label: "Quantized innovation",
    summary: "Zhang et al. (2016): activated sensors quantize their normalized innovation (eq. (2)-(5)) into real 802.15.4 frames; information-form fusion (eq. (9)-(14)); scalar sensors",
    params: &[
        ParamDoc {
            name: "quantizer",
            values: "zhang|you|msechu|sign|lloyd-max|analog",
            default: "required",
            meaning: "zhang: 4l+1 levels, dynamic strategy (Tables 1-4); you: 2^c+1 Lloyd-Max; msechu: 2^c Lloyd-Max; sign: SOI-KF; lloyd-max: any L; analog: EKF on 32-bit z",
        },
        ParamDoc {
            name: "bits",
            values: "integer (zhang: 1-3)",
            default: "required*",
            meaning: "payload bits c_i; for zhang, you, msechu only",
        },
        ParamDoc {
            name: "levels",
            values: "integer >= 2",
            default: "required*",
            meaning: "number of levels; for lloyd-max only",
        },
        ParamDoc {
            name: "flag_zone",
            values: "true|false",
            default: "true",
            meaning: "zhang: the flag-zone strategy (Table 2) or not (Table 4)",
        },
        ParamDoc {
            name: "activate",
            values: "integer in 1..=N",
            default: "all",
            meaning: "activate the k sensors nearest to the predicted position (placed sensors)",
        },
    ],
    knob: Some(registry::Knob {
        name: "bits",
        lo: registry::Bound::Fixed(1.0),
        // Values that do not build (zhang above 3) end the range on the calibrator's walk.
        hi: registry::Bound::Fixed(8.0),
        scale: registry::Scale::Linear,
        integer: true,
        grows: registry::Direction::MoreBits,
    }),
    applies: registry::Applies::ScalarMeasurements,
    build: registry::parse_and_build::<QuantizedParams>,
    example: "quantizer = \"zhang\"\nbits = 1",
    missing_packet: "a missing frame is read as the quantizer's silent level (a small innovation, Zhang et al.): a loss looks like a reading near the prediction",
};
