//! Replaying readings that are already in memory (the Python package's numpy arrays): no CSV
//! text between the caller and the replay, and the same checks, coins and estimates as the
//! command line's [`super::replay_csv`].
use super::{
    check_replay_memory, load_experiment, replay, CsvReplay, Readings, Recorded, ReplayError,
    ReplayOptions,
};
use crate::linalg::Vector;

/// A row-major matrix borrowed from the caller: `data.len() == rows * cols`.
#[derive(Debug, Clone, Copy)]
pub struct Matrix<'a> {
    pub data: &'a [f64],
    pub rows: usize,
    pub cols: usize,
}

impl Matrix<'_> {
    fn row(&self, k: usize) -> &[f64] {
        &self.data[k * self.cols..(k + 1) * self.cols]
    }
}

/// Recorded data as arrays: per sensor its readings (steps × components, in sensor order; an
/// all-NaN row: no reading at that step), and optionally the truth (steps × state).
#[derive(Debug, Clone)]
pub struct Arrays<'a> {
    pub measurements: Vec<Matrix<'a>>,
    pub truth: Option<Matrix<'a>>,
}

fn data(m: String) -> ReplayError {
    ReplayError::Data(m)
}

/// Sensor `i`'s reading at step `k + 1`: `None` for an all-NaN row; a row partly NaN or with
/// an infinity is refused.
fn reading(m: &Matrix, i: usize, k: usize) -> Result<Option<Vector>, ReplayError> {
    let row = m.row(k);
    let nan = row.iter().filter(|v| v.is_nan()).count();
    if nan == row.len() {
        return Ok(None);
    }
    let at = format!("measurements[{i}] row {k} (step {})", k + 1);
    if nan > 0 {
        return Err(data(format!(
            "{at}: some components are NaN and others not (an all-NaN row means no reading)"
        )));
    }
    if row.iter().any(|v| v.is_infinite()) {
        return Err(data(format!("{at}: a component is not finite")));
    }
    Ok(Some(Vector::from_row_slice(row)))
}

/// Replays every variant of the scenario on `arrays`, as [`super::replay_csv`] replays files.
pub fn replay_arrays(
    scenario_text: &str,
    source: &str,
    arrays: &Arrays,
    opts: &ReplayOptions,
) -> Result<CsvReplay, ReplayError> {
    let Some(first) = arrays.measurements.first() else {
        return Err(data(
            "measurements: no sensor arrays given (expected one per sensor)".into(),
        ));
    };
    let steps = first.rows;
    if let Some((i, m)) = arrays
        .measurements
        .iter()
        .enumerate()
        .find(|(_, m)| m.rows != steps || m.data.len() != m.rows * m.cols)
    {
        return Err(data(format!(
            "measurements[{i}]: {} rows, measurements[0] has {steps}: every sensor's array needs the same number of steps",
            m.rows
        )));
    }
    if steps == 0 {
        return Err(data(
            "measurements: the arrays have no rows (no steps)".into(),
        ));
    }
    if let Some(t) = &arrays.truth {
        if t.rows != steps || t.data.len() != t.rows * t.cols {
            return Err(data(format!(
                "truth: {} rows, the measurements {steps}: one row per step",
                t.rows
            )));
        }
    }
    // The readings, step-major. Rows partly NaN or with an infinity are refused here, first:
    // the data's own faults, whatever the scenario.
    let mut per_step = vec![Vec::with_capacity(arrays.measurements.len()); steps];
    for (i, m) in arrays.measurements.iter().enumerate() {
        for (k, row) in per_step.iter_mut().enumerate() {
            row.push(reading(m, i, k)?);
        }
    }
    let limits = opts.load.limits.unwrap_or_default();
    let rows = arrays.measurements.len() * steps;
    let readings = Readings {
        file: "measurements",
        rows,
        last_step: steps,
    };
    check_replay_memory(
        scenario_text,
        source,
        &readings,
        steps,
        arrays.truth.is_some(),
        opts,
        &limits,
    )
    .map_err(|e| ReplayError::TooLarge(e.to_string()))?;
    let load = crate::scenario::build::LoadOptions {
        threads: opts.load.threads.max(1),
        ..opts.load
    };
    let (exp, notes) = load_experiment(scenario_text, source, steps, opts.seed, &load)
        .map_err(|e| ReplayError::scenario(&e))?;
    let sys = &exp.system;
    let given = arrays.measurements.len();
    if given != sys.n_sensors() {
        return Err(data(format!(
            "measurements: {given} sensor arrays given, but {source} has {} sensors: give one array per sensor, in sensor order (an all-NaN row where a sensor has no reading)",
            sys.n_sensors()
        )));
    }
    for (i, m) in arrays.measurements.iter().enumerate() {
        let dim = sys.sensors[i].meas_dim();
        if m.cols != dim {
            return Err(data(format!(
                "measurements[{i}]: sensor {i} measures {dim} component{}, the array has {} columns",
                if dim == 1 { "" } else { "s" },
                m.cols
            )));
        }
    }
    let truth = match &arrays.truth {
        None => None,
        Some(t) => {
            let n = sys.state_dim();
            if t.cols != n {
                return Err(data(format!(
                    "truth: the state has {n} components, the array has {} columns",
                    t.cols
                )));
            }
            Some(
                (0..steps)
                    .map(|k| Vector::from_row_slice(t.row(k)))
                    .collect(),
            )
        }
    };
    // The remaining checks (finite truth, one reading per sensor) are the CSV path's own.
    let recorded = Recorded::from_parts(&exp, per_step, truth)
        .map_err(|m| data(format!("measurements: {m}")))?;
    let replayed = replay(&exp, &recorded, opts.trial).map_err(ReplayError::Run)?;
    Ok(CsvReplay {
        exp,
        recorded,
        replayed,
        notes,
    })
}
