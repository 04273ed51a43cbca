//! The error of a scenario that cannot be read or is inconsistent, and where it points.
use std::fmt;

/// A scenario that could not be read or is inconsistent.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// File (or built-in name) the scenario came from.
    pub file: String,
    /// Field path, e.g. `sensors[2].R`.
    pub field: String,
    /// What was expected and what was found.
    pub message: String,
    /// Set when the scenario is valid but the run would pass a limit of the machine (memory
    /// or run time): callers tell "too large" from "wrong" by this, never by the message.
    pub limit: Option<Limit>,
}

/// Which limit a valid scenario would pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    Memory,
    Time,
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

/// Where errors point: the file.
pub(crate) struct Ctx<'a> {
    pub file: &'a str,
}

impl Ctx<'_> {
    pub fn err(&self, field: impl Into<String>, message: impl Into<String>) -> ScenarioError {
        ScenarioError {
            file: self.file.to_string(),
            field: field.into(),
            message: message.into(),
            limit: None,
        }
    }
}
