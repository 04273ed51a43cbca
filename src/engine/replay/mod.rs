//! Replaying recorded measurements through every scheme of a scenario (`hushfuse replay`).
//!
//! Each sensor node sees its recorded z_k and decides what to send exactly as in a simulation
//! (the same loop, coins and bit counting as the runner: [`crate::engine::trace::run_variant_with`]).
//! A sensor without a reading at a step is not asked and reaches the fusion center as not
//! scheduled. With recorded truth, the usual metrics of one trial follow.
//!
//! # CSV layout
//!
//! Measurements, long form, one row per (step, sensor) that has a reading:
//!
//! ```text
//! step,sensor,z0,z1
//! 1,0,0.53
//! 1,1,0.12,-1.5
//! 2,1,0.40,-1.2
//! ```
//!
//! - the header names the columns; the first two must be `step` and `sensor`, the others may
//!   have any names;
//! - `step` counts from 1; steps must not decrease from row to row, and a (step, sensor) pair
//!   may appear once;
//! - `sensor` is the index of the sensor in the scenario (0-based, the order of `[[sensors]]`
//!   and `[[sensor_fields]]`);
//! - then the sensor's measurement components, exactly as many as it measures; a row may end
//!   in empty fields (a file that mixes sensors of different dimensions);
//! - a missing row means the sensor had no reading at that step.
//!
//! Truth (optional), one row per step 1, 2, ..., T in order: `step,x0,x1,...` with as many
//! components as the state. With truth, the run has T steps; without, as many as the last step
//! of the measurements.
//!
//! The files are read and checked on their own in `parse.rs`; this file checks them against the
//! scenario, replays them and writes the replay's CSV files and memory checks.
pub mod arrays;
mod parse;

use crate::engine::runner::TrialData;
use crate::engine::trace::{self, Link, LoopOptions};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::metrics::Sums;
use crate::scenario::build::{self, Experiment, LoadOptions, ScenarioError};
pub use parse::*;
use std::fmt::{self, Write as _};

/// Recorded data ready to replay: per step and sensor the reading (zeros where there is
/// none), which readings exist, and the truth if recorded.
#[derive(Debug, Clone)]
pub struct Recorded {
    pub measurements: Vec<Vec<Vector>>,
    /// `available[k - 1][i]`.
    pub available: Vec<Vec<bool>>,
    pub truth: Option<Vec<Vector>>,
}

impl Recorded {
    pub fn steps(&self) -> usize {
        self.measurements.len()
    }

    /// Every reading of a simulated trial, with its truth.
    pub fn from_trial(data: &TrialData) -> Self {
        Self {
            measurements: data.measurements.clone(),
            available: data
                .measurements
                .iter()
                .map(|m| vec![true; m.len()])
                .collect(),
            truth: Some(data.truth.clone()),
        }
    }

    /// From per-step readings (`None`: no reading) and truth, checked against the experiment
    /// (sensor count and dimensions, state dimension, number of steps, finite values).
    pub fn from_parts(
        exp: &Experiment,
        readings: Vec<Vec<Option<Vector>>>,
        truth: Option<Vec<Vector>>,
    ) -> Result<Self, String> {
        let sys = &exp.system;
        if readings.len() != exp.steps {
            return Err(format!(
                "measurements cover {} steps, the replay has {}",
                readings.len(),
                exp.steps
            ));
        }
        let mut measurements = Vec::with_capacity(readings.len());
        let mut available = Vec::with_capacity(readings.len());
        for (k, row) in readings.into_iter().enumerate() {
            if row.len() != sys.n_sensors() {
                return Err(format!(
                    "step {}: {} sensors' readings, the scenario has {} sensors",
                    k + 1,
                    row.len(),
                    sys.n_sensors()
                ));
            }
            let mut m = Vec::with_capacity(row.len());
            let mut a = Vec::with_capacity(row.len());
            for (i, z) in row.into_iter().enumerate() {
                let dim = sys.sensors[i].meas_dim();
                match z {
                    Some(z) => {
                        if z.len() != dim {
                            return Err(format!(
                                "step {}, sensor {i}: {} components, the sensor measures {dim}",
                                k + 1,
                                z.len()
                            ));
                        }
                        if z.iter().any(|v| !v.is_finite()) {
                            return Err(format!(
                                "step {}, sensor {i}: a component is not finite",
                                k + 1
                            ));
                        }
                        m.push(z);
                        a.push(true);
                    }
                    None => {
                        m.push(Vector::zeros(dim));
                        a.push(false);
                    }
                }
            }
            measurements.push(m);
            available.push(a);
        }
        if let Some(t) = &truth {
            if t.len() != exp.steps {
                return Err(format!(
                    "truth covers {} steps, the measurements {}",
                    t.len(),
                    exp.steps
                ));
            }
            for (k, x) in t.iter().enumerate() {
                if x.len() != sys.state_dim() {
                    return Err(format!(
                        "truth at step {}: {} components, the state has {}",
                        k + 1,
                        x.len(),
                        sys.state_dim()
                    ));
                }
                if x.iter().any(|v| !v.is_finite()) {
                    return Err(format!(
                        "truth at step {}: a component is not finite",
                        k + 1
                    ));
                }
            }
        }
        Ok(Self {
            measurements,
            available,
            truth,
        })
    }
}

/// Checks the tables against the experiment (built for [`steps_of`] steps) and assembles the
/// data: sensor indices, each row's number of components, the truth's dimension.
pub fn recorded(
    exp: &Experiment,
    meas: &MeasTable,
    truth: Option<&TruthTable>,
) -> Result<Recorded, DataError> {
    let sys = &exp.system;
    let n = sys.n_sensors();
    let mut readings: Vec<Vec<Option<Vector>>> = vec![vec![None; n]; exp.steps];
    for r in &meas.rows {
        let at = Some(At {
            line: r.line,
            row: r.row,
        });
        if r.sensor >= n {
            return Err(err_at(
                &meas.file,
                at,
                Some(col_name(&meas.header, 1)),
                format!(
                    "the scenario has no sensor {} (it has {n}: indices 0 to {})",
                    r.sensor,
                    n - 1
                ),
            ));
        }
        let dim = sys.sensors[r.sensor].meas_dim();
        if r.values.len() != dim {
            let c = 2 + r.values.len().min(dim);
            return Err(err_at(
                &meas.file,
                at,
                Some(col_name(&meas.header, c)),
                format!(
                    "sensor {} measures {dim} component{}, this row has {}",
                    r.sensor,
                    if dim == 1 { "" } else { "s" },
                    r.values.len()
                ),
            ));
        }
        readings[r.step - 1][r.sensor] = Some(Vector::from_vec(r.values.clone()));
    }
    let truth = match truth {
        None => None,
        Some(t) => {
            let n_x = sys.state_dim();
            let mut xs = Vec::with_capacity(t.rows.len());
            for (at, v) in &t.rows {
                if v.len() != n_x {
                    let c = 1 + v.len().min(n_x);
                    return Err(err_at(
                        &t.file,
                        Some(*at),
                        Some(col_name(&t.header, c)),
                        format!("the state has {n_x} components, this row has {}", v.len()),
                    ));
                }
                xs.push(Vector::from_vec(v.clone()));
            }
            Some(xs)
        }
    };
    Recorded::from_parts(exp, readings, truth).map_err(|m| err_at(&meas.file, None, None, m))
}

/// Loads a scenario for a replay of `steps` steps: one trial, `--seed` if given. A
/// `steady_state_from` beyond the recorded steps falls back to the default (the second half),
/// with a note saying so.
pub fn load_experiment(
    text: &str,
    source: &str,
    steps: usize,
    seed: Option<u64>,
    opts: &LoadOptions,
) -> Result<(Experiment, Vec<String>), ScenarioError> {
    let mut parsed = build::parse(text, source)?;
    let mut notes = Vec::new();
    if parsed.steady_state_from.is_some_and(|s| s > steps) {
        notes.push(format!(
            "the scenario's steady_state_from ({}) is beyond the {steps} recorded steps: steady-state averages from step {} instead",
            parsed.steady_state_from.unwrap_or_default(),
            steps / 2 + 1
        ));
        parsed.steady_state_from = None;
    }
    parsed.steps = steps;
    parsed.trials = 1;
    if let Some(s) = seed {
        parsed.seed = s;
    }
    Ok((build::build_with(parsed, source, opts)?, notes))
}

/// One variant replayed.
#[derive(Debug, Clone)]
pub struct VariantReplay {
    /// Fused estimate after step k (k = 1..T).
    pub estimates: Vec<Gaussian>,
    /// `links[k - 1][i]`: what sensor i did at step k (`NotScheduled` also where it had no
    /// reading; [`Recorded::available`] tells the two apart).
    pub links: Vec<Vec<Link>>,
    /// `bits[k - 1][i]`: payload bits sensor i sent at step k.
    pub bits: Vec<Vec<u64>>,
}

/// Every variant replayed, and with truth their metrics (one trial).
#[derive(Debug, Clone)]
pub struct Replayed {
    pub variants: Vec<VariantReplay>,
    pub sums: Option<Vec<Sums>>,
}

/// Replays every variant of `exp` (built by [`load_experiment`] for `rec.steps()` steps) on
/// the recorded data. The coins are those of trial `trial` of the scenario's seed, so data
/// written from trial `trial` of a simulation replays to that simulation.
pub fn replay(exp: &Experiment, rec: &Recorded, trial: usize) -> Result<Replayed, String> {
    if rec.steps() != exp.steps {
        return Err(format!(
            "the data has {} steps, the experiment {}",
            rec.steps(),
            exp.steps
        ));
    }
    let all = rec.available.iter().all(|a| a.iter().all(|&b| b));
    let opts = LoopOptions {
        trial,
        alone: false,
        available: (!all).then_some(rec.available.as_slice()),
    };
    let mut variants = Vec::with_capacity(exp.variants.len());
    let mut sums = Vec::new();
    for v in 0..exp.variants.len() {
        let mut vr = VariantReplay {
            estimates: Vec::with_capacity(exp.steps),
            links: Vec::with_capacity(exp.steps),
            bits: Vec::with_capacity(exp.steps),
        };
        let mut f = |s: &trace::StepOutput| {
            vr.estimates.push(s.estimate.clone());
            vr.links.push(s.links.to_vec());
            vr.bits.push(s.bits.to_vec());
            Ok(())
        };
        match &rec.truth {
            Some(truth) => {
                let mut s = Sums::new(exp.groups.len(), exp.steps, exp.system.state_dim());
                trace::run_variant_into(exp, &rec.measurements, truth, v, opts, &mut s, &mut f)?;
                // The readings' peaks as a run notes them (a hole, NaN, is not a reading).
                if exp.reals.is_f32() {
                    let mut peaks = Vec::new();
                    crate::metrics::precision::note_peaks(&rec.measurements, &mut peaks);
                    s.merge_peaks(&peaks);
                }
                sums.push(s);
            }
            None => trace::run_variant_with(exp, &rec.measurements, v, opts, &mut f)?,
        }
        variants.push(vr);
    }
    Ok(Replayed {
        variants,
        sums: rec.truth.as_ref().map(|_| sums),
    })
}

/// Name of a link in `estimates.csv`.
pub fn link_name(link: Link, available: bool) -> &'static str {
    match (link, available) {
        (_, false) => "missing",
        (Link::Sent, _) => "sent",
        (Link::Silent, _) => "silent",
        (Link::NotScheduled, _) => "not_scheduled",
        (Link::Lost, _) => "lost",
        (Link::Late, _) => "late",
    }
}

fn quoted(s: &str) -> String {
    format!("\"{}\"", s.replace('"', "\"\""))
}

/// `estimates.csv`: per variant and step the fused mean, the covariance diagonal, and per
/// sensor what it did (`sent`, `silent`, `not_scheduled`, `missing`: no reading) and the
/// payload bits it sent.
pub fn estimates_csv(exp: &Experiment, rec: &Recorded, rep: &Replayed) -> String {
    // Reserved at its bound, so that the string does not double past it as it grows (the
    // memory estimate counts the bound once).
    let mut out = String::with_capacity(estimates_csv_bytes(exp, exp.steps) as usize);
    out.push_str(&estimates_header(exp));
    for (v, vr) in rep.variants.iter().enumerate() {
        for (k, est) in vr.estimates.iter().enumerate() {
            let sensors = (0..exp.system.n_sensors()).map(|i| {
                (
                    link_name(vr.links[k][i], rec.available[k][i]),
                    vr.bits[k][i],
                )
            });
            out.push_str(&estimates_row(exp, v, k + 1, est, sensors));
        }
    }
    out
}

/// The header line of `estimates.csv` (with its newline).
pub fn estimates_header(exp: &Experiment) -> String {
    let n = exp.system.state_dim();
    let mut out = String::from("scheme,params,variant,step");
    (0..n).for_each(|j| {
        let _ = write!(out, ",mean_{j}");
    });
    (0..n).for_each(|j| {
        let _ = write!(out, ",var_{j}");
    });
    (0..exp.system.n_sensors()).for_each(|i| {
        let _ = write!(out, ",sensor_{i},bits_{i}");
    });
    out.push('\n');
    out
}

/// One line of `estimates.csv` (with its newline): variant `v` after step `k`, and per sensor
/// what it did and the payload bits it sent. `hushfuse replay` and the live center write the
/// same lines.
pub fn estimates_row<'s>(
    exp: &Experiment,
    v: usize,
    k: usize,
    est: &Gaussian,
    sensors: impl IntoIterator<Item = (&'s str, u64)>,
) -> String {
    let variant = &exp.variants[v];
    let label = quoted(&exp.curves[variant.curve].label);
    let params = quoted(&crate::metrics::results::params_text(&variant.params));
    let mut out = format!("{label},{params},{v},{k}");
    est.mean.iter().for_each(|m| {
        let _ = write!(out, ",{m}");
    });
    (0..exp.system.state_dim()).for_each(|j| {
        let _ = write!(out, ",{}", est.cov[(j, j)]);
    });
    for (link, bits) in sensors {
        let _ = write!(out, ",{link},{bits}");
    }
    out.push('\n');
    out
}

/// A simulated trial's measurements in the layout [`parse_measurements`] reads (every
/// reading; numbers written so that they read back to the same bits).
pub fn measurements_csv(exp: &Experiment, data: &TrialData) -> String {
    let width = exp
        .system
        .sensors
        .iter()
        .map(|s| s.meas_dim())
        .max()
        .unwrap_or(1);
    let mut out = String::from("step,sensor");
    (0..width).for_each(|j| {
        let _ = write!(out, ",z{j}");
    });
    out.push('\n');
    for (k, zs) in data.measurements.iter().enumerate() {
        for (i, z) in zs.iter().enumerate() {
            let _ = write!(out, "{},{i}", k + 1);
            z.iter().for_each(|v| {
                let _ = write!(out, ",{v}");
            });
            (z.len()..width).for_each(|_| out.push(','));
            out.push('\n');
        }
    }
    out
}

/// A simulated trial's truth in the layout [`parse_truth`] reads.
pub fn truth_csv(data: &TrialData) -> String {
    let n = data.truth.first().map_or(0, |x| x.len());
    let mut out = String::from("step");
    (0..n).for_each(|j| {
        let _ = write!(out, ",x{j}");
    });
    out.push('\n');
    for (k, x) in data.truth.iter().enumerate() {
        let _ = write!(out, "{}", k + 1);
        x.iter().for_each(|v| {
            let _ = write!(out, ",{v}");
        });
        out.push('\n');
    }
    out
}

/// A whole replay from CSV texts ([`replay_csv`], as `hushfuse replay` runs it) or arrays
/// ([`arrays::replay_arrays`]): the experiment, the data and
/// the replayed variants.
pub struct CsvReplay {
    pub exp: Experiment,
    pub recorded: Recorded,
    pub replayed: Replayed,
    /// What was adapted to the data (printed by the command line).
    pub notes: Vec<String>,
}

/// Why a replay failed. The first three are bad input (the command line exits 2), the last a
/// failed run (exit 1); Python raises a different exception for each.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplayError {
    /// The scenario cannot be read or is inconsistent.
    Scenario(String),
    /// The recorded data cannot be replayed (the message names the file, line and column).
    Data(String),
    /// The data or the replay would not fit in the memory limit.
    TooLarge(String),
    /// A scheme failed on the data.
    Run(String),
}

impl ReplayError {
    /// Bad input rather than a failed run.
    pub fn is_input(&self) -> bool {
        !matches!(self, ReplayError::Run(_))
    }

    /// A scenario error as a replay error: one that passes a memory limit is [`TooLarge`](Self::TooLarge).
    pub fn scenario(e: &ScenarioError) -> Self {
        match e.limit {
            Some(crate::scenario::error::Limit::Memory) => ReplayError::TooLarge(e.to_string()),
            _ => ReplayError::Scenario(e.to_string()),
        }
    }
}

impl fmt::Display for ReplayError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReplayError::Scenario(m)
            | ReplayError::Data(m)
            | ReplayError::TooLarge(m)
            | ReplayError::Run(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for ReplayError {}

/// Options of [`replay_csv`].
#[derive(Debug, Clone, Copy, Default)]
pub struct ReplayOptions {
    /// Replaces the scenario's seed.
    pub seed: Option<u64>,
    /// Trial whose coins the schemes use (0 unless replaying data of another trial).
    pub trial: usize,
    pub load: LoadOptions,
}

/// Parses the measurements (and truth), loads the scenario for their number of steps, checks
/// the data against it and replays every variant.
pub fn replay_csv(
    scenario_text: &str,
    source: &str,
    measurements: (&str, &str),
    truth: Option<(&str, &str)>,
    opts: &ReplayOptions,
) -> Result<CsvReplay, ReplayError> {
    let data = |e: DataError| ReplayError::Data(e.to_string());
    let too_large = |e: DataError| ReplayError::TooLarge(e.to_string());
    let limits = opts.load.limits.unwrap_or_default();
    for (text, file) in std::iter::once(measurements).chain(truth) {
        check_read(file, parse_bytes(text), text.len() as u64, &limits).map_err(too_large)?;
    }
    let meas = parse_measurements(measurements.0, measurements.1).map_err(data)?;
    let truth = truth
        .map(|(text, file)| parse_truth(text, file))
        .transpose()
        .map_err(data)?;
    let steps = steps_of(&meas, truth.as_ref()).map_err(data)?;
    check_replay_memory(
        scenario_text,
        source,
        &Readings::of(&meas),
        steps,
        truth.is_some(),
        opts,
        &limits,
    )
    .map_err(too_large)?;
    // One trial, replayed on this thread. Its memory was checked above, against what a replay
    // allocates: the run's estimate (the runner's sums and trial buffers) does not apply.
    let load = LoadOptions {
        threads: if opts.load.threads == 0 {
            1
        } else {
            opts.load.threads
        },
        limits: Some(crate::scenario::limits::Limits::none()),
        ..opts.load
    };
    let (exp, notes) = load_experiment(scenario_text, source, steps, opts.seed, &load)
        .map_err(|e| ReplayError::scenario(&e))?;
    let recorded = recorded(&exp, &meas, truth.as_ref()).map_err(data)?;
    let replayed = replay(&exp, &recorded, opts.trial).map_err(ReplayError::Run)?;
    Ok(CsvReplay {
        exp,
        recorded,
        replayed,
        notes,
    })
}

/// Heap overhead of one allocation (header and rounding), as [`crate::scenario::limits`] counts it.
const ALLOC_BYTES: f64 = 16.0;
/// A `Vec`'s own header (pointer, capacity, length).
const VEC_BYTES: f64 = 24.0;
/// A hash map entry of the duplicate check, with its share of the table's spare room.
const SEEN_BYTES: f64 = 64.0;

/// Bytes that reading a data file's text holds at once: the text itself and, per line, the
/// parsed row (kept in a vector that grows by doubling), its components and the duplicate
/// check's entry.
pub fn parse_bytes(text: &str) -> f64 {
    let lines = text.bytes().filter(|&b| b == b'\n').count() as f64 + 1.0;
    let columns = text.lines().next().map_or(1, |h| h.split(',').count()) as f64;
    let row = 2.0 * std::mem::size_of::<MeasRow>() as f64 + ALLOC_BYTES + 8.0 * columns;
    text.len() as f64 + lines * (row + SEEN_BYTES)
}

/// Refuses to read a data file needing `bytes` (see [`parse_bytes`]; the file's size before
/// it is read) above the memory limit.
pub fn check_read(
    file: &str,
    bytes: f64,
    size: u64,
    limits: &crate::scenario::limits::Limits,
) -> Result<(), DataError> {
    if bytes.is_nan() || bytes > limits.max_memory_bytes {
        return Err(err_at(
            file,
            None,
            None,
            format!(
                "reading this file ({}) would hold about {} in memory, more than the limit of {}; replay a shorter recording, or pass --allow-large",
                crate::scenario::limits::gib(size as f64),
                crate::scenario::limits::gib(bytes),
                crate::scenario::limits::gib(limits.max_memory_bytes)
            ),
        ));
    }
    Ok(())
}

/// Bytes a replay of `steps` steps and `rows` readings holds besides its schemes' instances and
/// plans ([`estimated_bytes`]): the per-step grid of readings and their flags, the truth, every
/// variant's estimates (mean and covariance on the heap), links and bits, and `estimates.csv`
/// as a string reserved at its bound (plus
/// `summary.json` and `per_step.csv` with truth).
pub fn replay_bytes(exp: &Experiment, steps: usize, rows: usize, truth: bool) -> f64 {
    use std::mem::size_of;
    let f = |x: usize| x as f64;
    let sys = &exp.system;
    let (n, ns) = (f(sys.state_dim()), f(sys.n_sensors()));
    let m: f64 = sys.sensors.iter().map(|s| f(s.meas_dim())).sum();
    let m_max = sys.sensors.iter().map(|s| s.meas_dim()).max().unwrap_or(1) as f64;
    let vector = f(size_of::<Vector>()) + ALLOC_BYTES;
    let t = f(steps);
    let readings = t * (VEC_BYTES + ns * f(size_of::<Option<Vector>>()))
        + f(rows) * (ALLOC_BYTES + 8.0 * m_max);
    let recorded = t * (2.0 * (VEC_BYTES + ALLOC_BYTES) + ns * (vector + 1.0) + 8.0 * m);
    let truth_bytes = if truth {
        2.0 * t * (vector + 8.0 * n)
    } else {
        0.0
    };
    let per_step = f(size_of::<Gaussian>())
        + 2.0 * ALLOC_BYTES
        + 8.0 * (n + n * n)
        + 2.0 * (VEC_BYTES + ALLOC_BYTES)
        + ns * (f(size_of::<Link>()) + 8.0);
    let csv = estimates_csv_bytes(exp, steps);
    let metrics = if truth {
        t * f(exp.variants.len()) * (f(exp.groups.len()) + 12.0) * 80.0
    } else {
        0.0
    };
    readings + recorded + truth_bytes + t * f(exp.variants.len()) * per_step + csv + metrics
}

/// About how many bytes `estimates.csv` of `steps` steps takes (an upper bound): a number is
/// written in at most 24 characters, a link and its bits in about 20.
pub fn estimates_csv_bytes(exp: &Experiment, steps: usize) -> f64 {
    let f = |x: usize| x as f64;
    let (n, ns) = (f(exp.system.state_dim()), f(exp.system.n_sensors()));
    let row = |v: &crate::scenario::build::Variant| {
        f(exp.curves[v.curve].label.len())
            + f(crate::metrics::results::params_text(&v.params).len())
            + 24.0
            + 2.0 * n * 25.0
            + ns * 20.0
    };
    f(steps) * exp.variants.iter().map(row).sum::<f64>()
}

/// Room a replay's output folder needs: `estimates.csv`, with truth the one-trial
/// `summary.json` and `per_step.csv`, and the manifest.
pub fn output_bytes(exp: &Experiment, truth: bool) -> f64 {
    let metrics = if truth {
        crate::scenario::limits::output_bytes(exp.groups.len(), exp.variants.len(), exp.steps, 1)
    } else {
        0.0
    };
    estimates_csv_bytes(exp, exp.steps) + metrics + 64.0 * 1024.0
}

/// What the memory check needs of the recorded readings: where they come from, how many there
/// are and the last step they name.
pub(super) struct Readings<'a> {
    pub(super) file: &'a str,
    pub(super) rows: usize,
    pub(super) last_step: usize,
}

impl<'a> Readings<'a> {
    fn of(meas: &'a MeasTable) -> Self {
        Self {
            file: &meas.file,
            rows: meas.rows.len(),
            last_step: meas.rows.last().map_or(0, |r| r.step),
        }
    }
}

/// About how many bytes a replay of `steps` steps and `rows` readings of the scenario holds
/// at its peak: the experiment (one trial, one thread) and [`replay_bytes`], from a build of
/// the scenario for one step (dimensions and variants do not depend on the steps), with that
/// build. `None` when the scenario does not build for one step (left to the real load).
pub fn estimated_bytes(
    scenario_text: &str,
    source: &str,
    rows: usize,
    steps: usize,
    truth: bool,
    load: &LoadOptions,
    seed: Option<u64>,
) -> Option<(f64, Experiment)> {
    use crate::scenario::limits;
    let probe_opts = LoadOptions {
        limits: Some(limits::Limits::none()),
        threads: 1,
        ..*load
    };
    let (probe, _) = load_experiment(scenario_text, source, 1, seed, &probe_opts).ok()?;
    // The replay holds its own data, estimates and metrics (`replay_bytes`), not the runner's
    // trial buffers and sums: of the run's estimate only the schemes' instances and plans.
    let schemes = probe.variants.iter().map(|v| v.scheme.as_ref());
    let instances = limits::with_schemes(limits::Estimate::default(), schemes, 1, steps, 1);
    let with_plan = probe
        .variants
        .iter()
        .filter(|v| v.scheme.keeps_step_plan())
        .count();
    let plans = limits::plans(&probe.system, with_plan, steps);
    let bytes = instances.memory_bytes + plans + replay_bytes(&probe, steps, rows, truth);
    Some((bytes, probe))
}

/// Refuses a replay whose data would not fit ([`estimated_bytes`]).
pub(super) fn check_replay_memory(
    scenario_text: &str,
    source: &str,
    meas: &Readings,
    steps: usize,
    truth: bool,
    opts: &ReplayOptions,
    limits: &crate::scenario::limits::Limits,
) -> Result<(), DataError> {
    use crate::scenario::limits;
    if limits.max_memory_bytes.is_infinite() {
        return Ok(());
    }
    let Some((bytes, probe)) = estimated_bytes(
        scenario_text,
        source,
        meas.rows,
        steps,
        truth,
        &opts.load,
        opts.seed,
    ) else {
        return Ok(());
    };
    if bytes.is_nan() || bytes > limits.max_memory_bytes {
        let last = meas.last_step;
        return Err(err_at(
            meas.file,
            None,
            None,
            format!(
                "a replay of its {steps} steps ({} readings of {} sensors, state dimension {}, {} scheme variants; the last step in the file is {last}) would hold about {} in memory, more than the limit of {}; replay a shorter recording (the step column counts the steps 1, 2, 3, ...), or pass --allow-large",
                meas.rows,
                probe.system.n_sensors(),
                probe.system.state_dim(),
                probe.variants.len(),
                limits::gib(bytes),
                limits::gib(limits.max_memory_bytes)
            ),
        ));
    }
    Ok(())
}

/// Every variant whose estimates are not all finite (readings that overflow a filter), with
/// the first such step: `label (params), variant v: ... from step k on`.
pub fn non_finite_estimates(exp: &Experiment, rep: &Replayed) -> Vec<String> {
    let mut bad = Vec::new();
    for (v, vr) in rep.variants.iter().enumerate() {
        let first = vr.estimates.iter().position(|e| {
            e.mean.iter().any(|x| !x.is_finite()) || e.cov.iter().any(|x| !x.is_finite())
        });
        if let Some(k) = first {
            let variant = &exp.variants[v];
            let e = &vr.estimates[k];
            let what = if e.mean.iter().any(|x| !x.is_finite()) {
                "mean"
            } else {
                "covariance"
            };
            bad.push(format!(
                "{} ({}), variant {v}: estimate ({what}) not finite from step {} on",
                exp.curves[variant.curve].label,
                crate::metrics::results::params_text(&variant.params),
                k + 1
            ));
        }
    }
    bad
}

/// [`crate::metrics::finite::non_finite`] for a replay: one trial has no standard errors (they are
/// NaN, written as null), which is not a failure; anything else not finite is.
pub fn non_finite(summary: &crate::metrics::results::Summary) -> Vec<String> {
    let mut check = summary.clone();
    for s in &mut check.schemes {
        let ss = &mut s.steady_state;
        (ss.mse_se, ss.trace_se, ss.rate_se) = (0.0, 0.0, 0.0);
    }
    crate::metrics::finite::non_finite(&check)
}
