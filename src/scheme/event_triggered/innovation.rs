//! Innovation-triggered sending with the Gaussian approximation of the truncated innovation
//! (Wu, Jia, Johansson, Shi, IEEE TAC 58(4), 2013).
//!
//! **Trigger** (their Section III, the event-based schedule): with the predicted measurement
//! covariance Z_k = C P_k^- C^T + R and F_k any factor with F_k F_k^T = Z_k^{-1} (here
//! F_k^T = L_k^{-1} for the Cholesky factor Z_k = L_k L_k^T), the whitened innovation
//! ε_k = F_k^T (z_k - C x̂_k^-) has identity covariance and the sensor sends iff
//! `||ε_k||_∞ > δ`.
//!
//! **Estimator** (their Theorem 2, the approximate MMSE estimator): assuming x_k given the
//! past stays Gaussian, a silence means each component of ε_k lies in [-δ, δ]; the components
//! are independent standard normals, so Cov(ε_k | silence) = v(δ) I with the truncated
//! variance factor
//!
//! v(δ) = 1 - (2/√(2π)) δ e^{-δ²/2} [1 - 2Q(δ)]^{-1},
//!
//! and x̂_k = x̂_k^- + γ_k K_k (z_k - C x̂_k^-),
//! P_k = P_k^- - [γ_k + (1 - γ_k) β(δ)] P_k^- C^T Z_k^{-1} C P_k^-, with β(δ) = 1 - v(δ) the
//! fraction of a measurement's information a silence carries. (Transcriptions of the paper
//! name either v or 1 - v "β"; the formula here is derived from the truncated moments and
//! pinned by the limits δ → 0, silence as good as z_k = C x̂_k^-, and δ → ∞, silence
//! uninformative — see the tests.)
//!
//! In the fused, multi-sensor form (see the [module](super) note) the silence of sensor i is
//! the pseudo-measurement C_i x̂_k^- with effective noise R_i' = R_i + (1/β - 1) Z_i, which
//! for one sensor reproduces Theorem 2 exactly: (C P^- C^T + R')^{-1} = β Z^{-1}, and the
//! pseudo-innovation is zero so the mean does not move.
//!
//! **Decision: feedback, not a replica.** The trigger needs x̂_k^- and P_k^- of the estimator.
//! With one sensor (the paper's setting) the sensor could run a replica of the estimator,
//! since the estimate depends only on what this sensor sent; with N sensors the fused
//! prediction depends on the others' data, so the center feeds back x̂_k^- and P_k^-
//! ([`Feedback::Prediction`] with the covariance: n + n(n+1)/2 reals, 32 bits each, broadcast
//! once per step and counted as downlink). The uplink payload is what the paper counts.
//!
//! **Loss-aware center (beyond the paper).** With `link_loss` = p > 0 the center reads "nothing
//! arrived" as {||ε||_∞ <= δ} ∪ {||ε||_∞ > δ and lost}: Cov(ε | nothing) = v_p I with v_p of
//! [`loss_aware::no_arrival_variance`] (the in-band and out-of-band truncated moments, mixed
//! with weights P_in and p P_out), and Theorem 2's update runs with β_p = 1 - v_p in place of
//! β(δ): R_i' = R_i + (1/β_p - 1) Z_i, the mean unmoved. The feedback is assumed to reach the
//! sensors (a lost downlink packet makes a sensor trigger against an older prediction, which
//! no center here models).
use super::{
    check_inbox, loss_aware, nonnegative, prediction_feedback, received_measurement, Evidence,
    Fusion,
};
use crate::filter::{kf, Gaussian};
use crate::linalg::{cholesky, Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::scheme::{
    Feedback, FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System,
};
use crate::stats::truncated_normal;
use rand::RngCore;
use std::sync::Arc;

/// Sensor side: whitens its innovation against the fed-back fused prediction and sends z_k
/// when the largest whitened component exceeds δ.
#[derive(Debug, Clone)]
pub struct InnovationTriggerSensor {
    system: Arc<System>,
    index: usize,
    delta: f64,
    work: WhitenWork,
}

/// Buffers of the whitened innovation for a linear sensor, sized at construction so a step
/// allocates only the message it sends.
#[derive(Debug, Clone)]
struct WhitenWork {
    /// H P^- (m x n).
    hp: Matrix,
    /// H^T (n x m), copied once (a transpose is exact).
    ht: Matrix,
    /// Z = H P^- H^T + R, then (in its storage) its Cholesky factor.
    z: Matrix,
    /// ε (m).
    eps: Vector,
}

impl WhitenWork {
    fn new(sensor: &dyn crate::model::MeasurementModel) -> Self {
        let (m, n) = (sensor.meas_dim(), sensor.state_dim());
        Self {
            hp: Matrix::zeros(m, n),
            ht: sensor
                .as_linear()
                .map_or_else(|| Matrix::zeros(n, m), |l| l.h().transpose()),
            z: Matrix::zeros(m, m),
            eps: Vector::zeros(m),
        }
    }
}

impl InnovationTriggerSensor {
    /// Sensor `index` of `system` with threshold `delta` >= 0.
    pub fn new(system: Arc<System>, index: usize, delta: f64) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        let work = WhitenWork::new(system.sensors[index].as_ref());
        Ok(Self {
            system,
            index,
            delta,
            work,
        })
    }

    /// `||ε||_∞` for a linear sensor, the operations of [`whitened_innovation`](Self::whitened_innovation)
    /// in the same order (ν = z - H x̂^- with H x̂^- as gemv, `(H P^-) H^T` as gemm, `+ R`,
    /// symmetrized, the Cholesky factor and the forward substitution), in the buffers of
    /// `work`. `None` for a nonlinear sensor (the caller takes the general path).
    fn whitened_amax_linear(
        &mut self,
        z: &Vector,
        mean: &Vector,
        cov: &Matrix,
    ) -> Option<Result<f64, SchemeError>> {
        let system = Arc::clone(&self.system);
        let sensor = system.sensors[self.index].as_linear()?;
        Some(self.whiten_linear(sensor, z, mean, cov))
    }

    fn whiten_linear(
        &mut self,
        sensor: &crate::model::LinearSensor,
        z: &Vector,
        mean: &Vector,
        cov: &Matrix,
    ) -> Result<f64, SchemeError> {
        use crate::linalg::fixed;
        use crate::model::MeasurementModel;
        kf::check_measurement(sensor, z)?;
        let w = &mut self.work;
        fixed::gemv(&mut w.eps, sensor.h(), mean);
        for (e, zi) in w.eps.iter_mut().zip(z.iter()) {
            *e = zi - *e;
        }
        fixed::gemm(&mut w.hp, sensor.h(), cov);
        fixed::gemm(&mut w.z, &w.hp, &w.ht);
        fixed::add_assign(w.z.as_mut_slice(), sensor.noise_cov().as_slice());
        crate::linalg::symmetrize(&mut w.z);
        let err = |source| SchemeError::Matrix {
            what: "innovation covariance Z",
            source,
        };
        if w.z.iter().any(|v| !v.is_finite()) {
            return Err(err(crate::linalg::LinalgError::NonFinite));
        }
        let m = w.z.nrows();
        let chol = fixed::cholesky(std::mem::replace(&mut w.z, Matrix::zeros(0, 0)))
            .ok_or(err(crate::linalg::LinalgError::NotPositiveDefinite))?;
        let solved = fixed::lower_solve(chol.l_dirty(), &mut w.eps);
        w.z = chol.unpack_dirty();
        debug_assert_eq!(w.z.nrows(), m);
        if !solved {
            return Err(SchemeError::Unsupported(
                "singular Cholesky factor of Z".into(),
            ));
        }
        Ok(w.eps.amax())
    }

    /// The whitened innovation ε = L^{-1} (z - h(x̂^-)), Z = H P^- H^T + R = L L^T.
    pub fn whitened_innovation(
        &self,
        z: &Vector,
        mean: &Vector,
        cov: &Matrix,
    ) -> Result<Vector, SchemeError> {
        let sensor = self.system.sensors[self.index].as_ref();
        let inn = kf::innovation(sensor, &Gaussian::new(mean.clone(), cov.clone()), z)?;
        let chol = cholesky(&inn.s).map_err(|source| SchemeError::Matrix {
            what: "innovation covariance Z",
            source,
        })?;
        let eps = chol
            .l()
            .solve_lower_triangular(&inn.nu)
            .ok_or_else(|| SchemeError::Unsupported("singular Cholesky factor of Z".into()))?;
        Ok(eps)
    }
}

impl SensorNode for InnovationTriggerSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        feedback: Option<&Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        let (mean, cov) = prediction_feedback(self.index, feedback, true)?;
        let cov = cov.expect("checked");
        let amax = match self.whitened_amax_linear(z, mean, cov) {
            Some(a) => a?,
            None => self.whitened_innovation(z, mean, cov)?.amax(),
        };
        if amax > self.delta {
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Fusion side: the KF with Theorem 2's silence update, fused over sensors.
///
/// A step allocates nothing (linear sensors): the prediction of the estimate is kept (made
/// after each step, it is both the feedback and the next step's prior) and the silences'
/// pseudo-measurements are formed in per-sensor buffers.
#[derive(Debug, Clone)]
pub struct InnovationTriggerCenter {
    system: Arc<System>,
    /// Per sensor, β(δ) = 1 - v(δ): the information fraction of a silence (the same for every
    /// sensor as published; with a loss-aware center, 1 - v_p of
    /// [`loss_aware::no_arrival_variance`], which depends on the sensor's dimension).
    betas: Vec<f64>,
    est: Gaussian,
    /// `kf::predict` of `est`: x̂_{k+1}^-, P_{k+1}^-.
    pred: Gaussian,
    predict_work: kf::PredictWork,
    fusion: Fusion,
    /// The fused estimate of a step, swapped into `est` when the step succeeds.
    out: Gaussian,
    silences: Vec<SilenceWork>,
}

/// A silence's pseudo-measurement C_i x̂_k^- and effective noise R_i', and the buffers they
/// are computed in.
#[derive(Debug, Clone)]
struct SilenceWork {
    z: Vector,
    r: Matrix,
    /// H P^- (m x n).
    hp: Matrix,
    /// H^T (n x m), copied once (a transpose is exact); empty for a nonlinear sensor.
    ht: Matrix,
}

/// R' = R + (1/β - 1) Z with Z = H P^- H^T + R, into `r` (Theorem 2's silence update as a
/// pseudo-measurement noise, see the module note): `(H P^-) H^T` as nalgebra's products
/// (`fixed::gemm` is their kernel; `hp` holds H P^-), `+ R`, the scaling and the sum, in the
/// order of the expression `R + (H P^- H^T + R) (1/β - 1)`, so the bits are the same.
fn effective_noise(
    beta: f64,
    h: &Matrix,
    ht: &Matrix,
    noise: &Matrix,
    cov: &Matrix,
    hp: &mut Matrix,
    r: &mut Matrix,
) {
    use crate::linalg::fixed;
    fixed::gemm(hp, h, cov);
    fixed::gemm(r, hp, ht);
    fixed::add_assign(r.as_mut_slice(), noise.as_slice());
    let scale = 1.0 / beta - 1.0;
    for (v, n) in r.iter_mut().zip(noise.iter()) {
        *v = n + *v * scale;
    }
}

impl InnovationTriggerCenter {
    pub fn new(system: Arc<System>, delta: f64) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        let est = system.prior.clone();
        let n = est.dim();
        let mut predict_work = kf::PredictWork::new(n);
        let mut pred = est.clone();
        kf::predict_into(&system.transition, &est, &mut pred, &mut predict_work);
        let silences = system
            .sensors
            .iter()
            .map(|s| {
                let m = s.meas_dim();
                SilenceWork {
                    z: Vector::zeros(m),
                    r: Matrix::zeros(m, m),
                    hp: Matrix::zeros(m, n),
                    ht: s
                        .as_linear()
                        .map_or_else(|| Matrix::zeros(0, 0), |l| l.h().transpose()),
                }
            })
            .collect();
        let betas = vec![1.0 - truncated_normal::band_variance(delta); system.n_sensors()];
        Ok(Self {
            fusion: Fusion::new(&system),
            out: est.clone(),
            system,
            betas,
            est,
            pred,
            predict_work,
            silences,
        })
    }

    /// The loss-aware center (beyond the paper): "nothing arrived" from sensor i, with the link
    /// losing a message with probability `link_loss` = p, is read with β_p = 1 - v_p
    /// ([`loss_aware::no_arrival_variance`], derived there) in Theorem 2's update in place of
    /// β(δ). `None` or 0: the published center, unchanged.
    pub fn with_link_loss(
        mut self,
        delta: f64,
        link_loss: Option<Vec<f64>>,
    ) -> Result<Self, SchemeError> {
        let n = self.system.n_sensors();
        if let Some(ps) = loss_aware::effective_link_loss(link_loss, n)? {
            for ((beta, s), p) in self.betas.iter_mut().zip(&self.system.sensors).zip(ps) {
                *beta = 1.0 - loss_aware::no_arrival_variance(delta, s.meas_dim(), p);
            }
        }
        Ok(self)
    }

    /// β of sensor `i`.
    pub fn beta(&self, i: usize) -> f64 {
        self.betas[i]
    }

    /// Whether a silence of sensor `i` carries information: β does not underflow (δ not so
    /// large, or the loss not so likely, that a silence says nothing).
    fn silence_informs(&self, i: usize) -> bool {
        let beta = self.betas[i];
        !(beta.is_nan() || beta <= 1e-300)
    }

    /// The effective noise of a silence of sensor `i` against the prediction:
    /// R' = R + (1/β - 1) Z (module note), or `None` when β underflows (δ so large that a
    /// silence says nothing).
    pub fn silence_noise(&self, i: usize, pred: &Gaussian) -> Option<Matrix> {
        if !self.silence_informs(i) {
            return None;
        }
        let sensor = self.system.sensors[i].as_ref();
        let h = sensor.jacobian(&pred.mean);
        let (m, n) = h.shape();
        let (mut hp, mut r) = (Matrix::zeros(m, n), Matrix::zeros(m, m));
        let ht = h.transpose();
        effective_noise(
            self.betas[i],
            &h,
            &ht,
            sensor.noise_cov(),
            &pred.cov,
            &mut hp,
            &mut r,
        );
        Some(r)
    }

    /// The pseudo-measurement C_i x̂_k^- and R_i' of a silence of sensor `i` into its buffers
    /// (`predict` and [`silence_noise`](Self::silence_noise), in place for a linear sensor).
    fn form_silence(&mut self, i: usize) {
        let sensor = self.system.sensors[i].as_ref();
        match sensor.as_linear() {
            Some(l) => {
                let w = &mut self.silences[i];
                crate::linalg::fixed::gemv(&mut w.z, l.h(), &self.pred.mean);
                let (beta, cov) = (self.betas[i], &self.pred.cov);
                effective_noise(
                    beta,
                    l.h(),
                    &w.ht,
                    sensor.noise_cov(),
                    cov,
                    &mut w.hp,
                    &mut w.r,
                );
            }
            None => {
                let r = self.silence_noise(i, &self.pred).expect("silences inform");
                let w = &mut self.silences[i];
                w.z = sensor.predict(&self.pred.mean);
                w.r = r;
            }
        }
    }
}

impl FusionCenter for InnovationTriggerCenter {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        check_inbox(&self.system, inbox)?;
        // The inbox first (its errors before the fusion's), and the silences' evidence.
        for (i, msg) in inbox.iter().enumerate() {
            received_measurement(i, msg)?;
            if self.silence_informs(i) && matches!(msg, Received::Silent) {
                self.form_silence(i);
            }
        }
        self.fusion.start(&self.pred)?;
        for (i, msg) in inbox.iter().enumerate() {
            let evidence = match (received_measurement(i, msg)?, msg) {
                (Some(z), _) => Evidence::Measurement(z),
                (None, Received::Silent) if self.silence_informs(i) => {
                    let w = &self.silences[i];
                    Evidence::Pseudo { z: &w.z, r: &w.r }
                }
                (None, _) => Evidence::Nothing,
            };
            self.fusion.add(&self.system, i, evidence)?;
        }
        self.fusion.finish(&mut self.out)?;
        std::mem::swap(&mut self.est, &mut self.out);
        kf::predict_into(
            &self.system.transition,
            &self.est,
            &mut self.pred,
            &mut self.predict_work,
        );
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }

    fn feedback(&self) -> Option<Feedback> {
        Some(Feedback::Prediction {
            mean: self.pred.mean.clone(),
            cov: Some(self.pred.cov.clone()),
        })
    }
}

/// The innovation-triggered scheme of Wu et al. 2013 with threshold δ (the knob).
#[derive(Debug, Clone)]
pub struct InnovationTriggerScheme {
    system: Arc<System>,
    delta: f64,
    /// The loss probability a loss-aware center assumes for each sensor (`None`: the
    /// published center).
    link_loss: Option<Vec<f64>>,
}

impl InnovationTriggerScheme {
    /// `delta` >= 0 (0: every sensor sends every measurement).
    pub fn new(system: Arc<System>, delta: f64) -> Result<Self, SchemeError> {
        nonnegative("delta", delta)?;
        Ok(Self {
            system,
            delta,
            link_loss: None,
        })
    }

    /// The loss-aware center ([`InnovationTriggerCenter::with_link_loss`]); `None` or 0: the
    /// published one.
    pub fn with_link_loss(mut self, link_loss: Option<Vec<f64>>) -> Result<Self, SchemeError> {
        self.link_loss = loss_aware::effective_link_loss(link_loss, self.system.n_sensors())?;
        Ok(self)
    }
}

impl Scheme for InnovationTriggerScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = (0..self.system.n_sensors())
            .map(|i| {
                InnovationTriggerSensor::new(self.system.clone(), i, self.delta)
                    .map(|s| Box::new(s) as Box<dyn SensorNode>)
            })
            .collect::<Result<_, _>>()?;
        Ok(SchemeInstance {
            sensors,
            center: Box::new(
                InnovationTriggerCenter::new(self.system.clone(), self.delta)?
                    .with_link_loss(self.delta, self.link_loss.clone())?,
            ),
        })
    }
}
