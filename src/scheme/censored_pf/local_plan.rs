//! The data-independent part of Zheng et al.'s (2014) local filters. A linear sensor's KF covariance,
//! gain and innovation covariance do not depend on its measurements (nor on the fed-back
//! prediction, which moves only the mean), so every sensor of every trial, and the fusion
//! center's replica of it (Remark 1 (I)), runs through the same sequence. We compute it once
//! per scheme and share it: the per-step matrix algebra (and its allocations) leaves the
//! Monte Carlo loop. EKF sensors linearize at a data-dependent point and keep computing.
//!
//! The arithmetic is exactly that of [`kf::predict`] and [`kf::update_cov`], so a
//! run with the plan gives bit-identical numbers to a run without.
use crate::filter::{kf, Gaussian};
use crate::linalg::{Matrix, Vector};
use crate::scheme::{SchemeError, System};

/// The most steps stored per sensor: a recursion that has not reached its fixed point by then
/// is left to the sensors and the fusion center to compute step by step.
const MAX_STORED_STEPS: usize = 10_000;

/// One sensor's local-filter matrices at one step k.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalStep {
    /// P^i_{k|k-1} = F P^i_{k-1|k-1} F^T + Q.
    pub p_pred: Matrix,
    /// P^i_{k|k} (Joseph form).
    pub p_post: Matrix,
    /// Gain W^i_k.
    pub gain: Matrix,
    /// Innovation covariance S^i_k = H P^i_{k|k-1} H^T + R: the `s_k` of the NIS rule (4)/(31)
    /// without feedback and with the prediction fed back (Prop. 1 / 4).
    pub s: Matrix,
}

/// The sequence of [`LocalStep`]s of every linear sensor for steps 1..=horizon, from the
/// common prior. When a sensor's covariance reaches its fixed point exactly (bit for bit), the
/// rest of its sequence is that step repeated and is not stored.
#[derive(Debug, Clone)]
pub struct LocalPlan {
    /// Per sensor: steps 1..=len, and whether the last one repeats for ever; `None` for a
    /// nonlinear sensor and for one whose recursion did not settle within
    /// [`MAX_STORED_STEPS`] of a longer horizon.
    sensors: Vec<Option<(Vec<LocalStep>, bool)>>,
    horizon: usize,
}

impl LocalPlan {
    /// Runs every linear sensor's covariance recursion for `horizon` steps.
    pub fn new(system: &System, horizon: usize) -> Result<Self, SchemeError> {
        let sensors = system
            .sensors
            .iter()
            .map(|sensor| {
                if sensor.as_linear().is_none() {
                    return Ok(None);
                }
                // H does not depend on the linearization point of a linear sensor.
                let x_ref = Vector::zeros(system.state_dim());
                let mut est = Gaussian::new(x_ref.clone(), system.prior.cov.clone());
                let mut steps: Vec<LocalStep> = Vec::new();
                for _ in 0..horizon.min(MAX_STORED_STEPS + 1) {
                    let p_pred = kf::predict(&system.transition, &est).cov;
                    let (p_post, gain, s) = kf::update_cov(sensor.as_ref(), &p_pred, &x_ref)?;
                    let step = LocalStep {
                        p_pred,
                        p_post,
                        gain,
                        s,
                    };
                    if steps.last() == Some(&step) {
                        return Ok(Some((steps, true)));
                    }
                    est.cov.copy_from(&step.p_post);
                    steps.push(step);
                }
                // A long horizon whose recursion never settles (a rounding cycle, or a
                // diverging model) is not stored: that sensor computes as it goes.
                Ok((steps.len() <= MAX_STORED_STEPS).then_some((steps, false)))
            })
            .collect::<Result<_, SchemeError>>()?;
        Ok(Self { sensors, horizon })
    }

    /// Sensor `i`'s matrices at step `k` (1-based); `Ok(None)` for a sensor without a plan, an
    /// error past the horizon unless the sequence converged.
    pub fn at(&self, i: usize, k: usize) -> Result<Option<&LocalStep>, SchemeError> {
        let Some((steps, converged)) = self.sensors.get(i).and_then(Option::as_ref) else {
            return Ok(None);
        };
        match steps.get(k.wrapping_sub(1)) {
            Some(s) => Ok(Some(s)),
            None if k >= 1 && *converged => Ok(steps.last()),
            None => Err(SchemeError::HorizonExceeded {
                k,
                horizon: self.horizon,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::matrix_from_rows;
    use crate::model::nonlinear::Placement;
    use crate::model::{LinearSensor, LinearTransition, MeasurementModel, RangeSensor};
    use std::sync::Arc;

    fn system(extra_range: bool) -> System {
        let f = matrix_from_rows(&[vec![1.0, 1.0], vec![0.0, 1.0]]);
        let q = matrix_from_rows(&[vec![0.25, 0.5], vec![0.5, 1.0]]);
        let h = matrix_from_rows(&[vec![1.0, 0.0]]);
        let mut sensors: Vec<Arc<dyn MeasurementModel>> = vec![
            Arc::new(LinearSensor::new(h.clone(), Matrix::identity(1, 1)).unwrap()),
            Arc::new(LinearSensor::new(h, Matrix::from_element(1, 1, 4.0)).unwrap()),
        ];
        if extra_range {
            let placement = Placement {
                position: [5.0, 5.0],
                indices: [0, 1],
                state_dim: 2,
            };
            sensors.push(Arc::new(RangeSensor::new(placement, 1.0).unwrap()));
        }
        System {
            transition: LinearTransition::new(f, q).unwrap(),
            sensors,
            prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2)),
        }
    }

    #[test]
    fn plan_equals_the_step_by_step_recursion_bit_for_bit() {
        let sys = system(true);
        let plan = LocalPlan::new(&sys, 300).unwrap();
        let x_ref = Vector::from_vec(vec![3.0, -1.0]);
        for i in 0..2 {
            let mut est = sys.prior.clone();
            // Past the horizon too: this recursion reaches its fixed point bit for bit.
            for k in 1..=400 {
                let p_pred = kf::predict(&sys.transition, &est).cov;
                let (p_post, gain, s) =
                    kf::update_cov(sys.sensors[i].as_ref(), &p_pred, &x_ref).unwrap();
                let step = plan.at(i, k).unwrap().expect("linear sensor");
                assert_eq!(step.p_pred, p_pred, "sensor {i}, k = {k}");
                assert_eq!(step.p_post, p_post, "sensor {i}, k = {k}");
                assert_eq!(step.gain, gain, "sensor {i}, k = {k}");
                assert_eq!(step.s, s, "sensor {i}, k = {k}");
                est.cov = p_post;
            }
        }
        assert!(
            plan.at(2, 1).unwrap().is_none(),
            "the range sensor has no plan"
        );
    }

    #[test]
    fn a_recursion_that_never_settles_is_not_stored_past_the_cap() {
        // The second component is unobserved and slowly unstable: its variance grows for ever.
        let mut sys = system(false);
        sys.transition = LinearTransition::new(
            matrix_from_rows(&[vec![1.0, 0.0], vec![0.0, 1.001]]),
            Matrix::identity(2, 2) * 0.1,
        )
        .unwrap();
        let long = LocalPlan::new(&sys, MAX_STORED_STEPS + 5).unwrap();
        assert!(long.at(0, 1).unwrap().is_none());
        assert!(long.at(0, MAX_STORED_STEPS + 5).unwrap().is_none());
        let short = LocalPlan::new(&sys, 50).unwrap();
        assert!(short.at(0, 50).unwrap().is_some());
    }

    #[test]
    fn an_unconverged_plan_refuses_steps_past_its_horizon() {
        let sys = system(false);
        let plan = LocalPlan::new(&sys, 3).unwrap();
        assert!(plan.at(0, 3).unwrap().is_some());
        assert!(matches!(
            plan.at(0, 4),
            Err(SchemeError::HorizonExceeded { k: 4, horizon: 3 })
        ));
        assert!(plan.at(0, 0).is_err());
    }
}
