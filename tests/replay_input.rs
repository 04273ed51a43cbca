//! `hushfuse replay` on data it cannot replay: estimates that overflow fail (exit 1) naming the
//! scheme and the step, with or without truth; steps given as timestamps name the file, row and
//! column; data too large for memory is refused before it is allocated (exit 2), naming the
//! file. Never a panic (101) or a signal.
#[path = "common/cli.rs"]
mod common;

use common::{hushfuse, TINY};
use std::path::Path;
use std::process::{Command, Output};

/// The tiny scenario with two schemes that carry an overflowing reading into their estimates
/// without stopping (the all-data KF and send-on-delta).
fn kf_scenario() -> String {
    let head = TINY.split("[[schemes]]").next().unwrap();
    format!(
        "{head}[[schemes]]\nkind = \"centralized-kf\"\n\n[[schemes]]\nkind = \"send-on-delta\"\ndelta = 1.0\n"
    )
}

fn setup(files: &[(&str, &str)]) -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("s.toml"), kf_scenario()).unwrap();
    for (name, text) in files {
        std::fs::write(d.path().join(name), text).unwrap();
    }
    d
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit code, never a panic or a signal.
fn code(o: &Output) -> i32 {
    let c = o.status.code();
    assert!(c.is_some(), "killed by a signal: {}", stderr(o));
    assert_ne!(c, Some(101), "panicked: {}", stderr(o));
    c.unwrap()
}

/// `hushfuse replay` with the memory ceiling lowered to `max_memory` bytes.
fn replay_limited(args: &[&str], cwd: &Path, max_memory: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .arg("replay")
        .args(args)
        .env("HUSHFUSE_MAX_MEMORY_BYTES", max_memory)
        .current_dir(cwd)
        .output()
        .expect("binary runs")
}

/// Readings near the largest double. They were meant to overflow the estimates; since a reading
/// crosses the network as an IEEE single (`link::as_sent`, issue 26), they arrive as infinities,
/// which the center rejects at step 1, naming the scheme and the step.
const OVERFLOW: &str = "step,sensor,z0\n1,0,1.7e308\n1,1,1.7e308\n2,0,-1.7e308\n2,1,-1.7e308\n3,0,1.7e308\n3,1,1.7e308\n";
const TRUTH3: &str = "step,x0,x1\n1,0,0\n2,0,0\n3,0,0\n";

#[test]
fn overflowing_estimates_without_truth_fail_naming_scheme_and_step() {
    let d = setup(&[("m.csv", OVERFLOW)]);
    let o = hushfuse(
        &["replay", "s.toml", "--measurements", "m.csv", "--out", "o"],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 1, "{err}");
    let want = "scheme Centralized KF (all data), step 1: measurement is not finite: [inf]";
    assert!(err.contains(want), "{err}");
}

#[test]
fn overflowing_estimates_with_truth_fail_naming_scheme_and_step() {
    let d = setup(&[("m.csv", OVERFLOW), ("t.csv", TRUTH3)]);
    let o = hushfuse(
        &[
            "replay",
            "s.toml",
            "--measurements",
            "m.csv",
            "--truth",
            "t.csv",
            "--out",
            "o",
        ],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 1, "{err}");
    let want = "scheme Centralized KF (all data), step 1: measurement is not finite: [inf]";
    assert!(err.contains(want), "{err}");
}

#[test]
fn finite_data_of_the_same_shape_replays() {
    let d = setup(&[(
        "m.csv",
        "step,sensor,z0\n1,0,1.0\n1,1,1.1\n2,0,2.0\n2,1,2.1\n3,0,3.0\n3,1,2.9\n",
    )]);
    let o = hushfuse(
        &["replay", "s.toml", "--measurements", "m.csv", "--out", "o"],
        d.path(),
    );
    assert_eq!(code(&o), 0, "{}", stderr(&o));
}

#[test]
fn unix_timestamp_steps_name_the_file_row_and_column() {
    let d = setup(&[(
        "ts.csv",
        "step,sensor,z0\n1700000000,0,1.0\n1700000000,1,1.2\n1700000001,0,1.1\n",
    )]);
    let o = hushfuse(&["replay", "s.toml", "--measurements", "ts.csv"], d.path());
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(
        err.contains("ts.csv: line 2 (data row 1), column 1 (step): step 1700000000 is beyond the most steps a replay can have (10000000)"),
        "{err}"
    );
    assert!(err.contains("1, 2, 3, ..."), "{err}");
    assert!(err.contains("not a time or a Unix timestamp"), "{err}");
    assert!(!err.contains("field `steps`"), "{err}");
    // Truth given as timestamps: its file, row and column.
    let d = setup(&[
        ("m.csv", "step,sensor,z0\n1,0,1.0\n"),
        ("t.csv", "step,x0,x1\n1700000000,0,0\n"),
    ]);
    let o = hushfuse(
        &[
            "replay",
            "s.toml",
            "--measurements",
            "m.csv",
            "--truth",
            "t.csv",
        ],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(
        err.contains(
            "t.csv: line 2 (data row 1), column 1 (step): expected step 1 here, got 1700000000"
        ),
        "{err}"
    );
}

#[test]
fn a_last_step_of_three_million_is_refused_before_allocating() {
    // The shipped example's scenario: four sensors, five schemes (about 9 GiB at 3e6 steps, the
    // peak heap measured at 1.15 times less: tests/memory_estimates.rs), under a 4 GB limit.
    let scen = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/replay/scenario.toml");
    let d = setup(&[("m.csv", "step,sensor,z0,z1\n1,0,1.0,\n3000000,1,1.0,\n")]);
    let o = replay_limited(&[scen, "--measurements", "m.csv"], d.path(), "4e9");
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(err.contains("m.csv: a replay of its 3000000 steps (2 readings of 4 sensors, state dimension 2, 5 scheme variants; the last step in the file is 3000000) would hold about"), "{err}");
    assert!(err.contains("in memory, more than the limit of"), "{err}");
    assert!(err.contains("or pass --allow-large"), "{err}");
}

#[test]
fn the_memory_bound_follows_the_steps_and_the_limit() {
    // 20000 steps fit by default and not under 1 MiB.
    let d = setup(&[("m.csv", "step,sensor,z0\n1,0,1.0\n20000,1,1.0\n")]);
    let args = ["s.toml", "--measurements", "m.csv", "--out", "o"];
    let o = replay_limited(&args, d.path(), "1048576");
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(err.contains("m.csv: a replay of its 20000 steps"), "{err}");
    assert!(err.contains("more than the limit of 0.0 GiB"), "{err}");
    let o = replay_limited(&args, d.path(), "1e12");
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    // --allow-large lifts the lowered limit.
    let o = replay_limited(
        &[
            "s.toml",
            "--measurements",
            "m.csv",
            "--out",
            "o2",
            "--allow-large",
        ],
        d.path(),
        "1048576",
    );
    assert_eq!(code(&o), 0, "{}", stderr(&o));
}

#[test]
fn many_rows_are_refused_before_they_are_parsed() {
    // 10^5 rows under a 4 MiB ceiling stand for 10^7 rows under the default one.
    let mut text = String::from("step,sensor,z0\n");
    for k in 1..=50_000 {
        text.push_str(&format!("{k},0,1.0\n{k},1,1.0\n"));
    }
    let d = setup(&[("many.csv", &text)]);
    let o = replay_limited(
        &["s.toml", "--measurements", "many.csv"],
        d.path(),
        "4194304",
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(
        err.contains("many.csv: reading this file (0.0 GiB) would hold about"),
        "{err}"
    );
    assert!(err.contains("or pass --allow-large"), "{err}");
}

#[test]
fn a_file_larger_than_the_limit_is_refused_before_it_is_read() {
    // A sparse file of 64 GiB: nothing is written to disk, and reading it would abort.
    let d = setup(&[]);
    let f = std::fs::File::create(d.path().join("huge.csv")).unwrap();
    f.set_len(64 << 30).unwrap();
    drop(f);
    let o = hushfuse(
        &["replay", "s.toml", "--measurements", "huge.csv"],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(
        err.contains("huge.csv: reading this file (64.0 GiB) would hold about 64.0 GiB in memory, more than the limit of"),
        "{err}"
    );
    // The truth file too.
    std::fs::write(d.path().join("m.csv"), "step,sensor,z0\n1,0,1.0\n").unwrap();
    let o = hushfuse(
        &[
            "replay",
            "s.toml",
            "--measurements",
            "m.csv",
            "--truth",
            "huge.csv",
        ],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    assert!(err.contains("huge.csv: reading this file"), "{err}");
}
