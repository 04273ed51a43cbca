//! `hushfuse.Trial`: one trial of one scheme variant stepped from Python, by the engine's one
//! stepper (`hushfuse::engine::trial::Trial::step`): the same rules as the simulator's loop —
//! sensors, schedule, the link over any network (a multi-hop mesh with every hop drawn and
//! paid, in-network aggregation), fusion and feedback — on readings the caller brings one step
//! at a time.
use crate::{resolve, scenario_err, InputError, RunError};
use hushfuse::engine::seeding;
use hushfuse::engine::trial::{self, Link, LoopBuffers, LoopError, TrialSpec};
use hushfuse::network::topology::tally::NODE_COUNTERS;
use hushfuse::scenario::build::{self, Experiment};
use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Arc, Mutex};

type Stepper = trial::Trial<'static, Arc<Experiment>, Box<LoopBuffers>>;

/// One trial of one variant of a scenario, stepped on the caller's readings.
#[pyclass(module = "hushfuse._hushfuse", frozen)]
pub(crate) struct Trial {
    inner: Mutex<Stepper>,
    exp: Arc<Experiment>,
    label: String,
}

fn loop_err(label: &str, e: LoopError) -> PyErr {
    match e {
        LoopError::Input { .. } => InputError::new_err(e.describe(label)),
        _ => RunError::new_err(e.describe(label)),
    }
}

fn link_name(l: Link) -> &'static str {
    match l {
        Link::Sent => "sent",
        Link::Silent => "silent",
        Link::NotScheduled => "not_scheduled",
        Link::Lost => "lost",
        Link::Late => "late",
    }
}

#[pymethods]
impl Trial {
    /// Trial `trial` of variant `variant` of `scenario` (a built-in name, a path or TOML
    /// text), with the coins and link fates the simulator gives that trial (`seed`: default
    /// the scenario's).
    #[new]
    #[pyo3(signature = (scenario, variant=0, trial=0, seed=None))]
    fn new(scenario: &str, variant: usize, trial: usize, seed: Option<u64>) -> PyResult<Self> {
        let (text, source) = resolve(scenario)?;
        let options = build::LoadOptions {
            seed,
            ..Default::default()
        };
        let exp = Arc::new(build::load_with(&text, &source, &options).map_err(scenario_err)?);
        let Some(v) = exp.variants.get(variant) else {
            return Err(PyValueError::new_err(format!(
                "{source}: variant {variant} does not exist (the scenario has {} variants: 0 to {})",
                exp.variants.len(),
                exp.variants.len() - 1
            )));
        };
        let label = exp.curves[v.curve].label.clone();
        let spec = TrialSpec {
            trial,
            variant,
            stream: seeding::coin_stream(variant),
            available: None,
        };
        let buffers = Box::new(LoopBuffers::new(exp.system.n_sensors()));
        let inner =
            trial::Trial::new(exp.clone(), spec, buffers, true).map_err(|e| loop_err(&label, e))?;
        Ok(Self {
            inner: Mutex::new(inner),
            exp,
            label,
        })
    }

    /// Step `k` (1, 2, … in order) on `readings`, one array per sensor. Returns a dict: `mean`
    /// (n,) and `cov` (n, n) of the fused estimate; per sensor `links` ("sent", "silent",
    /// "not_scheduled", "lost", "late") and `bits`; the step's `traffic` (messages, payload
    /// and frame bits on air over every hop, lost, retransmissions, ACK frames); over a
    /// multi-hop network `nodes`, each node's counters of the step by name.
    fn step<'py>(
        &self,
        py: Python<'py>,
        k: usize,
        readings: Vec<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let readings = readings
            .iter()
            .enumerate()
            .map(|(i, z)| {
                crate::helpers::vector_of(z)
                    .map_err(|m| InputError::new_err(format!("readings[{i}]: {m}")))
            })
            .collect::<PyResult<Vec<_>>>()?;
        if let Some(i) = readings
            .iter()
            .position(|z| z.iter().any(|v| !v.is_finite()))
        {
            return Err(InputError::new_err(format!(
                "readings[{i}] is not finite: {:?}",
                readings[i].as_slice()
            )));
        }
        let mut t = crate::lock(&self.inner);
        let s = t.step(k, &readings).map_err(|e| loop_err(&self.label, e))?;
        let out = PyDict::new(py);
        out.set_item("mean", s.estimate.mean.as_slice().to_vec().into_pyarray(py))?;
        let n = s.estimate.dim();
        let cov = numpy::ndarray::Array2::from_shape_fn((n, n), |(r, c)| s.estimate.cov[(r, c)]);
        out.set_item("cov", cov.into_pyarray(py))?;
        let links: Vec<&str> = s.links.iter().map(|l| link_name(*l)).collect();
        out.set_item("links", links)?;
        out.set_item("bits", s.bits.to_vec())?;
        let tr = &s.traffic;
        let traffic = PyDict::new(py);
        for (key, v) in [
            ("messages", tr.messages),
            ("bits", tr.bits),
            ("frame_bits", tr.frame_bits),
            ("downlink_bits", tr.downlink_bits),
            ("lost", tr.lost),
            ("late", tr.late),
            ("retransmissions", tr.retransmissions),
            ("ack_frames", tr.ack_frames),
        ] {
            traffic.set_item(key, v)?;
        }
        out.set_item("traffic", traffic)?;
        if let Some(net) = &self.exp.network {
            let nodes = PyDict::new(py);
            for (node, counts) in net.nodes.iter().zip(s.nodes) {
                let d = PyDict::new(py);
                for (name, v) in NODE_COUNTERS.iter().zip(counts) {
                    d.set_item(*name, *v)?;
                }
                nodes.set_item(&node.name, d)?;
            }
            out.set_item("nodes", nodes)?;
        }
        Ok(out)
    }

    /// The scheme's label.
    #[getter]
    fn label(&self) -> &str {
        &self.label
    }
    /// Steps of the scenario (the trial's last step).
    #[getter]
    fn steps(&self) -> usize {
        self.exp.steps
    }
    /// Number of sensors (readings per step).
    #[getter]
    fn n_sensors(&self) -> usize {
        self.exp.system.n_sensors()
    }
}
