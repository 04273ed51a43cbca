//! Baselines: the centralized Kalman filter that receives raw measurements — all of them (the
//! bound every scheme is measured against), or each with probability `rate` (Dormann et al.
//! Section V: a measurement not sent is lost for good).
use super::fast_path::{
    BatchSink, FastTrialError, LockstepFastPath, Losses, QuadBlock, TrialCache,
};
use super::{FusionCenter, Scheme, SchemeError, SchemeInstance, SensorNode, System};
use crate::filter::{kf, Gaussian};
use crate::linalg::fixed;
use crate::linalg::quad::F64x4;
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::link::{as_sent, round_as_sent, Message, Received, Transmission};
use nalgebra::{Cholesky, Dyn};
use rand::{Rng, RngCore};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;
use std::sync::RwLock;

mod aggregated;
mod means;
use means::{advance_means, advance_quad};
pub mod params;

/// Sensor that forwards its raw measurement with probability `send_probability`.
#[derive(Debug, Clone)]
pub struct ForwardingSensor {
    send_probability: f64,
}

impl ForwardingSensor {
    /// `send_probability` = 1 forwards everything.
    pub fn new(send_probability: f64) -> Self {
        Self { send_probability }
    }
}

impl SensorNode for ForwardingSensor {
    fn step(
        &mut self,
        _k: usize,
        z: &Vector,
        _feedback: Option<&super::Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        // Always draw, so the coin stream does not depend on the probability's value.
        let u: f64 = rng.random();
        if u < self.send_probability {
            Ok(Transmission::Send(Message::Measurement(z.clone())))
        } else {
            Ok(Transmission::Silent)
        }
    }
}

/// Kalman filter on whatever measurements arrive. Linear sensors are fused in information
/// form, one sum per step (Dormann et al., Section II; eq. (8)-(9) for a subset); nonlinear sensors
/// by sequential EKF updates.
#[derive(Debug, Clone)]
pub struct CentralizedKf {
    system: Arc<System>,
    est: Gaussian,
    /// The shared covariance schedule when every measurement of every step is known to arrive
    /// (linear sensors, rate 1); `None` once a step deviates from it.
    schedule: Option<Arc<AllDataSchedule>>,
    /// Steps taken (the schedule is indexed by it, not by the caller's k, as the direct step
    /// depends on the history only).
    steps_done: usize,
    /// Work space of the scheduled step.
    pred_mean: Vector,
    tmp: Vector,
    /// Work space of the direct linear step, made at its first use (a center on the schedule
    /// never needs it).
    work: Option<Box<DirectWork>>,
}

/// Buffers of [`CentralizedKf::direct_linear_step`]: F^T (as `F.transpose()` makes it), F P,
/// the predicted covariance, the information matrix and the matrix the Cholesky factors are
/// computed in.
#[derive(Debug, Clone)]
struct DirectWork {
    ft: Matrix,
    fp: Matrix,
    pred_cov: Matrix,
    info: Matrix,
    chol: Option<Matrix>,
}

impl DirectWork {
    /// The work space in `slot`, made for the transition matrix `f` at its first use.
    fn get<'a>(slot: &'a mut Option<Box<DirectWork>>, f: &Matrix) -> &'a mut DirectWork {
        let n = f.nrows();
        slot.get_or_insert_with(|| {
            Box::new(DirectWork {
                ft: f.transpose(),
                fp: Matrix::zeros(n, n),
                pred_cov: Matrix::zeros(n, n),
                info: Matrix::zeros(n, n),
                chol: None,
            })
        })
    }
}

/// `m.fill_with_identity()` on the slice of a square matrix.
fn identity(m: &mut Matrix) {
    let n = m.nrows();
    let s = m.as_mut_slice();
    s.fill(0.0);
    for i in 0..n {
        s[i * n + i] = 1.0;
    }
}

/// The error of a failed Cholesky factorization of `what` (as [`cholesky_in`] reports it).
fn matrix_error(what: &'static str, source: crate::linalg::LinalgError) -> SchemeError {
    SchemeError::Filter(crate::filter::FilterError::Matrix { what, source })
}

/// [`cholesky_in`] on an N x N column-major slice in place: the same finiteness check, the
/// same factorization ([`fixed::cholesky_square`]) and the same errors. Inlined, so that it
/// is compiled for the caller's target features.
#[inline(always)]
fn cholesky_square<const N: usize>(m: &mut [f64], what: &'static str) -> Result<(), SchemeError> {
    use crate::linalg::LinalgError;
    if !fixed::all_finite(&m[..N * N]) {
        return Err(matrix_error(what, LinalgError::NonFinite));
    }
    if !fixed::cholesky_square::<N>(m) {
        return Err(matrix_error(what, LinalgError::NotPositiveDefinite));
    }
    Ok(())
}

/// `cholesky(a)` of [`crate::linalg`] computed in `buf` (same checks, same factorization).
fn cholesky_in(
    a: &Matrix,
    buf: &mut Option<Matrix>,
    what: &'static str,
) -> Result<Cholesky<f64, Dyn>, SchemeError> {
    let err = |source| matrix_error(what, source);
    if a.as_slice().iter().any(|v| !v.is_finite()) {
        return Err(err(crate::linalg::LinalgError::NonFinite));
    }
    let mut m = match buf.take() {
        Some(m) if m.shape() == a.shape() => m,
        _ => Matrix::zeros(a.nrows(), a.ncols()),
    };
    m.as_mut_slice().copy_from_slice(a.as_slice());
    crate::linalg::fixed::cholesky(m).ok_or(err(crate::linalg::LinalgError::NotPositiveDefinite))
}

impl CentralizedKf {
    pub fn new(system: Arc<System>) -> Self {
        Self::build(system, None)
    }

    /// A center that follows `schedule` while every sensor's measurement arrives, and falls
    /// back to the direct form (from the same estimate) at the first step one does not.
    pub fn with_schedule(system: Arc<System>, schedule: Arc<AllDataSchedule>) -> Self {
        Self::build(system, Some(schedule))
    }

    fn build(system: Arc<System>, schedule: Option<Arc<AllDataSchedule>>) -> Self {
        let est = system.prior.clone();
        let n = est.dim();
        Self {
            system,
            est,
            schedule,
            steps_done: 0,
            pred_mean: Vector::zeros(n),
            tmp: Vector::zeros(n),
            work: None,
        }
    }

    /// The direct step for linear sensors: the operations of `kf::predict`,
    /// `Information::from_gaussian`, `add_measurement` and `to_gaussian` (the same products,
    /// factorizations and solves in the same order, hence the same numbers), without
    /// allocating. Dormann et al., Section II: the centralized KF fuses what arrived by a sum of
    /// H_i^T R_i^{-1} H_i and H_i^T R_i^{-1} z_i (eq. (8)-(9) for a subset). State dimensions
    /// 1..=6 run on stack arrays (where [`fixed::gemm_square`] has `gemm`'s kernel), others
    /// on nalgebra matrices.
    fn direct_linear_step<'a>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<(), SchemeError> {
        let n = self.est.dim();
        match n {
            _ if !fixed::gemm_square_covers(n) => self.direct_linear_dynamic(len, arrived),
            1 => self.direct_linear_fixed::<1>(len, arrived),
            2 => self.direct_linear_fixed::<2>(len, arrived),
            3 => self.direct_linear_fixed::<3>(len, arrived),
            4 => self.direct_linear_fixed::<4>(len, arrived),
            5 => self.direct_linear_fixed::<5>(len, arrived),
            6 => self.direct_linear_fixed::<6>(len, arrived),
            _ => self.direct_linear_dynamic(len, arrived),
        }
    }

    /// [`CentralizedKf::direct_linear_fixed_body`], compiled for AVX2 where the CPU has it
    /// (wider vectors for the same operations: a vector lane rounds as a scalar does, and
    /// Rust fuses no multiply and add on any target, so every bit is the same).
    fn direct_linear_fixed<'a, const N: usize>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<(), SchemeError> {
        #[cfg(target_arch = "x86_64")]
        if fixed::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { self.direct_linear_fixed_avx2::<N>(len, arrived) };
        }
        self.direct_linear_fixed_body::<N>(len, arrived)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn direct_linear_fixed_avx2<'a, const N: usize>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<(), SchemeError> {
        self.direct_linear_fixed_body::<N>(len, arrived)
    }

    /// [`CentralizedKf::direct_linear_dynamic`] for state dimension N, on stack arrays: every
    /// product, sum, factorization and solve of it by the `fixed` kernel that performs the
    /// same operations in the same order, so the numbers are the same bit for bit; the
    /// errors are the same, in the same order, and leave the estimate as it was.
    #[inline(always)]
    fn direct_linear_fixed_body<'a, const N: usize>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<(), SchemeError> {
        let nn = N * N;
        let t = &self.system.transition;
        let ft = DirectWork::get(&mut self.work, t.f()).ft.as_slice();
        let (f, p) = (t.f().as_slice(), self.est.cov.as_slice());
        let x: &[f64; N] = self.est.mean.as_slice().try_into().expect("N entries");
        // kf::predict: F x, and F P F^T + Q symmetrized.
        let mut y: [f64; N] = fixed::mat_vec::<N, N, _>(f, x);
        let mut fp = [0.0; 36];
        fixed::gemm_square::<N>(&mut fp, f, p);
        let mut m = [0.0; 36];
        fixed::gemm_square::<N>(&mut m, &fp, ft);
        fixed::add_assign(&mut m[..nn], t.q().as_slice());
        fixed::symmetrize_square::<N>(&mut m);
        // Information::from_gaussian: y = P^{-1} x, Y = P^{-1} symmetrized.
        cholesky_square::<N>(&mut m, "covariance")?;
        fixed::chol_solve_array::<N, _>(&m, &mut y);
        let mut info = [0.0; 36];
        fixed::chol_inverse_sym_square::<N>(&m, &mut info);
        // add_measurement of each arrived measurement, in sensor order.
        for i in 0..len {
            if let Some(z) = arrived(i)? {
                let sensor = self.system.sensors[i].as_linear().expect("checked linear");
                kf::check_measurement(sensor, z)?;
                fixed::add_assign(&mut info[..nn], sensor.information().as_slice());
                let t: [f64; N] =
                    fixed::mat_vec_cols::<N>(sensor.ht_rinv().as_slice(), z.as_slice());
                fixed::add_assign(&mut y, &t);
            }
        }
        // Information::to_gaussian.
        cholesky_square::<N>(&mut info, "information matrix")?;
        fixed::chol_solve_array::<N, _>(&info, &mut y);
        self.est.mean.copy_from_slice(&y);
        fixed::chol_inverse_sym_square::<N>(&info, self.est.cov.as_mut_slice());
        Ok(())
    }

    /// [`CentralizedKf::direct_linear_step`] on nalgebra matrices, in buffers.
    fn direct_linear_dynamic<'a>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<(), SchemeError> {
        let t = &self.system.transition;
        let w = DirectWork::get(&mut self.work, t.f());
        // kf::predict: F x, and F P F^T + Q symmetrized.
        crate::linalg::fixed::gemv(&mut self.pred_mean, t.f(), &self.est.mean);
        crate::linalg::fixed::gemm(&mut w.fp, t.f(), &self.est.cov);
        crate::linalg::fixed::gemm(&mut w.pred_cov, &w.fp, &w.ft);
        fixed::add_assign(w.pred_cov.as_mut_slice(), t.q().as_slice());
        symmetrize(&mut w.pred_cov);
        // Information::from_gaussian: y = P^{-1} x, Y = P^{-1} symmetrized.
        let chol = cholesky_in(&w.pred_cov, &mut w.chol, "covariance")?;
        crate::linalg::fixed::chol_solve(&chol, &mut self.pred_mean);
        identity(&mut w.info);
        crate::linalg::fixed::chol_solve_matrix(&chol, &mut w.info);
        w.chol = Some(chol.unpack_dirty());
        symmetrize(&mut w.info);
        // add_measurement of each arrived measurement, in sensor order.
        for i in 0..len {
            if let Some(z) = arrived(i)? {
                let sensor = self.system.sensors[i].as_linear().expect("checked linear");
                kf::check_measurement(sensor, z)?;
                fixed::add_assign(w.info.as_mut_slice(), sensor.information().as_slice());
                crate::linalg::fixed::gemv(&mut self.tmp, sensor.ht_rinv(), z);
                fixed::add_assign(self.pred_mean.as_mut_slice(), self.tmp.as_slice());
            }
        }
        // Information::to_gaussian.
        let chol = cholesky_in(&w.info, &mut w.chol, "information matrix")?;
        self.est.mean.copy_from_slice(self.pred_mean.as_slice());
        crate::linalg::fixed::chol_solve(&chol, &mut self.est.mean);
        identity(&mut self.est.cov);
        crate::linalg::fixed::chol_solve_matrix(&chol, &mut self.est.cov);
        w.chol = Some(chol.unpack_dirty());
        symmetrize(&mut self.est.cov);
        Ok(())
    }

    /// The direct step: predict, fuse in information form (or EKF updates), back.
    fn direct_step(&mut self, inbox: &[Received]) -> Result<(), SchemeError> {
        let all_linear = self.system.sensors.iter().all(|s| s.as_linear().is_some());
        if all_linear {
            self.direct_linear_step(inbox.len(), |i| measurement(i, &inbox[i]))?;
        } else {
            let mut e = kf::predict(&self.system.transition, &self.est);
            for (i, msg) in inbox.iter().enumerate() {
                if let Some(z) = measurement(i, msg)? {
                    e = kf::update(self.system.sensors[i].as_ref(), e, z)?;
                }
            }
            self.est = e;
        }
        Ok(())
    }

    /// [`FusionCenter::step`] for linear sensors with the measurements that arrived
    /// (`arrived[i]`, in sensor order) instead of an inbox: the same operations.
    fn step_linear(&mut self, arrived: &[Option<&Vector>]) -> Result<(), SchemeError> {
        let scheduled = self.scheduled_step(arrived.len(), |i| Ok(arrived[i]))?;
        self.steps_done += 1;
        if scheduled {
            return Ok(());
        }
        self.schedule = None;
        self.direct_linear_step(arrived.len(), |i| Ok(arrived[i]))
    }

    /// The scheduled step: the mean half of [`CentralizedKf::direct_step`] with the step's
    /// precomputed Cholesky factors, the covariance copied. `Ok(false)` when the step is not
    /// on the schedule (a measurement missing, or the schedule could not be computed).
    fn scheduled_step<'a>(
        &mut self,
        len: usize,
        arrived: impl Fn(usize) -> Result<Option<&'a Vector>, SchemeError>,
    ) -> Result<bool, SchemeError> {
        let Some(schedule) = &self.schedule else {
            return Ok(false);
        };
        let all_arrived =
            len == self.system.n_sensors() && (0..len).all(|i| matches!(arrived(i), Ok(Some(_))));
        if !all_arrived {
            return Ok(false);
        }
        let Some(step) = schedule.step(&self.system, self.steps_done + 1) else {
            return Ok(false);
        };
        // Information vector of the prediction, P^{-1} (F x) (from_gaussian) ...
        crate::linalg::fixed::gemv(
            &mut self.pred_mean,
            self.system.transition.f(),
            &self.est.mean,
        );
        crate::linalg::fixed::chol_solve(&step.pred_chol, &mut self.pred_mean);
        // ... plus H_i^T R_i^{-1} z_i of each sensor, in sensor order (add_measurement) ...
        for i in 0..len {
            let Ok(Some(z)) = arrived(i) else {
                unreachable!("checked above")
            };
            let sensor = self.system.sensors[i].as_linear().expect("checked linear");
            kf::check_measurement(sensor, z)?;
            crate::linalg::fixed::gemv(&mut self.tmp, sensor.ht_rinv(), z);
            self.pred_mean += &self.tmp;
        }
        // ... and back to covariance form (to_gaussian).
        self.est.mean.copy_from(&self.pred_mean);
        crate::linalg::fixed::chol_solve(&step.fused_chol, &mut self.est.mean);
        self.est.cov.copy_from(&step.cov);
        Ok(true)
    }
}

impl FusionCenter for CentralizedKf {
    fn step(&mut self, _k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let scheduled = self.scheduled_step(inbox.len(), |i| measurement(i, &inbox[i]))?;
        self.steps_done += 1;
        if scheduled {
            return Ok(());
        }
        // Off the schedule for good: the covariance now depends on which data arrived.
        self.schedule = None;
        self.direct_step(inbox)
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }

    fn fuse_information(
        &mut self,
        _k: usize,
        sum: Option<&crate::filter::information::Information>,
    ) -> Result<(), SchemeError> {
        self.fuse_sum(sum)
    }
}

/// One step of [`AllDataSchedule`].
#[derive(Debug)]
pub struct ScheduledStep {
    /// Cholesky factor of the predicted covariance F P F^T + Q.
    pub pred_chol: Cholesky<f64, Dyn>,
    /// Cholesky factor of the fused information matrix P^{-1}_pred + Σ_i H_i^T R_i^{-1} H_i.
    pub fused_chol: Cholesky<f64, Dyn>,
    /// The filtered covariance.
    pub cov: Matrix,
    /// Its Cholesky factor as NEES computes it ([`fixed::nees_factor`]), when it has one.
    pub nees_factor: Option<Vec<f64>>,
}

/// The covariance recursion of the centralized KF that receives every measurement of every
/// step. For a linear-Gaussian model it does not depend on the data — P_k is a function of
/// P_0, F, Q, H_i and R_i only (the Riccati recursion) — so it is computed once per scheme
/// and shared by all trials; a trial only runs the mean recursion. It is computed by the very
/// operations of the direct step (predict_cov, from_gaussian, add_measurement, to_gaussian),
/// so the numbers are the same bit for bit. (With random losses P_k depends on which
/// measurements arrived, and the direct step runs.) Grown on demand: the scheme does not know
/// the horizon.
#[derive(Debug, Default)]
pub struct AllDataSchedule {
    steps: RwLock<ScheduleSteps>,
}

#[derive(Debug, Default)]
struct ScheduleSteps {
    /// steps[k - 1] is step k.
    steps: Vec<Arc<ScheduledStep>>,
    /// The recursion failed at this step (the direct step then reports the error).
    failed_at: Option<usize>,
}

impl AllDataSchedule {
    pub fn new() -> Self {
        Self::default()
    }

    /// Steps 1..=k of the schedule of `system` (computed if needed), read-locked while the
    /// caller runs its trials; `None` for k = 0 or if the recursion fails at or before k.
    fn through(
        &self,
        system: &System,
        k: usize,
    ) -> Option<std::sync::RwLockReadGuard<'_, ScheduleSteps>> {
        self.step(system, k)?;
        Some(self.steps.read().unwrap_or_else(|e| e.into_inner()))
    }

    /// Step k (k >= 1) of the schedule of `system`, computed up to k if needed; `None` if the
    /// recursion fails at or before k.
    pub fn step(&self, system: &System, k: usize) -> Option<Arc<ScheduledStep>> {
        {
            let s = self.steps.read().unwrap_or_else(|e| e.into_inner());
            if let Some(step) = s.steps.get(k.checked_sub(1)?) {
                return Some(step.clone());
            }
            if s.failed_at.is_some_and(|f| f <= k) {
                return None;
            }
        }
        let mut s = self.steps.write().unwrap_or_else(|e| e.into_inner());
        while s.steps.len() < k && s.failed_at.is_none() {
            let prev = s.steps.last().map_or(&system.prior.cov, |p| &p.cov);
            match schedule_step(system, prev) {
                Some(next) => s.steps.push(Arc::new(next)),
                None => s.failed_at = Some(s.steps.len() + 1),
            }
        }
        s.steps.get(k - 1).cloned()
    }
}

/// The covariance half of the direct all-data step, keeping the two Cholesky factors.
fn schedule_step(system: &System, prev: &Matrix) -> Option<ScheduledStep> {
    let pred_cov = kf::predict_cov(&system.transition, prev);
    // Information::from_gaussian
    let pred_chol = cholesky(&pred_cov).ok()?;
    let mut matrix = pred_chol.inverse();
    symmetrize(&mut matrix);
    // Information::add_measurement, every sensor in order
    for s in &system.sensors {
        matrix += s.as_linear()?.information();
    }
    // Information::to_gaussian
    let fused_chol = cholesky(&matrix).ok()?;
    let mut cov = fused_chol.inverse();
    symmetrize(&mut cov);
    Some(ScheduledStep {
        pred_chol,
        fused_chol,
        nees_factor: fixed::nees_factor(&cov),
        cov,
    })
}

/// The all-data trial of [`LockstepFastPath::run_trial_fast`] for [`CentralizedScheme`].
struct AllData<'a> {
    sys: &'a System,
    /// Per sensor: measurement dimension and H^T R^{-1}.
    linear: &'a [(usize, Matrix)],
    schedule: &'a AllDataSchedule,
    /// Where the estimate handed to the sink is written.
    est: &'a mut Gaussian,
}

impl AllData<'_> {
    /// Several trials in lockstep (state dimensions 1..=6, else `None`): at each step every trial's mean by
    /// the scheduled step's operations (`means::advance_means`; independent recursions, which the
    /// processor overlaps), the covariance copied from the shared schedule, then every trial's
    /// report. The forwarding coins are not drawn: at rate 1 every measurement is sent
    /// whatever the coin, and the variant's stream serves nothing else. `None` (nothing
    /// reported yet) when the schedule does not reach `steps`; the caller then runs the
    /// general step, which reports the failure at its step. Measurements are checked
    /// (dimensions, finite) by the caller.
    fn batch_any(
        self,
        trials: &[&[Vec<Vector>]],
        steps: usize,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        match self.sys.state_dim() {
            1 => self.batch::<1>(trials, steps, sink),
            2 => self.batch::<2>(trials, steps, sink),
            3 => self.batch::<3>(trials, steps, sink),
            4 => self.batch::<4>(trials, steps, sink),
            5 => self.batch::<5>(trials, steps, sink),
            6 => self.batch::<6>(trials, steps, sink),
            _ => None,
        }
    }

    /// [`AllData::batch_any`] for state dimension N.
    fn batch<const N: usize>(
        self,
        trials: &[&[Vec<Vector>]],
        steps: usize,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        let sys = self.sys;
        let sched = self.schedule.through(sys, steps)?;
        let traffic = all_sent_traffic(sys);
        let f = sys.transition.f().as_slice();
        let linear = self.linear;
        let est = self.est;
        let x0: [f64; N] = sys.prior.mean.as_slice().try_into().ok()?;
        // The trials' means: on the stack for a runner block (4 trials), else on the heap.
        const STACK_TRIALS: usize = 8;
        let mut stack = [x0; STACK_TRIALS];
        let mut heap;
        let xs: &mut [[f64; N]] = if trials.len() <= STACK_TRIALS {
            &mut stack[..trials.len()]
        } else {
            heap = vec![x0; trials.len()];
            &mut heap
        };
        for (k, step) in (1..=steps).zip(&sched.steps) {
            advance_means(f, linear, step, xs, trials, k);
            est.cov.as_mut_slice().copy_from_slice(step.cov.as_slice());
            let factor = step.nees_factor.as_deref();
            if let Err(source) = sink.step_shared(k, xs.as_flattened(), est, factor, traffic) {
                return Some(Err(FastTrialError::Sink { k, source }));
            }
        }
        Some(Ok(()))
    }
}

impl CentralizedScheme {
    /// [`LockstepFastPath::run_quad_fast`] for state dimension N (checked by the caller): the
    /// means of [`AllData::batch`] in lanes, step after step, each step's four reported at
    /// once. `None` (nothing reported) when the schedule does not reach `steps`. A reading
    /// that is not finite as it arrives (what `covers` refuses) ends the block in an error:
    /// the trials then run one at a time, where the generic center reports it.
    fn quad_steps<const N: usize>(
        &self,
        block: &mut dyn QuadBlock,
        steps: usize,
    ) -> Option<Result<(), FastTrialError>> {
        let (sys, linear) = (&self.system, self.linear.as_ref()?);
        let sched = self.schedule.as_ref()?.through(sys, steps)?;
        let traffic = all_sent_traffic(sys);
        let f = sys.transition.f().as_slice();
        let x0: &[f64; N] = sys.prior.mean.as_slice().try_into().ok()?;
        let mut x: [F64x4; N] = x0.map(F64x4::splat);
        for (k, step) in (1..=steps).zip(&sched.steps) {
            let zs = block.readings(k);
            if !zs.iter().all(|z| z.map(as_sent).all_finite()) {
                let source = crate::linalg::LinalgError::NonFinite;
                return Some(Err(FastTrialError::Sink { k, source }));
            }
            x = advance_quad(f, linear, step, &x, zs);
            let factor = step.nees_factor.as_deref();
            if let Err(source) = block.step_quad(k, &x, &step.cov, factor, traffic) {
                return Some(Err(FastTrialError::Sink { k, source }));
            }
        }
        Some(Ok(()))
    }
}

/// What network::deliver counts when every sensor sends its measurement.
fn all_sent_traffic(sys: &System) -> crate::network::Traffic {
    let mut traffic = crate::network::Traffic::default();
    for s in &sys.sensors {
        let m = Message::Measurement(Vector::zeros(s.meas_dim()));
        traffic.messages += 1;
        traffic.bits += m.bits();
        traffic.frame_bits += m.frame_bits();
    }
    traffic.senders = crate::network::all_sensors(sys.n_sensors());
    traffic.scheduled = traffic.senders;
    traffic
}

fn measurement(i: usize, msg: &Received) -> Result<Option<&Vector>, SchemeError> {
    match msg {
        Received::Measurement(z) => Ok(Some(z)),
        Received::Silent | Received::NotScheduled => Ok(None),
        other => Err(SchemeError::Protocol {
            sensor: i,
            message: format!("centralized KF expects measurements, got {other:?}"),
        }),
    }
}

/// Centralized KF whose sensors forward each measurement with probability `rate`
/// (`rate` = 1: the all-data bound).
#[derive(Debug, Clone)]
pub struct CentralizedScheme {
    system: Arc<System>,
    rate: f64,
    /// At rate 1 with linear sensors every measurement arrives: the shared covariance schedule.
    schedule: Option<Arc<AllDataSchedule>>,
    /// Per sensor, when every sensor is linear: its measurement dimension and H^T R^{-1}
    /// (what the fast trial reads per step, without a virtual call).
    linear: Option<Vec<(usize, Matrix)>>,
}

impl CentralizedScheme {
    /// `rate` in (0, 1]: the probability that each measurement is forwarded.
    pub fn new(system: Arc<System>, rate: f64) -> Result<Self, SchemeError> {
        if !(rate > 0.0 && rate <= 1.0) {
            return Err(SchemeError::Invalid {
                field: "rate",
                message: format!("expected a rate in (0, 1], got {rate}"),
            });
        }
        // The coin u is in [0, 1): at rate >= 1 every measurement is forwarded.
        let all_data = rate >= 1.0 && system.sensors.iter().all(|s| s.as_linear().is_some());
        let schedule = all_data.then(|| Arc::new(AllDataSchedule::new()));
        let linear = system
            .sensors
            .iter()
            .map(|s| s.as_linear().map(|l| (s.meas_dim(), l.ht_rinv().clone())))
            .collect();
        Ok(Self {
            system,
            rate,
            schedule,
            linear,
        })
    }
}

impl CentralizedScheme {
    /// Whether the fast trials take `measurements`: linear sensors, a measurement of the
    /// sensor's dimension per sensor and step, all finite as they arrive ([`as_sent`]; the
    /// generic center rejects one that is not).
    fn covers(&self, measurements: &[Vec<Vector>], steps: usize) -> bool {
        let Some(linear) = &self.linear else {
            return false;
        };
        if measurements.len() < steps {
            return false;
        }
        // Plain loops: this runs over every measurement of every trial.
        for zs in &measurements[..steps] {
            if zs.len() != linear.len() {
                return false;
            }
            for (z, (m, _)) in zs.iter().zip(linear) {
                if z.len() != *m {
                    return false;
                }
                for &v in z.as_slice() {
                    if !as_sent(v).is_finite() {
                        return false;
                    }
                }
            }
        }
        true
    }
}

impl LockstepFastPath for CentralizedScheme {
    /// The all-data KF (rate 1, linear sensors) runs several trials in lockstep.
    fn batches(&self) -> bool {
        self.schedule.is_some()
    }

    fn run_batch_fast(
        &self,
        trials: &[&[Vec<Vector>]],
        steps: usize,
        cache: &mut TrialCache,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        let schedule = self.schedule.as_ref()?;
        let linear = self.linear.as_ref()?;
        if !trials.iter().all(|m| self.covers(m, steps)) {
            return None;
        }
        let sys = &self.system;
        let est = cache.scratch((Arc::as_ptr(schedule) as usize, 0), || sys.prior.clone());
        let all = AllData {
            sys,
            linear,
            schedule,
            est,
        };
        all.batch_any(trials, steps, sink)
    }

    /// The all-data KF (rate 1, linear scalar sensors, state dimensions 1..=6) on a block drawn
    /// side by side: the batch's operations on the four trials' lanes.
    fn quads(&self) -> bool {
        self.schedule.is_some()
    }

    fn run_quad_fast(
        &self,
        block: &mut dyn QuadBlock,
        steps: usize,
    ) -> Option<Result<(), FastTrialError>> {
        self.schedule.as_ref()?;
        let linear = self.linear.as_ref()?;
        let (n, sensors) = block.shape();
        if sensors != linear.len()
            || linear.iter().any(|(m, _)| *m != 1)
            || n != self.system.state_dim()
        {
            return None;
        }
        match n {
            1 => self.quad_steps::<1>(block, steps),
            2 => self.quad_steps::<2>(block, steps),
            3 => self.quad_steps::<3>(block, steps),
            4 => self.quad_steps::<4>(block, steps),
            5 => self.quad_steps::<5>(block, steps),
            6 => self.quad_steps::<6>(block, steps),
            _ => None,
        }
    }

    /// The generic loop's [`ForwardingSensor`] coins and [`CentralizedKf`] steps without the
    /// messages, boxes and inbox: linear sensors and well-formed data only.
    ///
    /// On a lossy link a lost measurement is one that did not arrive, as for the coins; a
    /// trial in which no packet is lost runs as on an ideal link.
    fn run_trial_fast(
        &self,
        measurements: &[Vec<Vector>],
        steps: usize,
        losses: Option<&Losses>,
        coins: &mut [Xoshiro256PlusPlus],
        cache: &mut TrialCache,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        let losses = losses.filter(|l| l.any(steps));
        let sys = &self.system;
        let ns = sys.n_sensors();
        let linear = self.linear.as_ref()?;
        if !self.covers(measurements, steps) {
            return None;
        }
        if let (Some(schedule), None) = (&self.schedule, losses) {
            // The estimate handed to the sink, kept from trial to trial.
            let est = cache.scratch((Arc::as_ptr(schedule) as usize, 0), || sys.prior.clone());
            let all = AllData {
                sys,
                linear,
                schedule,
                est,
            };
            // State dimensions 1..=6 while the shared covariance schedule holds: the mean
            // recursion on the stack.
            // One trial is a batch of one.
            let trials = &[measurements][..];
            let fixed = all.batch_any(trials, steps, sink);
            if fixed.is_some() {
                return fixed;
            }
        }
        let mut center = match &self.schedule {
            Some(s) => CentralizedKf::with_schedule(sys.clone(), s.clone()),
            None => CentralizedKf::new(sys.clone()),
        };
        // What network::deliver counts for each sensor's message.
        let cost: Vec<(u64, u64)> = sys
            .sensors
            .iter()
            .map(|s| {
                let m = Message::Measurement(Vector::zeros(s.meas_dim()));
                (m.bits(), m.frame_bits())
            })
            .collect();
        // Per sensor: its measurement of this step as it arrives ([`as_sent`]), and whether
        // it arrived.
        let mut sent: Vec<Vector> = linear.iter().map(|(m, _)| Vector::zeros(*m)).collect();
        let mut arrives = vec![false; ns];
        let mut run = || -> Result<(), FastTrialError> {
            for (k, zs) in (1..=steps).zip(measurements) {
                let mut traffic = crate::network::Traffic {
                    scheduled: crate::network::all_sensors(ns),
                    ..Default::default()
                };
                for (i, ((z, (bits, frame_bits)), rng)) in
                    zs.iter().zip(&cost).zip(coins.iter_mut()).enumerate()
                {
                    // ForwardingSensor::step: always draw, send if u < rate.
                    let u: f64 = rng.random();
                    if u < self.rate {
                        traffic.senders |= crate::network::sensor_bit(i);
                        traffic.messages += 1;
                        traffic.bits += bits;
                        traffic.frame_bits += frame_bits;
                        // The link layer: a lost packet is a silence, counted.
                        arrives[i] = !losses.is_some_and(|l| l.lost(i, k));
                        if arrives[i] {
                            sent[i].copy_from(z);
                            round_as_sent(sent[i].as_mut_slice());
                        } else {
                            traffic.lost += 1;
                        }
                    } else {
                        arrives[i] = false;
                    }
                }
                let arrived: Vec<Option<&Vector>> = sent
                    .iter()
                    .zip(&arrives)
                    .map(|(z, &a)| a.then_some(z))
                    .collect();
                center
                    .step_linear(&arrived)
                    .map_err(|source| FastTrialError::Scheme { k, source })?;
                sink.step(0, k, center.estimate(), None, traffic)
                    .map_err(|source| FastTrialError::Sink { k, source })?;
            }
            Ok(())
        };
        Some(run())
    }
}

impl Scheme for CentralizedScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        Ok(SchemeInstance {
            sensors: (0..self.system.n_sensors())
                .map(|_| Box::new(ForwardingSensor::new(self.rate)) as Box<dyn SensorNode>)
                .collect(),
            center: Box::new(match &self.schedule {
                Some(s) => CentralizedKf::with_schedule(self.system.clone(), s.clone()),
                None => CentralizedKf::new(self.system.clone()),
            }),
        })
    }

    /// Raw measurements of linear sensors: a relay may add their information up.
    fn aggregable(&self) -> bool {
        self.system.sensors.iter().all(|s| s.as_linear().is_some())
    }

    /// The all-data KF's lockstep trials and the forwarding sensors' coins without the loop.
    fn fast_path(&self) -> Option<&dyn LockstepFastPath> {
        Some(self)
    }
}

#[cfg(test)]
mod tests;
