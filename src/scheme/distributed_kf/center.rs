//! Fusion center of the globalized distributed KF (Dormann et al.).
use super::loss::{self, Streak};
use super::plan::{GlobalizedPlan, PredictedDelta};
use super::sensor::debiased_extrapolation_into;
use crate::filter::Gaussian;
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::MeasurementModel;
use crate::scheme::{FusionCenter, SchemeError};
use nalgebra::{Cholesky, Dyn};
use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::sync::{OnceLock, RwLock};

/// Which fusion rule the center applies to silent sensors.
#[derive(Debug, Clone, PartialEq)]
pub enum Fusion {
    /// Algorithm 1, eq. (10)-(11): exact (equal to the centralized KF that received everything
    /// up to k-1 and the same subset at k) as long as every silent sensor sent at k-1. Under
    /// the protocol a sensor is never silent twice in a row, so an estimate missing twice in a
    /// row was lost by the link: the center then uses the debiased extrapolation of its last
    /// estimate to arrive and inflates the covariance by that extrapolation's computed second
    /// moment (the loss fallback of `distributed_kf::loss`).
    OmittedEstimates,
    /// Algorithm 2 (Section IV): silent sensors contribute their debiased extrapolation x̃^{pp,i}
    /// and the covariance is inflated by (N - m - l)^2 C (C̄^p)^{-1} B (C̄^p)^{-1} C^T, which
    /// keeps the estimate consistent when the sensors use test (13) with the same B and every
    /// sent estimate arrives. A loss-aware center ([`DkfCenter::set_loss_aware`]) inflates by
    /// B plus the extrapolation's second moment instead (see `distributed_kf::loss`).
    Bounded { b: Matrix },
}

/// The fused covariance of one step and its Cholesky factor. It depends only on the plan step,
/// the set of silent sensors and (Algorithm 2) how many of them are extrapolated inexactly —
/// never on measurements — so it is computed once per such key and shared by all trials.
#[derive(Debug)]
pub struct FusedCovariance {
    /// Cholesky factor of the fused information matrix (10).
    pub chol: Cholesky<f64, Dyn>,
    /// The fused covariance, inflated for Algorithm 2.
    pub cov: Matrix,
}

/// Key of a [`FusedCovariance`]: plan step, bit set of silent sensors, inexact count.
type CovKey = (usize, u64, usize);

/// Memo of [`FusedCovariance`]s of one fusion rule, shared by the centers of all trials.
///
/// A key is admitted on its second sighting: most silence patterns of a long sweep occur
/// once, and keeping them would cost memory (hundreds of MB for `dormann-fig1`) for no reuse.
/// Both sets are capped; beyond the caps the covariance is simply recomputed. Which entries
/// are kept never changes a number, only how often one is recomputed.
///
/// The fast trial does not use these entries but the dense tables of `DenseMemo`, which
/// the memos made by [`CovarianceMemo::shared`] carry.
#[derive(Debug, Default)]
pub struct CovarianceMemo {
    entries: RwLock<Memo>,
    dense: Option<DenseMemo>,
}

#[derive(Debug, Default)]
struct Memo {
    kept: HashMap<CovKey, Arc<FusedCovariance>, KeyHash>,
    seen: HashSet<CovKey, KeyHash>,
}

/// A multiplicative hash of the three words of a [`CovKey`] (the keys are not adversarial;
/// SipHash would cost more than the lookup it guards).
#[derive(Debug, Default, Clone, Copy)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

type KeyHash = BuildHasherDefault<KeyHasher>;

/// Bytes all [`CovarianceMemo`]s of the process may keep together (kept entries are ~700
/// bytes for a 6-D state), and keys seen once one memo may remember.
const MEMO_BUDGET: usize = 8 << 20;
const MEMO_SEEN: usize = 1 << 13;
static MEMO_BYTES: AtomicUsize = AtomicUsize::new(0);

/// Approximate heap bytes of one kept entry of an n-D state: two n x n matrices and overhead.
fn memo_entry_bytes(n: usize) -> usize {
    2 * 8 * n * n + 160
}

impl Drop for Memo {
    fn drop(&mut self) {
        let n = self.kept.values().next().map_or(0, |c| c.cov.nrows());
        MEMO_BYTES.fetch_sub(self.kept.len() * memo_entry_bytes(n), Ordering::Relaxed);
    }
}

impl CovarianceMemo {
    pub fn new() -> Self {
        Self::default()
    }

    /// The memo of `plan` and `fusion`, shared with every other caller that asked for the same
    /// plan (same `Arc`) and an equal fusion rule while that memo is alive. The fused
    /// covariance depends on the plan step, the silence set, the inexact count and the rule
    /// only, so the variants of a sweep (Algorithm 1's rates and alphas, Algorithm 2's alphas
    /// at one B) see each other's entries instead of each computing its own.
    ///
    /// Memos of one plan share the fast trial's table of fused bases (which does not depend
    /// on the rule, see `DenseMemo`).
    pub fn shared(plan: &Arc<GlobalizedPlan>, fusion: &Fusion) -> Arc<Self> {
        type Entry = (
            std::sync::Weak<GlobalizedPlan>,
            Fusion,
            std::sync::Weak<CovarianceMemo>,
        );
        static CACHE: std::sync::Mutex<Vec<Entry>> = std::sync::Mutex::new(Vec::new());
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        cache.retain(|(p, _, m)| p.strong_count() > 0 && m.strong_count() > 0);
        let mut bases = None;
        for (p, f, m) in cache.iter() {
            if p.upgrade().is_some_and(|p| Arc::ptr_eq(&p, plan)) {
                if let Some(m) = m.upgrade() {
                    if f == fusion {
                        return m;
                    }
                    // The same plan under another rule: its base table serves this one too.
                    bases = bases.or_else(|| m.dense.as_ref().map(|d| d.bases().clone()));
                }
            }
        }
        let memo = Arc::new(Self {
            entries: RwLock::default(),
            dense: DenseMemo::new(plan, fusion, bases),
        });
        cache.push((Arc::downgrade(plan), fusion.clone(), Arc::downgrade(&memo)));
        memo
    }
}

/// The fusion center.
///
/// A step allocates nothing: the covariance comes from the shared [`CovarianceMemo`] (computed
/// there by the very operations the direct form performs), the information vector and the
/// held estimates live in buffers, and the predicted debiasing matrices are the plan's.
#[derive(Debug, Clone)]
pub struct DkfCenter {
    plan: Arc<GlobalizedPlan>,
    sensors: Vec<Arc<dyn MeasurementModel>>,
    fusion: Fusion,
    est: Gaussian,
    /// Per sensor: last received globalized estimate, predicted since (x̄^{pp,i}).
    held: Vec<Vector>,
    /// Per sensor: its debiasing matrix, predicted since (Δ^{pp,i}), a link of the plan's
    /// shared chain; Algorithm 2 only (`None` when A is singular).
    held_delta: Vec<Option<Arc<PredictedDelta>>>,
    /// Per sensor: consecutive silent steps including the current one.
    silent_steps: Vec<usize>,
    /// Per sensor: the last globalized estimate to arrive, as it arrived (x̄^{e,i}_s).
    received: Vec<Vector>,
    /// Per sensor: its run of estimates missing twice or more ([`super::loss`]).
    streaks: Vec<Option<Streak>>,
    /// Algorithm 2 only: treat a sensor silent twice or more as possibly lost (B plus the
    /// extrapolation's second moment) instead of Algorithm 2's B alone.
    loss_aware: bool,
    /// Σ of the second moments (plus B) of this step's loss fallbacks.
    loss_moment: Matrix,
    memo: Arc<CovarianceMemo>,
    /// Per sensor: the first sensor whose information matrix H^T R^{-1} H is bitwise the
    /// same (identical sensors remove identical information, see [`canonical_silence`]).
    pub(super) class: Vec<usize>,
    /// Work space.
    info_vec: Vector,
    tmp: Vector,
    tmp2: Vector,
    contribution: Vector,
}

impl DkfCenter {
    /// Starts from the common prior; at k = 0 every sensor's initial estimate is known.
    pub fn new(
        plan: Arc<GlobalizedPlan>,
        sensors: Vec<Arc<dyn MeasurementModel>>,
        prior: Gaussian,
        fusion: Fusion,
    ) -> Self {
        Self::with_memo(
            plan,
            sensors,
            prior,
            fusion,
            Arc::new(CovarianceMemo::new()),
        )
    }

    /// Like [`DkfCenter::new`], sharing the covariance memo `memo` with other centers of the
    /// same plan and fusion rule (the trials of one scheme variant).
    pub fn with_memo(
        plan: Arc<GlobalizedPlan>,
        sensors: Vec<Arc<dyn MeasurementModel>>,
        prior: Gaussian,
        fusion: Fusion,
        memo: Arc<CovarianceMemo>,
    ) -> Self {
        let n = prior.dim();
        let held = vec![prior.mean.clone(); sensors.len()];
        let held_delta = (0..sensors.len()).map(|i| plan.delta_head(i, 0)).collect();
        let silent_steps = vec![0; sensors.len()];
        let info = |s: &Arc<dyn MeasurementModel>| s.as_linear().map(|l| l.information().clone());
        let class = (0..sensors.len())
            .map(|i| {
                let mine = info(&sensors[i]);
                (0..i)
                    .find(|&j| mine.is_some() && info(&sensors[j]).is_some_and(|o| Some(o) == mine))
                    .unwrap_or(i)
            })
            .collect();
        Self {
            plan,
            received: held.clone(),
            streaks: vec![None; sensors.len()],
            loss_aware: false,
            loss_moment: Matrix::zeros(n, n),
            sensors,
            fusion,
            est: prior,
            held,
            held_delta,
            silent_steps,
            memo,
            class,
            info_vec: Vector::zeros(n),
            tmp: Vector::zeros(n),
            tmp2: Vector::zeros(n),
            contribution: Vector::zeros(n),
        }
    }

    /// The fused covariance of plan step `p` with the silent sensors `silent` (bit i = sensor
    /// i) of which `inexact` are extrapolated: memoized when there are at most 64 sensors.
    pub(super) fn fused_covariance(
        &self,
        p: usize,
        silent: u64,
        inexact: usize,
    ) -> Result<Arc<FusedCovariance>, SchemeError> {
        let memoized = self.sensors.len() <= 64;
        let key = (p, silent, inexact);
        if memoized {
            let entries = self.memo.entries.read().unwrap_or_else(|e| e.into_inner());
            if let Some(c) = entries.kept.get(&key) {
                return Ok(c.clone());
            }
        }
        let c = Arc::new(self.compute_fused_covariance(p, |i| silent >> i & 1 == 1, inexact)?);
        if memoized {
            let mut memo = self.memo.entries.write().unwrap_or_else(|e| e.into_inner());
            if memo.seen.remove(&key) {
                let bytes = memo_entry_bytes(c.cov.nrows());
                let budget = MEMO_BYTES.fetch_add(bytes, Ordering::Relaxed);
                if budget + bytes <= MEMO_BUDGET {
                    memo.kept.insert(key, c.clone());
                } else {
                    MEMO_BYTES.fetch_sub(bytes, Ordering::Relaxed);
                }
            } else if memo.seen.len() < MEMO_SEEN {
                memo.seen.insert(key);
            }
        }
        Ok(c)
    }

    /// (10): start from N (C̄^e)^{-1}, remove the information of each silent sensor (in sensor
    /// order), invert; Algorithm 2 adds (N - m - l)^2 C (C̄^p)^{-1} B (C̄^p)^{-1} C^T. The same
    /// operations in the same order as the direct per-step form, in the stages the fast
    /// trial's dense memo ([`DenseMemo`]) keeps separately.
    pub(super) fn compute_fused_covariance(
        &self,
        p: usize,
        is_silent: impl Fn(usize) -> bool,
        inexact: usize,
    ) -> Result<FusedCovariance, SchemeError> {
        let chol = self.fused_information_cholesky(p, is_silent)?;
        let raw = unsymmetrized_inverse(&chol);
        let mut cov = Matrix::zeros(raw.nrows(), raw.ncols());
        match &self.fusion {
            Fusion::Bounded { b } if inexact > 0 => {
                let unit = unit_inflation(&raw, &self.plan.at(p)?.cbar_p_inv, b);
                inflate_into(&raw, &unit, inexact, &mut cov);
            }
            _ => {
                cov.copy_from(&raw);
                symmetrize(&mut cov);
            }
        }
        Ok(FusedCovariance { chol, cov })
    }

    /// The Cholesky factor of (10)'s information matrix N (C̄^e_k)^{-1} - Σ_silent H_i^T R_i^{-1}
    /// H_i (subtracted in sensor order, then symmetrized). It does not depend on the fusion
    /// rule.
    pub(super) fn fused_information_cholesky(
        &self,
        p: usize,
        is_silent: impl Fn(usize) -> bool,
    ) -> Result<Cholesky<f64, Dyn>, SchemeError> {
        let m = self.plan.at(p)?;
        let nf = self.sensors.len() as f64;
        let mut info = &m.cbar_e_inv * nf;
        for (i, s) in self.sensors.iter().enumerate() {
            if is_silent(i) {
                let lin = s.as_linear().ok_or_else(|| {
                    SchemeError::Unsupported("distributed KF needs linear sensors".into())
                })?;
                info -= lin.information();
            }
        }
        symmetrize(&mut info);
        cholesky(&info).map_err(|source| SchemeError::Matrix {
            what: "fused information matrix (10)",
            source,
        })
    }

    /// Algorithm 2's center made loss-aware: a sensor silent twice or more in a row may have
    /// been lost, so its term is inflated by B plus the computed second moment of its
    /// extrapolation (see `distributed_kf::loss`). Algorithm 1's center always treats such a sensor
    /// as lost (the protocol never omits twice), so the flag changes nothing there.
    pub fn set_loss_aware(&mut self, on: bool) {
        self.loss_aware = on;
    }

    /// Whether a sensor silent twice or more is treated as Algorithm 2's bounded omission (B
    /// alone, as published) rather than by the loss fallback.
    fn published_bound(&self) -> bool {
        matches!(self.fusion, Fusion::Bounded { .. }) && !self.loss_aware
    }

    /// The plan the center fuses with.
    pub(super) fn plan(&self) -> &GlobalizedPlan {
        &self.plan
    }

    /// Which fusion rule the center applies.
    pub(super) fn fusion(&self) -> &Fusion {
        &self.fusion
    }

    /// The fast trial's dense tables of the shared memo, if it has them.
    pub(super) fn dense_memo(&self) -> Option<&DenseMemo> {
        self.memo.dense.as_ref()
    }
}

/// `chol.inverse()` before its symmetrization: the identity solved in place, in the
/// fixed-size kernels (the same operations as nalgebra's, bit for bit).
pub(super) fn unsymmetrized_inverse(chol: &Cholesky<f64, Dyn>) -> Matrix {
    let n = chol.l_dirty().nrows();
    let mut cov = Matrix::identity(n, n);
    crate::linalg::fixed::chol_solve_matrix(chol, &mut cov);
    cov
}

/// Algorithm 2's inflation for one inexact extrapolation, C (C̄^p)^{-1} B (C̄^p)^{-1} C^T with
/// C = `raw` (the unsymmetrized inverse): G = C (C̄^p)^{-1}, then (G B) G^T.
pub(super) fn unit_inflation(raw: &Matrix, cbar_p_inv: &Matrix, b: &Matrix) -> Matrix {
    let product = |a: &Matrix, b: &Matrix| {
        let mut y = Matrix::zeros(a.nrows(), b.ncols());
        crate::linalg::fixed::gemm(&mut y, a, b);
        y
    };
    let g = product(raw, cbar_p_inv);
    product(&product(&g, b), &g.transpose())
}

/// `out = sym(raw + unit * l^2)` for `inexact` = l extrapolated sensors: each product
/// `unit_j * l^2` rounded, then added to `raw_j` (as `raw += unit * factor` does), then
/// symmetrized as [`symmetrize`] does it — in fixed size for dimensions 1..=6 (the same
/// operations, unrolled).
pub(super) fn inflate_into(raw: &Matrix, unit: &Matrix, inexact: usize, out: &mut Matrix) {
    let factor = (inexact * inexact) as f64;
    let (r, u) = (raw.as_slice(), unit.as_slice());
    match out.nrows() {
        1 => inflate_fixed::<1>(r, u, factor, out.as_mut_slice()),
        2 => inflate_fixed::<2>(r, u, factor, out.as_mut_slice()),
        3 => inflate_fixed::<3>(r, u, factor, out.as_mut_slice()),
        4 => inflate_fixed::<4>(r, u, factor, out.as_mut_slice()),
        5 => inflate_fixed::<5>(r, u, factor, out.as_mut_slice()),
        6 => inflate_fixed::<6>(r, u, factor, out.as_mut_slice()),
        _ => {
            for ((o, &r), &u) in out.as_mut_slice().iter_mut().zip(r).zip(u) {
                *o = r + u * factor;
            }
            symmetrize(out);
        }
    }
}

#[inline(always)]
fn inflate_fixed<const N: usize>(raw: &[f64], unit: &[f64], factor: f64, out: &mut [f64]) {
    let (raw, unit, out) = (&raw[..N * N], &unit[..N * N], &mut out[..N * N]);
    for j in 0..N * N {
        out[j] = raw[j] + unit[j] * factor;
    }
    // `symmetrize`: (i, j) at j * N + i, the mean of each pair above the diagonal.
    for i in 0..N {
        for j in (i + 1)..N {
            let m = 0.5 * (out[j * N + i] + out[i * N + j]);
            out[j * N + i] = m;
            out[i * N + j] = m;
        }
    }
}

impl FusionCenter for DkfCenter {
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        if inbox.len() != self.sensors.len() {
            return Err(SchemeError::Unsupported(format!(
                "inbox has {} entries for {} sensors",
                inbox.len(),
                self.sensors.len()
            )));
        }
        let p = self.plan.index(k)?;
        let m = self.plan.at(k)?;
        let a = self.plan.a();
        let bounded = matches!(self.fusion, Fusion::Bounded { .. });
        let n = self.est.dim();
        // (11): the information vector; (10)'s matrix only depends on who was silent.
        self.info_vec.fill(0.0);
        let mut silent = 0u64;
        // Silent sensors whose extrapolation is not exact (N - m - l of Section IV).
        let mut inexact = 0usize;
        // Sensors under the loss fallback whose second moment is in `loss_moment`.
        let mut lost = 0usize;
        for (i, msg) in inbox.iter().enumerate() {
            super::sensor::predict_in_place(a, &mut self.held[i], &mut self.tmp);
            if bounded {
                if self.plan.a_inv().is_none() {
                    return Err(SchemeError::Unsupported(
                        "Algorithm 2 needs an invertible system matrix".into(),
                    ));
                }
                let next = self.held_delta[i].as_ref().map(|d| d.next(&self.plan));
                self.held_delta[i] = next;
            }
            match msg {
                Received::Estimate(x) => {
                    if x.len() != n || x.iter().any(|v| !v.is_finite()) {
                        return Err(SchemeError::Protocol {
                            sensor: i,
                            message: format!("corrupt estimate {:?}", x.as_slice()),
                        });
                    }
                    // (11), first sum.
                    crate::linalg::fixed::gemv(&mut self.tmp, &m.cbar_e_inv, x);
                    self.info_vec += &self.tmp;
                    self.held[i].copy_from(x);
                    self.received[i].copy_from(x);
                    self.streaks[i] = None;
                    if bounded {
                        self.held_delta[i] = self.plan.delta_head(i, p);
                    }
                    self.silent_steps[i] = 0;
                }
                Received::Silent | Received::NotScheduled => {
                    self.silent_steps[i] += 1;
                    if self.sensors[i].as_linear().is_none() {
                        return Err(SchemeError::Unsupported(
                            "distributed KF needs linear sensors".into(),
                        ));
                    }
                    if i < 64 {
                        silent |= 1 << i;
                    }
                    let contribution = if self.silent_steps[i] == 1 {
                        // Sent at k-1: x̄^{pp} = x̄^p, exact (11), second sum.
                        &self.held[i]
                    } else if self.published_bound() {
                        // Algorithm 2 (Section IV): the debiased extrapolation, bounded by B.
                        inexact += 1;
                        let pd = self.held_delta[i].as_ref().expect("checked invertible");
                        debiased_extrapolation_into(
                            &m.delta_p[i],
                            pd,
                            self.held[i].as_slice(),
                            &mut self.tmp2,
                            &mut self.contribution,
                        )?;
                        &self.contribution
                    } else if self.plan.a_inv().is_none() {
                        // Missing twice or more with a singular A: no debiasing, the plain
                        // extrapolation, uninflated (`super::loss`).
                        &self.held[i]
                    } else {
                        // Missing twice or more: lost (Algorithm 1) or possibly lost
                        // (loss-aware Algorithm 2), see `super::loss`.
                        if lost == 0 {
                            self.loss_moment.fill(0.0);
                        }
                        let s = k - self.silent_steps[i];
                        loss_fallback(
                            &self.plan,
                            &self.fusion,
                            &mut self.streaks[i],
                            (i, s, k),
                            &self.received[i],
                            (&mut self.contribution, &mut self.loss_moment),
                        )?;
                        lost += 1;
                        &self.contribution
                    };
                    crate::linalg::fixed::gemv(&mut self.tmp, &m.cbar_p_inv, contribution);
                    self.info_vec += &self.tmp;
                }
                Received::Measurement(_) | Received::Frame(_) => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: "distributed KF expects estimates".into(),
                    })
                }
            }
        }
        let fused = if self.sensors.len() <= 64 {
            let silent = canonical_silence(&self.class, silent);
            self.fused_covariance(p, silent, inexact)?
        } else {
            // Too many sensors for the bit set: the direct form, one silence set at a time.
            Arc::new(self.compute_fused_covariance(
                p,
                |i| matches!(inbox[i], Received::Silent | Received::NotScheduled),
                inexact,
            )?)
        };
        self.est.mean.copy_from(&self.info_vec);
        crate::linalg::fixed::chol_solve(&fused.chol, &mut self.est.mean);
        if lost > 0 {
            // The loss fallback's covariance (`super::loss`): C + L G (Σ S) G^T.
            self.est.cov = loss::inflate(&fused.cov, &m.cbar_p_inv, &self.loss_moment, lost);
        } else {
            self.est.cov.copy_from(&fused.cov);
        }
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
}

/// Sensor i, whose last estimate to arrive (`received`, x̄^{e,i}_s) was sent at step s, is
/// missing at step k for the second time or more (`at` = (i, s, k)), and A is invertible: its
/// term (the debiased extrapolation) into `out.0`, and its second moment S (plus B under
/// Algorithm 2) added to `out.1` ([`super::loss`]). The fast trial calls it too.
pub(super) fn loss_fallback(
    plan: &GlobalizedPlan,
    fusion: &Fusion,
    streak: &mut Option<Streak>,
    at: (usize, usize, usize),
    received: &Vector,
    out: (&mut Vector, &mut Matrix),
) -> Result<(), SchemeError> {
    let (i, s, k) = at;
    let (contribution, moment) = out;
    let table = plan.loss_table();
    let streak = match streak {
        Some(st) => st,
        None => streak.insert(Streak::start(plan, table, i, s, received)?),
    };
    while streak.t() + 1 < k {
        streak.advance(plan, table, i)?;
    }
    let (term, second_moment) = streak.term_and_moment(plan, i)?;
    contribution.copy_from(&term);
    *moment += &second_moment;
    if let Fusion::Bounded { b } = fusion {
        *moment += b;
    }
    Ok(())
}

/// The silence set that removes the same sequence of information matrices as `silent` (bit i
/// = sensor i silent): each silent sensor, in order, is replaced by the first sensor of its
/// class after the previous choice. (10) subtracts H_i^T R_i^{-1} H_i in sensor order, so two
/// sets with the same sequence of (bitwise equal) matrices give the same covariance bit for
/// bit; Dormann et al.'s Fig. 1 has its sensors in identical pairs, and the memo keys halve.
pub(super) fn canonical_silence(class: &[usize], silent: u64) -> u64 {
    let mut out = 0u64;
    let mut next = 0usize;
    for (i, &c) in class.iter().enumerate() {
        if silent >> i & 1 == 1 {
            let j = (next..=i)
                .find(|&j| class[j] == c)
                .expect("sensor i itself is of class c");
            out |= 1 << j;
            next = j + 1;
        }
    }
    out
}

// The dense memo of the fused covariances (formerly its own module, `fused`):
// The fast trial's memo of (10)'s fused covariance: dense tables indexed by plan step and
// silence set, instead of the generic center's hash map keyed by (step, set, inexact count).
//
// Algorithm 2's fused covariance is sym(C + l^2 C (C̄^p)^{-1} B (C̄^p)^{-1} C^T), with C the
// inverse of (10)'s information matrix before its symmetrization and l the number of silent
// sensors extrapolated inexactly (Algorithm 1's is sym(C)). C, its Cholesky factor and sym(C)
// depend on the plan step and the silence set only — not on the rule, B or l — and the
// inflation C (C̄^p)^{-1} B (C̄^p)^{-1} C^T on B too, but not on l. Keeping those two and
// applying l at each step (n^2 products and sums) keeps every key of a sweep, a few MB for
// `dormann-fig1`, where the generic memo's entries, one per (step, set, l, B), would be
// hundreds of MB (its budget keeps a fraction and recomputes the rest). Every entry is
// computed by the stages [`DkfCenter::compute_fused_covariance`] composes, on the same
// operands, so the numbers are its numbers bit for bit.

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
