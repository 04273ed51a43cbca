//! What a run writes, decided once: from an experiment and its results to the files of an
//! output folder. `run`, `merge`, `replay`, `report`, the arena's budget folders and the
//! Python package all stage their files through [`stage`], so a file is made one way wherever
//! it comes from; only which [`Part`]s a command writes differs.
use crate::engine::replay::{self, Recorded, Replayed};
use crate::metrics::results::{self, Summary};
use crate::output::folder::OutputDir;
use crate::output::{html, plot, report};
use crate::scenario::build::Experiment;
use serde::Serialize;

/// The `paper` section of `summary.json`: the published numbers beside ours and the checked
/// claims, for a scenario that reproduces a paper.
#[derive(Debug, Clone, Serialize)]
pub struct PaperSection<'a> {
    pub citation: &'a str,
    pub notes: &'a [String],
    pub published: Vec<report::Comparison>,
    pub claims: Vec<report::ClaimResult>,
}

/// The paper section of a run of `exp` with results `summary` (`None`: not a reproduction).
pub fn paper_section<'a>(exp: &'a Experiment, summary: &Summary) -> Option<PaperSection<'a>> {
    exp.paper.as_ref().map(|p| PaperSection {
        citation: &p.citation,
        notes: &p.notes,
        published: report::compare_published(exp, summary),
        claims: report::check_claims(exp, summary),
    })
}

/// `summary.json`: the summary, with the paper section after it when there is one.
#[derive(Serialize)]
struct SummaryFile<'a> {
    #[serde(flatten)]
    summary: &'a Summary,
    paper: &'a PaperSection<'a>,
}

/// What a run produced, for [`stage`].
#[derive(Clone, Copy)]
pub struct Results<'a> {
    pub exp: &'a Experiment,
    /// The metrics (`None`: a replay without truth has none).
    pub summary: Option<&'a Summary>,
    pub paper: Option<&'a PaperSection<'a>>,
    /// A replay's data and estimates (for `estimates.csv`).
    pub replay: Option<(&'a Recorded, &'a Replayed)>,
}

/// One file, or one family of files, of an output folder. [`stage`] writes the parts in the
/// order given, and the manifest lists the files in that order.
#[derive(Debug, Clone, Copy)]
pub enum Part<'a> {
    /// `estimates.csv`: every variant's fused estimate and links per step (a replay).
    Estimates,
    /// `summary.json`, with the `paper` section when the results have one.
    Summary,
    /// `per_step.csv`.
    PerStep,
    /// `reproduction.md`: the paper's numbers beside ours (`elapsed`: seconds, in its heading).
    Reproduction { elapsed: f64 },
    /// The SVG plots.
    Plots,
    /// The scenario as run, as file `name`.
    Scenario { name: &'a str, text: &'a str },
    /// `report.html`, the page a person reads (`scenario_text`: the scenario as run).
    Report { scenario_text: &'a str },
}

/// The parts of a Monte Carlo run's folder (`run`, `merge`, Python's `run(out=...)`):
/// `summary.json`, `per_step.csv`, `reproduction.md` when `reproduction` gives the seconds,
/// the plots, `scenario_as_run.toml` and, with `report`, `report.html`.
pub fn run_parts(scenario_as_run: &str, reproduction: Option<f64>, report: bool) -> Vec<Part<'_>> {
    let mut parts = vec![Part::Summary, Part::PerStep];
    if let Some(elapsed) = reproduction {
        parts.push(Part::Reproduction { elapsed });
    }
    parts.push(Part::Plots);
    parts.push(Part::Scenario {
        name: "scenario_as_run.toml",
        text: scenario_as_run,
    });
    if report {
        parts.push(Part::Report {
            scenario_text: scenario_as_run,
        });
    }
    parts
}

/// The parts of a replay's folder: `estimates.csv`, and with truth `summary.json` and
/// `per_step.csv`.
pub fn replay_parts(has_truth: bool) -> Vec<Part<'static>> {
    let mut parts = vec![Part::Estimates];
    if has_truth {
        parts.extend([Part::Summary, Part::PerStep]);
    }
    parts
}

/// Stages `parts` of `results` into `out_dir` under `prefix` (`""`, or a subfolder such as
/// `"budget-12/"`), in order, and returns the names staged. The large files (`summary.json`,
/// `per_step.csv`) are streamed, never held whole in memory beside the results. A part the
/// results cannot give (a summary without metrics, a reproduction without a paper) is skipped.
pub fn stage(
    out_dir: &mut OutputDir,
    prefix: &str,
    results: &Results,
    parts: &[Part],
) -> Result<Vec<String>, String> {
    let mut names = Vec::new();
    for part in parts {
        let before = names.len();
        stage_part(out_dir, prefix, results, part, &mut names)?;
        debug_assert!(names[before..].iter().all(|n| n.starts_with(prefix)));
    }
    Ok(names)
}

fn stage_part(
    out_dir: &mut OutputDir,
    prefix: &str,
    r: &Results,
    part: &Part,
    names: &mut Vec<String>,
) -> Result<(), String> {
    let mut put = |out_dir: &mut OutputDir, name: &str, bytes: &[u8]| {
        let name = format!("{prefix}{name}");
        out_dir.stage(&name, bytes)?;
        names.push(name);
        Ok::<_, String>(())
    };
    match *part {
        Part::Estimates => {
            if let Some((rec, rep)) = r.replay {
                put(
                    out_dir,
                    "estimates.csv",
                    replay::estimates_csv(r.exp, rec, rep).as_bytes(),
                )?;
            }
        }
        Part::Summary => {
            if let Some(summary) = r.summary {
                let name = format!("{prefix}summary.json");
                // A failed variant's numbers are written as null (through a JSON value, only
                // then: every other summary is written as it serializes).
                let failed = summary.schemes.iter().any(|s| s.failed.is_some());
                out_dir.stage_with(&name, |w| {
                    match (r.paper, failed) {
                        (Some(paper), false) => {
                            serde_json::to_writer_pretty(w, &SummaryFile { summary, paper })
                        }
                        (None, false) => serde_json::to_writer_pretty(w, summary),
                        (Some(paper), true) => {
                            crate::metrics::summary_json(&SummaryFile { summary, paper })
                                .and_then(|v| serde_json::to_writer_pretty(w, &v))
                        }
                        (None, true) => crate::metrics::summary_json(summary)
                            .and_then(|v| serde_json::to_writer_pretty(w, &v)),
                    }
                    .map_err(std::io::Error::from)
                })?;
                names.push(name);
            }
        }
        Part::PerStep => {
            if let Some(summary) = r.summary {
                let name = format!("{prefix}per_step.csv");
                out_dir.stage_with(&name, |w| {
                    crate::metrics::per_step_csv::write_per_step_csv(summary, w)
                })?;
                names.push(name);
            }
        }
        Part::Reproduction { elapsed } => {
            if let (Some(summary), Some(p)) = (r.summary, r.paper) {
                let md =
                    report::render_markdown(&summary.scenario, elapsed, &p.published, &p.claims);
                put(out_dir, "reproduction.md", md.as_bytes())?;
            }
        }
        Part::Plots => {
            if let Some(summary) = r.summary {
                let dir = out_dir.staging()?.join(prefix);
                std::fs::create_dir_all(&dir)
                    .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
                let mut plots = plot::write_all(r.exp, summary, &dir)?;
                plots.extend(crate::output::network_map::write(r.exp, summary, &dir)?);
                plots.extend(crate::output::energy_front::write(r.exp, summary, &dir)?);
                let plots: Vec<String> =
                    plots.into_iter().map(|p| format!("{prefix}{p}")).collect();
                out_dir.record(plots.iter().cloned());
                names.extend(plots);
            }
        }
        Part::Scenario { name, text } => put(out_dir, name, text.as_bytes())?,
        Part::Report { scenario_text } => {
            if let Some(summary) = r.summary {
                let page = report_page(r.exp, summary, scenario_text)?;
                put(out_dir, "report.html", page.as_bytes())?;
            }
        }
    }
    Ok(())
}

/// `report.html` of a run (not of a calibrated arena, whose page carries its tables).
pub fn report_page(
    exp: &Experiment,
    summary: &Summary,
    scenario_text: &str,
) -> Result<String, String> {
    html::render(&html::Input {
        exp,
        summary,
        scenario_text,
        alone: false,
        arena: None,
        se_trials: exp.trials.min(200),
    })
}

/// The text a run prints before it writes anything (so that a failed write loses no number
/// from sight): the headline, the table, the steady-state legend and, for a reproduction, the
/// paper's numbers beside ours.
pub fn run_text(
    exp: &Experiment,
    summary: &Summary,
    paper: Option<&PaperSection>,
    elapsed: f64,
    reproduce: bool,
) -> String {
    let mut text = format!(
        "{} — {} trials x {} steps, seed {}, {} sensors ({:.1} s)\n\n",
        summary.scenario, summary.trials, summary.steps, summary.seed, summary.sensors, elapsed
    );
    text.push_str(&results::table(summary));
    text.push_str(&crate::metrics::notes::block(summary));
    text.push_str(&format!(
        "\nMSE(ss), trace(ss): steady state from step {}; ANEES = mean NEES / state dimension (1 = consistent).\n",
        exp.steady_from
    ));
    if let (true, Some(p)) = (reproduce, paper) {
        text.push_str(&format!(
            "\n{}\n",
            report::render(exp, &p.published, &p.claims)
        ));
    }
    text
}

/// The scenario text as run: the file with the `trials` and `seed` overrides written in
/// (comments kept when nothing was overridden).
pub fn as_run_text(text: &str, trials: Option<usize>, seed: Option<u64>) -> String {
    if trials.is_none() && seed.is_none() {
        return text.to_string();
    }
    let Ok(mut t) = toml::from_str::<toml::Table>(text) else {
        return text.to_string();
    };
    if let Some(n) = trials {
        let value = i64::try_from(n)
            .map_or_else(|_| toml::Value::String(n.to_string()), toml::Value::Integer);
        t.insert("trials".into(), value);
    }
    if let Some(s) = seed {
        // TOML integers are 64-bit signed: a seed above 2^63 - 1 is written as a decimal string,
        // which scenario files accept as well.
        let value = i64::try_from(s)
            .map_or_else(|_| toml::Value::String(s.to_string()), toml::Value::Integer);
        t.insert("seed".into(), value);
    }
    toml::to_string(&t).unwrap_or_else(|_| text.to_string())
}
