//! `--budget`/`--budgets` input: close budgets get distinct folders, bad budgets and budget
//! options without a budget are refused (exit 2, naming the option), a calibration failure
//! names its cause, and a table reproduction naming an unknown row is refused before it runs.
#[path = "common/cli.rs"]
mod common;

use common::{hushfuse, TINY};
use std::path::Path;

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A temporary folder holding `tiny.toml`.
fn dir_with_tiny() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("tiny.toml"), TINY).unwrap();
    d
}

/// TINY's model, prior and sensors with `schemes` (TOML) in place of its schemes.
fn tiny_with_schemes(name: &str, schemes: &str) -> String {
    let head = TINY.split("[[schemes]]").next().unwrap();
    format!(
        "{}{schemes}",
        head.replace("name = \"tiny\"", &format!("name = \"{name}\""))
    )
}

#[test]
fn close_budgets_write_two_folders() {
    let d = dir_with_tiny();
    let o = hushfuse(
        &[
            "run",
            "tiny.toml",
            "--budgets",
            "24.00001,24.00004",
            "--budget-axis",
            "payload",
            "--trials",
            "2",
            "--out",
            "o",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let mut subs: Vec<String> = std::fs::read_dir(d.path().join("o"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("budget-"))
        .collect();
    subs.sort();
    assert_eq!(subs, ["budget-24.00001", "budget-24.00004"]);
    for s in &subs {
        assert!(
            d.path().join("o").join(s).join("summary.json").is_file(),
            "{s}"
        );
    }
}

#[test]
fn duplicate_budgets_are_refused() {
    let d = dir_with_tiny();
    for list in ["24,24", "24,24.0", "3,1e1,10"] {
        let o = hushfuse(
            &[
                "run",
                "tiny.toml",
                "--budgets",
                list,
                "--trials",
                "2",
                "--out",
                "o",
            ],
            d.path(),
        );
        assert_eq!(o.status.code(), Some(2), "{list}: {}", stderr(&o));
        assert!(stderr(&o).contains("--budgets"), "{list}: {}", stderr(&o));
        assert!(stderr(&o).contains("twice"), "{list}: {}", stderr(&o));
        assert!(!d.path().join("o").exists(), "{list}: wrote a folder");
    }
}

#[test]
fn zero_negative_and_non_finite_budgets_are_refused_naming_the_option() {
    let d = dir_with_tiny();
    for b in ["0", "-1", "nan", "NaN", "inf", "-inf"] {
        let flag = format!("--budget={b}");
        let o = hushfuse(
            &["run", "tiny.toml", &flag, "--trials", "2", "--out", "o"],
            d.path(),
        );
        assert_eq!(o.status.code(), Some(2), "{b}: {}", stderr(&o));
        assert!(stderr(&o).contains("--budget"), "{b}: {}", stderr(&o));
        assert!(!d.path().join("o").exists(), "{b}: wrote a folder");
        let list = format!("--budgets=8,{b}");
        let o = hushfuse(
            &["run", "tiny.toml", &list, "--trials", "2", "--out", "o"],
            d.path(),
        );
        assert_eq!(o.status.code(), Some(2), "{b}: {}", stderr(&o));
        assert!(stderr(&o).contains("--budgets"), "{b}: {}", stderr(&o));
    }
}

#[test]
fn a_huge_budget_gets_a_short_folder_name_or_is_refused_cleanly() {
    let d = dir_with_tiny();
    let o = hushfuse(
        &[
            "run",
            "tiny.toml",
            "--budget",
            "1e300",
            "--budget-axis",
            "payload",
            "--trials",
            "2",
            "--out",
            "o",
        ],
        d.path(),
    );
    match o.status.code() {
        Some(0) => {
            let names: Vec<String> = std::fs::read_dir(d.path().join("o"))
                .unwrap()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("budget-"))
                .collect();
            assert_eq!(names, ["budget-1e300"]);
            // The tables print the budget short, not as 301 digits.
            let out = String::from_utf8_lossy(&o.stdout);
            assert!(out.contains("1e300"), "{out}");
            let widest = out.lines().map(|l| l.chars().count()).max().unwrap_or(0);
            assert!(widest < 200, "a line of {widest} characters:\n{out}");
        }
        Some(2) => assert!(stderr(&o).contains("--budget"), "{}", stderr(&o)),
        c => panic!("exit {c:?}: {}", stderr(&o)),
    }
}

#[test]
fn budget_options_without_a_budget_are_refused() {
    let d = dir_with_tiny();
    for (command, args, name) in [
        ("run", &["--budget-axis", "frame"][..], "--budget-axis"),
        ("run", &["--budget-axis", "payload"][..], "--budget-axis"),
        ("run", &["--pilot-trials", "2"][..], "--pilot-trials"),
        (
            "reproduce",
            &["--budget-axis", "frame"][..],
            "--budget-axis",
        ),
        ("reproduce", &["--pilot-trials", "2"][..], "--pilot-trials"),
        // `reproduce` runs the file as written: a budget there would be silently ignored.
        ("reproduce", &["--budget", "24"][..], "--budget"),
        ("reproduce", &["--budgets", "24,48"][..], "--budget"),
    ] {
        let mut all = vec![command, "tiny.toml", "--out", "o"];
        all.extend_from_slice(args);
        let o = hushfuse(&all, d.path());
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(name) && stderr(&o).contains("--budget"),
            "{args:?}: {}",
            stderr(&o)
        );
        assert!(!d.path().join("o").exists(), "{args:?}: ran");
    }
    // With a budget they are accepted.
    let o = hushfuse(
        &[
            "run",
            "tiny.toml",
            "--budget",
            "24",
            "--budget-axis",
            "payload",
            "--pilot-trials",
            "2",
            "--trials",
            "2",
            "--out",
            "o",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn a_calibration_failure_names_its_cause() {
    let d = tempfile::tempdir().unwrap();
    // Builds as written, but no calibration value of the knob builds: lloyd-max takes no `bits`
    // (integer knob), policy "all" takes no `l` (continuous knob).
    for (name, scheme, knob, cause) in [
        (
            "lm",
            "[[schemes]]\nkind = \"quantized-innovation\"\nquantizer = \"lloyd-max\"\nlevels = 4\n",
            "bits",
            "not a parameter of quantizer",
        ),
        (
            "cp",
            "[[schemes]]\nkind = \"censored-pf\"\npolicy = \"all\"\nparticles = 20\n",
            "l",
            "remove `l`",
        ),
    ] {
        let file = format!("{name}.toml");
        std::fs::write(d.path().join(&file), tiny_with_schemes(name, scheme)).unwrap();
        let o = hushfuse(
            &[
                "run",
                &file,
                "--budget",
                "2",
                "--budget-axis",
                "payload",
                "--trials",
                "2",
                "--out",
                name,
            ],
            d.path(),
        );
        let err = stderr(&o);
        assert!(
            matches!(o.status.code(), Some(1 | 2)),
            "{name}: exit {:?}: {err}",
            o.status.code()
        );
        assert!(err.contains(&format!("`{knob}`")), "{name}: {err}");
        assert!(err.contains(cause), "{name}: cause not printed: {err}");
    }
}

#[test]
fn a_table_report_naming_an_unknown_row_is_refused_before_it_runs() {
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/zhang-tables.toml"),
    )
    .unwrap();
    let good = "row = \"L for c_i <= 2\"";
    assert!(text.contains(good));
    let bad = text.replacen(good, "row = \"L for c_i <= 7\"", 1);
    std::fs::write(d.path().join("typo.toml"), bad).unwrap();
    let o = hushfuse(&["run", "typo.toml", "--out", "o"], d.path());
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("L for c_i <= 7"),
        "the row is not named: {err}"
    );
    assert!(err.contains("published["), "{err}");
    // The valid rows are listed.
    assert!(
        err.contains("L for c_i <= 2") && err.contains("Msechu c_i at L = 13"),
        "{err}"
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("missing"));
    assert!(!d.path().join("o").exists(), "wrote a folder");
    // A table that does not exist is named too.
    let bad = text.replacen("table = \"Table 5\"", "table = \"Table 9\"", 1);
    std::fs::write(d.path().join("typo.toml"), bad).unwrap();
    let o = hushfuse(&["run", "typo.toml", "--out", "o"], d.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("Table 9"), "{}", stderr(&o));
    // The file as shipped still runs.
    std::fs::write(d.path().join("ok.toml"), &text).unwrap();
    let o = hushfuse(&["run", "ok.toml", "--out", "o"], d.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

/// `--pilot-trials 0` ran one pilot trial without a word: refused, naming the flag. A NaN
/// budget on the energy axis (the default) says µJ, on a bits axis bits.
#[test]
fn zero_pilot_trials_and_nan_budgets_name_flag_and_unit() {
    let d = dir_with_tiny();
    let run = |extra: &[&str]| {
        let mut args = vec!["run", "tiny.toml", "--trials", "2", "--out", "o"];
        args.extend_from_slice(extra);
        hushfuse(&args, d.path())
    };
    let o = run(&["--budget", "300", "--pilot-trials", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--pilot-trials: expected at least 1"),
        "{}",
        stderr(&o)
    );
    let o = run(&["--budget", "NaN"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("finite number of µJ per step"),
        "{}",
        stderr(&o)
    );
    let o = run(&["--budget", "NaN", "--budget-axis", "payload"]);
    assert!(
        stderr(&o).contains("finite number of bits per step"),
        "{}",
        stderr(&o)
    );
    assert!(!d.path().join("o").exists());
}
