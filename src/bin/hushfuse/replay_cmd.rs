//! `hushfuse replay`: every scheme of a scenario on recorded measurements.
use super::*;

pub(crate) struct ReplayArgs<'a> {
    pub(crate) scenario: &'a str,
    pub(crate) measurements: &'a Path,
    pub(crate) truth: Option<&'a Path>,
    pub(crate) out: Option<&'a Path>,
    pub(crate) seed: Option<u64>,
    pub(crate) trial: usize,
    pub(crate) allow_large: bool,
    pub(crate) loss: Option<f64>,
}

/// `hushfuse replay`: every scheme of the scenario on recorded measurements.
pub(crate) fn replay(a: &ReplayArgs) -> Result<(), Failure> {
    let (text, source) = scenario_text(a.scenario)?;
    let text = with_loss(text, &source, a.loss)?;
    let limits = if a.allow_large {
        hushfuse::scenario::limits::Limits::none()
    } else {
        hushfuse::scenario::limits::Limits::default()
    };
    // A file larger than the memory limit is refused before it is read.
    let read = |p: &Path| {
        let cannot =
            |e: std::io::Error| Failure::Input(format!("{}: cannot read: {e}", p.display()));
        let size = std::fs::metadata(p).map_err(cannot)?.len();
        replay::check_read(&p.display().to_string(), size as f64, size, &limits)
            .map_err(|e| Failure::Input(e.to_string()))?;
        std::fs::read_to_string(p).map_err(cannot)
    };
    let meas_name = a.measurements.display().to_string();
    let meas = read(a.measurements)?;
    let truth_name = a.truth.map(|p| p.display().to_string());
    let truth = a.truth.map(read).transpose()?;
    let opts = replay::ReplayOptions {
        seed: a.seed,
        trial: a.trial,
        load: build::LoadOptions {
            limits: Some(limits),
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
    .map_err(|e| match e.is_input() {
        true => Failure::Input(e.to_string()),
        false => Failure::Run(e.to_string()),
    })?;
    let elapsed = start.elapsed().as_secs_f64();
    let dir = a
        .out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(format!("{}-replay", r.exp.name)));
    // Staged and committed with a manifest, like every run's output (all or nothing).
    let mut out_dir = OutputDir::open(&dir).map_err(Failure::Input)?;
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
    for n in &r.notes {
        msg.push_str(&format!("note: {n}\n"));
    }
    let mut bad = replay::non_finite_estimates(&r.exp, &r.replayed);
    let summary = r
        .replayed
        .sums
        .as_ref()
        .map(|sums| results::summarize(&r.exp, sums));
    match &summary {
        Some(summary) => {
            msg.push('\n');
            msg.push_str(&results::table(summary));
            bad.extend(replay::non_finite(summary));
        }
        None => msg.push_str("(no --truth: estimates only, no error metrics)\n"),
    }
    // The results first: a failed write below loses nothing from sight.
    print_out(&msg);
    msg.clear();
    output::check_free_space(&dir, replay::output_bytes(&r.exp, summary.is_some()))
        .map_err(Failure::Input)?;
    let results = run_files::Results {
        exp: &r.exp,
        summary: summary.as_ref(),
        paper: None,
        replay: Some((&r.recorded, &r.replayed)),
    };
    let parts = run_files::replay_parts(summary.is_some());
    run_files::stage(&mut out_dir, "", &results, &parts).map_err(Failure::Run)?;
    let mut manifest =
        output::Manifest::new("replay", &r.exp.name, &output::sha256_hex(text.as_bytes()));
    manifest.seed = Some(r.exp.seed);
    manifest.trials = Some(1);
    let files = out_dir.commit(manifest, false).map_err(Failure::Run)?;
    msg.push_str(&format!(
        "\nwrote {}: {}\n",
        dir.display(),
        files.join(", ")
    ));
    print_out(&msg);
    if !bad.is_empty() {
        return Err(Failure::Run(format!(
            "the replay produced numbers that are not finite (written as they are in estimates.csv, as null in summary.json), so its results cannot be trusted:\n  {}\nrescale the data's units or check the scenario's noise levels",
            bad.join("\n  ")
        )));
    }
    Ok(())
}
