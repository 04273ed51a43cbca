//! Runs that survive: killed runs resume to the bytes of a clean run, shards merge to the bytes
//! of the unsharded run whatever the split, bad shards and checkpoints are refused with a
//! message naming them, and a failed write leaves the old complete output.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A small scenario: 5 blocks of 4 trials (the last one short), so that splits into 1 to 7
/// shards include empty shards.
fn small_text() -> String {
    common::TINY
        .replacen("name = \"tiny\"", "name = \"small\"", 1)
        .replacen("trials = 8", "trials = 18", 1)
        .replacen("steps = 20", "steps = 30", 1)
        .replacen("seed = 1", "seed = 7", 1)
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn refused(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "expected a refusal, got: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Every file under `dir` (relative path → bytes), but the lock files (which hold the pid of
/// the last process that wrote the folder).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else if p
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".hushfuse-lock"))
            {
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn assert_same_files(a: &Path, b: &Path) {
    let (fa, fb) = (files(a), files(b));
    assert_eq!(
        fa.keys().collect::<Vec<_>>(),
        fb.keys().collect::<Vec<_>>(),
        "{} and {} hold different files",
        a.display(),
        b.display()
    );
    for (name, bytes) in &fa {
        assert!(
            bytes == &fb[name],
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

fn small(dir: &Path) -> String {
    let p = dir.join("small.toml");
    std::fs::write(&p, small_text()).unwrap();
    p.to_str().unwrap().to_string()
}

/// A tiny deterministic generator for kill times (seeded and printed, so a failure replays).
struct Lcg(u64);
impl Lcg {
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Kills a run (SIGKILL or SIGINT) at random points of its progress and resumes it until it
/// finishes; the outputs must be those of a clean run, byte for byte.
fn kill_and_resume(threads: usize, signal: &str) {
    let dir = tempfile::tempdir().unwrap();
    let t = threads.to_string();
    let base = [
        "run",
        "default",
        "--trials",
        "600",
        "--threads",
        &t,
        "--checkpoint-every",
        "0",
    ];
    let started = Instant::now();
    ok(&hushfuse(
        &[&base[..], &["--out", "clean"]].concat(),
        dir.path(),
    ));
    let clean_time = started.elapsed().as_secs_f64();
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    eprintln!("{signal} x{threads}: clean run {clean_time:.2} s, kill-time seed {seed}");
    let mut rng = Lcg(seed);
    let mut resumed_from_progress = 0;
    let mut stops = 0;
    for attempt in 0.. {
        let mut args: Vec<&str> = [&base[..], &["--out", "killed"]].concat();
        if attempt > 0 {
            args.push("--resume");
        }
        let child = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
            .args(&args)
            .current_dir(dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The last attempts run to the end.
        if attempt < 5 {
            // The first kill lands well inside the run (after its first checkpoint, before
            // its end); the others anywhere in the first half of what is left.
            let (lo, span) = if attempt == 0 {
                (0.2, 0.3)
            } else {
                (0.05, 0.5)
            };
            let delay = clean_time * (lo + span * rng.unit());
            std::thread::sleep(Duration::from_secs_f64(delay));
            let pid = child.id().to_string();
            let sig = if signal == "SIGKILL" { "-KILL" } else { "-INT" };
            let _ = Command::new("kill").args([sig, &pid]).status();
        }
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(
            !err.contains("panicked") && !err.contains("corrupt"),
            "{err}"
        );
        if let Some(line) = err.lines().find(|l| l.starts_with("resuming from")) {
            let done: usize = line
                .split(": ")
                .nth(1)
                .and_then(|s| s.split(' ').next())
                .and_then(|s| s.parse().ok())
                .unwrap();
            if done > 0 && done < 600 {
                resumed_from_progress += 1;
            }
        }
        match out.status.code() {
            Some(0) => break,
            Some(130) => {
                assert_eq!(signal, "SIGINT");
                assert!(
                    err.contains("interrupted:") && err.contains("--resume"),
                    "a stopped run says how to resume: {err}"
                );
                assert!(dir.path().join("killed/hushfuse-checkpoint.bin").exists());
                stops += 1;
            }
            None => assert_eq!(signal, "SIGKILL"),
            code => panic!("exit {code:?}: {err}"),
        }
        assert!(attempt < 20, "the run never finished");
    }
    eprintln!("{signal} x{threads}: {stops} clean stops, {resumed_from_progress} resumes from a partial checkpoint");
    assert!(
        resumed_from_progress > 0,
        "no kill landed between two checkpoints (seed {seed}): the test proved nothing"
    );
    assert!(!dir.path().join("killed/hushfuse-checkpoint.bin").exists());
    assert_same_files(&dir.path().join("clean"), &dir.path().join("killed"));
}

#[test]
fn sigkill_at_random_points_then_resume_gives_the_bytes_of_a_clean_run_1_thread() {
    kill_and_resume(1, "SIGKILL");
}

#[test]
fn sigkill_at_random_points_then_resume_gives_the_bytes_of_a_clean_run_2_threads() {
    kill_and_resume(2, "SIGKILL");
}

#[test]
fn sigint_stops_cleanly_with_exit_130_and_resume_gives_the_same_bytes_1_thread() {
    kill_and_resume(1, "SIGINT");
}

#[test]
fn sigint_stops_cleanly_with_exit_130_and_resume_gives_the_same_bytes_2_threads() {
    kill_and_resume(2, "SIGINT");
}

fn shard_run(dir: &Path, scenario: &str, i: usize, n: usize, out: &str, extra: &[&str]) {
    let s = format!("{i}/{n}");
    // Odd shards on one thread, even ones on two: the thread count must not matter either.
    let threads = if i.is_multiple_of(2) { "2" } else { "1" };
    ok(&hushfuse(
        &[
            &[
                "run",
                scenario,
                "--shard",
                &s,
                "--threads",
                threads,
                "--out",
                out,
            ],
            extra,
        ]
        .concat(),
        dir,
    ));
}

#[test]
fn any_split_into_1_to_7_shards_merges_to_the_bytes_of_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = small(dir.path());
    ok(&hushfuse(&["run", &scenario, "--out", "whole"], dir.path()));
    for n in 1..=7 {
        let shards = format!("shards{n}");
        for i in 1..=n {
            shard_run(dir.path(), &scenario, i, n, &shards, &[]);
        }
        // Files given one by one, in reverse order: the merge order is the blocks', not the
        // command line's.
        let mut list: Vec<PathBuf> = std::fs::read_dir(dir.path().join(&shards))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "hfshard"))
            .collect();
        list.sort();
        list.reverse();
        assert_eq!(list.len(), n);
        let merged = format!("merged{n}");
        let mut args: Vec<String> = vec!["merge".into()];
        args.extend(list.iter().map(|p| p.display().to_string()));
        args.extend(["--out".into(), merged.clone()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        ok(&hushfuse(&args, dir.path()));
        assert_same_files(&dir.path().join("whole"), &dir.path().join(&merged));
    }
}

#[test]
fn missing_duplicated_foreign_corrupt_and_other_version_shards_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    for i in 1..=3 {
        shard_run(d, &scenario, i, 3, "s", &[]);
    }
    let name = |i: usize| format!("shard-{i:04}-of-0003.hfshard");
    let path = |i: usize| d.join("s").join(name(i)).display().to_string();
    // Missing.
    let err = refused(&hushfuse(&["merge", &path(1), &path(3), "--out", "m"], d));
    assert!(
        err.contains("missing shard 2/3") && err.contains(&name(2)),
        "{err}"
    );
    // Duplicated (the same shard twice, from two folders).
    std::fs::create_dir(d.join("copy")).unwrap();
    std::fs::copy(path(2), d.join("copy").join(name(2))).unwrap();
    let err = refused(&hushfuse(&["merge", "s", "copy", "--out", "m"], d));
    assert!(
        err.contains("shard 2/3 is given twice") && err.contains("copy/"),
        "{err}"
    );
    // Overlapping: a shard of another split of the same run.
    shard_run(d, &scenario, 1, 2, "half", &[]);
    let half = d
        .join("half/shard-0001-of-0002.hfshard")
        .display()
        .to_string();
    let err = refused(&hushfuse(&["merge", "s", &half, "--out", "m"], d));
    assert!(
        err.contains("in two shards") && err.contains(&half),
        "{err}"
    );
    // Foreign: a shard of the same scenario with another seed.
    shard_run(d, &scenario, 2, 3, "other", &["--seed", "8"]);
    let foreign = d.join("other").join(name(2)).display().to_string();
    let err = refused(&hushfuse(
        &["merge", &path(1), &foreign, &path(3), "--out", "m"],
        d,
    ));
    assert!(
        err.contains(&foreign) && err.contains("another run"),
        "{err}"
    );
    // Truncated and corrupted.
    let good = std::fs::read(path(2)).unwrap();
    let bad = d.join("bad.hfshard");
    std::fs::write(&bad, &good[..good.len() - 100]).unwrap();
    let b = bad.display().to_string();
    let err = refused(&hushfuse(
        &["merge", &path(1), &b, &path(3), "--out", "m"],
        d,
    ));
    assert!(err.contains(&b) && err.contains("truncated"), "{err}");
    let mut flipped = good.clone();
    let at = flipped.len() - 7;
    flipped[at] ^= 1;
    std::fs::write(&bad, &flipped).unwrap();
    let err = refused(&hushfuse(
        &["merge", &path(1), &b, &path(3), "--out", "m"],
        d,
    ));
    assert!(err.contains(&b) && err.contains("checksum"), "{err}");
    std::fs::write(&bad, b"not a shard").unwrap();
    let err = refused(&hushfuse(
        &["merge", &path(1), &b, &path(3), "--out", "m"],
        d,
    ));
    assert!(err.contains(&b) && err.contains("not a hushfuse"), "{err}");
    // Another hushfuse version: the version string rewritten, the checksum made valid again.
    let version = env!("CARGO_PKG_VERSION").as_bytes();
    let mut other = good.clone();
    let pos = other[52..]
        .windows(version.len())
        .position(|w| w == version)
        .unwrap()
        + 52;
    other[pos] = if other[pos] == b'9' { b'8' } else { b'9' };
    use sha2::Digest;
    let sum = sha2::Sha256::digest(&other[52..]);
    other[20..52].copy_from_slice(&sum);
    std::fs::write(&bad, &other).unwrap();
    let err = refused(&hushfuse(
        &["merge", &path(1), &b, &path(3), "--out", "m"],
        d,
    ));
    assert!(
        err.contains(&b) && err.contains("written by hushfuse"),
        "{err}"
    );
    // Another file format version.
    let mut format = good.clone();
    format[8] = 99;
    std::fs::write(&bad, &format).unwrap();
    let err = refused(&hushfuse(
        &["merge", &path(1), &b, &path(3), "--out", "m"],
        d,
    ));
    assert!(err.contains(&b) && err.contains("file format 99"), "{err}");
    assert!(!d.join("m").exists(), "a refused merge writes nothing");
    // All three merge.
    ok(&hushfuse(&["merge", "s", "--out", "m"], d));
}

#[test]
fn bad_shard_arguments_and_checkpoints_are_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    for bad in ["0/3", "3/2", "1/0", "x/2", "2"] {
        let err = refused(&hushfuse(&["run", &scenario, "--shard", bad], d));
        assert!(err.contains("--shard") && err.contains(bad), "{err}");
    }
    // A corrupt checkpoint: refused with its name, not a panic.
    std::fs::create_dir(d.join("o")).unwrap();
    let ckpt = d.join("o/hushfuse-checkpoint.bin");
    std::fs::write(&ckpt, b"HUSHFUSE\x01\x00\x00\x00garbage").unwrap();
    let err = refused(&hushfuse(&["run", &scenario, "--out", "o", "--resume"], d));
    assert!(
        err.contains("hushfuse-checkpoint.bin") && err.contains("truncated"),
        "{err}"
    );
    // A checkpoint left behind is never silently overwritten.
    let err = refused(&hushfuse(&["run", &scenario, "--out", "o"], d));
    assert!(err.contains("--resume"), "{err}");
    // A checkpoint of another run (other trials): refused, saying how it differs.
    std::fs::remove_file(&ckpt).unwrap();
    // A shard's state put where a whole run's checkpoint goes.
    shard_run(d, &scenario, 1, 2, "s", &[]);
    std::fs::copy(d.join("s/shard-0001-of-0002.hfshard"), &ckpt).unwrap();
    let err = refused(&hushfuse(
        &["run", &scenario, "--out", "o", "--resume", "--seed", "9"],
        d,
    ));
    assert!(
        err.contains("hushfuse-checkpoint.bin") && err.contains("seed"),
        "{err}"
    );
    let err = refused(&hushfuse(&["run", &scenario, "--out", "o", "--resume"], d));
    assert!(err.contains("another shard"), "{err}");
}

#[test]
fn a_rerun_removes_stale_files_of_its_manifest_and_refuses_unknown_files_before_running() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&hushfuse(
        &["reproduce", "dormann-fig1", "--trials", "4", "--out", "o"],
        d,
    ));
    assert!(d.join("o/reproduction.md").exists());
    let manifest = std::fs::read_to_string(d.join("o/hushfuse-manifest.json")).unwrap();
    assert!(manifest.contains("reproduction.md") && manifest.contains("\"seed\""));
    // The same scenario as a plain run writes no reproduction.md: the old one goes.
    ok(&hushfuse(
        &["run", "dormann-fig1", "--trials", "4", "--out", "o"],
        d,
    ));
    assert!(!d.join("o/reproduction.md").exists(), "stale file removed");
    // A file no manifest lists: refused before any trial runs.
    std::fs::write(d.join("o/notes.txt"), "mine").unwrap();
    let started = Instant::now();
    let err = refused(&hushfuse(
        &[
            "run",
            "dormann-fig1",
            "--trials",
            "100000",
            "--out",
            "o",
            "--allow-large",
        ],
        d,
    ));
    assert!(err.contains("notes.txt"), "{err}");
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "refused before running"
    );
    // A folder of files without a manifest (an older hushfuse's, or anything else).
    std::fs::create_dir(d.join("plain")).unwrap();
    std::fs::write(d.join("plain/summary.json"), "{}").unwrap();
    let err = refused(&hushfuse(
        &["run", "default", "--trials", "4", "--out", "plain"],
        d,
    ));
    assert!(
        err.contains("summary.json") && err.contains("no hushfuse-manifest.json"),
        "{err}"
    );
}

/// Runs `small` with `seed` into `out`, with the test hook failing the write of `fail`.
fn run_failing(d: &Path, scenario: &str, seed: &str, out: &str, fail: Option<&str>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_hushfuse"));
    cmd.args(["run", scenario, "--seed", seed, "--out", out, "--report"])
        .current_dir(d);
    if let Some(f) = fail {
        cmd.env("HUSHFUSE_TEST_FAIL_WRITE", f);
    }
    cmd.output().unwrap()
}

#[test]
fn a_failed_write_leaves_the_old_complete_output_and_prints_the_table_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    ok(&run_failing(d, &scenario, "1", "old", None));
    ok(&run_failing(d, &scenario, "2", "new", None));
    assert_ne!(
        std::fs::read(d.join("old/summary.json")).unwrap(),
        std::fs::read(d.join("new/summary.json")).unwrap()
    );
    for fail in [
        "summary.json",
        "per_step.csv",
        "rmse_position_per_step.svg",
        "scenario_as_run.toml",
        "report.html",
        "hushfuse-manifest.json",
    ] {
        let out_dir = format!("out-{fail}");
        ok(&run_failing(d, &scenario, "1", &out_dir, None));
        let out = run_failing(d, &scenario, "2", &out_dir, Some(fail));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{fail}: {stderr}");
        assert!(stderr.contains("no space left on device"), "{stderr}");
        assert!(
            stdout.contains("trials x 30 steps"),
            "table printed first: {stdout}"
        );
        // Exactly the old output: no new file, no truncated one, no temporary left.
        assert_same_files(&d.join("old"), &d.join(&out_dir));
        // And the next attempt, with room, gives the new complete output.
        ok(&run_failing(d, &scenario, "2", &out_dir, None));
        assert_same_files(&d.join("new"), &d.join(&out_dir));
    }
}

/// A real full disk: a tmpfs too small for two outputs at once (skipped where mounting is not
/// allowed).
#[test]
fn a_full_tmpfs_leaves_the_old_complete_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    ok(&run_failing(d, &scenario, "1", "old", None));
    let size: u64 = files(&d.join("old")).values().map(|b| b.len() as u64).sum();
    let mnt = d.join("mnt");
    std::fs::create_dir(&mnt).unwrap();
    // Room for one output and a half, and for the free-space estimate of one run (which the
    // first run must pass), plus tmpfs' own blocks; not for two outputs.
    let exp = hushfuse::scenario::build::load(&small_text(), "small.toml").unwrap();
    let estimate = hushfuse::scenario::limits::output_bytes(
        exp.groups.len(),
        exp.variants.len(),
        exp.steps,
        exp.trials,
    );
    let kib = (size * 3 / 2).max(estimate as u64 + 16 * 1024) / 1024 + 16;
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
        .arg(&mnt)
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        eprintln!("SKIPPED: cannot mount a tmpfs here (needs root); the injected-error test covers the same path");
        return;
    }
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    let _guard = Unmount(mnt.clone());
    let out = mnt.join("o").display().to_string();
    ok(&run_failing(d, &scenario, "1", &out, None));
    let failed = run_failing(d, &scenario, "2", &out, None);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    // Refused before any trial (free space below the estimate, exit 2) or failed when the disk
    // filled (exit 1): either way the old output stays whole.
    assert!(
        (failed.status.code() == Some(1) && stderr.contains("No space left on device"))
            || (failed.status.code() == Some(2) && stderr.contains("MiB free")),
        "the disk was not full: {stderr}"
    );
    assert_same_files(&d.join("old"), &mnt.join("o"));
}

/// A tmpfs of `kib` KiB on `mnt`, unmounted on drop; `None` where mounting is not allowed.
fn small_disk(mnt: &Path, kib: u64) -> Option<impl Drop> {
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    std::fs::create_dir_all(mnt).unwrap();
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
        .arg(mnt)
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    mounted.then(|| Unmount(mnt.to_path_buf()))
}

/// The arena and replay check free space too: on a disk with room for almost nothing they are
/// refused (exit 2, naming the free and needed sizes) and leave no file behind.
#[test]
fn arena_and_replay_are_refused_on_a_disk_without_room() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    let mnt = d.join("mnt");
    let Some(_guard) = small_disk(&mnt, 64) else {
        eprintln!("SKIPPED: cannot mount a tmpfs here (needs root)");
        return;
    };
    let out = mnt.join("arena").display().to_string();
    let arena = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args([
            "run",
            &scenario,
            "--budgets",
            "8,16",
            "--budget-axis",
            "payload",
            "--trials",
            "4",
            "--out",
            &out,
        ])
        .current_dir(d)
        .output()
        .unwrap();
    let e = refused(&arena);
    assert!(e.contains("MiB free") && e.contains("will write"), "{e}");
    // Recorded measurements long enough that the estimates do not fit in 64 KiB.
    let long = small_text().replacen("steps = 30", "steps = 3000", 1);
    std::fs::write(d.join("long.toml"), &long).unwrap();
    let exp = hushfuse::scenario::build::load(&long, "long.toml").unwrap();
    let data = hushfuse::engine::runner::draw_trial(&exp, 0);
    std::fs::write(
        d.join("meas.csv"),
        hushfuse::engine::replay::measurements_csv(&exp, &data),
    )
    .unwrap();
    let out = mnt.join("replay").display().to_string();
    let replay = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args([
            "replay",
            "long.toml",
            "--measurements",
            "meas.csv",
            "--out",
            &out,
        ])
        .current_dir(d)
        .output()
        .unwrap();
    let e = refused(&replay);
    assert!(e.contains("MiB free") && e.contains("will write"), "{e}");
    for sub in ["arena", "replay"] {
        let left: Vec<_> = std::fs::read_dir(mnt.join(sub))
            .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name()).collect())
            .unwrap_or_default();
        assert!(
            left.iter()
                .all(|n| n.to_string_lossy().starts_with(".hushfuse-lock")),
            "{sub}: {left:?}"
        );
    }
}

/// A shard stopped by SIGINT resumes too, and its merge is still the unsharded run's bytes.
#[test]
fn an_interrupted_shard_resumes_and_merges_to_the_bytes_of_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = ["run", "default", "--trials", "600", "--threads", "1"];
    let started = Instant::now();
    ok(&hushfuse(&[&base[..], &["--out", "whole"]].concat(), d));
    let clean_time = started.elapsed().as_secs_f64();
    let shard = [
        &base[..],
        &["--checkpoint-every", "0", "--out", "s", "--shard", "1/2"],
    ]
    .concat();
    let child = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(&shard)
        .current_dir(d)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs_f64(clean_time * 0.3));
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(d
        .join("s/hushfuse-checkpoint-shard-0001-of-0002.bin")
        .exists());
    let resumed = hushfuse(&[&shard[..], &["--resume"]].concat(), d);
    ok(&resumed);
    let err = String::from_utf8_lossy(&resumed.stderr);
    assert!(
        err.contains("resuming from") && !err.contains(" 0 of"),
        "{err}"
    );
    // Run again (a requeued task): already done.
    let again = ok(&hushfuse(&[&shard[..], &["--resume"]].concat(), d));
    assert!(again.contains("already done"), "{again}");
    ok(&hushfuse(
        &[&base[..], &["--out", "s", "--shard", "2/2"]].concat(),
        d,
    ));
    ok(&hushfuse(&["merge", "s", "--out", "merged"], d));
    assert_same_files(&d.join("whole"), &d.join("merged"));
}

/// A checkpoint that cannot be written costs only resumability: the run warns and finishes.
#[test]
fn a_failed_checkpoint_write_warns_and_the_run_still_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = small(d);
    let out = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(["run", &scenario, "--trials", "200", "--threads", "1"])
        .args(["--checkpoint-every", "0", "--out", "o"])
        .env("HUSHFUSE_TEST_FAIL_WRITE", "hushfuse-checkpoint.bin")
        .current_dir(d)
        .output()
        .unwrap();
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("warning: checkpoint not saved"), "{err}");
    assert!(!d.join("o/hushfuse-checkpoint.bin").exists());
}
