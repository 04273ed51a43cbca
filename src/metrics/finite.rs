//! Whether a run's numbers can be trusted: JSON has no NaN or infinity, so a non-finite number
//! in a summary shows as a `null` where a number belongs.
use super::results::{params_text, Summary};

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
        // No floor (none for the scenario, or a rate too low for a finite one) is a null by
        // design: `rate_distortion_floor_note` says why.
        bad.retain(|path| path != "floor_mse");
        // A link that carried no packet has no loss fraction: null by design ("no packets").
        bad.retain(|path| path != "link.loss_fraction");
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
