//! A failed variant in the outputs: its row of the terminal table and its `summary.json` value
//! (the numbers it recorded before it failed are not results). Which variants failed, and which
//! numbers are not finite, [`crate::metrics::results::failed`] and
//! [`crate::metrics::finite::non_finite`] say.

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
