//! Fusion center of the globalized distributed KF (seed 004).
use super::plan::GlobalizedPlan;
use super::sensor::debiased_extrapolation;
use crate::filter::Gaussian;
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::link::Received;
use crate::model::MeasurementModel;
use crate::scheme::{FusionCenter, SchemeError};
use std::sync::Arc;

/// Which fusion rule the center applies to silent sensors.
#[derive(Debug, Clone, PartialEq)]
pub enum Fusion {
    /// Algorithm 1, eq. (10)-(11): exact (equal to the centralized KF that received everything
    /// up to k-1 and the same subset at k) as long as every silent sensor sent at k-1; a sensor
    /// silent twice in a row is a protocol error.
    OmittedEstimates,
    /// Algorithm 2 (Section IV): silent sensors contribute their debiased extrapolation x̃^{pp,i}
    /// and the covariance is inflated by (N - m - l)^2 C (C̄^p)^{-1} B (C̄^p)^{-1} C^T, which
    /// keeps the estimate consistent when the sensors use test (13) with the same B.
    Bounded { b: Matrix },
}

/// The fusion center.
#[derive(Debug, Clone)]
pub struct DkfCenter {
    plan: Arc<GlobalizedPlan>,
    sensors: Vec<Arc<dyn MeasurementModel>>,
    fusion: Fusion,
    est: Gaussian,
    /// Per sensor: last received globalized estimate, predicted since (x̄^{pp,i}).
    held: Vec<Vector>,
    /// Per sensor: its debiasing matrix, predicted since (Δ^{pp,i}); Algorithm 2 only.
    held_delta: Vec<Matrix>,
    /// Per sensor: consecutive silent steps including the current one.
    silent_steps: Vec<usize>,
}

impl DkfCenter {
    /// Starts from the common prior; at k = 0 every sensor's initial estimate is known.
    pub fn new(
        plan: Arc<GlobalizedPlan>,
        sensors: Vec<Arc<dyn MeasurementModel>>,
        prior: Gaussian,
        fusion: Fusion,
    ) -> Self {
        let n = prior.dim();
        let held = vec![prior.mean.clone(); sensors.len()];
        let held_delta = vec![Matrix::identity(n, n); sensors.len()];
        let silent_steps = vec![0; sensors.len()];
        Self {
            plan,
            sensors,
            fusion,
            est: prior,
            held,
            held_delta,
            silent_steps,
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
        let m = self.plan.at(k)?;
        let a = self.plan.a();
        let bounded = matches!(self.fusion, Fusion::Bounded { .. });
        let nf = self.sensors.len() as f64;
        let n = self.est.dim();
        // (10): start from N (C̄^e)^{-1}, remove the information of each silent sensor.
        let mut info = &m.cbar_e_inv * nf;
        let mut info_vec = Vector::zeros(n);
        // Silent sensors whose extrapolation is not exact (N - m - l of Section IV).
        let mut inexact = 0usize;
        for (i, msg) in inbox.iter().enumerate() {
            self.held[i] = a * &self.held[i];
            if bounded {
                let a_inv = self.plan.a_inv().ok_or_else(|| {
                    SchemeError::Unsupported("Algorithm 2 needs an invertible system matrix".into())
                })?;
                self.held_delta[i] = a * &self.held_delta[i] * a_inv;
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
                    info_vec += &m.cbar_e_inv * x;
                    self.held[i].copy_from(x);
                    if bounded {
                        self.held_delta[i].copy_from(&m.delta_e[i]);
                    }
                    self.silent_steps[i] = 0;
                }
                Received::Silent | Received::NotScheduled => {
                    self.silent_steps[i] += 1;
                    let lin = self.sensors[i].as_linear().ok_or_else(|| {
                        SchemeError::Unsupported("distributed KF needs linear sensors".into())
                    })?;
                    info -= lin.information();
                    let contribution = if self.silent_steps[i] == 1 {
                        // Sent at k-1: x̄^{pp} = x̄^p, exact (11), second sum.
                        self.held[i].clone()
                    } else {
                        match &self.fusion {
                            Fusion::OmittedEstimates => {
                                return Err(SchemeError::Protocol {
                                    sensor: i,
                                    message: format!(
                                        "silent for {} steps; Algorithm 1 needs a \
                                         transmission at least every other step",
                                        self.silent_steps[i]
                                    ),
                                })
                            }
                            Fusion::Bounded { .. } => {
                                inexact += 1;
                                debiased_extrapolation(
                                    &m.delta_p[i],
                                    &self.held_delta[i],
                                    &self.held[i],
                                )?
                            }
                        }
                    };
                    info_vec += &m.cbar_p_inv * contribution;
                }
                Received::Measurement(_) | Received::Frame(_) => {
                    return Err(SchemeError::Protocol {
                        sensor: i,
                        message: "distributed KF expects estimates".into(),
                    })
                }
            }
        }
        symmetrize(&mut info);
        let chol = cholesky(&info).map_err(|source| SchemeError::Matrix {
            what: "fused information matrix (10)",
            source,
        })?;
        let mean = chol.solve(&info_vec);
        let mut cov = chol.inverse();
        if let Fusion::Bounded { b } = &self.fusion {
            if inexact > 0 {
                let g = &cov * &m.cbar_p_inv;
                let factor = (inexact * inexact) as f64;
                cov += (&g * b * g.transpose()) * factor;
            }
        }
        symmetrize(&mut cov);
        self.est = Gaussian { mean, cov };
        Ok(())
    }

    fn estimate(&self) -> &Gaussian {
        &self.est
    }
}
