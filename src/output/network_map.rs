//! The network map of a multi-hop run (`network_map.svg`, also in `report.html`): one panel per
//! scheme, the nodes at their positions (or, where the file gives none, by hops from the sink:
//! the sink right, each layer a column; a network of peers on a circle), every link in light grey, the routing tree's links
//! dark, each node filled by its radio's energy per step on one scale for all panels (yellow
//! low, dark red high), the sink a square, and the first node to die circled in red. Panels
//! are titled with the scheme and the network's lifetime.
use crate::metrics::network::NetworkSummary;
use crate::metrics::results::Summary;
use crate::network::topology::Topology;
use crate::scenario::build::Experiment;
use plotters::prelude::*;
use std::path::Path;

const PANEL: (u32, u32) = (460, 420);
const COLUMNS: usize = 3;
/// Panels drawn at most (the rest of the schemes are in `summary.json`).
const MAX_PANELS: usize = 12;

/// The map of `exp`'s network under the schemes of `summary`, as SVG; `None` on a star.
pub fn map_svg(exp: &Experiment, summary: &Summary) -> Option<Result<String, String>> {
    let net = exp.network.as_deref()?;
    let panels: Vec<(&str, &NetworkSummary)> = summary
        .schemes
        .iter()
        .filter_map(|s| s.network.as_ref().map(|n| (s.name.as_str(), n)))
        .take(MAX_PANELS)
        .collect();
    if panels.is_empty() {
        return None;
    }
    Some(draw(net, &panels).map_err(|e| format!("network map: {e}")))
}

/// Writes `network_map.svg` into `dir` for a multi-hop run; returns the file's name.
pub fn write(exp: &Experiment, summary: &Summary, dir: &Path) -> Result<Option<String>, String> {
    let Some(svg) = map_svg(exp, summary) else {
        return Ok(None);
    };
    let name = "network_map.svg";
    crate::output::write_file(&dir.join(name), svg?.as_bytes())
        .map_err(|e| format!("network map: {e}"))?;
    Ok(Some(name.into()))
}

/// Where each node is drawn, in the unit square: its position scaled, or its layer by hops.
fn layout(net: &Topology) -> Vec<(f64, f64)> {
    let raw: Vec<(f64, f64)> = if net.nodes.iter().all(|n| n.position.is_some()) {
        net.nodes
            .iter()
            .map(|n| {
                let p = n.position.unwrap_or_default();
                (p[0], p[1])
            })
            .collect()
    } else if net.sink().is_none() {
        // A network of peers has no layers: its nodes on a circle, in order.
        let m = net.nodes.len() as f64;
        (0..net.nodes.len())
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / m;
                (a.sin(), a.cos())
            })
            .collect()
    } else {
        let depth = (0..net.nodes.len()).map(|n| net.hops(n)).max().unwrap_or(0);
        let mut seen = vec![0usize; depth + 1];
        let counts: Vec<usize> = (0..=depth)
            .map(|d| (0..net.nodes.len()).filter(|&n| net.hops(n) == d).count())
            .collect();
        (0..net.nodes.len())
            .map(|n| {
                let d = net.hops(n);
                seen[d] += 1;
                ((depth - d) as f64, seen[d] as f64 / (counts[d] + 1) as f64)
            })
            .collect()
    };
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &raw {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let span = (x1 - x0).max(y1 - y0).max(1e-12);
    raw.iter()
        .map(|&(x, y)| {
            (
                0.5 + (x - (x0 + x1) / 2.0) / span,
                0.5 - (y - (y0 + y1) / 2.0) / span,
            )
        })
        .collect()
}

/// Yellow (t = 0) to dark red (t = 1).
fn heat(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
    RGBColor(lerp(255.0, 140.0), lerp(230.0, 10.0), lerp(90.0, 20.0))
}

fn draw(net: &Topology, panels: &[(&str, &NetworkSummary)]) -> Result<String, String> {
    let err = |e: DrawingAreaErrorKind<std::io::Error>| e.to_string();
    let at = layout(net);
    let energies = panels
        .iter()
        .flat_map(|(_, n)| n.nodes.iter().map(|x| x.energy_per_step_uj));
    let (lo, hi) = energies.fold((f64::MAX, f64::MIN), |(a, b), e| (a.min(e), b.max(e)));
    let rows = panels.len().div_ceil(COLUMNS);
    let cols = panels.len().min(COLUMNS);
    let size = (
        (PANEL.0 * cols as u32).max(1000),
        PANEL.1 * rows as u32 + 40,
    );
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (grid, legend) = root.split_vertically(PANEL.1 * rows as u32);
        let areas = grid.split_evenly((rows, cols));
        for ((name, summary), area) in panels.iter().zip(areas) {
            let mut title = match &summary.first_to_die {
                Some(f) => format!("{name}: {} dies first, {:.0} days", f.node, f.lifetime_days),
                None => name.to_string(),
            };
            if summary.aggregated {
                title.push_str(" (relays sum)");
            }
            area.draw(&Text::new(title, (10, 8), ("sans-serif", 14)))
                .map_err(err)?;
            let (w, h) = (PANEL.0 as f64 - 90.0, PANEL.1 as f64 - 80.0);
            let px = |i: usize| (30 + (at[i].0 * w) as i32, 40 + (at[i].1 * h) as i32);
            for l in &net.links {
                let tree = net.parent[l.a] == Some(l.b) || net.parent[l.b] == Some(l.a);
                let style = if tree {
                    RGBColor(60, 60, 60).stroke_width(2)
                } else {
                    RGBColor(205, 205, 205).stroke_width(1)
                };
                area.draw(&PathElement::new(vec![px(l.a), px(l.b)], style))
                    .map_err(err)?;
            }
            for (i, node) in summary.nodes.iter().enumerate() {
                let t = if hi > lo {
                    (node.energy_per_step_uj - lo) / (hi - lo)
                } else {
                    0.5
                };
                let (x, y) = px(i);
                if node.kind == "sink" {
                    area.draw(&Rectangle::new(
                        [(x - 9, y - 9), (x + 9, y + 9)],
                        heat(t).filled(),
                    ))
                    .map_err(err)?;
                    area.draw(&Rectangle::new(
                        [(x - 9, y - 9), (x + 9, y + 9)],
                        BLACK.stroke_width(2),
                    ))
                    .map_err(err)?;
                } else {
                    area.draw(&Circle::new((x, y), 8, heat(t).filled()))
                        .map_err(err)?;
                    area.draw(&Circle::new((x, y), 8, BLACK.stroke_width(1)))
                        .map_err(err)?;
                }
                if summary
                    .first_to_die
                    .as_ref()
                    .is_some_and(|f| f.node == node.name)
                {
                    area.draw(&Circle::new((x, y), 14, RED.stroke_width(3)))
                        .map_err(err)?;
                }
                area.draw(&Text::new(
                    node.name.clone(),
                    (x + 11, y - 16),
                    ("sans-serif", 12),
                ))
                .map_err(err)?;
            }
        }
        // The colour scale.
        for s in 0..=100 {
            let x = 20 + s * 3;
            legend
                .draw(&Rectangle::new(
                    [(x, 8), (x + 3, 22)],
                    heat(s as f64 / 100.0).filled(),
                ))
                .map_err(err)?;
        }
        let label = format!(
            "{lo:.1} to {hi:.1} µJ per step; square: sink; red ring: dies first; dark: routes"
        );
        legend
            .draw(&Text::new(label, (330, 9), ("sans-serif", 13)))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(buf)
}
