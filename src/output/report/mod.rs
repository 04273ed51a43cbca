//! `hushfuse reproduce`: our numbers beside the paper's published ones, and each of the paper's
//! claims checked on our numbers.
pub mod classic;
pub mod energy_ratio;
pub mod intermittent;
#[cfg(test)]
mod tests;
mod verdict;

pub use verdict::{trials_to_resolve, ClaimResult, Verdict, Z_DECIDE, Z_TARGET};

use crate::metrics::results::{curve_points, params_text, CurvePoint, Summary};
use crate::scenario::build::Experiment;
use crate::scenario::ClaimSpec;
use serde::Serialize;
use std::fmt::Write as _;

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
    /// `agrees` when |ours - paper| <= 2 standard errors (or, without a standard error,
    /// within `tolerance` relative), else `differs`; `missing` when we have no number.
    pub verdict: String,
    /// (ours - paper) / standard error, where there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub z: Option<f64>,
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
            } => check_below(exp, summary, text, a, b, metric, rate_range),
            ClaimSpec::ReachesRateBelow { text, scheme, rate } => {
                check_reaches_rate_below(exp, summary, text, scheme, rate)
            }
            ClaimSpec::Better {
                text,
                a,
                a_params,
                b,
                b_params,
                metric,
            } => pairwise(summary, text, (a, a_params), (b, b_params), metric, |d, se, _, _| {
                if d == 0.0 && se == 0.0 {
                    return (
                        Verdict::Fails,
                        None,
                        "identical on every trial: neither beats the other".to_string(),
                    );
                }
                let z = d / se;
                (
                    Verdict::of_z(z),
                    trials_to_resolve(summary.trials, z),
                    format!("z = {z:.1} (criterion: difference < 0 by more than {Z_DECIDE} standard errors)"),
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
                tolerance_source,
            } => check_close(
                summary,
                text,
                (a, a_params),
                (b, b_params),
                metric,
                within,
                tolerance_source,
            ),
            ClaimSpec::CloserToTarget { text, a, b, param, metric } => {
                check_closer_to_target(summary, text, a, b, param, metric)
            }
            ClaimSpec::Consistent { text, schemes } => check_consistent(exp, summary, text, schemes),
            ClaimSpec::Intermittent { text, scheme, check, within, sequences, range } => {
                intermittent::check(exp, summary, text, scheme, *check, (*within, *sequences, *range))
            }
            ClaimSpec::Inflation { text, scheme, check, reference, within } => {
                classic::check(exp, summary, text, scheme, (*check, reference.as_deref(), *within))
            }
            ClaimSpec::EnergyRatio { text, a, b, at_least } => {
                energy_ratio::check(exp, summary, text, (a, b), *at_least)
            }
        })
        .collect()
}

/// A `below` claim: `metric` of curve `a` below curve `b` (interpolated at the rates of `a`) by
/// more than [`Z_DECIDE`] standard errors at every distinct rate of `a` in `rate_range`.
fn check_below(
    exp: &Experiment,
    summary: &Summary,
    text: &str,
    a: &str,
    b: &str,
    metric: &str,
    rate_range: &[f64; 2],
) -> ClaimResult {
    let (Some(ia), Some(ib)) = (curve_index(exp, a), curve_index(exp, b)) else {
        return missing(text, &format!("{a} / {b}"));
    };
    let pa = curve_points(exp, summary, ia);
    let pb = curve_points(exp, summary, ib);
    let mut evidence = Vec::new();
    let mut verdict = Verdict::Holds;
    let mut need: Option<usize> = None;
    let mut compared = 0;
    for p in pa
        .iter()
        .filter(|p| p.rate >= rate_range[0] && p.rate <= rate_range[1])
    {
        let Some((d, se)) = below_difference(summary, p, &pb, metric) else {
            continue;
        };
        let va = metric_of(p, metric);
        if d == 0.0 && se == 0.0 {
            evidence.push(format!(
                "rate {:.3}: {va:.4} vs {va:.4} (identical on every trial: the same scheme, not counted)",
                p.rate
            ));
            continue;
        }
        compared += 1;
        let z = d / se;
        let v = Verdict::of_z(z);
        verdict = verdict.and(v);
        if v == Verdict::NotResolved {
            need = need.max(trials_to_resolve(summary.trials, z));
        }
        evidence.push(format!(
            "rate {:.3}: {va:.4} vs {:.4}, z = {z:.1} ({})",
            p.rate,
            va - d,
            v.label()
        ));
    }
    if compared == 0 {
        verdict = Verdict::Fails;
        evidence.push(format!(
            "no distinct rate of {a:?} in [{}, {}] is covered by {b:?}",
            rate_range[0], rate_range[1]
        ));
    }
    ClaimResult::new(
        text,
        verdict,
        need,
        format!(
            "{metric} of {a} vs {b} (criterion: difference below 0 by more than {Z_DECIDE} standard errors at every rate): {}",
            evidence.join("; ")
        ),
    )
}

/// A `reaches-rate-below` claim: the lowest steady-state rate of curve `scheme` below `rate`.
fn check_reaches_rate_below(
    exp: &Experiment,
    summary: &Summary,
    text: &str,
    scheme: &str,
    rate: &f64,
) -> ClaimResult {
    let Some(i) = curve_index(exp, scheme) else {
        return missing(text, scheme);
    };
    let lowest = summary
        .schemes
        .iter()
        .filter(|s| s.curve == i)
        .min_by(|x, y| x.steady_state.rate.total_cmp(&y.steady_state.rate));
    let Some(low) = lowest else {
        return missing(text, scheme);
    };
    let (min, se) = (low.steady_state.rate, low.steady_state.rate_se);
    let z = if se > 0.0 {
        (min - rate) / se
    } else if min < *rate {
        f64::NEG_INFINITY
    } else {
        f64::INFINITY
    };
    ClaimResult::new(
        text,
        Verdict::of_z(z),
        trials_to_resolve(summary.trials, z),
        format!("lowest steady-state rate of {scheme}: {min:.3} ± {se:.3} (bound {rate}; z = {z:.1}, criterion: below by more than {Z_DECIDE} standard errors)"),
    )
}

/// A `close` claim: the relative difference of `metric` between the variants `a` and `b`
/// within `within` (from `tolerance_source`).
fn check_close(
    summary: &Summary,
    text: &str,
    (a, a_params): (&str, &crate::scenario::Params),
    (b, b_params): (&str, &crate::scenario::Params),
    metric: &str,
    within: &f64,
    tolerance_source: &str,
) -> ClaimResult {
    let mut r = pairwise(
        summary,
        text,
        (a, a_params),
        (b, b_params),
        metric,
        |d, se, _, mb| {
            let rel = d.abs() / mb;
            let rel_se = se / mb;
            // Negative z supports the claim: |rel| is below the tolerance.
            let z = if rel_se > 0.0 {
                (rel - within) / rel_se
            } else if rel <= *within {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            };
            (
            Verdict::of_z(z),
            trials_to_resolve(summary.trials, z),
            format!(
                "relative difference {:.1}% ± {:.1}% (criterion: <= {:.1}% ({tolerance_source}) by more than {Z_DECIDE} standard errors; z = {z:.1})",
                100.0 * rel,
                100.0 * rel_se,
                100.0 * within
            ),
        )
        },
    );
    r.tolerance_source = Some(tolerance_source.to_string());
    r
}

/// A `closer-to-target` claim: at every common value of `param` (the target), `metric` of
/// scheme `a` closer to it than that of scheme `b`.
fn check_closer_to_target(
    summary: &Summary,
    text: &str,
    a: &str,
    b: &str,
    param: &str,
    metric: &str,
) -> ClaimResult {
    let value = |s: &crate::metrics::results::SchemeSummary| -> Option<f64> {
        match metric {
            "transmissions_per_step" => Some(s.transmissions_per_step),
            "rate" => Some(s.rate),
            _ => None,
        }
    };
    let mut verdict = Verdict::Holds;
    let mut need: Option<usize> = None;
    let mut evidence = Vec::new();
    // Standard error of the metric (both are rates of transmissions).
    let se_of = |s: &crate::metrics::results::SchemeSummary| -> f64 {
        if metric == "rate" {
            s.steady_state.rate_se
        } else {
            s.steady_state.rate_se * summary.sensors as f64
        }
    };
    for sa in summary.schemes.iter().filter(|s| s.name == a) {
        let Some(crate::scenario::ParamValue::Number(target)) = sa.params.get(param) else {
            continue;
        };
        let Some(sb) = summary.schemes.iter().find(|s| {
            s.name == b
                && s.params
                    .get(param)
                    .is_some_and(|v| v.matches(&crate::scenario::ParamValue::Number(*target)))
        }) else {
            continue;
        };
        let (Some(va), Some(vb)) = (value(sa), value(sb)) else {
            return missing(text, metric);
        };
        // Unpaired (the steady-state rates are summaries): a conservative SE.
        let d = (va - target).abs() - (vb - target).abs();
        let se = se_of(sa).hypot(se_of(sb));
        let z = if se > 0.0 {
            d / se
        } else if d < 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
        let v = Verdict::of_z(z);
        verdict = verdict.and(v);
        if v == Verdict::NotResolved {
            need = need.max(trials_to_resolve(summary.trials, z));
        }
        evidence.push(format!(
            "{param} = {target}: {a} {va:.4}, {b} {vb:.4}, z = {z:.1} ({})",
            v.label()
        ));
    }
    if evidence.is_empty() {
        verdict = Verdict::Fails;
        evidence.push(format!("no common values of {param}"));
    }
    ClaimResult::new(
        text,
        verdict,
        need,
        format!(
            "{metric} (criterion: |{a} - target| below |{b} - target| by more than {Z_DECIDE} standard errors): {}",
            evidence.join("; ")
        ),
    )
}

/// A `consistent` claim: every variant of the curves `schemes` with steady-state MSE at most
/// its trace plus 3 standard errors.
fn check_consistent(
    exp: &Experiment,
    summary: &Summary,
    text: &str,
    schemes: &[String],
) -> ClaimResult {
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
    ClaimResult::new(
        text,
        if holds { Verdict::Holds } else { Verdict::Fails },
        None,
        format!(
            "{count} variants; largest MSE/trace = {ratio:.3} at {at} (criterion: MSE <= trace + 3 se)"
        ),
    )
}

/// The one variant of curve `label` whose parameters include `params`.
fn variant<'a>(
    summary: &'a Summary,
    label: &str,
    params: &crate::scenario::Params,
) -> Result<&'a crate::metrics::results::SchemeSummary, String> {
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
    (a, ap): (&str, &crate::scenario::Params),
    (b, bp): (&str, &crate::scenario::Params),
    metric: &str,
    verdict: impl Fn(f64, f64, f64, f64) -> (Verdict, Option<usize>, String),
) -> ClaimResult {
    let found = variant(summary, a, ap)
        .and_then(|va| variant(summary, b, bp).map(|vb| (va, vb)))
        .and_then(|(va, vb)| metric_column(summary, metric).map(|c| (va, vb, c)));
    match found {
        Err(e) => ClaimResult::new(text, Verdict::Fails, None, e),
        Ok((va, vb, col)) => {
            let (d, se, ma, mb) = paired(&va.per_trial, &vb.per_trial, col);
            let (v, need, why) = verdict(d, se, ma, mb);
            ClaimResult::new(
                text,
                v,
                need,
                format!(
                    "{metric}: {a} {ma:.4} (RMS {:.4}) vs {b} {mb:.4} (RMS {:.4}); paired difference {d:.4} ± {se:.4} over {} trials; {why}",
                    ma.sqrt(),
                    mb.sqrt(),
                    va.per_trial.len()
                ),
            )
        }
    }
}

fn missing(text: &str, name: &str) -> ClaimResult {
    ClaimResult::new(
        text,
        Verdict::Fails,
        None,
        format!("no scheme labelled {name:?} in this scenario"),
    )
}

/// Paired difference (a - b) and its standard error at point `p` of curve a, with curve b
/// interpolated linearly in the rate trial by trial (MSE), or unpaired from the two standard
/// errors (trace). `None` outside b's span.
fn below_difference(
    summary: &Summary,
    p: &CurvePoint,
    pb: &[CurvePoint],
    metric: &str,
) -> Option<(f64, f64)> {
    let vb = interpolate(pb, p.rate, metric)?;
    let d = metric_of(p, metric) - vb;
    // The two points of b around p.rate and the weight of the second.
    let (q0, q1, t) = pb
        .windows(2)
        .find(|w| p.rate >= w[0].rate - 1e-9 && p.rate <= w[1].rate + 1e-9)
        .map(|w| {
            let span = w[1].rate - w[0].rate;
            let t = if span.abs() < 1e-12 {
                0.0
            } else {
                ((p.rate - w[0].rate) / span).clamp(0.0, 1.0)
            };
            (w[0], w[1], t)
        })
        .unwrap_or((pb[0], pb[0], 0.0));
    if metric != "mse" {
        let se_b = ((1.0 - t) * q0.mse_se).hypot(t * q1.mse_se);
        return Some((d, p.mse_se.hypot(se_b)));
    }
    let a = &summary.schemes[p.variant].per_trial;
    let b0 = &summary.schemes[q0.variant].per_trial;
    let b1 = &summary.schemes[q1.variant].per_trial;
    let n = a.len().min(b0.len()).min(b1.len());
    if n < 2 {
        return Some((d, f64::NAN));
    }
    let diffs: Vec<f64> = (0..n)
        .map(|i| a[i][0] - ((1.0 - t) * b0[i][0] + t * b1[i][0]))
        .collect();
    let mean = diffs.iter().sum::<f64>() / n as f64;
    let var = diffs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n as f64 - 1.0);
    Some((d, (var / n as f64).sqrt()))
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
            let tolerance = p.tolerance.unwrap_or(0.05);
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
            let z = match (ours, se) {
                (Some(v), Some(se)) if se > 0.0 => Some((v - p.value) / se),
                _ => None,
            };
            let verdict = match (ours, z) {
                (None, _) => "missing".to_string(),
                (Some(_), Some(z)) if z.abs() <= Z_DECIDE => {
                    format!("agrees (within {Z_DECIDE} standard errors)")
                }
                (Some(_), Some(z)) => format!("differs ({:.1} standard errors off)", z.abs()),
                (Some(v), None) => {
                    let rel = (v - p.value).abs() / p.value.abs();
                    let src = if p.tolerance.is_some() {
                        "stated"
                    } else {
                        "ours"
                    };
                    if rel <= tolerance {
                        format!(
                            "agrees (within {:.0}% relative, {src}; no standard error)",
                            100.0 * tolerance
                        )
                    } else {
                        format!(
                            "differs ({:.1}% relative, tolerance {:.0}% {src}; no standard error)",
                            100.0 * rel,
                            100.0 * tolerance
                        )
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
                verdict,
                z,
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
        "{} [{}] {} ({}): paper {:.4}, ours {ours}: {}",
        c.scheme, c.params, c.metric, c.source, c.paper, c.verdict
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
                verdict_text(c),
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
        if let Some(t) = p.trials.filter(|&t| exp.trials < t) {
            let _ = writeln!(
                out,
                "  warning: {} trials, fewer than the paper's {t}: our standard errors are about {:.1}x theirs, and some verdicts may not be resolved (run with --trials {t})",
                exp.trials,
                (t as f64 / exp.trials as f64).sqrt()
            );
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
            verdict_text(c),
            c.text,
            c.evidence
        );
    }
    out
}

/// "holds", "FAILS" or "not resolved at this trial count (about N trials would resolve it)".
fn verdict_text(c: &ClaimResult) -> String {
    match (c.verdict, c.trials_to_resolve) {
        (Verdict::NotResolved, Some(n)) => {
            format!("not resolved at this trial count; about {n} trials would resolve it")
        }
        (Verdict::NotResolved, None) => "not resolved at this trial count".to_string(),
        (v, _) => v.label().to_string(),
    }
}
