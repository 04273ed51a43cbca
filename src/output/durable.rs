//! Checkpoints and shards: a run's finished work, persisted at the granularity of the runner's
//! fixed trial blocks.
//!
//! The runner's result is the fold of per-block sums in block order, starting from empty sums.
//! A checkpoint of a whole run therefore holds that fold up to a block (the running total and
//! the next block): continuing the fold from there gives every bit of an uninterrupted run. A
//! shard runs a contiguous range of blocks and keeps each block's sums apart, so that a merge
//! folds all blocks of all shards in global block order from empty sums: the same additions in
//! the same order as one run, whatever the split.
//!
//! File format (checkpoint `hushfuse-checkpoint*.bin` and shard `shard-I-of-N.hfshard`): the
//! 8 bytes `HUSHFUSE`, the format version (u32, little endian), the payload length (u64, little
//! endian), the SHA-256 of the payload (32 bytes), then the payload: a [`State`] in `postcard`
//! (floats as their 8 IEEE bytes, so they round-trip exactly).
use crate::engine::runner;
use crate::metrics::Sums;
use crate::scenario::build::Experiment;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"HUSHFUSE";
/// Version of the file layout and of [`State`]; files of another version are refused.
/// 2: `Sums::per_trial` flat. 3: `Sums::link` (the link's per-step counts). 4: `Sums::link`
/// rows of 8 counters (ARQ's retransmissions, duplicates, ACK frames and ACK bits added). 5:
/// `Sums::failure` (a variant's first failed trial). 6: `Sums::sensors` (per-sensor scheduled and
/// sent steps, for the entropy-coded rate). 7: `Sums::reading_peaks` (the largest reading per
/// measurement component, for the singles' rounding warning).
pub const FORMAT: u32 = 7;
const HEADER: usize = 8 + 4 + 8 + 32;

/// What a run is, for telling whether a checkpoint or shard belongs to it, and how to rebuild
/// its experiment (merge).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RunKey {
    pub hushfuse_version: String,
    pub scenario: String,
    /// SHA-256 of the scenario text, its source name, trials and seed.
    pub scenario_sha256: String,
    pub seed: u64,
    pub trials: usize,
    pub n_blocks: usize,
    /// The scenario as given (file text or built-in text) and its source name.
    pub text: String,
    pub source: String,
    /// `--trials` and `--seed` as given.
    pub trials_override: Option<usize>,
    pub seed_override: Option<u64>,
    /// `--allow-large` as given.
    pub allow_large: bool,
    /// Whether the run was a `reproduce` (writes reproduction.md).
    pub reproduce: bool,
}

/// SHA-256 (hex) of a scenario as run.
pub fn scenario_hash(text: &str, source: &str, trials: usize, seed: u64) -> String {
    let mut bytes = Vec::with_capacity(text.len() + source.len() + 48);
    for part in [text.as_bytes(), source.as_bytes()] {
        bytes.extend_from_slice(&(part.len() as u64).to_le_bytes());
        bytes.extend_from_slice(part);
    }
    bytes.extend_from_slice(&(trials as u64).to_le_bytes());
    bytes.extend_from_slice(&seed.to_le_bytes());
    crate::output::sha256_hex(&bytes)
}

impl RunKey {
    /// The key of a run of `exp`, loaded from `text` (named `source`) with these overrides.
    pub fn new(
        exp: &Experiment,
        text: &str,
        source: &str,
        trials_override: Option<usize>,
        seed_override: Option<u64>,
        allow_large: bool,
        reproduce: bool,
    ) -> Self {
        Self {
            hushfuse_version: env!("CARGO_PKG_VERSION").to_string(),
            scenario: exp.name.clone(),
            scenario_sha256: scenario_hash(text, source, exp.trials, exp.seed),
            seed: exp.seed,
            trials: exp.trials,
            n_blocks: runner::n_blocks(exp.trials),
            text: text.to_string(),
            source: source.to_string(),
            trials_override,
            seed_override,
            allow_large,
            reproduce,
        }
    }

    /// How `other` differs from this run, if it does in what matters for the numbers.
    pub fn mismatch(&self, other: &RunKey) -> Option<String> {
        if other.hushfuse_version != self.hushfuse_version {
            Some(format!(
                "was written by hushfuse {}, not {}",
                other.hushfuse_version, self.hushfuse_version
            ))
        } else if other.scenario != self.scenario || other.scenario_sha256 != self.scenario_sha256 {
            Some(format!(
                "belongs to scenario {:?} ({} trials, seed {}, scenario hash {}), not {:?} ({} trials, seed {}, hash {})",
                other.scenario,
                other.trials,
                other.seed,
                &other.scenario_sha256[..12.min(other.scenario_sha256.len())],
                self.scenario,
                self.trials,
                self.seed,
                &self.scenario_sha256[..12.min(self.scenario_sha256.len())],
            ))
        } else if other.seed != self.seed || other.trials != self.trials {
            Some(format!(
                "is of a run with {} trials and seed {}, not {} trials and seed {}",
                other.trials, other.seed, self.trials, self.seed
            ))
        } else {
            None
        }
    }
}

/// Finished work of a run or a shard.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub enum Progress {
    /// Blocks `start..next` folded in block order from empty sums (a whole run's checkpoint).
    Prefix { next: usize, total: Vec<Sums> },
    /// Each block's sums, for blocks `start..start + len` (a shard, or its checkpoint).
    Blocks(Vec<Vec<Sums>>),
}

/// A checkpoint or shard file's content.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct State {
    pub key: RunKey,
    /// `(i, n)` for shard i of n (1-based), `None` for a whole run.
    pub shard: Option<(usize, usize)>,
    /// The blocks this run or shard is to run.
    pub start: usize,
    pub end: usize,
    pub progress: Progress,
}

impl State {
    /// The first block not yet done.
    pub fn next_block(&self) -> usize {
        match &self.progress {
            Progress::Prefix { next, .. } => *next,
            Progress::Blocks(b) => self.start + b.len(),
        }
    }

    /// Whether every block of the range is done.
    pub fn is_complete(&self) -> bool {
        self.next_block() >= self.end
    }

    /// Trials done.
    pub fn trials_done(&self) -> usize {
        let t = self.key.trials;
        runner::block_trials(self.next_block(), t).start - runner::block_trials(self.start, t).start
    }

    /// The bytes of the file.
    pub fn encode(&self) -> Vec<u8> {
        let payload = postcard::to_stdvec(self).expect("sums serialize");
        let mut out = Vec::with_capacity(HEADER + payload.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT.to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        use sha2::Digest;
        out.extend_from_slice(&sha2::Sha256::digest(&payload));
        out.extend_from_slice(&payload);
        out
    }

    /// Reads a file's bytes; a clear message (without the file name) when they are not a
    /// complete, intact file of this format.
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        if bytes.len() < 8 || &bytes[..8] != MAGIC {
            return Err("not a hushfuse checkpoint or shard file".into());
        }
        if bytes.len() < HEADER {
            return Err("truncated (shorter than its header)".into());
        }
        let format = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if format != FORMAT {
            return Err(format!(
                "file format {format}, but this hushfuse ({}) reads format {FORMAT}",
                env!("CARGO_PKG_VERSION")
            ));
        }
        let len = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
        let payload = &bytes[HEADER..];
        if (payload.len() as u64) < len {
            return Err(format!(
                "truncated ({} of {} bytes)",
                bytes.len(),
                HEADER as u64 + len
            ));
        }
        if payload.len() as u64 > len {
            return Err("corrupt (longer than its header says)".into());
        }
        use sha2::Digest;
        if sha2::Sha256::digest(payload).as_slice() != &bytes[20..52] {
            return Err("corrupt (checksum mismatch)".into());
        }
        let state: State =
            postcard::from_bytes(payload).map_err(|e| format!("corrupt (cannot decode: {e})"))?;
        state.check()?;
        Ok(state)
    }

    /// Internal consistency (a well-formed file of a buggy writer, or one edited by hand): the
    /// block count is the one of the trial count, the range lies inside it, and a shard's range
    /// is the one of its `I/N`. Checked before anything is sized from the file.
    fn check(&self) -> Result<(), String> {
        let nb = self.key.n_blocks;
        let expected = runner::n_blocks(self.key.trials);
        if nb != expected {
            return Err(format!(
                "inconsistent (field `n_blocks` is {nb}, but {} trials make {expected} blocks)",
                self.key.trials
            ));
        }
        let prefix_before_start =
            matches!(&self.progress, Progress::Prefix { next, .. } if *next < self.start);
        if self.start > self.end
            || self.end > nb
            || prefix_before_start
            || self.next_block() > self.end
        {
            return Err(format!(
                "inconsistent (field `start`/`end`: blocks {}..{} of {nb}, next {})",
                self.start,
                self.end,
                self.next_block()
            ));
        }
        if let Some((i, n)) = self.shard {
            if i == 0 || i > n || shard_blocks(i, n, nb) != (self.start..self.end) {
                return Err(format!(
                    "inconsistent (field `shard`: shard {i}/{n} of {nb} blocks is not blocks {}..{})",
                    self.start, self.end
                ));
            }
        }
        Ok(())
    }

    /// Reads a checkpoint or shard file; errors name the file.
    pub fn read(path: &Path) -> Result<Self, String> {
        let bytes =
            std::fs::read(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        Self::decode(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Writes the file durably (temporary name, fsync, rename).
    pub fn write(&self, path: &Path) -> Result<(), String> {
        crate::output::write_file(path, &self.encode())
    }
}

/// Parses `--shard I/N` (1 ≤ I ≤ N).
pub fn parse_shard(text: &str) -> Result<(usize, usize), String> {
    let bad = || {
        format!("--shard: expected I/N with 1 <= I <= N (e.g. 2/4 for the second of four shards), got {text:?}")
    };
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let i: usize = i.trim().parse().map_err(|_| bad())?;
    let n: usize = n.trim().parse().map_err(|_| bad())?;
    if i == 0 || n == 0 || i > n {
        return Err(bad());
    }
    Ok((i, n))
}

/// Blocks of shard `i` of `n` (1-based) of a run of `n_blocks` blocks: contiguous, in order,
/// covering every block once across i = 1..n; empty when there are more shards than blocks.
/// Computed in 128 bits: no overflow for any `i <= n` and `n_blocks` (the ends are at most
/// `n_blocks`, so they fit). `i = 0` or `n = 0` give an empty range (never a panic);
/// [`parse_shard`] refuses them.
pub fn shard_blocks(i: usize, n: usize, n_blocks: usize) -> Range<usize> {
    if i == 0 || n == 0 || i > n {
        return 0..0;
    }
    let at = |j: usize| {
        let b = j as u128 * n_blocks as u128 / n as u128;
        usize::try_from(b).expect("at most n_blocks")
    };
    at(i - 1)..at(i)
}

/// File name of shard `i` of `n`.
pub fn shard_file_name(i: usize, n: usize) -> String {
    format!("shard-{i:04}-of-{n:04}.hfshard")
}

/// File name of the checkpoint of a whole run (`None`) or of shard `i` of `n`.
pub fn checkpoint_file_name(shard: Option<(usize, usize)>) -> String {
    match shard {
        None => "hushfuse-checkpoint.bin".into(),
        Some((i, n)) => format!("hushfuse-checkpoint-shard-{i:04}-of-{n:04}.bin"),
    }
}

/// Shard files among `inputs`: files as given, folders by their `*.hfshard` files (sorted).
pub fn shard_paths(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| format!("{}: cannot read: {e}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "hfshard") && f.is_file())
                .collect();
            if found.is_empty() {
                return Err(format!("{}: holds no shard files (*.hfshard)", p.display()));
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    if out.is_empty() {
        return Err("no shard files given".into());
    }
    Ok(out)
}

/// Checks that `shards` (file, content) are complete shards of one run that together cover
/// every block exactly once, and returns the run's key and every block's sums in block order.
/// Errors name the offending file. Nothing is sized from a file's block count: the ranges are
/// sorted and checked for overlaps and gaps (memory: the files' own blocks).
pub fn check_shards(shards: Vec<(PathBuf, State)>) -> Result<(RunKey, Vec<Vec<Sums>>), String> {
    let (first_path, first) = shards.first().ok_or("no shard files given")?;
    let key = first.key.clone();
    let first_path = first_path.clone();
    let nb = key.n_blocks;
    check_each_shard(&shards, &key, &first_path)?;
    let order = block_order(&shards)?;
    check_split_complete(&shards, &key)?;
    check_no_gaps(&shards, &order, nb)?;
    // Every block is in exactly one shard: move the sums out in block order.
    let mut shards: Vec<Option<State>> = shards.into_iter().map(|(_, s)| Some(s)).collect();
    let mut by_block = Vec::new();
    for f in order {
        if let Some(State {
            progress: Progress::Blocks(blocks),
            ..
        }) = shards[f].take()
        {
            by_block.extend(blocks);
        }
    }
    Ok((key, by_block))
}

/// Each file on its own (in the order given): of the run of `key` (as `first_path` is), a
/// complete shard, not given twice, holding one sums entry per block of its range.
fn check_each_shard(
    shards: &[(PathBuf, State)],
    key: &RunKey,
    first_path: &Path,
) -> Result<(), String> {
    let nb = key.n_blocks;
    for (f, (path, s)) in shards.iter().enumerate() {
        if let Some(m) = key.mismatch(&s.key) {
            return Err(format!(
                "{} {m} (as {} is); it is a shard of another run",
                path.display(),
                first_path.display()
            ));
        }
        if s.key.n_blocks != nb {
            return Err(format!(
                "{}: field `n_blocks` is {}, not {nb} (as {} says)",
                path.display(),
                s.key.n_blocks,
                first_path.display()
            ));
        }
        let Some((i, n)) = s.shard else {
            return Err(format!(
                "{}: a checkpoint of a whole run, not a shard",
                path.display()
            ));
        };
        if !s.is_complete() {
            return Err(format!(
                "{}: shard {i}/{n} is unfinished ({} of {} blocks); rerun it with `--shard {i}/{n} --resume`",
                path.display(),
                s.next_block() - s.start,
                s.end - s.start
            ));
        }
        for (p2, s2) in shards.iter().take(f) {
            if s2.shard == s.shard {
                return Err(format!(
                    "shard {i}/{n} is given twice: {} and {}",
                    p2.display(),
                    path.display()
                ));
            }
        }
        let Progress::Blocks(blocks) = &s.progress else {
            return Err(format!(
                "{}: a shard without per-block sums",
                path.display()
            ));
        };
        if blocks.len() != s.end - s.start {
            return Err(format!(
                "{}: inconsistent block count (field `progress` holds {} blocks for blocks {}..{})",
                path.display(),
                blocks.len(),
                s.start,
                s.end
            ));
        }
    }
    Ok(())
}

/// The indices of the shards with a non-empty range, in block order; refuses two ranges that
/// overlap, naming both files.
fn block_order(shards: &[(PathBuf, State)]) -> Result<Vec<usize>, String> {
    // The non-empty ranges in block order: each must start at or after the end of those before.
    let mut order: Vec<usize> = (0..shards.len())
        .filter(|&f| shards[f].1.start < shards[f].1.end)
        .collect();
    order.sort_by_key(|&f| (shards[f].1.start, shards[f].1.end));
    for w in order.windows(2) {
        let (a, b) = (&shards[w[0]], &shards[w[1]]);
        if b.1.start < a.1.end {
            // Among the files given before, the one that holds b's first block.
            let (o, _) = order
                .iter()
                .map(|&f| &shards[f])
                .find(|(_, s)| s.start <= b.1.start && b.1.start < s.end)
                .expect("a holds it");
            let (x, y) = if w[0] < w[1] { (o, &b.0) } else { (&b.0, o) };
            return Err(format!(
                "block {} is in two shards: {} and {} (shards of different splits?)",
                b.1.start,
                x.display(),
                y.display()
            ));
        }
    }
    Ok(order)
}

/// When every file is of one split (the same N), refuses a missing shard of it (empty ones
/// too), naming the first few missing.
fn check_split_complete(shards: &[(PathBuf, State)], key: &RunKey) -> Result<(), String> {
    // One split (every file says the same N): every shard of it must be there, empty ones too.
    let splits: Vec<usize> = shards
        .iter()
        .filter_map(|(_, s)| s.shard.map(|x| x.1))
        .collect();
    if splits.iter().all(|&n| n == splits[0]) {
        let n = splits[0];
        // The missing ones counted from the sorted given ones (n may be huge: nothing is
        // sized from it), the first few named.
        const NAMED: usize = 20;
        let mut given: Vec<usize> = shards
            .iter()
            .filter_map(|(_, s)| s.shard.map(|x| x.0))
            .collect();
        given.sort_unstable();
        let (mut absent, mut count) = (Vec::new(), 0u128);
        let mut next = 1u128;
        for end in given
            .into_iter()
            .map(|i| i as u128)
            .chain(std::iter::once(n as u128 + 1))
        {
            count += end - next;
            let mut j = next;
            while j < end && absent.len() < NAMED {
                let j_ = j as usize;
                absent.push(format!("{j_}/{n} ({})", shard_file_name(j_, n)));
                j += 1;
            }
            next = end + 1;
        }
        if !absent.is_empty() {
            let more = if count > absent.len() as u128 {
                ", ...".to_string()
            } else {
                String::new()
            };
            return Err(format!(
                "missing shard{} {}{more} of the {n} shards of {:?}",
                if count == 1 { "" } else { "s" },
                absent.join(", "),
                key.scenario
            ));
        }
    }
    Ok(())
}

/// Refuses blocks of the `nb` in none of the ranges (taken in `order`, the block order).
fn check_no_gaps(shards: &[(PathBuf, State)], order: &[usize], nb: usize) -> Result<(), String> {
    // Gaps: blocks before the first range, between ranges, after the last.
    let mut missing: Vec<Range<usize>> = Vec::new();
    let mut covered = 0usize;
    for &f in order {
        let s = &shards[f].1;
        if s.start > covered {
            missing.push(covered..s.start);
        }
        covered = covered.max(s.end);
    }
    if covered < nb {
        missing.push(covered..nb);
    }
    if let (Some(lo), Some(hi)) = (missing.first(), missing.last()) {
        let total: usize = missing.iter().map(|r| r.len()).sum();
        return Err(format!(
            "blocks {}..={} of {nb} are in none of the shards given ({total} blocks missing)",
            lo.start,
            hi.end - 1
        ));
    }
    Ok(())
}

/// Folds every block's sums in block order from empty sums: the result of one run.
pub fn fold(exp: &Experiment, blocks: &[Vec<Sums>]) -> Vec<Sums> {
    let mut total = runner::empty_sums(exp);
    for b in blocks {
        runner::fold_block(&mut total, b);
    }
    total
}

/// Checks one block's (or a fold's) sums against `exp` and the `trials` they hold: one per
/// variant, of its steps, groups and state dimension, every vector of its length (the per-step
/// rows `steps x width`, the per-trial rows `trials x (1 + groups)`, one steady NEES a trial),
/// `trials` trials of which at most all diverged, and a NEES histogram that counts every
/// steady-state step of every trial exactly once (`trials x (steps - steady_from + 1)`: each
/// trial records every step, or the run fails). `at` says where (for the message).
pub fn validate_sums(
    exp: &Experiment,
    sums: &[Sums],
    trials: usize,
    at: &str,
) -> Result<(), String> {
    if sums.len() != exp.variants.len() {
        return Err(format!(
            "{at}: holds the sums of {} variants; scenario {:?} has {}",
            sums.len(),
            exp.name,
            exp.variants.len()
        ));
    }
    let shape = runner::empty_sums(exp);
    let steady_steps = (exp.steps + 1).saturating_sub(exp.steady_from) as u128;
    for (v, (s, e)) in sums.iter().zip(&shape).enumerate() {
        let bad = |field: &str, got: String, expected: String| {
            Err(format!(
                "{at}, variant {v} ({}): field `{field}` is {got}, expected {expected}",
                exp.variants[v].kind
            ))
        };
        let dims = [
            ("steps", s.steps, e.steps),
            ("layout_groups", s.layout_groups, e.layout_groups),
            ("state_dim", s.state_dim, e.state_dim),
        ];
        for (field, got, expected) in dims {
            if got != expected {
                return bad(field, got.to_string(), expected.to_string());
            }
        }
        // A variant with a failed trial holds what its trials recorded up to their failures:
        // its counts are not those of whole trials (and its numbers are not reported).
        let counted = match &s.failure {
            None => true,
            Some(f) if f.trial < exp.trials => false,
            Some(f) => {
                return bad(
                    "failure.trial",
                    f.trial.to_string(),
                    format!("below {} (the run's trials)", exp.trials),
                )
            }
        };
        let width = e.layout().width();
        let groups = e.layout_groups;
        let per_trial = trials as u128 * (1 + groups) as u128;
        let lengths = [
            (
                "per_step",
                s.per_step.len() as u128,
                e.per_step.len() as u128,
                format!("{} steps x {width} fields", e.steps),
            ),
            (
                "per_step_sq",
                s.per_step_sq.len() as u128,
                e.per_step_sq.len() as u128,
                format!("{} steps x {width} fields", e.steps),
            ),
            (
                "whole_run",
                s.whole_run.len() as u128,
                e.whole_run.len() as u128,
                format!("{width} fields"),
            ),
            (
                "ess_min",
                s.ess_min.len() as u128,
                e.ess_min.len() as u128,
                format!("{} steps", e.steps),
            ),
            (
                "nees_hist.counts",
                s.nees_hist.counts.len() as u128,
                e.nees_hist.counts.len() as u128,
                "bins".to_string(),
            ),
            (
                "per_trial",
                s.per_trial.len() as u128,
                per_trial,
                format!("{trials} trials x (1 + {groups} groups)"),
            ),
            (
                "per_trial_nees",
                s.per_trial_nees.len() as u128,
                trials as u128,
                format!("one per trial, {trials} trials"),
            ),
        ];
        for (field, got, expected, what) in lengths {
            let per_trial_field = matches!(field, "per_trial" | "per_trial_nees");
            if got != expected && (counted || !per_trial_field) {
                return bad(
                    field,
                    format!("{got} values long"),
                    format!("{expected} ({what})"),
                );
            }
        }
        if !(s.link.is_empty() || s.link.len() == e.steps) {
            return bad(
                "link",
                format!("{} steps long", s.link.len()),
                format!("empty or {} steps", e.steps),
            );
        }
        if let Some((got, expected)) = sensors_problem(s) {
            return bad("sensors", got, expected);
        }
        if let Some((got, expected)) = peaks_problem(exp, s) {
            return bad("reading_peaks", got, expected);
        }
        if !counted {
            continue;
        }
        if s.trials != trials {
            return bad(
                "trials",
                s.trials.to_string(),
                format!("{trials} (the trials of its blocks)"),
            );
        }
        if s.diverged > trials {
            return bad(
                "diverged",
                s.diverged.to_string(),
                format!("at most {trials} (its trials)"),
            );
        }
        let total: u128 = s.nees_hist.counts.iter().map(|&c| c as u128).sum();
        let expected = trials as u128 * steady_steps;
        if total != expected {
            return bad(
                "nees_hist",
                format!("a histogram of {total} values"),
                format!("{expected} ({trials} trials x {steady_steps} steady-state steps)"),
            );
        }
    }
    Ok(())
}

/// Checks every part of a checkpoint or shard against `exp` (see [`validate_sums`]): each
/// block's sums hold that block's trials, a running total those of the blocks it folds. The
/// message names the field; the caller adds the file.
pub fn validate(exp: &Experiment, state: &State) -> Result<(), String> {
    let t = exp.trials;
    if state.key.trials != t || state.key.n_blocks != runner::n_blocks(t) {
        return Err(format!(
            "field `trials`/`n_blocks`: {} trials in {} blocks, but the run has {t} trials in {} blocks",
            state.key.trials,
            state.key.n_blocks,
            runner::n_blocks(t)
        ));
    }
    match &state.progress {
        Progress::Prefix { next, total } => {
            let trials =
                runner::block_trials(*next, t).start - runner::block_trials(state.start, t).start;
            validate_sums(
                exp,
                total,
                trials,
                &format!("the running total of blocks {}..{next}", state.start),
            )
        }
        Progress::Blocks(blocks) => (state.start..).zip(blocks).try_for_each(|(b, sums)| {
            validate_sums(
                exp,
                sums,
                runner::block_trials(b, t).len(),
                &format!("block {b}"),
            )
        }),
    }
}

/// What is wrong with a checkpoint's reading peaks ([`Sums::reading_peaks`]), as (got,
/// expected): more than one per measurement component, or one negative or NaN.
fn peaks_problem(exp: &Experiment, s: &Sums) -> Option<(String, String)> {
    let components: usize = exp.system.sensors.iter().map(|m| m.meas_dim()).sum();
    let bad = s.reading_peaks.len() > components
        || s.reading_peaks.iter().any(|p| p.is_nan() || *p < 0.0);
    bad.then(|| {
        (
            format!("{} values", s.reading_peaks.len()),
            format!("at most {components} magnitudes (one per measurement component), none negative or NaN"),
        )
    })
}

/// What is wrong with a checkpoint's per-sensor counts ([`Sums::sensors`]), as (got,
/// expected): more sensors than are recorded, or a sensor that sent more often than it was
/// scheduled.
fn sensors_problem(s: &Sums) -> Option<(String, String)> {
    if s.sensors.len() > crate::network::MASKED_SENSORS {
        return Some((
            format!("{} sensors long", s.sensors.len()),
            format!("at most {}", crate::network::MASKED_SENSORS),
        ));
    }
    s.sensors.iter().find(|c| c[1] > c[0]).map(|c| {
        (
            format!("a sensor sent {} times in {} scheduled steps", c[1], c[0]),
            "at most once a scheduled step".to_string(),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::Sums;

    fn state(values: &[f64]) -> State {
        let mut s = Sums::new(1, 2, 2);
        for (a, v) in s.per_step.iter_mut().zip(values.iter().cycle()) {
            *a = *v;
        }
        s.per_trial.extend(values.iter().cycle().take(2));
        State {
            key: RunKey {
                hushfuse_version: env!("CARGO_PKG_VERSION").into(),
                scenario: "t".into(),
                scenario_sha256: scenario_hash("x", "y", 8, 1),
                seed: 1,
                trials: 8,
                n_blocks: 2,
                text: "x".into(),
                source: "y".into(),
                trials_override: None,
                seed_override: None,
                allow_large: false,
                reproduce: false,
            },
            shard: Some((1, 1)),
            start: 0,
            end: 2,
            progress: Progress::Blocks(vec![vec![s.clone()], vec![s]]),
        }
    }

    #[test]
    fn floats_round_trip_bit_for_bit() {
        let values = [
            0.1,
            -0.0,
            f64::MIN_POSITIVE / 3.0,
            f64::INFINITY,
            f64::NAN,
            1e308,
            std::f64::consts::PI,
        ];
        let s = state(&values);
        let back = State::decode(&s.encode()).unwrap();
        let bits = |s: &State| -> Vec<u64> {
            let Progress::Blocks(b) = &s.progress else {
                unreachable!()
            };
            b.iter()
                .flat_map(|v| v[0].per_step.iter().chain(&v[0].per_trial))
                .map(|x| x.to_bits())
                .collect()
        };
        assert_eq!(bits(&s), bits(&back));
    }

    #[test]
    fn every_truncation_and_every_flipped_byte_is_an_error_not_a_panic() {
        let bytes = state(&[1.5, 2.5]).encode();
        for len in 0..bytes.len() {
            assert!(
                State::decode(&bytes[..len]).is_err(),
                "prefix of {len} bytes"
            );
        }
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x40;
            assert!(State::decode(&b).is_err(), "byte {i} flipped");
        }
    }

    #[test]
    fn shards_cover_every_block_once_in_order() {
        for nb in 0..20 {
            for n in 1..=9 {
                let all: Vec<usize> = (1..=n).flat_map(|i| shard_blocks(i, n, nb)).collect();
                assert_eq!(all, (0..nb).collect::<Vec<_>>(), "{nb} blocks, {n} shards");
            }
        }
        assert!(parse_shard("0/3").is_err() && parse_shard("3/2").is_err());
        assert_eq!(parse_shard("2/3"), Ok((2, 3)));
    }
}
