//! The one list of schemes. Each entry names a `kind` as written in scenario files, its default
//! curve label, its documented parameters, its bandwidth knob, and the function that parses a
//! scheme table and builds the runnable scheme (in the manner of ripgrep's flag list). The list
//! itself, [`SCHEMES`], sits in `scheme/mod.rs` beside the module declarations, so adding a
//! scheme touches one new module and that one file (plus the regenerated docs).
//!
//! A scheme module owns its parameter type (serde, typed enums, `deny_unknown_fields`), its
//! defaults and its validation; the scenario layer only attaches the file and the field path
//! to a [`ParamError`].
use super::{Scheme, SchemeError, System};
use crate::model::MeasurementModel;
use serde::de::DeserializeOwned;
use std::sync::Arc;

/// What a scheme's builder gets besides its parameters.
#[derive(Debug, Clone, Copy)]
pub struct BuildContext<'a> {
    pub system: &'a Arc<System>,
    /// Time steps of the run (schemes precompute data-independent recursions this far).
    pub steps: usize,
    /// Each sensor's long-run probability that its link never delivers a packet
    /// ([`crate::network::channel::ChannelSpec::delivery_loss`]), for `link_loss = "channel"`;
    /// `None` on ideal links.
    pub link_loss: Option<&'a [f64]>,
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

/// `resampling` of every particle-filter scheme.
pub const RESAMPLING: ParamDoc = ParamDoc {
    name: "resampling",
    values: "systematic|stratified|residual|multinomial",
    default: "systematic",
    meaning: "resampling scheme",
};

/// `ess_threshold` of every particle-filter scheme.
pub const ESS_THRESHOLD: ParamDoc = ParamDoc {
    name: "ess_threshold",
    values: "number in [0, 1]",
    default: "none",
    meaning: "resample only when ESS < threshold x particles (default: every step)",
};

/// A scheme's parameters as read from a file: they validate themselves and build the scheme.
pub trait SchemeParams: DeserializeOwned {
    fn build(&self, cx: &BuildContext) -> Result<Box<dyn Scheme>, ParamError>;
}

/// One end of a knob's range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// This value.
    Fixed(f64),
    /// This many times the number of sensors N (e.g. censored-pf's `l` in [0.001 N, N]).
    PerSensor(f64),
    /// No end (a threshold's upper end): the calibrator finds one by quadrupling from 1.
    Open,
}

impl Bound {
    /// The end on a system of `n_sensors` sensors; `None` for [`Bound::Open`].
    pub fn at(self, n_sensors: usize) -> Option<f64> {
        match self {
            Bound::Fixed(v) => Some(v),
            Bound::PerSensor(c) => Some(c * n_sensors as f64),
            Bound::Open => None,
        }
    }
    fn text(self) -> String {
        match self {
            Bound::Fixed(v) => format!("{v}"),
            Bound::PerSensor(1.0) => "N".to_string(),
            Bound::PerSensor(c) => format!("{c} N"),
            Bound::Open => "open".to_string(),
        }
    }
}

/// How the calibrator steps between the ends of a knob's range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Bisection at the arithmetic midpoint (integer knobs: every integer of the range).
    Linear,
    /// Bisection at the geometric midpoint, for knobs whose effect spans decades (no built-in
    /// knob uses it yet).
    Log,
}

/// Which way the bits per step move when a knob grows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// A send probability, an expected number of senders, quantizer bits.
    MoreBits,
    /// A trigger threshold.
    FewerBits,
}

/// A scheme's bandwidth knob: the parameter that sets how much it talks, and where the
/// calibrator may move it (`engine::calibrate`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knob {
    /// The parameter's name in scenario files.
    pub name: &'static str,
    /// Lower end of the range (never [`Bound::Open`]).
    pub lo: Bound,
    /// Upper end; [`Bound::Open`] for a threshold.
    pub hi: Bound,
    pub scale: Scale,
    /// Integer values only (written as TOML integers).
    pub integer: bool,
    /// Which way the bits move as the knob grows. The calibrator measures the direction off
    /// the two ends of the range on each system; this is what the scheme promises.
    pub grows: Direction,
}

impl Knob {
    /// A trigger threshold: [0, open), linear, fewer bits as it grows.
    pub const fn threshold(name: &'static str) -> Self {
        Self {
            name,
            lo: Bound::Fixed(0.0),
            hi: Bound::Open,
            scale: Scale::Linear,
            integer: false,
            grows: Direction::FewerBits,
        }
    }
    /// A continuous knob on [lo, hi] whose bits grow with it, linear.
    pub const fn rising(name: &'static str, lo: Bound, hi: Bound) -> Self {
        Self {
            name,
            lo,
            hi,
            scale: Scale::Linear,
            integer: false,
            grows: Direction::MoreBits,
        }
    }
    /// The range as text, e.g. `[0.001 N, N]`, `[0, open)` or `integers 1..=8`.
    pub fn range_text(&self) -> String {
        if self.integer {
            return format!("integers {}..={}", self.lo.text(), self.hi.text());
        }
        let close = if self.hi == Bound::Open { ")" } else { "]" };
        format!("[{}, {}{close}", self.lo.text(), self.hi.text())
    }
}

/// Which systems a scheme applies to: what its builder refuses otherwise (with its default
/// options; some options ask for more, e.g. censored-pf's `fusion = "exact"` needs linear
/// sensors).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Applies {
    /// Every system.
    Any,
    /// Linear sensors (z = H x + v) of any dimension.
    LinearSensors,
    /// Scalar measurements, linear or not.
    ScalarMeasurements,
    /// Scalar linear sensors (z = h x + v, h 1 x n).
    ScalarLinearSensors,
}

impl Applies {
    /// Whether `system` is one the scheme applies to.
    pub fn holds(self, system: &System) -> bool {
        let all = |f: &dyn Fn(&dyn MeasurementModel) -> bool| {
            system.sensors.iter().all(|s| f(s.as_ref()))
        };
        match self {
            Applies::Any => true,
            Applies::LinearSensors => all(&|s| s.as_linear().is_some()),
            Applies::ScalarMeasurements => all(&|s| s.meas_dim() == 1),
            Applies::ScalarLinearSensors => {
                all(&|s| s.as_linear().is_some_and(|l| l.meas_dim() == 1))
            }
        }
    }
    pub fn text(self) -> &'static str {
        match self {
            Applies::Any => "any system",
            Applies::LinearSensors => "linear sensors",
            Applies::ScalarMeasurements => "scalar measurements",
            Applies::ScalarLinearSensors => "scalar linear sensors",
        }
    }
}

/// Parses a scheme table and builds the scheme.
pub type BuildFn = fn(toml::Table, &BuildContext) -> Result<Box<dyn Scheme>, ParamError>;

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
    pub knob: Option<Knob>,
    /// Which systems the scheme builds on (with its default options).
    pub applies: Applies,
    /// Parses a scheme table (its parameters only: no `kind`, `label`, `sweep`, `frontier`)
    /// and builds the scheme.
    pub build: BuildFn,
    /// A minimal parameter table in TOML (required parameters only) that builds on the
    /// reference system: a 1-D constant-velocity target with two scalar linear sensors of the
    /// position. Shown by `list-schemes`; a test builds every kind from it.
    pub example: &'static str,
    /// How the fusion center treats a packet that did not arrive (the link lost it), which it
    /// cannot tell from a silence: shown by `list-schemes`.
    pub missing_packet: &'static str,
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

pub use super::{DECENTRALIZED, SCHEMES};

/// The built-in kinds: the center schemes, then the decentralized ones.
pub fn built_in() -> impl Iterator<Item = &'static SchemeEntry> {
    SCHEMES.iter().chain(DECENTRALIZED)
}

/// Builds a scheme of a kind registered at run time from its table (a closure: a function
/// pointer cannot hold, e.g., the Python objects of a user's scheme).
pub type RuntimeBuilder = std::sync::Arc<
    dyn Fn(toml::Table, &BuildContext) -> Result<Box<dyn Scheme>, ParamError> + Send + Sync,
>;

/// The kinds registered at run time ([`super::external`] declares and checks them), beside the
/// built-in [`SCHEMES`]: the registry is the one place every kind is looked up.
static RUNTIME: std::sync::RwLock<Vec<(&'static SchemeEntry, RuntimeBuilder)>> =
    std::sync::RwLock::new(Vec::new());

fn runtime() -> std::sync::RwLockReadGuard<'static, Vec<(&'static SchemeEntry, RuntimeBuilder)>> {
    RUNTIME.read().unwrap_or_else(|e| e.into_inner())
}

/// Adds (or replaces) a kind registered at run time.
pub fn register_runtime(entry: &'static SchemeEntry, builder: RuntimeBuilder) {
    let mut list = RUNTIME.write().unwrap_or_else(|e| e.into_inner());
    list.retain(|(e, _)| e.kind != entry.kind);
    list.push((entry, builder));
}

/// Removes a kind registered at run time; whether it was there.
pub fn unregister_runtime(kind: &str) -> bool {
    let mut list = RUNTIME.write().unwrap_or_else(|e| e.into_inner());
    let before = list.len();
    list.retain(|(e, _)| e.kind != kind);
    list.len() != before
}

/// The entry of a kind registered at run time.
pub fn find_runtime(kind: &str) -> Option<&'static SchemeEntry> {
    runtime()
        .iter()
        .find(|(e, _)| e.kind == kind)
        .map(|(e, _)| *e)
}

/// The kinds registered at run time, in registration order.
pub fn runtime_kinds() -> Vec<&'static str> {
    runtime().iter().map(|(e, _)| e.kind).collect()
}

/// The entry of a kind.
pub fn find(kind: &str) -> Option<&'static SchemeEntry> {
    built_in()
        .find(|e| e.kind == kind)
        .or_else(|| find_runtime(kind))
}

/// Builds a scheme of `entry`'s kind from its table: the entry's own builder, or the builder
/// of a kind registered at run time.
pub fn build_entry(
    entry: &SchemeEntry,
    table: toml::Table,
    cx: &BuildContext,
) -> Result<Box<dyn Scheme>, ParamError> {
    if !built_in().any(|e| e.kind == entry.kind) {
        let builder = runtime()
            .iter()
            .find(|(e, _)| e.kind == entry.kind)
            .map(|(_, b)| b.clone());
        if let Some(b) = builder {
            return b(table, cx);
        }
    }
    (entry.build)(table, cx)
}

/// The known kinds, for error messages: the built-in ones, then those registered at run time.
pub fn kinds() -> Vec<&'static str> {
    let mut k: Vec<&'static str> = built_in().map(|e| e.kind).collect();
    k.extend(runtime_kinds());
    k
}

/// The registry as text: every kind with its parameters and defaults (`hushfuse list-schemes`).
pub fn describe() -> String {
    let mut out = String::new();
    for e in built_in() {
        if DECENTRALIZED.first().is_some_and(|d| d.kind == e.kind) {
            out.push_str("Decentralized (no center: every node of the [network] estimates)\n\n");
        }
        out.push_str(&format!("{}  ({})\n  {}\n", e.kind, e.label, e.summary));
        let example = e.example.trim().replace('\n', ", ");
        out.push_str(&format!(
            "  example: kind = \"{}\"{}{}\n",
            e.kind,
            if example.is_empty() { "" } else { ", " },
            example
        ));
        if let Some(k) = e.knob {
            out.push_str(&format!(
                "  bandwidth knob: {} in {} ({} as it grows)\n",
                k.name,
                k.range_text(),
                match k.grows {
                    Direction::MoreBits => "more bits",
                    Direction::FewerBits => "fewer bits",
                }
            ));
        }
        out.push_str(&format!("  applies to: {}\n", e.applies.text()));
        out.push_str(&format!("  a lost packet: {}\n", e.missing_packet));
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

/// Marks the start of the generated scheme reference in docs/scenarios.md.
pub const DOCS_BEGIN: &str =
    "<!-- registry:begin (generated by `hushfuse list-schemes --markdown`) -->";
/// Marks its end.
pub const DOCS_END: &str = "<!-- registry:end -->";

/// The scheme reference of docs/scenarios.md: a table of every kind, then each kind's
/// parameters with their values, defaults and meaning.
pub fn markdown() -> String {
    let esc = |t: &str| t.replace('|', "\\|");
    let mut out = String::from("| kind | parameters | scheme |\n|---|---|---|\n");
    for e in built_in() {
        let params = if e.params.is_empty() {
            "—".to_string()
        } else {
            e.params
                .iter()
                .map(|p| format!("`{}`", p.name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        out.push_str(&format!(
            "| `{}` | {params} | {} |\n",
            e.kind,
            esc(e.summary)
        ));
    }
    for e in built_in() {
        if DECENTRALIZED.first().is_some_and(|d| d.kind == e.kind) {
            out.push_str("\n### Decentralized schemes\n\nEvery node of the `[network]` runs the filter and talks only with its neighbours (no center); the row of a decentralized scheme is the mean over its nodes, each node's numbers beside it (`estimators` in `summary.json`). They run on the network's graph, including its relays and sink (nodes without a sensor); `sink = false` makes a network of peers. Not part of `every_scheme`.\n");
        }
        out.push_str(&format!(
            "\n### `{}` — {}\n\n{}\n",
            e.kind, e.label, e.summary
        ));
        if let Some(k) = e.knob {
            out.push_str(&format!("\nBandwidth knob: `{}`.\n", k.name));
        }
        out.push_str(&format!("\nA lost packet: {}.\n", e.missing_packet));
        let example = e.example.trim().replace('\n', ", ");
        out.push_str(&format!(
            "\nMinimal entry: `kind = \"{}\"{}{}`\n",
            e.kind,
            if example.is_empty() { "" } else { ", " },
            example
        ));
        if !e.params.is_empty() {
            out.push_str("\n| parameter | values | default | meaning |\n|---|---|---|---|\n");
            for p in e.params {
                out.push_str(&format!(
                    "| `{}` | {} | {} | {} |\n",
                    p.name,
                    esc(p.values),
                    esc(p.default),
                    esc(p.meaning)
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::Gaussian;
    use crate::linalg::{Matrix, Vector};
    use crate::model::{presets, LinearSensor, MeasurementModel};

    /// The reference system of [`SchemeEntry::example`].
    fn reference() -> Arc<System> {
        let sensor = |r: f64| {
            Arc::new(
                LinearSensor::new(
                    Matrix::from_row_slice(1, 2, &[1.0, 0.0]),
                    Matrix::from_element(1, 1, r),
                )
                .unwrap(),
            ) as Arc<dyn MeasurementModel>
        };
        Arc::new(System {
            transition: presets::constant_velocity_1d(1.0, 0.1).unwrap(),
            sensors: vec![sensor(1.0), sensor(2.0)],
            prior: Gaussian::new(Vector::from_vec(vec![0.0, 1.0]), Matrix::identity(2, 2)),
        })
    }

    fn example(e: &SchemeEntry) -> toml::Table {
        toml::from_str(e.example)
            .unwrap_or_else(|err| panic!("{}: example is not TOML: {err}", e.kind))
    }

    #[test]
    fn kinds_are_unique_and_labelled() {
        let mut seen = std::collections::BTreeSet::new();
        for e in built_in() {
            assert!(seen.insert(e.kind), "{} is registered twice", e.kind);
            assert!(!e.label.is_empty() && !e.summary.is_empty(), "{}", e.kind);
            if let Some(k) = e.knob {
                assert!(
                    e.params.iter().any(|p| p.name == k.name),
                    "{}: knob {} is not a documented parameter",
                    e.kind,
                    k.name
                );
                assert!(k.lo != Bound::Open, "{}: the lower end is open", e.kind);
            }
        }
    }

    /// Every kind builds, and an instance can be made, from its documented example on the
    /// reference system; the example uses only documented parameters.
    #[test]
    fn every_kind_builds_from_its_example() {
        let system = reference();
        let cx = BuildContext {
            system: &system,
            steps: 10,
            link_loss: None,
        };
        for e in built_in() {
            let table = example(e);
            for key in table.keys() {
                assert!(
                    e.params.iter().any(|p| p.name == key),
                    "{}: example key {key} is not documented",
                    e.kind
                );
            }
            let scheme = (e.build)(table, &cx)
                .unwrap_or_else(|err| panic!("{}: example does not build: {err}", e.kind));
            if scheme.peers().is_some() {
                // A decentralized scheme has no center to build: its nodes run on a graph.
                assert!(DECENTRALIZED.iter().any(|d| d.kind == e.kind), "{}", e.kind);
                assert!(scheme.build_with_seed(1).is_err(), "{}", e.kind);
                continue;
            }
            let inst = scheme.build_with_seed(1).unwrap();
            assert_eq!(inst.sensors.len(), 2, "{}", e.kind);
        }
    }

    /// An unknown key is refused, naming the key; and the set of keys serde knows is exactly
    /// the documented set (serde lists the expected fields in the message).
    #[test]
    fn unknown_keys_are_refused_and_docs_list_every_field() {
        let system = reference();
        let cx = BuildContext {
            system: &system,
            steps: 10,
            link_loss: None,
        };
        for e in built_in() {
            let mut table = example(e);
            table.insert("zz_not_a_parameter".into(), toml::Value::Integer(1));
            let err = match (e.build)(table, &cx) {
                Ok(_) => panic!("{}: an unknown key was accepted", e.kind),
                Err(err) => err,
            };
            assert_eq!(
                err.field.as_deref(),
                Some("zz_not_a_parameter"),
                "{}: {err}",
                e.kind
            );
            let mut expected: Vec<&str> = err.message.split('`').skip(3).step_by(2).collect();
            expected.sort_unstable();
            let mut documented: Vec<&str> = e.params.iter().map(|p| p.name).collect();
            documented.sort_unstable();
            assert_eq!(expected, documented, "{}: {}", e.kind, err.message);
        }
    }

    /// A wrong type names the key.
    #[test]
    fn wrong_types_name_the_key() {
        let system = reference();
        let cx = BuildContext {
            system: &system,
            steps: 10,
            link_loss: None,
        };
        for e in built_in() {
            for p in e.params {
                let mut table = example(e);
                table.insert(
                    p.name.into(),
                    toml::Value::Array(vec![toml::Value::Boolean(true)]),
                );
                match (e.build)(table, &cx) {
                    Ok(_) => panic!("{}: `{} = [true]` was accepted", e.kind, p.name),
                    Err(err) => {
                        let field = err.field.clone().unwrap_or_default();
                        let root = field.split(['[', '.']).next().unwrap_or_default();
                        assert_eq!(root, p.name, "{}: {err}", e.kind);
                    }
                }
            }
        }
    }

    /// docs/scenarios.md carries the registry's own text between its markers, so the docs
    /// cannot drift from the code (`hushfuse list-schemes --markdown` prints it).
    #[test]
    fn docs_carry_the_registry_text() {
        let docs = include_str!("../../docs/scenarios.md");
        let inside = docs
            .split(DOCS_BEGIN)
            .nth(1)
            .and_then(|rest| rest.split(DOCS_END).next())
            .expect("docs/scenarios.md has the registry markers");
        assert_eq!(
            inside.trim(),
            markdown().trim(),
            "docs/scenarios.md is stale: paste `hushfuse list-schemes --markdown` between the markers"
        );
    }
}
