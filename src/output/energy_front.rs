//! Accuracy against the network's radio energy of a multi-hop run (`rmse_vs_energy.svg`, also
//! in `report.html`): every scheme at its network energy per step (µJ, every battery-powered
//! node's radio; a sink on mains left out) and its mean RMSE of the first group, a swept scheme
//! as a line through its points; the Pareto front of all of them (dashed black; left out when one scheme dominates the rest) and the all-data
//! bound (dashed grey). It answers the deployment question the graph arenas ask — fuse at a
//! sink over relays, or let the peers agree, at the same battery? — for the schemes as written;
//! `run --budgets` draws the same figure with every knob calibrated to each energy budget.
use crate::metrics::results::Summary;
use crate::output::arena::{pareto_front, with_bound};
use crate::output::plot::{self, Line};
use crate::scenario::build::Experiment;
use std::path::Path;

/// The file's name.
pub const FILE: &str = "rmse_vs_energy.svg";

/// The figure's lines: per curve its schemes' (µJ per step, mean RMSE of `group`) points, the
/// Pareto front over all of them, the bound across their range. `None` without a network or
/// with fewer than two finite points (nothing to compare).
pub fn lines(exp: &Experiment, summary: &Summary, group: &str) -> Option<Vec<Line>> {
    exp.network.as_ref()?;
    let mut lines: Vec<Line> = Vec::new();
    let mut all = Vec::new();
    for (ci, curve) in exp.curves.iter().enumerate() {
        let mut points: Vec<(f64, f64)> = summary
            .schemes
            .iter()
            .filter(|s| s.curve == ci && s.failed.is_none())
            .filter_map(|s| Some((s.energy.energy_per_step_uj, *s.mean_rmse.get(group)?)))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        all.extend(points.iter().copied());
        lines.push(Line {
            name: curve.label.clone(),
            points,
            dashed: false,
            color: if ci >= 10 { ci + 1 } else { ci },
            markers: true,
        });
    }
    if all.len() < 2 {
        return None;
    }
    lines.retain(|l| !l.points.is_empty());
    // A front of one point is a scheme that dominates all others: its own marker says it.
    let front: Vec<(f64, f64)> = pareto_front(&all).into_iter().map(|i| all[i]).collect();
    if front.len() > 1 {
        lines.push(Line {
            name: "Pareto front".into(),
            points: front,
            dashed: true,
            color: 10,
            markers: false,
        });
    }
    let bound = summary
        .pcrb
        .as_ref()
        .and_then(|b| b.mean_rmse.get(group))
        .copied();
    let lines = with_bound(lines, bound);
    Some(lines)
}

/// The figure as SVG, `None` where [`lines`] has none.
pub fn svg(exp: &Experiment, summary: &Summary) -> Option<Result<String, String>> {
    let group = summary.group_order.first()?;
    let lines = lines(exp, summary, group)?;
    Some(plot::lines_svg(
        &format!(
            "{}: mean RMSE of {group} against the network's radio energy",
            summary.scenario
        ),
        "network radio energy, µJ per step (battery-powered nodes)",
        &format!("mean RMSE {group}"),
        &lines,
    ))
}

/// Writes [`FILE`] into `dir` for a multi-hop run; returns its name.
pub fn write(exp: &Experiment, summary: &Summary, dir: &Path) -> Result<Option<String>, String> {
    let Some(svg) = svg(exp, summary) else {
        return Ok(None);
    };
    crate::output::write_file(&dir.join(FILE), svg?.as_bytes())
        .map_err(|e| format!("{FILE}: {e}"))?;
    Ok(Some(FILE.into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary_of(exp: &Experiment) -> Summary {
        let sums = crate::engine::runner::run(exp, Default::default(), &|_| {}).unwrap();
        crate::metrics::results::summarize(exp, &sums)
    }

    /// Two schemes on a line network: each a marker at its energy and RMSE, the front through
    /// the cheaper-and-better ones; no figure on a star.
    #[test]
    fn one_marker_per_scheme_and_the_front() {
        let net = "[network]\nrelays = 1\nedges = \"line\"\n";
        let text = format!(
            "name = \"t\"\ntrials = 4\nsteps = 20\nseed = 1\n[model]\nkind = \"matrix\"\nF = [[0.95]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n[[sensors]]\nH = [[1.0]]\nR = [[2.0]]\n{net}\n[[schemes]]\nkind = \"centralized-kf\"\n[[schemes]]\nkind = \"send-on-delta\"\ndelta = 2.0\n"
        );
        let exp = crate::scenario::build::load(&text, "t.toml").unwrap();
        let summary = summary_of(&exp);
        let group = &summary.group_order[0];
        let lines = lines(&exp, &summary, group).unwrap();
        for (i, s) in summary.schemes.iter().enumerate() {
            assert_eq!(
                lines[i].points,
                vec![(s.energy.energy_per_step_uj, s.mean_rmse[group])]
            );
        }
        let front = lines.iter().find(|l| l.name == "Pareto front").unwrap();
        let kf = lines[0].points[0];
        assert!(
            front.points.contains(&kf),
            "the all-data KF is never dominated"
        );
        assert!(svg(&exp, &summary).unwrap().unwrap().contains("<svg"));
        let star = text.replace(net, "");
        let exp = crate::scenario::build::load(&star, "t.toml").unwrap();
        let summary = summary_of(&exp);
        assert!(svg(&exp, &summary).is_none());
    }
}
