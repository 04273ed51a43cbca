//! Variants whose trial failed, and numbers that are not finite: what makes a run's results
//! untrustworthy, said per scheme.
use super::results::{params_text, Summary};

/// One line per variant whose trial failed: `scheme (params): trial t, step k: message` (the
/// first failure, by trial). A run with one fails (exit 1) after writing its results.
pub fn failed(summary: &Summary) -> Vec<String> {
    summary
        .schemes
        .iter()
        .filter_map(|s| {
            let f = s.failed.as_ref()?;
            let who = if s.params.is_empty() {
                s.name.clone()
            } else {
                format!("{} ({})", s.name, params_text(&s.params))
            };
            Some(format!(
                "{who}: trial {}, step {}: {}",
                f.trial, f.step, f.message
            ))
        })
        .collect()
}

/// A failed variant's row of the terminal table: its name and parameters, then `FAILED` and
/// dashes (its numbers are not reported; the failure is said under the table).
pub(super) fn blank_row(row: &mut [String]) {
    for (j, cell) in row.iter_mut().enumerate().skip(2) {
        *cell = if j == 2 { "FAILED" } else { "-" }.to_string();
    }
}

/// `summary.json`'s value of a summary: a failed variant's numbers are null (what it recorded
/// before it failed is not a result); its name, kind, curve, parameters and failure stay.
pub fn summary_json<T: serde::Serialize>(summary: &T) -> serde_json::Result<serde_json::Value> {
    let mut v = serde_json::to_value(summary)?;
    if let Some(schemes) = v.get_mut("schemes").and_then(|s| s.as_array_mut()) {
        for s in schemes.iter_mut().filter(|s| !s["failed"].is_null()) {
            if let Some(m) = s.as_object_mut() {
                for (k, x) in m.iter_mut() {
                    if !matches!(k.as_str(), "name" | "kind" | "curve" | "params" | "failed") {
                        null_numbers(x);
                    }
                }
            }
        }
    }
    Ok(v)
}

fn null_numbers(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Number(_) => *v = serde_json::Value::Null,
        serde_json::Value::Object(m) => m.values_mut().for_each(null_numbers),
        serde_json::Value::Array(a) => a.iter_mut().for_each(null_numbers),
        _ => {}
    }
}

/// Where a summary holds a number that is not finite (an overflow or a collapsed filter):
/// `scheme (params): metric` for each. A run that produces one must not look like a success.
pub fn non_finite(summary: &Summary) -> Vec<String> {
    let mut out = Vec::new();
    // A failed variant's numbers are null by design; [`failed`] reports it.
    for s in summary.schemes.iter().filter(|s| s.failed.is_none()) {
        let value = serde_json::to_value(s).unwrap_or(serde_json::Value::Null);
        let mut bad = Vec::new();
        find_nulls(&value, "", &mut bad);
        // With one trial no standard error exists: its NaN says so, and is no overflow.
        if summary.trials < 2 {
            bad.retain(|path| !path.split('.').any(|seg| seg.contains("_se")));
        }
        bad.dedup();
        if !bad.is_empty() {
            out.push(format!(
                "{} ({}): {}",
                s.name,
                params_text(&s.params),
                bad.join(", ")
            ));
        }
    }
    out
}

/// JSON has no NaN or infinity: serde writes them as `null`, and nothing else in a scheme's
/// summary is optional.
fn find_nulls(v: &serde_json::Value, path: &str, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Null => out.push(path.to_string()),
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                find_nulls(x, &p, out);
            }
        }
        // A per-step or per-trial list is named once, not once per entry.
        serde_json::Value::Array(a) => {
            for x in a {
                find_nulls(x, path, out);
            }
        }
        _ => {}
    }
}
