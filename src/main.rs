//! `hushfuse` command line: run scenarios, list the built-in ones, reproduce paper figures.
use clap::{Parser, Subcommand};
use hushfuse::sim::durable::{self, State};
use hushfuse::sim::output::{self, OutputDir};
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
    /// Continue an interrupted run from the checkpoint in its output folder (same scenario and
    /// arguments); starts from the first trial when there is none.
    #[arg(long)]
    resume: bool,
    /// Run only shard I of N (1 <= I <= N; a fixed, contiguous part of the trial blocks) and
    /// write OUT/shard-I-of-N.hfshard; `hushfuse merge` turns the N shards into the outputs.
    #[arg(long, value_name = "I/N")]
    shard: Option<String>,
    /// Seconds between checkpoints of finished trial blocks (0: after every window of blocks).
    #[arg(long, default_value_t = 10.0, value_name = "SECS")]
    checkpoint_every: f64,
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
    /// Merge the shard files of `run --shard I/N` (files, or folders holding them) into the
    /// outputs of the whole run, byte for byte those of an unsharded run.
    Merge {
        /// Shard files (*.hfshard) or folders holding them.
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Also write report.html.
        #[arg(long)]
        report: bool,
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

/// Exit codes: 2 for bad input (scenario, arguments), 1 for a failed run, 130 for a run
/// stopped by Ctrl-C (its finished trials kept in a checkpoint).
enum Failure {
    Input(String),
    Run(String),
    Interrupted(String),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => quick_arena(),
        Some(Command::Run { scenario, args }) => {
            if args.budget.is_some() || args.budgets.is_some() {
                if args.shard.is_some() || args.resume {
                    Err(Failure::Input(
                        "--shard and --resume apply to plain runs, not to --budget/--budgets"
                            .into(),
                    ))
                } else {
                    arena_run(&scenario, &args).map(|_| ())
                }
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
        Some(Command::Merge {
            shards,
            out,
            report,
        }) => merge(&shards, &out, report),
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
        Err(Failure::Interrupted(m)) => {
            eprintln!("{m}");
            ExitCode::from(130)
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
    let out = tables::render(&file, &rows);
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&file.name));
    let mut out_dir = OutputDir::open(&dir).map_err(Failure::Input)?;
    let json =
        serde_json::json!({ "scenario": file.name, "citation": file.citation, "rows": rows });
    print_out(&out);
    out_dir
        .stage(
            "summary.json",
            serde_json::to_string_pretty(&json)
                .expect("serializable")
                .as_bytes(),
        )
        .map_err(Failure::Run)?;
    let hash = output::sha256_hex(format!("{source}\0{text}").as_bytes());
    out_dir
        .commit(output::Manifest::new("table", &file.name, &hash), false)
        .map_err(Failure::Run)?;
    print_out(&format!("\nwrote {}\n", dir.join("summary.json").display()));
    Ok(())
}

/// Raised by the first Ctrl-C (SIGINT): the runner stops between trials and the finished
/// blocks are checkpointed. A second Ctrl-C ends the process at once.
static STOP: AtomicBool = AtomicBool::new(false);

fn install_stop_handler() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
}

/// The command line of this process with `--resume` added (for the message of a stopped run).
fn resume_command() -> String {
    let mut args: Vec<String> = std::env::args().collect();
    if let Some(first) = args.first_mut() {
        *first = "hushfuse".into();
    }
    if !args.iter().any(|a| a == "--resume") {
        args.push("--resume".into());
    }
    args.iter()
        .map(|a| {
            if a.is_empty() || a.contains(|c: char| c.is_whitespace() || "'\"$\\;&|".contains(c)) {
                format!("'{}'", a.replace('\'', r"'\''"))
            } else {
                a.clone()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn run(scenario: &str, args: &RunArgs, reproduce: bool) -> Result<(), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let text_in = text.clone();
    let kind = build::file_kind(&text, &source).map_err(|e| Failure::Input(e.to_string()))?;
    if kind == build::FileKind::TableReport {
        if args.shard.is_some() || args.resume {
            return Err(Failure::Input(format!(
                "{source}: a table reproduction runs no trials; --shard and --resume do not apply"
            )));
        }
        return table_report(&text, &source, args);
    }
    // From here on Ctrl-C stops the run cleanly (a signal before the first trial: a checkpoint
    // of nothing, and exit 130).
    install_stop_handler();
    let shard = args
        .shard
        .as_deref()
        .map(durable::parse_shard)
        .transpose()
        .map_err(Failure::Input)?;
    if !(args.checkpoint_every >= 0.0 && args.checkpoint_every.is_finite()) {
        return Err(Failure::Input(format!(
            "--checkpoint-every: expected a number of seconds >= 0, got {}",
            args.checkpoint_every
        )));
    }
    let options = build::LoadOptions {
        trials: args.trials,
        seed: args.seed,
        threads: args.threads,
        limits: args.allow_large.then(hushfuse::sim::limits::Limits::none),
    };
    let exp =
        build::load_with(&text, &source, &options).map_err(|e| Failure::Input(e.to_string()))?;
    let key = durable::RunKey::new(
        &exp,
        &text_in,
        &source,
        args.trials,
        args.seed,
        args.allow_large,
        reproduce,
    );
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&exp.name));
    // A folder that cannot take the outputs is refused before any trial runs.
    let out_dir = match shard {
        None => Some(OutputDir::open(&dir).map_err(Failure::Input)?),
        Some(_) => {
            std::fs::create_dir_all(&dir)
                .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
            None
        }
    };
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
    let checkpoint = dir.join(durable::checkpoint_file_name(shard));
    if let (Some((i, n)), true) = (shard, args.resume) {
        // A requeued task whose shard is already written has nothing left to do.
        let path = dir.join(durable::shard_file_name(i, n));
        if let Ok(done) = State::read(&path) {
            if key.mismatch(&done.key).is_none() && done.shard == shard && done.is_complete() {
                print_out(&format!(
                    "shard {i}/{n} is already done: {}\n",
                    path.display()
                ));
                return Ok(());
            }
        }
    }
    let state = compute(&exp, &key, shard, &checkpoint, args, &progress);
    bar.finish_and_clear();
    let state = state?;
    let elapsed = start.elapsed().as_secs_f64();
    let Some(out_dir) = out_dir else {
        let (i, n) = shard.expect("a shard run");
        let path = dir.join(durable::shard_file_name(i, n));
        state.write(&path).map_err(Failure::Run)?;
        let _ = std::fs::remove_file(&checkpoint);
        let trials = runner::block_trials(state.start, exp.trials).start
            ..runner::block_trials(state.end, exp.trials).start;
        print_out(&format!(
            "{} — shard {i}/{n}: blocks {}..{} of {} (trials {}..{} of {}), {:.1} s\nwrote {}\nwhen all {n} shards are done: hushfuse merge {} --out <folder>\n",
            exp.name,
            state.start,
            state.end,
            key.n_blocks,
            trials.start,
            trials.end,
            exp.trials,
            elapsed,
            path.display(),
            dir.display()
        ));
        return Ok(());
    };
    let durable::Progress::Prefix { total, .. } = &state.progress else {
        unreachable!("a whole run folds its blocks")
    };
    let bad = write_run_outputs(
        &exp, total, &text_in, args, reproduce, elapsed, out_dir, "run", &key,
    )?;
    let _ = std::fs::remove_file(&checkpoint);
    check_finite(bad)
}

/// Runs the trial blocks of a whole run (`shard` None) or of a shard, from its checkpoint
/// with `--resume`, checkpointing every `--checkpoint-every` seconds and when stopped.
fn compute(
    exp: &build::Experiment,
    key: &durable::RunKey,
    shard: Option<(usize, usize)>,
    checkpoint: &Path,
    args: &RunArgs,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<State, Failure> {
    if let Some(dir) = checkpoint.parent() {
        output::remove_stale_temporaries(dir);
    }
    let range = shard.map_or(0..key.n_blocks, |(i, n)| {
        durable::shard_blocks(i, n, key.n_blocks)
    });
    let mut state = if checkpoint.exists() {
        if !args.resume {
            return Err(Failure::Input(format!(
                "{} holds the checkpoint of an interrupted run: add --resume to continue it, or remove the file to start over",
                checkpoint.display()
            )));
        }
        let s = State::read(checkpoint).map_err(Failure::Input)?;
        let refuse = |why: String| {
            Failure::Input(format!(
                "{}: the checkpoint {why}; resume with the arguments of the interrupted run, or remove the file to start over",
                checkpoint.display()
            ))
        };
        if let Some(m) = key.mismatch(&s.key) {
            return Err(refuse(m));
        }
        if s.shard != shard || s.start != range.start || s.end != range.end {
            return Err(refuse("is of another shard".into()));
        }
        durable::check_shape(exp, &s).map_err(refuse)?;
        eprintln!(
            "resuming from {}: {} of {} trials already done",
            checkpoint.display(),
            s.trials_done(),
            runner::block_trials(s.end, exp.trials).start
                - runner::block_trials(s.start, exp.trials).start
        );
        s
    } else {
        if args.resume {
            eprintln!(
                "no checkpoint {} to resume from: starting from the first trial",
                checkpoint.display()
            );
        }
        State {
            key: key.clone(),
            shard,
            start: range.start,
            end: range.end,
            progress: match shard {
                Some(_) => durable::Progress::Blocks(Vec::new()),
                None => durable::Progress::Prefix {
                    next: range.start,
                    total: runner::empty_sums(exp),
                },
            },
        }
    };
    let every = std::time::Duration::from_secs_f64(args.checkpoint_every);
    let mut last_save = Instant::now();
    let mut save_warned = false;
    let (mut saves, mut save_time) = (0usize, 0.0f64);
    let run_start = Instant::now();
    let before = state.trials_done();
    let blocks = state.next_block()..state.end;
    let completion = runner::run_windows(
        exp,
        runner::RunOptions {
            threads: args.threads,
        },
        blocks,
        Some(&STOP),
        &|n| progress(before + n),
        &mut |first, blocks| {
            match &mut state.progress {
                durable::Progress::Prefix { next, total } => {
                    for b in &blocks {
                        runner::fold_block(total, b);
                    }
                    *next = first + blocks.len();
                }
                durable::Progress::Blocks(done) => done.extend(blocks),
            }
            if last_save.elapsed() >= every && !state.is_complete() {
                let t = Instant::now();
                saves += 1;
                // A checkpoint that cannot be written costs only the resumability.
                let written = state.write(checkpoint);
                save_time += t.elapsed().as_secs_f64();
                if let Err(e) = written {
                    if !save_warned {
                        eprintln!("warning: checkpoint not saved: {e}");
                        save_warned = true;
                    }
                }
                last_save = Instant::now();
            }
            Ok(())
        },
    )
    .map_err(|e| Failure::Run(e.to_string()))?;
    if std::env::var_os("HUSHFUSE_CHECKPOINT_STATS").is_some() {
        // For measuring the cost of checkpointing (README, "Durable runs").
        eprintln!(
            "checkpoints: {saves} written in {save_time:.4} s of {:.3} s computing ({:.3}%)",
            run_start.elapsed().as_secs_f64(),
            100.0 * save_time / run_start.elapsed().as_secs_f64().max(1e-9)
        );
    }
    if completion == runner::Completion::Stopped {
        state.write(checkpoint).map_err(|e| {
            Failure::Run(format!(
                "interrupted, and the checkpoint could not be saved: {e}"
            ))
        })?;
        return Err(Failure::Interrupted(format!(
            "interrupted: {} of {} trials done, kept in {}\ncontinue with: {}",
            state.trials_done(),
            runner::block_trials(state.end, exp.trials).start
                - runner::block_trials(state.start, exp.trials).start,
            checkpoint.display(),
            resume_command()
        )));
    }
    Ok(state)
}

/// Prints the table of a finished run, then writes its outputs into `out_dir` (all or
/// nothing) with a manifest.
#[allow(clippy::too_many_arguments)]
fn write_run_outputs(
    exp: &build::Experiment,
    sums: &[hushfuse::sim::metrics::Sums],
    text_in: &str,
    args: &RunArgs,
    reproduce: bool,
    elapsed: f64,
    mut out_dir: OutputDir,
    kind: &str,
    key: &durable::RunKey,
) -> Result<Vec<String>, Failure> {
    let summary = results::summarize(exp, sums);
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
            published: report::compare_published(exp, &summary),
            claims: report::check_claims(exp, &summary),
        })
    } else {
        None
    };
    if reproduce {
        if let Some(p) = &paper {
            text.push_str(&format!(
                "\n{}\n",
                report::render(exp, &p.published, &p.claims)
            ));
        }
    }
    // The results first: a failed write below loses no computed number from sight.
    print_out(&text);

    let out = Output {
        summary: &summary,
        paper,
    };
    let json = serde_json::to_string_pretty(&out).map_err(|e| Failure::Run(e.to_string()))?;
    let mut stage = |name: &str, text: &str| out_dir.stage(name, text.as_bytes());
    stage("summary.json", &json).map_err(Failure::Run)?;
    stage("per_step.csv", &results::per_step_csv(&summary)).map_err(Failure::Run)?;
    if let (true, Some(p)) = (reproduce, &out.paper) {
        let md = report::render_markdown(&summary.scenario, elapsed, &p.published, &p.claims);
        stage("reproduction.md", &md).map_err(Failure::Run)?;
    }
    let plots = plot::write_all(exp, &summary, out_dir.staging().map_err(Failure::Run)?)
        .map_err(Failure::Run)?;
    out_dir.record(plots);
    let as_run = as_run_text(text_in, args);
    out_dir
        .stage("scenario_as_run.toml", as_run.as_bytes())
        .map_err(Failure::Run)?;
    if args.report {
        let page = html::render(&html::Input {
            exp,
            summary: &summary,
            scenario_text: &as_run,
            alone: false,
            arena: None,
            se_trials: exp.trials.min(200),
        })
        .map_err(Failure::Run)?;
        out_dir
            .stage("report.html", page.as_bytes())
            .map_err(Failure::Run)?;
    }
    // Trial K's data for `hushfuse replay`, outside the output folder (hidden option).
    let extra = match &args.write_trial {
        Some(wt) => write_trial(exp, wt)?,
        None => Vec::new(),
    };
    let dir = out_dir.dir().to_path_buf();
    let mut manifest = output::Manifest::new(kind, &key.scenario, &key.scenario_sha256);
    manifest.seed = Some(key.seed);
    manifest.trials = Some(key.trials);
    let mut files = out_dir.commit(manifest, false).map_err(Failure::Run)?;
    files.extend(extra);
    print_out(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    Ok(results::non_finite(&summary))
}

/// A run whose numbers are not all finite fails (after writing them, as null).
fn check_finite(bad: Vec<String>) -> Result<(), Failure> {
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the run produced numbers that are not finite (written as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}

/// `hushfuse merge`: the outputs of a whole run from the shard files of `run --shard I/N`.
fn merge(inputs: &[PathBuf], out: &Path, report: bool) -> Result<(), Failure> {
    let start = Instant::now();
    let paths = durable::shard_paths(inputs).map_err(Failure::Input)?;
    // First pass: every file read and checked, its sums dropped (memory: one shard at a time).
    let shards = paths
        .into_iter()
        .map(|p| {
            State::read(&p).map(|mut s| {
                if let durable::Progress::Blocks(b) = &mut s.progress {
                    let n = b.len();
                    *b = vec![Vec::new(); n];
                }
                (p, s)
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(Failure::Input)?;
    let n_files = shards.len();
    let mut order: Vec<(usize, usize, PathBuf)> = shards
        .iter()
        .map(|(p, s)| (s.start, s.end, p.clone()))
        .collect();
    order.sort();
    let (key, _) = durable::check_shards(shards).map_err(Failure::Input)?;
    let this = env!("CARGO_PKG_VERSION");
    if key.hushfuse_version != this {
        return Err(Failure::Input(format!(
            "the shards were written by hushfuse {}; this is hushfuse {this}: merge them with that version",
            key.hushfuse_version
        )));
    }
    let args = RunArgs {
        trials: key.trials_override,
        seed: key.seed_override,
        allow_large: key.allow_large,
        out: Some(out.to_path_buf()),
        report,
        ..Default::default()
    };
    let exp = build::load_with(
        &key.text,
        &key.source,
        &build::LoadOptions {
            trials: args.trials,
            seed: args.seed,
            threads: 0,
            limits: args.allow_large.then(hushfuse::sim::limits::Limits::none),
        },
    )
    .map_err(|e| Failure::Input(format!("the shards' scenario: {e}")))?;
    let rebuilt = durable::RunKey::new(
        &exp,
        &key.text,
        &key.source,
        key.trials_override,
        key.seed_override,
        key.allow_large,
        key.reproduce,
    );
    if let Some(m) = key.mismatch(&rebuilt) {
        return Err(Failure::Input(format!(
            "the shards' scenario, rebuilt, {m}: the shards are inconsistent"
        )));
    }
    let out_dir = OutputDir::open(out).map_err(Failure::Input)?;
    // Second pass: the shards in block order, each block folded in turn from empty sums.
    let mut sums = runner::empty_sums(&exp);
    for (start, end, path) in &order {
        let s = State::read(path).map_err(Failure::Input)?;
        if s.start != *start || s.end != *end || !s.is_complete() {
            return Err(Failure::Input(format!(
                "{}: it changed during the merge",
                path.display()
            )));
        }
        if let Some(m) = key.mismatch(&s.key) {
            return Err(Failure::Input(format!(
                "{} {m}: it changed during the merge",
                path.display()
            )));
        }
        durable::check_shape(&exp, &s)
            .map_err(|e| Failure::Input(format!("{}: {e}", path.display())))?;
        if let durable::Progress::Blocks(blocks) = &s.progress {
            for b in blocks {
                runner::fold_block(&mut sums, b);
            }
        }
    }
    eprintln!(
        "merged {n_files} shard files: {} blocks, {} trials",
        key.n_blocks, key.trials
    );
    let bad = write_run_outputs(
        &exp,
        &sums,
        &key.text,
        &args,
        key.reproduce,
        start.elapsed().as_secs_f64(),
        out_dir,
        // The same manifest as the unsharded run's: every file of the folder is the same.
        "run",
        &key,
    )?;
    check_finite(bad)
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
    // The output folder is checked before the calibration runs, when its name is known.
    let named_dir = args.out.clone().or_else(|| {
        toml::from_str::<toml::Table>(&text)
            .ok()
            .and_then(|t| t.get("name").and_then(|n| n.as_str().map(str::to_string)))
            .filter(|n| build::check_name(n).is_ok())
            .map(|n| PathBuf::from("hushfuse-out").join(n))
    });
    let early_dir = named_dir
        .as_deref()
        .map(OutputDir::open)
        .transpose()
        .map_err(Failure::Input)?;
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
    let mut out_dir = match early_dir {
        Some(d) if d.dir() == dir => d,
        _ => OutputDir::open(&dir).map_err(Failure::Input)?,
    };
    // The results first: a failed write below loses no computed number from sight.
    print_out(&msg);
    let mut write =
        |name: &str, text: &str| out_dir.stage(name, text.as_bytes()).map_err(Failure::Run);
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
    let plots = arena::write_plots(
        &out,
        &group,
        &first.scenario,
        out_dir.staging().map_err(Failure::Run)?,
    )
    .map_err(Failure::Run)?;
    out_dir.record(plots.iter().cloned());
    files.extend(plots);
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
        out_dir
            .stage("report.html", page.as_bytes())
            .map_err(Failure::Run)?;
        files.push("report.html".into());
    }
    let hash = output::sha256_hex(
        format!(
            "{source}\0{text}\0{:?}\0{:?}\0{:?}\0{}\0{:?}",
            args.trials, args.seed, budgets, args.budget_axis, args.pilot_trials
        )
        .as_bytes(),
    );
    let mut manifest = output::Manifest::new("arena", &first.scenario, &hash);
    manifest.seed = Some(first.seed);
    manifest.trials = Some(first.trials);
    out_dir.commit(manifest, false).map_err(Failure::Run)?;
    print_out(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
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
        output::write_file(&p, text.as_bytes()).map_err(Failure::Run)?;
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
    // Staged and committed with a manifest, like every run's output (all or nothing).
    let mut out_dir = OutputDir::open(&dir).map_err(Failure::Input)?;
    let mut staged: Vec<(&str, String)> = Vec::new();
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
    staged.push((
        "estimates.csv",
        replay::estimates_csv(&r.exp, &r.recorded, &r.replayed),
    ));
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
        staged.push(("summary.json", json));
        staged.push(("per_step.csv", results::per_step_csv(&summary)));
        files.extend(["summary.json".to_string(), "per_step.csv".to_string()]);
        bad = replay::non_finite(&summary);
    } else {
        msg.push_str("(no --truth: estimates only, no error metrics)\n");
    }
    // The results first: a failed write below loses nothing from sight.
    print_out(&msg);
    msg.clear();
    for (name, text) in &staged {
        out_dir.stage(name, text.as_bytes()).map_err(Failure::Run)?;
    }
    let mut manifest =
        output::Manifest::new("replay", &r.exp.name, &output::sha256_hex(text.as_bytes()));
    manifest.seed = Some(r.exp.seed);
    manifest.trials = Some(1);
    out_dir.commit(manifest, false).map_err(Failure::Run)?;
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
