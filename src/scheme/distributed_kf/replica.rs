//! Algorithm 2's replicas of the center, shared by the variants of one trial.
//!
//! What sensor i and the center hold about it at step k when its last transmission was at
//! step s — x̄^{pp,i}_k = A^{k-s} x̄^{e,i}_s, x̂^{pp,i}_k = A^{k-s} x̂^{e,i}_s and Δ^{pp,i}_k
//! (Δ^{e,i}_s predicted k - s times, Section IV) — depends on the trial's data and on
//! (i, s, k) only: a variant's trigger only decides at which s it is. So does everything test
//! (13) and the center's term of a silent sensor derive from them: the debiased extrapolation
//! x̃^{pp,i}_k = Δ^{p,i}_k (Δ^{pp,i}_k)^{-1} x̄^{pp,i}_k, d̃ = x̃^{pp} - x̄^p_k,
//! ||x̂^{pp} - x̂^e_k|| and (C̄^p_k)^{-1} x̃^{pp}. The 48 alpha x B variants of `dormann-fig1`
//! are mostly at the same few s, so each (i, s, k) is computed once per trial here ("an
//! entry"), by the operations the per-variant replica performed — each prediction `x <- A x`
//! from the step before, as the sensor steps it, and every other value from the same operands
//! in the same order — so the numbers are the same bit for bit.
use super::fast::Signals;
use super::plan::{GlobalizedPlan, PredictedDelta};
use super::sensor::debiased_extrapolation_into;
use crate::filter::fixed;
use crate::linalg::{Matrix, Vector};
use crate::scheme::SchemeError;
use std::sync::Arc;

/// No entry yet.
const NONE: u32 = u32::MAX;

/// The entries of one trial, each `n` long in the flat buffers, in the order they were made.
pub(super) struct Replicas {
    n: usize,
    sensors: usize,
    /// Entry (i, s, s + 1) at `s * sensors + i`.
    first: Vec<u32>,
    /// Per entry (i, s, k): entry (i, s, k + 1).
    next: Vec<u32>,
    /// x̄^{pp,i}_k.
    held: Vec<f64>,
    /// x̂^{pp,i}_k.
    kf_held: Vec<f64>,
    /// Δ^{pp,i}_k, a link of the plan's shared chain.
    delta: Vec<Arc<PredictedDelta>>,
    /// ||x̂^{pp,i}_k - x̂^{e,i}_k||: test (13)'s first part.
    kf_gap: Vec<f64>,
    /// d̃ = x̃^{pp,i}_k - x̄^{p,i}_k: test (13)'s second part.
    dtilde: Vec<f64>,
    /// (C̄^p_k)^{-1} x̃^{pp,i}_k, the center's term (11) of a sensor silent since s < k - 1
    /// (zeros for s = k - 1, whose term is exact and in [`Signals`]).
    info: Vec<f64>,
    /// Scratch: the next entry's x̄^{pp} and x̂^{pp}, the LU solve, x̃^{pp}, a product.
    held_new: Vector,
    kf_held_new: Vector,
    work: Vector,
    debiased: Vector,
    tmp: Vector,
}

impl Replicas {
    pub fn new(n: usize, sensors: usize, steps: usize) -> Self {
        Self {
            n,
            sensors,
            first: vec![NONE; steps * sensors],
            next: Vec::new(),
            held: Vec::new(),
            kf_held: Vec::new(),
            delta: Vec::new(),
            kf_gap: Vec::new(),
            dtilde: Vec::new(),
            info: Vec::new(),
            held_new: Vector::zeros(n),
            kf_held_new: Vector::zeros(n),
            work: Vector::zeros(n),
            debiased: Vector::zeros(n),
            tmp: Vector::zeros(n),
        }
    }

    fn slice(v: &[f64], n: usize, e: u32) -> &[f64] {
        let o = e as usize * n;
        &v[o..o + n]
    }

    /// Entry (i, s, s + 1): sensor i sent at step s (0: the common prior, which every node
    /// starts from). The center then holds the sensor's own predictions (the same gemv of
    /// the same estimate), and Δ^{e,i}_s predicted once.
    pub fn after_send(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        i: usize,
        s: usize,
    ) -> Result<u32, SchemeError> {
        let slot = s * self.sensors + i;
        if self.first[slot] != NONE {
            return Ok(self.first[slot]);
        }
        let k = s + 1;
        self.held_new.copy_from_slice(signals.xbar_p(k, i));
        self.kf_held_new.copy_from_slice(signals.kf_p(k, i));
        let head = plan
            .delta_head(i, plan.index(s)?)
            .expect("A is invertible for Algorithm 2");
        let e = self.push(plan, signals, i, k, false, head.next(plan))?;
        self.first[slot] = e;
        Ok(e)
    }

    /// Entry (i, s, k) from entry `e` = (i, s, k - 1): sensor i silent at k - 1 too. Its
    /// replica predicts both held estimates and steps Δ^{pp} along its chain.
    pub fn advance(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        e: u32,
        i: usize,
        k: usize,
    ) -> Result<u32, SchemeError> {
        if self.next[e as usize] != NONE {
            return Ok(self.next[e as usize]);
        }
        let n = self.n;
        let a = plan.a();
        fixed::gemv_square(
            self.held_new.as_mut_slice(),
            a,
            Self::slice(&self.held, n, e),
        );
        fixed::gemv_square(
            self.kf_held_new.as_mut_slice(),
            a,
            Self::slice(&self.kf_held, n, e),
        );
        let delta = self.delta[e as usize].next(plan);
        let next = self.push(plan, signals, i, k, true, delta)?;
        self.next[e as usize] = next;
        Ok(next)
    }

    /// Completes and appends the entry of sensor i at step k whose held estimates are in
    /// `held_new` and `kf_held_new` (nothing is appended when the debiasing fails). `inexact`:
    /// silent since before k - 1, so the center needs (C̄^p_k)^{-1} x̃^{pp}.
    fn push(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        i: usize,
        k: usize,
        inexact: bool,
        delta: Arc<PredictedDelta>,
    ) -> Result<u32, SchemeError> {
        let m = plan.at(k)?;
        debiased_extrapolation_into(
            &m.delta_p[i],
            &delta,
            self.held_new.as_slice(),
            &mut self.work,
            &mut self.debiased,
        )?;
        let e = u32::try_from(self.next.len()).expect("fewer than 2^32 entries");
        self.next.push(NONE);
        self.held.extend_from_slice(self.held_new.as_slice());
        self.kf_held.extend_from_slice(self.kf_held_new.as_slice());
        self.delta.push(delta);
        // d̃ = x̃^{pp} - x̄^p.
        let o = self.dtilde.len();
        self.dtilde.extend_from_slice(self.debiased.as_slice());
        fixed::sub_assign(&mut self.dtilde[o..], signals.xbar_p(k, i));
        // x̂^{pp} - x̂^e, in `tmp`.
        self.tmp.copy_from(&self.kf_held_new);
        fixed::sub_assign(self.tmp.as_mut_slice(), signals.kf(k, i));
        self.kf_gap.push(fixed::norm(self.tmp.as_slice()));
        if inexact {
            fixed::gemv(&mut self.tmp, &m.cbar_p_inv, &self.debiased);
            self.info.extend_from_slice(self.tmp.as_slice());
        } else {
            self.info.resize(self.info.len() + self.n, 0.0);
        }
        Ok(e)
    }

    /// Test (13) of entry `e`: ||x̂^{pp} - x̂^e|| > alpha, or d̃^T B^{-1} d̃ > 1 (the product
    /// into `tmp`), in the sensor's order (the second part only when the first fails).
    pub fn test_13(&self, e: u32, alpha: f64, b_inv: &Matrix, tmp: &mut [f64]) -> bool {
        self.kf_gap[e as usize] > alpha || {
            let d = Self::slice(&self.dtilde, self.n, e);
            fixed::gemv_square(tmp, b_inv, d);
            fixed::dot(d, tmp) > 1.0
        }
    }

    /// The center's term (11) of a sensor silent at entry `e` since before k - 1.
    pub fn info(&self, e: u32) -> &[f64] {
        Self::slice(&self.info, self.n, e)
    }
}
