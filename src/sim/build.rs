//! Scenario file -> validated experiment. Every check names the file, the field and what was
//! expected, so a user can fix a file without reading Rust.
use super::scenario::{
    FrontierSpec, ModelSpec, PaperSpec, ParamValue, Params, ScenarioFile, SensorFieldSpec,
    SensorSpec,
};
use crate::filter::Gaussian;
use crate::linalg::{check_spd, Matrix, Vector};
use crate::model::{presets, LinearSensor, LinearTransition, MeasurementModel};
use crate::model::{Placement, RangeSensor, RssSensor};
use crate::scheme::registry::{self, BuildContext};
use crate::scheme::{Scheme, System};
use rand::{Rng, SeedableRng};
use std::fmt;
use std::sync::Arc;

/// A scenario that could not be read or is inconsistent.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// File (or built-in name) the scenario came from.
    pub file: String,
    /// Field path, e.g. `sensors[2].R`.
    pub field: String,
    /// What was expected and what was found.
    pub message: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}: field `{}`: {}", self.file, self.field, self.message)
        }
    }
}

impl std::error::Error for ScenarioError {}

/// One scheme at one sweep point, ready to run.
#[derive(Debug)]
pub struct Variant {
    /// Index of the scheme entry in the file (a curve).
    pub curve: usize,
    /// Parameters of this point, as written (kind-specific numbers).
    pub params: Params,
    /// The scheme's `kind`, as registered.
    pub kind: &'static str,
    pub scheme: Box<dyn Scheme>,
}

/// One `[[schemes]]` entry: a curve of one or more variants.
#[derive(Debug, Clone)]
pub struct Curve {
    pub label: String,
    pub kind: String,
    /// Names of the swept parameters (empty when not swept).
    pub swept: Vec<String>,
    pub frontier: Option<FrontierSpec>,
}

/// A validated experiment.
#[derive(Debug)]
pub struct Experiment {
    pub name: String,
    pub description: String,
    pub source: String,
    pub system: Arc<System>,
    /// Distribution of the true x_0 (the filters' prior unless the file says otherwise).
    pub initial_truth: Gaussian,
    pub groups: Vec<(String, Vec<usize>)>,
    pub curves: Vec<Curve>,
    pub variants: Vec<Variant>,
    pub trials: usize,
    pub steps: usize,
    pub seed: u64,
    /// First step (1-based) of the steady-state averages.
    pub steady_from: usize,
    pub paper: Option<PaperSpec>,
}

struct Ctx<'a> {
    file: &'a str,
}

impl Ctx<'_> {
    fn err(&self, field: impl Into<String>, message: impl Into<String>) -> ScenarioError {
        ScenarioError {
            file: self.file.to_string(),
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Parses TOML text into the file structure.
pub fn parse(text: &str, file: &str) -> Result<ScenarioFile, ScenarioError> {
    toml::from_str(text).map_err(|e| ScenarioError {
        file: file.to_string(),
        field: e
            .span()
            .map(|s| field_at(text, s.start))
            .unwrap_or_default(),
        message: e.message().to_string(),
    })
}

/// Best-effort name of the key or table around a byte offset, for error messages.
fn field_at(text: &str, offset: usize) -> String {
    let upto = &text[..offset.min(text.len())];
    let line_no = upto.matches('\n').count() + 1;
    let line = text.lines().nth(line_no - 1).unwrap_or("").trim();
    let key = line.split('=').next().unwrap_or("").trim();
    let table = upto
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('['))
        .map(|l| l.trim().to_string())
        .unwrap_or_default();
    match (table.is_empty(), key.is_empty() || key.starts_with('[')) {
        (true, true) => format!("top level (line {line_no})"),
        (true, false) => format!("{key} (line {line_no})"),
        (false, true) => format!("{table} (line {line_no})"),
        (false, false) => format!("{table} {key} (line {line_no})"),
    }
}

/// Parses and validates a scenario.
pub fn load(text: &str, file: &str) -> Result<Experiment, ScenarioError> {
    let parsed = parse(text, file)?;
    build(parsed, file)
}

fn matrix(ctx: &Ctx, field: &str, rows: &[Vec<f64>]) -> Result<Matrix, ScenarioError> {
    if rows.is_empty() {
        return Err(ctx.err(field, "expected a non-empty matrix (a list of rows)"));
    }
    let cols = rows[0].len();
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
        return Err(ctx.err(
            field,
            format!("row {i} has {} entries, row 0 has {cols}", r.len()),
        ));
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(ctx.err(field, "expected finite numbers"));
    }
    Ok(crate::linalg::matrix_from_rows(rows))
}

fn covariance(ctx: &Ctx, field: &str, m: &Matrix, n: usize) -> Result<(), ScenarioError> {
    if m.nrows() != n || m.ncols() != n {
        return Err(ctx.err(
            field,
            format!("expected a {n}x{n} matrix, got {}x{}", m.nrows(), m.ncols()),
        ));
    }
    check_spd(m).map_err(|e| {
        ctx.err(
            field,
            format!("expected a symmetric positive definite covariance: {e}"),
        )
    })
}

fn transition(ctx: &Ctx, spec: &ModelSpec) -> Result<LinearTransition, ScenarioError> {
    let discrete = |noise: &Option<String>| -> Result<bool, ScenarioError> {
        match noise.as_deref() {
            None | Some("continuous") => Ok(false),
            Some("discrete") => Ok(true),
            Some(other) => Err(ctx.err(
                "model.noise",
                format!("expected \"continuous\" or \"discrete\", got {other:?}"),
            )),
        }
    };
    let built = match spec {
        ModelSpec::ConstantVelocity1d { dt, sigma2, noise } => {
            if discrete(noise)? {
                presets::constant_velocity_1d_discrete(*dt, *sigma2)
            } else {
                presets::constant_velocity_1d(*dt, *sigma2)
            }
        }
        ModelSpec::ConstantVelocity2d { dt, sigma2, noise } => {
            if discrete(noise)? {
                presets::constant_velocity_2d_discrete(*dt, *sigma2)
            } else {
                presets::constant_velocity_2d(*dt, *sigma2)
            }
        }
        ModelSpec::NearConstantAcceleration2d { dt, sigma2 } => {
            presets::near_constant_acceleration_2d(*dt, *sigma2)
        }
        ModelSpec::RotationOscillator { omega, dt, q } => {
            presets::rotation_oscillator(*omega, *dt, *q)
        }
        ModelSpec::Matrix { f, q } => {
            let f = matrix(ctx, "model.F", f)?;
            let q = matrix(ctx, "model.Q", q)?;
            LinearTransition::new(f, q)
        }
    };
    built.map_err(|e| ctx.err("model", e.to_string()))
}

/// Validates every field and builds the runtime objects.
pub fn build(file_spec: ScenarioFile, file: &str) -> Result<Experiment, ScenarioError> {
    let ctx = Ctx { file };
    if file_spec.trials == 0 {
        return Err(ctx.err("trials", "expected at least 1 trial"));
    }
    if file_spec.steps == 0 {
        return Err(ctx.err("steps", "expected at least 1 step"));
    }
    let transition = transition(&ctx, &file_spec.model)?;
    let n = transition.dim();

    // Prior, and the truth's initial distribution.
    let prior = gaussian_spec(&ctx, "prior", &file_spec.prior, n, false)?;
    let initial_truth = match &file_spec.initial_truth {
        Some(t) => gaussian_spec(&ctx, "initial_truth", t, n, true)?,
        None => prior.clone(),
    };

    // Sensors.
    let mut sensors: Vec<Arc<dyn MeasurementModel>> = Vec::new();
    for (i, s) in file_spec.sensors.iter().enumerate() {
        sensors.push(sensor(&ctx, &format!("sensors[{i}]"), s, n)?);
    }
    for (j, field) in file_spec.sensor_fields.iter().enumerate() {
        for (m, spec) in sensor_field(&ctx, j, field)?.iter().enumerate() {
            sensors.push(sensor(
                &ctx,
                &format!("sensor_fields[{j}] (sensor {m})"),
                spec,
                n,
            )?);
        }
    }
    if sensors.is_empty() {
        return Err(ctx.err(
            "sensors",
            "expected at least one [[sensors]] or [[sensor_fields]] entry",
        ));
    }

    // Groups.
    let mut groups = Vec::new();
    for (name, value) in &file_spec.groups {
        let idx: Vec<usize> = value.clone().try_into().map_err(|_| {
            ctx.err(
                format!("groups.{name}"),
                "expected a list of state indices, e.g. position = [0, 3]",
            )
        })?;
        if idx.is_empty() {
            return Err(ctx.err(
                format!("groups.{name}"),
                "expected at least one state index",
            ));
        }
        if let Some(bad) = idx.iter().find(|&&j| j >= n) {
            return Err(ctx.err(
                format!("groups.{name}"),
                format!("state index {bad} is outside the state dimension {n}"),
            ));
        }
        groups.push((name.clone(), idx));
    }
    if groups.is_empty() {
        groups.push(("state".to_string(), (0..n).collect()));
    }

    let steady_from = file_spec
        .steady_state_from
        .unwrap_or(file_spec.steps / 2 + 1);
    if steady_from == 0 || steady_from > file_spec.steps {
        return Err(ctx.err(
            "steady_state_from",
            format!(
                "expected a step in 1..={}, got {steady_from}",
                file_spec.steps
            ),
        ));
    }

    let system = Arc::new(System {
        transition,
        sensors,
        prior,
    });

    // Schemes and sweeps.
    if file_spec.schemes.is_empty() {
        return Err(ctx.err("schemes", "expected at least one [[schemes]] entry"));
    }
    let mut curves = Vec::new();
    let mut variants = Vec::new();
    for (ci, table) in file_spec.schemes.iter().enumerate() {
        let field = format!("schemes[{ci}]");
        let mut base = table.clone();
        let label = match base.remove("label") {
            Some(toml::Value::String(s)) => Some(s),
            Some(_) => return Err(ctx.err(format!("{field}.label"), "expected a string")),
            None => None,
        };
        let frontier = match base.remove("frontier") {
            Some(v) => {
                let f: FrontierSpec = v.try_into().map_err(|e: toml::de::Error| {
                    ctx.err(format!("{field}.frontier"), e.message().to_string())
                })?;
                if f.metric != "trace" && f.metric != "mse" {
                    return Err(ctx.err(
                        format!("{field}.frontier.metric"),
                        format!("expected \"trace\" or \"mse\", got {:?}", f.metric),
                    ));
                }
                if !(f.bin_width.is_finite() && f.bin_width > 0.0) {
                    return Err(ctx.err(
                        format!("{field}.frontier.bin_width"),
                        "expected a positive number",
                    ));
                }
                Some(f)
            }
            None => None,
        };
        let sweep: Vec<(String, Vec<toml::Value>)> = match base.remove("sweep") {
            None => Vec::new(),
            Some(toml::Value::Table(t)) => {
                let mut v = Vec::new();
                for (k, vals) in t {
                    match vals {
                        toml::Value::Array(a) if !a.is_empty() => v.push((k, a)),
                        _ => {
                            return Err(ctx.err(
                                format!("{field}.sweep.{k}"),
                                "expected a non-empty list of values",
                            ))
                        }
                    }
                }
                v
            }
            Some(_) => {
                return Err(ctx.err(
                    format!("{field}.sweep"),
                    "expected a table, e.g. sweep = { rate = [0.5, 1.0] }",
                ))
            }
        };
        let points = grid(&sweep);
        let mut kind = String::new();
        let mut curve_label = label.clone();
        for point in points {
            let mut t = base.clone();
            let mut desc = Vec::new();
            for (k, v) in &point {
                t.insert(k.clone(), v.clone());
                desc.push(format!("{k} = {v}"));
            }
            let at = if desc.is_empty() {
                field.clone()
            } else {
                format!("{field} (sweep point {})", desc.join(", "))
            };
            let kind_name = match t.get("kind") {
                Some(toml::Value::String(k)) => k.clone(),
                Some(_) => return Err(ctx.err(format!("{field}.kind"), "expected a string")),
                None => {
                    return Err(ctx.err(
                        format!("{field}.kind"),
                        format!(
                            "missing the scheme `kind`; one of {}",
                            registry::kinds().join(", ")
                        ),
                    ))
                }
            };
            let entry = registry::find(&kind_name).ok_or_else(|| {
                ctx.err(
                    format!("{field}.kind"),
                    format!(
                        "unknown scheme kind {kind_name:?}; expected one of {}",
                        registry::kinds().join(", ")
                    ),
                )
            })?;
            kind = entry.kind.to_string();
            if curve_label.is_none() {
                curve_label = Some(entry.label.to_string());
            }
            let params: Params = t
                .iter()
                .filter(|(k, _)| k.as_str() != "kind")
                .filter_map(|(k, v)| match v {
                    toml::Value::Float(x) => Some((k.clone(), ParamValue::Number(*x))),
                    toml::Value::Integer(x) => Some((k.clone(), ParamValue::Number(*x as f64))),
                    toml::Value::Boolean(b) => Some((k.clone(), ParamValue::Flag(*b))),
                    toml::Value::String(s) => Some((k.clone(), ParamValue::Text(s.clone()))),
                    _ => None,
                })
                .collect();
            let mut table = t.clone();
            table.remove("kind");
            let cx = BuildContext {
                system: &system,
                steps: file_spec.steps,
            };
            let scheme = (entry.build)(table, &cx).map_err(|e| match &e.field {
                Some(f) => ctx.err(format!("{at}.{f}"), e.message.clone()),
                None => ctx.err(&at, e.message.clone()),
            })?;
            variants.push(Variant {
                curve: ci,
                params,
                kind: entry.kind,
                scheme,
            });
        }
        curves.push(Curve {
            label: curve_label.unwrap_or_default(),
            kind,
            swept: sweep.iter().map(|(k, _)| k.clone()).collect(),
            frontier,
        });
    }
    let mut seen = std::collections::BTreeSet::new();
    for c in &curves {
        if !seen.insert(c.label.clone()) {
            return Err(ctx.err(
                "schemes",
                format!(
                    "two schemes share the label {:?}; give each a distinct `label`",
                    c.label
                ),
            ));
        }
    }

    Ok(Experiment {
        name: file_spec.name,
        description: file_spec.description,
        source: file.to_string(),
        system,
        initial_truth,
        groups,
        curves,
        variants,
        trials: file_spec.trials,
        steps: file_spec.steps,
        seed: file_spec.seed,
        steady_from,
        paper: file_spec.paper,
    })
}

/// A Gaussian from a `mean` and `cov`/`cov_diag`; the truth's may be semi-definite (a known
/// start), the filters' prior must be definite.
fn gaussian_spec(
    ctx: &Ctx,
    name: &str,
    p: &super::scenario::PriorSpec,
    n: usize,
    semidefinite: bool,
) -> Result<Gaussian, ScenarioError> {
    if p.mean.len() != n {
        return Err(ctx.err(
            format!("{name}.mean"),
            format!(
                "expected {n} entries (the model's state dimension), got {}",
                p.mean.len()
            ),
        ));
    }
    if p.mean.iter().any(|v| !v.is_finite()) {
        return Err(ctx.err(format!("{name}.mean"), "expected finite numbers"));
    }
    let (cov, field) = match (&p.cov, &p.cov_diag) {
        (Some(c), None) => (
            matrix(ctx, &format!("{name}.cov"), c)?,
            format!("{name}.cov"),
        ),
        (None, Some(d)) => {
            if d.len() != n {
                return Err(ctx.err(
                    format!("{name}.cov_diag"),
                    format!("expected {n} entries, got {}", d.len()),
                ));
            }
            if d.iter().any(|v| !v.is_finite()) {
                return Err(ctx.err(format!("{name}.cov_diag"), "expected finite numbers"));
            }
            (
                Matrix::from_diagonal(&Vector::from_vec(d.clone())),
                format!("{name}.cov_diag"),
            )
        }
        _ => return Err(ctx.err(name, "give exactly one of `cov` and `cov_diag`")),
    };
    if semidefinite {
        if cov.nrows() != n || cov.ncols() != n {
            return Err(ctx.err(&field, format!("expected a {n}x{n} matrix")));
        }
        crate::model::transition::psd_sqrt(&cov).map_err(|e| {
            ctx.err(
                &field,
                format!("expected a symmetric positive semi-definite covariance: {e}"),
            )
        })?;
    } else {
        covariance(ctx, &field, &cov, n)?;
    }
    Ok(Gaussian::new(Vector::from_vec(p.mean.clone()), cov))
}

/// One sensor from its spec; `at` names it in errors.
fn sensor(
    ctx: &Ctx,
    at: &str,
    s: &SensorSpec,
    n: usize,
) -> Result<Arc<dyn MeasurementModel>, ScenarioError> {
    let f = |name: &str| format!("{at}.{name}");
    let kind = s.kind.as_deref().unwrap_or("linear");
    if kind != "linear" {
        return placed_sensor(ctx, at, kind, s, n);
    }
    for (name, present) in [
        ("position", s.position.is_some()),
        ("position_indices", s.position_indices.is_some()),
        ("p0", s.p0.is_some()),
        ("path_loss_alpha", s.path_loss_alpha.is_some()),
        ("path_loss_exponent", s.path_loss_exponent.is_some()),
    ] {
        if present {
            return Err(ctx.err(f(name), "only for `range` and `rss` sensors"));
        }
    }
    let h = match (&s.h, &s.observe) {
        (Some(h), None) => {
            let h = matrix(ctx, &f("H"), h)?;
            if h.ncols() != n {
                return Err(ctx.err(
                    f("H"),
                    format!(
                        "expected {n} columns (the state dimension), got {}",
                        h.ncols()
                    ),
                ));
            }
            h
        }
        (None, Some(idx)) => {
            if idx.is_empty() {
                return Err(ctx.err(f("observe"), "expected at least one state index"));
            }
            if let Some(bad) = idx.iter().find(|&&j| j >= n) {
                return Err(ctx.err(
                    f("observe"),
                    format!("state index {bad} is outside the state dimension {n}"),
                ));
            }
            let mut h = Matrix::zeros(idx.len(), n);
            for (row, &j) in idx.iter().enumerate() {
                h[(row, j)] = 1.0;
            }
            h
        }
        _ => return Err(ctx.err(at.to_string(), "give exactly one of `H` and `observe`")),
    };
    let m = h.nrows();
    let (r, rname) = match (&s.r, &s.r_diag) {
        (Some(r), None) => (matrix(ctx, &f("R"), r)?, f("R")),
        (None, Some(d)) => {
            if d.len() != m {
                return Err(ctx.err(
                    f("R_diag"),
                    format!(
                        "expected {m} entries (one per measured component), got {}",
                        d.len()
                    ),
                ));
            }
            (
                Matrix::from_diagonal(&Vector::from_vec(d.clone())),
                f("R_diag"),
            )
        }
        _ => return Err(ctx.err(at.to_string(), "give exactly one of `R` and `R_diag`")),
    };
    covariance(ctx, &rname, &r, m)?;
    let sensor = LinearSensor::new(h, r).map_err(|e| ctx.err(at, e.to_string()))?;
    Ok(Arc::new(sensor))
}

/// A range or RSS sensor: position, target indices and a scalar noise variance.
fn placed_sensor(
    ctx: &Ctx,
    at: &str,
    kind: &str,
    s: &SensorSpec,
    n: usize,
) -> Result<Arc<dyn MeasurementModel>, ScenarioError> {
    let f = |name: &str| format!("{at}.{name}");
    if s.h.is_some() || s.observe.is_some() {
        return Err(ctx.err(at, format!("a `{kind}` sensor has no `H` or `observe`")));
    }
    let position = s
        .position
        .ok_or_else(|| ctx.err(f("position"), "expected the sensor position [x, y]"))?;
    let indices = s.position_indices.ok_or_else(|| {
        ctx.err(
            f("position_indices"),
            "expected the state indices of the target's [x, y]",
        )
    })?;
    if let Some(bad) = indices.iter().find(|&&j| j >= n) {
        return Err(ctx.err(
            f("position_indices"),
            format!("state index {bad} is outside the state dimension {n}"),
        ));
    }
    let r = match (&s.r, &s.r_diag) {
        (Some(r), None) if r.len() == 1 && r[0].len() == 1 => r[0][0],
        (None, Some(d)) if d.len() == 1 => d[0],
        _ => {
            return Err(ctx.err(
                f("R"),
                "expected the scalar noise variance as R = [[r]] or R_diag = [r]",
            ))
        }
    };
    if !(r.is_finite() && r > 0.0) {
        return Err(ctx.err(f("R"), format!("expected a positive variance, got {r}")));
    }
    let placement = Placement {
        position,
        indices,
        state_dim: n,
    };
    let built: Result<Arc<dyn MeasurementModel>, _> = match kind {
        "range" => RangeSensor::new(placement, r).map(|s| Arc::new(s) as Arc<dyn MeasurementModel>),
        "rss" => {
            let need = |v: Option<f64>, name: &str| {
                v.ok_or_else(|| ctx.err(f(name), "expected a positive number for an `rss` sensor"))
            };
            RssSensor::new(
                placement,
                need(s.p0, "p0")?,
                need(s.path_loss_alpha, "path_loss_alpha")?,
                need(s.path_loss_exponent, "path_loss_exponent")?,
                r,
            )
            .map(|s| Arc::new(s) as Arc<dyn MeasurementModel>)
        }
        other => {
            return Err(ctx.err(
                f("kind"),
                format!("unknown sensor kind {other:?}; expected `linear`, `range` or `rss`"),
            ))
        }
    };
    built.map_err(|e| ctx.err(at, e.to_string()))
}

/// The sensor specs of a field: random positions from the field's own seed, or grid cells.
fn sensor_field(
    ctx: &Ctx,
    j: usize,
    field: &SensorFieldSpec,
) -> Result<Vec<SensorSpec>, ScenarioError> {
    let at = |name: &str| format!("sensor_fields[{j}].{name}");
    let [x0, x1, y0, y1] = field.area;
    if !(field.area.iter().all(|v| v.is_finite()) && x0 < x1 && y0 < y1) {
        return Err(ctx.err(
            at("area"),
            "expected [x_min, x_max, y_min, y_max] with min < max",
        ));
    }
    let positions: Vec<[f64; 2]> = match field.layout.as_str() {
        "random" => {
            let count = field
                .count
                .filter(|&c| c > 0)
                .ok_or_else(|| ctx.err(at("count"), "expected a positive number of sensors"))?;
            let seed = field
                .seed
                .ok_or_else(|| ctx.err(at("seed"), "expected the placement seed"))?;
            let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
            (0..count)
                .map(|_| {
                    let u: f64 = rng.random();
                    let v: f64 = rng.random();
                    [x0 + u * (x1 - x0), y0 + v * (y1 - y0)]
                })
                .collect()
        }
        "grid" => {
            let [nx, ny] = field
                .grid
                .filter(|g| g[0] > 0 && g[1] > 0)
                .ok_or_else(|| ctx.err(at("grid"), "expected [nx, ny] with positive counts"))?;
            let mut p = Vec::with_capacity(nx * ny);
            for iy in 0..ny {
                for ix in 0..nx {
                    p.push([
                        x0 + (ix as f64 + 0.5) * (x1 - x0) / nx as f64,
                        y0 + (iy as f64 + 0.5) * (y1 - y0) / ny as f64,
                    ]);
                }
            }
            p
        }
        other => {
            return Err(ctx.err(
                at("layout"),
                format!("unknown layout {other:?}; expected `random` or `grid`"),
            ))
        }
    };
    Ok(positions
        .into_iter()
        .map(|position| SensorSpec {
            kind: Some(field.kind.clone()),
            position: Some(position),
            position_indices: Some(field.position_indices),
            r_diag: Some(vec![field.r]),
            p0: field.p0,
            path_loss_alpha: field.path_loss_alpha,
            path_loss_exponent: field.path_loss_exponent,
            ..SensorSpec::default()
        })
        .collect())
}

/// Cartesian product of the sweep lists, in file order.
fn grid(sweep: &[(String, Vec<toml::Value>)]) -> Vec<Vec<(String, toml::Value)>> {
    let mut points: Vec<Vec<(String, toml::Value)>> = vec![Vec::new()];
    for (k, vals) in sweep {
        let mut next = Vec::new();
        for p in &points {
            for v in vals {
                let mut q = p.clone();
                q.push((k.clone(), v.clone()));
                next.push(q);
            }
        }
        points = next;
    }
    points
}
