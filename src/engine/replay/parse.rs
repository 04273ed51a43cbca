//! The recorded CSV files of a replay, read and checked on their own (before a scenario is
//! involved): the measurements (long form) and the optional truth, in the layout described in
//! the parent module's documentation; [`steps_of`] says how many steps they make.
use crate::scenario::build;
use std::collections::HashMap;
use std::fmt;
/// Bad recorded data: the file, the line (and data row) and the column it is about.
#[derive(Debug, Clone, PartialEq)]
pub struct DataError {
    pub file: String,
    /// Line of the file (1-based; the header is line 1).
    pub line: Option<usize>,
    /// Data row (1-based: the first row after the header).
    pub row: Option<usize>,
    /// Column (1-based) and its header name.
    pub column: Option<(usize, String)>,
    pub message: String,
}

impl fmt::Display for DataError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.file)?;
        match (self.line, self.row) {
            (Some(l), Some(r)) => write!(f, " line {l} (data row {r}),")?,
            (Some(l), None) => write!(f, " line {l},")?,
            _ => {}
        }
        if let Some((c, name)) = &self.column {
            write!(f, " column {c} ({name}):")?;
        }
        write!(f, " {}", self.message)
    }
}

impl std::error::Error for DataError {}

/// Where in a file.
#[derive(Debug, Clone, Copy)]
pub(super) struct At {
    pub(super) line: usize,
    pub(super) row: usize,
}

/// One measurement row as read (not yet checked against a scenario).
#[derive(Debug, Clone)]
pub struct MeasRow {
    pub(super) line: usize,
    pub(super) row: usize,
    pub step: usize,
    pub sensor: usize,
    pub values: Vec<f64>,
}

/// A measurements file as read: rows whose numbers and order have been checked.
#[derive(Debug, Clone)]
pub struct MeasTable {
    pub file: String,
    pub(super) header: Vec<String>,
    pub rows: Vec<MeasRow>,
}

/// A truth file as read: one row per step 1..=T.
#[derive(Debug, Clone)]
pub struct TruthTable {
    pub file: String,
    pub(super) header: Vec<String>,
    pub(super) rows: Vec<(At, Vec<f64>)>,
}

impl TruthTable {
    /// Number of steps (rows).
    pub fn steps(&self) -> usize {
        self.rows.len()
    }
}

pub(super) fn col_name(header: &[String], c: usize) -> (usize, String) {
    (
        c + 1,
        header
            .get(c)
            .cloned()
            .unwrap_or_else(|| "beyond the header".to_string()),
    )
}

pub(super) fn err_at(
    file: &str,
    at: Option<At>,
    column: Option<(usize, String)>,
    m: String,
) -> DataError {
    DataError {
        file: file.to_string(),
        line: at.map(|a| a.line),
        row: at.map(|a| a.row),
        column,
        message: m,
    }
}

fn reader(text: &str) -> csv::Reader<&[u8]> {
    csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes())
}

fn csv_error(file: &str, e: &csv::Error) -> DataError {
    let line = e.position().map(|p| p.line() as usize);
    DataError {
        file: file.to_string(),
        line,
        row: None,
        column: None,
        message: format!("not a readable CSV file: {e}"),
    }
}

fn header_of(
    rdr: &mut csv::Reader<&[u8]>,
    file: &str,
    first: &[&str],
) -> Result<Vec<String>, DataError> {
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| csv_error(file, &e))?
        .iter()
        .map(str::to_string)
        .collect();
    let expected = format!("{},...", first.join(","));
    if header.len() <= first.len() || header.iter().all(|h| h.is_empty()) {
        return Err(err_at(
            file,
            None,
            None,
            format!(
                "line 1: expected a header row `{expected}` with at least one component column, got {:?}",
                header.join(",")
            ),
        ));
    }
    for (c, want) in first.iter().enumerate() {
        if !header[c].eq_ignore_ascii_case(want) {
            return Err(DataError {
                file: file.to_string(),
                line: Some(1),
                row: None,
                column: Some(col_name(&header, c)),
                message: format!(
                    "expected the header row to start with `{expected}`, got {:?} here",
                    header[c]
                ),
            });
        }
    }
    Ok(header)
}

/// Whole number >= 1 (steps) or >= 0 (sensors).
fn parse_index(s: &str, min: usize, what: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(v) if v >= min => Ok(v),
        Ok(v) => Err(format!("{what} must be at least {min}, got {v}")),
        Err(_) => Err(format!(
            "expected {what} as a whole number >= {min}, got {s:?}"
        )),
    }
}

/// The components of a row from column `from` on: numbers, then possibly empty fields.
fn parse_components(
    rec: &csv::StringRecord,
    from: usize,
    file: &str,
    at: At,
    header: &[String],
) -> Result<Vec<f64>, DataError> {
    let fields: Vec<&str> = rec.iter().skip(from).collect();
    let used = fields.len() - fields.iter().rev().take_while(|f| f.is_empty()).count();
    let mut values = Vec::with_capacity(used);
    for (j, f) in fields[..used].iter().enumerate() {
        let col = || Some(col_name(header, from + j));
        if f.is_empty() {
            return Err(err_at(
                file,
                Some(at),
                col(),
                "empty field before further components (only trailing fields may be empty)"
                    .to_string(),
            ));
        }
        let v: f64 = f.parse().map_err(|_| {
            err_at(
                file,
                Some(at),
                col(),
                format!("expected a number, got {f:?}"),
            )
        })?;
        if !v.is_finite() {
            return Err(err_at(
                file,
                Some(at),
                col(),
                format!("{f:?} is not a finite number"),
            ));
        }
        values.push(v);
    }
    if values.is_empty() {
        return Err(err_at(
            file,
            Some(at),
            Some(col_name(header, from)),
            "no components: a row holds one reading (leave the row out when there is none)"
                .to_string(),
        ));
    }
    Ok(values)
}

/// Reads a measurements file: numbers, step order and duplicates are checked here, sensor
/// indices and dimensions against a scenario by [`super::recorded`].
pub fn parse_measurements(text: &str, file: &str) -> Result<MeasTable, DataError> {
    let mut rdr = reader(text);
    let header = header_of(&mut rdr, file, &["step", "sensor"])?;
    let mut rows = Vec::new();
    let mut seen: HashMap<(usize, usize), usize> = HashMap::new();
    let mut last_step = 0;
    for (r, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| csv_error(file, &e))?;
        let line = rec.position().map_or(r + 2, |p| p.line() as usize);
        let at = At { line, row: r + 1 };
        let field = |c: usize| rec.get(c).unwrap_or("");
        let step = parse_index(field(0), 1, "a step")
            .map_err(|m| err_at(file, Some(at), Some(col_name(&header, 0)), m))?;
        let sensor = parse_index(field(1), 0, "a sensor index")
            .map_err(|m| err_at(file, Some(at), Some(col_name(&header, 1)), m))?;
        if step < last_step {
            return Err(err_at(
                file,
                Some(at),
                Some(col_name(&header, 0)),
                format!("step {step} after step {last_step}: steps out of order (rows must be sorted by step)"),
            ));
        }
        last_step = step;
        if let Some(first) = seen.insert((step, sensor), line) {
            return Err(err_at(
                file,
                Some(at),
                Some(col_name(&header, 1)),
                format!("sensor {sensor} at step {step} is duplicated (first on line {first})"),
            ));
        }
        let values = parse_components(&rec, 2, file, at, &header)?;
        rows.push(MeasRow {
            line,
            row: r + 1,
            step,
            sensor,
            values,
        });
    }
    Ok(MeasTable {
        file: file.to_string(),
        header,
        rows,
    })
}

/// Reads a truth file: one row per step 1, 2, ..., T in order.
pub fn parse_truth(text: &str, file: &str) -> Result<TruthTable, DataError> {
    let mut rdr = reader(text);
    let header = header_of(&mut rdr, file, &["step"])?;
    let mut rows = Vec::new();
    for (r, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| csv_error(file, &e))?;
        let line = rec.position().map_or(r + 2, |p| p.line() as usize);
        let at = At { line, row: r + 1 };
        let col0 = || Some(col_name(&header, 0));
        let step = parse_index(rec.get(0).unwrap_or(""), 1, "a step")
            .map_err(|m| err_at(file, Some(at), col0(), m))?;
        if r >= build::MAX_STEPS {
            return Err(err_at(
                file,
                Some(at),
                col0(),
                format!(
                    "more than {} rows: a replay has at most {} steps",
                    build::MAX_STEPS,
                    build::MAX_STEPS
                ),
            ));
        }
        if step != r + 1 {
            let what = if step <= r {
                "out of order or duplicated"
            } else {
                "a gap"
            };
            return Err(err_at(
                file,
                Some(at),
                col0(),
                format!(
                    "expected step {} here, got {step} ({what}): truth needs one row per step, in order, from step 1",
                    r + 1
                ),
            ));
        }
        rows.push((at, parse_components(&rec, 1, file, at, &header)?));
    }
    if rows.is_empty() {
        return Err(err_at(file, None, None, "no data rows".to_string()));
    }
    Ok(TruthTable {
        file: file.to_string(),
        header,
        rows,
    })
}

/// Steps of the replay: the truth's rows when there is truth (no measurement may lie beyond),
/// otherwise the last step of the measurements.
pub fn steps_of(meas: &MeasTable, truth: Option<&TruthTable>) -> Result<usize, DataError> {
    let last = meas.rows.last().map_or(0, |r| r.step);
    // The first measurement row whose step exceeds `limit`, reported at its step cell.
    let beyond = |limit: usize, why: &dyn Fn(usize) -> String| match meas
        .rows
        .iter()
        .find(|r| r.step > limit)
    {
        Some(r) => Err(err_at(
            &meas.file,
            Some(At {
                line: r.line,
                row: r.row,
            }),
            Some(col_name(&meas.header, 0)),
            why(r.step),
        )),
        None => Ok(()),
    };
    beyond(build::MAX_STEPS, &|step| {
        format!(
            "step {step} is beyond the most steps a replay can have ({}): the step column counts the time steps 1, 2, 3, ... of the recording (an index, not a time or a Unix timestamp); number the rows' steps from 1",
            build::MAX_STEPS
        )
    })?;
    match truth {
        Some(t) => {
            beyond(t.steps(), &|step| {
                format!(
                    "step {step} is beyond the last step of the truth ({}, {} steps)",
                    t.file,
                    t.steps()
                )
            })?;
            Ok(t.steps())
        }
        None if last == 0 => Err(err_at(
            &meas.file,
            None,
            None,
            "no data rows (and no truth to say how many steps there are)".to_string(),
        )),
        None => Ok(last),
    }
}
