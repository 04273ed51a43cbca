//! CFwMD-exact: exact fusion of censored data without feedback (beyond Zheng et al. (2014)).
//!
//! Without feedback each sensor censors against its own KF prediction, which the fusion center
//! never sees. Proposition 3 integrates over a Gaussian model of the local predictions given
//! x_k, and with that model the integral does not depend on x_k at all (see
//! [`super::center`]), so it cannot tell particles apart. But the fusion center knows every
//! sensor's KF recursion (for linear sensors the gains are deterministic) and, for every past
//! step, either the measurement or the band it fell in. So each particle carries the state
//! **and its own copy of every sensor's local KF mean**:
//! - a received z^i weights the particle by p(z^i | x) and by the send event itself,
//!   NIS >= eta for that copy (a particle whose copy would not have sent gets weight 0), then
//!   updates the copy with z^i;
//! - a silent sensor weights the particle by the band probability with the particle's own
//!   copy (Q(xi_1) - Q(xi_2) with mu = h (x - x_hat^i)), then the particle draws z^i from
//!   N(h x, R) truncated to the no-send region of its copy and updates the copy with the draw.
//!
//! Resampling copies a particle's state together with its copies, so every particle carries
//! a history that is consistent with everything the fusion center has seen.
use super::{PfOptions, Protocol};
use crate::filter::kf::update_cov;
use crate::filter::particle::{ParticleCloud, ParticleTransition};
use crate::filter::Gaussian;
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::{LinearSensor, LinearTransition};
use crate::scheme::{FusionCenter, SchemeError, System};
use crate::stats::{band_kernel, quadform::QuadFormCdf};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

fn pf_err(e: crate::filter::particle::ParticleError) -> SchemeError {
    SchemeError::Unsupported(format!("particle filter: {e}"))
}

/// A draw of N(0, 1) truncated to (a, b), exact, by rejection from the cheapest proposal
/// (every branch accepts with probability above about 0.37):
/// - a wide band straddling 0 (b - a >= 1): N(0, 1) itself;
/// - a narrow band (b^2 - a^2 <= 2 on the upper side, or b - a < 1 around 0): uniform on
///   (a, b), accepted with probability exp((m^2 - t^2) / 2), m the point of the band nearest 0;
/// - a wide band in a tail: Robert's (1995) translated exponential proposal with rate
///   lambda = (a + sqrt(a^2 + 4)) / 2, accepted with probability exp(-(t - lambda)^2 / 2).
///
/// The lower tail is the mirror image of the upper one.
pub fn truncated_standard_normal<R: Rng + ?Sized>(a: f64, b: f64, rng: &mut R) -> f64 {
    debug_assert!(a < b);
    if b <= 0.0 {
        return -truncated_standard_normal(-b, -a, rng);
    }
    if a < 0.0 {
        if b - a >= 1.0 {
            loop {
                let t: f64 = StandardNormal.sample(rng);
                if t > a && t < b {
                    return t;
                }
            }
        }
        // Narrow band around 0: uniform proposal, acceptance exp(-t^2/2) >= exp(-1/2).
        loop {
            let t = a + (b - a) * rng.random::<f64>();
            if rng.random::<f64>() < (-0.5 * t * t).exp() {
                return t;
            }
        }
    }
    if b * b - a * a <= 2.0 {
        loop {
            let t = a + (b - a) * rng.random::<f64>();
            if rng.random::<f64>() < (0.5 * (a * a - t * t)).exp() {
                return t;
            }
        }
    }
    let lambda = 0.5 * (a + (a * a + 4.0).sqrt());
    loop {
        let e: f64 = rand_distr::Exp1.sample(rng);
        let t = a + e / lambda;
        if t < b && rng.random::<f64>() < (-0.5 * (t - lambda) * (t - lambda)).exp() {
            return t;
        }
    }
}

/// The fusion center of CFwMD-exact (linear sensors, no feedback).
pub struct ExactCensoredCenter {
    system: Arc<System>,
    sensors: Vec<LinearSensor>,
    transition: ParticleTransition,
    options: PfOptions,
    eta: f64,
    cloud: ParticleCloud,
    rng: Xoshiro256PlusPlus,
    est: Gaussian,
    /// ESS after the last update, before resampling.
    last_ess: f64,
    /// Each sensor's local covariance P^i_{k-1|k-1} (deterministic for linear sensors).
    local_cov: Vec<Matrix>,
    /// Scratch: h x and h x_hat^i (rows component-major), the (drawn or received) z.
    hx: Vec<f64>,
    pred: Vec<f64>,
    z: Vec<f64>,
    /// Steps at which no particle's copy agreed with a sensor's send event, so the event's
    /// indicator was dropped for that sensor and step (a sign of too few particles).
    pub send_event_skips: usize,
}

impl ExactCensoredCenter {
    pub fn new(
        system: Arc<System>,
        protocol: Protocol,
        options: PfOptions,
        seed: u64,
    ) -> Result<Self, SchemeError> {
        let eta = protocol.eta().ok_or_else(|| {
            SchemeError::Unsupported("CFwMD-exact is for censoring sensors".into())
        })?;
        let sensors: Vec<LinearSensor> = system
            .sensors
            .iter()
            .map(|s| {
                s.as_linear().cloned().ok_or_else(|| {
                    SchemeError::Unsupported(
                        "CFwMD-exact needs linear sensors: an EKF's gains depend on its own (unknown) estimate".into(),
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        let d = system.state_dim();
        let n = sensors.len();
        // Augmented state (x, x_hat^1, ..., x_hat^N): the copies are predicted with F and no
        // noise, the state with F and Q.
        let dim = d * (n + 1);
        let mut f_aug = Matrix::zeros(dim, dim);
        let mut q_aug = Matrix::zeros(dim, dim);
        for b in 0..=n {
            f_aug
                .view_mut((b * d, b * d), (d, d))
                .copy_from(system.transition.f());
        }
        q_aug
            .view_mut((0, 0), (d, d))
            .copy_from(system.transition.q());
        let aug = LinearTransition::new(f_aug, q_aug)
            .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
        let transition = ParticleTransition::new(&aug).map_err(pf_err)?;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        // x ~ prior; every copy starts at the prior mean, as every sensor's KF does.
        let mut prior_mean = Vector::zeros(dim);
        let mut prior_cov = Matrix::zeros(dim, dim);
        for b in 0..=n {
            prior_mean.rows_mut(b * d, d).copy_from(&system.prior.mean);
        }
        prior_cov
            .view_mut((0, 0), (d, d))
            .copy_from(&system.prior.cov);
        let cloud = ParticleCloud::from_gaussian(
            options.particles,
            &Gaussian::new(prior_mean, prior_cov),
            &mut rng,
        )
        .map_err(pf_err)?;
        let max_m = sensors.iter().map(|s| s.h().nrows()).max().unwrap_or(1);
        let p = options.particles;
        Ok(Self {
            local_cov: vec![system.prior.cov.clone(); n],
            est: system.prior.clone(),
            hx: vec![0.0; max_m * p],
            pred: vec![0.0; max_m * p],
            z: vec![0.0; max_m * p],
            sensors,
            transition,
            options,
            eta,
            last_ess: cloud.len() as f64,
            cloud,
            rng,
            system,
            send_event_skips: 0,
        })
    }

    /// The particle cloud (augmented: state, then each sensor's copy).
    pub fn cloud(&self) -> &ParticleCloud {
        &self.cloud
    }

    /// The particle's copy of sensor `i`'s local mean (for tests).
    pub fn copy_of(&self, particle: usize, i: usize) -> Vector {
        let d = self.system.state_dim();
        Vector::from_fn(d, |j, _| self.cloud.component(d * (i + 1) + j)[particle])
    }

    /// Fills hx (rows of H x) and pred (rows of H x_hat^i) for sensor `i`.
    fn project(&mut self, i: usize) {
        let d = self.system.state_dim();
        let n = self.cloud.len();
        let h = self.sensors[i].h().clone();
        let states = self.cloud.states();
        for r in 0..h.nrows() {
            let (hx, pred) = (
                &mut self.hx[r * n..(r + 1) * n],
                &mut self.pred[r * n..(r + 1) * n],
            );
            hx.fill(0.0);
            pred.fill(0.0);
            for j in 0..d {
                let c = h[(r, j)];
                if c != 0.0 {
                    for (o, x) in hx.iter_mut().zip(states.component(j)) {
                        *o += c * x;
                    }
                    for (o, x) in pred.iter_mut().zip(states.component(d * (i + 1) + j)) {
                        *o += c * x;
                    }
                }
            }
        }
    }

    /// Copy update x_hat^i += K (z - H x_hat^i), with z and H x_hat^i in the scratch rows.
    fn update_copies(&mut self, i: usize, gain: &Matrix) {
        let d = self.system.state_dim();
        let n = self.cloud.len();
        let m = gain.ncols();
        for j in 0..d {
            let comp = self.cloud.component_mut(d * (i + 1) + j);
            for r in 0..m {
                let k = gain[(j, r)];
                if k == 0.0 {
                    continue;
                }
                let (z, pred) = (&self.z[r * n..(r + 1) * n], &self.pred[r * n..(r + 1) * n]);
                for ((c, zv), pv) in comp.iter_mut().zip(z).zip(pred) {
                    *c += k * (zv - pv);
                }
            }
        }
    }
}

impl FusionCenter for ExactCensoredCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let sys = self.system.clone();
        let (f, q) = (sys.transition.f(), sys.transition.q());
        let n_sensors = self.sensors.len();
        if inbox.len() != n_sensors {
            return Err(SchemeError::Unsupported(format!(
                "inbox has {} entries for {n_sensors} sensors",
                inbox.len()
            )));
        }
        let d = sys.state_dim();
        self.cloud
            .propagate(&self.transition, &mut self.rng)
            .map_err(pf_err)?;
        for (i, msg) in inbox.iter().enumerate() {
            let mut p_pred = f * &self.local_cov[i] * f.transpose() + q;
            symmetrize(&mut p_pred);
            let sensor = self.sensors[i].clone();
            let (p_post, gain, s) = update_cov(&sensor, &p_pred, &sys.prior.mean)?;
            self.local_cov[i] = p_post;
            let m = sensor.h().nrows();
            let r = crate::model::MeasurementModel::noise_cov(&sensor).clone();
            self.project(i);
            match msg {
                Received::Measurement(z) => {
                    self.weigh_measurement(i, z, m, &r, &s)?;
                }
                Received::Silent => {
                    if m == 1 {
                        self.weigh_silence_scalar(&s, &r);
                    } else {
                        self.weigh_silence_band(&sensor, m, &s, &r)?;
                    }
                }
                Received::NotScheduled => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: "CFwMD-exact needs every sensor's decision at every step".into(),
                    });
                }
                other => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: format!("expected a measurement or silence, got {other:?}"),
                    })
                }
            }
            self.update_copies(i, &gain);
        }
        self.cloud.normalize().map_err(pf_err)?;
        self.last_ess = self.cloud.ess().map_err(pf_err)?;
        self.fused_estimate(d)?;
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

impl ExactCensoredCenter {
    /// A received measurement `z` of sensor `i` (dimension `m`): each particle's send event
    /// (its copy's NIS at least eta, when any live particle has one), then p(z | x).
    fn weigh_measurement(
        &mut self,
        i: usize,
        z: &Vector,
        m: usize,
        r: &Matrix,
        s: &Matrix,
    ) -> Result<(), SchemeError> {
        let n = self.cloud.len();
        if z.len() != m || z.iter().any(|v| !v.is_finite()) {
            return Err(SchemeError::Protocol {
                sensor: i,
                message: format!("corrupt measurement {:?}", z.as_slice()),
            });
        }
        let r_inv = crate::linalg::spd_inverse(r)
            .map_err(|source| SchemeError::Matrix { what: "R", source })?;
        let s_inv = crate::linalg::spd_inverse(s)
            .map_err(|source| SchemeError::Matrix { what: "S", source })?;
        // The send event for each particle's copy, then p(z | x).
        // Only particles still alive count: sensors are conditioned one after the
        // other, so a send event could otherwise kill the survivors of another.
        // NIS of each copy goes into the z scratch row (z is filled after use).
        let mut consistent = 0usize;
        let (nis, lw) = (&mut self.z[..n], self.cloud.log_weights());
        for (p, (v, l)) in nis.iter_mut().zip(lw).enumerate() {
            let mut acc = 0.0;
            for a in 0..m {
                for b in 0..m {
                    acc += (z[a] - self.pred[a * n + p])
                        * s_inv[(a, b)]
                        * (z[b] - self.pred[b * n + p]);
                }
            }
            *v = acc;
            consistent += usize::from(acc >= self.eta && l.is_finite());
        }
        let use_event = consistent > 0;
        if !use_event {
            self.send_event_skips += 1;
        }
        let lw = self.cloud.log_weights_mut();
        for (p, l) in lw.iter_mut().enumerate() {
            let mut quad = 0.0;
            for a in 0..m {
                for b in 0..m {
                    quad +=
                        (z[a] - self.hx[a * n + p]) * r_inv[(a, b)] * (z[b] - self.hx[b * n + p]);
                }
            }
            *l -= 0.5 * quad;
            if use_event && self.z[p] < self.eta {
                *l = f64::NEG_INFINITY;
            }
        }
        for a in 0..m {
            self.z[a * n..(a + 1) * n].fill(z[a]);
        }
        Ok(())
    }

    /// Silence of a scalar sensor: the band term of each particle, then its copy's
    /// measurement drawn from the truncated normal of the band.
    fn weigh_silence_scalar(&mut self, s: &Matrix, r: &Matrix) {
        let n = self.cloud.len();
        let half = (self.eta * s[(0, 0)]).sqrt();
        let sd = r[(0, 0)].sqrt();
        // mu = h (x - x_hat^i): band term, then the truncated draw of z.
        // mu goes into the z scratch row; the draws below overwrite it.
        let mu = &mut self.z[..n];
        for ((v, hx), pr) in mu.iter_mut().zip(&self.hx[..n]).zip(&self.pred[..n]) {
            *v = hx - pr;
        }
        band_kernel::add_log_band_probability(
            &self.z[..n],
            half,
            1.0 / sd,
            self.cloud.log_weights_mut(),
        );
        for p in 0..n {
            let (hx, pr) = (self.hx[p], self.pred[p]);
            let t = truncated_standard_normal(
                (pr - half - hx) / sd,
                (pr + half - hx) / sd,
                &mut self.rng,
            );
            self.z[p] = hx + sd * t;
        }
    }

    /// Silence of a vector sensor: the probability of the whitened band (a quadratic form)
    /// of each particle, then its copy's measurement drawn by rejection into the band.
    fn weigh_silence_band(
        &mut self,
        sensor: &LinearSensor,
        m: usize,
        s: &Matrix,
        r: &Matrix,
    ) -> Result<(), SchemeError> {
        let n = self.cloud.len();
        // q = S^{-1/2} (z - H x_hat) ~ N(S^{-1/2} H (x - x_hat), S^{-1/2} R S^{-1/2}).
        let (s_inv_sqrt, c) = super::censoring::whitened_band(s, r);
        let qf = QuadFormCdf::new(&c).map_err(|e| SchemeError::Unsupported(e.to_string()))?;
        let r_sqrt = crate::model::MeasurementModel::noise_sqrt(sensor).clone();
        let s_chol = crate::linalg::cholesky(s)
            .map_err(|source| SchemeError::Matrix { what: "S", source })?;
        let s_l = s_chol.l();
        let mut mean = vec![0.0; m];
        // Scratch of the rejection loop (it may try many times per particle:
        // no allocation in it): normals, R^{1/2} draw, innovation, L^{-1} nu.
        let mut draw = vec![0.0; m];
        let mut nu = vec![0.0; m];
        let mut y = vec![0.0; m];
        for p in 0..n {
            for (a, v) in mean.iter_mut().enumerate() {
                *v = (0..m)
                    .map(|b| s_inv_sqrt[(a, b)] * (self.hx[b * n + p] - self.pred[b * n + p]))
                    .sum();
            }
            let prob = qf
                .prob_below_slice(&mean, self.eta)
                .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
            self.cloud.log_weights_mut()[p] += prob.max(f64::MIN_POSITIVE).ln();
            // Rejection from N(H x, R) until the copy's NIS is below eta; a
            // particle whose band is nearly impossible (weight < 1e-6 of its
            // prior share) keeps its last draw pulled radially into the band.
            let tries = if prob > 1e-6 { 100_000 } else { 64 };
            for _ in 0..tries {
                for v in draw.iter_mut() {
                    *v = StandardNormal.sample(&mut self.rng);
                }
                // nu = h(x) + R^{1/2} draw - H x_hat, then y = L^{-1} nu by
                // forward substitution (S = L L^T), NIS = |y|^2.
                for (a, v) in nu.iter_mut().enumerate() {
                    let mut e = 0.0;
                    for (b, d) in draw.iter().enumerate() {
                        e += r_sqrt[(a, b)] * d;
                    }
                    *v = self.hx[a * n + p] + e - self.pred[a * n + p];
                }
                let mut nis = 0.0;
                for (a, &nu_a) in nu.iter().enumerate() {
                    let mut acc = nu_a;
                    for (b, &y_b) in y[..a].iter().enumerate() {
                        acc -= s_l[(a, b)] * y_b;
                    }
                    y[a] = acc / s_l[(a, a)];
                    nis += y[a] * y[a];
                }
                let scale = if nis < self.eta {
                    1.0
                } else {
                    0.999 * (self.eta / nis).sqrt()
                };
                for (a, nu_a) in nu.iter().enumerate() {
                    self.z[a * n + p] = self.pred[a * n + p] + scale * nu_a;
                }
                if nis < self.eta {
                    break;
                }
            }
        }
        Ok(())
    }

    /// The fused estimate of dimension `d` into `self.est`.
    fn fused_estimate(&mut self, d: usize) -> Result<(), SchemeError> {
        // The fused estimate: weighted mean and covariance of the state part only.
        let w = self.cloud.weights().map_err(pf_err)?.to_vec();
        let mut mean = Vector::zeros(d);
        for j in 0..d {
            mean[j] = self
                .cloud
                .component(j)
                .iter()
                .zip(&w)
                .map(|(x, w)| x * w)
                .sum();
        }
        let mut cov = Matrix::zeros(d, d);
        for a in 0..d {
            for b in a..d {
                let (xa, xb) = (self.cloud.component(a), self.cloud.component(b));
                let v: f64 = xa
                    .iter()
                    .zip(xb)
                    .zip(&w)
                    .map(|((x, y), w)| w * (x - mean[a]) * (y - mean[b]))
                    .sum();
                cov[(a, b)] = v;
                cov[(b, a)] = v;
            }
        }
        self.est = Gaussian::new(mean, cov);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::particle::{ResamplePolicy, Resampling};
    use crate::linalg::matrix_from_rows;
    use crate::model::{presets, MeasurementModel};
    use crate::scheme::censored_pf::{
        censoring::nis_threshold, BandMethod, CensoringSensor, FeedbackMode, Fusion, SendRule,
    };
    use crate::scheme::SensorNode;
    use crate::stats::normal;

    fn system(vector: bool) -> Arc<System> {
        let transition = presets::constant_velocity_1d_discrete(1.0, 4.0).unwrap();
        let sensor = |_| -> Arc<dyn MeasurementModel> {
            if vector {
                Arc::new(
                    LinearSensor::new(
                        Matrix::identity(2, 2),
                        Matrix::from_diagonal(&Vector::from_vec(vec![2.0, 4.0])),
                    )
                    .unwrap(),
                )
            } else {
                Arc::new(
                    LinearSensor::new(
                        matrix_from_rows(&[vec![1.0, 0.0]]),
                        Matrix::from_element(1, 1, 1.0),
                    )
                    .unwrap(),
                )
            }
        };
        Arc::new(System {
            transition,
            sensors: (0..2).map(sensor).collect(),
            prior: Gaussian::new(Vector::from_vec(vec![0.0, 10.0]), Matrix::identity(2, 2)),
        })
    }

    fn options(particles: usize) -> PfOptions {
        PfOptions {
            particles,
            fusion: Fusion::Exact,
            resampling: Resampling::Systematic,
            resample_policy: ResamplePolicy::EssBelow(0.0),
            band: BandMethod::Exact,
            prop3_samples: 1,
            link_loss: 0.0,
        }
    }

    /// The truncated draws stay inside the band and have the truncated-normal mean and
    /// variance (within 4 Monte Carlo standard errors), in the centre and in both tails.
    #[test]
    fn truncated_draws_have_the_truncated_normal_moments() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(4);
        for (a, b) in [
            (-0.5, 0.7),
            (-3.0, -1.0),
            (1.5, 4.0),
            (6.0, 6.5),
            (-9.0, -8.2),
            (-0.1, 30.0),
        ] {
            let z = normal::cdf(b) - normal::cdf(a);
            let z = if a > 0.0 {
                normal::q(a) - normal::q(b)
            } else {
                z
            };
            let mean = (normal::pdf(a) - normal::pdf(b)) / z;
            let var = 1.0 + (a * normal::pdf(a) - b * normal::pdf(b)) / z - mean * mean;
            let n = 50_000;
            let draws: Vec<f64> = (0..n)
                .map(|_| truncated_standard_normal(a, b, &mut rng))
                .collect();
            assert!(
                draws.iter().all(|&t| t >= a && t <= b),
                "({a}, {b}): a draw left the band"
            );
            let m = draws.iter().sum::<f64>() / n as f64;
            let v = draws.iter().map(|t| (t - m).powi(2)).sum::<f64>() / (n - 1) as f64;
            let se_m = (var / n as f64).sqrt();
            // Variance of the sample variance ~ (mu4 - var^2) / n; bounded by 2 var^2 / n
            // times a kurtosis factor of at most 3 for these truncations.
            let se_v = var * (6.0 / n as f64).sqrt();
            assert!(
                (m - mean).abs() < 4.0 * se_m,
                "({a}, {b}): mean {m} vs {mean}"
            );
            assert!(
                (v - var).abs() < 4.0 * se_v,
                "({a}, {b}): variance {v} vs {var}"
            );
        }
    }

    /// With every measurement received, each particle's copy of a sensor's filter equals
    /// that sensor's own filter, and (l = N) the log-weights are exactly the all-send
    /// Gaussian likelihood of each particle.
    #[test]
    fn copies_track_the_sensors_and_weights_equal_all_send() {
        for vector in [false, true] {
            let sys = system(vector);
            let eta = nis_threshold(sys.sensors[0].meas_dim(), 2.0, 2).unwrap();
            assert_eq!(eta, 0.0);
            let protocol = Protocol::new(SendRule::Nis { eta }, FeedbackMode::None).unwrap();
            let mut center =
                ExactCensoredCenter::new(sys.clone(), protocol, options(200), 1).unwrap();
            let mut sensors: Vec<CensoringSensor> = sys
                .sensors
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    CensoringSensor::new(
                        i,
                        s.clone(),
                        Arc::new(sys.transition.clone()),
                        sys.prior.clone(),
                        protocol,
                    )
                })
                .collect();
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
            let mut x = sys.prior.mean.clone();
            for k in 1..=15 {
                x = sys.transition.sample_next(&x, &mut rng);
                // Readings that are singles already: they cross the network unchanged
                // (`link::as_sent`), so the copies see exactly what the sensors see.
                let zs: Vec<Vector> = sys
                    .sensors
                    .iter()
                    .map(|s| s.sample(&x, &mut rng).map(crate::link::as_sent))
                    .collect();
                let inbox: Vec<Received> = sensors
                    .iter_mut()
                    .zip(&zs)
                    .map(|(s, z)| s.step(k, z, None, &mut rng).unwrap().into())
                    .collect();
                assert!(inbox.iter().all(|r| matches!(r, Received::Measurement(_))));
                let before: Vec<f64> = center.cloud().log_weights().to_vec();
                center.step(k, &inbox).unwrap();
                for (i, s) in sensors.iter().enumerate() {
                    for p in [0, 57, 199] {
                        let diff = (center.copy_of(p, i) - &s.local().mean).amax();
                        assert!(diff < 1e-9, "vector={vector} step {k} sensor {i} particle {p}: copy differs by {diff}");
                    }
                }
                // Log-weight increments equal the Gaussian likelihood up to one constant.
                let after = center.cloud().log_weights();
                let mut incr = Vec::new();
                for p in 0..200 {
                    let xp = Vector::from_fn(2, |j, _| center.cloud().component(j)[p]);
                    let mut ll = 0.0;
                    for (s, z) in sys.sensors.iter().zip(&zs) {
                        ll -= 0.5
                            * crate::linalg::mahalanobis_sq(&(z - s.predict(&xp)), s.noise_cov())
                                .unwrap();
                    }
                    incr.push(after[p] - before[p] - ll);
                }
                let spread = incr.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v))
                    - incr.iter().fold(f64::INFINITY, |m, v| m.min(*v));
                assert!(
                    spread < 1e-9,
                    "vector={vector} step {k}: weights differ from all-send's by {spread}"
                );
            }
        }
    }
}
