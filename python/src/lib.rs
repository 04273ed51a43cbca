//! `hushfuse._hushfuse`: the compiled half of the Python package. The Python half
//! (`python/hushfuse/__init__.py`) turns numpy arrays and pandas frames into the command line's
//! CSV layout and the results back into numpy arrays, so that every check and every message is
//! the command line's own.
mod external;
mod helpers;
mod runs;
mod trial;

use hushfuse::engine::replay;
use hushfuse::engine::seeding;
use hushfuse::filter::Gaussian;
use hushfuse::linalg::Vector;
use hushfuse::link;
use hushfuse::network::Schedule;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use hushfuse::scheme;
use numpy::ndarray::{Array2, Array3};
use numpy::IntoPyArray;
use pyo3::create_exception;
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Mutex;

create_exception!(
    _hushfuse,
    InputError,
    PyValueError,
    "Bad input: a scenario or recorded data that cannot be used (the message names the file and where)."
);
create_exception!(
    _hushfuse,
    ScenarioError,
    InputError,
    "A scenario that cannot be read or is inconsistent (the message names the file and the field)."
);
create_exception!(
    _hushfuse,
    DataError,
    InputError,
    "Recorded data that cannot be replayed (the message names the file, line, row and column)."
);
create_exception!(
    _hushfuse,
    RunError,
    PyRuntimeError,
    "A run that failed: a scheme could not take a step (the message names the scheme and the step)."
);

/// The library's message in the words of the Python API: its options are arguments, and it
/// has no `--allow-large`.
pub(crate) fn python_words(message: &str) -> String {
    message
        .replace("(or --trials)", "(or trials=)")
        .replace(", or pass --allow-large", "")
        .replace(" or pass --allow-large", "")
        .replace("--allow-large", "a smaller request")
        .replace(" --out", " out=")
}

/// A scenario error as a Python exception: a request larger than the machine can hold is a
/// `MemoryError` (raised before anything is allocated), anything else a [`ScenarioError`].
pub(crate) fn scenario_err(e: build::ScenarioError) -> PyErr {
    let message = python_words(&e.to_string());
    match e.limit {
        Some(hushfuse::scenario::error::Limit::Memory) => PyMemoryError::new_err(message),
        _ => ScenarioError::new_err(message),
    }
}

/// A scenario's text and source from a built-in name, a path or TOML text.
pub(crate) fn resolve(scenario: &str) -> PyResult<(String, String)> {
    builtin::resolve(scenario, true).map_err(ScenarioError::new_err)
}

/// A scenario's text and source, with `loss` written in as `--loss P` writes it (a Bernoulli
/// link for every sensor and the loss-aware copies of the schemes that have one).
pub(crate) fn resolve_with_loss(scenario: &str, loss: Option<f64>) -> PyResult<(String, String)> {
    let (text, source) = resolve(scenario)?;
    match loss {
        None => Ok((text, source)),
        Some(p) => {
            let text =
                hushfuse::scenario::lossy::with_loss(&text, &source, p).map_err(scenario_err)?;
            Ok((text, source))
        }
    }
}

pub(crate) fn load(
    scenario: &str,
    trials: Option<usize>,
    seed: Option<u64>,
    threads: usize,
    loss: Option<f64>,
) -> PyResult<build::Experiment> {
    let (text, source) = resolve_with_loss(scenario, loss)?;
    load_text(&text, &source, trials, seed, threads)
}

/// [`load`] of a scenario's text.
pub(crate) fn load_text(
    text: &str,
    source: &str,
    trials: Option<usize>,
    seed: Option<u64>,
    threads: usize,
) -> PyResult<build::Experiment> {
    load_text_with(text, source, trials, seed, threads, false)
}

/// The system, data and links of a scenario, without its schemes
/// ([`build::LoadOptions::data_only`]): what drawing a trial needs.
pub(crate) fn load_data(scenario: &str, seed: Option<u64>) -> PyResult<build::Experiment> {
    let (text, source) = resolve_with_loss(scenario, None)?;
    load_text_with(&text, &source, None, seed, 1, true)
}

fn load_text_with(
    text: &str,
    source: &str,
    trials: Option<usize>,
    seed: Option<u64>,
    threads: usize,
    data_only: bool,
) -> PyResult<build::Experiment> {
    let (text, source) = (text.to_string(), source.to_string());
    let kind = build::file_kind(&text, &source).map_err(scenario_err)?;
    if kind == build::FileKind::TableReport {
        return Err(ScenarioError::new_err(format!(
            "{source}: a table report, not a scenario (run it with `hushfuse reproduce`)"
        )));
    }
    let opts = build::LoadOptions {
        trials,
        seed,
        threads,
        limits: None,
        data_only,
    };
    build::load_with(&text, &source, &opts).map_err(scenario_err)
}

pub(crate) fn vectors_to_array2(rows: &[Vector], cols: usize) -> Array2<f64> {
    let mut a = Array2::zeros((rows.len(), cols));
    for (k, v) in rows.iter().enumerate() {
        for (j, x) in v.iter().enumerate() {
            a[(k, j)] = *x;
        }
    }
    a
}

pub(crate) fn estimates_arrays(ests: &[Gaussian], n: usize) -> (Array2<f64>, Array3<f64>) {
    let mut mean = Array2::zeros((ests.len(), n));
    let mut cov = Array3::zeros((ests.len(), n, n));
    for (k, e) in ests.iter().enumerate() {
        for i in 0..n {
            mean[(k, i)] = e.mean[i];
            for j in 0..n {
                cov[(k, i, j)] = e.cov[(i, j)];
            }
        }
    }
    (mean, cov)
}

/// What one sensor put on the network at one step.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
pub(crate) struct Transmission {
    pub(crate) inner: link::Transmission,
}

#[pymethods]
impl Transmission {
    /// A silence (the sensor chose not to send).
    #[staticmethod]
    fn silent() -> Self {
        Self {
            inner: link::Transmission::Silent,
        }
    }
    /// A measurement z (a number, a list or an array), 32 bits per component.
    #[staticmethod]
    fn measurement(z: &Bound<'_, PyAny>) -> PyResult<Self> {
        let z = external::measurement_like(z, "measurement")?;
        Ok(Self {
            inner: link::Transmission::Send(link::Message::Measurement(z)),
        })
    }
    /// A state estimate x (a number, a list or an array), 32 bits per component.
    #[staticmethod]
    fn estimate(x: &Bound<'_, PyAny>) -> PyResult<Self> {
        let x = external::measurement_like(x, "estimate")?;
        Ok(Self {
            inner: link::Transmission::Send(link::Message::Estimate(x)),
        })
    }
    /// A quantization index 0 <= index < 2^bits sent in `bits` payload bits (1..=64), in an
    /// 802.15.4 frame (least significant octet first).
    #[staticmethod]
    fn quantized_index(index: u64, bits: u32) -> PyResult<Self> {
        if !(1..=64).contains(&bits) || (bits < 64 && index >> bits != 0) {
            return Err(PyValueError::new_err(format!(
                "quantized index {index} in {bits} bits: expected 1 <= bits <= 64 and 0 <= index < 2^bits"
            )));
        }
        let octets = (bits as usize).div_ceil(8);
        Self::payload(&index.to_le_bytes()[..octets], bits)
    }
    /// A raw payload: `data` (bytes) carrying `bits` payload bits (len(data) = ceil(bits / 8),
    /// unused high bits of the last octet zero), in an 802.15.4 frame.
    #[staticmethod]
    fn payload(data: &[u8], bits: u32) -> PyResult<Self> {
        let m = hushfuse::scheme::external::payload_message(data, bits, 0)
            .map_err(PyValueError::new_err)?;
        Ok(Self {
            inner: link::Transmission::Send(m),
        })
    }
    /// Whether a message was sent.
    #[getter]
    fn sent(&self) -> bool {
        matches!(self.inner, link::Transmission::Send(_))
    }
    /// "silent", "measurement", "estimate" or "frame".
    #[getter]
    fn kind(&self) -> &'static str {
        match &self.inner {
            link::Transmission::Silent => "silent",
            link::Transmission::Send(link::Message::Measurement(_)) => "measurement",
            link::Transmission::Send(link::Message::Estimate(_)) => "estimate",
            link::Transmission::Send(link::Message::Frame { .. }) => "frame",
        }
    }
    /// Payload bits (0 for a silence), counted as the simulator counts them.
    #[getter]
    fn bits(&self) -> u64 {
        match &self.inner {
            link::Transmission::Silent => 0,
            link::Transmission::Send(m) => m.bits(),
        }
    }
    /// Bits of the whole 802.15.4 MAC frame that carries the message (0 for a silence).
    #[getter]
    fn frame_bits(&self) -> u64 {
        match &self.inner {
            link::Transmission::Silent => 0,
            link::Transmission::Send(m) => m.frame_bits(),
        }
    }
    /// The sent vector (measurement or estimate) as a numpy array, the octets of a frame as
    /// bytes, or None for a silence.
    #[getter]
    fn value<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        Ok(match &self.inner {
            link::Transmission::Silent => None,
            link::Transmission::Send(link::Message::Measurement(v))
            | link::Transmission::Send(link::Message::Estimate(v)) => {
                Some(v.as_slice().to_vec().into_pyarray(py).into_any())
            }
            link::Transmission::Send(link::Message::Frame { octets, .. }) => {
                Some(PyBytes::new(py, octets).into_any())
            }
        })
    }
    fn __repr__(&self) -> String {
        format!("Transmission(kind={:?}, bits={})", self.kind(), self.bits())
    }
}

/// What the fusion center tells the sensors before the next step (schemes with feedback).
#[pyclass(module = "hushfuse._hushfuse", frozen)]
pub(crate) struct Feedback {
    pub(crate) inner: scheme::Feedback,
}

#[pymethods]
impl Feedback {
    /// "prediction" or "innovation_reference".
    #[getter]
    fn kind(&self) -> &'static str {
        match self.inner {
            scheme::Feedback::Prediction { .. } => "prediction",
            scheme::Feedback::InnovationReference(_) => "innovation_reference",
        }
    }
    /// Downlink bits of this feedback, as the simulator counts them.
    fn bits(&self, n_sensors: usize) -> u64 {
        self.inner.bits(n_sensors)
    }
    fn __repr__(&self) -> String {
        format!("Feedback(kind={:?})", self.kind())
    }
    /// The fused prediction as feedback (to every sensor): mean and, optionally, covariance
    /// (downlink: 32 bits per number, the covariance as its distinct entries).
    #[staticmethod]
    #[pyo3(signature = (mean, cov=None))]
    fn prediction(mean: &Bound<'_, PyAny>, cov: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let mean = external::measurement_like(mean, "mean")?;
        let cov = cov.map(|c| external::matrix_like(c, "cov")).transpose()?;
        Ok(Self {
            inner: scheme::Feedback::Prediction { mean, cov },
        })
    }
    /// A prediction's mean (None for other feedback).
    #[getter]
    fn mean<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        match &self.inner {
            scheme::Feedback::Prediction { mean, .. } => {
                Some(mean.as_slice().to_vec().into_pyarray(py).into_any())
            }
            _ => None,
        }
    }
    /// A prediction's covariance (None when it has none).
    #[getter]
    fn cov<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        match &self.inner {
            scheme::Feedback::Prediction { cov: Some(c), .. } => Some(helpers::matrix_array(py, c)),
            _ => None,
        }
    }
}

/// The sensor side of a scheme: one node, one step per call.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
struct SensorNode {
    /// The last step taken (0: none yet): steps must increase.
    last: Mutex<usize>,
    node: Mutex<Box<dyn scheme::SensorNode>>,
    /// The sensor's own coins ([`seeding::sensor_coins`]).
    rng: Mutex<Xoshiro256PlusPlus>,
    index: usize,
    dim: usize,
}

pub(crate) fn lock<T: ?Sized>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

#[pymethods]
impl SensorNode {
    /// Processes measurement `z` of step `k` (k >= 1) with the fusion center's feedback of
    /// step k - 1 (None if the scheme has none) and returns what the sensor transmits.
    #[pyo3(signature = (k, z, feedback=None))]
    fn step(
        &self,
        k: usize,
        z: &Bound<'_, PyAny>,
        feedback: Option<PyRef<'_, Feedback>>,
    ) -> PyResult<Transmission> {
        let z = helpers::vector_of(z).map_err(|m| PyValueError::new_err(format!("z: {m}")))?;
        if z.len() != self.dim {
            return Err(PyValueError::new_err(format!(
                "sensor {}: z has {} components, the sensor measures {}",
                self.index,
                z.len(),
                self.dim
            )));
        }
        if k == 0 {
            return Err(PyValueError::new_err("steps count from k = 1"));
        }
        if z.iter().any(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "sensor {}: z is not finite: {:?}",
                self.index,
                z.as_slice()
            )));
        }
        let mut last = lock(&self.last);
        if k <= *last {
            return Err(PyValueError::new_err(format!(
                "sensor {}: step k = {k} after step {}: a sensor's steps must increase (it may skip steps it is not scheduled at)",
                self.index, *last
            )));
        }
        let fb = feedback.as_ref().map(|f| &f.inner);
        let mut rng = lock(&self.rng);
        let t = lock(&self.node)
            .step(k, &z, fb, &mut *rng)
            .map_err(|e| RunError::new_err(format!("sensor {}, step {k}: {e}", self.index)))?;
        *last = k;
        Ok(Transmission { inner: t })
    }
    /// Index of the sensor in the scenario.
    #[getter]
    fn index(&self) -> usize {
        self.index
    }
    /// Number of measurement components.
    #[getter]
    fn dim(&self) -> usize {
        self.dim
    }
}

/// The fusion side of a scheme: fuses what arrived and what the silences say.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
struct FusionCenter {
    /// The last step fused (0: none yet): the center takes k = 1, 2, 3, ... in order.
    last: Mutex<usize>,
    center: Mutex<Box<dyn scheme::FusionCenter>>,
    n_sensors: usize,
}

#[pymethods]
impl FusionCenter {
    /// Fuses the inbox of step `k`: one entry per sensor, in sensor order, each a
    /// `Transmission` (what the sensor sent, or its silence) or None (the sensor was not
    /// scheduled or had no reading).
    fn step(&self, k: usize, inbox: Vec<Option<PyRef<'_, Transmission>>>) -> PyResult<()> {
        if inbox.len() != self.n_sensors {
            return Err(PyValueError::new_err(format!(
                "inbox has {} entries, the scheme has {} sensors",
                inbox.len(),
                self.n_sensors
            )));
        }
        if k == 0 {
            return Err(PyValueError::new_err("steps count from k = 1"));
        }
        let mut last = lock(&self.last);
        if k != *last + 1 {
            return Err(PyValueError::new_err(format!(
                "fusion center: step k = {k} after step {}: the center takes every step in order (k = {} next); pass None for a sensor that did not report",
                *last,
                *last + 1
            )));
        }
        let inbox: Vec<link::Received> = inbox
            .iter()
            .map(|t| match t {
                Some(t) => t.inner.clone().into(),
                None => link::Received::NotScheduled,
            })
            .collect();
        lock(&self.center)
            .step(k, &inbox)
            .map_err(|e| RunError::new_err(format!("fusion center, step {k}: {e}")))?;
        *last = k;
        Ok(())
    }
    /// The fused estimate after the last step (the prior before the first): (mean (n,),
    /// covariance (n, n)).
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let c = lock(&self.center);
        let e = c.estimate();
        let (mean, cov) = estimates_arrays(std::slice::from_ref(e), e.dim());
        let mean = mean
            .into_shape_with_order(e.dim())
            .map_err(|x| RunError::new_err(x.to_string()))?;
        let cov = cov
            .into_shape_with_order((e.dim(), e.dim()))
            .map_err(|x| RunError::new_err(x.to_string()))?;
        Ok((
            mean.into_pyarray(py).into_any(),
            cov.into_pyarray(py).into_any(),
        ))
    }
    /// Feedback for the sensors' next step as they receive it (every number a single, as
    /// priced and as the simulator delivers it), or None.
    fn feedback(&self) -> Option<Feedback> {
        lock(&self.center)
            .feedback()
            .map(|f| Feedback { inner: f.as_sent() })
    }
    /// Effective sample size of the particle weights after the last update (particle filters),
    /// or None.
    fn ess(&self) -> Option<f64> {
        lock(&self.center).ess()
    }
}

/// One variant of a scenario, built as the simulator builds it for one trial: its sensor
/// nodes, its fusion center and its schedule, with the coins of (seed, trial, variant), so a
/// loop that steps the sensors in order and then the center reproduces the simulator.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
struct Scheme {
    sensors: Vec<Py<SensorNode>>,
    center: Py<FusionCenter>,
    label: String,
    kind: String,
    variant: usize,
    schedule: Schedule,
    steps: usize,
    state_dim: usize,
}

#[pymethods]
impl Scheme {
    /// Builds variant `variant` of `scenario` (a built-in name, a path or TOML text) for
    /// `steps` steps (default: the scenario's), with the coins of trial `trial` of `seed`
    /// (default: the scenario's seed).
    #[new]
    #[pyo3(signature = (scenario, variant=0, trial=0, seed=None, steps=None))]
    fn new(
        py: Python<'_>,
        scenario: &str,
        variant: usize,
        trial: usize,
        seed: Option<u64>,
        steps: Option<usize>,
    ) -> PyResult<Self> {
        let (text, source) = resolve(scenario)?;
        let exp = match steps {
            Some(t) => {
                replay::load_experiment(&text, &source, t, seed, &build::LoadOptions::default())
                    .map(|(e, _)| e)
            }
            None => build::load_with(
                &text,
                &source,
                &build::LoadOptions {
                    seed,
                    ..Default::default()
                },
            ),
        }
        .map_err(scenario_err)?;
        if exp.network.is_some() {
            return Err(PyValueError::new_err(format!(
                "{source}: a multi-hop [network] is not supported by the step-by-step Scheme (its sensors and center are the star's pieces, and the network between them is yours); hushfuse.Trial steps a trial over the network, hushfuse.run runs it"
            )));
        }
        let Some(v) = exp.variants.get(variant) else {
            return Err(PyValueError::new_err(format!(
                "{source}: variant {variant} does not exist (the scenario has {} variants: 0 to {})",
                exp.variants.len(),
                exp.variants.len() - 1
            )));
        };
        // The engine's seeding rule: a notebook's loop draws the coins the runner draws.
        let n_sensors = exp.system.n_sensors();
        let (coins, center_seed) =
            seeding::coins(exp.seed, trial, seeding::coin_stream(variant), n_sensors);
        let inst = v
            .scheme
            .build_with_seed(center_seed)
            .map_err(|e| RunError::new_err(e.to_string()))?;
        let sensors = inst
            .sensors
            .into_iter()
            .zip(coins)
            .enumerate()
            .map(|(i, (node, rng))| {
                Py::new(
                    py,
                    SensorNode {
                        last: Mutex::new(0),
                        node: Mutex::new(node),
                        rng: Mutex::new(rng),
                        index: i,
                        dim: exp.system.sensors[i].meas_dim(),
                    },
                )
            })
            .collect::<PyResult<Vec<_>>>()?;
        let center = Py::new(
            py,
            FusionCenter {
                last: Mutex::new(0),
                center: Mutex::new(inst.center),
                n_sensors: exp.system.n_sensors(),
            },
        )?;
        Ok(Self {
            sensors,
            center,
            label: exp.curves[v.curve].label.clone(),
            kind: v.kind.to_string(),
            variant,
            schedule: v.scheme.schedule(),
            steps: exp.steps,
            state_dim: exp.system.state_dim(),
        })
    }
    /// The sensor nodes, in sensor order.
    #[getter]
    fn sensors(&self, py: Python<'_>) -> Vec<Py<SensorNode>> {
        self.sensors.iter().map(|s| s.clone_ref(py)).collect()
    }
    /// The fusion center.
    #[getter]
    fn center(&self, py: Python<'_>) -> Py<FusionCenter> {
        self.center.clone_ref(py)
    }
    #[getter]
    fn label(&self) -> &str {
        &self.label
    }
    #[getter]
    fn kind(&self) -> &str {
        &self.kind
    }
    #[getter]
    fn variant(&self) -> usize {
        self.variant
    }
    /// Steps the scheme was built for (its precomputed horizon).
    #[getter]
    fn steps(&self) -> usize {
        self.steps
    }
    #[getter]
    fn state_dim(&self) -> usize {
        self.state_dim
    }
    /// Whether the network lets sensor `i` send at step `k` (round-robin schemes: one sensor
    /// per step). A sensor not allowed must not be stepped; its inbox entry is None.
    fn allows(&self, k: usize, i: usize) -> bool {
        self.schedule.allows(k, i, self.sensors.len())
    }
    fn __repr__(&self) -> String {
        format!(
            "Scheme(label={:?}, kind={:?}, variant={}, sensors={})",
            self.label,
            self.kind,
            self.variant,
            self.sensors.len()
        )
    }
}

/// Lists every variant of a scenario: (label, kind, params).
#[pyfunction]
fn variants<'py>(
    py: Python<'py>,
    scenario: &str,
) -> PyResult<Vec<(String, String, Bound<'py, PyAny>)>> {
    let exp = load(scenario, None, None, 0, None)?;
    exp.variants
        .iter()
        .map(|v| {
            Ok((
                exp.curves[v.curve].label.clone(),
                v.kind.to_string(),
                runs::serialize(py, &v.params)?,
            ))
        })
        .collect()
}

/// The names of the built-in scenarios with their one-line descriptions.
#[pyfunction]
fn builtins() -> Vec<(&'static str, &'static str)> {
    builtin::BUILTIN.iter().map(|(n, d, _)| (*n, *d)).collect()
}

#[pymodule]
fn _hushfuse(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("ScenarioError", py.get_type::<ScenarioError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add("RunError", py.get_type::<RunError>())?;
    m.add_function(wrap_pyfunction!(runs::run, m)?)?;
    m.add_function(wrap_pyfunction!(runs::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(runs::replay_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(runs::replay_csv, m)?)?;
    m.add_function(wrap_pyfunction!(variants, m)?)?;
    m.add_function(wrap_pyfunction!(builtins, m)?)?;
    m.add_class::<Scheme>()?;
    m.add_class::<trial::Trial>()?;
    m.add_class::<SensorNode>()?;
    m.add_class::<FusionCenter>()?;
    m.add_class::<Transmission>()?;
    m.add_class::<Feedback>()?;
    m.add_class::<external::PyReceived>()?;
    m.add_class::<helpers::PySystem>()?;
    m.add_class::<helpers::LinearFusion>()?;
    m.add_function(wrap_pyfunction!(external::register_scheme, m)?)?;
    m.add_function(wrap_pyfunction!(external::unregister_scheme, m)?)?;
    m.add_function(wrap_pyfunction!(external::registered_schemes, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
