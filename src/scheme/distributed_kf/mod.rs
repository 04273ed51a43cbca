//! Dormann, Noack and Hanebeck, "Distributed Kalman Filtering With Reduced
//! Transmission Rate": the globalized distributed KF (Section II), Algorithm 1 with omitted
//! estimates (Section III, eq. (10)-(12)) and Algorithm 2 with debiasing and the bound B
//! (Section IV, eq. (13)-(14)).
//!
//! The sensor side ([`DkfSensor`]) and the fusion side ([`DkfCenter`]) are separate pieces;
//! they share only the data-independent [`GlobalizedPlan`], which each side could compute on
//! its own.
pub mod center;
mod fast;
mod loss;
pub mod params;
pub mod plan;
mod replica;
pub mod sensor;
mod signals;

pub use center::{CovarianceMemo, DkfCenter, Fusion};
pub use plan::GlobalizedPlan;
pub use sensor::{DkfSensor, Trigger};

use crate::linalg::Matrix;
use crate::scheme::fast_path::{BatchSink, FastTrialError, LockstepFastPath, Losses, TrialCache};
use crate::scheme::{Scheme, SchemeError, SchemeInstance, SensorNode, System};
use std::sync::Arc;

/// The distributed KF with one trigger for all sensors; the fusion rule follows from it
/// (Algorithm 2's for [`Trigger::Bounded`], Algorithm 1's otherwise).
#[derive(Debug, Clone)]
pub struct DistributedKfScheme {
    system: Arc<System>,
    plan: Arc<GlobalizedPlan>,
    trigger: Trigger,
    fusion: Fusion,
    /// Fused covariances by (step, silent set, inexact count), shared by the trials' centers
    /// and by the other variants of the same plan and fusion rule.
    memo: Arc<CovarianceMemo>,
    /// A fresh center (sharing `memo`), for the fast trial's fused covariances.
    proto: Arc<DkfCenter>,
    /// Algorithm 2's loss-aware center ([`DkfCenter::set_loss_aware`]).
    loss_aware: bool,
}

impl DistributedKfScheme {
    /// Precomputes the plan for `horizon` steps. Algorithm 2 needs B symmetric positive
    /// definite (checked by the caller) and an invertible system matrix.
    pub fn new(
        system: Arc<System>,
        horizon: usize,
        trigger: Trigger,
        bound: Option<Matrix>,
    ) -> Result<Self, SchemeError> {
        let plan = GlobalizedPlan::shared(&system, horizon)?;
        let fusion = match (&trigger, bound) {
            (Trigger::Bounded { .. }, Some(b)) => {
                if plan.a_inv().is_none() {
                    return Err(SchemeError::Unsupported(
                        "Algorithm 2 debiases with A^{-1}: the system matrix must be invertible"
                            .into(),
                    ));
                }
                Fusion::Bounded { b }
            }
            (Trigger::Bounded { .. }, None) => {
                return Err(SchemeError::Unsupported(
                    "Algorithm 2 needs the bound B".into(),
                ))
            }
            _ => Fusion::OmittedEstimates,
        };
        let memo = CovarianceMemo::shared(&plan, &fusion);
        let proto = Arc::new(DkfCenter::with_memo(
            plan.clone(),
            system.sensors.clone(),
            system.prior.clone(),
            fusion.clone(),
            memo.clone(),
        ));
        Ok(Self {
            system,
            plan,
            trigger,
            fusion,
            memo,
            proto,
            loss_aware: false,
        })
    }

    /// Algorithm 2's center made loss-aware: a sensor silent twice or more may have been
    /// lost, and its extrapolation is inflated by B plus its computed second moment (see
    /// [`DkfCenter::set_loss_aware`]). No effect on Algorithm 1, whose center always treats an
    /// estimate missing twice as lost.
    pub fn with_loss_aware(mut self, on: bool) -> Self {
        self.loss_aware = on && matches!(self.fusion, Fusion::Bounded { .. });
        self
    }

    /// The globalized DKF at full rate (Section II).
    pub fn full_rate(system: Arc<System>, horizon: usize) -> Result<Self, SchemeError> {
        Self::new(system, horizon, Trigger::Always, None)
    }

    /// Algorithm 1 with random communication at the average rate `rate` in [0.5, 1].
    pub fn alg1_random(
        system: Arc<System>,
        horizon: usize,
        rate: f64,
    ) -> Result<Self, SchemeError> {
        if !(0.5..=1.0).contains(&rate) {
            return Err(SchemeError::Invalid {
                field: "rate",
                message: format!("expected a rate in [0.5, 1] (Algorithm 1 needs a transmission at least every other step), got {rate}"),
            });
        }
        Self::new(system, horizon, Trigger::random_for_rate(rate), None)
    }

    /// Algorithm 1 with the event test (12) at threshold `alpha` >= 0.
    pub fn alg1_event(
        system: Arc<System>,
        horizon: usize,
        alpha: f64,
    ) -> Result<Self, SchemeError> {
        Self::new(
            system,
            horizon,
            Trigger::Event {
                alpha: check_alpha(alpha)?,
            },
            None,
        )
    }

    /// Algorithm 2: test (13) with threshold `alpha` >= 0 and the bound `b` (symmetric
    /// positive definite, n x n).
    pub fn alg2_event(
        system: Arc<System>,
        horizon: usize,
        alpha: f64,
        b: Matrix,
    ) -> Result<Self, SchemeError> {
        let alpha = check_alpha(alpha)?;
        let n = system.state_dim();
        if b.nrows() != n || b.ncols() != n {
            return Err(SchemeError::Invalid {
                field: "B",
                message: format!("expected a {n}x{n} matrix, got {}x{}", b.nrows(), b.ncols()),
            });
        }
        let b_inv = crate::linalg::check_spd(&b)
            .and_then(|()| crate::linalg::spd_inverse(&b))
            .map_err(|e| SchemeError::Invalid {
                field: "B",
                message: format!("expected a symmetric positive definite bound: {e}"),
            })?;
        Self::new(system, horizon, Trigger::Bounded { alpha, b_inv }, Some(b))
    }

    /// The shared plan.
    pub fn plan(&self) -> &Arc<GlobalizedPlan> {
        &self.plan
    }
}

impl Scheme for DistributedKfScheme {
    fn keeps_step_plan(&self) -> bool {
        true
    }

    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        let sensors = self
            .system
            .sensors
            .iter()
            .enumerate()
            .map(|(i, s)| {
                Box::new(DkfSensor::new(
                    self.plan.clone(),
                    i,
                    s.clone(),
                    self.system.prior.mean.clone(),
                    self.trigger.clone(),
                )) as Box<dyn SensorNode>
            })
            .collect();
        let mut center = Box::new(DkfCenter::with_memo(
            self.plan.clone(),
            self.system.sensors.clone(),
            self.system.prior.clone(),
            self.fusion.clone(),
            self.memo.clone(),
        ));
        center.set_loss_aware(self.loss_aware);
        Ok(SchemeInstance { sensors, center })
    }

    fn fast_path(&self) -> Option<&dyn LockstepFastPath> {
        Some(self)
    }
}

impl LockstepFastPath for DistributedKfScheme {
    fn run_trial_fast(
        &self,
        measurements: &[Vec<crate::linalg::Vector>],
        steps: usize,
        losses: Option<&Losses>,
        coins: &mut [rand_xoshiro::Xoshiro256PlusPlus],
        cache: &mut TrialCache,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        // The fast trial fuses as published (Algorithm 2's B alone).
        if self.loss_aware {
            return None;
        }
        fast::run(self, measurements, steps, losses, coins, cache, sink)
    }
}

fn check_alpha(alpha: f64) -> Result<f64, SchemeError> {
    if alpha.is_finite() && alpha >= 0.0 {
        Ok(alpha)
    } else {
        Err(SchemeError::Invalid {
            field: "alpha",
            message: format!("expected a finite number >= 0, got {alpha}"),
        })
    }
}

#[cfg(test)]
mod loss_tests;
#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
