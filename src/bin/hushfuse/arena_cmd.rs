//! `hushfuse run --budget/--budgets` (the arena: calibration to bit budgets) and the quick
//! arena of `hushfuse` without arguments.
use super::*;

/// Budgets from `--budget` or `--budgets`: positive finite numbers, no two equal.
pub(crate) fn budgets_of(args: &RunArgs) -> Result<Vec<f64>, Failure> {
    if let Some(b) = args.budget {
        if !(b.is_finite() && b > 0.0) {
            return Err(Failure::Input(format!(
                "--budget: expected a positive finite number of bits per step, got {b}"
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
    let Some(exp) = exp.filter(|_| axis == calibrate::Axis::Energy) else {
        return Ok(());
    };
    let asleep = exp.radio.asleep_step_uj(exp.system.n_sensors());
    match budgets.iter().find(|&&b| b < asleep) {
        Some(b) => Err(Failure::Input(format!(
            "budget {} µJ/step is below what the {} sensors' radios spend asleep ({} µJ/step), which no scheme goes under{}",
            calibrate::short(*b),
            exp.system.n_sensors(),
            calibrate::short(asleep),
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
    };
    // The scenario as run, loaded once for the checks before the first pilot run (one that does
    // not load is reported by the calibration with its full message).
    let loaded = build::load_with(&text, &source, &load).ok();
    check_energy_budgets(axis, loaded.as_ref(), &budgets, args.budget_axis.is_some())?;
    check_arena_room(&early_dir, loaded.as_ref(), budgets.len())?;
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
    check_arena_finite(&out, &budgets)?;
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
    let mut files = write_arena_files(
        &mut out_dir,
        &out,
        &budgets,
        &axis,
        elapsed,
        &group,
        (&source, &opts.load),
    )?;
    if args.report {
        write_arena_report(&mut out_dir, &out, &source, &opts)?;
        files.push("report.html".into());
    }
    let hash = output::sha256_hex(
        format!(
            "{source}\0{text}\0{:?}\0{:?}\0{:?}\0{}\0{:?}",
            args.trials,
            args.seed,
            budgets,
            budget_axis(args),
            args.pilot_trials
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

/// Refuses a calibration whose outputs (one run's per budget) would not fit on the disk of the
/// early output folder.
fn check_arena_room(
    early_dir: &Option<OutputDir>,
    exp: Option<&build::Experiment>,
    budget_count: usize,
) -> Result<(), Failure> {
    // Room for one run's output per budget, checked before the first pilot run.
    if let (Some(d), Some(exp)) = (early_dir, exp) {
        let per_budget = hushfuse::scenario::limits::output_bytes(
            exp.groups.len(),
            exp.variants.len(),
            exp.steps,
            exp.trials,
        );
        output::check_free_space(d.dir(), per_budget * budget_count as f64)
            .map_err(Failure::Input)?;
    }
    Ok(())
}

/// Refuses a calibration outcome with a non-finite number in any budget's summary.
fn check_arena_finite(out: &calibrate::Outcome, budgets: &[f64]) -> Result<(), Failure> {
    let bad: Vec<String> = out
        .summaries
        .iter()
        .zip(budgets)
        .flat_map(|(s, b)| {
            hushfuse::metrics::finite::non_finite(s)
                .into_iter()
                .map(move |m| format!("budget {}: {m}", calibrate::dir_label(*b)))
        })
        .collect();
    check_finite(bad)
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

/// Stages the arena's files (calibration.json, best_per_budget.md, each budget's folder, the
/// plots) and returns their names as listed to the user.
fn write_arena_files(
    out_dir: &mut OutputDir,
    out: &calibrate::Outcome,
    budgets: &[f64],
    axis: &calibrate::Axis,
    elapsed: f64,
    group: &str,
    (source, load): (&str, &build::LoadOptions),
) -> Result<Vec<String>, Failure> {
    let first = &out.summaries[0];
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
            "target": c.target, "achieved": c.achieved, "status": c.status, "end": c.end,
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
    write("best_per_budget.md", &arena::best_markdown(out, group))?;
    let mut files = vec![
        "calibration.json".to_string(),
        "best_per_budget.md".to_string(),
    ];
    for (b, s) in out.summaries.iter().enumerate() {
        let sub = format!("budget-{}/", calibrate::dir_label(budgets[b]));
        // The budget's scenario as run, rebuilt: the same files as a run of it would write.
        let exp = build::load_with(&out.texts[b], source, load)
            .map_err(|e| Failure::Run(e.to_string()))?;
        let results = run_files::Results {
            exp: &exp,
            summary: Some(s),
            paper: None,
            replay: None,
        };
        let parts = [
            run_files::Part::Scenario {
                name: "scenario.toml",
                text: &out.texts[b],
            },
            run_files::Part::Summary,
            run_files::Part::PerStep,
        ];
        run_files::stage(out_dir, &sub, &results, &parts).map_err(Failure::Run)?;
        files.push(sub);
    }
    let plots = arena::write_plots(
        out,
        group,
        &first.scenario,
        out_dir.staging().map_err(Failure::Run)?,
    )
    .map_err(Failure::Run)?;
    out_dir.record(plots.iter().cloned());
    files.extend(plots);
    Ok(files)
}

/// `--report`: stages report.html, the page of the first budget's run with the arena's tables.
fn write_arena_report(
    out_dir: &mut OutputDir,
    out: &calibrate::Outcome,
    source: &str,
    opts: &calibrate::Options,
) -> Result<(), Failure> {
    let exp = build::load_with(&out.texts[0], source, &opts.load)
        .map_err(|e| Failure::Run(e.to_string()))?;
    let page = html::render(&html::Input {
        exp: &exp,
        summary: &out.summaries[0],
        scenario_text: &out.texts[0],
        alone: true,
        arena: Some(out),
        se_trials: exp.trials.min(200),
    })
    .map_err(Failure::Run)?;
    out_dir
        .stage("report.html", page.as_bytes())
        .map_err(Failure::Run)?;
    Ok(())
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
    let asleep = exp.radio.asleep_step_uj(exp.system.n_sensors());
    let start = Instant::now();
    let mut msg = arena::quick_description(trials);
    let mut evaluations = 0;
    let mut bound = None;
    for (axis, budgets) in arena::QUICK_AXES {
        let opts = calibrate::Options {
            axis,
            load,
            ..Default::default()
        };
        let out = calibrate::calibrate(text, &source, budgets, &opts).map_err(Failure::Run)?;
        let group = out.summaries[0].group_order[0].clone();
        evaluations += out.evaluations;
        msg.push_str(&arena::quick_heading(&out, asleep));
        msg.push_str(&arena::best_rows(&out, &group));
        // The bound is the same under every table: printed once, at the end.
        bound = bound.or_else(|| arena::bound_line(&out, &group));
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
