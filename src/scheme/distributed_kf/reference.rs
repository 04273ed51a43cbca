//! The per-step code of the globalized DKF as it was before the shared memos and buffers,
//! kept as the oracle of the property test that the fast path computes the
//! same numbers bit for bit. Test-only.
#![allow(dead_code)]
use super::plan::GlobalizedPlan;
use super::{Fusion, Trigger};
use crate::filter::kf::check_measurement;
use crate::filter::Gaussian;
use crate::linalg::{cholesky, symmetrize, Matrix, Vector};
use crate::link::{Message, Received, Transmission};
use crate::model::MeasurementModel;
use crate::scheme::{Feedback, FusionCenter, SchemeError, SensorNode};
use rand::{Rng, RngCore};
use std::sync::Arc;

/// One sensor of the globalized distributed KF.
#[derive(Debug, Clone)]
pub struct RefSensor {
    plan: Arc<GlobalizedPlan>,
    index: usize,
    sensor: Arc<dyn MeasurementModel>,
    trigger: Trigger,
    /// Globalized estimate x̄^{e,i}_k.
    xbar: Vector,
    /// Standard local KF estimate x̂^{e,i}_k.
    kf: Vector,
    /// Replica of the center: last sent globalized estimate, predicted since (x̄^{pp,i}).
    held: Vector,
    /// Debiasing matrix of the last sent estimate, predicted since (Δ^{pp,i}).
    held_delta: Matrix,
    /// Standard KF estimate at the last transmission, predicted since (x̂^{pp,i}).
    kf_held: Vector,
    /// Consecutive silent steps before the current one.
    silent_steps: usize,
}

impl RefSensor {
    /// Sensor `index` of the plan's system, starting from the common prior mean.
    pub fn new(
        plan: Arc<GlobalizedPlan>,
        index: usize,
        sensor: Arc<dyn MeasurementModel>,
        prior_mean: Vector,
        trigger: Trigger,
    ) -> Self {
        let n = prior_mean.len();
        Self {
            plan,
            index,
            sensor,
            trigger,
            xbar: prior_mean.clone(),
            kf: prior_mean.clone(),
            held: prior_mean.clone(),
            held_delta: Matrix::identity(n, n),
            kf_held: prior_mean,
            silent_steps: 0,
        }
    }
}

impl SensorNode for RefSensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        _feedback: Option<&Feedback>,
        rng: &mut dyn RngCore,
    ) -> Result<Transmission, SchemeError> {
        check_measurement(self.sensor.as_ref(), z)?;
        let m = self.plan.at(k)?;
        let a = self.plan.a();
        let i = self.index;
        // Globalized prediction (2) and local filtering step (Section II).
        let xbar_p = a * &self.xbar;
        self.xbar = &m.prediction_weight * &xbar_p + &m.measurement_weight[i] * z;
        // Standard KF beside it.
        let kf_p = a * &self.kf;
        let correction = &m.kf_gain[i] * (z - self.sensor.predict(&kf_p));
        self.kf = &kf_p + &correction;
        // Replica of the center's extrapolation.
        self.held = a * &self.held;
        self.kf_held = a * &self.kf_held;
        let bounded = matches!(self.trigger, Trigger::Bounded { .. });
        if bounded {
            let a_inv = self.plan.a_inv().ok_or_else(|| {
                SchemeError::Unsupported("Algorithm 2 needs an invertible system matrix".into())
            })?;
            self.held_delta = a * &self.held_delta * a_inv;
        }

        let u: f64 = rng.random();
        let must_send = self.trigger.every_other_step() && self.silent_steps >= 1;
        let send = must_send
            || match &self.trigger {
                Trigger::Always => true,
                Trigger::Random { send_probability } => u < *send_probability,
                Trigger::Event { alpha } => correction.norm() > *alpha,
                Trigger::Bounded { alpha, b_inv } => {
                    let d =
                        debiased_difference(&m.delta_p[i], &self.held_delta, &self.held, &xbar_p)?;
                    (&self.kf_held - &self.kf).norm() > *alpha || d.dot(&(b_inv * &d)) > 1.0
                }
            };
        if send {
            self.held.copy_from(&self.xbar);
            self.kf_held.copy_from(&self.kf);
            if bounded {
                self.held_delta.copy_from(&m.delta_e[i]);
            }
            self.silent_steps = 0;
            Ok(Transmission::Send(Message::Estimate(self.xbar.clone())))
        } else {
            self.silent_steps += 1;
            Ok(Transmission::Silent)
        }
    }
}

/// x̃^{pp,i}_k = Δ^{p,i}_k (Δ^{pp,i}_k)^{-1} x̄^{pp,i}_k (Section IV).
fn debiased_extrapolation(
    delta_p: &Matrix,
    delta_pp: &Matrix,
    held: &Vector,
) -> Result<Vector, SchemeError> {
    let solved = delta_pp
        .clone()
        .lu()
        .solve(held)
        .ok_or_else(|| SchemeError::Unsupported("debiasing matrix Δ^pp is singular".into()))?;
    Ok(delta_p * solved)
}

/// d̃^i_k = x̃^{pp,i}_k - x̄^{p,i}_k (Section IV).
fn debiased_difference(
    delta_p: &Matrix,
    delta_pp: &Matrix,
    held: &Vector,
    xbar_p: &Vector,
) -> Result<Vector, SchemeError> {
    Ok(debiased_extrapolation(delta_p, delta_pp, held)? - xbar_p)
}

/// The fusion center.
#[derive(Debug, Clone)]
pub struct RefCenter {
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

impl RefCenter {
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

impl FusionCenter for RefCenter {
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

mod fast_equals_reference {
    use super::*;
    use crate::linalg::Matrix;
    use crate::model::{LinearSensor, LinearTransition};
    use crate::scheme::distributed_kf::{DistributedKfScheme, GlobalizedPlan};
    use crate::scheme::{Scheme, System};
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// A random small linear system: F = I + small coupling (invertible), Q = G G^T + 0.1 I,
    /// `n_sensors` sensors of 1 or 2 rows, R diagonal. Sensor 1 repeats sensor 0, so the
    /// canonical silence sets of the covariance memo are exercised.
    fn system(n: usize, n_sensors: usize, v: &[f64]) -> Arc<System> {
        let mut it = v.iter().copied().cycle();
        let mut next = || it.next().unwrap();
        let f = Matrix::from_fn(n, n, |i, j| f64::from(u8::from(i == j)) + 0.2 * next());
        let g = Matrix::from_fn(n, n, |_, _| 0.5 * next());
        let q = &g * g.transpose() + Matrix::identity(n, n) * 0.1;
        let q = (&q + q.transpose()) * 0.5;
        let transition = LinearTransition::new(f, q).unwrap();
        let mut sensors: Vec<Arc<dyn MeasurementModel>> = Vec::new();
        for i in 0..n_sensors {
            if i == 1 {
                sensors.push(sensors[0].clone());
                continue;
            }
            let m = 1 + i % 2;
            let h = Matrix::from_fn(m, n, |_, _| next());
            let r = Matrix::from_diagonal(&Vector::from_fn(m, |_, _| 0.5 + next().abs()));
            sensors.push(Arc::new(LinearSensor::new(h, r).unwrap()));
        }
        let prior = Gaussian::new(
            Vector::from_fn(n, |_, _| next()),
            Matrix::from_diagonal(&Vector::from_fn(n, |_, _| 1.0 + next().abs())),
        );
        Arc::new(System {
            transition,
            sensors,
            prior,
        })
    }

    fn bits(v: &Vector) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn bits_m(m: &Matrix) -> Vec<u64> {
        m.iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig {
            cases: 48,
            // A fixed seed: the same cases on every run and machine (CI included).
            rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0005),
            ..proptest::prelude::ProptestConfig::default()
        })]
        /// The memoized, buffered sensors and center of every trigger compute exactly what
        /// the direct per-step form computes (every bit of every message, fused mean and
        /// covariance), on random systems of dimension 1 to 6 (6 takes nalgebra's matrixmultiply
        /// path for the 6 x 6 products) with 2 to 4 sensors, run twice so that the second run
        /// reads every memo.
        #[test]
        fn fast_path_is_bit_identical(
            n in 1usize..=6,
            n_sensors in 2usize..=4,
            trigger_kind in 0usize..4,
            alpha in 0.0f64..2.0,
            b in 0.05f64..20.0,
            v in proptest::collection::vec(-1.0f64..1.0, 64),
            seed in 0u64..1000,
        ) {
            let sys = system(n, n_sensors, &v);
            let steps = 25;
            let (trigger, bound) = match trigger_kind {
                0 => (Trigger::Always, None),
                1 => (Trigger::Random { send_probability: 0.6 }, None),
                2 => (Trigger::Event { alpha }, None),
                _ => (
                    Trigger::Bounded { alpha, b_inv: Matrix::identity(n, n) / b },
                    Some(Matrix::identity(n, n) * b),
                ),
            };
            let fusion = match &trigger {
                Trigger::Bounded { .. } => Fusion::Bounded { b: bound.clone().unwrap() },
                _ => Fusion::OmittedEstimates,
            };
            let scheme = DistributedKfScheme::new(sys.clone(), steps, trigger.clone(), bound).unwrap();
            let plan: Arc<GlobalizedPlan> = scheme.plan().clone();
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let zs: Vec<Vec<Vector>> = {
                let mut x = sys.prior.mean.clone();
                (0..steps).map(|_| {
                    x = sys.transition.sample_next(&x, &mut rng);
                    sys.sensors.iter().map(|s| s.sample(&x, &mut rng)).collect()
                }).collect()
            };
            for _run in 0..2 {
                let mut fast = scheme.build().unwrap();
                let mut ref_sensors: Vec<RefSensor> = sys.sensors.iter().enumerate().map(|(i, s)| {
                    RefSensor::new(plan.clone(), i, s.clone(), sys.prior.mean.clone(), trigger.clone())
                }).collect();
                let mut ref_center = RefCenter::new(plan.clone(), sys.sensors.clone(), sys.prior.clone(), fusion.clone());
                let mut rng_fast = Xoshiro256PlusPlus::seed_from_u64(seed + 1);
                let mut rng_ref = Xoshiro256PlusPlus::seed_from_u64(seed + 1);
                for k in 1..=steps {
                    let mut inbox_fast = Vec::new();
                    let mut inbox_ref = Vec::new();
                    for i in 0..n_sensors {
                        let tf = fast.sensors[i].step(k, &zs[k - 1][i], None, &mut rng_fast);
                        let tr = ref_sensors[i].step(k, &zs[k - 1][i], None, &mut rng_ref);
                        prop_assert_eq!(&tf, &tr, "step {} sensor {}", k, i);
                        let (Ok(tf), Ok(tr)) = (tf, tr) else { return Ok(()) };
                        if let (Transmission::Send(Message::Estimate(a)), Transmission::Send(Message::Estimate(b))) = (&tf, &tr) {
                            prop_assert_eq!(bits(a), bits(b));
                        }
                        inbox_fast.push(Received::from(tf));
                        inbox_ref.push(Received::from(tr));
                    }
                    let rf = fast.center.step(k, &inbox_fast);
                    let rr = ref_center.step(k, &inbox_ref);
                    prop_assert_eq!(&rf, &rr, "step {}", k);
                    if rf.is_err() {
                        return Ok(());
                    }
                    let (ef, er) = (fast.center.estimate(), ref_center.estimate());
                    prop_assert_eq!(bits(&ef.mean), bits(&er.mean), "mean, step {}", k);
                    prop_assert_eq!(bits_m(&ef.cov), bits_m(&er.cov), "cov, step {}", k);
                }
            }
        }
    }
}
