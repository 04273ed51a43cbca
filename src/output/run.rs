//! The layer above the trial loop that owns a run: its blocks run in windows, stop on request
//! (Ctrl-C), checkpoint, split into shards, resume, merge, and end in the run's files through
//! [`crate::output::run_files`]. The command line and the Python package both call
//! [`execute`] and [`merge`]; they only say how progress is shown and where messages go.
use crate::engine::runner;
use crate::metrics::results::{self, Summary};
use crate::metrics::Sums;
use crate::output::durable::{self, Progress, RunKey, State};
use crate::output::run_files::{self, Results};
use crate::output::{self, OutputDir};
use crate::scenario::build::{self, Experiment};
use crate::scenario::limits;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// A run as asked for: the scenario, the overrides and what to write where.
#[derive(Debug, Clone, Default)]
pub struct Request {
    /// The scenario's text and the name of its source (a path or `built-in:<id>`).
    pub text: String,
    pub source: String,
    pub trials: Option<usize>,
    pub seed: Option<u64>,
    /// Worker threads (0: one per core); the results do not depend on it.
    pub threads: usize,
    /// Lifts the memory and run-time limits.
    pub allow_large: bool,
    /// A reproduction: also `reproduction.md`, and the paper's numbers in the printed text.
    pub reproduce: bool,
    /// Also `report.html`.
    pub report: bool,
    /// The output folder (default `hushfuse-out/<scenario name>`).
    pub out: Option<PathBuf>,
    /// Shard I of N (0-based): runs its blocks and writes a shard file for [`merge`].
    pub shard: Option<(usize, usize)>,
    /// Continue from the folder's checkpoint (from the first trial when there is none).
    pub resume: bool,
    /// Seconds between checkpoints (0: after every window).
    pub checkpoint_every: f64,
}

/// How the caller hears of a run: progress, messages and the results' text.
pub struct Hooks<'a> {
    /// Raised by the caller to stop between trials (the finished blocks are checkpointed).
    pub stop: Option<&'a AtomicBool>,
    /// Called once the experiment is built, before any trial runs.
    pub started: &'a dyn Fn(&Experiment),
    /// Trials finished so far (of the blocks this call runs, counting resumed ones).
    pub progress: &'a (dyn Fn(usize) + Sync),
    /// Notes and warnings (resuming, a checkpoint not saved).
    pub note: &'a dyn Fn(&str),
    /// The results' text, shown before anything is written (a failed write then loses no
    /// number from sight).
    pub show: &'a dyn Fn(&str),
}

impl Default for Hooks<'_> {
    fn default() -> Self {
        Self {
            stop: None,
            started: &|_| {},
            progress: &|_| {},
            note: &|_| {},
            show: &|_| {},
        }
    }
}

/// Why a run ended without results.
#[derive(Debug, Clone, PartialEq)]
pub enum RunFailure {
    /// Bad input: the scenario, the arguments, the output folder, a checkpoint or a shard.
    Input(String),
    /// A valid scenario whose run would pass the machine's memory limit (refused before
    /// anything is allocated).
    TooLarge(String),
    /// The run failed (a scheme could not take a step, a file could not be written).
    Run(String),
    /// Stopped on request: `done` of `total` trials are kept in the checkpoint.
    Interrupted {
        done: usize,
        total: usize,
        checkpoint: PathBuf,
    },
}

impl std::fmt::Display for RunFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunFailure::Input(m) | RunFailure::TooLarge(m) | RunFailure::Run(m) => f.write_str(m),
            RunFailure::Interrupted {
                done,
                total,
                checkpoint,
            } => write!(
                f,
                "interrupted: {done} of {total} trials done, kept in {}",
                checkpoint.display()
            ),
        }
    }
}

impl std::error::Error for RunFailure {}

/// A whole run's results and the files written.
pub struct Finished {
    pub exp: Experiment,
    pub summary: Summary,
    pub dir: PathBuf,
    /// The files written, relative to `dir`, as the manifest lists them.
    pub files: Vec<String>,
    pub elapsed: f64,
    /// Numbers that are not finite (written as null): such a run's results cannot be trusted.
    pub non_finite: Vec<String>,
    /// Variants whose trial failed (their rows are marked failed, their numbers null).
    pub failed: Vec<String>,
}

/// What [`execute`] did.
pub enum Outcome {
    /// A whole run: its results and its folder.
    Whole(Box<Finished>),
    /// One shard: its blocks, in `path`.
    Shard {
        exp: Box<Experiment>,
        path: PathBuf,
        blocks: std::ops::Range<usize>,
        n_blocks: usize,
        elapsed: f64,
    },
    /// A requeued shard whose file is already complete: nothing to do.
    ShardAlreadyDone { path: PathBuf },
}

fn input(e: impl std::fmt::Display) -> RunFailure {
    RunFailure::Input(e.to_string())
}

fn run_err(e: impl std::fmt::Display) -> RunFailure {
    RunFailure::Run(e.to_string())
}

/// Runs `req`: builds the experiment, checks the output folder before any trial, runs (or
/// resumes) its blocks with checkpoints, and writes the run's folder or the shard's file.
pub fn execute(req: &Request, hooks: &Hooks) -> Result<Outcome, RunFailure> {
    if !(req.checkpoint_every >= 0.0 && req.checkpoint_every.is_finite()) {
        return Err(RunFailure::Input(format!(
            "--checkpoint-every: expected a number of seconds >= 0, got {}",
            req.checkpoint_every
        )));
    }
    let options = build::LoadOptions {
        trials: req.trials,
        seed: req.seed,
        threads: req.threads,
        limits: req.allow_large.then(limits::Limits::none),
        ..Default::default()
    };
    let exp = build::load_with(&req.text, &req.source, &options).map_err(|e| match e.limit {
        Some(crate::scenario::error::Limit::Memory) => RunFailure::TooLarge(e.to_string()),
        _ => input(e),
    })?;
    let key = RunKey::new(
        &exp,
        &req.text,
        &req.source,
        req.trials,
        req.seed,
        req.allow_large,
        req.reproduce,
    );
    let dir = req
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(&exp.name));
    // A folder that cannot take the outputs is refused before any trial runs.
    let out_dir = match req.shard {
        None => Some(OutputDir::open(&dir).map_err(RunFailure::Input)?),
        Some(_) => None,
    };
    // Shards of one run share a folder and run at once; each shard (and its checkpoint) is
    // written by one process at a time.
    let _shard_lock = match req.shard {
        Some((i, n)) => Some(
            output::lock_folder(&dir, &format!(".hushfuse-lock-shard-{i:04}-of-{n:04}"))
                .map_err(RunFailure::Input)?,
        ),
        None => None,
    };
    let needed = limits::output_bytes(exp.groups.len(), exp.variants.len(), exp.steps, exp.trials);
    output::check_free_space(&dir, needed).map_err(RunFailure::Input)?;
    let start = Instant::now();
    let checkpoint = dir.join(durable::checkpoint_file_name(req.shard));
    if let (Some((i, n)), true) = (req.shard, req.resume) {
        // A requeued task whose shard is already written has nothing left to do.
        let path = dir.join(durable::shard_file_name(i, n));
        if let Ok(done) = State::read(&path) {
            if key.mismatch(&done.key).is_none() && done.shard == req.shard && done.is_complete() {
                return Ok(Outcome::ShardAlreadyDone { path });
            }
        }
    }
    (hooks.started)(&exp);
    let state = compute(&exp, &key, req, &checkpoint, hooks)?;
    let elapsed = start.elapsed().as_secs_f64();
    let Some(out_dir) = out_dir else {
        let (i, n) = req.shard.expect("a shard run");
        let path = dir.join(durable::shard_file_name(i, n));
        state.write(&path).map_err(RunFailure::Run)?;
        let _ = std::fs::remove_file(&checkpoint);
        return Ok(Outcome::Shard {
            exp: Box::new(exp),
            path,
            blocks: state.start..state.end,
            n_blocks: key.n_blocks,
            elapsed,
        });
    };
    let Progress::Prefix { total, .. } = state.progress else {
        unreachable!("a whole run folds its blocks")
    };
    let finished = write_run(exp, &total, &key, req.report, elapsed, out_dir, hooks)?;
    let _ = std::fs::remove_file(&checkpoint);
    Ok(Outcome::Whole(Box::new(finished)))
}

/// Summarizes a whole run's sums, shows its text, and writes its folder with a manifest of
/// kind `run` (a merged run's folder is the unsharded run's, file for file).
fn write_run(
    exp: Experiment,
    sums: &[Sums],
    key: &RunKey,
    report: bool,
    elapsed: f64,
    mut out_dir: OutputDir,
    hooks: &Hooks,
) -> Result<Finished, RunFailure> {
    let summary = results::summarize(&exp, sums);
    let paper = run_files::paper_section(&exp, &summary);
    (hooks.show)(&run_files::run_text(
        &exp,
        &summary,
        paper.as_ref(),
        elapsed,
        key.reproduce,
    ));
    let as_run = run_files::as_run_text(&key.text, key.trials_override, key.seed_override);
    let parts = run_files::run_parts(&as_run, key.reproduce.then_some(elapsed), report);
    let results = Results {
        exp: &exp,
        summary: Some(&summary),
        paper: paper.as_ref(),
        replay: None,
    };
    run_files::stage(&mut out_dir, "", &results, &parts).map_err(RunFailure::Run)?;
    drop(paper);
    let dir = out_dir.dir().to_path_buf();
    let mut manifest = output::Manifest::new("run", &key.scenario, &key.scenario_sha256);
    manifest.seed = Some(key.seed);
    manifest.trials = Some(key.trials);
    let files = out_dir.commit(manifest, false).map_err(RunFailure::Run)?;
    let non_finite = crate::metrics::finite::non_finite(&summary);
    let failed = results::failed(&summary);
    Ok(Finished {
        exp,
        summary,
        dir,
        files,
        elapsed,
        non_finite,
        failed,
    })
}

/// Trials in blocks `range` of a run of `trials` trials.
fn trials_in(range: std::ops::Range<usize>, trials: usize) -> usize {
    runner::block_trials(range.end, trials).start - runner::block_trials(range.start, trials).start
}

/// The state to start from: the checkpoint with `resume` (checked against this run), else
/// nothing done.
fn starting_state(
    exp: &Experiment,
    key: &RunKey,
    req: &Request,
    checkpoint: &Path,
    hooks: &Hooks,
) -> Result<State, RunFailure> {
    let range = req.shard.map_or(0..key.n_blocks, |(i, n)| {
        durable::shard_blocks(i, n, key.n_blocks)
    });
    if !checkpoint.exists() {
        if req.resume {
            (hooks.note)(&format!(
                "no checkpoint {} to resume from: starting from the first trial",
                checkpoint.display()
            ));
        }
        return Ok(State {
            key: key.clone(),
            shard: req.shard,
            start: range.start,
            end: range.end,
            progress: match req.shard {
                Some(_) => Progress::Blocks(Vec::new()),
                None => Progress::Prefix {
                    next: range.start,
                    total: runner::empty_sums(exp),
                },
            },
        });
    }
    if !req.resume {
        return Err(RunFailure::Input(format!(
            "{} holds the checkpoint of an interrupted run: add --resume to continue it, or remove the file to start over",
            checkpoint.display()
        )));
    }
    let s = State::read(checkpoint).map_err(RunFailure::Input)?;
    let refuse = |why: String| {
        RunFailure::Input(format!(
            "{}: the checkpoint {why}; resume with the arguments of the interrupted run, or remove the file to start over",
            checkpoint.display()
        ))
    };
    if let Some(m) = key.mismatch(&s.key) {
        return Err(refuse(m));
    }
    if s.shard != req.shard || s.start != range.start || s.end != range.end {
        return Err(refuse("is of another shard".into()));
    }
    durable::validate(exp, &s).map_err(refuse)?;
    (hooks.note)(&format!(
        "resuming from {}: {} of {} trials already done",
        checkpoint.display(),
        s.trials_done(),
        trials_in(s.start..s.end, exp.trials)
    ));
    Ok(s)
}

/// Runs the trial blocks of a whole run or of a shard, from its checkpoint with `resume`,
/// checkpointing every `checkpoint_every` seconds and when stopped.
fn compute(
    exp: &Experiment,
    key: &RunKey,
    req: &Request,
    checkpoint: &Path,
    hooks: &Hooks,
) -> Result<State, RunFailure> {
    if let Some(dir) = checkpoint.parent() {
        output::remove_stale_temporaries(dir);
    }
    let mut state = starting_state(exp, key, req, checkpoint, hooks)?;
    // Any number of seconds too large for a Duration means "never" (checked >= 0 and finite).
    let every = Duration::try_from_secs_f64(req.checkpoint_every).unwrap_or(Duration::MAX);
    let mut last_save = Instant::now();
    let mut save_warned = false;
    let (mut saves, mut save_time) = (0usize, 0.0f64);
    let run_start = Instant::now();
    let before = state.trials_done();
    let blocks = state.next_block()..state.end;
    let progress = hooks.progress;
    let completion = runner::run_windows(
        exp,
        runner::RunOptions {
            threads: req.threads,
        },
        blocks,
        hooks.stop,
        &|n| progress(before + n),
        &mut |first, blocks| {
            match &mut state.progress {
                Progress::Prefix { next, total } => {
                    *next = first + blocks.len();
                    for b in blocks.iter() {
                        runner::fold_block(total, b);
                    }
                }
                Progress::Blocks(done) => done.append(blocks),
            }
            if last_save.elapsed() >= every && !state.is_complete() {
                let t = Instant::now();
                saves += 1;
                // A checkpoint that cannot be written costs only the resumability.
                let written = state.write(checkpoint);
                save_time += t.elapsed().as_secs_f64();
                if let Err(e) = written {
                    if !save_warned {
                        (hooks.note)(&format!("warning: checkpoint not saved: {e}"));
                        save_warned = true;
                    }
                }
                last_save = Instant::now();
            }
            Ok(())
        },
    )
    .map_err(run_err)?;
    if std::env::var_os("HUSHFUSE_CHECKPOINT_STATS").is_some() {
        // For measuring the cost of checkpointing (README, "Durable runs").
        (hooks.note)(&format!(
            "checkpoints: {saves} written in {save_time:.4} s of {:.3} s computing ({:.3}%)",
            run_start.elapsed().as_secs_f64(),
            100.0 * save_time / run_start.elapsed().as_secs_f64().max(1e-9)
        ));
    }
    if completion == runner::Completion::Stopped {
        state.write(checkpoint).map_err(|e| {
            RunFailure::Run(format!(
                "interrupted, and the checkpoint could not be saved: {e}"
            ))
        })?;
        return Err(RunFailure::Interrupted {
            done: state.trials_done(),
            total: trials_in(state.start..state.end, exp.trials),
            checkpoint: checkpoint.to_path_buf(),
        });
    }
    Ok(state)
}

/// The outputs of a whole run from the shard files of `execute` with shards (`inputs`: the
/// files, or folders holding them), written into `out` exactly as the unsharded run writes
/// them.
pub fn merge(
    inputs: &[PathBuf],
    out: &Path,
    report: bool,
    hooks: &Hooks,
) -> Result<Finished, RunFailure> {
    let start = Instant::now();
    let (key, exp, order) = check_shard_files(inputs)?;
    let out_dir = OutputDir::open(out).map_err(RunFailure::Input)?;
    // Second pass: the shards in block order, each block folded in turn from empty sums.
    let mut sums = runner::empty_sums(&exp);
    for (start, end, path) in &order {
        let s = State::read(path).map_err(RunFailure::Input)?;
        if s.start != *start || s.end != *end || !s.is_complete() {
            return Err(RunFailure::Input(format!(
                "{}: it changed during the merge",
                path.display()
            )));
        }
        if let Some(m) = key.mismatch(&s.key) {
            return Err(RunFailure::Input(format!(
                "{} {m}: it changed during the merge",
                path.display()
            )));
        }
        durable::validate(&exp, &s)
            .map_err(|e| RunFailure::Input(format!("{}: {e}", path.display())))?;
        if let Progress::Blocks(blocks) = &s.progress {
            for b in blocks {
                runner::fold_block(&mut sums, b);
            }
        }
    }
    (hooks.note)(&format!(
        "merged {} shard files: {} blocks, {} trials",
        order.len(),
        key.n_blocks,
        key.trials
    ));
    let elapsed = start.elapsed().as_secs_f64();
    write_run(exp, &sums, &key, report, elapsed, out_dir, hooks)
}

/// The shard files in block order, checked (one run, every block once, this version), with
/// the run's key and experiment rebuilt. Reads one shard at a time and keeps no sums.
#[allow(clippy::type_complexity)]
fn check_shard_files(
    inputs: &[PathBuf],
) -> Result<(RunKey, Experiment, Vec<(usize, usize, PathBuf)>), RunFailure> {
    let paths = durable::shard_paths(inputs).map_err(RunFailure::Input)?;
    let shards = paths
        .into_iter()
        .map(|p| {
            State::read(&p).map(|mut s| {
                if let Progress::Blocks(b) = &mut s.progress {
                    let n = b.len();
                    *b = vec![Vec::new(); n];
                }
                (p, s)
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(RunFailure::Input)?;
    let mut order: Vec<(usize, usize, PathBuf)> = shards
        .iter()
        .map(|(p, s)| (s.start, s.end, p.clone()))
        .collect();
    order.sort();
    let (key, _) = durable::check_shards(shards).map_err(RunFailure::Input)?;
    let this = env!("CARGO_PKG_VERSION");
    if key.hushfuse_version != this {
        return Err(RunFailure::Input(format!(
            "the shards were written by hushfuse {}; this is hushfuse {this}: merge them with that version",
            key.hushfuse_version
        )));
    }
    let exp = build::load_with(
        &key.text,
        &key.source,
        &build::LoadOptions {
            trials: key.trials_override,
            seed: key.seed_override,
            threads: 0,
            limits: key.allow_large.then(limits::Limits::none),
            ..Default::default()
        },
    )
    .map_err(|e| RunFailure::Input(format!("the shards' scenario: {e}")))?;
    let rebuilt = RunKey::new(
        &exp,
        &key.text,
        &key.source,
        key.trials_override,
        key.seed_override,
        key.allow_large,
        key.reproduce,
    );
    if let Some(m) = key.mismatch(&rebuilt) {
        return Err(RunFailure::Input(format!(
            "the shards' scenario, rebuilt, {m}: the shards are inconsistent"
        )));
    }
    Ok((key, exp, order))
}
