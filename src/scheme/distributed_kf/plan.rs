//! The data-independent part of the globalized distributed KF (Dormann et al.): the globalized
//! covariances, the matrices that turn a globalized prediction and a measurement into the
//! globalized estimate, the debiasing matrices (eq. (14)) and the gains of the standard KF each
//! sensor runs beside the globalized one. None of them depends on measurements, so sensors and
//! fusion center compute them identically; we compute them once and share them.
use crate::linalg::{relative_difference, spd_inverse, symmetrize, Matrix};
use crate::scheme::{SchemeError, System};
use std::sync::{Arc, Mutex, OnceLock, Weak};

/// Matrices of one time step k.
#[derive(Debug, Clone)]
pub struct StepMatrices {
    /// Globalized predicted covariance C̄^p_k = A C̄^e_{k-1} A^T + N C^w (eq. (2)).
    pub cbar_p: Matrix,
    /// (C̄^p_k)^{-1}.
    pub cbar_p_inv: Matrix,
    /// Globalized filtered covariance C̄^e_k = ((C̄^p_k)^{-1} + 1/N Σ_i H_i^T R_i^{-1} H_i)^{-1}.
    pub cbar_e: Matrix,
    /// (C̄^e_k)^{-1}.
    pub cbar_e_inv: Matrix,
    /// C̄^e_k (C̄^p_k)^{-1}: multiplies the globalized prediction in the local filtering step.
    pub prediction_weight: Matrix,
    /// Per sensor: C̄^e_k H_i^T R_i^{-1}, multiplies z_k^i in the local filtering step.
    pub measurement_weight: Vec<Matrix>,
    /// Per sensor: debiasing matrix after prediction, Δ^{p,i}_k = A Δ^{e,i}_{k-1} A^{-1} (14).
    pub delta_p: Vec<Matrix>,
    /// Per sensor: debiasing matrix after filtering,
    /// Δ^{e,i}_k = C̄^e_k (C̄^p_k)^{-1} Δ^{p,i}_k + C̄^e_k H_i^T R_i^{-1} H_i (Section IV).
    pub delta_e: Vec<Matrix>,
    /// Per sensor: gain K^i_k of the standard (non-globalized) local KF, used by the event
    /// tests (12) and (13).
    pub kf_gain: Vec<Matrix>,
    /// Per sensor: filtered covariance of the standard local KF.
    pub kf_cov: Vec<Matrix>,
}

/// The precomputed recursion for steps 0..=horizon. When every recursion has converged before
/// the horizon (relative change below 1e-14), later steps reuse the converged matrices, so a
/// deployment can run for ever.
#[derive(Debug, Clone)]
pub struct GlobalizedPlan {
    steps: Vec<StepMatrices>,
    converged: bool,
    /// A, A^{-1}.
    a: Matrix,
    a_inv: Option<Matrix>,
    n_sensors: usize,
    /// Predicted debiasing matrices, filled on demand (see [`GlobalizedPlan::delta_head`]).
    deltas: Arc<DeltaMemo>,
    /// Covariances of the globalized estimates' debiased errors, for the center's treatment
    /// of estimates missing twice in a row ([`super::loss`]), filled on demand.
    loss: Arc<EpsilonTable>,
}

/// Δ^{pp,i} = A^j Δ^{e,i}_s A^{-j}: sensor i's debiasing matrix sent at step s, predicted j
/// times (Section IV), with its LU factors for the debiased extrapolation. It depends on
/// (i, s, j) only, never on measurements, so it is computed once and shared by the sensor, its
/// replica in the fusion center, every trial and every variant that shares the plan. It is
/// computed by exactly the products the per-trial recursion `Δ <- A Δ A^{-1}` performs, so the
/// numbers are the same bit for bit. The predictions of one Δ^{e,i}_s form a chain: a holder
/// steps to [`PredictedDelta::next`] each step (a lock-free read once computed).
#[derive(Debug)]
pub struct PredictedDelta {
    /// Δ^{pp,i}, until the next link is made from it: then only the factors are needed, and
    /// a long sweep keeps thousands of links (`dormann-fig1`: 2 MB of matrices otherwise).
    delta: Mutex<Option<Matrix>>,
    /// Its LU factorization (as `Δ.clone().lu()`), ready for the fixed-size solve.
    pub lu: crate::linalg::fixed::PackedLu,
    next: OnceLock<Arc<PredictedDelta>>,
}

impl PredictedDelta {
    fn new(delta: Matrix) -> Self {
        let lu = crate::linalg::fixed::PackedLu::from_packed(delta.clone().lu());
        Self {
            delta: Mutex::new(Some(delta)),
            lu,
            next: OnceLock::new(),
        }
    }

    /// A Δ A^{-1}: the matrix one step later, computed on first use. `plan` must be the plan
    /// this matrix came from (its A is invertible, or there would be no chain).
    pub fn next(&self, plan: &GlobalizedPlan) -> Arc<PredictedDelta> {
        self.next
            .get_or_init(|| {
                let a_inv = plan
                    .a_inv
                    .as_ref()
                    .expect("a chain exists only for invertible A");
                let delta = self
                    .delta
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .take()
                    .expect("the next link is made once, from the matrix");
                Arc::new(Self::new(predict_delta(&plan.a, &delta, a_inv)))
            })
            .clone()
    }
}

/// (A Δ) A^{-1} as `&a * &delta * a_inv` computes it, in the fixed-size gemm (the same
/// operations as nalgebra's product, bit for bit).
fn predict_delta(a: &Matrix, delta: &Matrix, a_inv: &Matrix) -> Matrix {
    let product = |x: &Matrix, y: &Matrix| {
        let mut out = Matrix::zeros(x.nrows(), y.ncols());
        crate::linalg::fixed::gemm(&mut out, x, y);
        out
    };
    product(&product(a, delta), a_inv)
}

impl Drop for PredictedDelta {
    /// Unlinks the chain iteratively: a long silence makes a long chain, and the default
    /// recursive drop could exhaust the stack.
    fn drop(&mut self) {
        let mut next = self.next.take();
        while let Some(n) = next {
            next = match Arc::try_unwrap(n) {
                Ok(mut node) => node.next.take(),
                Err(_) => None,
            };
        }
    }
}

/// The head of each chain: sensor i's Δ^{e,i} of plan step p at index chain[i] * steps + p.
#[derive(Debug, Default)]
struct DeltaMemo {
    heads: Vec<OnceLock<Arc<PredictedDelta>>>,
    /// Per sensor: the first sensor whose Δ^{e} is bitwise its own at every plan step (the
    /// same H and R give the same recursion). Their chains are the same products of the same
    /// matrices, hence the same numbers, so they share one: `dormann-fig1`'s sensors come in
    /// identical pairs, and this halves the chains' memory (about 5 MB) and their making.
    chain: Vec<usize>,
}

impl GlobalizedPlan {
    /// Runs the recursion of Dormann et al., Section II (and the debiasing of Section IV when A is
    /// invertible) from the common prior: the initial local estimates all equal the prior
    /// (x_0, P_0), so C̄^e_0 = N P_0 and Δ^{e,i}_0 = I. Requires linear sensors.
    pub fn new(system: &System, horizon: usize) -> Result<Self, SchemeError> {
        let n = system.state_dim();
        let nf = system.n_sensors() as f64;
        let sensors = system
            .sensors
            .iter()
            .map(|s| {
                s.as_linear().ok_or_else(|| {
                    SchemeError::Unsupported(
                        "the distributed KF of Dormann et al. needs linear sensors".into(),
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let a = system.transition.f().clone();
        let q = system.transition.q();
        let a_inv = a.clone().try_inverse();
        let mut mean_info = Matrix::zeros(n, n);
        for s in &sensors {
            mean_info += s.information();
        }
        mean_info /= nf;

        let p0 = &system.prior.cov;
        let p0_inv = spd_inverse(p0).map_err(|source| SchemeError::Matrix {
            what: "prior covariance",
            source,
        })?;
        let identity = Matrix::identity(n, n);
        let init = StepMatrices {
            cbar_p: p0 * nf,
            cbar_p_inv: &p0_inv / nf,
            cbar_e: p0 * nf,
            cbar_e_inv: &p0_inv / nf,
            prediction_weight: identity.clone(),
            measurement_weight: vec![Matrix::zeros(n, 0); sensors.len()],
            delta_p: vec![identity.clone(); sensors.len()],
            delta_e: vec![identity.clone(); sensors.len()],
            kf_gain: vec![Matrix::zeros(n, 0); sensors.len()],
            kf_cov: vec![p0.clone(); sensors.len()],
        };
        let mut steps = vec![init];
        let mut converged = false;
        for _k in 1..=horizon {
            let prev = steps.last().expect("non-empty");
            let mut cbar_p = &a * &prev.cbar_e * a.transpose() + q * nf;
            symmetrize(&mut cbar_p);
            let cbar_p_inv = inv(&cbar_p, "globalized predicted covariance")?;
            let cbar_e_inv = &cbar_p_inv + &mean_info;
            let cbar_e = inv(&cbar_e_inv, "globalized filtered covariance")?;
            let prediction_weight = &cbar_e * &cbar_p_inv;
            let measurement_weight: Vec<Matrix> =
                sensors.iter().map(|s| &cbar_e * s.ht_rinv()).collect();
            let (delta_p, delta_e) = match &a_inv {
                Some(a_inv) => {
                    let dp: Vec<Matrix> = prev.delta_e.iter().map(|d| &a * d * a_inv).collect();
                    let de = dp
                        .iter()
                        .zip(&measurement_weight)
                        .zip(&sensors)
                        .map(|((dp, w), s)| &prediction_weight * dp + w * s.h())
                        .collect();
                    (dp, de)
                }
                None => (Vec::new(), Vec::new()),
            };
            let mut kf_gain = Vec::with_capacity(sensors.len());
            let mut kf_cov = Vec::with_capacity(sensors.len());
            for (s, p_prev) in sensors.iter().zip(&prev.kf_cov) {
                let mut pp = &a * p_prev * a.transpose() + q;
                symmetrize(&mut pp);
                let mut innov =
                    s.h() * &pp * s.h().transpose() + crate::model::MeasurementModel::noise_cov(*s);
                symmetrize(&mut innov);
                let innov_inv = inv(&innov, "local innovation covariance")?;
                let k = &pp * s.h().transpose() * innov_inv;
                let i_kh = Matrix::identity(n, n) - &k * s.h();
                let mut pe = &i_kh * &pp * i_kh.transpose()
                    + &k * crate::model::MeasurementModel::noise_cov(*s) * k.transpose();
                symmetrize(&mut pe);
                kf_gain.push(k);
                kf_cov.push(pe);
            }
            let next = StepMatrices {
                cbar_p,
                cbar_p_inv,
                cbar_e,
                cbar_e_inv,
                prediction_weight,
                measurement_weight,
                delta_p,
                delta_e,
                kf_gain,
                kf_cov,
            };
            let done = steps.len() > 2 && same(&next, steps.last().expect("non-empty"));
            steps.push(next);
            if done {
                converged = true;
                break;
            }
        }
        let bits = |m: &Matrix| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let chain = (0..sensors.len())
            .map(|i| {
                // (No Δ without A^{-1}: then every sensor is its own.)
                (0..i)
                    .find(|&j| {
                        a_inv.is_some()
                            && steps
                                .iter()
                                .all(|st| bits(&st.delta_e[i]) == bits(&st.delta_e[j]))
                    })
                    .unwrap_or(i)
            })
            .collect();
        let heads = if a_inv.is_some() {
            (0..sensors.len() * steps.len())
                .map(|_| OnceLock::new())
                .collect()
        } else {
            Vec::new()
        };
        let loss = EpsilonTable::new(
            q.clone(),
            sensors
                .iter()
                .map(|s| crate::model::MeasurementModel::noise_cov(*s).clone())
                .collect(),
            p0.clone(),
        );
        Ok(Self {
            steps,
            converged,
            a,
            a_inv,
            n_sensors: sensors.len(),
            deltas: Arc::new(DeltaMemo { heads, chain }),
            loss: Arc::new(loss),
        })
    }

    /// The plan of `system` for `horizon` steps, shared with every other caller that asked for
    /// the same system (same `Arc`) and horizon while that plan is alive. A sweep builds many
    /// variants of one system; the plan (and its memo of predicted debiasing matrices) depends
    /// on the system only, so one copy serves them all instead of one per variant.
    pub fn shared(system: &Arc<System>, horizon: usize) -> Result<Arc<Self>, SchemeError> {
        type Entry = (Weak<System>, usize, Weak<GlobalizedPlan>);
        static CACHE: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        cache.retain(|(s, _, p)| s.strong_count() > 0 && p.strong_count() > 0);
        for (s, h, p) in cache.iter() {
            if *h == horizon && s.upgrade().is_some_and(|s| Arc::ptr_eq(&s, system)) {
                if let Some(p) = p.upgrade() {
                    return Ok(p);
                }
            }
        }
        let plan = Arc::new(Self::new(system, horizon)?);
        cache.push((Arc::downgrade(system), horizon, Arc::downgrade(&plan)));
        Ok(plan)
    }

    /// Index into the precomputed steps of step k: k itself, or the converged last step.
    pub fn index(&self, k: usize) -> Result<usize, SchemeError> {
        if k < self.steps.len() {
            Ok(k)
        } else if self.converged {
            Ok(self.steps.len() - 1)
        } else {
            Err(SchemeError::HorizonExceeded {
                k,
                horizon: self.steps.len() - 1,
            })
        }
    }

    /// Sensor i's debiasing matrix Δ^{e,i} of plan step `p` (an [`GlobalizedPlan::index`]),
    /// the head of its chain of predictions ([`PredictedDelta::next`]). `None` when A is
    /// singular (no debiasing).
    pub fn delta_head(&self, i: usize, p: usize) -> Option<Arc<PredictedDelta>> {
        self.a_inv.as_ref()?;
        let head = &self.deltas.heads[self.deltas.chain[i] * self.steps.len() + p];
        Some(
            head.get_or_init(|| Arc::new(PredictedDelta::new(self.steps[p].delta_e[i].clone())))
                .clone(),
        )
    }

    /// Matrices of step k (k = 0 is the initialization).
    pub fn at(&self, k: usize) -> Result<&StepMatrices, SchemeError> {
        match self.steps.get(k) {
            Some(s) => Ok(s),
            None if self.converged => Ok(self.steps.last().expect("non-empty")),
            None => Err(SchemeError::HorizonExceeded {
                k,
                horizon: self.steps.len() - 1,
            }),
        }
    }

    /// The system matrix A.
    pub fn a(&self) -> &Matrix {
        &self.a
    }

    /// A^{-1}, needed by the debiasing of Algorithm 2; `None` when A is singular.
    pub fn a_inv(&self) -> Option<&Matrix> {
        self.a_inv.as_ref()
    }

    /// The table of the loss fallback ([`super::loss`]).
    pub(super) fn loss_table(&self) -> &EpsilonTable {
        &self.loss
    }

    /// Number of sensors N.
    pub fn n_sensors(&self) -> usize {
        self.n_sensors
    }

    /// How many distinct plan steps there are: every [`GlobalizedPlan::index`] is below it.
    pub fn step_count(&self) -> usize {
        self.steps.len()
    }

    /// Whether the recursion converged before the horizon.
    pub fn converged(&self) -> bool {
        self.converged
    }
}

fn inv(m: &Matrix, what: &'static str) -> Result<Matrix, SchemeError> {
    spd_inverse(m).map_err(|source| SchemeError::Matrix { what, source })
}

fn same(a: &StepMatrices, b: &StepMatrices) -> bool {
    const TOL: f64 = 1e-14;
    relative_difference(&a.cbar_e, &b.cbar_e) < TOL
        && a.delta_e
            .iter()
            .zip(&b.delta_e)
            .all(|(x, y)| relative_difference(x, y) < TOL)
        && a.kf_cov
            .iter()
            .zip(&b.kf_cov)
            .all(|(x, y)| relative_difference(x, y) < TOL)
}

/// Cov ε^i_t per sensor and step (the memo of the loss fallback's recursion, which fills it in
/// [`super::loss`]; it lives here, with the plan it belongs to), filled on demand and shared by every center of the plan
/// (it depends on the plan, Q, R_i and P_0 only). A sensor's list stops growing once the
/// recursion has converged (relative change below 1e-14); later steps use its last entry.
#[derive(Debug)]
pub(super) struct EpsilonTable {
    pub(super) q: Matrix,
    pub(super) r: Vec<Matrix>,
    pub(super) p0: Matrix,
    pub(super) per_sensor: Mutex<Vec<SensorEpsilon>>,
}

#[derive(Debug, Default)]
pub(super) struct SensorEpsilon {
    pub(super) covs: Vec<Matrix>,
    pub(super) converged: bool,
}

impl EpsilonTable {
    pub fn new(q: Matrix, r: Vec<Matrix>, p0: Matrix) -> Self {
        let per_sensor = Mutex::new((0..r.len()).map(|_| SensorEpsilon::default()).collect());
        Self {
            q,
            r,
            p0,
            per_sensor,
        }
    }
}
