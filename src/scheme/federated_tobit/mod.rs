//! Seed 002 (Geng, Wang, Alsaadi, Alharbi, Cheng): federated Tobit Kalman filtering of a
//! multi-sensor system with dead-zone-like censoring (eq. (6)), dynamical bias (eq. (3),
//! carried as state augmentation) and round-robin scheduling (eq. (4)-(5)).
//!
//! [`exact_pf`] is the exact-likelihood particle filter shown beside the Tobit KF: the
//! Bayes-optimal answer on the same data, and the shared censoring function [`exact_pf::censor`].
pub mod exact_pf;
