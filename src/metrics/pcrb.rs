//! The posterior Cramér–Rao bound: the smallest mean squared error that any estimator using
//! every sensor's measurement at every step can reach (Tichavský, Muravchik, Nehorai,
//! "Posterior Cramér–Rao bounds for discrete-time nonlinear filtering", IEEE TSP 46(5), 1998).
//!
//! For linear dynamics x_k = F x_{k-1} + w_k, w_k ~ N(0, Q), and measurements
//! z_k^i = h_i(x_k) + v_k^i, v_k^i ~ N(0, R_i), the information recursion of the paper's eq.
//! (21) with D11 = F^T Q^-1 F, D12 = -F^T Q^-1, D22 = Q^-1 + E[sum_i H_i^T R_i^-1 H_i] reduces by
//! the matrix inversion lemma to
//!
//!   J_k = (Q + F J_{k-1}^-1 F^T)^-1 + E[ sum_i H_i(x_k)^T R_i^-1 H_i(x_k) ],
//!
//! with H_i the Jacobian of h_i at the true state; written with P = J^-1 it needs no Q^-1, so a
//! singular Q (a white-acceleration model) is fine, and J_0^-1 = P_0 may be singular too (a
//! known start). For linear sensors the expectation is a constant and the bound is the
//! all-data Kalman filter's covariance. For nonlinear sensors the expectation is taken over the
//! run's own true trajectories (the same (seed, trial) draws as the runner), so it carries a
//! Monte Carlo error of its own, small next to the schemes' for the same trials.
use crate::linalg::{spd_inverse, symmetrize, Matrix};
use crate::scenario::build::Experiment;
use crate::scenario::draw::draw_trial;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The bound per step, in the units of the schemes' results.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Pcrb {
    /// Bound on the total mean squared error per step (the trace of J_k^-1).
    pub mse: Vec<f64>,
    /// Bound on the RMSE per state group per step.
    pub rmse: BTreeMap<String, Vec<f64>>,
    /// Time average of `rmse`, per group (compare with a scheme's `mean_rmse`).
    pub mean_rmse: BTreeMap<String, f64>,
    /// Average of `mse` over the steady-state steps (compare with `steady_state.mse`).
    pub steady_mse: f64,
    /// True trajectories the expected information was averaged over (0: linear sensors, where
    /// it does not depend on the state).
    pub trajectories: usize,
}

/// Why the bound is not defined for a scenario.
#[derive(Debug, thiserror::Error)]
#[error("posterior Cramér–Rao bound not defined: {0}")]
pub struct PcrbError(String);

/// The bound of `exp`'s model with every sensor at every step.
pub fn compute(exp: &Experiment) -> Result<Pcrb, PcrbError> {
    let sys = &exp.system;
    let n = sys.state_dim();
    let f = sys.transition.f();
    let q = sys.transition.q();
    let all_linear = sys.sensors.iter().all(|s| s.as_linear().is_some());
    // E[sum_i H_i^T R_i^-1 H_i] per step.
    let r_inv: Vec<Matrix> = sys
        .sensors
        .iter()
        .enumerate()
        .map(|(i, s)| {
            spd_inverse(s.noise_cov())
                .map_err(|e| PcrbError(format!("sensor {i}: noise covariance: {e}")))
        })
        .collect::<Result<_, _>>()?;
    let info_at = |x: &crate::linalg::Vector| -> Matrix {
        let mut m = Matrix::zeros(n, n);
        for (s, ri) in sys.sensors.iter().zip(&r_inv) {
            let h = s.jacobian(x);
            m += h.transpose() * ri * h;
        }
        m
    };
    let (info, trajectories): (Vec<Matrix>, usize) = if all_linear {
        // Linear sensors: the Jacobian is H whatever the state.
        let m = info_at(&exp.initial_truth.mean);
        (vec![m; exp.steps], 0)
    } else {
        let mut sum = vec![Matrix::zeros(n, n); exp.steps];
        for trial in 0..exp.trials {
            let data = draw_trial(exp, trial);
            for (acc, x) in sum.iter_mut().zip(&data.truth) {
                *acc += info_at(x);
            }
        }
        let t = exp.trials.max(1) as f64;
        (sum.into_iter().map(|m| m / t).collect(), exp.trials)
    };
    let mut p = exp.initial_truth.cov.clone();
    let mut mse = Vec::with_capacity(exp.steps);
    let mut group_mse: Vec<Vec<f64>> = vec![Vec::with_capacity(exp.steps); exp.groups.len()];
    for (k, i_k) in info.iter().enumerate() {
        let mut pred = f * &p * f.transpose() + q;
        symmetrize(&mut pred);
        let j = spd_inverse(&pred)
            .map_err(|e| PcrbError(format!("step {}: predicted bound covariance: {e}", k + 1)))?
            + i_k;
        p = spd_inverse(&j)
            .map_err(|e| PcrbError(format!("step {}: information matrix: {e}", k + 1)))?;
        symmetrize(&mut p);
        mse.push(p.trace());
        for (g, (_, idx)) in exp.groups.iter().enumerate() {
            group_mse[g].push(idx.iter().map(|&j| p[(j, j)]).sum());
        }
    }
    let mut rmse = BTreeMap::new();
    let mut mean_rmse = BTreeMap::new();
    for ((name, _), m) in exp.groups.iter().zip(group_mse) {
        let r: Vec<f64> = m.into_iter().map(f64::sqrt).collect();
        mean_rmse.insert(
            name.clone(),
            r.iter().sum::<f64>() / exp.steps.max(1) as f64,
        );
        rmse.insert(name.clone(), r);
    }
    let steady: Vec<f64> = mse
        .iter()
        .skip(exp.steady_from.saturating_sub(1))
        .copied()
        .collect();
    Ok(Pcrb {
        steady_mse: steady.iter().sum::<f64>() / steady.len().max(1) as f64,
        mse,
        rmse,
        mean_rmse,
        trajectories,
    })
}

/// One line for the results table: the bound's mean RMSE per group and steady-state MSE.
pub fn line(b: &Pcrb, groups: &[String]) -> String {
    let parts: Vec<String> = groups
        .iter()
        .filter_map(|g| b.mean_rmse.get(g).map(|r| format!("{g} {r:.4}")))
        .collect();
    format!(
        "Posterior Cramér–Rao bound (every sensor at every step, any estimator): mean RMSE {}; steady-state MSE {:.4}{}",
        parts.join(", "),
        b.steady_mse,
        if b.trajectories > 0 {
            format!(" (expected information over {} true trajectories)", b.trajectories)
        } else {
            String::new()
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{MeasurementModel, Opaque};
    use std::sync::Arc;

    fn arena_1d(trials: usize) -> Experiment {
        let text = crate::scenario::builtin::get("arena-1d").unwrap();
        let opts = crate::scenario::build::LoadOptions {
            trials: Some(trials),
            ..Default::default()
        };
        crate::scenario::build::load_with(text, "arena-1d", &opts).unwrap()
    }

    /// Linear-Gaussian model: the bound is the all-data Kalman filter's covariance, whose trace
    /// the run reports as `trace`.
    #[test]
    fn linear_bound_is_the_all_data_kalman_covariance() {
        let exp = arena_1d(2);
        let bound = compute(&exp).unwrap();
        assert_eq!(bound.trajectories, 0);
        let sums = crate::engine::runner::run(&exp, Default::default(), &|_| {}).unwrap();
        let summary = crate::metrics::results::summarize(&exp, &sums);
        let kf = summary
            .schemes
            .iter()
            .find(|s| s.kind == "centralized-kf")
            .unwrap();
        for (k, (b, t)) in bound.mse.iter().zip(&kf.trace).enumerate() {
            assert!(
                (b / t - 1.0).abs() < 1e-9,
                "step {}: bound {b}, KF trace {t}",
                k + 1
            );
        }
        // The bound falls from the prior's spread and is positive.
        assert!(bound.mse[0] > bound.mse[exp.steps - 1] && bound.mse[exp.steps - 1] > 0.0);
    }

    /// The expectation over true trajectories (the nonlinear path) of a linear sensor hidden
    /// behind the general interface gives the linear bound.
    #[test]
    fn expected_information_over_trajectories_reduces_to_the_linear_bound() {
        let mut exp = arena_1d(5);
        let linear = compute(&exp).unwrap();
        let mut sys = (*exp.system).clone();
        sys.sensors = sys
            .sensors
            .iter()
            .map(|s| Arc::new(Opaque(s.as_linear().unwrap().clone())) as Arc<dyn MeasurementModel>)
            .collect();
        exp.system = Arc::new(sys);
        let general = compute(&exp).unwrap();
        assert_eq!(general.trajectories, 5);
        for (a, b) in linear.mse.iter().zip(&general.mse) {
            assert!((a / b - 1.0).abs() < 1e-12, "{a} vs {b}");
        }
        for g in linear.mean_rmse.keys() {
            assert!((linear.mean_rmse[g] / general.mean_rmse[g] - 1.0).abs() < 1e-12);
        }
    }

    /// A model whose predicted covariance is singular has no bound: an error, not a panic.
    #[test]
    fn a_singular_prediction_is_an_error() {
        let mut exp = arena_1d(1);
        let mut sys = (*exp.system).clone();
        let n = sys.state_dim();
        sys.transition = crate::model::transition::LinearTransition::new(
            crate::linalg::Matrix::zeros(n, n),
            crate::linalg::Matrix::zeros(n, n),
        )
        .unwrap();
        exp.system = Arc::new(sys);
        let e = compute(&exp).unwrap_err().to_string();
        assert!(e.contains("step 1"), "{e}");
    }
}
