//! `hushfuse run --budget/--budgets` (the arena: calibration to bit budgets) and the quick
//! arena of `hushfuse` without arguments.
use super::*;

/// Budgets from `--budget` or `--budgets`: positive finite numbers, no two equal.
pub(crate) fn budgets_of(args: &RunArgs) -> Result<Vec<f64>, Failure> {
    if args.pilot_trials == Some(0) {
        return Err(Failure::Input(
            "--pilot-trials: expected at least 1 trial per pilot run, got 0".into(),
        ));
    }
    if let Some(b) = args.budget {
        if !(b.is_finite() && b > 0.0) {
            // The unit of the axis: energy (the default) is µJ, the others bits.
            let unit = match args.budget_axis.as_deref() {
                None | Some("energy") => "µJ",
                Some(_) => "bits",
            };
            return Err(Failure::Input(format!(
                "--budget: expected a positive finite number of {unit} per step, got {b}"
            )));
        }
        return Ok(vec![b]);
    }
    let text = args.budgets.as_deref().unwrap_or_default();
    let mut out: Vec<f64> = Vec::new();
    for t in text.split(',') {
        let b = t
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|b| b.is_finite() && *b > 0.0)
            .ok_or_else(|| {
                Failure::Input(format!(
                    "--budgets: expected positive finite numbers separated by commas, got {:?}",
                    t.trim()
                ))
            })?;
        if out.contains(&b) {
            return Err(Failure::Input(format!(
                "--budgets: the budget {:?} is given twice (as numbers they are equal); give each budget once",
                t.trim()
            )));
        }
        out.push(b);
    }
    Ok(out)
}

/// The `--budget-axis` given, or `energy` (the default, also in the output hash): what a
/// battery-powered deployment pays (docs/scenarios.md, "Which axis").
pub(crate) fn budget_axis(args: &RunArgs) -> &str {
    args.budget_axis.as_deref().unwrap_or("energy")
}

/// Refuses energy budgets below what the sensors spend asleep (no scheme spends less): most
/// likely bits given without `--budget-axis`.
fn check_energy_budgets(
    axis: calibrate::Axis,
    exp: Option<&build::Experiment>,
    budgets: &[f64],
    given: bool,
) -> Result<(), Failure> {
    let Some(exp) = exp else {
        return Ok(());
    };
    match calibrate::energy_floor_problem(exp, axis, budgets) {
        Some(m) => Err(Failure::Input(format!(
            "{m}{}",
            if given {
                ""
            } else {
                ": budgets are on the energy axis by default (µJ per step); for bits give --budget-axis payload, frame or total"
            }
        ))),
        None => Ok(()),
    }
}

/// Refuses the budget options that mean nothing without `--budget`/`--budgets` (for plain runs).
pub(crate) fn check_budget_options(args: &RunArgs) -> Result<(), Failure> {
    if args.budget.is_some() || args.budgets.is_some() {
        return Ok(());
    }
    for (given, name) in [
        (args.budget_axis.is_some(), "--budget-axis"),
        (args.pilot_trials.is_some(), "--pilot-trials"),
    ] {
        if given {
            return Err(Failure::Input(format!(
                "{name} applies only with --budget or --budgets"
            )));
        }
    }
    Ok(())
}

/// `run --budget` / `--budgets`: calibrate every scheme to each budget, print and write the
/// comparison. Returns the outcome and the output folder.
pub(crate) fn arena_run(
    scenario: &str,
    args: &RunArgs,
) -> Result<(calibrate::Outcome, PathBuf), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let text = with_loss(text, &source, args.loss)?;
    let budgets = budgets_of(args)?;
    let early_dir = early_out_dir(args, &text)?;
    let axis = calibrate::Axis::parse(budget_axis(args)).map_err(Failure::Input)?;
    let load = build::LoadOptions {
        trials: args.trials,
        seed: args.seed,
        threads: args.threads,
        limits: args
            .allow_large
            .then(hushfuse::scenario::limits::Limits::none),
        ..Default::default()
    };
    // The scenario as run, loaded once for the checks before the first pilot run (one that does
    // not load is reported by the calibration with its full message).
    let loaded = build::load_with(&text, &source, &load).ok();
    check_energy_budgets(axis, loaded.as_ref(), &budgets, args.budget_axis.is_some())?;
    // Room for one run's output per budget, checked before the first pilot run.
    if let (Some(d), Some(exp)) = (&early_dir, &loaded) {
        arena_files::check_room(d.dir(), exp, budgets.len()).map_err(Failure::Input)?;
    }
    if let (Some(p), Some(exp)) = (args.pilot_trials, &loaded) {
        if p > exp.trials {
            eprintln!(
                "note: --pilot-trials {p} is more than the run's {} trials: the pilot runs use {}",
                exp.trials, exp.trials
            );
        }
    }
    let opts = calibrate::Options {
        axis,
        pilot_trials: args.pilot_trials,
        threads: args.threads,
        load,
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
    check_finite(arena_files::non_finite(&out))?;
    let first = &out.summaries[0];
    let group = first.group_order[0].clone();
    let msg = arena_message(&out, &budgets, &axis, elapsed, &group);
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
    let files = arena_files::stage(
        &mut out_dir,
        &out,
        elapsed,
        (&source, &opts.load),
        args.report,
    )
    .map_err(Failure::Run)?;
    let hash = arena_files::inputs_sha256(&text, &source, &budgets, &opts);
    arena_files::commit(out_dir, &out, &hash).map_err(Failure::Run)?;
    print_out(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    Ok((out, dir))
}

/// The arena's output folder when its name is known before the calibration runs (`--out`, or
/// the scenario's valid `name`), opened (checked) early.
fn early_out_dir(args: &RunArgs, text: &str) -> Result<Option<OutputDir>, Failure> {
    // The output folder is checked before the calibration runs, when its name is known.
    let named_dir = args.out.clone().or_else(|| {
        toml::from_str::<toml::Table>(text)
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
    Ok(early_dir)
}

/// The printed comparison: the headline, one table per budget, the best scheme per budget.
fn arena_message(
    out: &calibrate::Outcome,
    budgets: &[f64],
    axis: &calibrate::Axis,
    elapsed: f64,
    group: &str,
) -> String {
    let first = &out.summaries[0];
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
            "\nbudget {} {}/step (tolerance {}%):\n",
            calibrate::short(*budget),
            axis.unit(),
            calibrate::short(100.0 * out.tolerance)
        ));
        msg.push_str(&arena::budget_table(out, b, group));
        // The health of each scheme at this budget, worded as a plain run words it.
        msg.push_str(&results::warning_block(&out.summaries[b]));
        msg.push_str(&hushfuse::metrics::notes::block(&out.summaries[b]));
    }
    msg.push_str("\nbest scheme per budget (lowest mean RMSE among schemes within the budget):\n");
    msg.push_str(&arena::best_table(out, group));
    msg.push_str(&format!("{}\n", arena::SPEND_LEGEND));
    if let Some(note) = &first.rate_distortion_floor_note {
        msg.push_str(&format!("floor: none for this scenario ({note})\n"));
    }
    msg
}

/// `hushfuse` without arguments: the quick arena, and which scheme wins at which budget, on
/// every axis (energy first).
pub(crate) fn quick_arena() -> Result<(), Failure> {
    let (name, trials) = arena::QUICK;
    let text = builtin::get(name).expect("built-in quick arena");
    let source = format!("built-in:{name}");
    let load = build::LoadOptions {
        trials: Some(trials),
        ..Default::default()
    };
    let exp = build::load_with(text, &source, &load).map_err(|e| Failure::Run(e.to_string()))?;
    let asleep = exp.radio.asleep_step_uj(exp.battery_radios());
    let start = Instant::now();
    let mut msg = arena::quick_description(trials);
    let mut evaluations = 0;
    let mut bound = None;
    let opts = calibrate::Options {
        load,
        ..Default::default()
    };
    // Every axis from the same pilot runs (one run gives the spend on each).
    let outcomes = calibrate::calibrate_axes(text, &source, &arena::QUICK_AXES, &opts)
        .map_err(Failure::Run)?;
    for out in &outcomes {
        let group = out.summaries[0].group_order[0].clone();
        evaluations += out.evaluations;
        msg.push_str(&arena::quick_heading(out, asleep));
        msg.push_str(&arena::best_rows(out, &group));
        // The bound is the same under every table: printed once, at the end.
        bound = bound.or_else(|| arena::bound_line(out, &group));
    }
    msg.push_str(&format!("\n{}\n", arena::SPEND_LEGEND));
    if let Some(line) = bound {
        msg.push_str(&line);
        msg.push('\n');
    }
    msg.push_str(&format!(
        "\n({} pilot runs, {:.1} s. `hushfuse list` shows the built-in scenarios, `hushfuse run default` the Dormann et al. comparison, `hushfuse --help` the commands.)\n",
        evaluations,
        start.elapsed().as_secs_f64()
    ));
    print_out(&msg);
    Ok(())
}
