//! The fusion center of seed 002: the p remote local Tobit KFs (Theorem 1, eq. (18)-(25)), the
//! federated fusion (Theorem 2, eq. (26)) and the reset (27), with the zero-order hold and the
//! detection device (6) at its input.
use crate::filter::tobit::{self, Thresholds, TobitOptions};
use crate::filter::{kf, Gaussian};
use crate::linalg::{spd_inverse, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::LinearTransition;
use crate::network::{Schedule, ZeroOrderHold};
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
    pub theta_l: f64,
    /// The local prediction covariance `P^-_{m,k}` (19).
    pub pred_cov: Matrix,
}

/// Per-trial state of the fusion center.
#[derive(Debug, Clone)]
pub struct FtkfCenter {
    model: Arc<FtkfModel>,
    hold: ZeroOrderHold,
    /// The fused estimate (Federated / LocalInLoop) or the lone local's (Local).
    fused: Gaussian,
    /// Per local filter: its filtered mean at the step its held value was measured.
    last_post: Vec<Option<Vector>>,
    bias: Option<Gaussian>,
    out: Gaussian,
    /// `Some` when recording: per step, per local filter.
    pub records: Option<Vec<Vec<LocalRecord>>>,
    /// When recording: the fused prediction covariance per step.
    pub fused_pred: Vec<Matrix>,
}

impl FtkfCenter {
    /// A fresh center; `record` keeps what the Theorem 4-5 bounds need.
    pub fn new(model: Arc<FtkfModel>, record: bool) -> Self {
        let p = model.n_sensors();
        let fused = model.prior.clone();
        let bias = model.bias_blind.as_ref().map(|b| b.b_prior.clone());
        let mut c = Self {
            hold: ZeroOrderHold::new(p),
            last_post: vec![None; p],
            out: fused.clone(),
            fused,
            bias,
            records: record.then(Vec::new),
            fused_pred: Vec::new(),
            model,
        };
        c.out = c.full_output(&c.fused);
        c
    }

    /// The estimate on the full state (the bias-blind filter's x with the bias's open-loop
    /// prior beside it).
    fn full_output(&self, est: &Gaussian) -> Gaussian {
        match (&self.model.bias_blind, &self.bias) {
            (Some(bb), Some(b)) => {
                let n = self.model.full_dim;
                let mut mean = Vector::zeros(n);
                let mut cov = Matrix::zeros(n, n);
                for (i, &xi) in bb.x_idx.iter().enumerate() {
                    mean[xi] = est.mean[i];
                    for (j, &xj) in bb.x_idx.iter().enumerate() {
                        cov[(xi, xj)] = est.cov[(i, j)];
                    }
                }
                for (i, &bi) in bb.b_idx.iter().enumerate() {
                    mean[bi] = b.mean[i];
                    for (j, &bj) in bb.b_idx.iter().enumerate() {
                        cov[(bi, bj)] = b.cov[(i, j)];
                    }
                }
                Gaussian::new(mean, cov)
            }
            _ => est.clone(),
        }
    }

    /// Local filter `m` from its prediction: the Tobit update (20)-(25) if its sensor was
    /// scheduled and its reading arrived, else the prediction itself (K = 0 by (24)).
    fn local_step(
        &mut self,
        m: usize,
        pred: Gaussian,
        fresh: Option<f64>,
    ) -> Result<Gaussian, SchemeError> {
        let (h, r, thr) = &self.model.sensors[m];
        let opts = self.model.opts;
        let (post, alpha, beta, theta_l) = match fresh {
            Some(ybar) => {
                let y = thr.censor(ybar); // detection device (6)
                let (post, t) = tobit::update(pred.clone(), h, *r, y, 0.0, thr, &opts)?;
                self.last_post[m] = Some(post.mean.clone());
                (post, t.alpha, t.beta, t.theta_l)
            }
            None => {
                let (a, b, tl) = match &self.last_post[m] {
                    Some(x) => {
                        let t = tobit::terms((h * x)[0], *r, thr, &opts);
                        (t.alpha, t.beta, t.theta_l)
                    }
                    None => (0.0, 0.0, f64::NEG_INFINITY),
                };
                (pred.clone(), a, b, tl)
            }
        };
        if let Some(rec) = self.records.as_mut().and_then(|r| r.last_mut()) {
            rec.push(LocalRecord {
                scheduled: fresh.is_some(),
                alpha,
                beta,
                theta_l,
                pred_cov: pred.cov,
            });
        }
        Ok(post)
    }
}

/// Federated fusion (26): `P = (sum P_m^{-1})^{-1}`, `xi = P sum P_m^{-1} xi_m`.
pub fn federated_fusion(locals: &[Gaussian]) -> Result<Gaussian, SchemeError> {
    let n = locals[0].dim();
    let mut info = Matrix::zeros(n, n);
    let mut vec = Vector::zeros(n);
    for l in locals {
        let inv = spd_inverse(&l.cov).map_err(|source| SchemeError::Matrix {
            what: "local covariance in the federated fusion (26)",
            source,
        })?;
        vec += &inv * &l.mean;
        info += inv;
    }
    let mut cov = spd_inverse(&info).map_err(|source| SchemeError::Matrix {
        what: "fused information matrix (26)",
        source,
    })?;
    symmetrize(&mut cov);
    Ok(Gaussian::new(&cov * vec, cov))
}

/// The reset (27) of a local filter from the fused estimate: `xi_m = xi`, `P_m = P / epsilon_m`.
pub fn reset(fused: &Gaussian, epsilon: f64) -> Gaussian {
    Gaussian::new(fused.mean.clone(), &fused.cov / epsilon)
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
        let held = self.hold.step(k, inbox);
        let fresh: Vec<Option<f64>> = held
            .iter()
            .enumerate()
            .map(|(i, h)| {
                (h.is_fresh() && Schedule::RoundRobin.allows(k, i, p))
                    .then(|| h.value().map(|v| v[0]))
                    .flatten()
            })
            .collect();
        let model = self.model.clone();
        // Common prediction of the fused estimate: P^- = F P F^T + Q; the locals' (19) after the
        // reset (27) are (F xi, P^- / epsilon_m) since Q_m = Q / epsilon_m.
        let pred = kf::predict(&model.transition, &self.fused);
        if let Some(r) = self.records.as_mut() {
            r.push(Vec::with_capacity(p));
            self.fused_pred.push(pred.cov.clone());
        }
        let report = match model.fusion {
            Fusion::Local(m) => {
                self.fused = self.local_step(m, pred, fresh[m])?;
                None
            }
            Fusion::Federated | Fusion::LocalInLoop(_) => {
                let mut locals = Vec::with_capacity(p);
                for (m, (&eps, &y)) in model.sharing.iter().zip(&fresh).enumerate() {
                    locals.push(self.local_step(m, reset(&pred, eps), y)?);
                }
                self.fused = federated_fusion(&locals)?;
                // LocalInLoop reports local m; the loop continues from the fused estimate.
                match model.fusion {
                    Fusion::LocalInLoop(m) => Some(locals.swap_remove(m)),
                    _ => None,
                }
            }
        };
        if let (Some(bb), Some(b)) = (&model.bias_blind, &self.bias) {
            self.bias = Some(kf::predict(&bb.b_transition, b));
        }
        self.out = self.full_output(report.as_ref().unwrap_or(&self.fused));
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.out
    }
}
