//! Checkpoints and shards re-encoded with a valid checksum but edited structure (block range,
//! trial count, a vector's length, the NEES histogram's total, a huge block count) are refused
//! by name with exit 2: never merged or resumed into wrong numbers, never a panic or an abort.
#[path = "common/cli.rs"]
mod common;

use common::{hushfuse, TINY};
use hushfuse::output::durable::{self, Progress, State};
use proptest::prelude::*;
use std::path::Path;

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A folder with tiny.toml, its two shards in `s/` and the unsharded run in `whole/`.
fn with_shards() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    for i in 1..=2 {
        let shard = format!("{i}/2");
        let o = hushfuse(
            &["run", "tiny.toml", "--out", "s", "--shard", &shard],
            d.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
    }
    d
}

fn shard_path(d: &Path, i: usize) -> std::path::PathBuf {
    d.join("s").join(durable::shard_file_name(i, 2))
}

/// Merges `s/` into `out`; the exit code and stderr.
fn merge(d: &Path, out: &str) -> (Option<i32>, String) {
    let o = hushfuse(&["merge", "s", "--out", out], d);
    (o.status.code(), stderr(&o))
}

fn edit_shard(d: &Path, i: usize, f: impl FnOnce(&mut State)) {
    let p = shard_path(d, i);
    let mut s = State::read(&p).unwrap();
    f(&mut s);
    std::fs::write(&p, s.encode()).unwrap();
}

fn first_sums(s: &mut State) -> &mut hushfuse::metrics::Sums {
    match &mut s.progress {
        Progress::Blocks(b) => &mut b[0][0],
        Progress::Prefix { total, .. } => &mut total[0],
    }
}

#[test]
fn structurally_edited_shards_with_a_valid_checksum_are_refused_by_name_and_field() {
    let d = with_shards();
    let d = d.path();
    let clean = std::fs::read(shard_path(d, 1)).unwrap();
    type Edit = Box<dyn Fn(&mut State)>;
    let edits: Vec<(&str, Edit)> = vec![
        ("n_blocks", Box::new(|s| s.key.n_blocks = 1 << 40)),
        ("shard", Box::new(|s| s.end += 1)),
        ("trials", Box::new(|s| first_sums(s).trials += 1)),
        ("per_trial", Box::new(|s| first_sums(s).per_trial.push(1.0))),
        (
            "per_trial_nees",
            Box::new(|s| {
                first_sums(s).per_trial_nees.pop();
            }),
        ),
        ("per_step", Box::new(|s| first_sums(s).per_step.push(0.0))),
        (
            "nees_hist",
            Box::new(|s| first_sums(s).nees_hist.counts[5] += 1),
        ),
        ("diverged", Box::new(|s| first_sums(s).diverged = 1000)),
    ];
    for (field, edit) in edits {
        std::fs::write(shard_path(d, 1), &clean).unwrap();
        edit_shard(d, 1, edit);
        let (code, err) = merge(d, "m");
        assert_eq!(code, Some(2), "{field}: {err}");
        assert!(
            err.contains("shard-0001-of-0002.hfshard") && err.contains(&format!("`{field}`")),
            "{field}: {err}"
        );
        assert!(!d.join("m").join("summary.json").exists(), "{field}");
    }
    std::fs::write(shard_path(d, 1), &clean).unwrap();
    let (code, err) = merge(d, "m");
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn an_edited_checkpoint_is_refused_on_resume_by_name_and_field() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    std::fs::write(d.join("tiny.toml"), TINY).unwrap();
    // A checkpoint of the first block: a shard 1/2's progress written as a whole-run prefix.
    let o = hushfuse(&["run", "tiny.toml", "--out", "s", "--shard", "1/2"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = State::read(&shard_path(d, 1)).unwrap();
    let Progress::Blocks(blocks) = &s.progress else {
        panic!()
    };
    let mut total = blocks[0].clone();
    for b in &blocks[1..] {
        for (t, x) in total.iter_mut().zip(b) {
            t.merge(x);
        }
    }
    let ckpt = State {
        shard: None,
        start: 0,
        end: s.key.n_blocks,
        progress: Progress::Prefix { next: s.end, total },
        key: s.key.clone(),
    };
    std::fs::create_dir_all(d.join("o")).unwrap();
    let path = d.join("o/hushfuse-checkpoint.bin");
    let resume = |c: &State| {
        std::fs::write(&path, c.encode()).unwrap();
        let o = hushfuse(&["run", "tiny.toml", "--out", "o", "--resume"], d);
        (o.status.code(), stderr(&o))
    };
    let mut c = ckpt.clone();
    first_sums(&mut c).nees_hist.counts[3] += 2;
    let (code, err) = resume(&c);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("hushfuse-checkpoint.bin") && err.contains("nees_hist"),
        "{err}"
    );
    let mut c = ckpt.clone();
    c.key.n_blocks = 1 << 40;
    let (code, err) = resume(&c);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("n_blocks"), "{err}");
    let mut c = ckpt.clone();
    if let Progress::Prefix { next, .. } = &mut c.progress {
        *next += 1;
    }
    let (code, err) = resume(&c);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("trials"), "{err}");
    // The clean checkpoint resumes.
    let (code, err) = resume(&ckpt);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn shard_specs_near_2_pow_64_are_clear_errors_not_overflows() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let max = u64::MAX;
    for spec in [format!("{max}/{max}"), format!("{}/{max}", max - 1)] {
        let o = hushfuse(
            &["run", "tiny.toml", "--out", "s", "--shard", &spec],
            d.path(),
        );
        // An empty shard of a huge split: runs nothing and writes its (empty) shard.
        assert!(
            matches!(o.status.code(), Some(0 | 2)),
            "{spec}: {}",
            stderr(&o)
        );
    }
    for spec in [format!("{max}0/{max}0"), format!("{max}/{}", max - 1)] {
        let o = hushfuse(
            &["run", "tiny.toml", "--out", "s", "--shard", &spec],
            d.path(),
        );
        assert_eq!(o.status.code(), Some(2), "{spec}: {}", stderr(&o));
        assert!(stderr(&o).contains("--shard"), "{spec}");
    }
    assert_eq!(durable::shard_blocks(usize::MAX, usize::MAX, 10), 9..10);
    assert_eq!(durable::shard_blocks(1, usize::MAX, usize::MAX / 4), 0..0);
}

proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 24,
        // A fixed seed: the same cases on every run and machine (CI included).
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0001),
        ..proptest::prelude::ProptestConfig::default()
    })]
    /// Random byte edits of a shard, its checksum made valid again: never a panic (exit 0 or 2, or
    /// 1 naming numbers that are not finite);
    /// random structural edits: exit 2, or exit 0 with the clean run's numbers.
    #[test]
    fn random_edits_never_panic_nor_merge_wrong_numbers(
        at in 52usize..100_000, xor in 1u8..=255, field in 0usize..6, delta in 1usize..5,
    ) {
        let dir = with_shards();
        let d = dir.path();
        let (code, err) = merge(d, "clean");
        prop_assert_eq!(code, Some(0), "{}", err);
        let clean = std::fs::read(d.join("clean/summary.json")).unwrap();
        let p = shard_path(d, 2);
        let good = std::fs::read(&p).unwrap();
        let mut bytes = good.clone();
        let at = 52 + (at - 52) % (bytes.len() - 52);
        bytes[at] ^= xor;
        use sha2::Digest;
        let sum = sha2::Sha256::digest(&bytes[52..]);
        bytes[20..52].copy_from_slice(&sum);
        std::fs::write(&p, &bytes).unwrap();
        let (code, err) = merge(d, "bytes");
        // A refusal (2), or numbers the merge itself finds not finite and says so (1).
        prop_assert!(
            matches!(code, Some(0 | 2)) || (code == Some(1) && err.contains("not finite")),
            "byte {}: {:?} {}", at, code, err
        );
        std::fs::write(&p, &good).unwrap();
        edit_shard(d, 2, |s| {
            let x = first_sums(s);
            match field {
                0 => x.trials += delta,
                1 => x.per_trial.truncate(x.per_trial.len().saturating_sub(delta)),
                2 => x.nees_hist.counts[delta] += delta as u64,
                3 => x.diverged += 100 * delta,
                4 => s.start = s.start.saturating_sub(delta),
                _ => s.key.n_blocks += delta,
            }
        });
        let (code, err) = merge(d, "fields");
        prop_assert!(matches!(code, Some(0 | 2)), "field {}: {:?} {}", field, code, err);
        if code == Some(0) {
            prop_assert_eq!(std::fs::read(d.join("fields/summary.json")).unwrap(), clean);
        }
    }
}
