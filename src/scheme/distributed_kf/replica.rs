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
use super::plan::{GlobalizedPlan, PredictedDelta};
use super::sensor::debiased_extrapolation_into;
use super::signals::Signals;
use crate::linalg::fixed;
use crate::linalg::{Matrix, Vector};
use crate::scheme::SchemeError;
use std::sync::Arc;

/// No entry yet.
const NONE: u32 = u32::MAX;

/// Offsets of an entry's values in its record of `4 n + 1` numbers.
const HELD: usize = 0;
/// x̂^{pp,i}_k at `n`, d̃ at `2 n`, (C̄^p_k)^{-1} x̃^{pp,i}_k at `3 n`, the gap at `4 n`.
const KF_HELD: usize = 1;
const DTILDE: usize = 2;
const INFO: usize = 3;
const GAP: usize = 4;

/// The entries of one trial, in the order they were made. Entry e's record, at
/// `e * (4 n + 1)` in `records`, holds x̄^{pp,i}_k, x̂^{pp,i}_k, d̃ = x̃^{pp,i}_k - x̄^{p,i}_k,
/// (C̄^p_k)^{-1} x̃^{pp,i}_k (the center's term (11) of a sensor silent since s < k - 1; zeros
/// for s = k - 1, whose term is exact and in [`Signals`]) and ||x̂^{pp,i}_k - x̂^{e,i}_k||.
pub(super) struct Replicas {
    n: usize,
    sensors: usize,
    /// Entry (i, s, s + 1) at `s * sensors + i`.
    first: Vec<u32>,
    /// Per entry (i, s, k): entry (i, s, k + 1).
    next: Vec<u32>,
    records: Vec<f64>,
    /// Per entry: Δ^{pp,i}_k, a link of the plan's shared chain.
    delta: Vec<Arc<PredictedDelta>>,
    /// The bounds B^{-1} of the variants so far (bitwise distinct), and per bound and entry
    /// the outcome of d̃^T B^{-1} d̃ > 1: 0 not yet evaluated, 1 false, 2 true. It depends
    /// on the entry and B only, and the alphas of a sweep share each B.
    bounds: Vec<Matrix>,
    quadratic: Vec<Vec<u8>>,
    /// Scratch: the LU solve, x̃^{pp}, a product.
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
            records: Vec::new(),
            delta: Vec::new(),
            bounds: Vec::new(),
            quadratic: Vec::new(),
            work: Vector::zeros(n),
            debiased: Vector::zeros(n),
            tmp: Vector::zeros(n),
        }
    }

    fn stride(&self) -> usize {
        4 * self.n + 1
    }

    /// Value `part` (HELD, KF_HELD, DTILDE, INFO) of entry `e`.
    fn part(&self, e: u32, part: usize) -> &[f64] {
        let o = e as usize * self.stride() + part * self.n;
        &self.records[o..o + self.n]
    }

    /// Entry (i, s, s + 1): sensor i sent at step s (0: the common prior, which every node
    /// starts from).
    #[inline]
    pub fn after_send(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        i: usize,
        s: usize,
    ) -> Result<u32, SchemeError> {
        match self.first[s * self.sensors + i] {
            NONE => self.make_after_send(plan, signals, i, s),
            e => Ok(e),
        }
    }

    /// Makes entry (i, s, s + 1): the center then holds the prediction of the estimate as it
    /// arrived ([`Signals::held_p`], which the sensor's replica holds too), the sensor's own
    /// KF prediction, and Δ^{e,i}_s predicted once.
    #[inline(never)]
    fn make_after_send(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        i: usize,
        s: usize,
    ) -> Result<u32, SchemeError> {
        let k = s + 1;
        let (o, n) = self.open_record();
        self.records[o..o + n].copy_from_slice(signals.held_p(k, i));
        self.records[o + n..o + 2 * n].copy_from_slice(signals.kf_p(k, i));
        let head = plan
            .delta_head(i, plan.index(s)?)
            .expect("A is invertible for Algorithm 2");
        let e = self.close_record(plan, signals, i, k, false, head.next(plan))?;
        self.first[s * self.sensors + i] = e;
        Ok(e)
    }

    /// Entry (i, s, k) from entry `e` = (i, s, k - 1): sensor i silent at k - 1 too.
    #[inline]
    pub fn advance(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        e: u32,
        i: usize,
        k: usize,
    ) -> Result<u32, SchemeError> {
        match self.next[e as usize] {
            NONE => self.make_advance(plan, signals, e, i, k),
            next => Ok(next),
        }
    }

    /// Makes entry (i, s, k) from `e`: the replica predicts both held estimates (x <- A x)
    /// and steps Δ^{pp} along its chain.
    #[inline(never)]
    fn make_advance(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        e: u32,
        i: usize,
        k: usize,
    ) -> Result<u32, SchemeError> {
        let (o, n) = self.open_record();
        let from = e as usize * self.stride();
        let (old, new) = self.records.split_at_mut(o);
        fixed::gemv_square(&mut new[..n], plan.a(), &old[from..from + n]);
        fixed::gemv_square(&mut new[n..2 * n], plan.a(), &old[from + n..from + 2 * n]);
        let delta = self.delta[e as usize].next(plan);
        let next = self.close_record(plan, signals, i, k, true, delta)?;
        self.next[e as usize] = next;
        Ok(next)
    }

    /// Appends a record (zeros) for the held estimates to be written into: its offset and n.
    fn open_record(&mut self) -> (usize, usize) {
        let o = self.records.len();
        self.records.resize(o + self.stride(), 0.0);
        (o, self.n)
    }

    /// Completes the last record, of sensor i at step k with Δ^{pp} = `delta`, and makes it an
    /// entry; on a failed debiasing the record is dropped. `inexact`: silent since before
    /// k - 1, so the center needs (C̄^p_k)^{-1} x̃^{pp}.
    fn close_record(
        &mut self,
        plan: &GlobalizedPlan,
        signals: &Signals,
        i: usize,
        k: usize,
        inexact: bool,
        delta: Arc<PredictedDelta>,
    ) -> Result<u32, SchemeError> {
        let (n, o) = (self.n, self.records.len() - self.stride());
        let m = plan.at(k)?;
        let record = &mut self.records[o..];
        let debiased = debiased_extrapolation_into(
            &m.delta_p[i],
            &delta,
            &record[HELD * n..(HELD + 1) * n],
            &mut self.work,
            &mut self.debiased,
        );
        if let Err(e) = debiased {
            self.records.truncate(o);
            return Err(e);
        }
        // d̃ = x̃^{pp} - x̄^p.
        let dtilde = &mut record[DTILDE * n..(DTILDE + 1) * n];
        dtilde.copy_from_slice(self.debiased.as_slice());
        fixed::sub_assign(dtilde, signals.xbar_p(k, i));
        // x̂^{pp} - x̂^e, in `tmp`.
        self.tmp
            .copy_from_slice(&record[KF_HELD * n..(KF_HELD + 1) * n]);
        fixed::sub_assign(self.tmp.as_mut_slice(), signals.kf(k, i));
        record[GAP * n] = fixed::norm(self.tmp.as_slice());
        if inexact {
            fixed::gemv(&mut self.tmp, &m.cbar_p_inv, &self.debiased);
            record[INFO * n..(INFO + 1) * n].copy_from_slice(self.tmp.as_slice());
        }
        let e = u32::try_from(self.next.len()).expect("fewer than 2^32 entries");
        self.next.push(NONE);
        self.delta.push(delta);
        Ok(e)
    }

    /// The index of the bound B^{-1} for [`Replicas::test_13`], registered if new.
    pub fn bound(&mut self, b_inv: &Matrix) -> usize {
        let same = |m: &Matrix| {
            m.shape() == b_inv.shape()
                && m.iter()
                    .zip(b_inv.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits())
        };
        self.bounds.iter().position(same).unwrap_or_else(|| {
            self.bounds.push(b_inv.clone());
            self.quadratic.push(Vec::new());
            self.bounds.len() - 1
        })
    }

    /// Test (13) of entry `e`: ||x̂^{pp} - x̂^e|| > alpha, or else d̃^T B^{-1} d̃ > 1 for the
    /// bound `bound`, as the sensor evaluates it.
    #[inline]
    pub fn test_13(&mut self, e: u32, alpha: f64, bound: usize, tmp: &mut [f64]) -> bool {
        let eu = e as usize;
        if self.records[eu * self.stride() + GAP * self.n] > alpha {
            return true;
        }
        match self.quadratic[bound].get(eu) {
            Some(1) => false,
            Some(2) => true,
            _ => self.evaluate_quadratic(e, bound, tmp),
        }
    }

    /// d̃^T B^{-1} d̃ > 1 for entry `e` (the product into `tmp`), remembered.
    #[inline(never)]
    fn evaluate_quadratic(&mut self, e: u32, bound: usize, tmp: &mut [f64]) -> bool {
        let d = self.part(e, DTILDE);
        fixed::gemv_square(tmp, &self.bounds[bound], d);
        let outside = fixed::dot(d, tmp) > 1.0;
        let q = &mut self.quadratic[bound];
        if q.len() <= e as usize {
            q.resize(self.next.len(), 0);
        }
        q[e as usize] = 1 + u8::from(outside);
        outside
    }

    /// The center's term (11) of a sensor silent at entry `e` since before k - 1.
    pub fn info(&self, e: u32) -> &[f64] {
        self.part(e, INFO)
    }
}
