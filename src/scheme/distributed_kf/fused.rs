//! The fast trial's memo of (10)'s fused covariance: dense tables indexed by plan step and
//! silence set, instead of the generic center's hash map keyed by (step, set, inexact count).
//!
//! Algorithm 2's fused covariance is sym(C + l^2 C (C̄^p)^{-1} B (C̄^p)^{-1} C^T), with C the
//! inverse of (10)'s information matrix before its symmetrization and l the number of silent
//! sensors extrapolated inexactly (Algorithm 1's is sym(C)). C, its Cholesky factor and sym(C)
//! depend on the plan step and the silence set only — not on the rule, B or l — and the
//! inflation C (C̄^p)^{-1} B (C̄^p)^{-1} C^T on B too, but not on l. Keeping those two and
//! applying l at each step (n^2 products and sums) keeps every key of a sweep, a few MB for
//! `dormann-fig1`, where the generic memo's entries, one per (step, set, l, B), would be
//! hundreds of MB (its budget keeps a fraction and recomputes the rest). Every entry is
//! computed by the stages [`DkfCenter::compute_fused_covariance`] composes, on the same
//! operands, so the numbers are its numbers bit for bit.
use super::center::{
    canonical_silence, inflate_into, unit_inflation, unsymmetrized_inverse, DkfCenter,
};
use super::plan::GlobalizedPlan;
use super::Fusion;
use crate::linalg::{symmetrize, Matrix};
use crate::scheme::SchemeError;
use nalgebra::{Cholesky, Dyn};
use std::sync::{Arc, OnceLock};

/// Silence sets are indexed densely up to this many sensors (2^8 sets per step).
const MAX_DENSE_SENSORS: usize = 8;

/// The rule-independent part of one (step, silence set).
#[derive(Debug)]
pub(super) struct FusedBase {
    /// Cholesky factor of (10)'s information matrix.
    pub chol: Cholesky<f64, Dyn>,
    /// Its inverse C before symmetrization (what Algorithm 2 inflates).
    raw: Matrix,
    /// sym(C): the fused covariance when no sensor is extrapolated inexactly.
    pub cov: Matrix,
    /// `fixed::nees_factor(&cov)`: the factor the recorder's NEES would compute from these
    /// very bits, computed once for every trial that has this covariance.
    nees: Option<Vec<f64>>,
}

/// Per plan: the [`FusedBase`] of each (plan step, canonical silence set), filled on demand and
/// shared by every rule, trial and variant of the plan.
#[derive(Debug)]
pub(super) struct BaseTable {
    sets: usize,
    /// [`canonical_silence`] of every set (the centers' classes are those of the plan's
    /// sensors, the same for every center of the plan).
    canonical: OnceLock<Vec<u64>>,
    slots: Vec<OnceLock<Box<FusedBase>>>,
}

/// One fusion rule's dense memo: the plan's bases, and for Algorithm 2 the inflation of each
/// (plan step, canonical set) under its B.
#[derive(Debug)]
pub(super) struct DenseMemo {
    bases: Arc<BaseTable>,
    inflations: Vec<OnceLock<Box<Matrix>>>,
}

/// A slot's value, computed by `make` when empty. A failure is not kept (the next caller fails
/// the same way); two threads filling one slot compute the same value, and one is kept.
fn get_or_try<T>(
    slot: &OnceLock<Box<T>>,
    make: impl FnOnce() -> Result<T, SchemeError>,
) -> Result<&T, SchemeError> {
    if let Some(v) = slot.get() {
        return Ok(v);
    }
    let v = make()?;
    Ok(slot.get_or_init(|| Box::new(v)))
}

impl DenseMemo {
    /// The tables for `plan` under `fusion`, with `bases` from another rule's memo of the same
    /// plan if there is one; `None` when there are too many sensors to index sets densely.
    pub fn new(
        plan: &GlobalizedPlan,
        fusion: &Fusion,
        bases: Option<Arc<BaseTable>>,
    ) -> Option<Self> {
        let ns = plan.n_sensors();
        if ns > MAX_DENSE_SENSORS {
            return None;
        }
        let len = plan.step_count() << ns;
        let bases = bases.unwrap_or_else(|| {
            Arc::new(BaseTable {
                sets: 1 << ns,
                canonical: OnceLock::new(),
                slots: (0..len).map(|_| OnceLock::new()).collect(),
            })
        });
        let inflations = match fusion {
            Fusion::Bounded { .. } => (0..len).map(|_| OnceLock::new()).collect(),
            Fusion::OmittedEstimates => Vec::new(),
        };
        Some(Self { bases, inflations })
    }

    pub fn bases(&self) -> &Arc<BaseTable> {
        &self.bases
    }

    /// The canonical form of the silence set `silent` (see [`canonical_silence`]).
    pub fn canonical(&self, center: &DkfCenter, silent: u64) -> u64 {
        let table = self.bases.canonical.get_or_init(|| {
            (0..self.bases.sets as u64)
                .map(|s| canonical_silence(&center.class, s))
                .collect()
        });
        table[silent as usize]
    }

    /// The base of plan step `p` and the canonical silence set `set`.
    #[inline]
    pub fn base(&self, center: &DkfCenter, p: usize, set: u64) -> Result<&FusedBase, SchemeError> {
        let slot = &self.bases.slots[p * self.bases.sets + set as usize];
        match slot.get() {
            Some(base) => Ok(base),
            None => Self::make_base(slot, center, p, set),
        }
    }

    #[inline(never)]
    fn make_base<'a>(
        slot: &'a OnceLock<Box<FusedBase>>,
        center: &DkfCenter,
        p: usize,
        set: u64,
    ) -> Result<&'a FusedBase, SchemeError> {
        get_or_try(slot, || {
            let chol = center.fused_information_cholesky(p, |i| set >> i & 1 == 1)?;
            let raw = unsymmetrized_inverse(&chol);
            let mut cov = raw.clone();
            symmetrize(&mut cov);
            let nees = crate::linalg::fixed::nees_factor(&cov);
            Ok(FusedBase {
                chol,
                raw,
                cov,
                nees,
            })
        })
    }

    /// The fused covariance of plan step `p`, canonical set `set` (whose base is `base`) and
    /// `inexact` inexactly extrapolated sensors, into `out`: sym(C) as kept, or Algorithm 2's
    /// inflation of C by `inexact`^2 times the kept unit inflation. Returns
    /// `fixed::nees_factor(out)` when it is kept (`out` is then a kept covariance's copy).
    #[inline]
    pub fn covariance_into<'a>(
        &'a self,
        center: &DkfCenter,
        p: usize,
        set: u64,
        base: &'a FusedBase,
        inexact: usize,
        out: &mut Matrix,
    ) -> Result<Option<&'a [f64]>, SchemeError> {
        match center.fusion() {
            Fusion::Bounded { b } if inexact > 0 => {
                self.inflated_into(center, p, set, base, b, inexact, out)?;
                Ok(None)
            }
            _ => {
                out.as_mut_slice().copy_from_slice(base.cov.as_slice());
                Ok(base.nees.as_deref())
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn inflated_into(
        &self,
        center: &DkfCenter,
        p: usize,
        set: u64,
        base: &FusedBase,
        b: &Matrix,
        inexact: usize,
        out: &mut Matrix,
    ) -> Result<(), SchemeError> {
        let slot = &self.inflations[p * self.bases.sets + set as usize];
        let unit = get_or_try(slot, || {
            Ok(unit_inflation(
                &base.raw,
                &center.plan().at(p)?.cbar_p_inv,
                b,
            ))
        })?;
        inflate_into(&base.raw, unit, inexact, out);
        Ok(())
    }
}
