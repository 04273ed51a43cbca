//! The dense matrix and vector types of the crate (a leaf module: the fixed-size kernels and
//! the dense helpers both use them).
use nalgebra::{DMatrix, DVector};

/// Dense matrix with run-time dimensions (scenarios choose dimensions at run time).
pub type Matrix = DMatrix<f64>;
/// Dense vector with run-time dimension.
pub type Vector = DVector<f64>;
