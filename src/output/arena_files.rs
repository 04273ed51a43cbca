//! What a calibrated arena (`hushfuse run --budgets`, Python's `run(..., budgets=, out=)`)
//! writes: `calibration.json`, `best_per_budget.md`, one `budget-X/` folder per budget (the
//! files a run of that budget's scenario writes), the plots, optionally `report.html`, and the
//! manifest of kind `arena`. The command line and the Python package both write through this
//! module, so an arena's folder is the same file for file whichever of them made it.
use crate::engine::calibrate::{self, Options, Outcome};
use crate::output::folder::{self, Manifest, OutputDir};
use crate::output::{arena, html, run_files};
use crate::scenario::build::{self, Experiment, LoadOptions};
use std::path::Path;

/// The hash of an arena's inputs, for its manifest: the scenario's source and text as run,
/// the trials and seed overrides, the budgets, the axis and the pilot trials. The tolerance
/// joins them only when it is not the default, which the command line cannot change: the
/// same arena asked from Python and from the command line then has the same manifest.
pub fn inputs_sha256(text: &str, source: &str, budgets: &[f64], opts: &Options) -> String {
    let mut inputs = format!(
        "{source}\0{text}\0{:?}\0{:?}\0{:?}\0{}\0{:?}",
        opts.load.trials,
        opts.load.seed,
        budgets,
        opts.axis.name(),
        opts.pilot_trials
    );
    if opts.tolerance != Options::default().tolerance {
        inputs.push_str(&format!("\0{:?}", opts.tolerance));
    }
    folder::sha256_hex(inputs.as_bytes())
}

/// Refuses an arena whose outputs (one run's per budget) would not fit on the disk of `dir`:
/// checked before the first pilot run, so that a full disk does not throw the calibration away.
pub fn check_room(dir: &Path, exp: &Experiment, budget_count: usize) -> Result<(), String> {
    let per_budget = crate::scenario::limits::output_bytes(
        exp.groups.len(),
        exp.variants.len(),
        exp.steps,
        exp.trials,
    );
    folder::check_free_space(dir, per_budget * budget_count as f64)
}

/// The numbers of every budget's summary that are not finite, named by their budget: such an
/// arena's results cannot be trusted, and its callers refuse it before writing anything.
pub fn non_finite(out: &Outcome) -> Vec<String> {
    out.summaries
        .iter()
        .zip(&out.budgets)
        .flat_map(|(s, b)| {
            crate::metrics::finite::non_finite(s)
                .into_iter()
                .map(move |m| format!("budget {}: {m}", calibrate::dir_label(*b)))
        })
        .collect()
}

/// Stages the arena's files into `out_dir` (already opened: its folder was checked before the
/// calibration ran): `calibration.json` (`elapsed` seconds in it), `best_per_budget.md`, each
/// budget's folder, the plots and, with `report`, `report.html`. Each budget's scenario is
/// rebuilt from its text, `source` and `load` (the calibration keeps texts, not experiments).
/// Returns the names as listed to the user (a budget's folder as `budget-X/`); nothing is in
/// place until [`commit`].
pub fn stage(
    out_dir: &mut OutputDir,
    out: &Outcome,
    elapsed: f64,
    (source, load): (&str, &LoadOptions),
    report: bool,
) -> Result<Vec<String>, String> {
    let first = &out.summaries[0];
    let group = &first.group_order[0];
    out_dir.stage(
        "calibration.json",
        calibration_json(out, elapsed)?.as_bytes(),
    )?;
    out_dir.stage(
        "best_per_budget.md",
        arena::best_markdown(out, group).as_bytes(),
    )?;
    let mut files = vec![
        "calibration.json".to_string(),
        "best_per_budget.md".to_string(),
    ];
    for (b, s) in out.summaries.iter().enumerate() {
        let sub = format!("budget-{}/", calibrate::dir_label(out.budgets[b]));
        // The budget's scenario as run, rebuilt: the same files as a run of it would write.
        let exp = build::load_with(&out.texts[b], source, load).map_err(|e| e.to_string())?;
        let results = run_files::Results {
            exp: &exp,
            summary: Some(s),
            paper: None,
            replay: None,
        };
        let parts = [
            run_files::Part::Scenario {
                name: "scenario.toml",
                text: &out.texts[b],
            },
            run_files::Part::Summary,
            run_files::Part::PerStep,
        ];
        run_files::stage(out_dir, &sub, &results, &parts)?;
        files.push(sub);
    }
    let plots = arena::write_plots(out, group, &first.scenario, out_dir.staging()?)?;
    out_dir.record(plots.iter().cloned());
    files.extend(plots);
    if report {
        stage_report(out_dir, out, (source, load))?;
        files.push("report.html".into());
    }
    Ok(files)
}

/// `calibration.json`: per budget, per scheme, the knob found and what it achieved.
fn calibration_json(out: &Outcome, elapsed: f64) -> Result<String, String> {
    let json = serde_json::json!({
        "scenario": out.summaries[0].scenario,
        "axis": out.axis.name(),
        "tolerance": out.tolerance,
        "pilot_runs": out.evaluations,
        "seconds": elapsed,
        "budgets": out.budgets,
        "rows": out.rows.iter().map(|row| row.iter().map(|c| serde_json::json!({
            "scheme": c.label, "kind": c.kind, "knob": c.knob, "value": c.value,
            "target": c.target, "achieved": c.achieved, "status": c.status, "end": c.end,
            "bits_per_step": c.result.bits_per_step,
            "frame_bits_per_step": c.result.frame_bits_per_step,
            "downlink_bits_per_step": c.result.downlink_bits_per_step,
            "mean_rmse": c.result.mean_rmse, "anees": c.result.anees,
            "steady_state": c.result.steady_state,
        })).collect::<Vec<_>>()).collect::<Vec<_>>(),
    });
    serde_json::to_string_pretty(&json).map_err(|e| e.to_string())
}

/// `report.html`: the page of the first budget's run, with the arena's tables.
fn stage_report(
    out_dir: &mut OutputDir,
    out: &Outcome,
    (source, load): (&str, &LoadOptions),
) -> Result<(), String> {
    let exp = build::load_with(&out.texts[0], source, load).map_err(|e| e.to_string())?;
    let page = html::render(&html::Input {
        exp: &exp,
        summary: &out.summaries[0],
        scenario_text: &out.texts[0],
        alone: true,
        arena: Some(out),
        se_trials: exp.trials.min(200),
    })?;
    out_dir.stage("report.html", page.as_bytes())
}

/// Moves the staged files into place under a manifest of kind `arena` (the scenario, the
/// seed and trials of the first budget's run, `inputs_sha256`); returns the files written,
/// relative to the folder, as the manifest lists them.
pub fn commit(
    out_dir: OutputDir,
    out: &Outcome,
    inputs_sha256: &str,
) -> Result<Vec<String>, String> {
    let first = &out.summaries[0];
    let mut manifest = Manifest::new("arena", &first.scenario, inputs_sha256);
    manifest.seed = Some(first.seed);
    manifest.trials = Some(first.trials);
    out_dir.commit(manifest, false)
}
