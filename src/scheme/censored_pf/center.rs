//! Fusion center of Zheng et al. (2014): a bootstrap particle filter whose weights use the received
//! measurements and, with the full likelihood (CFwMD), the probability that each silent
//! sensor's innovation stayed inside its no-send band.
use super::censoring::whitened_band;
use super::local_plan::{LocalPlan, LocalStep};
use super::{BandMethod, FeedbackMode, Fusion, PfOptions, Protocol};
use crate::filter::kf::update_cov;
use crate::filter::particle::{ParticleCloud, ParticleTransition};
use crate::filter::{kf, Gaussian};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::scheme::{Feedback, FusionCenter, SchemeError, System};
use crate::stats::{band_kernel, normal, quadform::QuadFormCdf, quadform2d::EllipseBand2};
use multiversion::multiversion;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

fn pf_err(e: crate::filter::particle::ParticleError) -> SchemeError {
    SchemeError::Unsupported(format!("particle filter: {e}"))
}

/// `l_p -= w (z - h_p)^2`: a received scalar measurement's log-likelihood over the particles
/// (`w = 1 / (2 r)`). Compiled also for AVX2 (same bits).
#[multiversion(targets("x86_64+avx2"))]
fn add_scalar_gaussian(z: f64, w: f64, h: &[f64], lw: &mut [f64]) {
    for (l, h) in lw.iter_mut().zip(h) {
        let e = z - h;
        *l -= w * e * e;
    }
}

/// Sensor `i`'s planned local matrices at step `k`, if it has any.
fn planned(
    plan: Option<&LocalPlan>,
    i: usize,
    k: usize,
) -> Result<Option<&LocalStep>, SchemeError> {
    match plan {
        Some(plan) => plan.at(i, k),
        None => Ok(None),
    }
}

/// The particle-filter fusion center.
pub struct CensoredPfCenter {
    system: Arc<System>,
    transition: ParticleTransition,
    /// The send rule and feedback the sensors follow (shared with them by construction).
    protocol: Protocol,
    options: PfOptions,
    cloud: ParticleCloud,
    rng: Xoshiro256PlusPlus,
    est: Gaussian,
    /// ESS after the last update, before resampling.
    last_ess: f64,
    /// x_{k|k-1} and P_{k|k-1} fed back before step k.
    prediction: Gaussian,
    /// Replica of each sensor's local covariance P^i_{k-1|k-1} (Remark 1 (I), Remark 3 (I)).
    local_cov: Vec<Matrix>,
    /// Cross-covariances P^{i,j}_{k-1|k-1} of the local filters (eq. (22)-(23)), for the
    /// non-feedback full likelihood (Prop. 3 / 6).
    cross_cov: Vec<Vec<Matrix>>,
    /// h(x) of every particle for one sensor, rows component-major.
    hx: Vec<f64>,
    /// Log of the Prop. 3 / 6 factor of the last step (the same for every particle).
    last_prop3_log_factor: f64,
    /// R^{-1} of each sensor, computed once.
    r_inv: Vec<Matrix>,
    /// The shared local-covariance sequence of the linear sensors, if the scheme has one.
    plan: Option<Arc<LocalPlan>>,
    /// Scratch: the replicas' predicted covariances and the silent sensors of a step.
    p_pred: Vec<Matrix>,
    silent: Vec<usize>,
    /// Scratch: the log weights before a silence's band factor (loss-aware fusion).
    before_band: Vec<f64>,
    /// The loss probability assumed for each sensor's link (`options.link_loss` for all,
    /// unless [`CensoredPfCenter::with_link_losses`] gave one per sensor).
    link_loss: Vec<f64>,
}

impl CensoredPfCenter {
    pub fn new(
        system: Arc<System>,
        protocol: Protocol,
        options: PfOptions,
        seed: u64,
    ) -> Result<Self, SchemeError> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let transition = ParticleTransition::new(&system.transition).map_err(pf_err)?;
        let cloud = ParticleCloud::from_gaussian(options.particles, &system.prior, &mut rng)
            .map_err(pf_err)?;
        let n = system.n_sensors();
        let max_m = system
            .sensors
            .iter()
            .map(|s| s.meas_dim())
            .max()
            .unwrap_or(1);
        let prediction = kf::predict(&system.transition, &system.prior);
        let r_inv = system
            .sensors
            .iter()
            .map(|s| {
                crate::linalg::spd_inverse(s.noise_cov()).map_err(|source| SchemeError::Matrix {
                    what: "measurement noise R",
                    source,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            r_inv,
            local_cov: vec![system.prior.cov.clone(); n],
            p_pred: vec![system.prior.cov.clone(); n],
            cross_cov: vec![vec![system.prior.cov.clone(); n]; n],
            hx: vec![0.0; max_m * options.particles],
            est: system.prior.clone(),
            prediction,
            transition,
            last_ess: options.particles as f64,
            cloud,
            rng,
            protocol,
            options,
            system,
            last_prop3_log_factor: 0.0,
            plan: None,
            silent: Vec::with_capacity(n),
            before_band: Vec::new(),
            link_loss: vec![options.link_loss; n],
        })
    }

    /// Each sensor's loss probability, in place of `options.link_loss` for all (checked by
    /// [`super::CensoredPfScheme::with_link_losses`]).
    pub fn with_link_losses(mut self, per_sensor: &[f64]) -> Self {
        self.link_loss = per_sensor.to_vec();
        self
    }

    /// Takes the replicas' local covariances from `plan` (the one computed for this system)
    /// instead of computing them every step; `step` must then be called for k = 1, 2, 3, ...
    /// in order (the plan's step k is the covariance after k updates).
    pub fn with_plan(mut self, plan: Arc<LocalPlan>) -> Self {
        self.plan = Some(plan);
        self
    }

    /// The log of the Prop. 3 / 6 factor at the last step.
    pub fn last_prop3_log_factor(&self) -> f64 {
        self.last_prop3_log_factor
    }

    /// Adds -1/2 (z - h(x))^T R^{-1} (z - h(x)) to every particle's log-weight.
    fn add_measurement(&mut self, i: usize, z: &Vector) -> Result<(), SchemeError> {
        let sensor = self.system.sensors[i].clone();
        let n = self.cloud.len();
        let m = sensor.meas_dim();
        let (states, lw) = self.cloud.states_and_log_weights_mut();
        sensor.predict_many(&|j| states.component(j), n, &mut self.hx[..m * n]);
        let r_inv = &self.r_inv[i];
        if m == 1 {
            add_scalar_gaussian(z[0], 0.5 * r_inv[(0, 0)], &self.hx[..n], lw);
        } else {
            for (p, l) in lw.iter_mut().enumerate() {
                let mut q = 0.0;
                for a in 0..m {
                    let ea = z[a] - self.hx[a * n + p];
                    for b in 0..m {
                        q += ea * r_inv[(a, b)] * (z[b] - self.hx[b * n + p]);
                    }
                }
                *l -= 0.5 * q;
            }
        }
        Ok(())
    }

    /// The likelihood of "nothing arrived" from sensor `i`: the band probability of
    /// [`Self::add_band`] (the published CFwMD likelihood) or, when the center assumes a lossy
    /// link (`link_loss` = p > 0), the exact likelihood of nothing arriving,
    /// P(silent | x) + p P(sent | x) = p + (1 - p) P(silent | x): a silence, or a message the
    /// link lost. A Gilbert-Elliott link is taken at its stationary loss rate (the channel
    /// state is not carried in the particles).
    fn add_silence(
        &mut self,
        i: usize,
        x_ref: &Vector,
        s: &Matrix,
        eta: f64,
    ) -> Result<(), SchemeError> {
        let p = self.link_loss[i];
        if p == 0.0 {
            return self.add_band(i, x_ref, s, eta);
        }
        self.before_band.clear();
        self.before_band.extend_from_slice(self.cloud.log_weights());
        self.add_band(i, x_ref, s, eta)?;
        for (l, before) in self
            .cloud
            .log_weights_mut()
            .iter_mut()
            .zip(&self.before_band)
        {
            let log_silent = *l - before;
            *l = before + (p + (1.0 - p) * log_silent.exp()).ln();
        }
        Ok(())
    }

    /// Full likelihood of a silent sensor with feedback: log P(NIS < eta | x) with the
    /// innovation taken against `x_ref` and covariance `s` (Zheng et al. (2014), eq. (9), (15), (44), (45)
    /// for scalars with xi_1 = (-sqrt(eta s) - mu) / sqrt(r), xi_2 = (sqrt(eta s) - mu) /
    /// sqrt(r), the square root covering eta s only as (14) shows; eq. (33), (39) for vectors).
    fn add_band(
        &mut self,
        i: usize,
        x_ref: &Vector,
        s: &Matrix,
        eta: f64,
    ) -> Result<(), SchemeError> {
        let sensor = self.system.sensors[i].clone();
        let n = self.cloud.len();
        let m = sensor.meas_dim();
        let h_ref = sensor.predict(x_ref);
        let r = sensor.noise_cov().clone();
        let band_method = self.options.band;
        let (states, lw) = self.cloud.states_and_log_weights_mut();
        sensor.predict_many(&|j| states.component(j), n, &mut self.hx[..m * n]);
        if m == 1 {
            let half_width = (eta * s[(0, 0)]).sqrt();
            let inv_sd = 1.0 / r[(0, 0)].sqrt();
            // mu = h(x) - h(x_{k|k-1}), eq. (13) / Prop. 7, formed inside the kernel.
            band_kernel::add_log_band_probability_about(
                &self.hx[..n],
                h_ref[0],
                half_width,
                inv_sd,
                lw,
            );
            return Ok(());
        }
        // Vector: q = S^{-1/2} nu ~ N(S^{-1/2} (h(x) - h(x_ref)), S^{-1/2} R S^{-1/2}) (35)-(38).
        let (s_inv_sqrt, c) = whitened_band(s, &r);
        let mut mean = vec![0.0; m];
        match band_method {
            BandMethod::Exact if m == 2 => {
                // The 2-D kernel: the whitened means in place of h(x), then ln P for all
                // particles at once (Ruben's series with the per-call work hoisted).
                let band = EllipseBand2::new(&c, eta)
                    .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                let (h0, h1) = (h_ref[0], h_ref[1]);
                let (s00, s01) = (s_inv_sqrt[(0, 0)], s_inv_sqrt[(0, 1)]);
                let (s10, s11) = (s_inv_sqrt[(1, 0)], s_inv_sqrt[(1, 1)]);
                let (m0, m1) = self.hx[..2 * n].split_at_mut(n);
                for (a, b) in m0.iter_mut().zip(m1.iter_mut()) {
                    let (d0, d1) = (*a - h0, *b - h1);
                    *a = s00 * d0 + s01 * d1;
                    *b = s10 * d0 + s11 * d1;
                }
                band.add_log_prob_below(m0, m1, lw);
            }
            BandMethod::Exact => {
                let qf =
                    QuadFormCdf::new(&c).map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                for (p, l) in lw.iter_mut().enumerate() {
                    for (a, v) in mean.iter_mut().enumerate() {
                        *v = (0..m)
                            .map(|b| s_inv_sqrt[(a, b)] * (self.hx[b * n + p] - h_ref[b]))
                            .sum();
                    }
                    let prob = qf
                        .prob_below_slice(&mean, eta)
                        .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                    *l += prob.max(f64::MIN_POSITIVE).ln();
                }
            }
            BandMethod::MonteCarlo { samples } => {
                // The paper's counting estimate: N_q draws of q, count q^T q < eta. A count of
                // zero gets half a count, so a particle is never given weight exactly zero.
                let sqrt_c = crate::model::transition::psd_sqrt(&c).map_err(|source| {
                    SchemeError::Matrix {
                        what: "band covariance",
                        source,
                    }
                })?;
                let mut draw = vec![0.0; m];
                for (p, lp) in lw.iter_mut().enumerate() {
                    for (a, v) in mean.iter_mut().enumerate() {
                        *v = (0..m)
                            .map(|b| s_inv_sqrt[(a, b)] * (self.hx[b * n + p] - h_ref[b]))
                            .sum();
                    }
                    let mut inside = 0usize;
                    for _ in 0..samples {
                        for v in draw.iter_mut() {
                            *v = StandardNormal.sample(&mut self.rng);
                        }
                        let mut q2 = 0.0;
                        for a in 0..m {
                            let qa =
                                mean[a] + (0..m).map(|b| sqrt_c[(a, b)] * draw[b]).sum::<f64>();
                            q2 += qa * qa;
                        }
                        inside += usize::from(q2 < eta);
                    }
                    *lp += (inside.max(1) as f64 - if inside == 0 { 0.5 } else { 0.0 }).ln()
                        - (samples as f64).ln();
                }
            }
        }
        Ok(())
    }

    /// Prop. 3 / 6 (no feedback): the band probability integrated over the local predictions
    /// given x, with p(x_hat^{1:N} | x) = N([x; ...; x], Sigma) of eq. (21)-(23). With that
    /// model the innovation mean h_i (x - x_hat^i) = -h_i e_i, e ~ N(0, Sigma), does not depend
    /// on x: the integral is the same number for every particle, so the weights (and the
    /// estimate) equal CFoMD's. We still evaluate it (Monte Carlo with shared draws, as the
    /// paper integrates numerically) because it is the likelihood as printed and enters the
    /// evidence; see the scheme's notes for what this means for Fig. 3 and Fig. 6.
    fn prop3_log_factor(
        &mut self,
        silent: &[usize],
        p_pred: &[Matrix],
        cross_pred: &[Vec<Matrix>],
        eta: f64,
    ) -> Result<f64, SchemeError> {
        if silent.is_empty() {
            return Ok(0.0);
        }
        let d = self.system.state_dim();
        // Joint covariance of the silent sensors' prediction errors.
        let k = silent.len();
        let mut sigma = Matrix::zeros(k * d, k * d);
        for (a, &i) in silent.iter().enumerate() {
            for (b, &j) in silent.iter().enumerate() {
                let block = if i == j {
                    &p_pred[i]
                } else {
                    &cross_pred[i][j]
                };
                sigma.view_mut((a * d, b * d), (d, d)).copy_from(block);
            }
        }
        symmetrize(&mut sigma);
        let l =
            crate::model::transition::psd_sqrt(&sigma).map_err(|source| SchemeError::Matrix {
                what: "cross-covariance (21)",
                source,
            })?;
        let samples = self.options.prop3_samples.max(1);
        let mut total = 0.0;
        let mut w = Vector::zeros(k * d);
        for _ in 0..samples {
            for v in w.iter_mut() {
                *v = StandardNormal.sample(&mut self.rng);
            }
            let e = &l * &w;
            let mut logp = 0.0;
            for (a, &i) in silent.iter().enumerate() {
                let sensor = &self.system.sensors[i];
                let h = sensor.as_linear().ok_or_else(|| {
                    SchemeError::Unsupported(
                        "Prop. 3 / 6 needs linear sensors (Remark 4 (III))".into(),
                    )
                })?;
                let ea = e.rows(a * d, d).into_owned();
                let mu = -(h.h() * ea); // h (x - x_hat) with x_hat = x + e
                let s = h.h() * &p_pred[i] * h.h().transpose() + sensor.noise_cov();
                if mu.len() == 1 {
                    let half = (eta * s[(0, 0)]).sqrt();
                    let sd = sensor.noise_cov()[(0, 0)].sqrt();
                    logp += normal::log_q_band((-half - mu[0]) / sd, (half - mu[0]) / sd);
                } else {
                    let (sis, c) = whitened_band(&s, sensor.noise_cov());
                    let p = crate::stats::quadform::prob_below(&(&sis * mu), &c, eta)
                        .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                    logp += p.max(f64::MIN_POSITIVE).ln();
                }
            }
            total += logp.exp();
        }
        Ok((total / samples as f64).max(f64::MIN_POSITIVE).ln())
    }
}

impl FusionCenter for CensoredPfCenter {
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let sys = self.system.clone();
        let plan = self.plan.clone();
        let f = sys.transition.f();
        let q = sys.transition.q();
        let n_sensors = sys.n_sensors();
        if inbox.len() != n_sensors {
            return Err(SchemeError::Unsupported(format!(
                "inbox has {} entries for {n_sensors} sensors",
                inbox.len()
            )));
        }
        // Replicas of the local covariance predictions (from the shared plan where there is
        // one: the same numbers).
        for i in 0..n_sensors {
            match planned(plan.as_deref(), i, k)? {
                Some(step) => self.p_pred[i].copy_from(&step.p_pred),
                None => self.p_pred[i] = kf::predict_cov(&sys.transition, &self.local_cov[i]),
            }
        }
        let full_nofb = self.options.fusion == Fusion::Full
            && self.protocol.feedback() == FeedbackMode::None
            && self.protocol.eta().is_some();
        let cross_pred: Vec<Vec<Matrix>> = if full_nofb {
            self.cross_cov
                .iter()
                .map(|row| row.iter().map(|p| f * p * f.transpose() + q).collect())
                .collect()
        } else {
            Vec::new()
        };

        self.cloud
            .propagate(&self.transition, &mut self.rng)
            .map_err(pf_err)?;
        let mut silent = std::mem::take(&mut self.silent);
        silent.clear();
        for (i, msg) in inbox.iter().enumerate() {
            match msg {
                Received::Measurement(z) => {
                    if z.len() != sys.sensors[i].meas_dim() || z.iter().any(|v| !v.is_finite()) {
                        return Err(SchemeError::Protocol {
                            sensor: i,
                            message: format!("corrupt measurement {:?}", z.as_slice()),
                        });
                    }
                    self.add_measurement(i, z)?
                }
                Received::Silent => silent.push(i),
                Received::NotScheduled => {}
                other => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("expected a measurement or silence, got {other:?}"),
                    })
                }
            }
        }
        // Silence is data only under censoring with the full likelihood.
        if let (Fusion::Full, Some(eta)) = (self.options.fusion, self.protocol.eta()) {
            match self.protocol.feedback() {
                FeedbackMode::None => {
                    let p_pred = self.p_pred.clone();
                    self.last_prop3_log_factor =
                        self.prop3_log_factor(&silent, &p_pred, &cross_pred, eta)?;
                    let c = self.last_prop3_log_factor;
                    for l in self.cloud.log_weights_mut() {
                        *l += c;
                    }
                }
                mode => {
                    let x_ref = self.prediction.mean.clone();
                    for &i in &silent {
                        let planned = planned(plan.as_deref(), i, k)?;
                        let s = match planned {
                            Some(step) if mode == FeedbackMode::Prediction => step.s.clone(),
                            _ => {
                                let sensor = &sys.sensors[i];
                                let p_ref = if mode == FeedbackMode::Prediction {
                                    &self.p_pred[i]
                                } else {
                                    &self.prediction.cov
                                };
                                let h = sensor.jacobian(&x_ref);
                                let mut s = &h * p_ref * h.transpose() + sensor.noise_cov();
                                symmetrize(&mut s);
                                s
                            }
                        };
                        self.add_silence(i, &x_ref, &s, eta)?;
                    }
                }
            }
        }
        self.silent = silent;
        self.cloud.normalize().map_err(pf_err)?;
        self.last_ess = self.cloud.ess().map_err(pf_err)?;
        self.cloud.estimate_into(&mut self.est).map_err(pf_err)?;
        self.cloud
            .resample_if(
                self.options.resample_policy,
                self.options.resampling,
                &mut self.rng,
            )
            .map_err(pf_err)?;

        // Replicas of the local covariance updates (each sensor always uses its own z).
        let mut gains = Vec::new();
        for (i, sensor) in sys.sensors.iter().enumerate() {
            // With feedback the sensors linearize at the fed-back prediction (Remark 3);
            // without, only linear sensors need replicas and H does not depend on the point.
            let x_ref = &self.prediction.mean;
            let gain = match planned(plan.as_deref(), i, k)? {
                Some(step) => {
                    self.local_cov[i].copy_from(&step.p_post);
                    full_nofb.then(|| step.gain.clone())
                }
                None => {
                    let (p, gain, _) = update_cov(sensor.as_ref(), &self.p_pred[i], x_ref)?;
                    self.local_cov[i] = p;
                    full_nofb.then_some(gain)
                }
            };
            if let Some(gain) = gain {
                gains.push((gain, sensor.jacobian(x_ref)));
            }
        }
        if full_nofb {
            // Eq. (23): P^{i,j}_{k|k} = (I - w_i h_i^T) (F P^{i,j} F^T + Q) (I - w_j h_j^T)^T.
            let d = sys.state_dim();
            let eye = Matrix::identity(d, d);
            for i in 0..n_sensors {
                for j in 0..n_sensors {
                    self.cross_cov[i][j] = if i == j {
                        self.local_cov[i].clone()
                    } else {
                        (&eye - &gains[i].0 * &gains[i].1)
                            * &cross_pred[i][j]
                            * (&eye - &gains[j].0 * &gains[j].1).transpose()
                    };
                }
            }
        }
        // What is fed back before the next step: x_{k+1|k} = F x_{k|k}, P = F P_{k|k} F^T + Q.
        self.prediction = kf::predict(&sys.transition, &self.est);
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
    fn ess(&self) -> Option<f64> {
        Some(self.last_ess)
    }

    fn feedback(&self) -> Option<Feedback> {
        match self.protocol.feedback() {
            FeedbackMode::None => None,
            FeedbackMode::Prediction => Some(Feedback::Prediction {
                mean: self.prediction.mean.clone(),
                cov: None,
            }),
            FeedbackMode::PredictionAndCovariance => Some(Feedback::Prediction {
                mean: self.prediction.mean.clone(),
                cov: Some(self.prediction.cov.clone()),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::particle::{ResamplePolicy, Resampling};
    use crate::linalg::matrix_from_rows;
    use crate::model::{presets, LinearSensor, MeasurementModel};

    /// The 2-D band kernel gives every particle the log of the exact generalized chi-square
    /// probability (`QuadFormCdf`), to 1e-9, wherever that probability is at least 1e-300.
    #[test]
    fn vector_band_matches_the_exact_quadratic_form_per_particle() {
        let transition = presets::constant_velocity_2d_discrete(1.0, 1.0).unwrap();
        let h = matrix_from_rows(&[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]]);
        let r = matrix_from_rows(&[vec![2.0, 0.3], vec![0.3, 4.0]]);
        let sensor: Arc<dyn MeasurementModel> = Arc::new(LinearSensor::new(h.clone(), r).unwrap());
        let prior = Gaussian::new(Vector::zeros(4), Matrix::identity(4, 4) * 25.0);
        let system = Arc::new(System {
            transition,
            sensors: vec![sensor.clone()],
            prior,
        });
        let options = PfOptions {
            particles: 3000,
            fusion: Fusion::Full,
            resampling: Resampling::Systematic,
            resample_policy: ResamplePolicy::Always,
            band: BandMethod::Exact,
            prop3_samples: 1,
            link_loss: 0.0,
        };
        let protocol = Protocol::new(
            super::super::SendRule::Nis { eta: 1.4 },
            FeedbackMode::Prediction,
        )
        .unwrap();
        let mut center = CensoredPfCenter::new(system, protocol, options, 5).unwrap();
        let x_ref = Vector::from_vec(vec![1.0, 0.0, -2.0, 0.0]);
        let p = Matrix::identity(4, 4) * 3.0;
        let s = &h * &p * h.transpose() + sensor.noise_cov();
        center.cloud.log_weights_mut().fill(0.0);
        center.add_band(0, &x_ref, &s, 1.4).unwrap();
        let (s_inv_sqrt, c) = whitened_band(&s, sensor.noise_cov());
        let qf = QuadFormCdf::new(&c).unwrap();
        let h_ref = sensor.predict(&x_ref);
        let mut checked = 0;
        for k in 0..center.cloud.len() {
            let mut x = vec![0.0; 4];
            center.cloud.copy_particle(k, &mut x).unwrap();
            let d = sensor.predict(&Vector::from_vec(x)) - &h_ref;
            let m = &s_inv_sqrt * d;
            let want = qf.prob_below(&m, 1.4).unwrap();
            let got = center.cloud.log_weights()[k];
            assert!(got.is_finite(), "particle {k}: {got}");
            if want >= 1e-300 {
                assert!(
                    (got - want.ln()).abs() <= 1e-9,
                    "particle {k}: {got} vs {}",
                    want.ln()
                );
                checked += 1;
            }
        }
        assert!(checked > 2000, "only {checked} particles compared");
    }
}
