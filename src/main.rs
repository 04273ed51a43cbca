//! `hushfuse` command line: run scenarios, list the built-in ones, reproduce paper figures.
use clap::{Parser, Subcommand};
use hushfuse::sim::{
    arena, build, builtin, calibrate, html, plot, replay, report, results, runner, tables,
};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "hushfuse",
    version,
    about = "Multi-sensor state estimation when sensors must save bandwidth.\nWith no command, runs a quick arena: every scheme at a few bit budgets (seconds)."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(clap::Args, Clone, Default)]
struct RunArgs {
    /// Override the number of Monte Carlo trials.
    #[arg(long)]
    trials: Option<usize>,
    /// Override the seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (default: one per core). Results do not depend on it.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Output folder (default: hushfuse-out/<scenario>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run even if the estimated memory or run time is above the limits (16 GiB, 24 hours).
    #[arg(long)]
    allow_large: bool,
    /// Tune every scheme's bandwidth knob so that all spend BITS bits per step (pilot runs on
    /// common random numbers), then compare them.
    #[arg(long, value_name = "BITS", conflicts_with = "budgets")]
    budget: Option<f64>,
    /// Several budgets, comma-separated: accuracy against bits, the Pareto front and the best
    /// scheme per budget.
    #[arg(long, value_name = "B1,B2,...")]
    budgets: Option<String>,
    /// What the budget counts: uplink payload bits, whole 802.15.4 frames, or frames plus the
    /// downlink feedback.
    #[arg(long, default_value = "payload", value_name = "payload|frame|total")]
    budget_axis: String,
    /// Trials of the calibration's pilot runs (default: the scenario's; fewer is faster, and the
    /// calibrated knobs are then rerun at the full count).
    #[arg(long)]
    pilot_trials: Option<usize>,
    /// Also write report.html (self-contained: figures, tables, the scenario as run).
    #[arg(long)]
    report: bool,
    /// Also write trial K's simulated measurements and truth as CSV into DIR (the layout
    /// `hushfuse replay` reads).
    #[arg(long, hide = true, num_args = 2, value_names = ["K", "DIR"])]
    write_trial: Option<Vec<String>>,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario file or a built-in scenario and write summary.json, per_step.csv, SVGs.
    Run {
        /// Path of a TOML scenario, or the name of a built-in one (see `hushfuse list`).
        scenario: String,
        #[command(flatten)]
        args: RunArgs,
    },
    /// Write report.html for the results in OUT_DIR (of `hushfuse run`): figures, tables, one
    /// trial in detail, the scenario as run. Reruns trial 0 and the per-step errors.
    Report {
        /// The output folder of a run (holds summary.json and scenario_as_run.toml).
        out_dir: PathBuf,
        /// Worker threads (unused by the report itself; kept for symmetry).
        #[arg(long, default_value_t = 0)]
        threads: usize,
    },
    /// Run every scheme of a scenario on recorded measurements (CSV) instead of simulated
    /// ones: write estimates.csv, and with --truth summary.json and per_step.csv (one trial).
    Replay {
        /// Path of a TOML scenario, or the name of a built-in one.
        scenario: String,
        /// Recorded measurements: `step,sensor,z0,...`, one row per reading (a missing row:
        /// no reading at that step).
        #[arg(long, value_name = "FILE.csv")]
        measurements: PathBuf,
        /// Recorded truth: `step,x0,...`, one row per step from 1.
        #[arg(long, value_name = "FILE.csv")]
        truth: Option<PathBuf>,
        /// Output folder (default: hushfuse-out/<scenario>-replay/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override the scenario's seed (the schemes' coins).
        #[arg(long)]
        seed: Option<u64>,
        /// Use the coins of this trial (to replay data written from trial K of a run).
        #[arg(long, default_value_t = 0)]
        trial: usize,
        /// Run even if the estimated memory or run time is above the limits.
        #[arg(long)]
        allow_large: bool,
    },
    /// List the built-in scenarios.
    List,
    /// List every scheme kind with its parameters and defaults.
    ListSchemes {
        /// Print the reference as Markdown (the text of docs/scenarios.md).
        #[arg(long)]
        markdown: bool,
    },
    /// Run a built-in paper scenario and print our numbers beside the paper's, and its claims.
    Reproduce {
        /// Built-in scenario id (e.g. dormann-fig1) or a scenario file with a [paper] section.
        id: String,
        #[command(flatten)]
        args: RunArgs,
    },
}

/// Exit codes: 2 for bad input (scenario, arguments), 1 for a failed run.
enum Failure {
    Input(String),
    Run(String),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => quick_arena(),
        Some(Command::Run { scenario, args }) => {
            if args.budget.is_some() || args.budgets.is_some() {
                arena_run(&scenario, &args).map(|_| ())
            } else {
                run(&scenario, &args, false)
            }
        }
        Some(Command::Reproduce { id, args }) => {
            if builtin::get(&id).is_none() && !Path::new(&id).exists() {
                Err(Failure::Input(format!(
                    "unknown built-in scenario {id:?}; `hushfuse list` shows them"
                )))
            } else {
                run(&id, &args, true)
            }
        }
        Some(Command::ListSchemes { markdown }) => {
            print_out(&if markdown {
                hushfuse::scheme::registry::markdown()
            } else {
                hushfuse::scheme::registry::describe()
            });
            Ok(())
        }
        Some(Command::Report { out_dir, .. }) => report_dir(&out_dir),
        Some(Command::Replay {
            scenario,
            measurements,
            truth,
            out,
            seed,
            trial,
            allow_large,
        }) => replay(&ReplayArgs {
            scenario: &scenario,
            measurements: &measurements,
            truth: truth.as_deref(),
            out: out.as_deref(),
            seed,
            trial,
            allow_large,
        }),
        Some(Command::List) => {
            let text: String = builtin::BUILTIN
                .iter()
                .map(|(name, desc, _)| format!("{name:<20} {desc}\n"))
                .collect();
            print_out(&text);
            Ok(())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Input(m)) => {
            eprintln!("error: {m}");
            ExitCode::from(2)
        }
        Err(Failure::Run(m)) => {
            eprintln!("error: {m}");
            ExitCode::from(1)
        }
    }
}

/// Writes to stdout; a closed pipe (`hushfuse | head`) is not an error worth a panic.
fn print_out(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

#[derive(Serialize)]
struct Output<'a> {
    #[serde(flatten)]
    summary: &'a results::Summary,
    #[serde(skip_serializing_if = "Option::is_none")]
    paper: Option<PaperOutput<'a>>,
}

#[derive(Serialize)]
struct PaperOutput<'a> {
    citation: &'a str,
    notes: &'a [String],
    published: Vec<report::Comparison>,
    claims: Vec<report::ClaimResult>,
}

/// Text and source name of a scenario given as a path or a built-in name.
fn scenario_text(scenario: &str) -> Result<(String, String), Failure> {
    builtin::resolve(scenario, false).map_err(Failure::Input)
}

/// A computed table reproduction (no Monte Carlo): ours beside the paper's printed values.
fn table_report(text: &str, source: &str, args: &RunArgs) -> Result<(), Failure> {
    let file: tables::TableReportFile =
        toml::from_str(text).map_err(|e| Failure::Input(format!("{source}: {}", e.message())))?;
    build::check_name(&file.name)
        .map_err(|m| Failure::Input(format!("{source}: field `name`: {m}")))?;
    let rows = tables::compare(&file).map_err(|e| Failure::Input(format!("{source}: {e}")))?;
    let mut out = tables::render(&file, &rows);
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&file.name));
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
    let json =
        serde_json::json!({ "scenario": file.name, "citation": file.citation, "rows": rows });
    let path = dir.join("summary.json");
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&json).expect("serializable"),
    )
    .map_err(|e| Failure::Run(format!("cannot write {}: {e}", path.display())))?;
    out.push_str(&format!("\nwrote {}\n", path.display()));
    print_out(&out);
    Ok(())
}

fn run(scenario: &str, args: &RunArgs, reproduce: bool) -> Result<(), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let text_in = text.clone();
    let kind = build::file_kind(&text, &source).map_err(|e| Failure::Input(e.to_string()))?;
    if kind == build::FileKind::TableReport {
        return table_report(&text, &source, args);
    }
    let options = build::LoadOptions {
        trials: args.trials,
        seed: args.seed,
        threads: args.threads,
        limits: args.allow_large.then(hushfuse::sim::limits::Limits::none),
    };
    let exp =
        build::load_with(&text, &source, &options).map_err(|e| Failure::Input(e.to_string()))?;
    let start = Instant::now();
    let bar = ProgressBar::with_draw_target(Some(exp.trials as u64), ProgressDrawTarget::hidden());
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} trials ({eta} left)")
            .expect("static template")
            .progress_chars("=> "),
    );
    bar.set_message(exp.name.clone());
    let shown = AtomicBool::new(false);
    let interactive = std::io::stderr().is_terminal();
    let progress = |done: usize| {
        // Only for runs longer than a second, and only on a terminal.
        if interactive && !shown.load(Ordering::Relaxed) && start.elapsed().as_secs_f64() > 1.0 {
            shown.store(true, Ordering::Relaxed);
            bar.set_draw_target(ProgressDrawTarget::stderr());
        }
        bar.set_position(done as u64);
    };
    let sums = runner::run(
        &exp,
        runner::RunOptions {
            threads: args.threads,
        },
        &progress,
    )
    .map_err(|e| Failure::Run(e.to_string()))?;
    bar.finish_and_clear();
    let elapsed = start.elapsed().as_secs_f64();
    let summary = results::summarize(&exp, &sums);

    let mut text = format!(
        "{} — {} trials x {} steps, seed {}, {} sensors ({:.1} s)\n\n",
        summary.scenario, summary.trials, summary.steps, summary.seed, summary.sensors, elapsed
    );
    text.push_str(&results::table(&summary));
    text.push_str(&format!(
        "\nMSE(ss), trace(ss): steady state from step {}; ANEES = mean NEES / state dimension (1 = consistent).\n",
        exp.steady_from
    ));

    let paper = if reproduce || exp.paper.is_some() {
        exp.paper.as_ref().map(|p| PaperOutput {
            citation: &p.citation,
            notes: &p.notes,
            published: report::compare_published(&exp, &summary),
            claims: report::check_claims(&exp, &summary),
        })
    } else {
        None
    };
    if reproduce {
        if let Some(p) = &paper {
            text.push_str(&format!(
                "\n{}\n",
                report::render(&exp, &p.published, &p.claims)
            ));
        }
    }

    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&summary.scenario));
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
    let out = Output {
        summary: &summary,
        paper,
    };
    let json = serde_json::to_string_pretty(&out).map_err(|e| Failure::Run(e.to_string()))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text)
            .map_err(|e| Failure::Run(format!("cannot write {}: {e}", dir.join(name).display())))
    };
    write("summary.json", &json)?;
    write("per_step.csv", &results::per_step_csv(&summary))?;
    let mut files = vec!["summary.json".to_string(), "per_step.csv".to_string()];
    if let (true, Some(p)) = (reproduce, &out.paper) {
        let md = report::render_markdown(&summary.scenario, elapsed, &p.published, &p.claims);
        write("reproduction.md", &md)?;
        files.push("reproduction.md".to_string());
    }
    files.extend(plot::write_all(&exp, &summary, &dir).map_err(Failure::Run)?);
    let as_run = as_run_text(&text_in, args);
    write("scenario_as_run.toml", &as_run)?;
    files.push("scenario_as_run.toml".to_string());
    if args.report {
        let page = html::render(&html::Input {
            exp: &exp,
            summary: &summary,
            scenario_text: &as_run,
            alone: false,
            arena: None,
            se_trials: exp.trials.min(200),
        })
        .map_err(Failure::Run)?;
        write("report.html", &page)?;
        files.push("report.html".to_string());
    }
    if let Some(wt) = &args.write_trial {
        files.extend(write_trial(&exp, wt)?);
    }
    text.push_str(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    print_out(&text);
    // One trial has no standard errors (NaN): not a failure of the run.
    let bad = if exp.trials == 1 {
        replay::non_finite(&summary)
    } else {
        results::non_finite(&summary)
    };
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the run produced numbers that are not finite (written as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}

/// Budgets from `--budget` or `--budgets`.
fn budgets_of(args: &RunArgs) -> Result<Vec<f64>, Failure> {
    if let Some(b) = args.budget {
        return Ok(vec![b]);
    }
    let text = args.budgets.as_deref().unwrap_or_default();
    text.split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|b| b.is_finite() && *b > 0.0)
                .ok_or_else(|| {
                    Failure::Input(format!(
                        "--budgets: expected positive numbers separated by commas, got {t:?}"
                    ))
                })
        })
        .collect()
}

/// `run --budget` / `--budgets`: calibrate every scheme to each budget, print and write the
/// comparison. Returns the outcome and the output folder.
fn arena_run(scenario: &str, args: &RunArgs) -> Result<(calibrate::Outcome, PathBuf), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let budgets = budgets_of(args)?;
    let axis = calibrate::Axis::parse(&args.budget_axis).map_err(Failure::Input)?;
    let opts = calibrate::Options {
        axis,
        pilot_trials: args.pilot_trials,
        threads: args.threads,
        load: build::LoadOptions {
            trials: args.trials,
            seed: args.seed,
            threads: args.threads,
            limits: args.allow_large.then(hushfuse::sim::limits::Limits::none),
        },
        ..Default::default()
    };
    let start = Instant::now();
    let out = calibrate::calibrate(&text, &source, &budgets, &opts).map_err(|e| {
        if e.contains("field `") || e.starts_with(&source) {
            Failure::Input(e)
        } else {
            Failure::Run(e)
        }
    })?;
    let elapsed = start.elapsed().as_secs_f64();
    let first = &out.summaries[0];
    let group = first.group_order[0].clone();
    let mut msg = format!(
        "{} — {} trials x {} steps, seed {}, {} sensors: {} schemes calibrated to {} budget(s) on the {} axis ({} pilot runs, {:.1} s)\n",
        first.scenario,
        first.trials,
        first.steps,
        first.seed,
        first.sensors,
        out.rows[0].len(),
        budgets.len(),
        axis.name(),
        out.evaluations,
        elapsed
    );
    for (b, budget) in budgets.iter().enumerate() {
        msg.push_str(&format!(
            "\nbudget {} {} bits/step (tolerance {}%):\n",
            calibrate::short(*budget),
            axis.name(),
            calibrate::short(100.0 * out.tolerance)
        ));
        msg.push_str(&calibrate::table(&out, b, &group));
    }
    msg.push_str("\nbest scheme per budget (lowest mean RMSE among schemes within the budget):\n");
    msg.push_str(&arena::best_table(&out, &group));
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&first.scenario));
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| Failure::Run(format!("cannot create {}: {e}", parent.display())))?;
        }
        std::fs::write(&p, text)
            .map_err(|e| Failure::Run(format!("cannot write {}: {e}", p.display())))
    };
    let json = serde_json::json!({
        "scenario": first.scenario,
        "axis": axis.name(),
        "tolerance": out.tolerance,
        "pilot_runs": out.evaluations,
        "seconds": elapsed,
        "budgets": budgets,
        "rows": out.rows.iter().map(|row| row.iter().map(|c| serde_json::json!({
            "scheme": c.label, "kind": c.kind, "knob": c.knob, "value": c.value,
            "target": c.target, "achieved": c.achieved, "status": c.status,
            "bits_per_step": c.result.bits_per_step,
            "frame_bits_per_step": c.result.frame_bits_per_step,
            "downlink_bits_per_step": c.result.downlink_bits_per_step,
            "mean_rmse": c.result.mean_rmse, "anees": c.result.anees,
            "steady_state": c.result.steady_state,
        })).collect::<Vec<_>>()).collect::<Vec<_>>(),
    });
    write(
        "calibration.json",
        &serde_json::to_string_pretty(&json).map_err(|e| Failure::Run(e.to_string()))?,
    )?;
    write("best_per_budget.md", &arena::best_markdown(&out, &group))?;
    let mut files = vec![
        "calibration.json".to_string(),
        "best_per_budget.md".to_string(),
    ];
    for (b, s) in out.summaries.iter().enumerate() {
        let sub = format!("budget-{}", calibrate::short(budgets[b]));
        write(&format!("{sub}/scenario.toml"), &out.texts[b])?;
        write(
            &format!("{sub}/summary.json"),
            &serde_json::to_string_pretty(s).map_err(|e| Failure::Run(e.to_string()))?,
        )?;
        write(&format!("{sub}/per_step.csv"), &results::per_step_csv(s))?;
        files.push(format!("{sub}/"));
    }
    files.extend(arena::write_plots(&out, &group, &first.scenario, &dir).map_err(Failure::Run)?);
    if args.report {
        let exp = build::load_with(&out.texts[0], &source, &opts.load)
            .map_err(|e| Failure::Run(e.to_string()))?;
        let page = html::render(&html::Input {
            exp: &exp,
            summary: &out.summaries[0],
            scenario_text: &out.texts[0],
            alone: true,
            arena: Some(&out),
            se_trials: exp.trials.min(200),
        })
        .map_err(Failure::Run)?;
        write("report.html", &page)?;
        files.push("report.html".into());
    }
    msg.push_str(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    print_out(&msg);
    Ok((out, dir))
}

/// `hushfuse` without arguments: the quick arena, and which scheme wins at which budget.
fn quick_arena() -> Result<(), Failure> {
    let (name, trials, budgets) = arena::QUICK;
    let text = builtin::get(name).expect("built-in quick arena");
    let opts = calibrate::Options {
        load: build::LoadOptions {
            trials: Some(trials),
            ..Default::default()
        },
        ..Default::default()
    };
    let start = Instant::now();
    let out = calibrate::calibrate(text, &format!("built-in:{name}"), budgets, &opts)
        .map_err(Failure::Run)?;
    let group = out.summaries[0].group_order[0].clone();
    let mut msg = arena::quick_description(trials, budgets);
    msg.push('\n');
    msg.push_str(&arena::best_table(&out, &group));
    msg.push_str(&format!(
        "\n({} pilot runs, {:.1} s. `hushfuse list` shows the built-in scenarios, `hushfuse run default` the seed 004 comparison, `hushfuse --help` the commands.)\n",
        out.evaluations,
        start.elapsed().as_secs_f64()
    ));
    print_out(&msg);
    Ok(())
}

/// The scenario text as run: the file with `--trials` and `--seed` written in (comments kept
/// when nothing was overridden).
fn as_run_text(text: &str, args: &RunArgs) -> String {
    if args.trials.is_none() && args.seed.is_none() {
        return text.to_string();
    }
    let Ok(mut t) = toml::from_str::<toml::Table>(text) else {
        return text.to_string();
    };
    if let Some(n) = args.trials {
        t.insert("trials".into(), toml::Value::Integer(n as i64));
    }
    if let Some(s) = args.seed {
        t.insert("seed".into(), toml::Value::Integer(s as i64));
    }
    toml::to_string(&t).unwrap_or_else(|_| text.to_string())
}

/// `hushfuse report <out-dir>`: report.html from a run's summary.json and scenario_as_run.toml.
fn report_dir(dir: &Path) -> Result<(), Failure> {
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
    let page = html::render(&html::Input {
        exp: &exp,
        summary: &summary,
        scenario_text: &text,
        alone: false,
        arena: None,
        se_trials: exp.trials.min(200),
    })
    .map_err(Failure::Run)?;
    let path = dir.join("report.html");
    std::fs::write(&path, page)
        .map_err(|e| Failure::Run(format!("cannot write {}: {e}", path.display())))?;
    print_out(&format!("wrote {}\n", path.display()));
    Ok(())
}

/// `run --write-trial K DIR`: trial K's simulated measurements and truth as CSV.
fn write_trial(exp: &build::Experiment, args: &[String]) -> Result<Vec<String>, Failure> {
    let [k, dir] = args else {
        return Err(Failure::Input("--write-trial: expected K DIR".into()));
    };
    let k: usize = k.parse().map_err(|_| {
        Failure::Input(format!("--write-trial: expected a trial number, got {k:?}"))
    })?;
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
    let data = runner::draw_trial(exp, k);
    let mut files = Vec::new();
    for (name, text) in [
        ("measurements.csv", replay::measurements_csv(exp, &data)),
        ("truth.csv", replay::truth_csv(&data)),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, text)
            .map_err(|e| Failure::Run(format!("cannot write {}: {e}", p.display())))?;
        files.push(p.display().to_string());
    }
    Ok(files)
}

struct ReplayArgs<'a> {
    scenario: &'a str,
    measurements: &'a Path,
    truth: Option<&'a Path>,
    out: Option<&'a Path>,
    seed: Option<u64>,
    trial: usize,
    allow_large: bool,
}

/// `hushfuse replay`: every scheme of the scenario on recorded measurements.
fn replay(a: &ReplayArgs) -> Result<(), Failure> {
    let (text, source) = scenario_text(a.scenario)?;
    let read = |p: &Path| {
        std::fs::read_to_string(p)
            .map_err(|e| Failure::Input(format!("{}: cannot read: {e}", p.display())))
    };
    let meas_name = a.measurements.display().to_string();
    let meas = read(a.measurements)?;
    let truth_name = a.truth.map(|p| p.display().to_string());
    let truth = a.truth.map(read).transpose()?;
    let opts = replay::ReplayOptions {
        seed: a.seed,
        trial: a.trial,
        load: build::LoadOptions {
            limits: a.allow_large.then(hushfuse::sim::limits::Limits::none),
            ..Default::default()
        },
    };
    let start = Instant::now();
    let r = replay::replay_csv(
        &text,
        &source,
        (&meas, &meas_name),
        truth.as_deref().zip(truth_name.as_deref()),
        &opts,
    )
    .map_err(|e| match e {
        replay::ReplayError::Input(m) => Failure::Input(m),
        replay::ReplayError::Run(m) => Failure::Run(m),
    })?;
    let elapsed = start.elapsed().as_secs_f64();
    let dir = a
        .out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(format!("{}-replay", r.exp.name)));
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text)
            .map_err(|e| Failure::Run(format!("cannot write {}: {e}", dir.join(name).display())))
    };
    let readings: usize = r
        .recorded
        .available
        .iter()
        .map(|a| a.iter().filter(|&&b| b).count())
        .sum();
    let mut msg = format!(
        "{} — replay of {} ({} steps, {} readings of {} sensors), seed {}, {} scheme variants ({:.1} s)\n",
        r.exp.name,
        meas_name,
        r.exp.steps,
        readings,
        r.exp.system.n_sensors(),
        r.exp.seed,
        r.exp.variants.len(),
        elapsed
    );
    write(
        "estimates.csv",
        &replay::estimates_csv(&r.exp, &r.recorded, &r.replayed),
    )?;
    for n in &r.notes {
        msg.push_str(&format!("note: {n}\n"));
    }
    let mut files = vec!["estimates.csv".to_string()];
    let mut bad = Vec::new();
    if let Some(sums) = &r.replayed.sums {
        let summary = results::summarize(&r.exp, sums);
        msg.push('\n');
        msg.push_str(&results::table(&summary));
        let json =
            serde_json::to_string_pretty(&summary).map_err(|e| Failure::Run(e.to_string()))?;
        write("summary.json", &json)?;
        write("per_step.csv", &results::per_step_csv(&summary))?;
        files.extend(["summary.json".to_string(), "per_step.csv".to_string()]);
        bad = replay::non_finite(&summary);
    } else {
        msg.push_str("(no --truth: estimates only, no error metrics)\n");
    }
    msg.push_str(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    print_out(&msg);
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the replay produced numbers that are not finite (written as null in summary.json):\n  {}",
            bad.join("\n  ")
        )));
    }
    Ok(())
}
