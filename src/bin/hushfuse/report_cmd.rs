//! `hushfuse report`: report.html for the results of a run.
use super::*;

/// `hushfuse report <out-dir>`: report.html from a run's summary.json and scenario_as_run.toml.
pub(crate) fn report_dir(dir: &Path) -> Result<(), Failure> {
    let read = |name: &str| {
        std::fs::read_to_string(dir.join(name)).map_err(|e| {
            Failure::Input(format!(
                "{}: cannot read: {e} (run `hushfuse run <scenario> --out {}` first; calibrated arenas: `run --budgets ... --report`)",
                dir.join(name).display(),
                dir.display()
            ))
        })
    };
    let text = read("scenario_as_run.toml")?;
    let summary: results::Summary = serde_json::from_str(&read("summary.json")?)
        .map_err(|e| Failure::Input(format!("{}: {e}", dir.join("summary.json").display())))?;
    let source = dir.join("scenario_as_run.toml").display().to_string();
    let exp = build::load(&text, &source).map_err(|e| Failure::Input(e.to_string()))?;
    if exp.variants.len() != summary.schemes.len() || exp.trials != summary.trials {
        return Err(Failure::Input(format!(
            "{}: summary.json and scenario_as_run.toml do not belong together",
            dir.display()
        )));
    }
    let page = run_files::report_page(&exp, &summary, &text).map_err(Failure::Run)?;
    let path = dir.join("report.html");
    match output::read_manifest(dir).map_err(Failure::Input)? {
        // Joins the run's files in its manifest.
        Some(manifest) => {
            let mut out_dir = OutputDir::open_existing(dir).map_err(Failure::Input)?;
            out_dir
                .stage("report.html", page.as_bytes())
                .map_err(Failure::Run)?;
            out_dir.commit(manifest, true).map_err(Failure::Run)?;
        }
        None => output::write_file(&path, page.as_bytes()).map_err(Failure::Run)?,
    }
    print_out(&format!("wrote {}\n", path.display()));
    Ok(())
}
