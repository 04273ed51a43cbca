//! Runs, replays and simulated trials for Python: numpy arrays in and out, results as Python
//! objects (never JSON or CSV text in between), and the engine's own run layer
//! ([`hushfuse::output::run`]) for output folders, resuming and shards.
use crate::external;
use crate::helpers::to_py;
use crate::{
    estimates_arrays, python_words, resolve, vectors_to_array2, DataError, RunError, ScenarioError,
};
use hushfuse::engine::calibrate;
use hushfuse::engine::replay::{self, arrays};
use hushfuse::engine::runner;
use hushfuse::linalg::Vector;
use hushfuse::metrics::results;
use hushfuse::output::durable;
use hushfuse::output::run as engine_run;
use hushfuse::output::{arena_files, run_files, OutputDir};
use hushfuse::scenario::build;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::exceptions::PyMemoryError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

pub(crate) fn serialize<'py>(
    py: Python<'py>,
    x: &impl serde::Serialize,
) -> PyResult<Bound<'py, PyAny>> {
    let v = serde_json::to_value(x).map_err(|e| RunError::new_err(e.to_string()))?;
    to_py(py, &v)
}

/// The summary of a run as Python objects, with the `paper` section of `summary.json` when
/// the scenario reproduces a paper.
fn summary_object<'py>(
    py: Python<'py>,
    exp: &build::Experiment,
    summary: &results::Summary,
) -> PyResult<Bound<'py, PyAny>> {
    let out = serialize(py, summary)?;
    if let Some(paper) = run_files::paper_section(exp, summary) {
        out.set_item("paper", serialize(py, &paper)?)?;
    }
    Ok(out)
}

fn check_finite(bad: Vec<String>) -> PyResult<()> {
    if bad.is_empty() {
        return Ok(());
    }
    Err(RunError::new_err(format!(
        "the run produced numbers that are not finite, so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
        bad.join("\n  ")
    )))
}

fn run_failure(e: engine_run::RunFailure) -> PyErr {
    match e {
        engine_run::RunFailure::Input(m) => ScenarioError::new_err(python_words(&m)),
        engine_run::RunFailure::TooLarge(m) => PyMemoryError::new_err(python_words(&m)),
        engine_run::RunFailure::Run(m) => RunError::new_err(m),
        stopped @ engine_run::RunFailure::Interrupted { .. } => {
            RunError::new_err(format!("{stopped}; continue with run(..., resume=True)"))
        }
    }
}

/// A failure of a Python scheme (user code) as the error of the run: the scheme, the trial,
/// the step and the Python traceback. Failures of built-in schemes stay failed rows.
fn python_failure(summary: &results::Summary) -> PyResult<()> {
    for s in &summary.schemes {
        if let (Some(f), true) = (&s.failed, external::is_python_kind(&s.kind)) {
            // The loop's words are "scheme {label}, step {k}: {cause}": said once, with the trial.
            let prefix = format!("scheme {}, step {}: ", s.name, f.step);
            let cause = f.message.strip_prefix(&prefix).unwrap_or(&f.message);
            return Err(RunError::new_err(format!(
                "scheme {:?}, trial {}, step {}: {cause}",
                s.name, f.trial, f.step
            )));
        }
    }
    Ok(())
}

/// The scenario's text with `extra` (JSON: a list of scheme tables) appended to its
/// `[[schemes]]`.
fn with_schemes(text: &str, source: &str, extra: Option<&str>) -> PyResult<String> {
    let Some(extra) = extra else {
        return Ok(text.to_string());
    };
    let tables: Vec<toml::Table> = serde_json::from_str(extra).map_err(|e| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "schemes: expected a list of dicts of numbers, strings and flags ({e})"
        ))
    })?;
    let mut doc: toml::Table =
        toml::from_str(text).map_err(|e| ScenarioError::new_err(format!("{source}: {e}")))?;
    let list = doc
        .entry("schemes")
        .or_insert_with(|| toml::Value::Array(Vec::new()));
    let Some(list) = list.as_array_mut() else {
        return Err(ScenarioError::new_err(format!(
            "{source}: `schemes` is not a list of tables"
        )));
    };
    list.extend(tables.into_iter().map(toml::Value::Table));
    Ok(toml::to_string(&doc).expect("a TOML table serializes"))
}

/// The scenario's text and source: resolved, with `extra` schemes and `--loss`.
fn scenario_text(
    scenario: &str,
    extra: Option<&str>,
    loss: Option<f64>,
) -> PyResult<(String, String)> {
    let (text, source) = resolve(scenario)?;
    let text = with_schemes(&text, &source, extra)?;
    match loss {
        None => Ok((text, source)),
        Some(p) => Ok((
            hushfuse::scenario::lossy::with_loss(&text, &source, p).map_err(crate::scenario_err)?,
            source,
        )),
    }
}

/// The worker threads of a run: `threads`, except that the default (0: one per core) is one
/// thread when the scenario lists a Python scheme. Python code runs one call at a time (the
/// GIL), and worker threads that take turns at it are slower than one thread (measured in
/// `benches/python_scheme.py`); the results are the same for any count.
fn threads_for(text: &str, threads: usize) -> usize {
    if threads != 0 {
        return threads;
    }
    let python = toml::from_str::<toml::Table>(text).ok().is_some_and(|doc| {
        doc.get("schemes")
            .and_then(|v| v.as_array())
            .is_some_and(|list| {
                list.iter().any(|t| {
                    t.get("kind")
                        .and_then(|k| k.as_str())
                        .is_some_and(external::is_python_kind)
                })
            })
    });
    if python {
        1
    } else {
        0
    }
}

/// Runs a scenario (Monte Carlo) as `hushfuse run` does. Without `out`: in memory, returns
/// the summary (with its `paper` section). With `out`: the run's folder, written exactly as
/// the command line writes it, checkpointed every `checkpoint_every` seconds so that
/// `resume=True` continues a run that was killed; `shard="I/N"` runs one shard (for
/// `hushfuse merge`). Returns a dict; with `out`, also `out` and `files` (or, for a shard,
/// only `shard`, `blocks` and `done`). `schemes`: JSON of scheme tables added to the
/// scenario's. With `budgets`: the arena (see [`arena`]), in memory or, with `out`, into the
/// folder `hushfuse run --budgets --out` writes.
#[pyfunction]
#[pyo3(signature = (scenario, trials=None, seed=None, threads=0, out=None, resume=false, shard=None, report=false, reproduce=false, checkpoint_every=10.0, loss=None, schemes=None, budgets=None, budget_axis="energy", tolerance=0.02, pilot_trials=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn run<'py>(
    py: Python<'py>,
    scenario: &str,
    trials: Option<usize>,
    seed: Option<u64>,
    threads: usize,
    out: Option<PathBuf>,
    resume: bool,
    shard: Option<&str>,
    report: bool,
    reproduce: bool,
    checkpoint_every: f64,
    loss: Option<f64>,
    schemes: Option<&str>,
    budgets: Option<Vec<f64>>,
    budget_axis: &str,
    tolerance: f64,
    pilot_trials: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let (text, source) = scenario_text(scenario, schemes, loss)?;
    let threads = threads_for(&text, threads);
    if let Some(budgets) = budgets {
        if resume || shard.is_some() || reproduce {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "budget=/budgets= take no resume=, shard= or reproduce=: a calibration is not checkpointed (each budget's knobs are searched by pilot runs, one after another, with nothing saved to continue from or to split into shards), and a reproduction runs a paper's scenario as published, not calibrated",
            ));
        }
        if report && out.is_none() {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "report= needs out= (the folder that keeps the arena's files)",
            ));
        }
        let opts = calibrate::Options {
            axis: calibrate::Axis::parse(budget_axis).map_err(|m| {
                pyo3::exceptions::PyValueError::new_err(m.replace("--budget-axis", "budget_axis"))
            })?,
            tolerance,
            pilot_trials,
            threads,
            load: build::LoadOptions {
                trials,
                seed,
                threads,
                limits: None,
                ..Default::default()
            },
        };
        if pilot_trials == Some(0) {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "pilot_trials: expected at least 1 trial per pilot run, got 0",
            ));
        }
        // As the command line: a budget no scheme can meet is refused before any pilot run
        // (a scenario that does not load is left to the calibration, which names its error).
        if let Ok(exp) = build::load_with(&text, &source, &opts.load) {
            if let Some(m) = calibrate::energy_floor_problem(&exp, opts.axis, &budgets) {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "{m}; budgets are on the energy axis by default (µJ per step): for bits give budget_axis=\"payload\", \"frame\" or \"total\""
                )));
            }
        }
        let write = out.map(|dir| (dir, report));
        return arena(py, (&text, &source), &budgets, &opts, write);
    }
    if out.is_none() && (resume || shard.is_some() || report) {
        return Err(pyo3::exceptions::PyValueError::new_err(
            "resume=, shard= and report= need out= (the folder that keeps the run's files)",
        ));
    }
    let Some(out) = out else {
        let exp = crate::load_text(&text, &source, trials, seed, threads)?;
        let sums = crate::helpers::interruptible(py, |stop| {
            runner::run_until(&exp, runner::RunOptions { threads }, &|_| {}, stop)
        })?
        .map_err(|e| RunError::new_err(e.to_string()))?;
        let summary = results::summarize(&exp, &sums);
        python_failure(&summary)?;
        check_finite(hushfuse::metrics::finite::non_finite(&summary))?;
        return summary_object(py, &exp, &summary);
    };
    let shard = shard
        .map(durable::parse_shard)
        .transpose()
        .map_err(|m| pyo3::exceptions::PyValueError::new_err(format!("shard: {m}")))?;
    let request = engine_run::Request {
        text,
        source,
        trials,
        seed,
        threads,
        allow_large: false,
        reproduce,
        report,
        out: Some(out),
        shard,
        resume,
        checkpoint_every,
    };
    let outcome = crate::helpers::interruptible(py, |stop| {
        let hooks = engine_run::Hooks {
            stop: Some(stop),
            ..Default::default()
        };
        engine_run::execute(&request, &hooks)
    })?
    .map_err(run_failure)?;
    let d = PyDict::new(py);
    match outcome {
        engine_run::Outcome::Whole(done) => {
            python_failure(&done.summary)?;
            check_finite(done.non_finite.clone())?;
            let s = summary_object(py, &done.exp, &done.summary)?;
            s.set_item("out", done.dir.display().to_string())?;
            s.set_item("files", done.files.clone())?;
            return Ok(s);
        }
        engine_run::Outcome::Shard { path, blocks, .. } => {
            d.set_item("shard", path.display().to_string())?;
            d.set_item("blocks", (blocks.start, blocks.end))?;
            d.set_item("done", false)?;
        }
        engine_run::Outcome::ShardAlreadyDone { path } => {
            d.set_item("shard", path.display().to_string())?;
            d.set_item("done", true)?;
        }
    }
    Ok(d.into_any())
}

/// The arena, as `hushfuse run --budgets`: every scheme's knob calibrated to each budget
/// ([`calibrate::calibrate`]). Returns `budgets`, `axis`, `tolerance`, `evaluations` (pilot
/// runs), `calibration` (per budget, per scheme: label, kind, knob, value, target, achieved,
/// status) and `runs` (per budget, the summary of every scheme at its knob). With `write`
/// (the folder, and whether to add report.html): the command line's arena folder, written by
/// the same library code ([`arena_files`]), and `out` and `files` in the result.
fn arena<'py>(
    py: Python<'py>,
    (text, source): (&str, &str),
    budgets: &[f64],
    opts: &calibrate::Options,
    write: Option<(PathBuf, bool)>,
) -> PyResult<Bound<'py, PyAny>> {
    // The folder is checked (and held) before the calibration runs, as the command line
    // checks it: a folder that cannot take the files costs no pilot run.
    let mut out_dir = match &write {
        Some((dir, _)) => Some(open_arena_dir(dir, (text, source), budgets.len(), opts)?),
        None => None,
    };
    let start = std::time::Instant::now();
    let out = py
        .allow_threads(|| calibrate::calibrate(text, source, budgets, opts))
        .map_err(|m| RunError::new_err(python_words(&m)))?;
    let elapsed = start.elapsed().as_secs_f64();
    for summary in &out.summaries {
        python_failure(summary)?;
    }
    let d = PyDict::new(py);
    if let (Some(out_dir), Some((dir, report))) = (out_dir.take(), &write) {
        // As the command line: numbers that are not finite are refused before any file.
        check_finite(arena_files::non_finite(&out))?;
        let hash = arena_files::inputs_sha256(text, source, budgets, opts);
        let files = py
            .allow_threads(|| {
                let mut out_dir = out_dir;
                arena_files::stage(&mut out_dir, &out, elapsed, (source, &opts.load), *report)?;
                arena_files::commit(out_dir, &out, &hash)
            })
            .map_err(RunError::new_err)?;
        d.set_item("out", dir.display().to_string())?;
        d.set_item("files", files)?;
    }
    d.set_item("budgets", out.budgets.clone())?;
    d.set_item("axis", out.axis.name())?;
    d.set_item("tolerance", out.tolerance)?;
    d.set_item("evaluations", out.evaluations)?;
    d.set_item("calibration", serialize(py, &out.rows)?)?;
    let runs = PyList::empty(py);
    for summary in &out.summaries {
        runs.append(serialize(py, summary)?)?;
    }
    d.set_item("runs", runs)?;
    Ok(d.into_any())
}

/// The arena's output folder, opened before the calibration, with room for one run's files
/// per budget (a scenario that does not load is left to the calibration, which names its
/// cause).
fn open_arena_dir(
    dir: &std::path::Path,
    (text, source): (&str, &str),
    budget_count: usize,
    opts: &calibrate::Options,
) -> PyResult<OutputDir> {
    let folder_err = |m: String| ScenarioError::new_err(python_words(&m));
    let out_dir = OutputDir::open(dir).map_err(folder_err)?;
    if let Ok(exp) = build::load_with(text, source, &opts.load) {
        arena_files::check_room(dir, &exp, budget_count).map_err(folder_err)?;
    }
    Ok(out_dir)
}

/// Simulates trial `trial` of a scenario: truth (T, n) and per sensor its measurements
/// (T, m_i), drawn exactly as `hushfuse run` draws them.
#[pyfunction]
#[pyo3(signature = (scenario, trial=0, seed=None))]
pub(crate) fn simulate<'py>(
    py: Python<'py>,
    scenario: &str,
    trial: usize,
    seed: Option<u64>,
) -> PyResult<Bound<'py, PyDict>> {
    // One trial's data is all it holds: no scheme is built, and the memory check is that of
    // one trial (not the whole run's).
    let exp = crate::load_data(scenario, seed)?;
    let data = runner::draw_trial(&exp, trial);
    let d = PyDict::new(py);
    d.set_item(
        "truth",
        vectors_to_array2(&data.truth, exp.system.state_dim()).into_pyarray(py),
    )?;
    let per_sensor = PyList::empty(py);
    for (i, s) in exp.system.sensors.iter().enumerate() {
        let rows: Vec<Vector> = data.measurements.iter().map(|m| m[i].clone()).collect();
        per_sensor.append(vectors_to_array2(&rows, s.meas_dim()).into_pyarray(py))?;
    }
    d.set_item("measurements", per_sensor)?;
    d.set_item("steps", exp.steps)?;
    d.set_item("seed", exp.seed)?;
    Ok(d)
}

/// A replay's error as the Python exception of its kind.
fn replay_err(e: replay::ReplayError) -> PyErr {
    match e {
        replay::ReplayError::Scenario(m) => ScenarioError::new_err(python_words(&m)),
        replay::ReplayError::Data(m) => DataError::new_err(python_words(&m)),
        replay::ReplayError::TooLarge(m) => PyMemoryError::new_err(python_words(&m)),
        replay::ReplayError::Run(m) => RunError::new_err(m),
    }
}

/// Replays numpy arrays through every variant of a scenario: per sensor a float array
/// (T, m_i) (an all-NaN row: no reading), and optionally the truth (T, n). Returns what
/// [`replay_csv`] returns.
#[pyfunction]
#[pyo3(signature = (scenario, measurements, truth=None, seed=None, trial=0, schemes=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn replay_arrays<'py>(
    py: Python<'py>,
    scenario: &str,
    measurements: Vec<PyReadonlyArray2<'py, f64>>,
    truth: Option<PyReadonlyArray2<'py, f64>>,
    seed: Option<u64>,
    trial: usize,
    schemes: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let (text, source) = scenario_text(scenario, schemes, None)?;
    // Contiguous row-major copies only where numpy's layout is not (a column slice of a 3-D
    // array): the replay reads rows.
    let owned: Vec<(Vec<f64>, usize, usize)> = measurements
        .iter()
        .map(|a| {
            let v = a.as_array();
            (v.iter().copied().collect(), v.nrows(), v.ncols())
        })
        .collect();
    let truth_owned = truth.map(|t| {
        let v = t.as_array();
        (
            v.iter().copied().collect::<Vec<f64>>(),
            v.nrows(),
            v.ncols(),
        )
    });
    fn matrix((data, rows, cols): &(Vec<f64>, usize, usize)) -> arrays::Matrix<'_> {
        arrays::Matrix {
            data,
            rows: *rows,
            cols: *cols,
        }
    }
    let input = arrays::Arrays {
        measurements: owned.iter().map(matrix).collect(),
        truth: truth_owned.as_ref().map(matrix),
    };
    let opts = replay::ReplayOptions {
        seed,
        trial,
        load: build::LoadOptions::default(),
    };
    let r = py
        .allow_threads(|| arrays::replay_arrays(&text, &source, &input, &opts))
        .map_err(replay_err)?;
    replay_dict(py, &r)
}

/// Replays CSV texts (the command line's layout: a pandas DataFrame in long form) through
/// every variant of a scenario, with the command line's messages (file, line, column).
#[pyfunction]
#[pyo3(signature = (scenario, measurements_csv, measurements_name, truth_csv=None, truth_name="truth", seed=None, trial=0, schemes=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn replay_csv<'py>(
    py: Python<'py>,
    scenario: &str,
    measurements_csv: &str,
    measurements_name: &str,
    truth_csv: Option<&str>,
    truth_name: &str,
    seed: Option<u64>,
    trial: usize,
    schemes: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let (text, source) = scenario_text(scenario, schemes, None)?;
    let opts = replay::ReplayOptions {
        seed,
        trial,
        load: build::LoadOptions::default(),
    };
    let r = py
        .allow_threads(|| {
            replay::replay_csv(
                &text,
                &source,
                (measurements_csv, measurements_name),
                truth_csv.map(|t| (t, truth_name)),
                &opts,
            )
        })
        .map_err(replay_err)?;
    replay_dict(py, &r)
}

/// A replay as a dict: `steps`, `seed`, `notes`, `available` (T, N), `schemes` (per variant:
/// name, kind, variant, params, mean (T, n), cov (T, n, n), links (T x N names), bits (T, N))
/// and `summary` (None without truth).
fn replay_dict<'py>(py: Python<'py>, r: &replay::CsvReplay) -> PyResult<Bound<'py, PyDict>> {
    let exp = &r.exp;
    let n = exp.system.state_dim();
    let ns = exp.system.n_sensors();
    let bad = replay::non_finite_estimates(exp, &r.replayed);
    if !bad.is_empty() {
        return Err(RunError::new_err(format!(
            "the replay produced estimates that are not finite: {}; rescale the data's units or check the scenario's noise levels",
            bad.join("; ")
        )));
    }
    let d = PyDict::new(py);
    d.set_item("steps", exp.steps)?;
    d.set_item("seed", exp.seed)?;
    d.set_item("notes", r.notes.clone())?;
    let mut avail = Array2::from_elem((exp.steps, ns), false);
    for (k, a) in r.recorded.available.iter().enumerate() {
        for (i, b) in a.iter().enumerate() {
            avail[(k, i)] = *b;
        }
    }
    d.set_item("available", avail.into_pyarray(py))?;
    let schemes = PyList::empty(py);
    for (v, vr) in r.replayed.variants.iter().enumerate() {
        let variant = &exp.variants[v];
        let s = PyDict::new(py);
        s.set_item("name", &exp.curves[variant.curve].label)?;
        s.set_item("kind", variant.kind)?;
        s.set_item("variant", v)?;
        s.set_item("params", serialize(py, &variant.params)?)?;
        let (mean, cov) = estimates_arrays(&vr.estimates, n);
        s.set_item("mean", mean.into_pyarray(py))?;
        s.set_item("cov", cov.into_pyarray(py))?;
        let links: Vec<Vec<&str>> = vr
            .links
            .iter()
            .zip(&r.recorded.available)
            .map(|(l, a)| {
                l.iter()
                    .zip(a)
                    .map(|(l, a)| replay::link_name(*l, *a))
                    .collect()
            })
            .collect();
        s.set_item("links", links)?;
        let mut bits = Array2::<u64>::zeros((exp.steps, ns));
        for (k, b) in vr.bits.iter().enumerate() {
            for (i, x) in b.iter().enumerate() {
                bits[(k, i)] = *x;
            }
        }
        s.set_item("bits", bits.into_pyarray(py))?;
        schemes.append(s)?;
    }
    d.set_item("schemes", schemes)?;
    match &r.replayed.sums {
        Some(sums) => {
            let summary = results::summarize(exp, sums);
            let bad = replay::non_finite(&summary);
            if !bad.is_empty() {
                return Err(RunError::new_err(format!(
                    "the replay produced numbers that are not finite:\n  {}",
                    bad.join("\n  ")
                )));
            }
            d.set_item("summary", serialize(py, &summary)?)?;
        }
        None => d.set_item("summary", py.None())?,
    }
    Ok(d)
}
