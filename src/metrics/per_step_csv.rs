//! `per_step.csv`: the tidy per-step table of a run's summary (one row per scheme variant and
//! step), streamed to a writer so that a large run is never held as one string.
use super::results::{SchemeSummary, Summary};
use std::fmt::Write as _;

/// `per_step.csv`: one row per scheme variant and step, in tidy form. Each scheme parameter
/// has its own column `param_<name>` (the union over all variants, empty where a scheme has
/// no such parameter); every mean over trials is followed by its standard error (`*_se`).
pub fn per_step_csv(summary: &Summary) -> String {
    let mut out = Vec::new();
    write_per_step_csv(summary, &mut out).expect("writing to memory cannot fail");
    String::from_utf8(out).expect("CSV of UTF-8 names and numbers")
}

/// [`per_step_csv`] streamed into `out`: the file of a large run is several megabytes, which
/// need not exist in memory at once beside the summary they are written from.
pub fn write_per_step_csv(summary: &Summary, out: &mut dyn std::io::Write) -> std::io::Result<()> {
    let params = param_names(summary);
    write_csv_header(summary, &params, out)?;
    for s in &summary.schemes {
        write_csv_rows(summary, s, &params, out)?;
    }
    Ok(())
}

/// The union of the variants' parameter names, in order of first appearance.
fn param_names(summary: &Summary) -> Vec<&String> {
    let mut params: Vec<&String> = Vec::new();
    for s in &summary.schemes {
        for k in s.params.keys() {
            if !params.contains(&k) {
                params.push(k);
            }
        }
    }
    params
}

/// The header row of `per_step.csv`.
fn write_csv_header(
    summary: &Summary,
    params: &[&String],
    out: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    out.write_all(b"scheme,kind")?;
    for p in params {
        // Prefixed: a parameter may share a name with a metric column (`rate`, `bits`).
        write!(out, ",{}", csv_field(&format!("param_{p}")))?;
    }
    out.write_all(b",step")?;
    for g in &summary.group_order {
        write!(out, ",rmse_{g},rmse_{g}_se")?;
    }
    out.write_all(b",mse,mse_se,trace,trace_se,anees,anees_se,rate,rate_se,payload_bits,payload_bits_se,frame_bits,frame_bits_se,downlink_bits,downlink_bits_se")?;
    if summary.schemes.iter().any(|s| s.link.is_some()) {
        out.write_all(crate::metrics::link::CSV_HEADER.as_bytes())?;
    }
    if summary.schemes.iter().any(|s| s.network.is_some()) {
        out.write_all(b",hop_frames,hop_forwards")?;
    }
    out.write_all(b"\n")
}

/// The rows of one scheme variant in `per_step.csv`, one per step.
fn write_csv_rows(
    summary: &Summary,
    s: &SchemeSummary,
    params: &[&String],
    out: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    let mut lead = format!("{},{}", csv_field(&s.name), csv_field(&s.kind));
    for p in params {
        // Numbers in full (shortest round-trip form), not the table's six decimals.
        let v = match s.params.get(*p) {
            Some(crate::scenario::ParamValue::Number(x)) => format!("{x}"),
            Some(v) => v.to_string(),
            None => String::new(),
        };
        let _ = write!(lead, ",{}", csv_field(&v));
    }
    let t = &s.traffic_per_step;
    for k in 0..summary.steps {
        write!(out, "{lead},{}", k + 1)?;
        for g in &summary.group_order {
            write!(out, ",{},{}", s.rmse[g][k], s.rmse_se[g][k])?;
        }
        for (v, se) in [
            (s.mse[k], s.mse_se[k]),
            (s.trace[k], s.trace_se[k]),
            (s.anees_per_step[k], s.anees_per_step_se[k]),
            (t.rate[k], t.rate_se[k]),
            (t.payload_bits[k], t.payload_bits_se[k]),
            (t.frame_bits[k], t.frame_bits_se[k]),
            (t.downlink_bits[k], t.downlink_bits_se[k]),
        ] {
            write!(out, ",{v},{se}")?;
        }
        if let Some(l) = &s.link {
            out.write_all(crate::metrics::link::csv_fields(l, k).as_bytes())?;
        }
        if let Some(n) = &s.network {
            let at = |v: &[f64]| v.get(k).copied().unwrap_or(0.0);
            write!(
                out,
                ",{},{}",
                at(&n.frames_per_step),
                at(&n.forwards_per_step)
            )?;
        }
        out.write_all(b"\n")?;
    }
    Ok(())
}

/// A CSV field, quoted (with doubled quotes) when it holds a comma, a quote or a line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
