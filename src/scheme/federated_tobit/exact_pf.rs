//! The exact Bayesian answer to Geng et al.'s Tobit model (the exact reference beside the Tobit approximation): one bootstrap
//! particle filter at the fusion center, on the augmented state xi = [x; b] (the dynamical
//! bias of eq. (3) is carried by the [`System`]'s transition), weighted by the exact
//! likelihood of each censored reading.
//!
//! # The model
//! Each sensor is linear and scalar, z = H xi + v, v ~ N(0, R). Under round-robin
//! ([`Schedule::RoundRobin`], eq. (4)-(5)) only sensor (k - 1) mod p sends its raw z at step k
//! (one 32-bit [`Message::Measurement`](crate::link::Message::Measurement)); the detection
//! device at the estimator, i.e. at the fusion center, censors it two-sided (eq. (6)) with
//! [`censor`]. The likelihood of the censored reading y given the state is exact:
//!
//! | reading | likelihood p(y \| xi) | computed as |
//! |---|---|---|
//! | inside, y = z in (tau_l, tau_r) | N(y; H xi, R) | [`normal::log_pdf`] |
//! | left, z <= tau_l | Phi((tau_l - H xi) / sqrt(R)) | [`normal::log_cdf`] |
//! | right, z >= tau_r | 1 - Phi((tau_r - H xi) / sqrt(R)) | [`normal::log_q`] |
//!
//! all in the log domain, so a reading deep in a tail (|theta| = 40 and beyond) still gives
//! finite log-weights that normalize (see [`log_likelihood`]).
//!
//! # What is not data
//! The zero-order hold of eq. (4) repeats a non-scheduled sensor's last reading at the
//! estimator: that value was already used when it arrived, so it carries no new information
//! and is not weighed again. The runner delivers it as [`Received::NotScheduled`] and the
//! center skips it; a scheduled sensor that sent nothing ([`Received::Silent`], which
//! [`super::RoundRobinSensor`] never does) is skipped as well. That silence is what a packet the
//! link lost becomes, and skipping it is exact: a scheduled sensor always sends, so P(silent |
//! xi) = 0 and the likelihood of nothing arriving is the link's loss probability p, the same
//! for every particle (no information, whatever p; a lost reading is neither an error nor a
//! fresh reading; `tests/channel_loss_aware.rs` checks it).
//! Every measurement that does arrive is used, whatever the schedule: the readings are
//! conditionally independent given the state, so the filter stays exact under
//! [`Schedule::All`] too.
//!
//! # Traffic
//! Sensors forward z only when scheduled: one 32-bit measurement per step under the paper's
//! round-robin; the knob `granted` (sensors granted per step, [`super::granted_schedule`])
//! moves the token of (5) on by that many sensors a step, `32 granted` bits per step on
//! average. Nothing is fed back.
//!
//! # Sharing
//! [`censor`] and [`Censored`] are eq. (6) as a function; the federated Tobit KF uses the same
//! one, so both filters see the same censored readings.
//!
//! ```
//! use hushfuse::filter::Gaussian;
//! use hushfuse::linalg::{Matrix, Vector};
//! use hushfuse::link::Received;
//! use hushfuse::model::{LinearSensor, LinearTransition, MeasurementModel};
//! use hushfuse::scheme::federated_tobit::exact_pf::{censor, Censored, TobitPfCenter, TobitPfOptions};
//! use hushfuse::scheme::{FusionCenter, System};
//! use std::sync::Arc;
//!
//! // A scalar random walk seen by one sensor (R = 0.5) whose readings are censored to (-1, 1).
//! let sensor = LinearSensor::new(Matrix::from_element(1, 1, 1.0), Matrix::from_element(1, 1, 0.5))?;
//! let system = Arc::new(System {
//!     transition: LinearTransition::new(Matrix::from_element(1, 1, 1.0), Matrix::from_element(1, 1, 0.1))?,
//!     sensors: vec![Arc::new(sensor) as Arc<dyn MeasurementModel>],
//!     prior: Gaussian::new(Vector::zeros(1), Matrix::from_element(1, 1, 1.0)),
//! });
//! assert_eq!(censor(3.2, -1.0, 1.0), Censored::Right);
//! let mut center = TobitPfCenter::new(system, &[-1.0], &[1.0], TobitPfOptions::default(), 7)?;
//! // The state sits near 3: every reading is right-censored, and the filter still moves up.
//! for k in 1..=20 {
//!     center.step(k, &[Received::Measurement(Vector::from_element(1, 3.0))])?;
//! }
//! assert_eq!(center.last_censored(), 1);
//! assert!(center.estimate().mean[0] > 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
use crate::filter::particle::{
    ParticleCloud, ParticleError, ParticleTransition, ResamplePolicy, Resampling,
};
use crate::filter::Gaussian;
use crate::link::Received;
use crate::model::MeasurementModel as _;
use crate::network::Schedule;
use crate::scheme::{FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System};
use crate::stats::normal;
use multiversion::multiversion;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

pub mod params;
#[cfg(test)]
mod tests;

pub use params::{TobitPfParams, ENTRY};

/// Largest particle count: 10^7 particles of a 3-D augmented state are about 0.5 GB per
/// fusion center and thread.
pub const MAX_PARTICLES: usize = 10_000_000;

pub use crate::filter::tobit::{censor, Censored};

/// `log p(y | mu)`: the exact log-likelihood of a censored reading when the state predicts
/// the measurement `mu = H xi` with noise standard deviation `sd = sqrt(R)`:
/// `log N(y; mu, sd^2)` inside, `log Phi((tau_l - mu) / sd)` at the left threshold,
/// `log(1 - Phi((tau_r - mu) / sd))` at the right one. The constants are included, so sums of
/// these are log-evidences. Finite for every finite `mu` (the tails are computed as logs:
/// `log Phi(-40) = -804.608...`, not `log 0`). `Left` with `tau_l = -inf` (or `Right` with
/// `tau_r = +inf`) is an impossible reading and gives `-inf` or NaN; [`censor`] never returns
/// it.
#[inline]
pub fn log_likelihood(reading: Censored, mu: f64, sd: f64, tau_l: f64, tau_r: f64) -> f64 {
    match reading {
        Censored::Left => normal::log_cdf((tau_l - mu) / sd),
        Censored::Right => normal::log_q((tau_r - mu) / sd),
        Censored::Inside(y) => normal::log_pdf((y - mu) / sd) - sd.ln(),
    }
}

/// [`log_likelihood`] for every particle: adds `log p(y | mu[p])` to `lw[p]`.
///
/// # Panics
/// If the slices differ in length.
pub fn add_log_likelihood(
    reading: Censored,
    sd: f64,
    tau_l: f64,
    tau_r: f64,
    mu: &[f64],
    lw: &mut [f64],
) {
    assert_eq!(
        mu.len(),
        lw.len(),
        "add_log_likelihood: slice lengths differ"
    );
    match reading {
        Censored::Left => add_log_cdf(tau_l, sd, mu, lw),
        Censored::Right => add_log_q(tau_r, sd, mu, lw),
        Censored::Inside(y) => add_gaussian(y, sd, mu, lw),
    }
}

/// `l_p += log N(y; mu_p, sd^2)`.
#[multiversion(targets("x86_64+avx2"))]
fn add_gaussian(y: f64, sd: f64, mu: &[f64], lw: &mut [f64]) {
    let inv_sd = 1.0 / sd;
    let c = -sd.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
    for (l, m) in lw.iter_mut().zip(mu) {
        let t = (y - m) * inv_sd;
        *l += c - 0.5 * t * t;
    }
}

/// `l_p += log Phi((tau - mu_p) / sd)`.
fn add_log_cdf(tau: f64, sd: f64, mu: &[f64], lw: &mut [f64]) {
    for (l, m) in lw.iter_mut().zip(mu) {
        *l += normal::log_cdf((tau - m) / sd);
    }
}

/// `l_p += log Q((tau - mu_p) / sd)`.
fn add_log_q(tau: f64, sd: f64, mu: &[f64], lw: &mut [f64]) {
    for (l, m) in lw.iter_mut().zip(mu) {
        *l += normal::log_q((tau - m) / sd);
    }
}

/// The fusion center's options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TobitPfOptions {
    /// Particles, in `1..=MAX_PARTICLES`.
    pub particles: usize,
    pub resampling: Resampling,
    pub resample_policy: ResamplePolicy,
}

impl Default for TobitPfOptions {
    /// 2000 particles, systematic resampling at every step.
    fn default() -> Self {
        Self {
            particles: 2000,
            resampling: Resampling::Systematic,
            resample_policy: ResamplePolicy::Always,
        }
    }
}

/// One sensor as the center sees it: its row of `H`, `sqrt(R)` and its thresholds.
#[derive(Debug, Clone, PartialEq)]
struct Channel {
    sd: f64,
    tau_l: f64,
    tau_r: f64,
}

/// Checks the system, thresholds and options; returns the per-sensor channels.
fn validate(
    system: &System,
    tau_l: &[f64],
    tau_r: &[f64],
    options: &TobitPfOptions,
) -> Result<Vec<Channel>, SchemeError> {
    let p = system.n_sensors();
    for (field, taus) in [("tau_l", tau_l), ("tau_r", tau_r)] {
        if taus.len() != p {
            return Err(SchemeError::Invalid {
                field,
                message: format!(
                    "expected one threshold per sensor ({p}), got {}",
                    taus.len()
                ),
            });
        }
        if let Some(i) = taus.iter().position(|t| t.is_nan()) {
            return Err(SchemeError::Invalid {
                field,
                message: format!("sensor {i}: threshold is NaN (use -inf / inf for none)"),
            });
        }
    }
    if let Some(i) = (0..p).find(|&i| tau_l[i] >= tau_r[i]) {
        return Err(SchemeError::Invalid {
            field: "tau_r",
            message: format!(
                "sensor {i}: expected tau_l < tau_r, got tau_l = {} and tau_r = {}",
                tau_l[i], tau_r[i]
            ),
        });
    }
    if !(1..=MAX_PARTICLES).contains(&options.particles) {
        return Err(SchemeError::Invalid {
            field: "particles",
            message: format!(
                "expected 1..={MAX_PARTICLES} particles, got {}",
                options.particles
            ),
        });
    }
    if let ResamplePolicy::EssBelow(t) = options.resample_policy {
        if !(0.0..=1.0).contains(&t) {
            return Err(SchemeError::Invalid {
                field: "ess_threshold",
                message: format!("expected a fraction in [0, 1], got {t}"),
            });
        }
    }
    let n = system.state_dim();
    system
        .sensors
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let lin = s.as_linear().filter(|l| l.meas_dim() == 1).ok_or_else(|| {
                SchemeError::Unsupported(format!(
                    "sensor {i}: the Tobit model needs linear scalar sensors (z = H x + v, H 1 x n)"
                ))
            })?;
            if lin.state_dim() != n {
                return Err(SchemeError::Unsupported(format!(
                    "sensor {i}: H has {} columns for a {n}-dimensional state",
                    lin.state_dim()
                )));
            }
            let r = s.noise_cov()[(0, 0)];
            if !(r > 0.0 && r.is_finite()) {
                return Err(SchemeError::Unsupported(format!(
                    "sensor {i}: expected a positive finite R, got {r}"
                )));
            }
            Ok(Channel {
                sd: r.sqrt(),
                tau_l: tau_l[i],
                tau_r: tau_r[i],
            })
        })
        .collect()
}

fn pf_err(e: ParticleError) -> SchemeError {
    SchemeError::Unsupported(format!("particle filter: {e}"))
}

/// The exact-likelihood particle-filter fusion center (see the module documentation).
///
/// Each step: propagate every particle through the augmented transition (bootstrap proposal),
/// add [`log_likelihood`] of each received reading after censoring it with [`censor`],
/// normalize, report the weighted mean and covariance, resample as the options say. Its
/// random numbers come from its own Xoshiro256++ stream, seeded at construction: the same seed
/// and inboxes give bit-identical estimates.
pub struct TobitPfCenter {
    system: Arc<System>,
    channels: Arc<[Channel]>,
    transition: ParticleTransition,
    options: TobitPfOptions,
    cloud: ParticleCloud,
    rng: Xoshiro256PlusPlus,
    est: Gaussian,
    /// `H xi` of every particle for one sensor.
    mu: Vec<f64>,
    last_log_evidence: f64,
    last_censored: usize,
    /// ESS after the last update, before resampling.
    last_ess: f64,
}

impl TobitPfCenter {
    /// A center for `system` with per-sensor thresholds `tau_l[i] < tau_r[i]` (infinite for
    /// none), its particles drawn from the system's prior with the generator seeded by `seed`.
    pub fn new(
        system: Arc<System>,
        tau_l: &[f64],
        tau_r: &[f64],
        options: TobitPfOptions,
        seed: u64,
    ) -> Result<Self, SchemeError> {
        let channels: Arc<[Channel]> = validate(&system, tau_l, tau_r, &options)?.into();
        let transition = ParticleTransition::new(&system.transition).map_err(pf_err)?;
        Self::from_parts(system, channels, transition, options, seed)
    }

    fn from_parts(
        system: Arc<System>,
        channels: Arc<[Channel]>,
        transition: ParticleTransition,
        options: TobitPfOptions,
        seed: u64,
    ) -> Result<Self, SchemeError> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let cloud = ParticleCloud::from_gaussian(options.particles, &system.prior, &mut rng)
            .map_err(pf_err)?;
        let particles = options.particles as f64;
        Ok(Self {
            est: system.prior.clone(),
            mu: vec![0.0; options.particles],
            channels,
            transition,
            options,
            cloud,
            rng,
            system,
            last_log_evidence: 0.0,
            last_censored: 0,
            last_ess: particles,
        })
    }

    /// The particle estimate of `log p(y_k | y_{1:k-1})` at the last step (0 before the
    /// first, and on steps without readings).
    pub fn last_log_evidence(&self) -> f64 {
        self.last_log_evidence
    }

    /// How many readings of the last step were censored.
    pub fn last_censored(&self) -> usize {
        self.last_censored
    }

    /// The options the center runs with.
    pub fn options(&self) -> &TobitPfOptions {
        &self.options
    }

    /// The particle cloud (after the last step's resampling, if there was one).
    pub fn cloud(&self) -> &ParticleCloud {
        &self.cloud
    }
}

impl FusionCenter for TobitPfCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let p = self.channels.len();
        if inbox.len() != p {
            return Err(SchemeError::Unsupported(format!(
                "inbox has {} entries for {p} sensors",
                inbox.len()
            )));
        }
        // Check the whole inbox before touching the cloud, so a bad message leaves it as is.
        for (i, msg) in inbox.iter().enumerate() {
            match msg {
                Received::Measurement(z) if z.len() == 1 && z[0].is_finite() => {}
                Received::Measurement(z) => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("corrupt measurement {:?}", z.as_slice()),
                    })
                }
                Received::NotScheduled | Received::Silent => {}
                other => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("expected a raw measurement, got {other:?}"),
                    })
                }
            }
        }
        self.cloud
            .propagate(&self.transition, &mut self.rng)
            .map_err(pf_err)?;
        let n = self.cloud.len();
        self.last_censored = 0;
        let mut any = false;
        for (i, msg) in inbox.iter().enumerate() {
            // Held values (NotScheduled) and silences carry no new information.
            let Received::Measurement(z) = msg else {
                continue;
            };
            let ch = &self.channels[i];
            let reading = censor(z[0], ch.tau_l, ch.tau_r);
            self.last_censored += usize::from(reading.is_censored());
            any = true;
            let sensor = &self.system.sensors[i];
            let (states, lw) = self.cloud.states_and_log_weights_mut();
            sensor.predict_many(&|j| states.component(j), n, &mut self.mu);
            add_log_likelihood(reading, ch.sd, ch.tau_l, ch.tau_r, &self.mu, lw);
        }
        let log_evidence = self.cloud.normalize().map_err(pf_err)?;
        self.last_ess = self.cloud.ess().map_err(pf_err)?;
        self.last_log_evidence = if any { log_evidence } else { 0.0 };
        self.cloud.estimate_into(&mut self.est).map_err(pf_err)?;
        self.cloud
            .resample_if(
                self.options.resample_policy,
                self.options.resampling,
                &mut self.rng,
            )
            .map_err(pf_err)?;
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
    fn ess(&self) -> Option<f64> {
        Some(self.last_ess)
    }
}

/// Geng et al.'s network with the exact Bayesian fusion center: sensors forward their raw
/// measurement when round-robin schedules them ([`super::RoundRobinSensor`]), the
/// center censors and fuses it with [`TobitPfCenter`].
#[derive(Debug, Clone)]
pub struct TobitPfScheme {
    system: Arc<System>,
    channels: Arc<[Channel]>,
    transition: ParticleTransition,
    options: TobitPfOptions,
    /// Extra noise each sensor adds before sending (Geng et al.'s Table III on one scenario, as
    /// [`super::RoundRobinSensor`]); zero by default.
    extra_sd: Vec<f64>,
    /// Round-robin (4)-(5), or granting `granted` sensors per step ([`Self::with_granted`]).
    schedule: Schedule,
}

impl TobitPfScheme {
    /// Validates and builds the scheme: one threshold pair per sensor with
    /// `tau_l[i] < tau_r[i]` (`-inf` / `inf` for no censoring on that side; NaN is refused),
    /// linear scalar sensors, `1..=MAX_PARTICLES` particles, an ESS fraction in `[0, 1]`.
    /// Errors name the scenario-file field (`tau_l`, `tau_r`, `particles`, `ess_threshold`).
    pub fn new(
        system: Arc<System>,
        tau_l: &[f64],
        tau_r: &[f64],
        options: TobitPfOptions,
    ) -> Result<Self, SchemeError> {
        let channels: Arc<[Channel]> = validate(&system, tau_l, tau_r, &options)?.into();
        let transition = ParticleTransition::new(&system.transition).map_err(pf_err)?;
        Ok(Self {
            extra_sd: vec![0.0; system.n_sensors()],
            system,
            channels,
            transition,
            options,
            schedule: Schedule::RoundRobin,
        })
    }

    /// The scheme granting `granted` sensors per step ([`super::granted_schedule`]; 1:
    /// unchanged). Every reading that arrives is weighed, so the filter stays exact.
    pub fn with_granted(mut self, granted: f64) -> Result<Self, SchemeError> {
        self.schedule = super::granted_schedule(granted, self.extra_sd.len())?;
        Ok(self)
    }

    /// The scheme at other noise variances than the sensors' own (`noise_var[i] >= R_i`): each
    /// sensor adds the same extra noise as the federated Tobit KF's sensors, and the filter
    /// weighs with the new variances.
    pub fn with_noise_var(
        system: Arc<System>,
        noise_var: &[f64],
        tau_l: &[f64],
        tau_r: &[f64],
        options: TobitPfOptions,
    ) -> Result<Self, SchemeError> {
        let sensors = super::scalar_sensors(&system, Some(noise_var))?;
        let extra_sd = sensors.iter().map(|s| s.2).collect();
        let mut sys = (*system).clone();
        sys.sensors = sensors
            .into_iter()
            .map(|(h, r, _)| {
                crate::model::LinearSensor::new(h, crate::linalg::Matrix::from_element(1, 1, r))
                    .map(|s| Arc::new(s) as Arc<dyn crate::model::MeasurementModel>)
                    .map_err(|e| SchemeError::Unsupported(e.to_string()))
            })
            .collect::<Result<_, _>>()?;
        let mut scheme = Self::new(Arc::new(sys), tau_l, tau_r, options)?;
        scheme.extra_sd = extra_sd;
        Ok(scheme)
    }

    /// Sensor `i`'s thresholds `(tau_l, tau_r)`.
    pub fn thresholds(&self, i: usize) -> Option<(f64, f64)> {
        self.channels.get(i).map(|c| (c.tau_l, c.tau_r))
    }

    /// The fusion center's options.
    pub fn options(&self) -> &TobitPfOptions {
        &self.options
    }

    /// A fusion center for one trial, its generator seeded by `seed`.
    pub fn center(&self, seed: u64) -> Result<TobitPfCenter, SchemeError> {
        TobitPfCenter::from_parts(
            self.system.clone(),
            self.channels.clone(),
            self.transition.clone(),
            self.options,
            seed,
        )
    }
}

impl Scheme for TobitPfScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        self.build_with_seed(0)
    }

    fn build_with_seed(&self, seed: u64) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: self
                .extra_sd
                .iter()
                .map(|&sd| Box::new(super::RoundRobinSensor::new(sd)) as Box<dyn SensorNode>)
                .collect(),
            center: Box::new(self.center(seed)?),
        })
    }

    /// Round-robin (eq. (4)-(5)): at step k only sensor (k - 1) mod p sends; with `granted`,
    /// the step's slots of [`Schedule::RoundRobinGranted`].
    fn schedule(&self) -> Schedule {
        self.schedule
    }
}
