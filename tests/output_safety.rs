//! Nothing outside `--out` is touched, one run writes a folder at a time, a commit killed half
//! way is finished, seeds survive every file, and odd option values neither panic nor hang.
#[path = "common/cli.rs"]
mod common;

use common::{hushfuse, TINY};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};

/// Every file under `dir` (symbolic links not followed) with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            let ft = e.file_type().unwrap();
            let rel = p.strip_prefix(root).unwrap().display().to_string();
            if rel.ends_with(".hushfuse-lock") {
                // Holds the pid of the last process that took the lock.
                continue;
            }
            if ft.is_dir() {
                out.insert(format!("{rel}/"), Vec::new());
                walk(root, &p, out);
            } else {
                out.insert(rel, std::fs::read(&p).unwrap_or_default());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A folder with the tiny scenario, run once into `o/`.
fn with_run() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let o = hushfuse(&["run", "tiny.toml", "--out", "o"], d.path());
    assert!(o.status.success(), "{}", stderr(&o));
    d
}

fn set_manifest_files(dir: &Path, files: &[String]) {
    let path = dir.join("hushfuse-manifest.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    m["files"] = serde_json::json!(files);
    std::fs::write(&path, serde_json::to_string(&m).unwrap()).unwrap();
}

#[test]
fn a_manifest_naming_files_outside_the_folder_is_refused_and_nothing_outside_changes() {
    let d = with_run();
    std::fs::create_dir_all(d.path().join("keep")).unwrap();
    std::fs::write(d.path().join("keep/victim.txt"), "user data").unwrap();
    let absolute = d.path().join("keep/victim.txt").display().to_string();
    for bad in [
        "../keep/victim.txt",
        absolute.as_str(),
        "sub/../../keep/victim.txt",
    ] {
        set_manifest_files(&d.path().join("o"), &[bad.to_string()]);
        let before = snapshot(d.path());
        for args in [
            &["run", "tiny.toml", "--out", "o"][..],
            &["report", "o"][..],
        ] {
            let o = hushfuse(args, d.path());
            assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
            assert!(
                stderr(&o).contains("hushfuse-manifest.json") && stderr(&o).contains(bad),
                "{}",
                stderr(&o)
            );
            assert!(snapshot(d.path()) == before, "{bad}: a file changed");
        }
    }
}

#[test]
fn user_files_in_a_staging_folder_are_refused_and_kept() {
    let d = with_run();
    let staging = d.path().join("o/.hushfuse-staging");
    std::fs::create_dir_all(&staging).unwrap();
    std::fs::write(staging.join("notes.txt"), "mine").unwrap();
    let o = hushfuse(&["run", "tiny.toml", "--out", "o"], d.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("notes.txt"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(staging.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn a_second_run_into_a_busy_folder_is_refused_naming_the_other_run() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let mut first = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args([
            "run",
            "default",
            "--trials",
            "200000",
            "--threads",
            "1",
            "--out",
            "o",
        ])
        .current_dir(d.path())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The first run holds the lock from before its first trial.
    let lock = d.path().join("o/.hushfuse-lock");
    let t = std::time::Instant::now();
    while std::fs::read_to_string(&lock).map_or(true, |s| s.trim() != first.id().to_string()) {
        assert!(
            t.elapsed().as_secs() < 60,
            "the first run never took the lock"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = hushfuse(&["run", "tiny.toml", "--seed", "2", "--out", "o"], d.path());
    first.kill().unwrap();
    first.wait().unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("being written by another hushfuse run")
            && stderr(&o).contains(&first.id().to_string()),
        "{}",
        stderr(&o)
    );
    // The killed run's lock does not stand.
    let o = hushfuse(&["run", "tiny.toml", "--out", "o"], d.path());
    assert!(
        o.status.success() || stderr(&o).contains("checkpoint"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_run_killed_between_moving_its_files_and_writing_the_manifest_is_finished_by_resume() {
    let d = with_run();
    let o = d.path().join("o");
    let whole = snapshot(&o);
    // The state such a kill leaves: the staged manifest and the files not yet moved in the
    // staging folder, the others in place, no manifest in the folder yet.
    let staging = o.join(".hushfuse-staging");
    std::fs::create_dir_all(&staging).unwrap();
    std::fs::write(staging.join(".hushfuse-owner"), "1").unwrap();
    std::fs::rename(
        o.join("hushfuse-manifest.json"),
        staging.join("hushfuse-manifest.json"),
    )
    .unwrap();
    std::fs::rename(o.join("per_step.csv"), staging.join("per_step.csv")).unwrap();
    std::fs::rename(o.join("summary.json"), staging.join("summary.json")).unwrap();
    let r = hushfuse(&["run", "tiny.toml", "--out", "o", "--resume"], d.path());
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(stderr(&r).contains("finished moving"), "{}", stderr(&r));
    let mut after = snapshot(&o);
    let mut whole = whole;
    for m in [&mut after, &mut whole] {
        m.remove(".hushfuse-lock");
        m.remove("hushfuse-manifest.json");
    }
    assert!(after == whole, "the finished folder is the run's");
}

#[test]
fn a_seed_above_two_to_the_63_survives_the_as_run_file_report_and_rerun() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let seed = u64::MAX.to_string();
    let o = hushfuse(
        &["run", "tiny.toml", "--seed", &seed, "--out", "o"],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let as_run = std::fs::read_to_string(d.path().join("o/scenario_as_run.toml")).unwrap();
    assert!(as_run.contains(&format!("seed = \"{seed}\"")), "{as_run}");
    let summary = std::fs::read_to_string(d.path().join("o/summary.json")).unwrap();
    let r = hushfuse(&["report", "o"], d.path());
    assert!(r.status.success(), "{}", stderr(&r));
    let r = hushfuse(&["run", "o/scenario_as_run.toml", "--out", "o2"], d.path());
    assert!(r.status.success(), "{}", stderr(&r));
    let again = std::fs::read_to_string(d.path().join("o2/summary.json")).unwrap();
    let numbers = |text: &str| {
        let mut v: serde_json::Value = serde_json::from_str(text).unwrap();
        v.as_object_mut().unwrap().remove("source");
        v
    };
    assert!(
        numbers(&summary) == numbers(&again),
        "the rerun of the as-run file is the same run"
    );
}

#[test]
fn odd_option_values_neither_panic_nor_hang() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let o = hushfuse(
        &[
            "run",
            "tiny.toml",
            "--checkpoint-every",
            "1e20",
            "--out",
            "a",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let t = std::time::Instant::now();
    let o = hushfuse(
        &["run", "tiny.toml", "--threads", "100000", "--out", "b"],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("capped"), "{}", stderr(&o));
    assert!(t.elapsed().as_secs() < 60, "no minutes creating threads");
    assert_eq!(
        std::fs::read(d.path().join("a/summary.json")).unwrap(),
        std::fs::read(d.path().join("b/summary.json")).unwrap()
    );
}

#[test]
fn an_output_folder_that_cannot_be_written_is_refused_before_any_trial() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    std::fs::write(d.path().join("file"), "not a folder").unwrap();
    for extra in [&[][..], &["--shard", "1/2"][..]] {
        let mut args = vec!["run", "tiny.toml", "--out", "file/o"];
        args.extend_from_slice(extra);
        let o = hushfuse(&args, d.path());
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains("file/o"), "{}", stderr(&o));
        assert!(o.stdout.is_empty(), "no table: no trial ran");
    }
}

#[test]
fn the_free_space_estimate_bounds_what_a_run_writes_without_refusing_ordinary_runs() {
    let d = tempfile::tempdir().unwrap();
    let o = hushfuse(
        &["run", "default", "--trials", "40", "--out", "o"],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let written: usize = snapshot(&d.path().join("o")).values().map(Vec::len).sum();
    let text = std::fs::read_to_string(d.path().join("o/scenario_as_run.toml")).unwrap();
    let exp = hushfuse::scenario::build::load(&text, "scenario_as_run.toml").unwrap();
    let estimate = hushfuse::scenario::limits::output_bytes(
        exp.groups.len(),
        exp.variants.len(),
        exp.steps,
        40,
    );
    assert!(
        estimate >= written as f64 && estimate <= 10.0 * written as f64,
        "estimate {estimate} bytes for {written} written"
    );
}

/// A hand-made manifest that lists a folder: refused (exit 2) before any trial, and the earlier
/// output is untouched (the run used to fail at its end with exit 1, "Is a directory", its new
/// files already beside the old manifest).
#[test]
fn a_manifest_listing_a_folder_is_refused_before_anything_moves() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    let run = |out: &str| {
        hushfuse(
            &["run", "tiny.toml", "--trials", "2", "--out", out],
            d.path(),
        )
    };
    assert_eq!(run("o").status.code(), Some(0));
    let o = d.path().join("o");
    std::fs::create_dir(o.join("sub")).unwrap();
    let m = o.join("hushfuse-manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    manifest["files"].as_array_mut().unwrap().push("sub".into());
    std::fs::write(&m, serde_json::to_string(&manifest).unwrap()).unwrap();
    let before = snapshot(&o);
    let out = run("o");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("lists \"sub\", which is a folder"), "{err}");
    assert_eq!(snapshot(&o), before, "the earlier output changed");
}
