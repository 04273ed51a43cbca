//! Geng, Wang, Alsaadi, Alharbi and Cheng, "Federated Tobit Kalman Filtering Fusion
//! with Dead-Zone-Like Censoring and Dynamical Bias under the Round-Robin Protocol".
//!
//! How the paper's system maps onto hushfuse:
//!
//! * **Dynamical bias = state augmentation** (eq. (10)-(11)): the scenario's `[model]` is the
//!   augmented `F = [[A, B], [0, H]]`, `Q = blockdiag(Q, Xi)` on `xi = [x; b]`, and the sensors
//!   are linear with `H = [[C_m, 0]]`. The prior is the paper's `x_0`, `P_x0`, `b_0`, `P_b0`.
//! * **Round-robin** (eq. (4)-(5)): [`Scheme::schedule`] is [`Schedule::RoundRobin`]; a
//!   scheduled sensor sends its raw reading (32 bits, `Message::Measurement`) — that uplink,
//!   sensor -> estimator, is what the runner counts. Unscheduled sensors are not stepped and
//!   arrive as `Received::NotScheduled`.
//! * **Bandwidth knob `granted`** (beyond the paper): the sensors granted per step. The
//!   token `h_k = mod(k - 1, p) + 1` of (5) moves on by `granted` sensors a step instead of
//!   one ([`Schedule::RoundRobinGranted`]), so `Gamma_{m, h_k}` of (4) is one for every sensor
//!   among the step's slots: `granted = 1` (the default) is the paper's protocol exactly,
//!   `granted = p` every sensor at every step, a fraction one sensor every `1/granted` steps.
//!   Each granted sensor's local filter updates (20)-(25) and the others only predict, as in
//!   the paper; with several updated locals the fusion (26) is no longer one Tobit KF.
//! * **Remote estimators, hold and detection device at the fusion center**: the p local Tobit
//!   filters sit next to the fusion center (the paper's Remark after (5): the
//!   estimator-to-center channel is short and perfect), so the center applies the zero-order
//!   hold (the rule of [`crate::network::ZeroOrderHold`]: a reading is fresh on the step it
//!   arrives, held after; the center keeps only which readings are fresh, since a held value
//!   enters the filters only through the local filtered mean kept for it) and the two-sided
//!   censoring (6) itself. The
//!   estimator -> center traffic (local estimates and their covariances) is co-located and
//!   **not counted**; in the federated loop the reset (27) also flows back for free.
//! * **What a local filter does when its sensor is not scheduled**: by (24) the cross
//!   covariance is zero (`Gamma_{m, h_k} = 0`), so K = 0 and the filter only predicts (18)-(19).
//!   The held value carries no new information. On a scheduled step the protocol sum of (25)
//!   and the past terms of zeta-hat vanish (only one `Gamma_{m, h_{k-l}}`, l = 0..p-1, is one),
//!   so zeta-hat = C xi^-. On unscheduled steps the zeta-hat of the held value is
//!   `C xi_{m, k-l}` with `xi_{m, k-l}` the local filter's own *filtered* estimate at the step
//!   l the value was measured (the paper's `xi_{k-l}` after Lemma 1, read as the local one); it
//!   enters only the censoring probabilities recorded for the Theorem 4 bounds.
//! * **A packet the link lost** reaches the center as `Received::Silent`: not fresh, so the
//!   hold keeps the last reading that arrived and that sensor's local filter only predicts, as
//!   for a held value (Geng et al.'s published behaviour). A scheduled sensor always sends, so
//!   nothing arriving is a loss and carries no information: this is also the exact update.
//! * Before a sensor's first transmission its hold is empty and its filter only predicts (the
//!   paper's `z_{m,0}` does not exist in the simulation).
//!
//! With the reset (27) and every `epsilon_m > 0` summing to one, the federated fusion (26) of
//! one updated and p - 1 predicted locals equals a single Tobit KF that updates with the
//! scheduled sensor (the test `federated_equals_the_centralized_tobit_kf`): the fused filter
//! does not depend on the sharing coefficients.
//!
//! **The printed typos** are options of the scenario file (see [`crate::filter::tobit`]),
//! the corrected reading the default:
//!
//! * `theta_denominator`. (9) prints the censoring probabilities with the standard deviation,
//!   `alpha ~ Phi((tau_l - zeta^-)/sqrt(R))`, `beta ~ Phi((zeta^- - tau_r)/sqrt(R))`; the theta
//!   that feeds `lambda` (14) and `varphi` (15), hence (23) and (25) and Theorem 4's
//!   `varphi(theta_l)`, is printed as `(tau - zeta)/R` (after (11), and with `zeta^-` before
//!   Lemma 2). The corrected form (`"sqrt-r"`) uses `sqrt(R)` in (9) and (14)-(15) alike, as
//!   (16)-(17) and the truncated moments (31)-(32) require; the printed form (`"r"`) follows
//!   the equations literally: `sqrt(R)` in (9), `R` in (14)-(15). The factors `sqrt(R)` before
//!   `lambda` in (23) and `R` before `1 + varphi` in (25) are printed correctly and shared.
//! * `lambda_sign`: `zeta - sqrt(R) lambda` as (12) and (32) give, or the `+` printed in (23).
//!
//! [`exact_pf`] is the exact-likelihood particle filter shown beside the Tobit KF: one particle filter on the augmented state weighing the scheduled reading by its
//! exact censored likelihood, the Bayes-optimal answer on the same data.
pub mod bounds;
pub mod center;
pub mod exact_pf;
pub mod params;
#[cfg(test)]
mod tests;

pub use center::{FtkfCenter, FtkfModel, Fusion, LocalRecord};

use crate::filter::tobit::{Thresholds, TobitOptions};
use crate::linalg::{Matrix, Vector};
use crate::link::{Message, Transmission};
use crate::model::{LinearSensor, MeasurementModel};
use crate::network::Schedule;
use crate::scheme::centralized::CentralizedKf;
use crate::scheme::{Scheme, SchemeError, SchemeInstance, SensorNode, System};
use rand::RngCore;
use std::sync::Arc;

/// The sensor of Geng et al.: when scheduled it sends its raw reading. With a noise override
/// (`noise_var` above the sensor's R) it first adds independent `N(0, noise_var - R)` noise, so
/// one scenario can compare noise variances (Table III) on common truths.
///
/// The added noise is a deterministic function of the base reading (a SplitMix64 hash of its
/// bits, mapped to a standard normal by Box-Muller): it derives from the runner's seeded
/// measurement stream and is the *same* for every scheme variant, so schemes at one noise
/// variance see identical readings (common random numbers; the scheme's own coin stream would
/// give each variant different readings).
#[derive(Debug, Clone)]
pub struct RoundRobinSensor {
    extra_sd: f64,
}

impl RoundRobinSensor {
    /// `extra_sd` = 0: forwards the reading as measured.
    pub fn new(extra_sd: f64) -> Self {
        Self { extra_sd }
    }
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A standard normal determined by `v`'s bits (Box-Muller on two hashed uniforms in (0, 1)).
pub fn hashed_normal(v: f64) -> f64 {
    let a = splitmix64(v.to_bits() ^ 0x5EED_0002_7AB1_7000);
    let b = splitmix64(a);
    let u1 = ((a >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = ((b >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl SensorNode for RoundRobinSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        _feedback: Option<&super::Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        let z = if self.extra_sd > 0.0 {
            z.map(|v| v + self.extra_sd * hashed_normal(v))
        } else {
            z.clone()
        };
        Ok(Transmission::Send(Message::Measurement(z)))
    }
}

/// The system's scalar linear sensors, each with the noise variance the scheme runs at
/// (`noise_var[i]`, or the sensor's own R) and the extra noise standard deviation that makes
/// it so.
pub fn scalar_sensors(
    system: &System,
    noise_var: Option<&[f64]>,
) -> Result<Vec<(Matrix, f64, f64)>, SchemeError> {
    system
        .sensors
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let lin = s
                .as_linear()
                .filter(|l| l.h().nrows() == 1)
                .ok_or_else(|| {
                    SchemeError::Unsupported(format!(
                        "Geng et al.'s schemes need scalar linear sensors; sensor {i} is not one"
                    ))
                })?;
            let r0 = lin.noise_cov()[(0, 0)];
            let r = noise_var.map_or(r0, |v| v[i]);
            if !(r.is_finite() && r >= r0) {
                return Err(SchemeError::Invalid {
                    field: "noise_var",
                    message: format!(
                        "sensor {i}: noise_var must be finite and at least the sensor's R = {r0} \
                         (the scheme can only add noise), got {r}"
                    ),
                });
            }
            Ok((lin.h().clone(), r, (r - r0).sqrt()))
        })
        .collect()
}

/// The round-robin schedule granting `granted` sensors per step on `p` sensors (the knob of
/// Geng et al.'s schemes; [`Schedule::round_robin`]): refused outside `(0, p]`.
pub fn granted_schedule(granted: f64, p: usize) -> Result<Schedule, SchemeError> {
    if !(granted.is_finite() && granted > 0.0 && granted <= p as f64) {
        return Err(SchemeError::Invalid {
            field: "granted",
            message: format!(
                "expected sensors granted per step in (0, {p}] (1: the paper's round-robin), got {granted}"
            ),
        });
    }
    Ok(Schedule::round_robin(granted))
}

/// Geng et al.'s FTKF-DB / FTKF / LTKF under round-robin.
#[derive(Debug, Clone)]
pub struct FederatedTobitScheme {
    model: Arc<FtkfModel>,
    extra_sd: Vec<f64>,
}

impl FederatedTobitScheme {
    /// The scheme on `system` with per-sensor thresholds, noise override, sharing
    /// coefficients, fusion mode and, if `bias_states` is given with `bias_model = false`,
    /// the bias-blind FTKF on the remaining states.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        system: Arc<System>,
        thresholds: Vec<Thresholds>,
        noise_var: Option<Vec<f64>>,
        sharing: Option<Vec<f64>>,
        fusion: Fusion,
        bias_blind: Option<Vec<usize>>,
        opts: TobitOptions,
    ) -> Result<Self, SchemeError> {
        let sensors = scalar_sensors(&system, noise_var.as_deref())?;
        let extra_sd = sensors.iter().map(|s| s.2).collect();
        let model = FtkfModel::new(
            &system,
            sensors.into_iter().map(|(h, r, _)| (h, r)).collect(),
            thresholds,
            sharing,
            fusion,
            bias_blind,
            opts,
        )?;
        Ok(Self {
            model: Arc::new(model),
            extra_sd,
        })
    }

    /// The validated model the fusion center runs.
    pub fn model(&self) -> &Arc<FtkfModel> {
        &self.model
    }

    /// The scheme granting `granted` sensors per step ([`granted_schedule`]; 1: unchanged).
    pub fn with_granted(mut self, granted: f64) -> Result<Self, SchemeError> {
        let schedule = granted_schedule(granted, self.model.n_sensors())?;
        Arc::make_mut(&mut self.model).schedule = schedule;
        Ok(self)
    }
}

impl Scheme for FederatedTobitScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: self
                .extra_sd
                .iter()
                .map(|&sd| Box::new(RoundRobinSensor::new(sd)) as Box<dyn SensorNode>)
                .collect(),
            center: Box::new(FtkfCenter::new(self.model.clone(), false)),
        })
    }
    fn schedule(&self) -> Schedule {
        self.model.schedule
    }
}

/// The information bound of every Geng et al. report: a Kalman filter on the same round-robin
/// schedule with the *uncensored* readings (same noise override). Censoring only removes
/// information, so no estimator of the censored data has a smaller mean squared error.
#[derive(Debug, Clone)]
pub struct RoundRobinKfScheme {
    system: Arc<System>,
    extra_sd: Vec<f64>,
    schedule: Schedule,
}

impl RoundRobinKfScheme {
    pub fn new(system: Arc<System>, noise_var: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        let sensors = scalar_sensors(&system, noise_var.as_deref())?;
        let extra_sd = sensors.iter().map(|s| s.2).collect();
        let mut sys = (*system).clone();
        sys.sensors = sensors
            .into_iter()
            .map(|(h, r, _)| {
                LinearSensor::new(h, Matrix::from_element(1, 1, r))
                    .map(|s| Arc::new(s) as Arc<dyn MeasurementModel>)
                    .map_err(|e| SchemeError::Unsupported(e.to_string()))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            system: Arc::new(sys),
            extra_sd,
            schedule: Schedule::RoundRobin,
        })
    }

    /// The scheme granting `granted` sensors per step ([`granted_schedule`]; 1: unchanged).
    pub fn with_granted(mut self, granted: f64) -> Result<Self, SchemeError> {
        self.schedule = granted_schedule(granted, self.extra_sd.len())?;
        Ok(self)
    }
}

impl Scheme for RoundRobinKfScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: self
                .extra_sd
                .iter()
                .map(|&sd| Box::new(RoundRobinSensor::new(sd)) as Box<dyn SensorNode>)
                .collect(),
            center: Box::new(CentralizedKf::new(self.system.clone())),
        })
    }
    fn schedule(&self) -> Schedule {
        self.schedule
    }
}
