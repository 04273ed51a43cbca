//! SVG figures: RMSE per step per scheme, and steady-state MSE (solid) and trace (dashed)
//! against the communication rate, the layout of Dormann et al.'s Fig. 1.
use crate::metrics::results::{curve_points, Summary};
use crate::scenario::build::Experiment;
use plotters::prelude::*;
use std::path::Path;

/// The line colours, in order (shared with the report).
pub(super) const COLORS: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
    RGBColor(0, 0, 0),
    RGBColor(255, 187, 120),
];

fn color(i: usize) -> RGBColor {
    COLORS[i % COLORS.len()]
}

/// Tick values of a log axis over [lo, hi]: 1, 2 and 5 times every power of ten in range (also
/// 3 and 4, 6 to 9 when the range spans little more than a decade), so that every decade is labelled,
/// those above 10 and below 1 included (plotters' own log key points skip them).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let decades = (hi / lo).log10();
    let mantissas: &[f64] = if decades < 1.2 {
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    } else {
        &[1.0, 2.0, 5.0]
    };
    let mut ticks = Vec::new();
    for e in lo.log10().floor() as i32..=hi.log10().ceil() as i32 {
        for m in mantissas {
            // Divided for negative powers: 6 / 10 is 0.6, 6 * 0.1 is not.
            let v = if e < 0 {
                m / 10f64.powi(-e)
            } else {
                m * 10f64.powi(e)
            };
            if v >= lo && v <= hi {
                ticks.push(v);
            }
        }
    }
    ticks
}

/// A tick label: up to four significant digits without trailing zeros ("0.5", "20", "0.025"),
/// powers of ten beyond 1e5 or below 1e-3 ("1e6").
fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.0e}");
    }
    let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

fn plot_err(e: impl std::fmt::Display) -> String {
    format!("plot: {e}")
}

/// A named line of (x, y) points.
#[derive(Debug, Clone)]
pub struct Line {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub dashed: bool,
    pub color: usize,
    /// Draw a marker at every point (a line of one point is always drawn as a marker).
    pub markers: bool,
}

/// Marker shape of a color index: circles for the first palette round, then triangles, then
/// squares, so that more than 12 series stay distinguishable.
fn shape(i: usize) -> usize {
    (i / COLORS.len()) % 3
}

/// Draws lines into an SVG file with a log-scale y axis when the data span more than a decade.
/// The legend sits to the right of the plot (it never hides data); dashed lines are dashed in
/// the legend too, and markers appear there as well.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    data: &[Line],
) -> Result<(), String> {
    let svg = lines_svg(title, x_label, y_label, data)?;
    crate::output::write_file(path, svg.as_bytes()).map_err(|e| format!("plot: {e}"))
}

/// [`lines`] into a string (for inline SVG in `report.html`).
pub fn lines_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    data: &[Line],
) -> Result<String, String> {
    let all: Vec<(f64, f64)> = data
        .iter()
        .flat_map(|l| l.points.iter().copied())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    if all.is_empty() {
        return Err("plot: nothing to draw".into());
    }
    let (mut x0, mut x1) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
    if x1 - x0 < 1e-12 {
        x0 -= 0.5;
        x1 += 0.5;
    }
    let pad = 0.03 * (x1 - x0);
    let (x0, x1) = (x0 - pad, x1 + pad);
    let positive: Vec<f64> = all.iter().map(|p| p.1).filter(|y| *y > 0.0).collect();
    let y0 = positive.iter().copied().fold(f64::INFINITY, f64::min);
    let y1 = positive.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let log = y0.is_finite() && y1 / y0 > 10.0;
    let legend_w = 330u32;
    let height = 560u32.max(60 + 18 * data.len() as u32);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (780 + legend_w, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (plot_area, legend_area) = root.split_horizontally(780);
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                // On a log axis plotters draws a light line at every tenth of a decade, which
                // renders as a grey band at the top of each decade: only the bold lines stay.
                let light = if log {
                    RGBColor(255, 255, 255)
                } else {
                    RGBColor(242, 242, 242)
                };
                chart
                    .configure_mesh()
                    .light_line_style(light)
                    .y_labels(12)
                    .y_label_formatter(&|v| tick_label(*v))
                    .x_desc(x_label)
                    .y_desc(y_label)
                    .draw()
                    .map_err(plot_err)?;
                for l in data {
                    let c = color(l.color);
                    let pts: Vec<(f64, f64)> = l
                        .points
                        .iter()
                        .copied()
                        .filter(|(x, y)| x.is_finite() && y.is_finite() && (!log || *y > 0.0))
                        .collect();
                    if l.dashed {
                        chart
                            .draw_series(DashedLineSeries::new(
                                pts.clone(),
                                6,
                                4,
                                c.stroke_width(2),
                            ))
                            .map_err(plot_err)?;
                    } else if pts.len() > 1 {
                        chart
                            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                            .map_err(plot_err)?;
                    }
                    if l.markers || pts.len() == 1 {
                        let sh = shape(l.color);
                        match sh {
                            0 => chart
                                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))
                                .map_err(plot_err)?,
                            1 => chart
                                .draw_series(
                                    pts.iter().map(|&p| TriangleMarker::new(p, 5, c.filled())),
                                )
                                .map_err(plot_err)?,
                            _ => chart
                                .draw_series(
                                    pts.iter().map(|&p| Cross::new(p, 4, c.stroke_width(2))),
                                )
                                .map_err(plot_err)?,
                        };
                    }
                }
            }};
        }
        let mut builder = ChartBuilder::on(&plot_area);
        builder
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70);
        if log {
            let (lo, hi) = (y0 * 0.8, y1 * 1.25);
            draw!(builder
                .build_cartesian_2d(
                    x0..x1,
                    (lo..hi).log_scale().with_key_points(log_ticks(lo, hi))
                )
                .map_err(plot_err)?);
        } else {
            let ymax = all.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
            let ymin = all
                .iter()
                .map(|p| p.1)
                .fold(f64::INFINITY, f64::min)
                .min(0.0);
            draw!(builder
                .build_cartesian_2d(x0..x1, ymin..(ymax * 1.1).max(ymin + 1e-12))
                .map_err(plot_err)?);
        }
        draw_legend(&legend_area, data)?;
        root.present().map_err(plot_err)?;
    }
    Ok(buf)
}

/// The legend of [`lines_svg`] in its area right of the plot.
fn draw_legend(
    legend_area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    data: &[Line],
) -> Result<(), String> {
    // The legend: a sample of each line (dashed when dashed, with its marker), then its name.
    for (i, l) in data.iter().enumerate() {
        let c = color(l.color);
        let y = 40 + 18 * i as i32;
        let (xa, xb) = (8, 40);
        if l.dashed {
            for seg in 0..3 {
                let s0 = xa + seg * 12;
                legend_area
                    .draw(&PathElement::new(
                        vec![(s0, y), (s0 + 7, y)],
                        c.stroke_width(2),
                    ))
                    .map_err(plot_err)?;
            }
        } else if l.points.len() > 1 {
            legend_area
                .draw(&PathElement::new(vec![(xa, y), (xb, y)], c.stroke_width(2)))
                .map_err(plot_err)?;
        }
        if l.markers || l.points.len() == 1 {
            let p = (24, y);
            match shape(l.color) {
                0 => legend_area.draw(&Circle::new(p, 4, c.filled())),
                1 => legend_area.draw(&TriangleMarker::new(p, 5, c.filled())),
                _ => legend_area.draw(&Cross::new(p, 4, c.stroke_width(2))),
            }
            .map_err(plot_err)?;
        }
        legend_area
            .draw(&Text::new(
                l.name.clone(),
                (48, y - 7),
                ("sans-serif", 13).into_font().color(&BLACK),
            ))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// Writes the figures of a run into `dir`; returns the files written.
pub fn write_all(exp: &Experiment, summary: &Summary, dir: &Path) -> Result<Vec<String>, String> {
    let mut written = Vec::new();
    for group in &summary.group_order {
        per_step(exp, summary, dir, group, &mut written)?;
    }
    // Steady state against the communication rate, when any scheme is swept.
    if exp.curves.iter().any(|c| !c.swept.is_empty()) {
        let mut data = Vec::new();
        for (ci, curve) in exp.curves.iter().enumerate() {
            let pts = curve_points(exp, summary, ci);
            data.push(Line {
                name: format!("{} MSE", curve.label),
                points: pts.iter().map(|p| (p.rate, p.mse)).collect(),
                dashed: false,
                color: ci,
                markers: true,
            });
            data.push(Line {
                name: format!("{} trace", curve.label),
                points: pts.iter().map(|p| (p.rate, p.trace)).collect(),
                dashed: true,
                color: ci,
                markers: true,
            });
        }
        let f = "mse_trace_vs_rate.svg".to_string();
        lines(
            &dir.join(&f),
            &format!(
                "{}: steady-state MSE (solid) and trace (dashed)",
                summary.scenario
            ),
            "communication rate",
            "MSE / trace of covariance",
            &data,
        )?;
        written.push(f);
    }
    if let Some(f) = stability(exp, summary, dir)? {
        written.push(f);
    }
    Ok(written)
}

/// Sequences of the independent recursion drawn for the stability figure.
const STABILITY_SEQUENCES: usize = 5000;

/// `stability.svg`, for a scenario with an `intermittent` claim: the steady-state error variance
/// of its curve (our trace and MSE, the independent recursion's mean) against the arrival rate γ
/// (or p_bg), on a log axis, with the critical value as a vertical line and Sinopoli's bounds
/// (posterior equivalents) as curves where they are finite. Below the critical value the points
/// are sample means of a variable without a mean: finite, and set by the longest loss run drawn.
fn stability(exp: &Experiment, summary: &Summary, dir: &Path) -> Result<Option<String>, String> {
    use crate::output::report::intermittent as im;
    use crate::scenario::intermittent::{Arrivals, ScalarModel};
    let Some(scheme) = exp
        .paper
        .iter()
        .flat_map(|p| &p.claims)
        .find_map(|c| match c {
            crate::scenario::ClaimSpec::Intermittent { scheme, .. } => Some(scheme),
            _ => None,
        })
    else {
        return Ok(None);
    };
    let (Ok(m), Ok(pts)) = (
        ScalarModel::of(&exp.system),
        im::points(exp, summary, scheme),
    ) else {
        return Ok(None);
    };
    let Some(first) = pts.first() else {
        return Ok(None);
    };
    let bernoulli = matches!(first.arrivals, Arrivals::Bernoulli { .. });
    let x_name = if bernoulli {
        "arrival rate γ"
    } else {
        "p_bg (bad → good)"
    };
    let mut ours = Vec::new();
    let mut mse = Vec::new();
    let mut recursion = Vec::new();
    for p in &pts {
        let x = p.arrivals.abscissa();
        ours.push((x, p.summary.steady_state.trace));
        mse.push((x, p.summary.steady_state.mse));
        let sim = im::simulate_variant(exp, &m, p, STABILITY_SEQUENCES);
        recursion.push((x, im::mean_se(&sim.trace).0));
    }
    let all_y = ours.iter().chain(&mse).chain(&recursion).map(|p| p.1);
    let (y_lo, y_hi) = all_y.fold((f64::INFINITY, 0.0f64), |(a, b), y| (a.min(y), b.max(y)));
    let critical = crate::network::channel::stability::critical_arrival_rate(m.a);
    let mut data = vec![
        Line {
            name: format!("{scheme}: steady-state trace P(k|k)"),
            points: ours,
            dashed: false,
            color: 0,
            markers: true,
        },
        Line {
            name: format!("{scheme}: steady-state MSE"),
            points: mse,
            dashed: false,
            color: 2,
            markers: true,
        },
        Line {
            name: format!("independent recursion ({STABILITY_SEQUENCES} sequences)"),
            points: recursion,
            dashed: true,
            color: 1,
            markers: true,
        },
    ];
    if bernoulli {
        // The bounds on a fine grid from γ_c to the largest γ run, cut where they leave the
        // decades of the data (the lower bound falls to 0 at γ = 1).
        let x_hi = pts
            .iter()
            .map(|p| p.arrivals.abscissa())
            .fold(critical, f64::max);
        let grid: Vec<f64> = (1..=400)
            .map(|i| critical + (x_hi - critical) * i as f64 / 400.0)
            .collect();
        let curve = |upper: bool| -> Vec<(f64, f64)> {
            grid.iter()
                .filter_map(|&g| {
                    let (lo, hi) = im::posterior_bounds(&m, g);
                    let v = if upper { hi } else { lo }?;
                    (v >= y_lo / 3.0 && v <= 10.0 * y_hi).then_some((g, v))
                })
                .collect()
        };
        data.push(Line {
            name: "Sinopoli lower bound (posterior)".into(),
            points: curve(false),
            dashed: true,
            color: 3,
            markers: false,
        });
        data.push(Line {
            name: "Sinopoli upper bound (posterior)".into(),
            points: curve(true),
            dashed: true,
            color: 4,
            markers: false,
        });
    }
    data.push(Line {
        name: format!(
            "critical {} = 1 - 1/a² = {critical:.4}",
            if bernoulli { "γ_c" } else { "p_bg" }
        ),
        points: vec![(critical, 0.5 * y_lo), (critical, 2.0 * y_hi)],
        dashed: false,
        color: 10,
        markers: false,
    });
    let f = "stability.svg".to_string();
    lines(
        &dir.join(&f),
        &format!(
            "{}: steady-state error variance against {x_name} (a = {})",
            summary.scenario, m.a
        ),
        &format!("{x_name} (left of the line: no finite expectation; points are sample means)"),
        "steady-state error variance (log)",
        &data,
    )?;
    Ok(Some(f))
}

/// RMSE of one state group per step: every variant on one figure when that stays readable;
/// otherwise the unswept schemes together and each swept scheme on a figure of its own.
fn per_step(
    exp: &Experiment,
    summary: &Summary,
    dir: &Path,
    group: &str,
    written: &mut Vec<String>,
) -> Result<(), String> {
    // Every variant on one figure when that stays readable; otherwise the unswept schemes
    // together and each swept scheme on a figure of its own (one line per sweep point).
    let few = summary.schemes.len() <= 12;
    // Label plus the swept parameters only (the fixed ones are the same for every line).
    let name = |s: &crate::metrics::results::SchemeSummary| {
        let swept = &exp.curves[s.curve].swept;
        let shown: crate::scenario::Params = s
            .params
            .iter()
            .filter(|(k, _)| swept.contains(k))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        if shown.is_empty() {
            s.name.clone()
        } else {
            format!(
                "{} [{}]",
                s.name,
                crate::metrics::results::params_text(&shown)
            )
        }
    };
    let single: Vec<Line> = summary
        .schemes
        .iter()
        .enumerate()
        .filter(|(_, s)| few || exp.curves[s.curve].swept.is_empty())
        .map(|(i, s)| Line {
            name: name(s),
            points: s.rmse[group]
                .iter()
                .enumerate()
                .map(|(k, v)| ((k + 1) as f64, *v))
                .collect(),
            dashed: false,
            color: if few { i } else { s.curve },
            markers: false,
        })
        .collect();
    if !single.is_empty() {
        let f = format!("rmse_{group}_per_step.svg");
        lines(
            &dir.join(&f),
            &format!("{}: RMSE of {group} per step", summary.scenario),
            "step k",
            &format!("RMSE {group}"),
            &single,
        )?;
        written.push(f);
    }
    for (ci, curve) in exp
        .curves
        .iter()
        .enumerate()
        .filter(|(_, c)| !few && !c.swept.is_empty())
    {
        let data: Vec<Line> = summary
            .schemes
            .iter()
            .filter(|s| s.curve == ci)
            .enumerate()
            .map(|(j, s)| Line {
                name: crate::metrics::results::params_text(&s.params),
                points: s.rmse[group]
                    .iter()
                    .enumerate()
                    .map(|(k, v)| ((k + 1) as f64, *v))
                    .collect(),
                dashed: false,
                color: j,
                markers: false,
            })
            .collect();
        if data.len() > 12 {
            continue; // unreadable; the rate plot summarizes this curve
        }
        let f = format!("rmse_{group}_per_step_{}.svg", slug(&curve.label));
        lines(
            &dir.join(&f),
            &format!("{}: RMSE of {group} per step", curve.label),
            "step k",
            &format!("RMSE {group}"),
            &data,
        )?;
        written.push(f);
    }
    Ok(())
}

/// File-name-safe version of a label.
pub fn slug(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_matches('-').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_ticks_label_every_decade_above_ten_and_below_one() {
        let t = log_ticks(0.4, 15.0);
        assert_eq!(t, vec![0.5, 1.0, 2.0, 5.0, 10.0]);
        let t = log_ticks(0.4, 3.0);
        assert_eq!(t, vec![0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 2.0, 3.0]);
        let t = log_ticks(3.0, 2500.0);
        assert_eq!(
            t,
            vec![5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0]
        );
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.5), "0.5");
        assert_eq!(tick_label(20.0), "20");
        assert_eq!(tick_label(0.025), "0.025");
        assert_eq!(tick_label(0.30000000000000004), "0.3");
        assert_eq!(tick_label(1e6), "1e6");
        assert_eq!(tick_label(0.0), "0");
    }
}
