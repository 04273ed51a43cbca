//! `hushfuse` command line: run scenarios, list the built-in ones, reproduce paper figures.
//! This file holds the arguments, the exit codes and the dispatch; each command lives in its
//! own module (`run`: run and reproduce; `merge`; `arena_cmd`: budgets and the quick arena;
//! `report_cmd`; `replay_cmd`). The modules share this file's imports through `use super::*`.
mod arena_cmd;
mod live_cmd;
mod merge;
mod replay_cmd;
mod report_cmd;
mod run;

use arena_cmd::*;
use clap::{Parser, Subcommand};
use hushfuse::engine::calibrate;
use hushfuse::engine::replay;
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::output::arena;
use hushfuse::output::arena_files;
use hushfuse::output::durable;
use hushfuse::output::run as engine_run;
use hushfuse::output::run_files;
use hushfuse::output::tables;
use hushfuse::output::{self, OutputDir};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use merge::*;
use replay_cmd::*;
use report_cmd::*;
use run::*;
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
    /// Tune every scheme's bandwidth knob so that all spend BUDGET per step on the budget axis
    /// (µJ of radio energy by default; bits with --budget-axis payload|frame|total; pilot runs on
    /// common random numbers), then compare them.
    #[arg(long, value_name = "BUDGET", conflicts_with = "budgets")]
    budget: Option<f64>,
    /// Several budgets, comma-separated: accuracy against what is spent, the Pareto front and
    /// the best scheme per budget.
    #[arg(long, value_name = "B1,B2,...")]
    budgets: Option<String>,
    /// What the budget counts: the sensors' radio energy in µJ per step (default: what a
    /// battery-powered deployment pays), uplink payload bits (the papers' count), whole
    /// 802.15.4 frames, or frames plus the downlink feedback.
    #[arg(long, value_name = "payload|frame|total|energy")]
    budget_axis: Option<String>,
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
    /// Run over a lossy link: every packet is lost with probability P (a Bernoulli
    /// `[channel]` replacing the scenario's), the same losses for every scheme; every scheme
    /// with a loss-aware center also runs loss-aware ("… (loss-aware)", link_loss = P). A
    /// `[[schemes]]` entry with a `channel` of its own keeps it.
    #[arg(long, value_name = "P")]
    loss: Option<f64>,
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
        /// Over a lossy link: every packet lost with probability P (as `hushfuse run --loss`),
        /// with the fates of trial K.
        #[arg(long, value_name = "P")]
        loss: Option<f64>,
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
    /// List every link model (`[channel]` kind) with its keys.
    ListLinks {
        /// Print the table as Markdown (the `[channel]` table of docs/scenarios.md).
        #[arg(long)]
        markdown: bool,
    },
    /// The fusion center of a live run: listens for the sensor nodes (UDP), announces each
    /// step, fuses the 802.15.4 frames that arrive, sends the feedback; appends every fused step
    /// to OUT/estimates.csv (flushed).
    Center {
        /// Path of a TOML scenario, or the name of a built-in one.
        scenario: String,
        /// Address to listen on (HOST:PORT).
        #[arg(long, value_name = "HOST:PORT")]
        listen: String,
        #[command(flatten)]
        run: live_cmd::LiveRun,
        #[command(flatten)]
        pacing: live_cmd::Pacing,
        /// Output folder (default: hushfuse-out/<scenario>-live/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Continue an interrupted center from the journal in its output folder.
        #[arg(long)]
        resume: bool,
    },
    /// One sensor node of a live run: reads its measurements (simulated as trial K, from a
    /// recording, or from standard input), runs its scheme's sensor side, sends real 802.15.4
    /// frames to the center.
    Node {
        /// Path of a TOML scenario, or the name of a built-in one.
        scenario: String,
        /// Which sensor (0-based, the order of the scenario's sensors).
        #[arg(long)]
        sensor: usize,
        /// The center's (or the channel proxy's) address.
        #[arg(long, value_name = "HOST:PORT")]
        connect: String,
        #[command(flatten)]
        run: live_cmd::LiveRun,
        /// Recorded measurements (the CSV `hushfuse replay` reads); this sensor's rows are used.
        #[arg(long, value_name = "FILE.csv", conflicts_with = "stdin")]
        measurements: Option<PathBuf>,
        /// Read one line per step from standard input (the components, separated by commas or
        /// spaces; an empty line: no reading).
        #[arg(long)]
        stdin: bool,
        /// Give up after SECS without a word from the center.
        #[arg(long, value_name = "SECS", default_value_t = 60.0)]
        give_up: f64,
    },
    /// A live run on this machine: the center, one node process per sensor, and the channel
    /// proxy when the scenario's link loses packets. Writes the estimates.csv of `replay`.
    Live {
        /// Path of a TOML scenario, or the name of a built-in one.
        scenario: String,
        #[command(flatten)]
        run: live_cmd::LiveRun,
        #[command(flatten)]
        pacing: live_cmd::Pacing,
        /// Recorded measurements (default: trial K simulated).
        #[arg(long, value_name = "FILE.csv")]
        measurements: Option<PathBuf>,
        /// Recorded truth (checked against the measurements' steps).
        #[arg(long, value_name = "FILE.csv")]
        truth: Option<PathBuf>,
        /// Output folder (default: hushfuse-out/<scenario>-live/).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Relay between the nodes and the center that applies the scenario's [channel] with the
    /// simulation's fates (same seed and trial): lost frames are dropped, lost feedback is
    /// taken out of the step's announcement.
    ChannelProxy {
        /// Path of a TOML scenario, or the name of a built-in one.
        scenario: String,
        /// Address the nodes send to (HOST:PORT; port 0: any free port, printed).
        #[arg(long, value_name = "HOST:PORT")]
        listen: String,
        /// The center's address.
        #[arg(long, value_name = "HOST:PORT")]
        center: String,
        #[command(flatten)]
        run: live_cmd::LiveRun,
    },
    /// A fresh key for secured live runs (`[security]`): writes FILE (owner-only) and, beside
    /// it, the frame counter files of the center and of each sensor (docs/live.md).
    Keygen {
        /// Where to write the key (refused if it exists).
        file: PathBuf,
        /// Sensors of the run (counter files for the center and sensors 0..N-1).
        #[arg(long, value_name = "N")]
        sensors: usize,
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

/// Warns that `--threads` above [`runner::max_threads`] is capped there (results do not depend
/// on the count).
fn warn_threads(threads: usize) {
    let max = runner::max_threads();
    if threads > max {
        eprintln!("note: --threads {threads} capped at {max} (eight per core); results do not depend on it");
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(Command::Run { args, .. } | Command::Reproduce { args, .. }) = &cli.command {
        warn_threads(args.threads);
    }
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
                check_budget_options(&args).and_then(|()| run(&scenario, &args, false))
            }
        }
        Some(Command::Reproduce { id, args }) => {
            if args.budget.is_some() || args.budgets.is_some() {
                Err(Failure::Input(format!(
                    "--budget/--budgets apply to `hushfuse run`, not to `reproduce` (try `hushfuse run {id} --budgets ...`)"
                )))
            } else if let Err(e) = check_budget_options(&args) {
                Err(e)
            } else if builtin::get(&id).is_none() && !Path::new(&id).exists() {
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
        Some(Command::ListLinks { markdown }) => {
            print_out(&if markdown {
                hushfuse::network::channel::models::markdown()
            } else {
                hushfuse::network::channel::models::describe()
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
            loss,
        }) => replay(&ReplayArgs {
            scenario: &scenario,
            measurements: &measurements,
            truth: truth.as_deref(),
            out: out.as_deref(),
            seed,
            trial,
            allow_large,
            loss,
        }),
        Some(Command::Center {
            scenario,
            listen,
            run,
            pacing,
            out,
            resume,
        }) => live_cmd::center(&scenario, &listen, &run, &pacing, out.as_deref(), resume),
        Some(Command::Node {
            scenario,
            sensor,
            connect,
            run,
            measurements,
            stdin,
            give_up,
        }) => {
            let source = match (&measurements, stdin) {
                (Some(m), _) => live_cmd::Source::Csv(m),
                (None, true) => live_cmd::Source::Stdin,
                (None, false) => live_cmd::Source::Simulated,
            };
            live_cmd::node(&scenario, sensor, &connect, &run, source, give_up)
        }
        Some(Command::Live {
            scenario,
            run,
            pacing,
            measurements,
            truth,
            out,
        }) => live_cmd::live_all(
            &scenario,
            &run,
            &pacing,
            measurements.as_deref(),
            truth.as_deref(),
            out.as_deref(),
        ),
        Some(Command::ChannelProxy {
            scenario,
            listen,
            center,
            run,
        }) => live_cmd::channel_proxy(&scenario, &listen, &center, &run),
        Some(Command::Keygen { file, sensors }) => live_cmd::keygen(&file, sensors),
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

/// Text and source name of a scenario given as a path or a built-in name.
fn scenario_text(scenario: &str) -> Result<(String, String), Failure> {
    builtin::resolve(scenario, false).map_err(Failure::Input)
}

/// The scenario text with `--loss P` written in: a Bernoulli `[channel]` for every sensor and a
/// loss-aware copy of every scheme that has one ([`hushfuse::scenario::lossy::with_loss`]);
/// unchanged without `--loss`.
fn with_loss(text: String, source: &str, loss: Option<f64>) -> Result<String, Failure> {
    match loss {
        None => Ok(text),
        Some(p) => hushfuse::scenario::lossy::with_loss(&text, source, p)
            .map_err(|e| Failure::Input(e.to_string())),
    }
}
