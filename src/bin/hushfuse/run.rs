//! `hushfuse run` and `reproduce`: a Monte Carlo run (with checkpoints, resume and shards), its
//! table, and its outputs; table reproductions; `--write-trial`.
use super::*;

#[derive(Serialize)]
pub(crate) struct Output<'a> {
    #[serde(flatten)]
    summary: &'a results::Summary,
    #[serde(skip_serializing_if = "Option::is_none")]
    paper: Option<PaperOutput<'a>>,
}

#[derive(Serialize)]
pub(crate) struct PaperOutput<'a> {
    citation: &'a str,
    notes: &'a [String],
    published: Vec<report::Comparison>,
    claims: Vec<report::ClaimResult>,
}

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
        limits: args
            .allow_large
            .then(hushfuse::scenario::limits::Limits::none),
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
        Some(_) => None,
    };
    // Shards of one run share a folder and run at once; each shard (and its checkpoint) is
    // written by one process at a time.
    let _shard_lock = match shard {
        Some((i, n)) => Some(
            output::lock_folder(&dir, &format!(".hushfuse-lock-shard-{i:04}-of-{n:04}"))
                .map_err(Failure::Input)?,
        ),
        None => None,
    };
    let needed = hushfuse::scenario::limits::output_bytes(
        exp.groups.len(),
        exp.variants.len(),
        exp.steps,
        exp.trials,
    );
    output::check_free_space(&dir, needed).map_err(Failure::Input)?;
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
pub(crate) fn compute(
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
        durable::validate(exp, &s).map_err(refuse)?;
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
    // Any number of seconds too large for a Duration means "never" (checked >= 0 and finite).
    let every = std::time::Duration::try_from_secs_f64(args.checkpoint_every)
        .unwrap_or(std::time::Duration::MAX);
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
                    *next = first + blocks.len();
                    for b in blocks.iter() {
                        runner::fold_block(total, b);
                    }
                }
                durable::Progress::Blocks(done) => done.append(blocks),
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
pub(crate) fn write_run_outputs(
    exp: &build::Experiment,
    sums: &[hushfuse::metrics::Sums],
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
    // The two large files are streamed into their staged files, never held whole in memory:
    // together they were most of the peak memory of a large run.
    out_dir
        .stage_with("summary.json", |w| {
            serde_json::to_writer_pretty(w, &out).map_err(std::io::Error::from)
        })
        .map_err(Failure::Run)?;
    out_dir
        .stage_with("per_step.csv", |w| results::write_per_step_csv(&summary, w))
        .map_err(Failure::Run)?;
    if let (true, Some(p)) = (reproduce, &out.paper) {
        let md = report::render_markdown(&summary.scenario, elapsed, &p.published, &p.claims);
        out_dir
            .stage("reproduction.md", md.as_bytes())
            .map_err(Failure::Run)?;
    }
    drop(out);
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
pub(crate) fn check_finite(bad: Vec<String>) -> Result<(), Failure> {
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the run produced numbers that are not finite (written as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the scenario's units or check its noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}

/// The scenario text as run: the file with `--trials` and `--seed` written in (comments kept
/// when nothing was overridden).
pub(crate) fn as_run_text(text: &str, args: &RunArgs) -> String {
    if args.trials.is_none() && args.seed.is_none() {
        return text.to_string();
    }
    let Ok(mut t) = toml::from_str::<toml::Table>(text) else {
        return text.to_string();
    };
    if let Some(n) = args.trials {
        let value = i64::try_from(n)
            .map_or_else(|_| toml::Value::String(n.to_string()), toml::Value::Integer);
        t.insert("trials".into(), value);
    }
    if let Some(s) = args.seed {
        // TOML integers are 64-bit signed: a seed above 2^63 - 1 is written as a decimal string,
        // which scenario files accept as well.
        let value = i64::try_from(s)
            .map_or_else(|_| toml::Value::String(s.to_string()), toml::Value::Integer);
        t.insert("seed".into(), value);
    }
    toml::to_string(&t).unwrap_or_else(|_| text.to_string())
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
