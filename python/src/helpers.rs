//! What a Python scheme is given to work with: the system it estimates ([`PySystem`]: F, Q,
//! H_i, R_i, the prior) and the library's own Kalman arithmetic ([`LinearFusion`]: the
//! prediction and the information-form fusion the built-in event-triggered centers use), so that
//! a Python center can reproduce a built-in one bit for bit. Also the conversions of numbers,
//! lists and numpy arrays to vectors and matrices, with messages that name no Rust type.
use crate::lock;
use hushfuse::filter::{kf, Gaussian};
use hushfuse::linalg::{Matrix, Vector};
use hushfuse::scheme::event_triggered::{Evidence, Fusion};
use hushfuse::scheme::System;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::sync::{Arc, Mutex};

/// `obj` as a float64 numpy array (scalars, lists and arrays of ints accepted), with its
/// shape; an error in words otherwise.
fn floats(obj: &Bound<'_, PyAny>) -> Result<(Vec<f64>, Vec<usize>), String> {
    // A float64 array, contiguous: read as it is (the common case, without numpy calls).
    if let Ok(arr) = obj.downcast::<numpy::PyArrayDyn<f64>>() {
        let ro = arr.readonly();
        if let Ok(data) = ro.as_slice() {
            return Ok((data.to_vec(), ro.shape().to_vec()));
        }
    }
    // A Python number (a numpy float64 scalar is one), not a flag.
    let number = obj.is_instance_of::<pyo3::types::PyFloat>()
        || (obj.is_instance_of::<pyo3::types::PyInt>()
            && !obj.is_instance_of::<pyo3::types::PyBool>());
    if number {
        if let Ok(x) = obj.extract::<f64>() {
            return Ok((vec![x], Vec::new()));
        }
    }
    let py = obj.py();
    let np = py.import("numpy").map_err(|e| e.to_string())?;
    let arr = np
        .call_method1("asarray", (obj,))
        .map_err(|_| "expected numbers (a number, a list or a numpy array)".to_string())?;
    let kind: String = arr
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .map_err(|e| e.to_string())?;
    if !"fiu".contains(kind.as_str()) || kind.is_empty() {
        return Err(format!(
            "expected real numbers, got values of numpy dtype kind {kind:?}"
        ));
    }
    let arr = np
        .call_method1("ascontiguousarray", (arr, "float64"))
        .map_err(|e| e.to_string())?;
    let arr = arr
        .downcast::<numpy::PyArrayDyn<f64>>()
        .map_err(|_| "expected a float array".to_string())?;
    let ro = arr.readonly();
    let shape = ro.shape().to_vec();
    let data = ro.as_slice().map_err(|e| e.to_string())?.to_vec();
    Ok((data, shape))
}

/// A vector from a number, a list or a 1-D array (an (m, 1) or (1, m) array too).
pub(crate) fn vector_of(obj: &Bound<'_, PyAny>) -> Result<Vector, String> {
    let (data, shape) = floats(obj)?;
    let ok = match shape.as_slice() {
        [] | [_] => true,
        [a, b] => *a == 1 || *b == 1,
        _ => false,
    };
    if !ok {
        return Err(format!(
            "expected a vector, got an array of shape {shape:?}"
        ));
    }
    Ok(Vector::from_vec(data))
}

/// A matrix from a number (1 x 1), a list of rows or a 2-D array.
pub(crate) fn matrix_of(obj: &Bound<'_, PyAny>) -> Result<Matrix, String> {
    let (data, shape) = floats(obj)?;
    match shape.as_slice() {
        [] => Ok(Matrix::from_element(1, 1, data[0])),
        [r, c] => Ok(Matrix::from_row_slice(*r, *c, &data)),
        s => Err(format!("expected a matrix, got an array of shape {s:?}")),
    }
}

/// (mean (n,), cov (n, n)) from a pair, checked finite and of dimension `n`.
pub(crate) fn gaussian_of(obj: &Bound<'_, PyAny>, n: usize) -> Result<(Vector, Matrix), String> {
    let (m, c): (Bound<'_, PyAny>, Bound<'_, PyAny>) = obj
        .extract()
        .map_err(|_| "not a pair (mean, cov)".to_string())?;
    let mean = vector_of(&m).map_err(|e| format!("a mean that is not a vector: {e}"))?;
    let cov = matrix_of(&c).map_err(|e| format!("a covariance that is not a matrix: {e}"))?;
    if mean.len() != n || cov.shape() != (n, n) {
        return Err(format!(
            "a mean of {} components and a {}x{} covariance; the state has {n}",
            mean.len(),
            cov.nrows(),
            cov.ncols()
        ));
    }
    if mean.iter().chain(cov.iter()).any(|v| !v.is_finite()) {
        return Err("numbers that are not finite".into());
    }
    Ok((mean, cov))
}

pub(crate) fn matrix_array<'py>(py: Python<'py>, m: &Matrix) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
}

fn pair<'py>(py: Python<'py>, g: &Gaussian) -> (Bound<'py, PyAny>, Bound<'py, PyAny>) {
    (
        PyArray1::from_slice(py, g.mean.as_slice()).into_any(),
        matrix_array(py, &g.cov),
    )
}

/// The system a scheme estimates: x_k = F x_{k-1} + w_k (cov Q), sensor i measures
/// z_k^i = H_i x_k + v_k^i (cov R_i; H_i None for a nonlinear sensor), x_0 ~ N(prior).
#[pyclass(module = "hushfuse._hushfuse", name = "System", frozen)]
pub(crate) struct PySystem {
    pub(crate) system: Arc<System>,
}

impl PySystem {
    pub(crate) fn new(system: Arc<System>) -> Self {
        Self { system }
    }
}

#[pymethods]
impl PySystem {
    #[getter]
    fn n_sensors(&self) -> usize {
        self.system.n_sensors()
    }
    #[getter]
    fn state_dim(&self) -> usize {
        self.system.state_dim()
    }
    /// Measurement dimension per sensor.
    #[getter]
    fn meas_dims(&self) -> Vec<usize> {
        self.system.sensors.iter().map(|s| s.meas_dim()).collect()
    }
    #[getter(F)]
    fn f<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        matrix_array(py, self.system.transition.f())
    }
    #[getter(Q)]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        matrix_array(py, self.system.transition.q())
    }
    /// Per sensor its H (None for a nonlinear sensor).
    #[getter(H)]
    fn h<'py>(&self, py: Python<'py>) -> Vec<Option<Bound<'py, PyAny>>> {
        self.system
            .sensors
            .iter()
            .map(|s| s.as_linear().map(|l| matrix_array(py, l.h())))
            .collect()
    }
    /// Per sensor its noise covariance R.
    #[getter(R)]
    fn r<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyAny>> {
        self.system
            .sensors
            .iter()
            .map(|s| matrix_array(py, s.noise_cov()))
            .collect()
    }
    /// The prior of x_0: (mean, cov).
    #[getter]
    fn prior<'py>(&self, py: Python<'py>) -> (Bound<'py, PyAny>, Bound<'py, PyAny>) {
        pair(py, &self.system.prior)
    }
    fn __repr__(&self) -> String {
        format!(
            "System(state_dim={}, n_sensors={})",
            self.system.state_dim(),
            self.system.n_sensors()
        )
    }
}

/// The library's Kalman arithmetic for a Python center: `predict` (x = F x, P = F P F^T + Q)
/// and one step's fusion in information form, sensor by sensor (`start`, `add` per sensor in
/// order, `finish`), the operations of the built-in event-triggered centers in their order, so
/// that the same calls give the same bits. Nonlinear sensors: sequential EKF updates.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
pub(crate) struct LinearFusion {
    system: Arc<System>,
    /// The fusion, the prediction's work space, the last output, whether a step is started.
    state: Mutex<(Fusion, kf::PredictWork, Gaussian, bool)>,
}

fn gaussian_arg(mean: &Bound<'_, PyAny>, cov: &Bound<'_, PyAny>, n: usize) -> PyResult<Gaussian> {
    let t = pyo3::types::PyTuple::new(mean.py(), [mean, cov])?;
    let (mean, cov) =
        gaussian_of(t.as_any(), n).map_err(|m| PyValueError::new_err(format!("estimate: {m}")))?;
    Ok(Gaussian { mean, cov })
}

fn scheme_err(e: hushfuse::scheme::SchemeError) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

#[pymethods]
impl LinearFusion {
    #[new]
    fn new(system: PyRef<'_, PySystem>) -> Self {
        let s = system.system.clone();
        let n = s.state_dim();
        Self {
            state: Mutex::new((
                Fusion::new(&s),
                kf::PredictWork::new(n),
                s.prior.clone(),
                false,
            )),
            system: s,
        }
    }
    /// The prediction of (mean, cov) one step ahead: (F x, F P F^T + Q).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        mean: &Bound<'py, PyAny>,
        cov: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let est = gaussian_arg(mean, cov, self.system.state_dim())?;
        let mut st = lock(&self.state);
        let (_, work, out, _) = &mut *st;
        kf::predict_into(&self.system.transition, &est, out, work);
        Ok(pair(py, out))
    }
    /// Starts a step's fusion from the prediction (mean, cov).
    fn start(&self, mean: &Bound<'_, PyAny>, cov: &Bound<'_, PyAny>) -> PyResult<()> {
        let pred = gaussian_arg(mean, cov, self.system.state_dim())?;
        let mut st = lock(&self.state);
        st.3 = false;
        st.0.start(&pred).map_err(scheme_err)?;
        st.3 = true;
        Ok(())
    }
    /// Adds sensor `i`'s measurement `z` (noise R_i), or, with `r`, the pseudo-measurement `z`
    /// with noise `r` (a silence read as a measurement).
    #[pyo3(signature = (i, z, r=None))]
    fn add(&self, i: usize, z: &Bound<'_, PyAny>, r: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        if i >= self.system.n_sensors() {
            return Err(PyValueError::new_err(format!(
                "sensor {i}: the system has {} sensors",
                self.system.n_sensors()
            )));
        }
        let z = vector_of(z).map_err(|m| PyValueError::new_err(format!("z: {m}")))?;
        let r = r
            .map(matrix_of)
            .transpose()
            .map_err(|m| PyValueError::new_err(format!("r: {m}")))?;
        let evidence = match &r {
            None => Evidence::Measurement(&z),
            Some(r) => Evidence::Pseudo { z: &z, r },
        };
        let mut st = lock(&self.state);
        if !st.3 {
            return Err(PyRuntimeError::new_err(
                "add() before start(): start the step from the prediction first",
            ));
        }
        st.0.add(&self.system, i, evidence).map_err(scheme_err)
    }
    /// Ends the step: the fused (mean, cov).
    fn finish<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let mut st = lock(&self.state);
        let (fusion, _, out, started) = &mut *st;
        if !*started {
            return Err(PyRuntimeError::new_err(
                "finish() before start(): start the step from the prediction first",
            ));
        }
        *started = false;
        fusion.finish(out).map_err(scheme_err)?;
        Ok(pair(py, out))
    }
}

/// A serde value as the Python object `json.loads` would give (`null` -> `None`), made
/// without text in between.
pub(crate) fn to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_u64(), n.as_i64()) {
            (Some(u), _) => u.into_pyobject(py)?.into_any(),
            (None, Some(i)) => i.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let list = pyo3::types::PyList::empty(py);
            for x in a {
                list.append(to_py(py, x)?)?;
            }
            list.into_any()
        }
        Value::Object(o) => {
            let d = pyo3::types::PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Raised while a Ctrl-C is being handled ([`interruptible`]): Python nodes called after it
/// return an error at once instead of running, so the run winds down.
pub(crate) static INTERRUPTED: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Runs `work` (which gets a stop flag) off the Python thread while this thread, every 50 ms,
/// lets Python handle its signals: a Ctrl-C raises the stop flag and [`INTERRUPTED`], and once
/// `work` has wound down it is raised as `KeyboardInterrupt`. Without this a Ctrl-C during a
/// run whose Python sensor is slow was never seen: the signal handler runs only on the main
/// thread, which waited for the run with the GIL released.
pub(crate) fn interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&std::sync::atomic::AtomicBool) -> T + Send,
) -> PyResult<T> {
    use std::sync::atomic::{AtomicBool, Ordering};
    INTERRUPTED.store(false, Ordering::SeqCst);
    let stop = AtomicBool::new(false);
    let (out, interrupt) = py.allow_threads(|| {
        std::thread::scope(|s| {
            let handle = s.spawn(|| work(&stop));
            let mut interrupt: Option<PyErr> = None;
            while !handle.is_finished() {
                std::thread::sleep(std::time::Duration::from_millis(50));
                if interrupt.is_none() {
                    if let Err(e) = Python::with_gil(|py| py.check_signals()) {
                        stop.store(true, Ordering::SeqCst);
                        INTERRUPTED.store(true, Ordering::SeqCst);
                        interrupt = Some(e);
                    }
                }
            }
            (handle.join(), interrupt)
        })
    });
    INTERRUPTED.store(false, Ordering::SeqCst);
    if let Some(e) = interrupt {
        return Err(e);
    }
    out.map_err(|_| PyRuntimeError::new_err("the run's thread panicked"))
}
