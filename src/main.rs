//! `hushfuse` command line: run scenarios, list the built-in ones, reproduce paper figures.
use clap::{Parser, Subcommand};
use hushfuse::sim::{build, builtin, plot, report, results, runner, tables};
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
    about = "Multi-sensor state estimation when sensors must save bandwidth.\nWith no command, runs the built-in default scenario."
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
        None => run("default", &RunArgs::default(), false),
        Some(Command::Run { scenario, args }) => run(&scenario, &args, false),
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
    let path = Path::new(scenario);
    if path.exists() || scenario.ends_with(".toml") {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Failure::Input(format!("{scenario}: cannot read: {e}")))?;
        Ok((text, scenario.to_string()))
    } else if let Some(t) = builtin::get(scenario) {
        Ok((t.to_string(), format!("built-in:{scenario}")))
    } else {
        Err(Failure::Input(format!(
            "{scenario:?} is neither a file nor a built-in scenario (`hushfuse list`)"
        )))
    }
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
    text.push_str(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    print_out(&text);
    let bad = results::non_finite(&summary);
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the run produced numbers that are not finite (written as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}
