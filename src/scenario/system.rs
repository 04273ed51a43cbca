//! The system a scenario describes: motion model, prior, initial truth, sensors (one by one or
//! as placed fields) and the reported state groups, each validated with errors that name the
//! field.
use crate::filter::Gaussian;
use crate::linalg::{check_spd, Matrix, Vector};
use crate::model::{presets, LinearSensor, LinearTransition, MeasurementModel};
use crate::model::{Placement, RangeSensor, RssSensor};
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scenario::{
    Layout, ModelSpec, NoiseForm, PlacedKind, PriorSpec, SensorFieldSpec, SensorKind, SensorSpec,
};
use rand::{Rng, SeedableRng};
use std::sync::Arc;

/// Most sensors a scenario may place: each sensor costs every scheme work at every step, and
/// a typo in a grid (`grid = [100000, 100000]`) must not exhaust the machine.
pub const MAX_SENSORS: usize = 100_000;
/// Largest state dimension: covariances are dense n x n.
pub const MAX_STATE_DIM: usize = 1_000;

pub(crate) fn matrix(ctx: &Ctx, field: &str, rows: &[Vec<f64>]) -> Result<Matrix, ScenarioError> {
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

pub(crate) fn covariance(
    ctx: &Ctx,
    field: &str,
    m: &Matrix,
    n: usize,
) -> Result<(), ScenarioError> {
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

pub(crate) fn transition(ctx: &Ctx, spec: &ModelSpec) -> Result<LinearTransition, ScenarioError> {
    let discrete = |noise: &NoiseForm| *noise == NoiseForm::Discrete;
    let positive = |name: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(ctx.err(
                format!("model.{name}"),
                format!("expected a finite positive number, got {v}"),
            ))
        }
    };
    match spec {
        ModelSpec::ConstantVelocity1d { dt, sigma2, .. }
        | ModelSpec::ConstantVelocity2d { dt, sigma2, .. }
        | ModelSpec::NearConstantAcceleration2d { dt, sigma2 } => {
            positive("dt", *dt)?;
            positive("sigma2", *sigma2)?;
        }
        ModelSpec::RotationOscillator { omega, dt, q } => {
            positive("dt", *dt)?;
            positive("q", *q)?;
            if !omega.is_finite() {
                return Err(ctx.err("model.omega", "expected a finite number"));
            }
        }
        ModelSpec::Matrix { .. } => {}
    }
    let built = match spec {
        ModelSpec::ConstantVelocity1d { dt, sigma2, noise } => {
            if discrete(noise) {
                presets::constant_velocity_1d_discrete(*dt, *sigma2)
            } else {
                presets::constant_velocity_1d(*dt, *sigma2)
            }
        }
        ModelSpec::ConstantVelocity2d { dt, sigma2, noise } => {
            if discrete(noise) {
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
            if f.nrows() > MAX_STATE_DIM {
                return Err(ctx.err(
                    "model.F",
                    format!("at most {MAX_STATE_DIM} states, got {}", f.nrows()),
                ));
            }
            let q = matrix(ctx, "model.Q", q)?;
            return LinearTransition::new(f, q).map_err(|e| {
                let field = if e.to_string().contains("process noise") {
                    "model.Q"
                } else {
                    "model.F"
                };
                ctx.err(field, e.to_string())
            });
        }
    };
    built.map_err(|e| ctx.err("model", e.to_string()))
}

/// A Gaussian from a `mean` and `cov`/`cov_diag`; the truth's may be semi-definite (a known
/// start), the filters' prior must be definite.
pub(crate) fn gaussian_spec(
    ctx: &Ctx,
    name: &str,
    p: &PriorSpec,
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
pub(crate) fn sensor(
    ctx: &Ctx,
    at: &str,
    s: &SensorSpec,
    n: usize,
) -> Result<Arc<dyn MeasurementModel>, ScenarioError> {
    let f = |name: &str| format!("{at}.{name}");
    let kind = match s.kind {
        SensorKind::Linear => None,
        SensorKind::Range => Some(PlacedKind::Range),
        SensorKind::Rss => Some(PlacedKind::Rss),
    };
    if let Some(kind) = kind {
        return placed_sensor(ctx, at, kind, s, n);
    }
    // A linear sensor may have a position: where its node sits in a `[network]` (the edge
    // rules `radius` and `grid`, distance loss, the map); its measurement does not use it.
    if s.position.is_some_and(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(ctx.err(f("position"), "expected finite coordinates"));
    }
    for (name, present) in [
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
    kind: PlacedKind,
    s: &SensorSpec,
    n: usize,
) -> Result<Arc<dyn MeasurementModel>, ScenarioError> {
    let f = |name: &str| format!("{at}.{name}");
    let name = match kind {
        PlacedKind::Range => "range",
        PlacedKind::Rss => "rss",
    };
    if s.h.is_some() || s.observe.is_some() {
        return Err(ctx.err(at, format!("a `{name}` sensor has no `H` or `observe`")));
    }
    if kind == PlacedKind::Range {
        for (field, present) in [
            ("p0", s.p0.is_some()),
            ("path_loss_alpha", s.path_loss_alpha.is_some()),
            ("path_loss_exponent", s.path_loss_exponent.is_some()),
        ] {
            if present {
                return Err(ctx.err(f(field), "only for `rss` sensors"));
            }
        }
    }
    if let Some(p) = s.position {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(ctx.err(f("position"), "expected finite coordinates"));
        }
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
        PlacedKind::Range => {
            RangeSensor::new(placement, r).map(|s| Arc::new(s) as Arc<dyn MeasurementModel>)
        }
        PlacedKind::Rss => {
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
    };
    built.map_err(|e| ctx.err(at, e.to_string()))
}

/// The sensor specs of a field: random positions from the field's own seed, or grid cells.
pub(crate) fn sensor_field(
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
    let positions: Vec<[f64; 2]> = match field.layout {
        Layout::Random => {
            if field.grid.is_some() {
                return Err(ctx.err(
                    at("grid"),
                    "only for layout = \"grid\" (this field is random)",
                ));
            }
            let count = field
                .count
                .filter(|&c| c > 0)
                .ok_or_else(|| ctx.err(at("count"), "expected a positive number of sensors"))?;
            if count > MAX_SENSORS {
                return Err(ctx.err(
                    at("count"),
                    format!("at most {MAX_SENSORS} sensors, got {count}"),
                ));
            }
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
        Layout::Grid => {
            for (name, present) in [
                ("count", field.count.is_some()),
                ("seed", field.seed.is_some()),
            ] {
                if present {
                    return Err(ctx.err(
                        at(name),
                        "only for layout = \"random\"; a grid has grid = [nx, ny] sensors",
                    ));
                }
            }
            let [nx, ny] = field
                .grid
                .filter(|g| g[0] > 0 && g[1] > 0)
                .ok_or_else(|| ctx.err(at("grid"), "expected [nx, ny] with positive counts"))?;
            if nx.saturating_mul(ny) > MAX_SENSORS {
                return Err(ctx.err(
                    at("grid"),
                    format!("at most {MAX_SENSORS} sensors, got {nx} x {ny}"),
                ));
            }
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
    };
    Ok(positions
        .into_iter()
        .map(|position| SensorSpec {
            kind: match field.kind {
                PlacedKind::Range => SensorKind::Range,
                PlacedKind::Rss => SensorKind::Rss,
            },
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

/// The validated system of a scenario, with the truth's initial distribution and the groups.
pub(crate) struct SystemParts {
    pub system: crate::scheme::System,
    pub initial_truth: Gaussian,
    pub groups: Vec<(String, Vec<usize>)>,
}

/// Builds and checks the motion model, prior, initial truth, sensors and groups.
pub(crate) fn build_system(
    ctx: &Ctx,
    file: &crate::scenario::ScenarioFile,
) -> Result<SystemParts, ScenarioError> {
    let transition = transition(ctx, &file.model)?;
    let n = transition.dim();

    // Prior, and the truth's initial distribution.
    let prior = gaussian_spec(ctx, "prior", &file.prior, n, false)?;
    let initial_truth = match &file.initial_truth {
        Some(t) => gaussian_spec(ctx, "initial_truth", t, n, true)?,
        None => prior.clone(),
    };

    // Sensors: the count is checked before any is built.
    let placed: usize = file
        .sensor_fields
        .iter()
        .map(|f| match f.layout {
            Layout::Random => f.count.unwrap_or(0),
            Layout::Grid => f.grid.map_or(0, |g| g[0].saturating_mul(g[1])),
        })
        .fold(file.sensors.len(), usize::saturating_add);
    if placed > MAX_SENSORS {
        return Err(ctx.err(
            "sensor_fields",
            format!("at most {MAX_SENSORS} sensors in all, got {placed}"),
        ));
    }
    let mut sensors: Vec<Arc<dyn MeasurementModel>> = Vec::new();
    for (i, s) in file.sensors.iter().enumerate() {
        sensors.push(sensor(ctx, &format!("sensors[{i}]"), s, n)?);
    }
    for (j, field) in file.sensor_fields.iter().enumerate() {
        for (m, spec) in sensor_field(ctx, j, field)?.iter().enumerate() {
            sensors.push(sensor(
                ctx,
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
    let groups = groups(ctx, &file.groups, n)?;
    Ok(SystemParts {
        system: crate::scheme::System {
            transition,
            sensors,
            prior,
        },
        initial_truth,
        groups,
    })
}

/// Named groups of state indices, in file order; one group `state` of every index by default.
fn groups(
    ctx: &Ctx,
    table: &toml::Table,
    n: usize,
) -> Result<Vec<(String, Vec<usize>)>, ScenarioError> {
    let mut groups = Vec::new();
    for (name, value) in table {
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
    Ok(groups)
}
