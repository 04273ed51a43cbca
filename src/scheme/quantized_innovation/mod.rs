//! Zhang, Li and Liu (2016), "Distributed state estimation and data fusion in wireless sensor
//! networks using multi-level quantized innovation": activated sensors quantize their
//! normalized innovation (eq. (3)-(5)) against the fusion center's y_hat and Delta (eq. (2)),
//! send the level as a real IEEE 802.15.4 frame (Tables 1-4) or stay silent on the centre
//! level, and the fusion center fuses the quantized innovations of all activated sensors in
//! information form (eq. (9)-(14), with (13)'s denominator sqrt(h P h^T + R) as derived in
//! (A24)). The same fusion runs with the baselines' quantizers (SOI-KF's sign, Msechu's 2^c
//! levels, You's 2^c + 1 levels) and, for reference, with analog measurements (the EKF).
pub mod params;

use crate::filter::information::{h_p_ht, Information};
use crate::filter::{kf, Gaussian};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::link::codec802154::{
    DynamicCodec, FixedLengthCodec, LevelCodec, LinkAddressing, Strategy,
};
use crate::link::quantizer::{
    CellTable, InnovationQuantizer, Level, MsechuQuantizer, SignQuantizer, YouQuantizer,
};
use crate::link::{Message, Received, Transmission};
use crate::model::MeasurementModel;
use crate::scheme::{
    Feedback, FusionCenter, InnovationReference, Scheme, SchemeError, SchemeInstance, SensorNode,
    System,
};
use rand::RngCore;
use std::sync::Arc;

/// PAN id and fusion-center short address of the simulated network; sensor i has short
/// address i + 1.
const PAN_ID: u16 = 0x0003;
const FUSION_CENTER_ADDRESS: u16 = 0x0000;

/// A quantizer together with the codec that carries its levels.
pub struct QuantizerLink {
    pub quantizer: Box<dyn InnovationQuantizer + Send + Sync>,
    pub codec: Box<dyn LevelCodec + Send + Sync>,
}

impl std::fmt::Debug for QuantizerLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "QuantizerLink({} levels)", self.quantizer.levels())
    }
}

/// Which quantizer the activated sensors use.
#[derive(Debug, Clone, PartialEq)]
pub enum QuantizerChoice {
    /// Zhang et al.'s (2016) 4l + 1 levels with the dynamic transmission strategy, at most `bits` payload
    /// bits (Tables 2 and 4: 5/21/69 levels with the flag zone, 5/13/29 without).
    Zhang { bits: u8, flag_zone: bool },
    /// You et al.: 2^c + 1 Lloyd-Max levels, silent centre, c-bit fixed-length code.
    You { bits: u8 },
    /// Msechu et al.: 2^c Lloyd-Max levels, always sent, c-bit code (c = 1 is SOI-KF's sign).
    Msechu { bits: u8 },
    /// Any number of Lloyd-Max levels (silent centre when odd), fixed-length code.
    LloydMax { levels: usize },
    /// Analog measurements (32-bit floats): the EKF the paper compares against.
    Analog,
}

impl QuantizerChoice {
    /// Builds the quantizer and its codec; `None` for analog.
    pub fn build(&self) -> Result<Option<QuantizerLink>, SchemeError> {
        let link = LinkAddressing::new(PAN_ID, FUSION_CENTER_ADDRESS)
            .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
        let q = |e: crate::link::quantizer::QuantizerError| SchemeError::Unsupported(e.to_string());
        let c = |e: crate::link::codec802154::CodecError| SchemeError::Unsupported(e.to_string());
        Ok(Some(match *self {
            QuantizerChoice::Zhang { bits, flag_zone } => {
                let strategy = if flag_zone {
                    Strategy::FlagZone
                } else {
                    Strategy::NoFlagZone
                };
                let codec = DynamicCodec::new(strategy, bits, link).map_err(c)?;
                QuantizerLink {
                    quantizer: Box::new(codec.quantizer().map_err(q)?),
                    codec: Box::new(codec),
                }
            }
            QuantizerChoice::You { bits } => QuantizerLink {
                quantizer: Box::new(YouQuantizer::new(bits).map_err(q)?),
                codec: Box::new(FixedLengthCodec::you(bits, link).map_err(c)?),
            },
            QuantizerChoice::Msechu { bits: 1 } => QuantizerLink {
                quantizer: Box::new(SignQuantizer::new()),
                codec: Box::new(FixedLengthCodec::sign(link)),
            },
            QuantizerChoice::Msechu { bits } => QuantizerLink {
                quantizer: Box::new(MsechuQuantizer::new(bits).map_err(q)?),
                codec: Box::new(FixedLengthCodec::msechu(bits, link).map_err(c)?),
            },
            QuantizerChoice::LloydMax { levels } => QuantizerLink {
                quantizer: Box::new(GenericLloydMax::new(levels).map_err(q)?),
                codec: Box::new(FixedLengthCodec::new(levels, levels % 2 == 1, link).map_err(c)?),
            },
            QuantizerChoice::Analog => return Ok(None),
        }))
    }
}

/// Lloyd-Max quantizer with any number of levels; the centre level of an odd count is silent.
#[derive(Debug, Clone)]
struct GenericLloydMax {
    table: CellTable,
}

impl GenericLloydMax {
    fn new(levels: usize) -> Result<Self, crate::link::quantizer::QuantizerError> {
        Ok(Self {
            table: CellTable::lloyd_max(levels)?,
        })
    }
}

impl InnovationQuantizer for GenericLloydMax {
    fn table(&self) -> &CellTable {
        &self.table
    }
    fn is_silent(&self, level: Level) -> bool {
        self.table.levels() % 2 == 1 && level.index() == self.table.levels() / 2
    }
}

/// Which sensors the fusion center activates at each step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Activation {
    /// Every sensor.
    All,
    /// The `count` sensors nearest to the predicted target position (Zhang et al. (2016), Section 6 keeps
    /// the three nearest active; the fusion center can only know the prediction). Needs
    /// sensors with positions and the target's position at `indices` of the state.
    Nearest { count: usize, indices: [usize; 2] },
}

/// Sensor node: quantizes ψ = (y - y_hat) / Delta (eq. (3)) when activated, encodes the
/// level into a frame, stays silent on the centre level. Analog sensors send z itself.
pub struct QuantizingSensor {
    index: usize,
    sensor: Arc<dyn MeasurementModel>,
    link: Option<Arc<QuantizerLink>>,
    sequence: u8,
}

impl QuantizingSensor {
    pub fn new(
        index: usize,
        sensor: Arc<dyn MeasurementModel>,
        link: Option<Arc<QuantizerLink>>,
    ) -> Self {
        Self {
            index,
            sensor,
            link,
            sequence: 0,
        }
    }

    fn address(&self) -> u16 {
        self.index as u16 + 1
    }
}

impl SensorNode for QuantizingSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        kf::check_measurement(self.sensor.as_ref(), z)?;
        let reference = match feedback {
            Some(Feedback::InnovationReference(refs)) => refs.get(self.index).copied().flatten(),
            _ => {
                return Err(SchemeError::Protocol {
                    sensor: self.index,
                    message: "needs y_hat and Delta from the fusion center (eq. (2))".into(),
                })
            }
        };
        let Some(r) = reference else {
            return Ok(Transmission::Silent); // not activated at this step
        };
        let Some(link) = &self.link else {
            return Ok(Transmission::Send(Message::Measurement(z.clone())));
        };
        let psi = (z[0] - r.y_hat) / r.delta; // eq. (3)
        let level = link.quantizer.quantize(psi); // eq. (4)-(5)
        self.sequence = self.sequence.wrapping_add(1);
        let frame = link
            .codec
            .encode(level, self.address(), self.sequence)
            .map_err(|e| SchemeError::Protocol {
                sensor: self.index,
                message: e.to_string(),
            })?;
        Ok(match frame {
            None => Transmission::Silent,
            Some(octets) => {
                let payload_bits = u32::from(link.codec.payload_bits(level).map_err(|e| {
                    SchemeError::Protocol {
                        sensor: self.index,
                        message: e.to_string(),
                    }
                })?);
                Transmission::Send(Message::Frame {
                    octets,
                    payload_bits,
                })
            }
        })
    }
}

/// What the fusion center told an activated sensor at this step, kept to fuse its answer
/// (its Jacobian row is in the center's `h`, by sensor index).
#[derive(Debug, Clone, Copy)]
struct Activated {
    index: usize,
    y_hat: f64,
    delta: f64,
}

/// The fusion center's per-step buffers, sized at construction so a step allocates nothing
/// for linear sensors.
#[derive(Debug, Clone)]
struct CenterWork {
    predict: kf::PredictWork,
    /// The fused information (eq. (9), (12)).
    info: Information,
    /// Storage for the Cholesky factors.
    factor: Matrix,
    /// Sensor i's Jacobian row at the prediction.
    h: Vec<Matrix>,
    /// (distance, sensor) for the nearest-sensor activation.
    by_distance: Vec<(f64, usize)>,
    /// The activated sensors, in activation order.
    chosen: Vec<usize>,
}

impl CenterWork {
    fn new(system: &System) -> Self {
        let (n, m) = (system.prior.dim(), system.n_sensors());
        Self {
            predict: kf::PredictWork::new(n),
            info: Information {
                matrix: Matrix::zeros(n, n),
                vector: Vector::zeros(n),
            },
            factor: Matrix::zeros(n, n),
            h: system
                .sensors
                .iter()
                .map(|s| Matrix::zeros(s.meas_dim(), n))
                .collect(),
            by_distance: Vec::with_capacity(m),
            chosen: Vec::with_capacity(m),
        }
    }
}

/// Fusion center of Zhang et al.'s (2016) Algorithm 1.
pub struct QuantizedFusionCenter {
    system: Arc<System>,
    link: Option<Arc<QuantizerLink>>,
    activation: Activation,
    est: Gaussian,
    prediction: Gaussian,
    active: Vec<Activated>,
    work: CenterWork,
}

impl QuantizedFusionCenter {
    pub fn new(
        system: Arc<System>,
        link: Option<Arc<QuantizerLink>>,
        activation: Activation,
    ) -> Result<Self, SchemeError> {
        let est = system.prior.clone();
        let mut fc = Self {
            prediction: est.clone(),
            work: CenterWork::new(&system),
            active: Vec::with_capacity(system.n_sensors()),
            system,
            link,
            activation,
            est,
        };
        fc.prepare()?;
        Ok(fc)
    }

    /// Predicts to the next step ((A2)-(A3)), chooses the activated sensors and computes
    /// their y_hat and Delta (eq. (2)), linearizing at the prediction (EKF).
    fn prepare(&mut self) -> Result<(), SchemeError> {
        kf::predict_into(
            &self.system.transition,
            &self.est,
            &mut self.prediction,
            &mut self.work.predict,
        );
        self.choose();
        self.active.clear();
        let x = &self.prediction.mean;
        for &i in &self.work.chosen {
            let s = &self.system.sensors[i];
            let h = &mut self.work.h[i];
            let y_hat = match s.as_linear() {
                // A linear sensor's Jacobian is H and h(x) = H x (gemv), without the copies
                // `jacobian` and `predict` return.
                Some(lin) => {
                    h.copy_from(lin.h());
                    let mut y = [0.0];
                    crate::linalg::fixed::mat_vec_dyn(&mut y, h.as_slice(), x.as_slice());
                    y[0]
                }
                None => {
                    *h = s.jacobian(x);
                    s.predict(x)[0]
                }
            };
            let s2 = h_p_ht(h, &self.prediction.cov) + s.noise_cov()[(0, 0)];
            self.active.push(Activated {
                index: i,
                y_hat,
                delta: s2.sqrt(),
            });
        }
        Ok(())
    }

    /// The sensors activated at this step into `work.chosen`, in activation order.
    fn choose(&mut self) {
        let x = &self.prediction.mean;
        let chosen = &mut self.work.chosen;
        chosen.clear();
        match self.activation {
            Activation::All => chosen.extend(0..self.system.n_sensors()),
            Activation::Nearest { count, indices } => {
                let by_distance = &mut self.work.by_distance;
                by_distance.clear();
                by_distance.extend(self.system.sensors.iter().enumerate().map(|(i, s)| {
                    let p = s.position().unwrap_or([f64::INFINITY; 2]);
                    ((x[indices[0]] - p[0]).hypot(x[indices[1]] - p[1]), i)
                }));
                // The `count` nearest in (distance, index) order: a total order, so selecting
                // them and sorting only those gives the sort's first `count` exactly (and an
                // unstable sort the stable one's order, without its buffer).
                let order =
                    |a: &(f64, usize), b: &(f64, usize)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
                if count < by_distance.len() {
                    by_distance.select_nth_unstable_by(count, order);
                    by_distance.truncate(count);
                }
                by_distance.sort_unstable_by(order);
                chosen.extend(by_distance.iter().take(count).map(|&(_, i)| i));
            }
        }
    }

    /// Decodes what sensor `i` sent into a quantization level; silence is the centre level.
    fn level_of(link: &QuantizerLink, i: usize, msg: &Received) -> Result<Level, SchemeError> {
        let err = |message: String| SchemeError::Protocol { sensor: i, message };
        match msg {
            Received::Frame(octets) => {
                let d = link
                    .codec
                    .decode(octets)
                    .map_err(|e| err(format!("corrupt frame: {e}")))?;
                if usize::from(d.source) != i + 1 {
                    return Err(err(format!(
                        "frame from address {} in sensor {i}'s slot",
                        d.source
                    )));
                }
                Ok(d.level)
            }
            Received::Silent | Received::NotScheduled => (0..link.quantizer.levels())
                .map(|j| Level::new(j as u16))
                .find(|&l| link.quantizer.is_silent(l))
                .ok_or_else(|| err("silent, but this quantizer has no silent level".into())),
            other => Err(err(format!("expected a quantized frame, got {other:?}"))),
        }
    }
}

impl FusionCenter for QuantizedFusionCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let pred = &self.prediction;
        // Eq. (9) and (12): each activated sensor's individual update from the common
        // prediction enters as (P^i)^{-1} - P^{-1} and (P^i)^{-1} x^i - P^{-1} x. With
        // P^i = P - c g g^T, g = P h^T, c = eta / Delta^2 (eq. (10)), and x^i = x + sigma g /
        // Delta (eq. (13) with the (A24) denominator), Sherman-Morrison gives both without
        // inverting P^i: Information::add_rank_one_update with b = sigma / Delta.
        let work = &mut self.work;
        let info = &mut work.info;
        info.set_inverted_covariance(pred, &mut work.factor)?;
        for a in &self.active {
            let msg = inbox.get(a.index).ok_or_else(|| SchemeError::Protocol {
                sensor: a.index,
                message: "missing from the inbox".into(),
            })?;
            let (c, sigma) = match &self.link {
                Some(link) => {
                    let level = Self::level_of(link, a.index, msg)?;
                    (
                        link.quantizer.eta(level) / (a.delta * a.delta),
                        link.quantizer.reconstruction(level),
                    )
                }
                None => match msg {
                    // Analog: eta = 1 and sigma = psi recover the EKF update.
                    Received::Measurement(z) => {
                        (1.0 / (a.delta * a.delta), (z[0] - a.y_hat) / a.delta)
                    }
                    other => {
                        return Err(SchemeError::Protocol {
                            sensor: a.index,
                            message: format!("expected an analog measurement, got {other:?}"),
                        })
                    }
                },
            };
            if !info.add_rank_one_update_in_place(pred, &work.h[a.index], c, sigma / a.delta) {
                return Err(SchemeError::Unsupported(format!(
                    "sensor {}: quantized update would remove more than the prior covariance",
                    a.index
                )));
            }
        }
        // The fused information matrix (9), back to covariance form.
        symmetrize(&mut info.matrix);
        info.to_gaussian_into(&mut self.est, &mut work.factor)?;
        self.prepare()
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }

    fn feedback(&self) -> Option<Feedback> {
        let mut refs = vec![None; self.system.n_sensors()];
        for a in &self.active {
            refs[a.index] = Some(InnovationReference {
                y_hat: a.y_hat,
                delta: a.delta,
            });
        }
        Some(Feedback::InnovationReference(refs))
    }
}

/// Zhang et al.'s (2016) scheme with a chosen quantizer and activation rule.
#[derive(Debug, Clone)]
pub struct QuantizedInnovationScheme {
    system: Arc<System>,
    link: Option<Arc<QuantizerLink>>,
    activation: Activation,
}

impl QuantizedInnovationScheme {
    /// Checks that every sensor is scalar (the paper's h^i are rows) and, for nearest-sensor
    /// activation, placed.
    pub fn new(
        system: Arc<System>,
        quantizer: &QuantizerChoice,
        activation: Activation,
    ) -> Result<Self, SchemeError> {
        if let Some(i) = system.sensors.iter().position(|s| s.meas_dim() != 1) {
            return Err(SchemeError::Unsupported(format!(
                "sensor {i} is not scalar; Zhang et al. (2016) quantizes scalar innovations"
            )));
        }
        if let Activation::Nearest { count, .. } = activation {
            if count == 0 {
                return Err(SchemeError::Unsupported(
                    "activate at least one sensor".into(),
                ));
            }
            if let Some(i) = system.sensors.iter().position(|s| s.position().is_none()) {
                return Err(SchemeError::Unsupported(format!(
                    "sensor {i} has no position, so the nearest sensors cannot be activated"
                )));
            }
        }
        Ok(Self {
            link: quantizer.build()?.map(Arc::new),
            system,
            activation,
        })
    }
}

impl Scheme for QuantizedInnovationScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = self
            .system
            .sensors
            .iter()
            .enumerate()
            .map(|(i, s)| {
                Box::new(QuantizingSensor::new(i, s.clone(), self.link.clone()))
                    as Box<dyn SensorNode>
            })
            .collect();
        let center =
            QuantizedFusionCenter::new(self.system.clone(), self.link.clone(), self.activation)?;
        Ok(SchemeInstance {
            sensors,
            center: Box::new(center),
        })
    }
}

#[cfg(test)]
mod tests;
