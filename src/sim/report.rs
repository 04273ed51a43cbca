//! `hushfuse reproduce`: our numbers beside the paper's published ones, and each of the paper's
//! claims checked on our numbers.
use super::build::Experiment;
use super::results::{curve_points, params_text, CurvePoint, Summary};
use super::scenario::ClaimSpec;
use serde::Serialize;
use std::fmt::Write as _;

/// A claim and whether it holds in our run.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ClaimResult {
    pub text: String,
    pub holds: bool,
    /// The numbers behind the verdict.
    pub evidence: String,
}

/// A published number and ours.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Comparison {
    pub scheme: String,
    pub params: String,
    pub metric: String,
    pub source: String,
    pub paper: f64,
    pub ours: Option<f64>,
    pub ours_se: Option<f64>,
}

fn curve_index(exp: &Experiment, label: &str) -> Option<usize> {
    exp.curves.iter().position(|c| c.label == label)
}

fn metric_of(p: &CurvePoint, metric: &str) -> f64 {
    if metric == "trace" {
        p.trace
    } else {
        p.mse
    }
}

/// Linear interpolation of `metric` along a curve sorted by rate; `None` outside its span.
fn interpolate(pts: &[CurvePoint], rate: f64, metric: &str) -> Option<f64> {
    let first = pts.first()?;
    let last = pts.last()?;
    if rate < first.rate - 1e-9 || rate > last.rate + 1e-9 {
        return None;
    }
    for w in pts.windows(2) {
        let (p, q) = (&w[0], &w[1]);
        if rate >= p.rate - 1e-9 && rate <= q.rate + 1e-9 {
            let span = q.rate - p.rate;
            if span.abs() < 1e-12 {
                return Some(metric_of(p, metric).min(metric_of(q, metric)));
            }
            let t = ((rate - p.rate) / span).clamp(0.0, 1.0);
            return Some(metric_of(p, metric) * (1.0 - t) + metric_of(q, metric) * t);
        }
    }
    Some(metric_of(first, metric))
}

/// Checks every claim of the scenario's `[paper]` section.
pub fn check_claims(exp: &Experiment, summary: &Summary) -> Vec<ClaimResult> {
    let Some(paper) = &exp.paper else {
        return Vec::new();
    };
    paper
        .claims
        .iter()
        .map(|c| match c {
            ClaimSpec::Below {
                text,
                a,
                b,
                metric,
                rate_range,
            } => {
                let (Some(ia), Some(ib)) = (curve_index(exp, a), curve_index(exp, b)) else {
                    return missing(text, &format!("{a} / {b}"));
                };
                let pa = curve_points(exp, summary, ia);
                let pb = curve_points(exp, summary, ib);
                let mut evidence = Vec::new();
                let mut holds = true;
                let mut compared = 0;
                for p in pa
                    .iter()
                    .filter(|p| p.rate >= rate_range[0] && p.rate <= rate_range[1])
                {
                    if let Some(vb) = interpolate(&pb, p.rate, metric) {
                        let va = metric_of(p, metric);
                        compared += 1;
                        holds &= va < vb;
                        evidence.push(format!(
                            "rate {:.3}: {:.4} vs {:.4} ({})",
                            p.rate,
                            va,
                            vb,
                            if va < vb { "ok" } else { "FAILS" }
                        ));
                    }
                }
                if compared == 0 {
                    holds = false;
                    evidence.push(format!(
                        "no rate of {a:?} in [{}, {}] is covered by {b:?}",
                        rate_range[0], rate_range[1]
                    ));
                }
                ClaimResult {
                    text: text.clone(),
                    holds,
                    evidence: format!("{metric} of {a} vs {b}: {}", evidence.join("; ")),
                }
            }
            ClaimSpec::ReachesRateBelow { text, scheme, rate } => {
                let Some(i) = curve_index(exp, scheme) else {
                    return missing(text, scheme);
                };
                let min = summary
                    .schemes
                    .iter()
                    .filter(|s| s.curve == i)
                    .map(|s| s.steady_state.rate)
                    .fold(f64::INFINITY, f64::min);
                ClaimResult {
                    text: text.clone(),
                    holds: min < *rate,
                    evidence: format!("lowest steady-state rate of {scheme}: {min:.3} (bound {rate})"),
                }
            }
            ClaimSpec::Better {
                text,
                a,
                a_params,
                b,
                b_params,
                metric,
            } => pairwise(summary, text, (a, a_params), (b, b_params), metric, |d, se, _, _| {
                let z = d / se;
                (
                    d < 0.0 && z < -2.0,
                    format!("z = {z:.1} (criterion: difference < 0 by more than 2 standard errors)"),
                )
            }),
            ClaimSpec::Close {
                text,
                a,
                a_params,
                b,
                b_params,
                metric,
                within,
            } => pairwise(summary, text, (a, a_params), (b, b_params), metric, |_, _, ma, mb| {
                let rel = (ma - mb).abs() / mb;
                (
                    rel <= *within,
                    format!("relative difference {:.1}% (criterion: <= {:.1}%)", 100.0 * rel, 100.0 * within),
                )
            }),
            ClaimSpec::CloserToTarget { text, a, b, param, metric } => {
                let value = |s: &super::results::SchemeSummary| -> Option<f64> {
                    match metric.as_str() {
                        "transmissions_per_step" => Some(s.transmissions_per_step),
                        "rate" => Some(s.rate),
                        _ => None,
                    }
                };
                let mut holds = true;
                let mut evidence = Vec::new();
                for sa in summary.schemes.iter().filter(|s| &s.name == a) {
                    let Some(super::scenario::ParamValue::Number(target)) = sa.params.get(param) else {
                        continue;
                    };
                    let Some(sb) = summary.schemes.iter().find(|s| {
                        &s.name == b && s.params.get(param).is_some_and(|v| v.matches(&super::scenario::ParamValue::Number(*target)))
                    }) else {
                        continue;
                    };
                    let (Some(va), Some(vb)) = (value(sa), value(sb)) else {
                        return missing(text, metric);
                    };
                    let ok = (va - target).abs() < (vb - target).abs();
                    holds &= ok;
                    evidence.push(format!(
                        "{param} = {target}: {a} {va:.4}, {b} {vb:.4} ({})",
                        if ok { "ok" } else { "FAILS" }
                    ));
                }
                if evidence.is_empty() {
                    holds = false;
                    evidence.push(format!("no common values of {param}"));
                }
                ClaimResult {
                    text: text.clone(),
                    holds,
                    evidence: format!("{metric}: {}", evidence.join("; ")),
                }
            }
            ClaimSpec::Consistent { text, schemes } => {
                let mut holds = true;
                let mut worst: Option<(f64, String)> = None;
                let mut count = 0;
                for name in schemes {
                    let Some(i) = curve_index(exp, name) else {
                        return missing(text, name);
                    };
                    for s in summary.schemes.iter().filter(|s| s.curve == i) {
                        count += 1;
                        let ss = &s.steady_state;
                        holds &= ss.mse <= ss.trace + 3.0 * ss.mse_se;
                        let ratio = ss.mse / ss.trace;
                        if worst.as_ref().is_none_or(|(w, _)| ratio > *w) {
                            worst = Some((
                                ratio,
                                format!(
                                    "{} [{}]: MSE {:.4} ± {:.4}, trace {:.4}",
                                    s.name,
                                    params_text(&s.params),
                                    ss.mse,
                                    ss.mse_se,
                                    ss.trace
                                ),
                            ));
                        }
                    }
                }
                let (ratio, at) = worst.unwrap_or((f64::NAN, String::new()));
                ClaimResult {
                    text: text.clone(),
                    holds,
                    evidence: format!(
                        "{count} variants; largest MSE/trace = {ratio:.3} at {at} (criterion: MSE <= trace + 3 se)"
                    ),
                }
            }
        })
        .collect()
}

/// The one variant of curve `label` whose parameters include `params`.
fn variant<'a>(
    summary: &'a Summary,
    label: &str,
    params: &super::scenario::Params,
) -> Result<&'a super::results::SchemeSummary, String> {
    let found: Vec<_> = summary
        .schemes
        .iter()
        .filter(|s| {
            s.name == label
                && params
                    .iter()
                    .all(|(k, v)| s.params.get(k).is_some_and(|x| x.matches(v)))
        })
        .collect();
    match found.len() {
        1 => Ok(found[0]),
        0 => Err(format!(
            "no scheme labelled {label:?} with those parameters"
        )),
        n => Err(format!(
            "{n} variants of {label:?} match; give its sweep parameters"
        )),
    }
}

/// Column of `per_trial` for a metric: `mse` (total) or `mse:<group>`.
fn metric_column(summary: &Summary, metric: &str) -> Result<usize, String> {
    if metric == "mse" {
        return Ok(0);
    }
    metric
        .strip_prefix("mse:")
        .and_then(|g| summary.group_order.iter().position(|n| n == g))
        .map(|i| i + 1)
        .ok_or_else(|| format!("unknown metric {metric:?}; expected mse or mse:<group>"))
}

/// Mean of `a - b` over trials and its standard error.
fn paired(a: &[Vec<f64>], b: &[Vec<f64>], col: usize) -> (f64, f64, f64, f64) {
    let n = a.len().min(b.len()) as f64;
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x[col] - y[col]).collect();
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0).max(1.0);
    let ma = a.iter().map(|x| x[col]).sum::<f64>() / n;
    let mb = b.iter().map(|x| x[col]).sum::<f64>() / n;
    (mean, (var / n).sqrt(), ma, mb)
}

fn pairwise(
    summary: &Summary,
    text: &str,
    (a, ap): (&str, &super::scenario::Params),
    (b, bp): (&str, &super::scenario::Params),
    metric: &str,
    verdict: impl Fn(f64, f64, f64, f64) -> (bool, String),
) -> ClaimResult {
    let found = variant(summary, a, ap)
        .and_then(|va| variant(summary, b, bp).map(|vb| (va, vb)))
        .and_then(|(va, vb)| metric_column(summary, metric).map(|c| (va, vb, c)));
    match found {
        Err(e) => ClaimResult {
            text: text.to_string(),
            holds: false,
            evidence: e,
        },
        Ok((va, vb, col)) => {
            let (d, se, ma, mb) = paired(&va.per_trial, &vb.per_trial, col);
            let (holds, why) = verdict(d, se, ma, mb);
            ClaimResult {
                text: text.to_string(),
                holds,
                evidence: format!(
                    "{metric}: {a} {ma:.4} (RMS {:.4}) vs {b} {mb:.4} (RMS {:.4}); paired difference {d:.4} ± {se:.4} over {} trials; {why}",
                    ma.sqrt(),
                    mb.sqrt(),
                    va.per_trial.len()
                ),
            }
        }
    }
}

fn missing(text: &str, name: &str) -> ClaimResult {
    ClaimResult {
        text: text.to_string(),
        holds: false,
        evidence: format!("no scheme labelled {name:?} in this scenario"),
    }
}

/// Our value of each published number.
pub fn compare_published(exp: &Experiment, summary: &Summary) -> Vec<Comparison> {
    let Some(paper) = &exp.paper else {
        return Vec::new();
    };
    paper
        .published
        .iter()
        .map(|p| {
            let found = summary.schemes.iter().find(|s| {
                s.name == p.scheme
                    && p.params
                        .iter()
                        .all(|(k, v)| s.params.get(k).is_some_and(|x| x.matches(v)))
            });
            let (ours, se) = match found {
                None => (None, None),
                Some(s) => {
                    let ss = &s.steady_state;
                    match p.metric.as_str() {
                        "mse" => (Some(ss.mse), Some(ss.mse_se)),
                        "trace" => (Some(ss.trace), Some(ss.trace_se)),
                        "rate" => (Some(ss.rate), Some(ss.rate_se)),
                        "transmissions_per_step" => (
                            Some(s.transmissions_per_step),
                            Some(ss.rate_se * summary.sensors as f64),
                        ),
                        m => match m.strip_prefix("rmse:") {
                            Some(g) => (s.mean_rmse.get(g).copied(), None),
                            None => (None, None),
                        },
                    }
                }
            };
            Comparison {
                scheme: p.scheme.clone(),
                params: params_text(&p.params),
                metric: p.metric.clone(),
                source: p.source.clone(),
                paper: p.value,
                ours,
                ours_se: se,
            }
        })
        .collect()
}

/// A published number beside ours (with its Monte Carlo standard error when it has one).
fn comparison_text(c: &Comparison) -> String {
    let ours = match (c.ours, c.ours_se) {
        (Some(v), Some(se)) => format!("{v:.4} ± {se:.4}"),
        (Some(v), None) => format!("{v:.4}"),
        _ => "not found".to_string(),
    };
    format!(
        "{} [{}] {} ({}): paper {:.4}, ours {ours}",
        c.scheme, c.params, c.metric, c.source, c.paper
    )
}

/// The reproduction as a Markdown section, as `docs/reproductions.md` collects them
/// (`scripts/reproductions.sh` regenerates that file from these sections).
pub fn render_markdown(
    id: &str,
    seconds: f64,
    comparisons: &[Comparison],
    claims: &[ClaimResult],
) -> String {
    let mut out = format!("## `{id}` ({seconds:.2} s)\n\n");
    if !comparisons.is_empty() {
        out.push_str("Published numbers beside ours:\n\n");
        for c in comparisons {
            let _ = writeln!(out, "- {}", comparison_text(c));
        }
        out.push('\n');
    }
    if !claims.is_empty() {
        out.push_str("Claims:\n\n");
        for c in claims {
            let _ = writeln!(
                out,
                "- **{}** {}  \n  {}",
                if c.holds { "holds" } else { "FAILS" },
                c.text,
                c.evidence
            );
        }
        out.push('\n');
    }
    out
}

/// Human-readable reproduction report.
pub fn render(exp: &Experiment, comparisons: &[Comparison], claims: &[ClaimResult]) -> String {
    let mut out = String::new();
    if let Some(p) = &exp.paper {
        let _ = writeln!(out, "Reproducing: {}", p.citation);
        for n in &p.notes {
            let _ = writeln!(out, "  note: {n}");
        }
    }
    if comparisons.is_empty() {
        let _ = writeln!(
            out,
            "\nThe paper prints no numbers for this figure; its claims:"
        );
    } else {
        let _ = writeln!(out, "\nPublished numbers vs ours:");
        for c in comparisons {
            let _ = writeln!(out, "  {}", comparison_text(c));
        }
        let _ = writeln!(out, "\nClaims:");
    }
    for c in claims {
        let _ = writeln!(
            out,
            "  [{}] {}\n        {}",
            if c.holds { "holds" } else { "FAILS" },
            c.text,
            c.evidence
        );
    }
    out
}
