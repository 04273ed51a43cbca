//! Scheme construction: each `[[schemes]]` entry is one curve; each point of its sweep one
//! variant, parsed and built by the scheme's registry entry. This file knows no scheme by name.
//! Besides the scheme's parameters an entry may carry `label`, `note` (what differs on its
//! row, shown under the tables), `sweep`, `frontier`, `channel` and `sequence_bits`.
use crate::network::channel::ChannelSpec;
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scenario::experiment::{Curve, Variant};
use crate::scenario::scheme_link::PointLink;
use crate::scenario::sweep;
use crate::scenario::{FrontierSpec, ParamValue, Params};
use crate::scheme::registry::{self, BuildContext};
use crate::scheme::System;
use std::sync::Arc;

/// Most variants a scenario may define (every variant runs every trial).
pub const MAX_VARIANTS: usize = 10_000;

/// Builds every curve and variant of the `[[schemes]]` entries; a variant without a `channel`
/// of its own takes `channel`, the scenario's link.
pub(crate) fn build_schemes(
    ctx: &Ctx,
    tables: &[toml::Table],
    system: &Arc<System>,
    steps: usize,
    (channel, path_loss): (&Option<Arc<Vec<ChannelSpec>>>, Option<&[f64]>),
) -> Result<(Vec<Curve>, Vec<Variant>), ScenarioError> {
    if tables.is_empty() {
        return Err(ctx.err("schemes", "expected at least one [[schemes]] entry"));
    }
    let mut curves = Vec::new();
    let mut variants = Vec::new();
    for (ci, table) in tables.iter().enumerate() {
        let field = format!("schemes[{ci}]");
        let mut base = table.clone();
        let label = match base.remove("label") {
            Some(toml::Value::String(s)) => Some(s),
            Some(_) => return Err(ctx.err(format!("{field}.label"), "expected a string")),
            None => None,
        };
        let row_note = match base.remove("note") {
            Some(toml::Value::String(s)) if !s.trim().is_empty() => Some(s.trim().to_string()),
            Some(_) => {
                return Err(ctx.err(
                    format!("{field}.note"),
                    "expected a non-empty string: what differs on this row from the others",
                ))
            }
            None => None,
        };
        let entry = match base.remove("kind") {
            Some(toml::Value::String(k)) => registry::find(&k).ok_or_else(|| {
                ctx.err(
                    format!("{field}.kind"),
                    format!(
                        "unknown scheme kind {k:?}; expected one of {} (`hushfuse list-schemes`)",
                        registry::kinds().join(", ")
                    ),
                )
            })?,
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
        let frontier = frontier(ctx, &field, base.remove("frontier"))?;
        let swept = sweep::parse(ctx, &field, base.remove("sweep"), &base)?;
        if variants.len().saturating_add(sweep::count(&swept)) > MAX_VARIANTS {
            return Err(ctx.err(
                format!("{field}.sweep"),
                format!("at most {MAX_VARIANTS} variants in a scenario"),
            ));
        }
        for point in sweep::points(&swept) {
            let mut t = base.clone();
            let mut desc = Vec::new();
            for (k, v) in &point {
                if !k.starts_with(sweep::CHANNEL_PREFIX) {
                    t.insert(k.clone(), v.clone());
                }
                desc.push(format!("{k} = {v}"));
            }
            let link = PointLink::take(&mut t, &point);
            let note = if desc.is_empty() {
                String::new()
            } else {
                format!(" (sweep point {})", desc.join(", "))
            };
            let at = format!("{field}{note}");
            let mut params = params_of(&t);
            link.params(&mut params);
            let variant_channel =
                link.channel(ctx, (&field, &note), system.n_sensors(), channel)?;
            let sequence_bits = link.sequence_bits(ctx, (&field, &note))?;
            // Over a multi-hop network, the loss of each sensor's whole route.
            let link_loss: Option<Vec<f64>> = match path_loss {
                Some(p) => Some(p.to_vec()),
                None => variant_channel
                    .as_deref()
                    .map(|specs| specs.iter().map(ChannelSpec::delivery_loss).collect()),
            };
            let cx = BuildContext {
                system,
                steps,
                link_loss: link_loss.as_deref(),
            };
            let scheme = registry::build_entry(entry, t, &cx).map_err(|e| match &e.field {
                Some(f) => ctx.err(format!("{at}.{f}"), e.message.clone()),
                None => ctx.err(&at, e.message.clone()),
            })?;
            variants.push(Variant {
                curve: ci,
                params,
                kind: entry.kind,
                scheme,
                channel: variant_channel,
                sequence_bits,
            });
        }
        curves.push(Curve {
            label: label.unwrap_or_else(|| entry.label.to_string()),
            kind: entry.kind.to_string(),
            swept: swept.iter().map(|(k, _)| k.clone()).collect(),
            frontier,
            note: row_note,
        });
    }
    let mut seen = std::collections::BTreeSet::new();
    for (ci, c) in curves.iter().enumerate() {
        if !seen.insert(c.label.clone()) {
            return Err(ctx.err(
                format!("schemes[{ci}].label"),
                format!(
                    "two schemes share the label {:?}; give each a distinct `label`",
                    c.label
                ),
            ));
        }
    }
    Ok((curves, variants))
}

/// The parameters of a variant as written (numbers, flags and names; lists are left out of
/// the summary's `params`).
fn params_of(t: &toml::Table) -> Params {
    t.iter()
        .filter_map(|(k, v)| match v {
            toml::Value::Float(x) => Some((k.clone(), ParamValue::Number(*x))),
            toml::Value::Integer(x) => Some((k.clone(), ParamValue::Number(*x as f64))),
            toml::Value::Boolean(b) => Some((k.clone(), ParamValue::Flag(*b))),
            toml::Value::String(s) => Some((k.clone(), ParamValue::Text(s.clone()))),
            _ => None,
        })
        .collect()
}

fn frontier(
    ctx: &Ctx,
    field: &str,
    value: Option<toml::Value>,
) -> Result<Option<FrontierSpec>, ScenarioError> {
    let Some(v) = value else {
        return Ok(None);
    };
    let f: FrontierSpec = registry::parse(v.try_into().map_err(|_| {
        ctx.err(
            format!("{field}.frontier"),
            "expected a table { metric = \"trace\" or \"mse\", bin_width = w }",
        )
    })?)
    .map_err(|e| {
        ctx.err(
            format!(
                "{field}.frontier{}",
                e.field.map(|f| format!(".{f}")).unwrap_or_default()
            ),
            e.message,
        )
    })?;
    if !(f.bin_width.is_finite() && f.bin_width > 0.0) {
        return Err(ctx.err(
            format!("{field}.frontier.bin_width"),
            "expected a positive number",
        ));
    }
    Ok(Some(f))
}
