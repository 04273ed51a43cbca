//! The fusion center's treatment of a sensor whose estimate is missing two steps or more in a
//! row (beyond Dormann et al., who assume every sent estimate arrives).
//!
//! # What the center knows, and what the sensor believes
//!
//! Algorithm 1 (eq. (10)-(11)) is exact for a sensor i silent at k that sent at k - 1: the
//! center then holds x̄^{p,i}_k = A x̄^{e,i}_{k-1}, which is all (11) needs. The protocol makes
//! a sensor silent at k - 1 send at k, so under Algorithm 1 (and at full rate) an estimate
//! missing twice in a row can only be a loss of the link. Algorithm 2 allows long silences, and
//! the center cannot tell them from losses.
//!
//! The sensor has no acknowledgement (no ARQ on the link): it assumes every estimate it sent
//! arrived. Its replica of the center, and hence test (12)'s "silent at k - 1 must send" rule
//! and test (13)'s bound d̃ d̃^T ≤ B, refer to its last *sent* estimate. After a loss the center
//! holds an older one, so the sensor's belief is wrong and B no longer bounds the difference
//! the center is left with. The sensor is unchanged: it cannot know, and nothing here assumes
//! it does.
//!
//! # The fallback
//!
//! Say sensor i's last estimate to arrive was sent at s, and it is missing at k = s + j,
//! j >= 2. The center keeps Algorithm 2's term for it, the debiased extrapolation (Section IV)
//!
//!   x̃^{pp,i}_k = Δ^{p,i}_k (Δ^{pp,i}_k)^{-1} A^j x̄^{e,i}_s = Δ^{p,i}_k A^j (Δ^{e,i}_s)^{-1} x̄^{e,i}_s,
//!
//! in place of the unknown x̄^{p,i}_k in (11), and (10)'s information matrix. As in the proof
//! of Algorithm 2's consistency, the fused error is the exact one minus
//! C (C̄^p_k)^{-1} Σ_i d̃^i_k with d̃^i_k = x̃^{pp,i}_k - x̄^{p,i}_k, and the two are orthogonal
//! (d̃ is a function of the data the exact estimate conditions on). So
//!
//!   E[e e^T] = C + C (C̄^p)^{-1} E[D D^T] (C̄^p)^{-1} C,  D = Σ_{i lost} d̃^i,
//!   E[D D^T] ≤ L Σ_i E[d̃^i (d̃^i)^T]   (L sensors in the sum; as Algorithm 2's (N - m - l)^2 B),
//!
//! where Algorithm 2 bounds E[d̃ d̃^T] by B through its test. Here no test bounds it, but its
//! second moment S^i = E[d̃^i (d̃^i)^T] is data-independent and the center computes it:
//! with ε^i_t = x̄^{e,i}_t - Δ^{e,i}_t x_t (zero mean: Δ^{e,i} is exactly the bias of the
//! globalized estimate),
//!
//!   ε_t = W_t A ε_{t-1} + G_t v_t - W_t Δ^p_t w_{t-1},   ε_0 = x̄_0 - x_0 ~ N(0, P_0),
//!
//! with W_t = C̄^e_t (C̄^p_t)^{-1} and G_t = C̄^e_t H_i^T R_i^{-1} (the local filtering step of
//! Section II), Δ^p_t = A Δ^e_{t-1} A^{-1} (14). With g_t = A^{t-s} (Δ^e_s)^{-1} x̄^e_s - x_t
//! (the debiased held estimate's error, g_s = (Δ^e_s)^{-1} ε_s, g_t = A g_{t-1} - w_{t-1}),
//!
//!   d̃_k = Δ^p_k A g_{k-1} - A ε_{k-1},
//!
//! so S is [Δ^p_k A, -A] P_{k-1} [Δ^p_k A, -A]^T for the covariance P of (g, ε), propagated
//! from P_s = [[D Σ_s D^T, D Σ_s], [Σ_s D^T, Σ_s]] (D = (Δ^e_s)^{-1}, Σ_s = Cov ε_s) along
//! the streak. The center's covariance becomes
//!
//!   C + L C (C̄^p)^{-1} (Σ_i S^i) (C̄^p)^{-1} C.
//!
//! For one missing sensor this is the error covariance itself when the missing pattern does
//! not depend on the data (random omission, Bernoulli losses); with event-based omissions the
//! pattern is data-dependent and the figure is the unconditional one. With one sensor it is
//! the pure prediction: a single sensor lost at 1 and 2 leaves the center with A^2 x̄_0 and
//! A^2 P_0 A^{2T} + A Q A^T + Q (the unit tests check this by hand).
//!
//! Under Algorithm 2 a streak may be a pure omission (d̃ d̃^T ≤ B by the sensor's test) or
//! contain a loss (then about S); the loss-aware center (`loss_aware`) cannot tell, and uses
//! B + S^i, which dominates both. Its published center keeps B alone.
//!
//! A singular A has no debiasing (14): the center then uses the plain extrapolation
//! A^j x̄^{e,i}_s, uninflated, and its covariance may be optimistic after a loss.
use super::plan::{EpsilonTable, GlobalizedPlan};
use crate::linalg::{symmetrize, Matrix, Vector};
use crate::scheme::SchemeError;

impl EpsilonTable {
    /// Cov ε^i_t.
    pub fn at(&self, plan: &GlobalizedPlan, i: usize, t: usize) -> Result<Matrix, SchemeError> {
        let mut all = self.per_sensor.lock().unwrap_or_else(|e| e.into_inner());
        let me = &mut all[i];
        if me.covs.is_empty() {
            me.covs.push(self.p0.clone());
        }
        while me.covs.len() <= t && !me.converged {
            let u = me.covs.len();
            let prev = me.covs.last().expect("non-empty");
            let next = self.step(plan, i, u, prev)?;
            me.converged = u > 2 && crate::linalg::relative_difference(&next, prev) < 1e-14;
            me.covs.push(next);
        }
        Ok(me.covs[t.min(me.covs.len() - 1)].clone())
    }

    /// Σ_t = (W_t A) Σ_{t-1} (W_t A)^T + G_t R_i G_t^T + (W_t Δ^p_t) Q (W_t Δ^p_t)^T.
    fn step(
        &self,
        plan: &GlobalizedPlan,
        i: usize,
        t: usize,
        prev: &Matrix,
    ) -> Result<Matrix, SchemeError> {
        let m = plan.at(t)?;
        let wa = &m.prediction_weight * plan.a();
        let g = &m.measurement_weight[i];
        let mw = &m.prediction_weight * delta_p(m, i)?;
        let mut out = &wa * prev * wa.transpose()
            + g * &self.r[i] * g.transpose()
            + &mw * &self.q * mw.transpose();
        symmetrize(&mut out);
        Ok(out)
    }

    /// Q.
    pub fn q(&self) -> &Matrix {
        &self.q
    }

    /// R_i.
    pub fn r(&self, i: usize) -> &Matrix {
        &self.r[i]
    }
}

fn delta_p(m: &super::plan::StepMatrices, i: usize) -> Result<&Matrix, SchemeError> {
    m.delta_p.get(i).ok_or_else(|| {
        SchemeError::Unsupported("the loss-aware fallback debiases with A^{-1}".into())
    })
}

/// One sensor's run of missing estimates, from its last estimate to arrive (step `s`) on: the
/// debiased held estimate A^{t-s} (Δ^{e,i}_s)^{-1} x̄^{e,i}_s and the covariance of (g_t, ε_t)
/// at step `t` (see the module's text).
#[derive(Debug, Clone)]
pub(super) struct Streak {
    t: usize,
    held: Vector,
    cov: Matrix,
}

impl Streak {
    /// The streak of sensor i whose estimate `received` (x̄^{e,i}_s) arrived at step s.
    pub fn start(
        plan: &GlobalizedPlan,
        table: &EpsilonTable,
        i: usize,
        s: usize,
        received: &Vector,
    ) -> Result<Self, SchemeError> {
        let n = received.len();
        let m = plan.at(s)?;
        let delta_e = m.delta_e.get(i).ok_or_else(|| {
            SchemeError::Unsupported("the loss-aware fallback debiases with A^{-1}".into())
        })?;
        let d = delta_e
            .clone()
            .try_inverse()
            .ok_or_else(|| SchemeError::Unsupported("debiasing matrix Δ^e is singular".into()))?;
        let sigma = table.at(plan, i, s)?;
        let d_sigma = &d * &sigma;
        let mut cov = Matrix::zeros(2 * n, 2 * n);
        cov.view_mut((0, 0), (n, n))
            .copy_from(&(&d_sigma * d.transpose()));
        cov.view_mut((0, n), (n, n)).copy_from(&d_sigma);
        cov.view_mut((n, 0), (n, n)).copy_from(&d_sigma.transpose());
        cov.view_mut((n, n), (n, n)).copy_from(&sigma);
        symmetrize(&mut cov);
        Ok(Self {
            t: s,
            held: &d * received,
            cov,
        })
    }

    /// The step the streak stands at.
    pub fn t(&self) -> usize {
        self.t
    }

    /// One step on: t -> t + 1. The held estimate is predicted; (g, ε) by
    /// F = [[A, 0], [0, W A]] and the noise (-w, G v - W Δ^p w), whose covariance is
    /// [[Q, Q M^T], [M Q, G R G^T + M Q M^T]] with M = W Δ^p.
    pub fn advance(
        &mut self,
        plan: &GlobalizedPlan,
        table: &EpsilonTable,
        i: usize,
    ) -> Result<(), SchemeError> {
        let t = self.t + 1;
        let n = self.held.len();
        let m = plan.at(t)?;
        let a = plan.a();
        self.held = a * &self.held;
        let wa = &m.prediction_weight * a;
        let mw = &m.prediction_weight * delta_p(m, i)?;
        let g = &m.measurement_weight[i];
        let q = table.q();
        let mut f = Matrix::zeros(2 * n, 2 * n);
        f.view_mut((0, 0), (n, n)).copy_from(a);
        f.view_mut((n, n), (n, n)).copy_from(&wa);
        let mq = &mw * q;
        let mut noise = Matrix::zeros(2 * n, 2 * n);
        noise.view_mut((0, 0), (n, n)).copy_from(q);
        noise.view_mut((0, n), (n, n)).copy_from(&mq.transpose());
        noise.view_mut((n, 0), (n, n)).copy_from(&mq);
        noise
            .view_mut((n, n), (n, n))
            .copy_from(&(g * table.r(i) * g.transpose() + &mq * mw.transpose()));
        self.cov = &f * &self.cov * f.transpose() + noise;
        symmetrize(&mut self.cov);
        self.t = t;
        Ok(())
    }

    /// At step k = t + 1: the debiased extrapolation x̃^{pp,i}_k = Δ^{p,i}_k A held and the
    /// second moment S = E[d̃ d̃^T] = Φ P Φ^T, Φ = [Δ^{p,i}_k A, -A].
    pub fn term_and_moment(
        &self,
        plan: &GlobalizedPlan,
        i: usize,
    ) -> Result<(Vector, Matrix), SchemeError> {
        let k = self.t + 1;
        let n = self.held.len();
        let m = plan.at(k)?;
        let a = plan.a();
        let dpa = delta_p(m, i)? * a;
        let term = &dpa * &self.held;
        let mut phi = Matrix::zeros(n, 2 * n);
        phi.view_mut((0, 0), (n, n)).copy_from(&dpa);
        phi.view_mut((0, n), (n, n)).copy_from(&(-a));
        let mut s = &phi * &self.cov * phi.transpose();
        symmetrize(&mut s);
        Ok((term, s))
    }
}

/// `base + l G S G^T` with G = `base` (C̄^p)^{-1}, symmetrized: the covariance of the loss
/// fallback for `l` sensors whose summed second moments (plus B under Algorithm 2) are `s`.
pub(super) fn inflate(base: &Matrix, cbar_p_inv: &Matrix, s: &Matrix, l: usize) -> Matrix {
    let g = base * cbar_p_inv;
    let mut out = base + (&g * s * g.transpose()) * (l as f64);
    symmetrize(&mut out);
    out
}
