//! `hushfuse merge`: the outputs of a whole run from the shard files of `run --shard I/N`.
use super::*;

/// `hushfuse merge`: the outputs of a whole run from the shard files of `run --shard I/N`.
pub(crate) fn merge(inputs: &[PathBuf], out: &Path, report: bool) -> Result<(), Failure> {
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
            limits: args
                .allow_large
                .then(hushfuse::scenario::limits::Limits::none),
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
        durable::validate(&exp, &s)
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
