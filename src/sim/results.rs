//! From merged sums to the numbers people read: `summary.json`, `per_step.csv` and the table.
use super::build::Experiment;
use super::metrics::{Layout, Sums};
use super::scenario::Params;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Steady-state averages (steps >= `from_step`) with Monte Carlo standard errors computed from
/// the spread of the per-trial averages.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SteadyState {
    pub from_step: usize,
    /// Total squared error summed over all state components (comparable with `trace`).
    pub mse: f64,
    pub mse_se: f64,
    pub trace: f64,
    pub trace_se: f64,
    /// Mean NEES divided by the state dimension (1 for a consistent filter).
    pub anees: f64,
    pub rate: f64,
    pub rate_se: f64,
}

/// Results of one scheme variant.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SchemeSummary {
    pub name: String,
    pub kind: String,
    pub curve: usize,
    pub params: Params,
    /// RMSE per state group per step.
    pub rmse: BTreeMap<String, Vec<f64>>,
    /// Time average of the per-step RMSE, per group.
    pub mean_rmse: BTreeMap<String, f64>,
    /// Mean total squared error per step.
    pub mse: Vec<f64>,
    /// Mean trace of the fused covariance per step.
    pub trace: Vec<f64>,
    /// Mean NEES / state dimension per step.
    pub anees_per_step: Vec<f64>,
    /// Time average of `anees_per_step`.
    pub anees: f64,
    /// Transmissions / (sensors x steps).
    pub rate: f64,
    /// Mean number of sensors transmitting per step.
    pub transmissions_per_step: f64,
    /// Mean payload bits sent per step (all sensors).
    pub bits_per_step: f64,
    /// Mean bits of the 802.15.4 MAC frames sent per step (header, payload, footer).
    pub frame_bits_per_step: f64,
    /// Mean feedback bits from the fusion center to the sensors per step.
    pub downlink_bits_per_step: f64,
    /// Fraction of (trial, step) pairs whose fused covariance was singular (collapsed
    /// particle clouds); their NEES used a 1e-9 relative jitter.
    pub degenerate_covariance_fraction: f64,
    /// Fraction of (trial, step) pairs whose NEES was below the chi-square 99% quantile: 0.99
    /// for a consistent filter. Robust where the mean NEES is ruined by a few collapsed
    /// particle clouds.
    pub nees_coverage_99: f64,
    pub steady_state: SteadyState,
    /// Per trial: steady-state MSE, total then per group (for paired comparisons; not
    /// written to summary.json).
    #[serde(skip)]
    pub per_trial: Vec<Vec<f64>>,
}

/// The whole run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    pub scenario: String,
    pub description: String,
    pub source: String,
    pub trials: usize,
    pub steps: usize,
    pub seed: u64,
    pub sensors: usize,
    pub state_dim: usize,
    pub groups: BTreeMap<String, Vec<usize>>,
    /// Group names in file order.
    pub group_order: Vec<String>,
    pub schemes: Vec<SchemeSummary>,
}

/// Turns sums into per-scheme results.
pub fn summarize(exp: &Experiment, sums: &[Sums]) -> Summary {
    let n = exp.system.state_dim() as f64;
    let n_sensors = exp.system.n_sensors() as f64;
    let trials = exp.trials as f64;
    let steps = exp.steps;
    let schemes = exp
        .variants
        .iter()
        .zip(sums)
        .map(|(v, s)| {
            let layout = s.layout();
            let col = |f: usize| -> Vec<f64> { (0..steps).map(|k| s.at(k, f) / trials).collect() };
            let mut rmse = BTreeMap::new();
            let mut mean_rmse = BTreeMap::new();
            for (g, (name, _)) in exp.groups.iter().enumerate() {
                let r: Vec<f64> = col(layout.group(g)).into_iter().map(f64::sqrt).collect();
                mean_rmse.insert(name.clone(), r.iter().sum::<f64>() / steps as f64);
                rmse.insert(name.clone(), r);
            }
            let anees_per_step: Vec<f64> = col(Layout::NEES).into_iter().map(|x| x / n).collect();
            let messages: f64 = col(Layout::MESSAGES).iter().sum();
            let bits: f64 = col(Layout::BITS).iter().sum();
            let frame_bits: f64 = col(Layout::FRAME_BITS).iter().sum();
            let downlink_bits: f64 = col(Layout::DOWNLINK_BITS).iter().sum();
            let degenerate: f64 = col(Layout::DEGENERATE).iter().sum();
            let covered: f64 = col(Layout::NEES_COVERED).iter().sum();
            let (mse_ss, mse_se) = s.steady_mse.mean_se(exp.trials);
            let (trace_ss, trace_se) = s.steady_trace.mean_se(exp.trials);
            let (nees_ss, _) = s.steady_nees.mean_se(exp.trials);
            let (msg_ss, msg_se) = s.steady_messages.mean_se(exp.trials);
            SchemeSummary {
                name: exp.curves[v.curve].label.clone(),
                kind: v.kind.to_string(),
                curve: v.curve,
                params: v.params.clone(),
                rmse,
                mean_rmse,
                mse: col(Layout::TOTAL_SE),
                trace: col(Layout::TRACE),
                anees: anees_per_step.iter().sum::<f64>() / steps as f64,
                anees_per_step,
                rate: messages / (steps as f64 * n_sensors),
                transmissions_per_step: messages / steps as f64,
                bits_per_step: bits / steps as f64,
                frame_bits_per_step: frame_bits / steps as f64,
                downlink_bits_per_step: downlink_bits / steps as f64,
                degenerate_covariance_fraction: degenerate / steps as f64,
                nees_coverage_99: covered / steps as f64,
                per_trial: s.per_trial.clone(),
                steady_state: SteadyState {
                    from_step: exp.steady_from,
                    mse: mse_ss,
                    mse_se,
                    trace: trace_ss,
                    trace_se,
                    anees: nees_ss / n,
                    rate: msg_ss / n_sensors,
                    rate_se: msg_se / n_sensors,
                },
            }
        })
        .collect();
    Summary {
        scenario: exp.name.clone(),
        description: exp.description.clone(),
        source: exp.source.clone(),
        trials: exp.trials,
        steps: exp.steps,
        seed: exp.seed,
        sensors: exp.system.n_sensors(),
        state_dim: exp.system.state_dim(),
        groups: exp.groups.iter().cloned().collect(),
        group_order: exp.groups.iter().map(|(g, _)| g.clone()).collect(),
        schemes,
    }
}

/// Compact "k=v, k=v" of a variant's parameters.
pub fn params_text(p: &Params) -> String {
    p.iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `per_step.csv`: one row per scheme variant and step.
pub fn per_step_csv(summary: &Summary) -> String {
    let groups: Vec<&String> = summary.group_order.iter().collect();
    let mut out = String::from("scheme,params,step");
    for g in &groups {
        let _ = write!(out, ",rmse_{g}");
    }
    out.push_str(",mse,trace,anees\n");
    for s in &summary.schemes {
        for k in 0..summary.steps {
            let _ = write!(
                out,
                "\"{}\",\"{}\",{}",
                s.name,
                params_text(&s.params),
                k + 1
            );
            for g in &groups {
                let _ = write!(out, ",{}", s.rmse[*g][k]);
            }
            let _ = writeln!(out, ",{},{},{}", s.mse[k], s.trace[k], s.anees_per_step[k]);
        }
    }
    out
}

/// The results table printed on the terminal.
pub fn table(summary: &Summary) -> String {
    let groups: Vec<&String> = summary.group_order.iter().collect();
    let mut header = vec!["scheme".to_string(), "params".to_string()];
    header.extend(groups.iter().map(|g| format!("RMSE {g}")));
    header.extend(
        [
            "MSE(ss)",
            "±se",
            "trace(ss)",
            "ANEES",
            "NEES<99%",
            "rate",
            "tx/step",
            "bits/step",
            "frame bits/step",
            "downlink/step",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    let mut rows = vec![header];
    for s in &summary.schemes {
        let mut r = vec![s.name.clone(), params_text(&s.params)];
        r.extend(groups.iter().map(|g| format!("{:.4}", s.mean_rmse[*g])));
        r.push(format!("{:.4}", s.steady_state.mse));
        r.push(format!("{:.4}", s.steady_state.mse_se));
        r.push(format!("{:.4}", s.steady_state.trace));
        r.push(if s.anees.abs() < 1e6 {
            format!("{:.3}", s.anees)
        } else {
            format!("{:.1e}", s.anees)
        });
        r.push(format!("{:.3}", s.nees_coverage_99));
        r.push(format!("{:.3}", s.rate));
        r.push(format!("{:.2}", s.transmissions_per_step));
        r.push(format!("{:.0}", s.bits_per_step));
        r.push(format!("{:.0}", s.frame_bits_per_step));
        r.push(format!("{:.0}", s.downlink_bits_per_step));
        rows.push(r);
    }
    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut out = String::new();
    for (i, r) in rows.iter().enumerate() {
        let line: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(c, cell)| {
                if c < 2 {
                    format!("{cell:<w$}", w = widths[c])
                } else {
                    format!("{cell:>w$}", w = widths[c])
                }
            })
            .collect();
        out.push_str(line.join("  ").trim_end());
        out.push('\n');
        if i == 0 {
            out.push_str(&"-".repeat(widths.iter().sum::<usize>() + 2 * (widths.len() - 1)));
            out.push('\n');
        }
    }
    out
}

/// A point of a curve against the communication rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    pub rate: f64,
    pub mse: f64,
    pub mse_se: f64,
    pub trace: f64,
    /// Index into `summary.schemes`.
    pub variant: usize,
}

/// The steady-state points of curve `curve`, sorted by rate; with a frontier, only the best
/// variant per rate bin.
pub fn curve_points(exp: &Experiment, summary: &Summary, curve: usize) -> Vec<CurvePoint> {
    let mut pts: Vec<CurvePoint> = summary
        .schemes
        .iter()
        .enumerate()
        .filter(|(_, s)| s.curve == curve)
        .map(|(i, s)| CurvePoint {
            rate: s.steady_state.rate,
            mse: s.steady_state.mse,
            mse_se: s.steady_state.mse_se,
            trace: s.steady_state.trace,
            variant: i,
        })
        .collect();
    if let Some(f) = &exp.curves[curve].frontier {
        let mut best: BTreeMap<i64, CurvePoint> = BTreeMap::new();
        for p in pts {
            let bin = (p.rate / f.bin_width).floor() as i64;
            let key = |q: &CurvePoint| match f.metric {
                super::scenario::FrontierMetric::Mse => q.mse,
                super::scenario::FrontierMetric::Trace => q.trace,
            };
            match best.get(&bin) {
                Some(b) if key(b) <= key(&p) => {}
                _ => {
                    best.insert(bin, p);
                }
            }
        }
        pts = best.into_values().collect();
    }
    pts.sort_by(|a, b| a.rate.total_cmp(&b.rate));
    pts
}

/// Where a summary holds a number that is not finite (an overflow or a collapsed filter):
/// `scheme (params): metric` for each. A run that produces one must not look like a success.
pub fn non_finite(summary: &Summary) -> Vec<String> {
    let mut out = Vec::new();
    for s in &summary.schemes {
        let value = serde_json::to_value(s).unwrap_or(serde_json::Value::Null);
        let mut bad = Vec::new();
        find_nulls(&value, "", &mut bad);
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
