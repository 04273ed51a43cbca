//! The one list of schemes. Each entry names a `kind` as written in scenario files, its default
//! curve label, its documented parameters, its bandwidth knob, and the function that parses a
//! scheme table and builds the runnable scheme (in the manner of ripgrep's flag list: adding a
//! scheme is one module and one line here).
//!
//! A scheme module owns its parameter type (serde, typed enums, `deny_unknown_fields`), its
//! defaults and its validation; the scenario layer only attaches the file and the field path
//! to a [`ParamError`].
use super::{Scheme, SchemeError, System};
use serde::de::DeserializeOwned;
use std::sync::Arc;

/// What a scheme's builder gets besides its parameters.
#[derive(Debug, Clone, Copy)]
pub struct BuildContext<'a> {
    pub system: &'a Arc<System>,
    /// Time steps of the run (schemes precompute data-independent recursions this far).
    pub steps: usize,
}

/// A parameter that is missing, malformed or inconsistent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct ParamError {
    /// The parameter, relative to the scheme table (e.g. `rate`, `B`); `None` when the error
    /// concerns the scheme as a whole.
    pub field: Option<String>,
    pub message: String,
}

impl ParamError {
    /// An error about one parameter.
    pub fn at(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: Some(field.into()),
            message: message.into(),
        }
    }
    /// An error about the scheme as a whole.
    pub fn whole(message: impl Into<String>) -> Self {
        Self {
            field: None,
            message: message.into(),
        }
    }
}

impl From<SchemeError> for ParamError {
    fn from(e: SchemeError) -> Self {
        match e {
            SchemeError::Invalid { field, message } => ParamError::at(field, message),
            other => ParamError::whole(other.to_string()),
        }
    }
}

/// One documented parameter of a scheme kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamDoc {
    pub name: &'static str,
    /// What values it takes, e.g. `number in (0, 1]` or `"nis" | "kl" | "random" | "all"`.
    pub values: &'static str,
    /// The default, or `required`.
    pub default: &'static str,
    pub meaning: &'static str,
}

/// A scheme's parameters as read from a file: they validate themselves and build the scheme.
pub trait SchemeParams: DeserializeOwned {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError>;
}

/// One registered scheme kind.
#[derive(Clone, Copy)]
pub struct SchemeEntry {
    /// The `kind` string of scenario files.
    pub kind: &'static str,
    /// Default curve label.
    pub label: &'static str,
    /// One line: what the scheme is and where it comes from.
    pub summary: &'static str,
    pub params: &'static [ParamDoc],
    /// The parameter that sets how much the scheme talks (a rate, a threshold, a number of
    /// levels), for calibrating schemes to one bit budget; `None` if it has none.
    pub knob: Option<&'static str>,
    /// Parses a scheme table (its parameters only: no `kind`, `label`, `sweep`, `frontier`)
    /// and builds the scheme.
    pub build: fn(toml::Table, &BuildContext) -> Result<Box<dyn Scheme>, ParamError>,
}

impl std::fmt::Debug for SchemeEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SchemeEntry")
            .field("kind", &self.kind)
            .finish_non_exhaustive()
    }
}

/// Deserializes `P` from a scheme table, naming the offending key on error, and builds it.
pub fn parse_and_build<P: SchemeParams>(
    table: toml::Table,
    cx: &BuildContext,
) -> Result<Box<dyn Scheme>, ParamError> {
    parse::<P>(table)?.build(cx)
}

/// Deserializes `P` from a scheme table, naming the offending key on error.
pub fn parse<P: DeserializeOwned>(table: toml::Table) -> Result<P, ParamError> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let message = inner.message().to_string();
        // serde names unknown and missing keys in the message, not in the path.
        let field = backticked(&message, "unknown field `")
            .or_else(|| backticked(&message, "missing field `"))
            .or_else(|| (path != ".").then_some(path));
        ParamError { field, message }
    })
}

fn backticked(message: &str, prefix: &str) -> Option<String> {
    let rest = &message[message.find(prefix)? + prefix.len()..];
    Some(rest[..rest.find('`')?].to_string())
}

/// Every scheme kind, in the order `hushfuse list-schemes` prints them.
pub const SCHEMES: &[SchemeEntry] = &[
    super::centralized::params::ALL,
    super::centralized::params::RANDOM,
    super::distributed_kf::params::FULL_RATE,
    super::distributed_kf::params::ALG1_RANDOM,
    super::distributed_kf::params::ALG1_EVENT,
    super::distributed_kf::params::ALG2_EVENT,
    super::quantized_innovation::params::ENTRY,
    super::censored_pf::params::ENTRY,
    super::event_triggered::params::INNOVATION,
    super::event_triggered::params::STOCHASTIC_OPEN,
    super::event_triggered::params::STOCHASTIC_CLOSED,
    super::event_triggered::params::SEND_ON_DELTA,
    super::estimate_fusion::params::CI,
    super::estimate_fusion::params::NAIVE,
];

/// The entry of a kind.
pub fn find(kind: &str) -> Option<&'static SchemeEntry> {
    SCHEMES.iter().find(|e| e.kind == kind)
}

/// The known kinds, for error messages.
pub fn kinds() -> Vec<&'static str> {
    SCHEMES.iter().map(|e| e.kind).collect()
}

/// The registry as text: every kind with its parameters and defaults (`hushfuse list-schemes`).
pub fn describe() -> String {
    let mut out = String::new();
    for e in SCHEMES {
        out.push_str(&format!("{}  ({})\n  {}\n", e.kind, e.label, e.summary));
        if let Some(k) = e.knob {
            out.push_str(&format!("  bandwidth knob: {k}\n"));
        }
        for p in e.params {
            out.push_str(&format!(
                "  {:<16} {:<34} default {:<12} {}\n",
                p.name, p.values, p.default, p.meaning
            ));
        }
        out.push('\n');
    }
    out
}

/// A matrix parameter written as a list of rows: non-empty, rectangular, finite.
pub fn matrix_param(field: &str, rows: &[Vec<f64>]) -> Result<crate::linalg::Matrix, ParamError> {
    if rows.is_empty() || rows[0].is_empty() {
        return Err(ParamError::at(
            field,
            "expected a non-empty matrix (a list of rows)",
        ));
    }
    let cols = rows[0].len();
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
        return Err(ParamError::at(
            field,
            format!("row {i} has {} entries, row 0 has {cols}", r.len()),
        ));
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(ParamError::at(field, "expected finite numbers"));
    }
    Ok(crate::linalg::matrix_from_rows(rows))
}
