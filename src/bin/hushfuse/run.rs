//! `hushfuse run` and `reproduce`: a Monte Carlo run (with checkpoints, resume and shards), its
//! table, and its outputs; table reproductions; `--write-trial`.
use super::*;

/// A computed table reproduction (no Monte Carlo): ours beside the paper's printed values.
pub(crate) fn table_report(text: &str, source: &str, args: &RunArgs) -> Result<(), Failure> {
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
pub(crate) static STOP: AtomicBool = AtomicBool::new(false);

pub(crate) fn install_stop_handler() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
}

/// The command line of this process with `--resume` added (for the message of a stopped run).
pub(crate) fn resume_command() -> String {
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

pub(crate) fn run(scenario: &str, args: &RunArgs, reproduce: bool) -> Result<(), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let kind = build::file_kind(&text, &source).map_err(|e| Failure::Input(e.to_string()))?;
    if kind == build::FileKind::TableReport {
        if args.shard.is_some() || args.resume {
            return Err(Failure::Input(format!(
                "{source}: a table reproduction runs no trials; --shard and --resume do not apply"
            )));
        }
        return table_report(&text, &source, args);
    }
    let text = with_loss(text, &source, args.loss)?;
    // From here on Ctrl-C stops the run cleanly (a signal before the first trial: a checkpoint
    // of nothing, and exit 130).
    install_stop_handler();
    let shard = args
        .shard
        .as_deref()
        .map(durable::parse_shard)
        .transpose()
        .map_err(Failure::Input)?;
    let request = engine_run::Request {
        text,
        source,
        trials: args.trials,
        seed: args.seed,
        threads: args.threads,
        allow_large: args.allow_large,
        reproduce,
        report: args.report,
        out: args.out.clone(),
        shard,
        resume: args.resume,
        checkpoint_every: args.checkpoint_every,
    };
    let start = Instant::now();
    let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} trials ({eta} left)")
            .expect("static template")
            .progress_chars("=> "),
    );
    let shown = AtomicBool::new(false);
    let interactive = std::io::stderr().is_terminal();
    let started = |exp: &build::Experiment| {
        bar.set_length(exp.trials as u64);
        bar.set_message(exp.name.clone());
    };
    let progress = |done: usize| {
        // Only for runs longer than a second, and only on a terminal.
        if interactive && !shown.load(Ordering::Relaxed) && start.elapsed().as_secs_f64() > 1.0 {
            shown.store(true, Ordering::Relaxed);
            bar.set_draw_target(ProgressDrawTarget::stderr());
        }
        bar.set_position(done as u64);
    };
    let show = |text: &str| {
        bar.finish_and_clear();
        print_out(text);
    };
    let hooks = engine_run::Hooks {
        stop: Some(&STOP),
        started: &started,
        progress: &progress,
        note: &|m| eprintln!("{m}"),
        show: &show,
    };
    let outcome = engine_run::execute(&request, &hooks);
    bar.finish_and_clear();
    match outcome.map_err(failure)? {
        engine_run::Outcome::ShardAlreadyDone { path } => {
            let (i, n) = shard.expect("a shard run");
            print_out(&format!(
                "shard {i}/{n} is already done: {}\n",
                path.display()
            ));
            Ok(())
        }
        engine_run::Outcome::Shard {
            exp,
            path,
            blocks,
            n_blocks,
            elapsed,
        } => {
            let (i, n) = shard.expect("a shard run");
            let trials = runner::block_trials(blocks.start, exp.trials).start
                ..runner::block_trials(blocks.end, exp.trials).start;
            let dir = path.parent().unwrap_or(Path::new("."));
            print_out(&format!(
                "{} — shard {i}/{n}: blocks {}..{} of {} (trials {}..{} of {}), {:.1} s\nwrote {}\nwhen all {n} shards are done: hushfuse merge {} --out <folder>\n",
                exp.name,
                blocks.start,
                blocks.end,
                n_blocks,
                trials.start,
                trials.end,
                exp.trials,
                elapsed,
                path.display(),
                dir.display()
            ));
            Ok(())
        }
        engine_run::Outcome::Whole(done) => {
            // Trial K's data for `hushfuse replay`, outside the output folder (hidden option).
            let extra = match &args.write_trial {
                Some(wt) => write_trial(&done.exp, wt)?,
                None => Vec::new(),
            };
            wrote(&done, extra);
            check_failed(&done.failed)?;
            check_finite(done.non_finite)
        }
    }
}

/// Prints where a finished run's files went.
pub(crate) fn wrote(done: &engine_run::Finished, extra: Vec<String>) {
    let mut files = done.files.clone();
    files.extend(extra);
    print_out(&format!(
        "\nwrote {}: {}\n",
        done.dir.display(),
        files.join(", ")
    ));
}

/// The command line's failure for an engine's: an interrupted run says how to continue it.
pub(crate) fn failure(e: engine_run::RunFailure) -> Failure {
    match e {
        engine_run::RunFailure::Input(m) | engine_run::RunFailure::TooLarge(m) => Failure::Input(m),
        engine_run::RunFailure::Run(m) => Failure::Run(m),
        stopped @ engine_run::RunFailure::Interrupted { .. } => {
            Failure::Interrupted(format!("{stopped}\ncontinue with: {}", resume_command()))
        }
    }
}

/// A run with a variant whose trial failed fails (after writing the others' results).
pub(crate) fn check_failed(failed: &[String]) -> Result<(), Failure> {
    if !failed.is_empty() {
        return Err(Failure::Run(format!(
            "a scheme's trial failed (its row is marked failed, its numbers null in summary.json; the other schemes finished):\n  {}",
            failed.join("\n  ")
        )));
    }
    Ok(())
}

/// A run whose numbers are not all finite fails (after writing them, as null).
pub(crate) fn check_finite(bad: Vec<String>) -> Result<(), Failure> {
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the run produced numbers that are not finite (written as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}

/// `run --write-trial K DIR`: trial K's simulated measurements and truth as CSV.
pub(crate) fn write_trial(
    exp: &build::Experiment,
    args: &[String],
) -> Result<Vec<String>, Failure> {
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
