//! The arena: every scheme of a scenario at several bit budgets,
//! accuracy against bits per step, the Pareto front and the best scheme per budget.
use crate::engine::calibrate::{bits_cell, render, short, Axis, Calibrated, Outcome, Status};
use crate::output::plot::{self, Line};
use std::path::Path;

/// Indices of the non-dominated points (lower bits and lower error are better), sorted by
/// bits. A point is dominated when another has bits <= and error <= with one of them strictly
/// smaller. Non-finite points are never on the front.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut front: Vec<usize> = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// Whether a result counts at its budget: calibrated, or spending no more than the budget
/// (within the tolerance).
fn within(c: &Calibrated, tol: f64) -> bool {
    c.status == Status::Calibrated || c.achieved <= c.target * (1.0 + tol)
}

/// A scheme that diverged in more than this share of its trials is marked (†) wherever the
/// best-per-budget tables name it: its low mean RMSE comes from a filter that, in some trials,
/// lost the target while claiming to know where it was.
pub const DIVERGED_MARK: f64 = 0.01;

/// Per budget: the schemes within it with a finite mean RMSE of `group`, best first.
fn ranked<'a>(out: &'a Outcome, group: &str) -> Vec<Vec<&'a Calibrated>> {
    out.rows
        .iter()
        .map(|row| {
            let mut ok: Vec<&Calibrated> = row
                .iter()
                .filter(|c| within(c, out.tolerance))
                .filter(|c| c.result.mean_rmse.get(group).is_some_and(|r| r.is_finite()))
                .collect();
            ok.sort_by(|a, c| a.result.mean_rmse[group].total_cmp(&c.result.mean_rmse[group]));
            ok
        })
        .collect()
}

/// Whether `c` diverged often enough to be marked.
fn marked(c: &Calibrated) -> bool {
    c.result.diverged_fraction > DIVERGED_MARK
}

/// The scheme's label, with † when it is [`marked`].
fn label(c: &Calibrated) -> String {
    if marked(c) {
        format!("{} †", c.label)
    } else {
        c.label.clone()
    }
}

/// The headers of what a result spends on every axis ([`Axis::ALL`]), then its entropy-coded
/// rate: every headline row shows them all, whichever axis it was calibrated on.
/// Their meaning: [`SPEND_LEGEND`].
pub fn spend_headers() -> Vec<String> {
    Axis::ALL
        .iter()
        .map(|a| a.name().replace("energy", "µJ"))
        .chain(["R_eff".to_string()])
        .collect()
}

/// What the columns of [`spend_headers`] count, printed once under the tables that have them.
pub const SPEND_LEGEND: &str = "per step: payload, frame (whole 802.15.4 frames) and total (frames + downlink feedback) in bits;\nµJ: the sensors' radio energy, over a [network] every battery-powered node's ([radio], CC2420 by\ndefault); R_eff: the entropy-coded rate in bits (each sensor's send-or-silence entropy + its\npayload), at which the rate-distortion floor is taken.";

/// The cells of [`spend_headers`] for one result.
pub fn spend_cells(s: &crate::metrics::results::SchemeSummary) -> Vec<String> {
    Axis::ALL
        .iter()
        .map(|a| bits_cell(a.of(s)))
        .chain([bits_cell(s.r_eff_per_step)])
        .collect()
}

/// A floor cell: the rate–distortion floor at the result's R_eff, or "—".
fn floor_cell(s: &crate::metrics::results::SchemeSummary) -> String {
    s.floor_mse.map_or("—".into(), |f| format!("{f:.4}"))
}

/// The calibration table of one budget: each scheme's knob and status, what it spends on every
/// axis, its accuracy beside the rate–distortion floor at its R_eff, and its consistency.
pub fn budget_table(outcome: &Outcome, b: usize, group: &str) -> String {
    let mut head = vec!["scheme".to_string(), "knob".into(), "status".into()];
    head.extend(spend_headers());
    head.extend([
        format!("RMSE {group}"),
        "MSE(ss)".into(),
        "±se".into(),
        "floor".into(),
        "ANEES".into(),
    ]);
    let mut rows = vec![head];
    for c in &outcome.rows[b] {
        let r = &c.result;
        let mut row = vec![c.label.clone(), knob_text(c), c.status_text()];
        row.extend(spend_cells(r));
        row.extend([
            r.mean_rmse
                .get(group)
                .map_or("—".into(), |x| format!("{x:.4}")),
            format!("{:.4}", r.steady_state.mse),
            format!("{:.4}", r.steady_state.mse_se),
            floor_cell(r),
            format!("{:.3}", r.anees),
        ]);
        rows.push(row);
    }
    render(&rows)
}

/// "knob = value", or "—" for a scheme without one.
fn knob_text(c: &Calibrated) -> String {
    match (&c.knob, c.value) {
        (Some(k), Some(v)) => format!("{k} = {}", short(v)),
        _ => "—".into(),
    }
}

/// Per budget: the scheme with the lowest mean RMSE of `group` among those within budget,
/// as (budget, label, knob text, RMSE, achieved bits, runner-up label and RMSE). A label
/// carries † when the scheme diverged in more than [`DIVERGED_MARK`] of its trials.
pub fn best_per_budget(out: &Outcome, group: &str) -> Vec<Vec<String>> {
    let mut head = vec![
        format!("budget ({}/step)", out.axis.unit()),
        "best scheme".to_string(),
        "knob".to_string(),
        format!("RMSE {group}"),
    ];
    // What it spends on every axis (the budget's among them).
    head.extend(spend_headers());
    head.extend(["runner-up".to_string(), format!("RMSE {group}")]);
    let mut rows = vec![head];
    for (b, ok) in ranked(out, group).iter().enumerate() {
        let mut r = vec![short(out.budgets[b])];
        match ok.first() {
            Some(c) => {
                r.extend([
                    label(c),
                    knob_text(c),
                    format!("{:.4}", c.result.mean_rmse[group]),
                ]);
                r.extend(spend_cells(&c.result));
            }
            None => {
                r.push("(none within budget)".into());
                r.extend(std::iter::repeat_n(String::new(), 2 + Axis::ALL.len() + 1));
            }
        }
        match ok.get(1) {
            Some(c) => r.extend([label(c), format!("{:.4}", c.result.mean_rmse[group])]),
            None => r.extend(["—".into(), "".into()]),
        }
        rows.push(r);
    }
    rows
}

/// The legend of the † marks of [`best_per_budget`]: which scheme diverged in what share of its
/// trials at which budget; `None` when nothing in the table is marked.
pub fn diverged_legend(out: &Outcome, group: &str) -> Option<String> {
    let mut seen = Vec::new();
    for (b, ok) in ranked(out, group).iter().enumerate() {
        for c in ok.iter().take(2).filter(|c| marked(c)) {
            seen.push(format!(
                "{} at budget {} ({:.1}%)",
                c.label,
                short(out.budgets[b]),
                100.0 * c.result.diverged_fraction
            ));
        }
    }
    (!seen.is_empty()).then(|| {
        format!(
            "† diverged in more than {}% of its trials (NEES above the chi-square 99.9% quantile for {} steps in a row, or not finite): {}",
            short(100.0 * DIVERGED_MARK),
            crate::metrics::DIVERGENCE_RUN,
            seen.join(", ")
        )
    })
}

/// The best-per-budget table as text, with the bound below it where there is one.
pub fn best_table(out: &Outcome, group: &str) -> String {
    let mut s = best_rows(out, group);
    if let Some(line) = bound_line(out, group) {
        s.push_str(&line);
        s.push('\n');
    }
    s
}

/// The best-per-budget table as text with its † legend, without the bound (the quick arena
/// prints several tables and the bound once).
pub fn best_rows(out: &Outcome, group: &str) -> String {
    let mut s = render(&best_per_budget(out, group));
    if let Some(line) = diverged_legend(out, group) {
        s.push_str(&line);
        s.push('\n');
    }
    s
}

/// The posterior Cramér–Rao bound on the mean RMSE of `group` (every sensor at every step,
/// any estimator): no scheme can be below it, whatever its budget.
pub fn bound_line(out: &Outcome, group: &str) -> Option<String> {
    let b = out.summaries.first()?.pcrb.as_ref()?;
    let r = b.mean_rmse.get(group)?;
    Some(format!(
        "bound: posterior Cramér–Rao bound on the mean RMSE of {group} with every sensor at every step, for any estimator: {r:.4}"
    ))
}

/// The best-per-budget table as Markdown.
pub fn best_markdown(out: &Outcome, group: &str) -> String {
    let rows = best_per_budget(out, group);
    let mut s = String::new();
    for (i, r) in rows.iter().enumerate() {
        s.push_str(&format!("| {} |\n", r.join(" | ")));
        if i == 0 {
            s.push_str(&format!("|{}\n", "---|".repeat(r.len())));
        }
    }
    if let Some(line) = diverged_legend(out, group) {
        s.push_str(&format!("\n{line}\n"));
    }
    if let Some(line) = bound_line(out, group) {
        s.push_str(&format!("\n{line}\n"));
    }
    s
}

/// The lines of an accuracy-against-bits figure: per scheme its points over the budgets
/// (markers; a scheme without a knob is one marker), and the Pareto front (dashed black).
pub fn bits_lines(
    out: &Outcome,
    metric: &dyn Fn(&crate::engine::calibrate::Calibrated) -> f64,
    front: bool,
) -> Vec<Line> {
    scheme_lines(out, &|c| c.achieved, metric, front)
}

/// [`bits_lines`] with any abscissa `x` (e.g. the entropy-coded rate).
pub fn scheme_lines(
    out: &Outcome,
    x: &dyn Fn(&Calibrated) -> f64,
    metric: &dyn Fn(&Calibrated) -> f64,
    front: bool,
) -> Vec<Line> {
    let n = out.rows.first().map_or(0, Vec::len);
    let mut lines = Vec::new();
    let mut all = Vec::new();
    for s in 0..n {
        let mut pts: Vec<(f64, f64)> = out
            .rows
            .iter()
            .map(|row| (x(&row[s]), metric(&row[s])))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        pts.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-12);
        all.extend(pts.iter().copied());
        let first = &out.rows[0][s];
        let tag = match first.status {
            Status::NoKnob => " (no knob)",
            Status::NotTunable => " (as written)",
            _ => "",
        };
        lines.push(Line {
            name: format!("{}{tag}", first.label),
            points: pts,
            dashed: false,
            color: if s >= 10 { s + 1 } else { s },
            markers: true,
        });
    }
    if !front {
        return lines;
    }
    let front: Vec<(f64, f64)> = pareto_front(&all).into_iter().map(|i| all[i]).collect();
    lines.push(Line {
        name: "Pareto front".into(),
        points: front,
        dashed: true,
        color: 10,
        markers: false,
    });
    lines
}

/// Adds the bound as a dashed grey horizontal line across the points' range of x.
pub fn with_bound(mut lines: Vec<Line>, bound: Option<f64>) -> Vec<Line> {
    let xs = lines.iter().flat_map(|l| l.points.iter().map(|p| p.0));
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if let Some(b) = bound.filter(|b| b.is_finite() && lo.is_finite()) {
        lines.push(Line {
            name: "PCRB (all data, any estimator)".into(),
            points: vec![(lo, b), (hi, b)],
            dashed: true,
            color: 9,
            markers: false,
        });
    }
    lines
}

/// The lines of the rate–distortion figure: every scheme's steady-state MSE against its
/// entropy-coded rate R_eff over the budgets, the floor (dashed black: no scheme can lie below
/// it) and the all-data bound (dashed grey); `None` without a floor.
pub fn floor_lines(out: &Outcome) -> Option<Vec<Line>> {
    let first = out.summaries.first()?;
    let curve = first.rate_distortion_floor.as_ref()?;
    let mut lines = scheme_lines(
        out,
        &|c| c.result.r_eff_per_step,
        &|c| c.result.steady_state.mse,
        false,
    );
    let hi = lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| p.0))
        .fold(curve.rate.last().copied().unwrap_or(1.0), f64::max);
    let mut pts: Vec<(f64, f64)> = curve
        .rate
        .iter()
        .copied()
        .zip(curve.mse.iter().copied())
        .collect();
    // Beyond the curve's last rate the floor is the all-data error to within 1e-6.
    pts.push((hi, curve.all_data_mse));
    lines.push(Line {
        name: "rate-distortion floor (any causal scheme)".into(),
        points: pts,
        dashed: true,
        color: 10,
        markers: false,
    });
    if let Some(b) = &first.pcrb {
        let lo = curve.rate.first().copied().unwrap_or(0.0);
        lines.push(Line {
            name: "PCRB (all data, any estimator)".into(),
            points: vec![(lo, b.steady_mse), (hi, b.steady_mse)],
            dashed: true,
            color: 9,
            markers: false,
        });
    }
    Some(lines)
}

/// Writes `rmse_<group>_vs_bits.svg` (first group), `anees_vs_bits.svg` and, where the scenario
/// has a rate–distortion floor, `mse_vs_r_eff.svg`; returns the files.
pub fn write_plots(
    out: &Outcome,
    group: &str,
    scenario: &str,
    dir: &Path,
) -> Result<Vec<String>, String> {
    let x = format!("{} per step (achieved)", out.axis.unit());
    let mut files = Vec::new();
    let f = format!("rmse_{group}_vs_bits.svg");
    let g = group.to_string();
    plot::lines(
        &dir.join(&f),
        &format!(
            "{scenario}: mean RMSE of {group} against {}",
            out.axis.unit()
        ),
        &x,
        &format!("mean RMSE {group}"),
        &with_bound(
            bits_lines(
                out,
                &|c| c.result.mean_rmse.get(&g).copied().unwrap_or(f64::NAN),
                true,
            ),
            out.summaries
                .first()
                .and_then(|s| s.pcrb.as_ref())
                .and_then(|b| b.mean_rmse.get(&g).copied()),
        ),
    )?;
    files.push(f);
    let f = "anees_vs_bits.svg".to_string();
    plot::lines(
        &dir.join(&f),
        &format!(
            "{scenario}: ANEES against {} (1 = consistent)",
            out.axis.unit()
        ),
        &x,
        "ANEES",
        &bits_lines(out, &|c| c.result.anees, false),
    )?;
    files.push(f);
    if let Some(lines) = floor_lines(out) {
        let f = "mse_vs_r_eff.svg".to_string();
        plot::lines(
            &dir.join(&f),
            &format!("{scenario}: {FLOOR_TITLE}"),
            FLOOR_X,
            FLOOR_Y,
            &lines,
        )?;
        files.push(f);
    }
    Ok(files)
}

/// The rate–distortion figure's title and axes.
pub const FLOOR_TITLE: &str = "steady-state MSE against the entropy-coded rate, above the floor";
pub const FLOOR_X: &str = "R_eff, bits per step (send-or-silence entropy + payload)";
pub const FLOOR_Y: &str = "steady-state MSE (total)";

/// The quick arena of `hushfuse` without arguments: its scenario and trials.
pub const QUICK: (&str, usize) = ("arena-1d", 40);

/// The quick arena's axes and budgets, in the order it prints them: energy first, the axis a
/// battery-powered deployment pays (docs/scenarios.md, "Which axis"), payload last, the
/// papers' count. On arena-1d the four sensors spend 240 µJ a step asleep and 420 sending
/// every reading; every reading is 480 frame bits and 128 payload bits.
pub const QUICK_AXES: [(Axis, &[f64]); 4] = [
    (Axis::Energy, &[270.0, 300.0, 330.0, 390.0]),
    (Axis::Total, &[96.0, 192.0, 288.0, 384.0]),
    (Axis::Frame, &[96.0, 192.0, 288.0, 384.0]),
    (Axis::Payload, &[12.0, 24.0, 48.0, 96.0]),
];

/// The paragraph above the quick arena's tables.
pub fn quick_description(trials: usize) -> String {
    format!(
        "The quick arena (built-in `arena-1d`, {trials} trials x 100 steps): a target moving on a \
line at nearly constant velocity, watched by three position sensors (noise variances 1, 2 and 4) \
and one velocity sensor, each sending 32-bit readings in IEEE 802.15.4 frames. Every scheme of \
the library runs on the same truths and measurements; each scheme's one bandwidth knob (a send \
probability, a threshold, the number of quantizer bits, the average number of senders) is tuned \
so that it spends the same budget per step, and each table names, per budget, the scheme with the \
lowest mean position RMSE and what it spends on every axis. First the axis a battery-powered \
deployment pays: the sensors' radio energy (CC2420 radios, one step a second: whole frames with \
their headers and turnaround, listening for the center's feedback, sleep). Then total bits \
(frames plus feedback), frame bits, and last payload bits, the papers' count, on which a scheme \
that sends tiny payloads in whole frames, or listens for feedback, looks cheaper than its radio \
is. Schemes without a knob (the all-data KF, the round-robin Geng et al. schemes) spend what they \
spend and count only at budgets they fit. `hushfuse run arena-1d --budgets 270,300,330,390 \
--report` gives the full comparison with figures (`--budget-axis payload` for payload bits).\n"
    )
}

/// The heading of one axis's table in the quick arena: the axis, with what the sensors spend
/// asleep (energy) and what the all-data Kalman filter spends on it.
pub fn quick_heading(out: &Outcome, asleep_uj: f64) -> String {
    let all_data = out
        .rows
        .first()
        .and_then(|row| row.iter().find(|c| c.kind == "centralized-kf"))
        .map(|c| out.axis.of(&c.result));
    let mut h = format!("\n{} per step", out.axis.unit());
    let mut notes = Vec::new();
    if out.axis == Axis::Energy {
        notes.push(format!("asleep: {}", short(asleep_uj)));
    }
    if let Some(a) = all_data {
        notes.push(format!("every reading sent: {}", short(a)));
    }
    if !notes.is_empty() {
        h.push_str(&format!(" ({})", notes.join("; ")));
    }
    h.push_str(":\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_of_a_hand_made_set() {
        let pts = [
            (10.0, 5.0),     // 0: front
            (20.0, 3.0),     // 1: front
            (15.0, 6.0),     // 2: dominated by 0
            (30.0, 3.0),     // 3: dominated by 1 (same error, more bits)
            (5.0, 9.0),      // 4: front (fewest bits)
            (40.0, 1.0),     // 5: front
            (20.0, 4.0),     // 6: dominated by 1 (same bits, more error)
            (f64::NAN, 0.1), // 7: never
            (10.0, 5.0),     // 8: duplicate of 0: only one of them
        ];
        let f = pareto_front(&pts);
        assert_eq!(f.len(), 4, "{f:?}");
        assert_eq!(f[0], 4);
        assert!(f[1] == 0 || f[1] == 8);
        assert_eq!(&f[2..], &[1, 5]);
        // No point of the front is dominated by any point, and every other point is.
        for (i, p) in pts.iter().enumerate() {
            if !p.0.is_finite() {
                continue;
            }
            let dominated = pts
                .iter()
                .any(|q| q.0.is_finite() && q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1));
            if f.contains(&i) {
                assert!(!dominated, "{i} on the front but dominated");
            } else if i != 0 && i != 8 {
                assert!(dominated, "{i} off the front but not dominated");
            }
        }
    }
}
