//! Schemes written in Python: the library's external scheme kinds
//! ([`hushfuse::scheme::external`]) whose sensor nodes and fusion center are Python objects.
//! `hushfuse.register` (in `__init__.py`) declares a kind here with a factory; the engine then
//! builds, per trial, fresh Python objects through it and drives them with the same truth,
//! noise, schedule and link as every other scheme.
//!
//! **Threads and the GIL.** The engine's worker threads run trials in parallel; every call into
//! a Python object (a sensor's `step`, the center's `step` / `estimate` / `feedback`) takes the
//! GIL for that call only, so Python code runs one call at a time. Each trial has its own
//! objects, built by the factory with the trial's index and a seed derived from (seed, trial,
//! variant) by the engine's seeding rule, from which the Python side seeds one
//! `numpy.random.Generator` per object: a trial's numbers depend on nothing else, so results
//! are the same for any thread count (as long as user code keeps no state outside its objects).
use crate::helpers::{self, PySystem};
use crate::{Feedback, Transmission};
use hushfuse::filter::Gaussian;
use hushfuse::linalg::{Matrix, Vector};
use hushfuse::link::{self, Received};
use hushfuse::scheme::external::{self, Declaration};
use hushfuse::scheme::registry::{Bound as KnobBound, Direction, Knob, ParamError, Scale};
use hushfuse::scheme::{self, SchemeError, SchemeInstance, System};
use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};
use rand::RngCore;
use std::sync::{Arc, OnceLock};

/// An exception of user code in words: "ExcType: message" and the Python traceback.
pub(crate) fn describe(py: Python<'_>, e: &PyErr) -> String {
    let formatted = py.import("traceback").and_then(|tb| {
        let lines = tb.call_method1(
            "format_exception",
            (e.get_type(py), e.value(py), e.traceback(py)),
        )?;
        let lines: Vec<String> = lines.extract()?;
        Ok(lines.concat())
    });
    match formatted {
        Ok(t) => t.trim_end().to_string(),
        Err(_) => e.to_string(),
    }
}

/// Whose user code failed, for its error (the engine adds the trial and the step).
#[derive(Debug, Clone)]
struct Origin {
    kind: Arc<str>,
}

impl Origin {
    fn fail(&self, py: Python<'_>, what: &str, e: &PyErr) -> SchemeError {
        SchemeError::Unsupported(format!(
            "Python scheme {:?}: {what} raised {}\n{}",
            self.kind,
            e.get_type(py)
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default(),
            describe(py, e)
        ))
    }
    fn bad(&self, what: &str, message: String) -> SchemeError {
        SchemeError::Unsupported(format!("Python scheme {:?}: {what} {message}", self.kind))
    }
}

/// A registered Python scheme, configured by one scheme table.
struct PyScheme {
    kind: Arc<str>,
    factory: Arc<Py<PyAny>>,
    params: serde_json::Value,
    system: Arc<System>,
    view: OnceLock<Py<PySystem>>,
}

impl std::fmt::Debug for PyScheme {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PyScheme")
            .field("kind", &self.kind)
            .field("params", &self.params)
            .finish_non_exhaustive()
    }
}

impl PyScheme {
    fn make(&self, trial: Option<usize>, seed: u64) -> Result<SchemeInstance, SchemeError> {
        let origin = Origin {
            kind: self.kind.clone(),
        };
        Python::with_gil(|py| {
            let view = match self.view.get() {
                Some(v) => v.clone_ref(py),
                None => {
                    let v = Py::new(py, PySystem::new(self.system.clone()))
                        .map_err(|e| origin.fail(py, "describing the system", &e))?;
                    let _ = self.view.set(v.clone_ref(py));
                    v
                }
            };
            let params = crate::helpers::to_py(py, &self.params)
                .map_err(|e| origin.fail(py, "reading the parameters", &e))?;
            let made = self
                .factory
                .bind(py)
                .call1((params, view, trial, seed))
                .map_err(|e| origin.fail(py, "building the sensors and the center", &e))?;
            let (sensors, center): (Vec<Py<PyAny>>, Py<PyAny>) = made
                .extract()
                .map_err(|e| origin.fail(py, "the factory", &e))?;
            let n = self.system.n_sensors();
            if sensors.len() != n {
                return Err(origin.bad(
                    "the factory",
                    format!("made {} sensor nodes for {n} sensors", sensors.len()),
                ));
            }
            let mut center = PyCenter {
                obj: center,
                origin: origin.clone(),
                est: self.system.prior.clone(),
                feedback: None,
            };
            center.refresh(py, 0)?;
            let sensors = sensors
                .into_iter()
                .enumerate()
                .map(|(i, obj)| {
                    Box::new(PySensor {
                        obj,
                        origin: origin.clone(),
                        index: i,
                    }) as Box<dyn scheme::SensorNode>
                })
                .collect();
            Ok(SchemeInstance {
                sensors,
                center: Box::new(center),
            })
        })
    }
}

impl scheme::Scheme for PyScheme {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        self.make(None, 0)
    }
    fn build_with_seed(&self, seed: u64) -> Result<SchemeInstance, SchemeError> {
        self.make(None, seed)
    }
    fn build_for_trial(&self, trial: usize, seed: u64) -> Result<SchemeInstance, SchemeError> {
        self.make(Some(trial), seed)
    }
}

/// An error once Ctrl-C was pressed ([`helpers::INTERRUPTED`]): the run winds down without
/// calling Python again.
fn interrupted() -> Result<(), SchemeError> {
    match helpers::INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        true => Err(SchemeError::Unsupported("interrupted (Ctrl-C)".into())),
        false => Ok(()),
    }
}

/// A Python sensor node.
struct PySensor {
    obj: Py<PyAny>,
    origin: Origin,
    index: usize,
}

impl scheme::SensorNode for PySensor {
    fn step(
        &mut self,
        k: usize,
        z: &Vector,
        feedback: Option<&scheme::Feedback>,
        _rng: &mut dyn RngCore,
    ) -> Result<link::Transmission, SchemeError> {
        let what = || format!("sensor {}.step(k={k})", self.index);
        interrupted()?;
        Python::with_gil(|py| {
            let z = PyArray1::from_slice(py, z.as_slice());
            let fb = feedback.map(|f| Feedback { inner: f.clone() });
            let out = self
                .obj
                .bind(py)
                .call_method1("step", (k, z, fb))
                .map_err(|e| self.origin.fail(py, &what(), &e))?;
            if out.is_none() {
                return Ok(link::Transmission::Silent);
            }
            match out.downcast::<Transmission>() {
                Ok(t) => Ok(t.get().inner.clone()),
                Err(_) => Err(self.origin.bad(
                    &what(),
                    format!(
                        "returned a {}; expected a message (hushfuse.Measurement, Estimate, QuantizedIndex, Payload) or hushfuse.Silence() / None",
                        out.get_type().name().map(|n| n.to_string()).unwrap_or_default()
                    ),
                )),
            }
        })
    }
}

/// A Python fusion center; its estimate and feedback are read after every step.
struct PyCenter {
    obj: Py<PyAny>,
    origin: Origin,
    est: Gaussian,
    feedback: Option<scheme::Feedback>,
}

impl PyCenter {
    /// Reads `estimate()` (and `feedback()`, when the object has one) after step `k`.
    fn refresh(&mut self, py: Python<'_>, k: usize) -> Result<(), SchemeError> {
        let obj = self.obj.bind(py);
        let what = format!("center.estimate() after step {k}");
        let e = obj
            .call_method0("estimate")
            .map_err(|e| self.origin.fail(py, &what, &e))?;
        let (mean, cov) = helpers::gaussian_of(&e, self.est.dim())
            .map_err(|m| self.origin.bad(&what, format!("returned {m}")))?;
        self.est = Gaussian { mean, cov };
        if obj.hasattr("feedback").unwrap_or(false) {
            let what = format!("center.feedback() after step {k}");
            let f = obj
                .call_method0("feedback")
                .map_err(|e| self.origin.fail(py, &what, &e))?;
            self.feedback = if f.is_none() {
                None
            } else {
                Some(
                    f.downcast::<Feedback>()
                        .map_err(|_| {
                            self.origin.bad(
                                &what,
                                "returned neither None nor a hushfuse.Feedback".into(),
                            )
                        })?
                        .get()
                        .inner
                        .clone(),
                )
            };
        }
        Ok(())
    }
}

impl scheme::FusionCenter for PyCenter {
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        interrupted()?;
        Python::with_gil(|py| {
            let list = PyList::empty(py);
            for r in inbox {
                let item = Py::new(py, PyReceived { inner: r.clone() })
                    .map_err(|e| self.origin.fail(py, "building the inbox", &e))?;
                list.append(item)
                    .map_err(|e| self.origin.fail(py, "building the inbox", &e))?;
            }
            let what = format!("center.step(k={k})");
            self.obj
                .bind(py)
                .call_method1("step", (k, list))
                .map_err(|e| self.origin.fail(py, &what, &e))?;
            self.refresh(py, k)
        })
    }
    fn estimate(&self) -> &Gaussian {
        &self.est
    }
    fn feedback(&self) -> Option<scheme::Feedback> {
        self.feedback.clone()
    }
}

/// What the fusion center finds from one sensor at one step.
#[pyclass(module = "hushfuse._hushfuse", name = "Received", frozen)]
pub(crate) struct PyReceived {
    inner: Received,
}

#[pymethods]
impl PyReceived {
    /// "silent" (the sensor chose not to send, or its packet was lost), "not_scheduled",
    /// "measurement", "estimate" or "payload" (a QuantizedIndex or Payload message).
    #[getter]
    fn kind(&self) -> &'static str {
        match self.inner {
            Received::Silent => "silent",
            Received::NotScheduled => "not_scheduled",
            Received::Measurement(_) => "measurement",
            Received::Estimate(_) => "estimate",
            Received::Frame(_) => "payload",
        }
    }
    /// Whether something arrived.
    #[getter]
    fn arrived(&self) -> bool {
        matches!(
            self.inner,
            Received::Measurement(_) | Received::Estimate(_) | Received::Frame(_)
        )
    }
    /// The measurement or estimate as a numpy array, a payload's octets as bytes, or None.
    #[getter]
    fn value<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        Ok(match &self.inner {
            Received::Measurement(v) | Received::Estimate(v) => {
                Some(PyArray1::from_slice(py, v.as_slice()).into_any())
            }
            Received::Frame(octets) => Some(PyBytes::new(py, payload_of(octets)?).into_any()),
            _ => None,
        })
    }
    /// A payload's octets read as one unsigned integer, least significant octet first (the
    /// index of a QuantizedIndex), or None.
    #[getter]
    fn index(&self) -> PyResult<Option<u64>> {
        Ok(match &self.inner {
            Received::Frame(octets) => Some(
                payload_of(octets)?
                    .iter()
                    .rev()
                    .fold(0u64, |acc, b| (acc << 8) | u64::from(*b)),
            ),
            _ => None,
        })
    }
    fn __repr__(&self) -> String {
        format!("Received(kind={:?})", self.kind())
    }
}

fn payload_of(octets: &[u8]) -> PyResult<&[u8]> {
    external::frame_payload(octets)
        .ok_or_else(|| PyValueError::new_err("a corrupt frame (its check sum does not match)"))
}

/// The knob of a declaration: (name, lo, hi or None, "linear" | "log", integer, grows:
/// "more_bits" | "fewer_bits").
type KnobArgs = (String, f64, Option<f64>, String, bool, String);

fn knob_of(k: KnobArgs) -> PyResult<Knob> {
    let (name, lo, hi, scale, integer, grows) = k;
    if !lo.is_finite() || hi.is_some_and(|h| !(h.is_finite() && h > lo)) {
        return Err(PyValueError::new_err(format!(
            "knob {name:?}: expected finite lo < hi (hi None: open), got lo = {lo}, hi = {hi:?}"
        )));
    }
    let scale = match scale.as_str() {
        "linear" => Scale::Linear,
        "log" if lo > 0.0 => Scale::Log,
        "log" => {
            return Err(PyValueError::new_err(format!(
                "knob {name:?}: a log scale needs lo > 0"
            )))
        }
        s => {
            return Err(PyValueError::new_err(format!(
                "knob {name:?}: scale {s:?}; expected \"linear\" or \"log\""
            )))
        }
    };
    let grows = match grows.as_str() {
        "more_bits" => Direction::MoreBits,
        "fewer_bits" => Direction::FewerBits,
        g => {
            return Err(PyValueError::new_err(format!(
                "knob {name:?}: grows {g:?}; expected \"more_bits\" or \"fewer_bits\""
            )))
        }
    };
    Ok(Knob {
        name: Box::leak(name.into_boxed_str()),
        lo: KnobBound::Fixed(lo),
        hi: hi.map_or(KnobBound::Open, KnobBound::Fixed),
        scale,
        integer,
        grows,
    })
}

/// Declares (or replaces) the Python scheme kind `kind`: its parameters (name, default as
/// TOML text or None when required, meaning), its knob, and `factory(params, system, trial,
/// seed) -> (sensors, center)`.
#[pyfunction]
#[pyo3(signature = (kind, label, summary, params, knob, factory))]
pub(crate) fn register_scheme(
    kind: String,
    label: String,
    summary: String,
    params: Vec<(String, Option<String>, String)>,
    knob: Option<KnobArgs>,
    factory: Py<PyAny>,
) -> PyResult<()> {
    let knob = knob.map(knob_of).transpose()?;
    let names: Vec<String> = params.iter().map(|(n, _, _)| n.clone()).collect();
    let required: Vec<String> = params
        .iter()
        .filter(|(_, d, _)| d.is_none())
        .map(|(n, _, _)| n.clone())
        .collect();
    let example = params
        .iter()
        .filter_map(|(n, d, _)| d.as_ref().map(|d| format!("{n} = {d}")))
        .collect::<Vec<_>>()
        .join("\n");
    let factory = Arc::new(factory);
    let kind_arc: Arc<str> = Arc::from(kind.as_str());
    let builder: external::Builder = Arc::new(move |table, cx| {
        if let Some(bad) = table.keys().find(|k| !names.contains(k)) {
            return Err(ParamError::at(
                bad.clone(),
                format!(
                    "unknown parameter of {kind_arc}; expected one of: {}",
                    names.join(", ")
                ),
            ));
        }
        if let Some(missing) = required.iter().find(|r| !table.contains_key(*r)) {
            return Err(ParamError::at(
                missing.clone(),
                format!("{kind_arc} needs the parameter `{missing}`"),
            ));
        }
        let params = serde_json::to_value(&table).map_err(|e| ParamError::whole(e.to_string()))?;
        Ok(Box::new(PyScheme {
            kind: kind_arc.clone(),
            factory: factory.clone(),
            params,
            system: cx.system.clone(),
            view: OnceLock::new(),
        }))
    });
    external::register(Declaration {
        kind,
        label,
        summary,
        params: params
            .into_iter()
            .map(|(n, d, m)| (n, d.unwrap_or_else(|| "required".into()), m))
            .collect(),
        knob,
        example,
        builder,
    })
    .map_err(PyValueError::new_err)
}

/// Removes a Python scheme kind; whether it was registered.
#[pyfunction]
pub(crate) fn unregister_scheme(kind: &str) -> bool {
    external::unregister(kind)
}

/// The registered Python scheme kinds.
#[pyfunction]
pub(crate) fn registered_schemes() -> Vec<&'static str> {
    external::kinds()
}

/// Whether a summary's scheme of kind `kind` is a Python one.
pub(crate) fn is_python_kind(kind: &str) -> bool {
    external::is_external(kind)
}

/// Stepping objects for `Transmission` constructors: the message types of the library.
pub(crate) fn measurement_like(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vector> {
    let v = helpers::vector_of(obj).map_err(|m| PyValueError::new_err(format!("{what}: {m}")))?;
    Ok(v)
}

/// A matrix argument (list of rows, numpy array or scalar for 1 x 1).
pub(crate) fn matrix_like(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Matrix> {
    helpers::matrix_of(obj).map_err(|m| PyValueError::new_err(format!("{what}: {m}")))
}
