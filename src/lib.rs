//! hushfuse: multi-sensor state estimation under bandwidth limits.
//!
//! Sensors decide whether and with how many bits to talk; a fusion center fuses what arrives
//! and what the silence says. Where each paper lives:
//! - Dormann, Noack and Hanebeck (distributed KF with omitted estimates):
//!   [`scheme::distributed_kf`];
//! - Zheng, Niu and Varshney, 2014 (censoring and a particle filter that listens to
//!   silence): [`scheme::censored_pf`];
//! - Zhang, Li and Liu, 2016 (quantized innovations and 802.15.4 bits):
//!   [`scheme::quantized_innovation`], [`link::quantizer`], [`link::codec802154`];
//! - Geng, Wang et al. (federated Tobit Kalman filter: two-sided censoring, dynamical bias,
//!   round-robin with zero-order hold): [`scheme::federated_tobit`], [`filter::tobit`];
//! - event-triggered and estimate-fusion baselines: [`scheme::event_triggered`],
//!   [`scheme::estimate_fusion`]; the baselines every scheme is measured against:
//!   [`scheme::centralized`].
//!
//! The engine ([`engine`]: [`engine::trial`] the one trial loop, [`engine::runner`] the Monte
//! Carlo runner) owns the only time loop; filters, sensor nodes and fusion centers do one step
//! per call and can be used on their own. [`network`] says how messages cross (channels, radio
//! energy), [`metrics`] what a run measures, [`output`] what it writes, and [`live`] runs the
//! same sensor and fusion sides as processes exchanging real 802.15.4 frames over UDP. The sensor side and the fusion side of a
//! scheme are separate pieces:
//!
//! ```
//! use hushfuse::filter::Gaussian;
//! use hushfuse::linalg::{Matrix, Vector};
//! use hushfuse::link::Received;
//! use hushfuse::model::{presets, LinearSensor, MeasurementModel};
//! use hushfuse::scheme::distributed_kf::{DkfCenter, DkfSensor, Fusion, GlobalizedPlan, Trigger};
//! use hushfuse::scheme::{FusionCenter, SensorNode, System};
//! use rand::SeedableRng;
//! use std::sync::Arc;
//!
//! // Two position sensors on a 1-D constant-velocity target.
//! let sensor = |r: f64| -> Arc<dyn MeasurementModel> {
//!     Arc::new(LinearSensor::new(Matrix::from_row_slice(1, 2, &[1.0, 0.0]),
//!                                Matrix::from_element(1, 1, r)).unwrap())
//! };
//! let system = System {
//!     transition: presets::constant_velocity_1d(1.0, 0.1).unwrap(),
//!     sensors: vec![sensor(1.0), sensor(2.0)],
//!     prior: Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2)),
//! };
//! // Both sides compute the same data-independent plan (here for 10 steps).
//! let plan = Arc::new(GlobalizedPlan::new(&system, 10).unwrap());
//! let mut nodes: Vec<DkfSensor> = (0..2)
//!     .map(|i| DkfSensor::new(plan.clone(), i, system.sensors[i].clone(),
//!                             system.prior.mean.clone(), Trigger::Event { alpha: 0.2 }))
//!     .collect();
//! let mut center = DkfCenter::new(plan.clone(), system.sensors.clone(),
//!                                 system.prior.clone(), Fusion::OmittedEstimates);
//! let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
//! for k in 1..=10 {
//!     let z = Vector::from_element(1, k as f64); // the target moves one unit per step
//!     let inbox: Vec<Received> = nodes.iter_mut()
//!         .map(|n| n.step(k, &z, None, &mut rng).unwrap().into())
//!         .collect();
//!     center.step(k, &inbox).unwrap();
//! }
//! let est = center.estimate();
//! assert!((est.mean[0] - 10.0).abs() < 1.5, "position {}", est.mean[0]);
//! ```
pub mod decentralized;
pub mod engine;
pub mod filter;
pub mod linalg;
pub mod link;
pub mod live;
pub mod metrics;
pub mod model;
pub mod network;
pub mod output;
pub mod scenario;
pub mod scheme;
pub mod stats;
