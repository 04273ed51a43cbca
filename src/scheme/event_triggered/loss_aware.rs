//! Loss-aware fusion of the event-triggered baselines (beyond the papers): the center is told
//! the link's loss probability p (scheme parameter `link_loss`) and reads "nothing arrived" as
//! what it is, a silence **or** a message the link lost, instead of a silence.
//!
//! A lost packet reaches the center as [`crate::link::Received::Silent`]: it cannot tell the
//! two apart. The published centers read every silence as the trigger's information ("the
//! innovation stayed small"), which a loss makes wrong and overconfident. With a lossy link the
//! event is
//!
//! {nothing arrived} = {silent} ∪ {sent and lost},
//! P(nothing arrived | z) = P(silent | z) + p P(sent | z) = p + (1 - p) P(silent | z),
//!
//! since the link's fate is independent of z (and of the trigger's coin). Every update here is
//! that likelihood, or the Gaussian approximation its scheme already makes, and reduces to the
//! published update at p = 0; a scheme with `link_loss` absent or 0 runs the published code
//! itself, bit for bit. A Gilbert–Elliott link is taken at its stationary loss rate: the
//! center does not track the channel state (the losses' burstiness is ignored).
//!
//! - **Han et al.'s stochastic triggers** ([`stochastic_no_arrival`]): the posterior after
//!   "nothing arrived" is a two-component Gaussian mixture, computed exactly and projected on
//!   one Gaussian by moment matching (the Gaussian closest in KL(exact ‖ Gaussian)).
//! - **Wu et al.'s innovation trigger** ([`no_arrival_variance`]): the second moment of the
//!   whitened innovation given nothing arrived replaces the truncated variance v(δ) of their
//!   Theorem 2.
//! - **Send-on-delta** ([`SendOnDeltaMixture`]): the uniform reading of a silence (the sensor's
//!   reference is still the center's last received value and the reading in its band), the
//!   prior conditioned on the reading outside that band (sent and lost), and no information
//!   (the reference already went stale), mixed and moment-matched.
//!
//! With several silent sensors in one step the mixture updates are applied one sensor after
//! the other, each projected on a Gaussian before the next (assumed-density filtering), after
//! the received measurements have been fused: exact for one silence, an approximation beyond.
//! These paths allocate per silence (they are not the published hot loops).
use super::update_with_noise;
use crate::filter::{kf, Gaussian};
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::model::MeasurementModel;
use crate::scheme::SchemeError;
use crate::stats::{normal, truncated_normal};

/// The loss probabilities a center assumes, one per sensor of `sensors` (each checked to lie
/// in [0, 1), [`crate::scheme::link_loss::check`]): `None` (the published update) for an absent
/// `link_loss` and where every sensor's is 0, where the loss-aware update is the published one,
/// so that the published code runs and its numbers stay bit for bit.
pub fn effective_link_loss(
    link_loss: Option<Vec<f64>>,
    sensors: usize,
) -> Result<Option<Vec<f64>>, SchemeError> {
    let Some(ps) = link_loss else {
        return Ok(None);
    };
    if ps.len() != sensors {
        return Err(SchemeError::Invalid {
            field: "link_loss",
            message: format!(
                "expected one probability per sensor ({sensors}), got {}",
                ps.len()
            ),
        });
    }
    for &p in &ps {
        crate::scheme::link_loss::check(p)?;
    }
    Ok(Some(ps).filter(|ps| ps.iter().any(|&p| p > 0.0)))
}

/// The Gaussian closest to the mixture `(1 - w1) N(prior) + w1 N(post)` (the KL projection:
/// its mean and covariance), in place of `post`:
///
/// mean = m0 + w1 (m1 - m0), cov = w0 P0 + w1 P1 + w0 w1 d d^T, d = m1 - m0, w0 = 1 - w1.
///
/// A sum of positive semidefinite terms, so it stays a covariance whatever the weights.
pub fn moment_match(w1: f64, prior: &Gaussian, post: &mut Gaussian) {
    let w0 = 1.0 - w1;
    let d = &post.mean - &prior.mean;
    post.mean = &prior.mean + &d * w1;
    let mut cov = &prior.cov * w0 + &post.cov * w1 + (&d * d.transpose()) * (w0 * w1);
    symmetrize(&mut cov);
    post.cov = cov;
}

/// The weight `(1 - p) a / (p + (1 - p) a)` of the "silent" component given `log a`, in a form
/// that neither overflows nor divides 0 by 0 when `a` underflows: `1 / (1 + e^{ln(p/(1-p)) -
/// ln a})`.
fn silent_weight(p: f64, log_a: f64) -> f64 {
    if p == 0.0 {
        return 1.0;
    }
    let t = (p / (1.0 - p)).ln() - log_a;
    1.0 / (1.0 + t.exp())
}

/// `log det` of an SPD matrix through its Cholesky factor.
fn log_det(what: &'static str, a: &Matrix) -> Result<f64, SchemeError> {
    let chol = cholesky(a).map_err(|source| SchemeError::Matrix { what, source })?;
    Ok(2.0
        * chol
            .l_dirty()
            .diagonal()
            .iter()
            .map(|d| d.ln())
            .sum::<f64>())
}

/// `log det Y^{-1}` of a trigger matrix Y, once per sensor.
pub fn log_det_y_inv(y: &Matrix) -> Result<f64, SchemeError> {
    Ok(-log_det("trigger matrix Y", y)?)
}

/// The outcome of a mixture update: the Gaussian and the weight of the informative component.
#[derive(Debug, Clone, PartialEq)]
pub struct MixtureUpdate {
    pub estimate: Gaussian,
    /// Posterior probability of the informative component ("silent", or "in band").
    pub weight: f64,
}

/// Han et al.'s stochastic trigger, one sensor's "nothing arrived" with loss probability p > 0,
/// against the (Gaussian) running estimate `est` = N(m, P).
///
/// **Likelihood.** The trigger is silent with probability φ(u) = exp(-½ u^T Y u), u = z (open
/// loop) or z - C x̂^- (closed loop). With v ~ N(0, R) and `pseudo` = 0 (open) or C x̂^- (closed),
/// ∫ N(z; Cx, R) φ(u) dz = c N_u(Cx), c = [det Y^{-1} / det(R + Y^{-1})]^{1/2} and
/// N_u(Cx) = exp(-½ (pseudo - Cx)^T (R + Y^{-1})^{-1} (pseudo - Cx)): the Gaussian silence
/// likelihood of their Theorems 1 and 2. So P(nothing arrived | x) = p + (1 - p) c N_u(Cx).
///
/// **Posterior.** Prior times that is the mixture
/// w0 N(m, P) + w1 N(m1, P1), where N(m1, P1) is the published silence update (the KF with
/// the pseudo-measurement `pseudo` and noise R + Y^{-1}: Theorem 1's x̂_k = x̂^- - P^- C^T
/// (C P^- C^T + R + Y^{-1})^{-1} C x̂^-, Theorem 2's x̂_k = x̂^-, and P_k = P^- - P^- C^T (C P^-
/// C^T + R + Y^{-1})^{-1} C P^- in both) and the weights are exact:
///
/// w1 ∝ (1 - p) π, w0 ∝ p, π = E[φ | past] = [det Y^{-1} / det S]^{1/2} exp(-½ r^T S^{-1} r),
///
/// S = C P C^T + R + Y^{-1}, r = pseudo - C m (π is the probability that the trigger stays
/// silent given the past, the mixture's marginal likelihood factor). The result is the mixture
/// projected by [`moment_match`]. For a nonlinear sensor C is the Jacobian at m (an EKF, as
/// the published center).
pub fn stochastic_no_arrival(
    sensor: &dyn MeasurementModel,
    est: &Gaussian,
    pseudo: &Vector,
    silence_noise: &Matrix,
    log_det_y_inv: f64,
    p: f64,
) -> Result<MixtureUpdate, SchemeError> {
    let mut inn = kf::innovation(sensor, est, pseudo)?;
    inn.s += silence_noise - sensor.noise_cov();
    symmetrize(&mut inn.s);
    let chol = cholesky(&inn.s).map_err(|source| SchemeError::Matrix {
        what: "innovation covariance of a silence",
        source,
    })?;
    let log_det_s = 2.0
        * chol
            .l_dirty()
            .diagonal()
            .iter()
            .map(|d| d.ln())
            .sum::<f64>();
    let quad = inn.nu.dot(&chol.solve(&inn.nu));
    let log_pi = 0.5 * (log_det_y_inv - log_det_s) - 0.5 * quad;
    let w1 = silent_weight(p, log_pi);
    let mut estimate = update_with_noise(sensor, est.clone(), pseudo, silence_noise)?;
    moment_match(w1, est, &mut estimate);
    Ok(MixtureUpdate {
        estimate,
        weight: w1,
    })
}

/// Wu et al.'s innovation trigger: the second moment, per component, of the whitened
/// innovation ε ~ N(0, I_m) given that nothing arrived with loss probability p, the sensor
/// being silent iff ||ε||_∞ <= δ:
///
/// E[ε_j² | nothing] = (P_in v(δ) + p E[ε_j² 1{out}]) / (P_in + p P_out),
///
/// a mixture of the in-band truncated law (weight P_in = (1 - 2Q(δ))^m, variance v(δ) per
/// component, Wu et al. 2013, Theorem 2) and the out-of-band one (weight p P_out, P_out = 1 -
/// P_in). Both are symmetric under the sign flip of any component, so the mixture has mean 0
/// and a diagonal covariance, and exchangeable, so the diagonal is constant: Cov(ε | nothing)
/// = v_p I exactly (no independence between components is assumed; the out-of-band set is not
/// a product set). The out-of-band part is formed without cancellation from the two-tailed
/// truncated moment m_out = E[ε_j² | |ε_j| > δ] (one tail by symmetry, from
/// [`truncated_normal::truncated_standard`]):
///
/// E[ε_j² 1{out}] = 2Q(δ) m_out + (1 - 2Q(δ)) v(δ) (1 - (1 - 2Q(δ))^{m-1}).
///
/// At p = 0 it is v(δ); at δ = 0 (always send) it is 1 (nothing arriving is a loss and says
/// nothing); as δ grows it tends to 1.
///
/// How it plugs in: the published update of Theorem 2, P_k = P^- - β P^- C^T Z^{-1} C P^- with
/// β = 1 - v(δ), takes β_p = 1 - v_p (the pseudo-measurement noise R' = R + (1/β_p - 1) Z);
/// the mean does not move (E[ε | nothing] = 0). The approximation is Wu et al.'s: x_k given the
/// past is taken Gaussian (so ε ~ N(0, I)) and the posterior is the Gaussian with the exact
/// second moments of that conditional law, which is itself not Gaussian.
pub fn no_arrival_variance(delta: f64, m: usize, p: f64) -> f64 {
    let v_in = truncated_normal::band_variance(delta);
    if p == 0.0 {
        return v_in;
    }
    let out1 = 2.0 * normal::q(delta);
    let in1 = 1.0 - out1;
    let tail = truncated_normal::truncated_standard(delta, f64::INFINITY);
    let m_out = tail.var + tail.mean * tail.mean;
    let m = m.max(1) as i32;
    let p_in = in1.powi(m);
    // 1 - (1 - 2Q)^m without cancellation for small Q.
    let p_out = -((m as f64) * (-out1).ln_1p()).exp_m1();
    let others_out = if m == 1 {
        0.0
    } else {
        -(((m - 1) as f64) * (-out1).ln_1p()).exp_m1()
    };
    let out_second = out1 * m_out + in1 * v_in * others_out;
    ((p_in * v_in + p * out_second) / (p_in + p * p_out)).clamp(0.0, 1.0)
}

/// Send-on-delta's "nothing arrived" under a lossy link (uniform reading of silences).
///
/// **Two references.** The sensor's band is around its last *sent* value; the center's around
/// its last *received* one, z_r. After a lost send the two differ and the center cannot know
/// the sensor's (there is no acknowledgement; the sensor keeps its last sent value, as
/// published). So the center keeps, per sensor, the probability q that the sensor's reference
/// is still z_r (q = 1 when a message arrives) and reads "nothing arrived" as the mixture of
///
/// - A, "reference z_r, silent": the published uniform reading (z_r with noise R + δ²/3 I),
///   prior weight q P_in, P_in = P(||z_k - z_r||_∞ <= δ | past);
/// - L, "reference z_r, sent and lost": the prior conditioned on z_k outside the band, prior
///   weight q p (1 - P_in) (the out-of-band truncated moments, as for Wu et al.'s trigger);
/// - S, "reference already stale": no information (the prediction: the band around the
///   sensor's unknown reference cannot be placed), prior weight (1 - q) (p + (1 - p) P_in);
///
/// projected on one Gaussian by [`mix`]; after it, q = w_A (only A keeps the reference at z_r).
///
/// Approximations, beyond the uniform reading's own: the predictive law of z_k is the Gaussian
/// N(h(m), H P H^T + R) of the running estimate; P_in is the product of the per-component band
/// probabilities (the correlation between components is ignored; exact for one component);
/// the out-of-band component L is exact (given that Gaussian) for a scalar sensor and is the
/// prediction for a vector one (the complement of a box is not a product set); with a stale
/// reference the sensor is taken to stay silent with the same probability P_in (the band
/// around its unknown reference is as likely to hold z_k as the center's); the history is
/// summarized by q alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SendOnDeltaMixture {
    pub delta: f64,
    pub p: f64,
}

/// The standardized band `((ν_j - δ) / sd_j, (ν_j + δ) / sd_j)` of component j of z_k - ŷ,
/// where ν = z_r - ŷ and sd_j² = S_jj.
fn band(inn: &kf::Innovation, delta: f64, j: usize) -> (f64, f64) {
    let sd = inn.s[(j, j)].sqrt();
    ((inn.nu[j] - delta) / sd, (inn.nu[j] + delta) / sd)
}

/// The Gaussian of the moments of a weighted mixture (weights summing to 1): mean Σ w_c m_c,
/// covariance Σ w_c (P_c + (m_c - mean)(m_c - mean)^T) (the KL projection of the mixture).
pub fn mix(components: &[(f64, &Gaussian)]) -> Gaussian {
    let n = components[0].1.dim();
    let mut mean = Vector::zeros(n);
    for (w, g) in components {
        mean += &g.mean * *w;
    }
    let mut cov = Matrix::zeros(n, n);
    for (w, g) in components {
        let d = &g.mean - &mean;
        cov += (&g.cov + &d * d.transpose()) * *w;
    }
    symmetrize(&mut cov);
    Gaussian { mean, cov }
}

impl SendOnDeltaMixture {
    /// log P_in: the product over components of P(|z_j - z_r,j| <= δ) under the predictive
    /// N(h(m), H P H^T + R) of `est`, from the band masses of [`truncated_normal::log_mass`].
    pub fn log_in_band(
        &self,
        sensor: &dyn MeasurementModel,
        est: &Gaussian,
        z_r: &Vector,
    ) -> Result<f64, SchemeError> {
        Ok(self.log_in_band_of(&kf::innovation(sensor, est, z_r)?))
    }

    fn log_in_band_of(&self, inn: &kf::Innovation) -> f64 {
        (0..inn.nu.len())
            .map(|j| match band(inn, self.delta, j) {
                (a, b) if a < b => truncated_normal::log_mass(a, b),
                _ => f64::NEG_INFINITY,
            })
            .sum()
    }

    /// Component L for a scalar sensor: `est` conditioned on z_k outside the band. With t =
    /// (z_k - ŷ) / √S ~ N(0, 1) truncated to the two tails (-∞, a) ∪ (b, ∞) (means μ, variances
    /// v and masses of [`truncated_normal::truncated_standard`] per tail, mixed), x = m + K √S t
    /// plus a part independent of t, K = P H^T / S: mean m + P H^T E[t] / √S, covariance
    /// P - (1 - Var t) P H^T H P / S. `None` when the tails carry no mass.
    fn out_of_band(&self, est: &Gaussian, inn: &kf::Innovation) -> Option<Gaussian> {
        let (a, b) = band(inn, self.delta, 0);
        let left = truncated_normal::truncated_standard(f64::NEG_INFINITY, a);
        let right = truncated_normal::truncated_standard(b, f64::INFINITY);
        let (ml, mr) = (left.log_mass.exp(), right.log_mass.exp());
        let mass = ml + mr;
        if mass.is_nan() || mass <= 0.0 {
            return None;
        }
        let mean_t = (ml * left.mean + mr * right.mean) / mass;
        let second = (ml * (left.var + left.mean * left.mean)
            + mr * (right.var + right.mean * right.mean))
            / mass;
        let var_t = second - mean_t * mean_t;
        let s = inn.s[(0, 0)];
        let pht = &est.cov * inn.h.transpose();
        let mean = &est.mean + &pht * (mean_t / s.sqrt());
        let mut cov = &est.cov - (&pht * pht.transpose()) * ((1.0 - var_t) / s);
        symmetrize(&mut cov);
        Some(Gaussian { mean, cov })
    }

    /// The update of `est` for a sensor whose reference is z_r with probability `q`; `uniform`
    /// is the published uniform noise R + δ²/3 I. Returns the estimate and the new q (w_A).
    pub fn update(
        &self,
        sensor: &dyn MeasurementModel,
        est: &Gaussian,
        z_r: &Vector,
        uniform: &Matrix,
        q: f64,
    ) -> Result<MixtureUpdate, SchemeError> {
        let inn = kf::innovation(sensor, est, z_r)?;
        let p_in = self.log_in_band_of(&inn).exp();
        let p = self.p;
        let scalar_lost = if inn.nu.len() == 1 {
            self.out_of_band(est, &inn)
        } else {
            None
        };
        let lost = scalar_lost.as_ref().unwrap_or(est);
        let mut w = [
            q * p_in,
            q * p * (1.0 - p_in),
            (1.0 - q) * (p + (1.0 - p) * p_in),
        ];
        // The sum is >= q p (1 - P_in) + (1 - q) p > 0 unless q = 1 and P_in = 1 (then w_A > 0).
        let total: f64 = w.iter().sum();
        if total.is_nan() || total <= 0.0 {
            return Ok(MixtureUpdate {
                estimate: est.clone(),
                weight: 0.0,
            });
        }
        w.iter_mut().for_each(|x| *x /= total);
        let a = update_with_noise(sensor, est.clone(), z_r, uniform)?;
        Ok(MixtureUpdate {
            estimate: mix(&[(w[0], &a), (w[1], lost), (w[2], est)]),
            weight: w[0],
        })
    }
}

#[cfg(test)]
mod tests;
