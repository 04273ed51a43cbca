//! `report.html`: one self-contained file — inline SVG figures, the tables,
//! the scenario as run, the version and seeds; no scripts, fonts, styles or images from
//! anywhere else, so it reads offline and can be mailed as it is.
use crate::engine::calibrate::{short, Outcome};
use crate::engine::trace::{self, Link};
use crate::metrics::results::{params_text, Summary};
use crate::output::arena;
use crate::output::plot;
use crate::scenario::build::Experiment;
use plotters::prelude::*;
use std::fmt::Write as _;

/// What a report shows.
pub struct Input<'a> {
    /// The experiment as run (for a calibrated arena: the scenario at the first budget).
    pub exp: &'a Experiment,
    pub summary: &'a Summary,
    /// The scenario text as run.
    pub scenario_text: &'a str,
    /// Every scheme ran alone (calibrated arenas): coins of stream 1 for each.
    pub alone: bool,
    pub arena: Option<&'a Outcome>,
    /// Trials used for the per-step standard errors (at most the run's).
    pub se_trials: usize,
}

/// Escapes text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn html_table(rows: &[Vec<String>]) -> String {
    let mut s = String::from("<table>\n<tr>");
    for h in &rows[0] {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    s.push_str("</tr>\n");
    for r in &rows[1..] {
        s.push_str("<tr>");
        for (i, c) in r.iter().enumerate() {
            let class = if i == 0 { "" } else { " class=\"n\"" };
            let _ = write!(s, "<td{class}>{}</td>", esc(c));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table>\n");
    s
}

/// The report's scheme colours: the first ten of the plots' palette (its black and light
/// orange are kept for fronts and bounds there).
const PALETTE: &[RGBColor] = crate::output::plot::COLORS.split_at(10).0;

fn pe(e: impl std::fmt::Display) -> String {
    format!("plot: {e}")
}

/// The variants shown in the detailed figures: the all-data bound (if any) and the best by
/// mean RMSE of the first group, at most `max` in all.
fn selected(summary: &Summary, max: usize, allowed: &dyn Fn(usize) -> bool) -> Vec<usize> {
    let g = &summary.group_order[0];
    let mut idx: Vec<usize> = (0..summary.schemes.len()).collect();
    idx.sort_by(|&a, &b| {
        let r = |i: usize| summary.schemes[i].mean_rmse[g];
        r(a).total_cmp(&r(b))
    });
    let mut out: Vec<usize> = summary
        .schemes
        .iter()
        .position(|s| s.kind == "centralized-kf")
        .into_iter()
        .collect();
    for i in idx {
        if out.len() >= max {
            break;
        }
        if !out.contains(&i) && allowed(i) && summary.schemes[i].mean_rmse[g].is_finite() {
            out.push(i);
        }
    }
    out
}

/// A figure with a legend to its right, drawn by `body` into the chart.
fn legend(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    names: &[(String, RGBColor)],
) -> Result<(), String> {
    for (i, (n, c)) in names.iter().enumerate() {
        let y = 40 + 18 * i as i32;
        area.draw(&PathElement::new(vec![(8, y), (40, y)], c.stroke_width(2)))
            .map_err(pe)?;
        area.draw(&Text::new(
            n.clone(),
            (48, y - 7),
            ("sans-serif", 13).into_font().color(&BLACK),
        ))
        .map_err(pe)?;
    }
    Ok(())
}

/// Per-step RMSE with +-2 standard-error bands.
fn rmse_bands(input: &Input, sel: &[usize]) -> Result<String, String> {
    let exp = input.exp;
    let (gname, idx) = &exp.groups[0];
    let curves = trace::rmse_with_se(exp, idx, input.se_trials, input.alone)?;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (a, b) = root.split_horizontally(780);
        let ymax = sel
            .iter()
            .flat_map(|&v| {
                curves[v]
                    .0
                    .iter()
                    .zip(&curves[v].1)
                    .map(|(r, s)| r + 2.0 * s)
            })
            .filter(|y| y.is_finite())
            .fold(0.0, f64::max)
            .max(1e-12);
        let mut chart = ChartBuilder::on(&a)
            .caption(
                format!(
                    "RMSE of {gname} per step, ±2 standard errors ({} trials)",
                    input.se_trials
                ),
                ("sans-serif", 17),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(1.0..exp.steps as f64, 0.0..ymax * 1.05)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .x_desc("step k")
            .y_desc(format!("RMSE {gname}"))
            .draw()
            .map_err(pe)?;
        let mut names = Vec::new();
        for (j, &v) in sel.iter().enumerate() {
            let c = PALETTE[j % PALETTE.len()];
            let (r, se) = &curves[v];
            let mut poly: Vec<(f64, f64)> = (0..exp.steps)
                .map(|k| ((k + 1) as f64, r[k] + 2.0 * se[k]))
                .collect();
            poly.extend(
                (0..exp.steps)
                    .rev()
                    .map(|k| ((k + 1) as f64, (r[k] - 2.0 * se[k]).max(0.0))),
            );
            chart
                .draw_series(std::iter::once(Polygon::new(poly, c.mix(0.18).filled())))
                .map_err(pe)?;
            chart
                .draw_series(LineSeries::new(
                    (0..exp.steps).map(|k| ((k + 1) as f64, r[k])),
                    c.stroke_width(2),
                ))
                .map_err(pe)?;
            names.push((input.summary.schemes[v].name.clone(), c));
        }
        // The posterior Cramér–Rao bound: no estimator with every sensor's data is below it.
        if let Some(r) = input.summary.pcrb.as_ref().and_then(|b| b.rmse.get(gname)) {
            let grey = RGBColor(110, 110, 110);
            chart
                .draw_series(DashedLineSeries::new(
                    (0..exp.steps).map(|k| ((k + 1) as f64, r[k])),
                    6,
                    4,
                    grey.stroke_width(2),
                ))
                .map_err(pe)?;
            names.push(("PCRB (all data, any estimator; dashed)".into(), grey));
        }
        legend(&b, &names)?;
        root.present().map_err(pe)?;
    }
    Ok(buf)
}

/// 2-sigma ellipse of a 2x2 covariance around a centre, as a closed polyline.
fn ellipse(c: (f64, f64), p: [[f64; 2]; 2]) -> Vec<(f64, f64)> {
    let (a, b, d) = (p[0][0], p[0][1], p[1][1]);
    let tr = 0.5 * (a + d);
    let disc = (0.25 * (a - d).powi(2) + b * b).sqrt();
    let (l1, l2) = ((tr + disc).max(0.0), (tr - disc).max(0.0));
    let th = 0.5 * (2.0 * b).atan2(a - d);
    (0..=40)
        .map(|i| {
            let t = i as f64 / 40.0 * std::f64::consts::TAU;
            let (u, v) = (2.0 * l1.sqrt() * t.cos(), 2.0 * l2.sqrt() * t.sin());
            (
                c.0 + u * th.cos() - v * th.sin(),
                c.1 + u * th.sin() + v * th.cos(),
            )
        })
        .collect()
}

/// Trial 0: truth, estimates with 2-sigma ellipses (2-D position groups) or bands (1-D),
/// and the sensor positions.
fn trajectory(input: &Input, tr: &trace::Trace, sel: &[usize]) -> Result<String, String> {
    let exp = input.exp;
    // A two-index group (a position) when there is one, else the first group.
    let (gname, idx) = exp
        .groups
        .iter()
        .find(|(_, i)| i.len() == 2)
        .unwrap_or(&exp.groups[0]);
    let mut buf = String::new();
    let positions: Vec<[f64; 2]> = exp
        .system
        .sensors
        .iter()
        .filter_map(|s| s.position())
        .collect();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 620)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (a, b) = root.split_horizontally(780);
        let mut names = vec![("truth".to_string(), BLACK)];
        let every = (exp.steps / 10).max(1);
        if idx.len() == 2 {
            trajectory_2d(
                input, tr, sel, &a, gname, idx, &positions, every, &mut names,
            )?;
        } else {
            trajectory_1d(input, tr, sel, &a, gname, idx, &mut names)?;
        }
        legend(&b, &names)?;
        root.present().map_err(pe)?;
    }
    Ok(buf)
}

/// The 2-D panel of [`trajectory`]: the position group `idx` (two indices) of trial 0, truth
/// and estimates in the plane with 2σ ellipses every `every` steps, the sensors in the frame.
#[allow(clippy::too_many_arguments)]
fn trajectory_2d(
    input: &Input,
    tr: &trace::Trace,
    sel: &[usize],
    a: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    gname: &str,
    idx: &[usize],
    positions: &[[f64; 2]],
    every: usize,
    names: &mut Vec<(String, RGBColor)>,
) -> Result<(), String> {
    let (ix, iy) = (idx[0], idx[1]);
    let mut pts: Vec<(f64, f64)> = tr.truth.iter().map(|x| (x[ix], x[iy])).collect();
    for &v in sel {
        pts.extend(
            tr.variants[v]
                .estimates
                .iter()
                .map(|e| (e.mean[ix], e.mean[iy])),
        );
    }
    let finite: Vec<(f64, f64)> = pts
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = finite.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
    );
    // Zoom on the track (with a margin of a quarter of its extent); sensors inside
    // the frame are drawn, the others are counted in the legend.
    let (mx, my) = (0.25 * (x1 - x0).max(1e-9), 0.25 * (y1 - y0).max(1e-9));
    let m = mx.max(my);
    (x0, x1, y0, y1) = (x0 - m, x1 + m, y0 - m, y1 + m);
    let shown: Vec<[f64; 2]> = positions
        .iter()
        .copied()
        .filter(|p| p[0] >= x0 && p[0] <= x1 && p[1] >= y0 && p[1] <= y1)
        .collect();
    let hidden = positions.len() - shown.len();
    let positions = shown;
    let (px, py) = (0.0, 0.0);
    let mut chart = ChartBuilder::on(a)
        .caption(
            format!("trial 0: {gname}, estimates with 2σ ellipses every {every} steps"),
            ("sans-serif", 17),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0 - px..x1 + px, y0 - py..y1 + py)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .x_desc(format!("state {ix}"))
        .y_desc(format!("state {iy}"))
        .draw()
        .map_err(pe)?;
    if !positions.is_empty() || hidden > 0 {
        chart
            .draw_series(
                positions
                    .iter()
                    .map(|p| TriangleMarker::new((p[0], p[1]), 6, BLACK.mix(0.6).filled())),
            )
            .map_err(pe)?;
        names.push((
            if hidden > 0 {
                format!("sensor positions (▲; {hidden} outside the frame)")
            } else {
                "sensor positions (▲)".into()
            },
            RGBColor(110, 110, 110),
        ));
    }
    chart
        .draw_series(LineSeries::new(
            tr.truth.iter().map(|x| (x[ix], x[iy])),
            BLACK.stroke_width(3),
        ))
        .map_err(pe)?;
    for (j, &v) in sel.iter().enumerate() {
        let c = PALETTE[j % PALETTE.len()];
        let est = &tr.variants[v].estimates;
        chart
            .draw_series(LineSeries::new(
                est.iter().map(|e| (e.mean[ix], e.mean[iy])),
                c.stroke_width(2),
            ))
            .map_err(pe)?;
        for e in est.iter().skip(every - 1).step_by(every) {
            let p = [
                [e.cov[(ix, ix)], e.cov[(ix, iy)]],
                [e.cov[(iy, ix)], e.cov[(iy, iy)]],
            ];
            chart
                .draw_series(std::iter::once(PathElement::new(
                    ellipse((e.mean[ix], e.mean[iy]), p),
                    c.stroke_width(1),
                )))
                .map_err(pe)?;
        }
        names.push((input.summary.schemes[v].name.clone(), c));
    }
    Ok(())
}

/// The 1-D panel of [`trajectory`]: estimate minus truth of the first index of `idx` over
/// the steps of trial 0, with ±2σ bands.
fn trajectory_1d(
    input: &Input,
    tr: &trace::Trace,
    sel: &[usize],
    a: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    gname: &str,
    idx: &[usize],
    names: &mut Vec<(String, RGBColor)>,
) -> Result<(), String> {
    let exp = input.exp;
    let i = idx[0];
    let t = exp.steps as f64;
    // Estimates minus the truth, so that small errors stay visible on a long track.
    let truth: Vec<f64> = tr.truth.iter().map(|x| x[i]).collect();
    let mut ys: Vec<f64> = vec![0.0];
    for &v in sel {
        ys.extend(
            tr.variants[v]
                .estimates
                .iter()
                .zip(&truth)
                .flat_map(|(e, x)| {
                    let s = 2.0 * e.cov[(i, i)].max(0.0).sqrt();
                    [e.mean[i] - x - s, e.mean[i] - x + s]
                }),
        );
    }
    let ys: Vec<f64> = ys.into_iter().filter(|y| y.is_finite()).collect();
    let (y0, y1) = ys
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
            (a.min(*y), b.max(*y))
        });
    let pad = 0.05 * (y1 - y0).max(1e-9);
    let mut chart = ChartBuilder::on(a)
        .caption(
            format!("trial 0: estimate − truth of state {i} ({gname}), ±2σ (truth = 0)"),
            ("sans-serif", 17),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(1.0..t, y0 - pad..y1 + pad)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .x_desc("step k")
        .y_desc(format!("error of state {i}"))
        .draw()
        .map_err(pe)?;
    for (j, &v) in sel.iter().enumerate() {
        let c = PALETTE[j % PALETTE.len()];
        let est = &tr.variants[v].estimates;
        let mut poly: Vec<(f64, f64)> = est
            .iter()
            .enumerate()
            .map(|(k, e)| {
                (
                    (k + 1) as f64,
                    e.mean[i] - truth[k] + 2.0 * e.cov[(i, i)].max(0.0).sqrt(),
                )
            })
            .collect();
        poly.extend(est.iter().enumerate().rev().map(|(k, e)| {
            (
                (k + 1) as f64,
                e.mean[i] - truth[k] - 2.0 * e.cov[(i, i)].max(0.0).sqrt(),
            )
        }));
        chart
            .draw_series(std::iter::once(Polygon::new(poly, c.mix(0.12).filled())))
            .map_err(pe)?;
        chart
            .draw_series(LineSeries::new(
                est.iter()
                    .enumerate()
                    .map(|(k, e)| ((k + 1) as f64, e.mean[i] - truth[k])),
                c.stroke_width(2),
            ))
            .map_err(pe)?;
        names.push((input.summary.schemes[v].name.clone(), c));
    }
    chart
        .draw_series(LineSeries::new(
            (1..=exp.steps).map(|k| (k as f64, 0.0)),
            BLACK.stroke_width(3),
        ))
        .map_err(pe)?;
    Ok(())
}

#[allow(clippy::needless_range_loop)] // i indexes sensors across the per-step rows
/// Per selected scheme, a row per sensor and a cell per step: sent, silent, not scheduled, and
/// with a lossy link lost or late.
fn timeline(input: &Input, tr: &trace::Trace, sel: &[usize]) -> String {
    let steps = input.exp.steps;
    let n = input.exp.system.n_sensors();
    let cw = (900.0 / steps as f64).clamp(0.5, 8.0);
    let rh = (160.0 / n as f64).clamp(2.0, 12.0);
    let left = 230.0;
    let block = 22.0 + rh * n as f64 + 10.0;
    // Wide enough for the legend line even when there are few steps.
    let width = (left + cw * steps as f64 + 20.0).max(left + 560.0);
    let height = 40.0 + block * sel.len() as f64;
    let lossy = input.exp.variants.iter().any(|v| v.channel.is_some());
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    let _ = writeln!(
        s,
        "<rect x=\"{left}\" y=\"8\" width=\"12\" height=\"12\" fill=\"#1f77b4\"/><text x=\"{}\" y=\"18\">sent</text><rect x=\"{}\" y=\"8\" width=\"12\" height=\"12\" fill=\"#d9d9d9\"/><text x=\"{}\" y=\"18\">silent</text><rect x=\"{}\" y=\"8\" width=\"12\" height=\"12\" fill=\"#ffffff\" stroke=\"#999\"/><text x=\"{}\" y=\"18\">not scheduled</text><text x=\"{}\" y=\"18\">steps 1..{steps}, one row per sensor</text>",
        left + 16.0, left + 60.0, left + 76.0, left + 130.0, left + 146.0,
        // With a lossy link the legend has one more entry, and the note moves right.
        left + if lossy { 350.0 } else { 260.0 }
    );
    if lossy {
        let _ = writeln!(
            s,
            r##"<rect x="{}" y="8" width="12" height="12" fill="#d62728"/><text x="{}" y="18">lost / late</text>"##,
            left + 250.0,
            left + 266.0
        );
    }
    for (j, &v) in sel.iter().enumerate() {
        let y0 = 36.0 + block * j as f64;
        let _ = writeln!(
            s,
            "<text x=\"4\" y=\"{:.1}\" font-weight=\"bold\">{}</text>",
            y0 + 12.0,
            esc(&input.summary.schemes[v].name)
        );
        let links = &tr.variants[v].links;
        for i in 0..n {
            let y = y0 + 20.0 + rh * i as f64;
            if n <= 12 {
                let _ = writeln!(s, "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"end\">sensor {}</text>", left - 4.0, y + rh - 1.0, i + 1);
            }
            let _ = writeln!(
                s,
                "<rect x=\"{left}\" y=\"{y:.1}\" width=\"{:.1}\" height=\"{rh:.1}\" fill=\"#ffffff\" stroke=\"#bbb\" stroke-width=\"0.3\"/>",
                cw * steps as f64
            );
            // Runs of equal status as one rectangle each.
            let mut k = 0;
            while k < steps {
                let st = links[k][i];
                let mut e = k + 1;
                while e < steps && links[e][i] == st {
                    e += 1;
                }
                let fill = match st {
                    Link::Sent => Some("#1f77b4"),
                    Link::Silent => Some("#d9d9d9"),
                    // Sent, and lost or late on the link: the bits were spent.
                    Link::Lost | Link::Late => Some("#d62728"),
                    Link::NotScheduled => None,
                };
                if let Some(f) = fill {
                    let _ = writeln!(
                        s,
                        "<rect x=\"{:.2}\" y=\"{y:.1}\" width=\"{:.2}\" height=\"{:.1}\" fill=\"{f}\"/>",
                        left + cw * k as f64,
                        cw * (e - k) as f64,
                        (rh - 0.5).max(1.0)
                    );
                }
                k = e;
            }
        }
    }
    s.push_str("</svg>\n");
    s
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1150px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:13px}\
th,td{border:1px solid #ccc;padding:3px 7px}th{background:#f0f0f0;text-align:left}\
td.n{text-align:right;font-variant-numeric:tabular-nums}\
pre{background:#f7f7f7;border:1px solid #ddd;padding:0.7em;overflow:auto;font-size:12px}\
h2{border-bottom:1px solid #ddd;padding-bottom:0.2em;margin-top:1.6em}.meta td{border:none;padding:1px 12px 1px 0}\
figure{margin:0.5em 0}svg{max-width:100%;height:auto}\
ul.warnings{color:#8a3b00;background:#fff6ec;border-left:3px solid #d9822b;padding:0.4em 0.6em 0.4em 2em;font-size:13px}\
ul.warnings+p,p.legend{font-size:13px}";

/// The report as one HTML string.
pub fn render(input: &Input) -> Result<String, String> {
    let s = input.summary;
    let exp = input.exp;
    let group = &s.group_order[0];
    let mut h = String::new();
    header(&mut h, input);
    if let Some(out) = input.arena {
        arena_section(&mut h, out, group)?;
    }
    results_section(&mut h, input);
    if let Some(svg) = crate::output::network_map::map_svg(exp, s) {
        let _ = writeln!(h, "<h2>The network</h2>\n<p>Every node at its place, filled by its radio's energy per step; dark links carry the routes to the sink (the square); the node circled in red dies first; &ldquo;relays sum&rdquo;: the relays added that scheme's reports into one frame per link. Per node and per step figures are in <code>summary.json</code> (<code>network.nodes</code>).</p>\n<figure>{}</figure>", svg?);
    }
    if input.arena.is_none() {
        if let Some(svg) = crate::output::energy_front::svg(exp, s) {
            let _ = writeln!(h, "<h2>Error against the network's energy</h2>\n<p>Every scheme at its network radio energy per step (every battery-powered node; a sink on mains left out) and its mean RMSE of {}, as written (no knob calibrated: <code>--budgets</code> calibrates them to equal energy); the dashed black line is the Pareto front, the dashed grey one the all-data bound.</p>\n<figure>{}</figure>", esc(group), svg?);
        }
    }
    let within = |i: usize| {
        input.arena.is_none_or(|o| {
            let c = &o.rows[0][i];
            c.status == crate::engine::calibrate::Status::Calibrated
                || c.achieved <= c.target * (1.0 + o.tolerance)
        })
    };
    let sel = selected(s, 6, &within);
    let _ = writeln!(h, "<h2>Per-step error</h2>\n<p>The all-data bound and the best schemes by mean RMSE of {}{}; bands: ±2 standard errors of the RMSE (delta method on the per-trial squared errors).</p>", esc(group), if input.arena.is_some() { " among those within the first budget" } else { "" });
    let _ = writeln!(h, "<figure>{}</figure>", rmse_bands(input, &sel)?);
    let tr = trace::trace(exp, 0, input.alone)?;
    let _ = writeln!(
        h,
        "<h2>One trial</h2>\n<figure>{}</figure>",
        trajectory(input, &tr, &sel)?
    );
    let _ = writeln!(
        h,
        "<h3>Who sent when (trial 0)</h3>\n<figure>{}</figure>",
        timeline(input, &tr, &sel)
    );
    let _ = writeln!(
        h,
        "<h2>The scenario as run</h2>\n<pre>{}</pre>",
        esc(input.scenario_text)
    );
    h.push_str("</body></html>\n");
    Ok(h)
}

/// The page head and the run's title, description and metadata table.
fn header(h: &mut String, input: &Input) {
    let s = input.summary;
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>hushfuse report: {}</title><style>{STYLE}</style></head><body>\n",
        esc(&s.scenario)
    );
    let _ = writeln!(
        h,
        "<h1>{}</h1>\n<p>{}</p>",
        esc(&s.scenario),
        esc(&s.description)
    );
    let _ = writeln!(
        h,
        "<table class=\"meta\"><tr><td>hushfuse</td><td>{}</td></tr><tr><td>source</td><td>{}</td></tr><tr><td>seed</td><td>{} (trial t draws truth and measurements from stream (seed, t, 0); scheme v its coins from (seed, t, 1 + v){})</td></tr><tr><td>trials x steps</td><td>{} x {}</td></tr><tr><td>sensors, state dimension</td><td>{}, {}</td></tr></table>",
        env!("CARGO_PKG_VERSION"),
        esc(&s.source),
        s.seed,
        if input.alone { "; here every scheme ran alone, v = 0" } else { "" },
        s.trials,
        s.steps,
        s.sensors,
        s.state_dim
    );
    if let Some(sec) = &s.security {
        let _ = writeln!(
            h,
            "<p class=\"legend\">802.15.4 security: level {} (key identifier mode {}), feedback {}. Every data frame carries {} more octets (auxiliary security header and MIC){}: the frame bits and energy below include them; payload bits and estimates are those of the unsecured run.</p>",
            esc(sec.level.name()),
            esc(sec.key_id_mode.name()),
            if sec.secure_feedback { "secured" } else { "in clear" },
            sec.overhead_octets(),
            if sec.secure_feedback { ", and so does each step's feedback frame" } else { "" },
        );
    }
}

/// The calibrated arena's section: the best scheme per budget, accuracy and ANEES against bits,
/// the calibration table of every budget.
fn arena_section(h: &mut String, out: &Outcome, group: &str) -> Result<(), String> {
    let _ = writeln!(h, "<h2>Best scheme per budget</h2>\n<p>Every scheme's bandwidth knob tuned so that it spends the budget in {} per step (pilot runs on common random numbers, tolerance {}%); schemes without a knob count at budgets they fit.</p>", out.axis.unit(), short(100.0 * out.tolerance));
    h.push_str(&html_table(&arena::best_per_budget(out, group)));
    if let Some(line) = arena::diverged_legend(out, group) {
        let _ = writeln!(h, "<p class=\"legend\">{}</p>", esc(&line));
    }
    let x = format!("{} per step (achieved)", out.axis.unit());
    let g = group.to_string();
    let svg = plot::lines_svg(
        &format!("mean RMSE of {group} against {}", out.axis.unit()),
        &x,
        &format!("mean RMSE {group}"),
        &arena::bits_lines(
            out,
            &|c| c.result.mean_rmse.get(&g).copied().unwrap_or(f64::NAN),
            true,
        ),
    )?;
    let _ = writeln!(
        h,
        "<h2>Accuracy against {}</h2>\n<figure>{svg}</figure>",
        out.axis.unit()
    );
    let svg = plot::lines_svg(
        &format!("ANEES against {} (1 = consistent)", out.axis.unit()),
        &x,
        "ANEES",
        &arena::bits_lines(out, &|c| c.result.anees, false),
    )?;
    let _ = writeln!(h, "<figure>{svg}</figure>");
    floor_figure(h, out)?;
    let _ = writeln!(h, "<h2>Calibration</h2>");
    for (b, row) in out.rows.iter().enumerate() {
        let mut head = vec!["scheme".to_string(), "knob".into(), "status".into()];
        head.extend(arena::spend_headers());
        head.extend(
            [
                format!("mean RMSE {group}").as_str(),
                "MSE(ss)",
                "±se",
                "floor",
                "ANEES",
                "NEES<95%",
                "NEES<99%",
                "diverged",
            ]
            .map(String::from),
        );
        let mut rows = vec![head];
        for c in row {
            let r = &c.result;
            let mut cells = vec![
                c.label.clone(),
                match (&c.knob, c.value) {
                    (Some(k), Some(v)) => format!("{k} = {}", short(v)),
                    _ => "—".into(),
                },
                c.status_text(),
            ];
            cells.extend(arena::spend_cells(r));
            cells.extend([
                format!("{:.4}", r.mean_rmse[group]),
                format!("{:.4}", r.steady_state.mse),
                format!("{:.4}", r.steady_state.mse_se),
                r.floor_mse.map_or("—".into(), |f| format!("{f:.4}")),
                crate::metrics::results::num(r.anees, 3),
                format!("{:.3}", r.nees_coverage_95),
                format!("{:.3}", r.nees_coverage_99),
                format!("{:.1}%", 100.0 * r.diverged_fraction),
            ]);
            rows.push(cells);
        }
        let _ = writeln!(
            h,
            "<h3>budget {} {} per step</h3>",
            short(out.budgets[b]),
            out.axis.unit()
        );
        h.push_str(&html_table(&rows));
        // Each budget's health under its table, as the terminal prints it under the same table.
        warnings_list(h, 4, &crate::metrics::results::warnings(&out.summaries[b]));
    }
    let _ = writeln!(h, "<p>NEES&lt;95%, NEES&lt;99%: share of steps whose NEES lies below the chi-square quantile (a consistent filter: 0.95, 0.99); diverged: share of trials whose NEES stayed above the 99.9% quantile for {} steps in a row.</p>", crate::metrics::DIVERGENCE_RUN);
    Ok(())
}

/// The rate–distortion figure of the arena, or why there is none.
fn floor_figure(h: &mut String, out: &Outcome) -> Result<(), String> {
    let _ = writeln!(h, "<h2>Accuracy against the rate-distortion floor</h2>");
    match arena::floor_lines(out) {
        Some(lines) => {
            let svg = plot::lines_svg(arena::FLOOR_TITLE, arena::FLOOR_X, arena::FLOOR_Y, &lines)?;
            let _ = writeln!(h, "<p>Each scheme's steady-state MSE at each budget against its entropy-coded rate R_eff (the entropy of each sensor's send-or-silence decision plus its payload, bits per step), and the sequential rate-distortion floor of the system with every sensor: no causal scheme spending R_eff bits per step has a lower MSE (Tatikonda, Sahai, Mitter; Tanaka et al.). The floor meets the all-data bound as the rate grows.</p>\n<figure>{svg}</figure>");
        }
        None => {
            let why = out
                .summaries
                .first()
                .and_then(|s| s.rate_distortion_floor_note.clone())
                .unwrap_or_else(|| "not computed".into());
            let _ = writeln!(h, "<p>No floor for this scenario: {}.</p>", esc(&why));
        }
    }
    Ok(())
}

/// The results table: every scheme's mean RMSE per group, steady-state MSE, ANEES, rate and
/// bits, and the all-data bound when there is one.
fn results_section(h: &mut String, input: &Input) {
    let s = input.summary;
    let _ = writeln!(
        h,
        "<h2>Results{}</h2>",
        if input.arena.is_some() {
            format!(
                " at the first budget ({} bits per step)",
                short(input.arena.map_or(0.0, |o| o.budgets[0]))
            )
        } else {
            String::new()
        }
    );
    let mut rows = vec![vec!["scheme".to_string(), "params".into()]];
    rows[0].extend(s.group_order.iter().map(|g| format!("mean RMSE {g}")));
    rows[0].extend(
        [
            "MSE(ss)",
            "±se",
            "ANEES",
            "NEES<95%",
            "NEES<99%",
            "diverged",
            "rate",
            "payload bits/step",
            "frame bits/step",
            "downlink bits/step",
            "µJ/step",
            "R_eff bits/step",
            "floor MSE(ss)",
        ]
        .map(String::from),
    );
    // With a link: what it lost, so a row's accuracy can be read against its losses.
    let with_link = s.schemes.iter().any(|r| r.link.is_some());
    if with_link {
        rows[0].push("lost/step".into());
    }
    for r in &s.schemes {
        let mut row = vec![r.name.clone(), params_text(&r.params)];
        row.extend(
            s.group_order
                .iter()
                .map(|g| format!("{:.4}", r.mean_rmse[g])),
        );
        row.extend([
            format!("{:.4}", r.steady_state.mse),
            format!("{:.4}", r.steady_state.mse_se),
            crate::metrics::results::num(r.anees, 3),
            format!("{:.3}", r.nees_coverage_95),
            format!("{:.3}", r.nees_coverage_99),
            format!("{:.1}%", 100.0 * r.diverged_fraction),
            format!("{:.3}", r.rate),
            format!("{:.1}", r.bits_per_step),
            format!("{:.1}", r.frame_bits_per_step),
            format!("{:.1}", r.downlink_bits_per_step),
            format!("{:.1}", r.energy.energy_per_step_uj),
            format!("{:.1}", r.r_eff_per_step),
            r.floor_mse.map_or("—".into(), |f| format!("{f:.4}")),
        ]);
        if with_link {
            row.push(
                r.link
                    .as_ref()
                    .map_or("—".into(), |l| format!("{:.2}", l.lost)),
            );
        }
        rows.push(row);
    }
    if let Some(b) = &s.pcrb {
        let mut row = vec![
            "Posterior Cramér–Rao bound (all data, any estimator)".to_string(),
            String::new(),
        ];
        row.extend(s.group_order.iter().map(|g| {
            b.mean_rmse
                .get(g)
                .map_or(String::new(), |r| format!("{r:.4}"))
        }));
        row.push(format!("{:.4}", b.steady_mse));
        row.resize(rows[0].len(), String::new());
        rows.push(row);
    }
    h.push_str(&html_table(&rows));
    let _ = writeln!(h, "<p>NEES&lt;95%, NEES&lt;99%: share of steps whose NEES lies below the chi-square quantile (a consistent filter: 0.95, 0.99); diverged: share of trials whose NEES stayed above the 99.9% quantile for {} steps in a row.</p>", crate::metrics::DIVERGENCE_RUN);
    warnings_list(h, 3, &crate::metrics::results::warnings(s));
    super::notes::list(h, &crate::metrics::notes::lines(s), esc);
}

/// A "Warnings" heading (`<h{level}>`: under the section it belongs to) and one item per
/// warning ([`crate::metrics::results::warnings`]); nothing when there are none.
fn warnings_list(h: &mut String, level: u8, warnings: &[String]) {
    if !warnings.is_empty() {
        let _ = writeln!(h, "<h{level}>Warnings</h{level}>\n<ul class=\"warnings\">");
        for w in warnings {
            let _ = writeln!(h, "<li>{}</li>", esc(w));
        }
        h.push_str("</ul>\n");
    }
}

/// Whether an HTML text refers to anything outside itself: `src=` or `href=` attributes (any
/// value but an in-page `#anchor`), `@import`, `url(` other than `url(#...)`, or `<link`.
pub fn external_references(html: &str) -> Vec<String> {
    let lower = html.to_ascii_lowercase();
    let mut bad = Vec::new();
    for pat in [
        "src=", "href=", "@import", "url(", "<link", "<script", "<iframe", "<img", "<object",
        "<embed",
    ] {
        let mut from = 0;
        while let Some(i) = lower[from..].find(pat) {
            let at = from + i;
            let rest = &lower[at + pat.len()..];
            let rest = rest.trim_start_matches(['"', '\'', ' ']);
            let in_page = (pat.ends_with('=') || pat == "url(") && rest.starts_with('#');
            if !in_page {
                bad.push(html[at..(at + 60).min(html.len())].to_string());
            }
            from = at + pat.len();
        }
    }
    bad
}
