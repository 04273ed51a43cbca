//! The fusion center of Geng et al.: the p remote local Tobit KFs (Theorem 1, eq. (18)-(25)), the
//! federated fusion (Theorem 2, eq. (26)) and the reset (27), with the zero-order hold and the
//! detection device (6) at its input.
use crate::filter::tobit::{self, Thresholds, TobitOptions};
use crate::filter::{kf, Gaussian};
use crate::linalg::fixed;
use crate::linalg::{spd_inverse_into, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::LinearTransition;
use crate::network::Schedule;
use crate::scheme::{FusionCenter, SchemeError, System};
use std::sync::Arc;

/// What the fusion center reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fusion {
    /// Theorem 2: federated fusion (26) of all local filters, reset (27) each step (FTKF-DB).
    Federated,
    /// One local filter alone (0-based sensor index): `epsilon = 1`, no reset, no fusion —
    /// the paper's LTKF-DB-S1/S2 "based on partial sensor observations".
    Local(usize),
    /// One local filter inside the federated loop (0-based): its estimate (20)-(21) before
    /// fusion, started each step from the reset (27).
    LocalInLoop(usize),
}

/// The bias-blind FTKF (the paper's "FTKF"): the filter runs on the states `x` only; the bias
/// states get their open-loop prior (mean `H^k b_0`, covariance propagated with `H`, `Xi`).
#[derive(Debug, Clone)]
pub struct BiasBlind {
    x_idx: Vec<usize>,
    b_idx: Vec<usize>,
    b_transition: LinearTransition,
    b_prior: Gaussian,
}

/// The validated, data-independent part of the scheme.
#[derive(Debug, Clone)]
pub struct FtkfModel {
    /// The filter's model: the augmented `(F, Q)`, or `(A, Q_x)` for the bias-blind FTKF.
    pub transition: LinearTransition,
    /// Per sensor: `C_m` (1 x n of the filter state), `R_m` as the filter uses it, thresholds.
    pub sensors: Vec<(Matrix, f64, Thresholds)>,
    /// Information-sharing coefficients `epsilon_m` (sum 1).
    pub sharing: Vec<f64>,
    pub fusion: Fusion,
    pub opts: TobitOptions,
    /// The filter's prior (of the filter state).
    pub prior: Gaussian,
    pub bias_blind: Option<BiasBlind>,
    /// Which sensors send at a step: Geng et al.'s round-robin (4)-(5) by default, or one
    /// granting more (or fewer) sensors per step (`granted`, [`super::granted_schedule`]).
    pub schedule: Schedule,
    full_dim: usize,
}

fn sub(m: &Matrix, rows: &[usize], cols: &[usize]) -> Matrix {
    Matrix::from_fn(rows.len(), cols.len(), |i, j| m[(rows[i], cols[j])])
}

impl FtkfModel {
    /// Validates and builds. `sensors` are `(C_m, R_m)` on the full state.
    pub fn new(
        system: &System,
        sensors: Vec<(Matrix, f64)>,
        thresholds: Vec<Thresholds>,
        sharing: Option<Vec<f64>>,
        fusion: Fusion,
        bias_blind: Option<Vec<usize>>,
        opts: TobitOptions,
    ) -> Result<Self, SchemeError> {
        let p = sensors.len();
        let n = system.state_dim();
        if thresholds.len() != p {
            return Err(SchemeError::Invalid {
                field: "tau_l",
                message: format!(
                    "expected {p} thresholds (one per sensor), got {}",
                    thresholds.len()
                ),
            });
        }
        let sharing = sharing.unwrap_or_else(|| vec![1.0 / p as f64; p]);
        if sharing.len() != p
            || sharing.iter().any(|e| !(e.is_finite() && *e > 0.0))
            || (sharing.iter().sum::<f64>() - 1.0).abs() > 1e-9
        {
            return Err(SchemeError::Invalid {
                field: "sharing",
                message: format!(
                    "expected {p} positive coefficients summing to 1 (Lemma 2), got {sharing:?}"
                ),
            });
        }
        if let Fusion::Local(m) | Fusion::LocalInLoop(m) = fusion {
            if m >= p {
                return Err(SchemeError::Invalid {
                    field: "local",
                    message: format!("expected a sensor number in 1..={p}, got {}", m + 1),
                });
            }
        }
        let (transition, sensors, prior, bias_blind) = match bias_blind {
            None => (
                system.transition.clone(),
                sensors,
                system.prior.clone(),
                None,
            ),
            Some(b_idx) => {
                let mut seen = vec![false; n];
                for &b in &b_idx {
                    if b >= n || seen[b] {
                        return Err(SchemeError::Invalid {
                            field: "bias_states",
                            message: format!(
                                "expected distinct state indices below {n}, got {b_idx:?}"
                            ),
                        });
                    }
                    seen[b] = true;
                }
                let x_idx: Vec<usize> = (0..n).filter(|i| !seen[*i]).collect();
                if x_idx.is_empty() || b_idx.is_empty() {
                    return Err(SchemeError::Invalid {
                        field: "bias_states",
                        message: "the bias must be some, not all, of the states".into(),
                    });
                }
                let f = system.transition.f();
                let q = system.transition.q();
                if sub(f, &b_idx, &x_idx).amax() > 0.0 {
                    return Err(SchemeError::Invalid {
                        field: "bias_states",
                        message: "the bias must evolve on its own (F[b, x] = 0, eq. (3))".into(),
                    });
                }
                let tx = LinearTransition::new(sub(f, &x_idx, &x_idx), sub(q, &x_idx, &x_idx))
                    .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                let tb = LinearTransition::new(sub(f, &b_idx, &b_idx), sub(q, &b_idx, &b_idx))
                    .map_err(|e| SchemeError::Unsupported(e.to_string()))?;
                let pick = |v: &Vector, idx: &[usize]| Vector::from_fn(idx.len(), |i, _| v[idx[i]]);
                let prior = Gaussian::new(
                    pick(&system.prior.mean, &x_idx),
                    sub(&system.prior.cov, &x_idx, &x_idx),
                );
                let b_prior = Gaussian::new(
                    pick(&system.prior.mean, &b_idx),
                    sub(&system.prior.cov, &b_idx, &b_idx),
                );
                let sensors = sensors
                    .into_iter()
                    .map(|(h, r)| (sub(&h, &[0], &x_idx), r))
                    .collect();
                (
                    tx,
                    sensors,
                    prior,
                    Some(BiasBlind {
                        x_idx,
                        b_idx,
                        b_transition: tb,
                        b_prior,
                    }),
                )
            }
        };
        Ok(Self {
            transition,
            sensors: sensors
                .into_iter()
                .zip(thresholds)
                .map(|((h, r), t)| (h, r, t))
                .collect(),
            sharing,
            fusion,
            opts,
            prior,
            bias_blind,
            schedule: Schedule::RoundRobin,
            full_dim: n,
        })
    }

    /// Number of sensors p.
    pub fn n_sensors(&self) -> usize {
        self.sensors.len()
    }
}

/// One local filter's step, as recorded for the Theorem 4 bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalRecord {
    /// Whether the sensor was scheduled (`Gamma_{m, h_k} = 1`) and its reading arrived.
    pub scheduled: bool,
    /// Censoring probabilities (9) of what the estimator holds (zero while the hold is empty).
    pub alpha: f64,
    pub beta: f64,
    /// The left theta of (14)-(15) (`/ R` under the printed `theta_denominator`).
    pub theta_l: f64,
    /// The local prediction covariance `P^-_{m,k}` (19).
    pub pred_cov: Matrix,
}

/// Per-trial state of the fusion center, with the buffers every step works in (allocated
/// once, so a step allocates nothing).
#[derive(Debug, Clone)]
pub struct FtkfCenter {
    model: Arc<FtkfModel>,
    /// Per sensor: the fresh reading of this step if the sensor was scheduled (the zero-order
    /// hold's value counts as fresh only on the step it arrived; a held value carries no new
    /// information and enters only through `last_post`).
    fresh: Vec<Option<f64>>,
    /// The fused estimate (Federated / LocalInLoop) or the lone local's (Local).
    fused: Gaussian,
    /// The common prediction (18)-(19) of the fused estimate.
    pred: Gaussian,
    /// The local filters of the federated loop, each reset (27) and updated in place.
    locals: Vec<Gaussian>,
    /// Per local filter: its filtered mean at the step its held value was measured (`None`
    /// before its first reading), in a buffer allocated once.
    last_post: Vec<LastPost>,
    bias: Option<Gaussian>,
    /// The bias's next prediction (swapped with `bias`).
    bias_next: Option<Gaussian>,
    out: Gaussian,
    work: CenterWork,
    /// `Some` when recording: per step, per local filter.
    pub records: Option<Vec<Vec<LocalRecord>>>,
    /// When recording: the fused prediction covariance per step.
    pub fused_pred: Vec<Matrix>,
}

/// A local filter's filtered mean at its last reading, if it has had one.
#[derive(Debug, Clone)]
struct LastPost {
    seen: bool,
    mean: Vector,
}

/// Scratch buffers of [`FtkfCenter`]'s step.
#[derive(Debug, Clone)]
struct CenterWork {
    predict: kf::PredictWork,
    bias_predict: Option<kf::PredictWork>,
    update: tobit::UpdateWork,
    fusion: FusionWork,
    /// `C_m xi` (1) of a held reading.
    zeta: Vector,
}

impl FtkfCenter {
    /// A fresh center; `record` keeps what the Theorem 4-5 bounds need.
    pub fn new(model: Arc<FtkfModel>, record: bool) -> Self {
        let p = model.n_sensors();
        let fused = model.prior.clone();
        let n = fused.dim();
        let bias = model.bias_blind.as_ref().map(|b| b.b_prior.clone());
        let work = CenterWork {
            predict: kf::PredictWork::new(n),
            bias_predict: bias.as_ref().map(|b| kf::PredictWork::new(b.dim())),
            update: tobit::UpdateWork::new(n),
            fusion: FusionWork::new(n),
            zeta: Vector::zeros(1),
        };
        let mut out = Gaussian::new(
            Vector::zeros(model.full_dim),
            Matrix::zeros(model.full_dim, model.full_dim),
        );
        full_output_into(&model, bias.as_ref(), &fused, &mut out);
        let locals = match model.fusion {
            Fusion::Local(_) => Vec::new(),
            Fusion::Federated | Fusion::LocalInLoop(_) => vec![fused.clone(); p],
        };
        Self {
            fresh: vec![None; p],
            pred: fused.clone(),
            locals,
            fused,
            last_post: vec![
                LastPost {
                    seen: false,
                    mean: Vector::zeros(n)
                };
                p
            ],
            bias_next: bias.clone(),
            bias,
            out,
            work,
            records: record.then(Vec::new),
            fused_pred: Vec::new(),
            model,
        }
    }
}

/// The estimate on the full state into `out` (the bias-blind filter's x with the bias's
/// open-loop prior beside it; zero cross-covariance).
fn full_output_into(
    model: &FtkfModel,
    bias: Option<&Gaussian>,
    est: &Gaussian,
    out: &mut Gaussian,
) {
    match (&model.bias_blind, bias) {
        (Some(bb), Some(b)) => {
            out.mean.fill(0.0);
            out.cov.fill(0.0);
            for (i, &xi) in bb.x_idx.iter().enumerate() {
                out.mean[xi] = est.mean[i];
                for (j, &xj) in bb.x_idx.iter().enumerate() {
                    out.cov[(xi, xj)] = est.cov[(i, j)];
                }
            }
            for (i, &bi) in bb.b_idx.iter().enumerate() {
                out.mean[bi] = b.mean[i];
                for (j, &bj) in bb.b_idx.iter().enumerate() {
                    out.cov[(bi, bj)] = b.cov[(i, j)];
                }
            }
        }
        _ => {
            out.mean.copy_from(&est.mean);
            out.cov.copy_from(&est.cov);
        }
    }
}

/// Local filter `m` from its prediction `est`, in place: the Tobit update (20)-(25) if its
/// sensor was scheduled and its reading arrived, else the prediction itself (K = 0 by (24)).
#[allow(clippy::too_many_arguments)]
fn local_step(
    model: &FtkfModel,
    m: usize,
    est: &mut Gaussian,
    fresh: Option<f64>,
    last_post: &mut [LastPost],
    records: Option<&mut Vec<Vec<LocalRecord>>>,
    update: &mut tobit::UpdateWork,
    zeta: &mut Vector,
) -> Result<(), SchemeError> {
    let (h, r, thr) = &model.sensors[m];
    let opts = model.opts;
    // The record keeps the prediction, which the update overwrites (only when recording).
    let pred_cov = records.is_some().then(|| est.cov.clone());
    let (alpha, beta, theta_l) = match fresh {
        Some(ybar) => {
            let y = thr.censor(ybar); // detection device (6)
            let t = tobit::update_in_place(est, h, *r, y, 0.0, thr, &opts, update)?;
            last_post[m].seen = true;
            last_post[m].mean.copy_from(&est.mean);
            (t.alpha, t.beta, t.theta_l)
        }
        None => match &last_post[m] {
            LastPost { seen: true, mean } => {
                fixed::gemv(zeta, h, mean);
                let t = tobit::terms(zeta[0], *r, thr, &opts);
                (t.alpha, t.beta, t.theta_l)
            }
            LastPost { seen: false, .. } => (0.0, 0.0, f64::NEG_INFINITY),
        },
    };
    if let Some(rec) = records.and_then(|r| r.last_mut()) {
        rec.push(LocalRecord {
            scheduled: fresh.is_some(),
            alpha,
            beta,
            theta_l,
            pred_cov: pred_cov.expect("recording"),
        });
    }
    Ok(())
}

/// Buffers of [`federated_fusion_into`] for an n-dimensional state.
#[derive(Debug, Clone)]
pub struct FusionWork {
    /// `sum P_m^{-1}` and `sum P_m^{-1} xi_m`.
    info: Matrix,
    vec: Vector,
    /// One `P_m^{-1}`, its Cholesky factor's storage, and `P_m^{-1} xi_m`.
    inv: Matrix,
    factor: Matrix,
    tmp: Vector,
}

impl FusionWork {
    /// Buffers for an n-dimensional state.
    pub fn new(n: usize) -> Self {
        Self {
            info: Matrix::zeros(n, n),
            vec: Vector::zeros(n),
            inv: Matrix::zeros(n, n),
            factor: Matrix::zeros(n, n),
            tmp: Vector::zeros(n),
        }
    }
}

/// Federated fusion (26): `P = (sum P_m^{-1})^{-1}`, `xi = P sum P_m^{-1} xi_m`.
pub fn federated_fusion(locals: &[Gaussian]) -> Result<Gaussian, SchemeError> {
    let n = locals[0].dim();
    let mut out = Gaussian::new(Vector::zeros(n), Matrix::zeros(n, n));
    federated_fusion_into(locals, &mut out, &mut FusionWork::new(n))?;
    Ok(out)
}

/// [`federated_fusion`] into `out` through `work`: the sums from zero, the inverses by
/// [`crate::linalg::spd_inverse_into`] (the factorization and solves of `spd_inverse`) and
/// the products by [`fixed::gemv`] (nalgebra's), without allocating.
pub fn federated_fusion_into(
    locals: &[Gaussian],
    out: &mut Gaussian,
    work: &mut FusionWork,
) -> Result<(), SchemeError> {
    let w = work;
    w.info.fill(0.0);
    w.vec.fill(0.0);
    for l in locals {
        spd_inverse_into(&l.cov, &mut w.inv, &mut w.factor).map_err(|source| {
            SchemeError::Matrix {
                what: "local covariance in the federated fusion (26)",
                source,
            }
        })?;
        fixed::gemv(&mut w.tmp, &w.inv, &l.mean);
        fixed::add_assign(w.vec.as_mut_slice(), w.tmp.as_slice());
        fixed::add_assign(w.info.as_mut_slice(), w.inv.as_slice());
    }
    spd_inverse_into(&w.info, &mut out.cov, &mut w.factor).map_err(|source| {
        SchemeError::Matrix {
            what: "fused information matrix (26)",
            source,
        }
    })?;
    symmetrize(&mut out.cov);
    fixed::gemv(&mut out.mean, &out.cov, &w.vec);
    Ok(())
}

/// The reset (27) of a local filter from the fused estimate: `xi_m = xi`, `P_m = P / epsilon_m`.
pub fn reset(fused: &Gaussian, epsilon: f64) -> Gaussian {
    Gaussian::new(fused.mean.clone(), &fused.cov / epsilon)
}

/// [`reset`] into `out` (the same divisions, entry by entry).
pub fn reset_into(fused: &Gaussian, epsilon: f64, out: &mut Gaussian) {
    out.mean.copy_from(&fused.mean);
    for (o, p) in out.cov.iter_mut().zip(fused.cov.iter()) {
        *o = p / epsilon;
    }
}

impl FusionCenter for FtkfCenter {
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        let p = self.model.n_sensors();
        if inbox.len() != p {
            return Err(SchemeError::Unsupported(format!(
                "expected {p} inbox entries, got {}",
                inbox.len()
            )));
        }
        // The zero-order hold (4): a reading is fresh on the step it arrived; only a fresh,
        // scheduled reading (Gamma_{m, h_k} = 1 of (4)-(5), or one of the `granted` slots)
        // updates a local filter.
        let schedule = self.model.schedule;
        for (i, (f, r)) in self.fresh.iter_mut().zip(inbox).enumerate() {
            *f = match r {
                Received::Measurement(z) if schedule.allows(k, i, p) => Some(z[0]),
                _ => None,
            };
        }
        let model = &*self.model;
        let w = &mut self.work;
        // Common prediction of the fused estimate: P^- = F P F^T + Q; the locals' (19) after the
        // reset (27) are (F xi, P^- / epsilon_m) since Q_m = Q / epsilon_m.
        kf::predict_into(
            &model.transition,
            &self.fused,
            &mut self.pred,
            &mut w.predict,
        );
        if let Some(r) = self.records.as_mut() {
            r.push(Vec::with_capacity(p));
            self.fused_pred.push(self.pred.cov.clone());
        }
        let report = match model.fusion {
            Fusion::Local(m) => {
                local_step(
                    model,
                    m,
                    &mut self.pred,
                    self.fresh[m],
                    &mut self.last_post,
                    self.records.as_mut(),
                    &mut w.update,
                    &mut w.zeta,
                )?;
                std::mem::swap(&mut self.fused, &mut self.pred);
                None
            }
            Fusion::Federated | Fusion::LocalInLoop(_) => {
                for (m, (&eps, &y)) in model.sharing.iter().zip(&self.fresh).enumerate() {
                    let local = &mut self.locals[m];
                    reset_into(&self.pred, eps, local);
                    local_step(
                        model,
                        m,
                        local,
                        y,
                        &mut self.last_post,
                        self.records.as_mut(),
                        &mut w.update,
                        &mut w.zeta,
                    )?;
                }
                federated_fusion_into(&self.locals, &mut self.fused, &mut w.fusion)?;
                // LocalInLoop reports local m; the loop continues from the fused estimate.
                match model.fusion {
                    Fusion::LocalInLoop(m) => Some(m),
                    _ => None,
                }
            }
        };
        if let (Some(bb), Some(b), Some(next), Some(pw)) = (
            &model.bias_blind,
            &mut self.bias,
            &mut self.bias_next,
            &mut w.bias_predict,
        ) {
            kf::predict_into(&bb.b_transition, b, next, pw);
            std::mem::swap(b, next);
        }
        let est = report.map_or(&self.fused, |m| &self.locals[m]);
        full_output_into(model, self.bias.as_ref(), est, &mut self.out);
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.out
    }
}
