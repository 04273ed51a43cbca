//! Sweep expansion: a `[[schemes]]` entry with `sweep = { p = [v1, v2], ... }` becomes one
//! variant per point of the cartesian product, in file order. A sweep may not touch what
//! identifies the curve (`kind`, `label`), may not shadow a base value, and may not list a
//! value twice. A key of the entry's own link is swept by its dotted name,
//! `sweep."channel.loss" = [..]` (the entry must have a `channel` table).
use crate::scenario::error::{Ctx, ScenarioError};

/// Keys of a scheme table that are not scheme parameters.
pub const RESERVED: &[&str] = &["kind", "label", "note", "sweep", "frontier", "channel"];

/// The prefix of a swept key of the entry's own link (`channel.loss`).
pub const CHANNEL_PREFIX: &str = "channel.";

/// One point of a sweep: the parameter values it sets, in file order.
pub type Point = Vec<(String, toml::Value)>;

/// Reads and checks the `sweep` table of scheme entry `field` against its `base` parameters.
pub(crate) fn parse(
    ctx: &Ctx,
    field: &str,
    sweep: Option<toml::Value>,
    base: &toml::Table,
) -> Result<Vec<(String, Vec<toml::Value>)>, ScenarioError> {
    let table = match sweep {
        None => return Ok(Vec::new()),
        Some(toml::Value::Table(t)) => t,
        Some(_) => {
            return Err(ctx.err(
                format!("{field}.sweep"),
                "expected a table, e.g. sweep = { rate = [0.5, 1.0] }",
            ))
        }
    };
    let mut out = Vec::new();
    for (k, vals) in table {
        let at = format!("{field}.sweep.{k}");
        if RESERVED.contains(&k.as_str()) {
            return Err(ctx.err(
                at,
                if k == "channel" {
                    "`channel` cannot be swept as a whole; sweep its keys by their dotted names, e.g. sweep.\"channel.loss\" = [0.1, 0.2]".to_string()
                } else {
                    format!("`{k}` cannot be swept: one [[schemes]] entry is one curve of one kind; write one entry per {k}")
                },
            ));
        }
        if let Some(sub) = k.strip_prefix(CHANNEL_PREFIX) {
            let Some(toml::Value::Table(link)) = base.get("channel") else {
                return Err(ctx.err(
                    at,
                    format!("`{k}` is swept but the entry has no `channel` table; give one, e.g. channel = {{ kind = \"bernoulli\" }}"),
                ));
            };
            if link.contains_key(sub) {
                return Err(ctx.err(
                    at,
                    format!("`{k}` has a base value (in `channel`) and a sweep; give one of them"),
                ));
            }
        } else if k.contains('.') {
            return Err(ctx.err(
                at,
                format!("`{k}`: only the keys of the entry's own link may be swept by a dotted name (`channel.<key>`)"),
            ));
        } else if base.contains_key(&k) {
            return Err(ctx.err(
                at,
                format!("`{k}` has a base value and a sweep; give one of them"),
            ));
        }
        let toml::Value::Array(values) = vals else {
            return Err(ctx.err(at, "expected a non-empty list of values"));
        };
        if values.is_empty() {
            return Err(ctx.err(at, "expected a non-empty list of values"));
        }
        for (i, v) in values.iter().enumerate() {
            if let Some(j) = values[..i].iter().position(|w| same(v, w)) {
                return Err(ctx.err(
                    at,
                    format!("value {v} is listed twice (entries {j} and {i})"),
                ));
            }
        }
        out.push((k, values));
    }
    Ok(out)
}

/// Equal as parameter values (an integer and a float of the same value are the same).
fn same(a: &toml::Value, b: &toml::Value) -> bool {
    let num = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(x) => Some(*x),
        _ => None,
    };
    match (num(a), num(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Cartesian product of the sweep lists, in file order (a single empty point when unswept).
pub fn points(sweep: &[(String, Vec<toml::Value>)]) -> Vec<Point> {
    let mut points: Vec<Point> = vec![Vec::new()];
    for (k, vals) in sweep {
        let mut next = Vec::with_capacity(points.len() * vals.len());
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

/// Number of points without building them (saturating), to refuse absurd grids early.
pub fn count(sweep: &[(String, Vec<toml::Value>)]) -> usize {
    sweep
        .iter()
        .fold(1usize, |n, (_, v)| n.saturating_mul(v.len()))
}
