//! The command line as a user meets it: bad scenario files get exit code 2 and a message that
//! names the field; good runs write their outputs; the thread count never changes a result.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;

use common::TINY as VALID;

fn run_text(text: &str) -> (Option<i32>, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scenario.toml");
    std::fs::write(&path, text).unwrap();
    let out = hushfuse(&["run", path.to_str().unwrap()], dir.path());
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn valid_scenario_runs_and_writes_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scenario.toml");
    std::fs::write(&path, VALID).unwrap();
    let out = hushfuse(&["run", path.to_str().unwrap(), "--out", "o"], dir.path());
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("Centralized KF (all data)"), "{stdout}");
    for f in [
        "summary.json",
        "per_step.csv",
        "rmse_position_per_step.svg",
        "mse_trace_vs_rate.svg",
    ] {
        assert!(dir.path().join("o").join(f).exists(), "missing {f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap())
            .unwrap();
    for key in ["scenario", "trials", "steps", "seed", "schemes"] {
        assert!(json.get(key).is_some(), "summary.json lacks {key}");
    }
    let s = &json["schemes"][0];
    for key in [
        "name",
        "params",
        "rmse",
        "mean_rmse",
        "mse",
        "trace",
        "anees",
        "rate",
        "transmissions_per_step",
        "bits_per_step",
    ] {
        assert!(s.get(key).is_some(), "scheme entry lacks {key}");
    }
    assert_eq!(s["rmse"]["position"].as_array().unwrap().len(), 20);
    // All-send: both sensors every step, one 32-bit component each.
    assert_eq!(s["rate"].as_f64().unwrap(), 1.0);
    assert_eq!(s["bits_per_step"].as_f64().unwrap(), 64.0);
    // Every mean has its standard error; an all-send scheme's traffic has no spread.
    assert_eq!(s["bits_per_step_se"].as_f64().unwrap(), 0.0);
    assert_eq!(
        s["traffic_per_step"]["payload_bits"][3].as_f64(),
        Some(64.0)
    );
    assert_eq!(
        s["traffic_per_step"]["payload_bits_se"][3].as_f64(),
        Some(0.0)
    );
    assert!(s["rmse_se"]["position"][5].as_f64().unwrap() > 0.0);
    assert!(s["anees_se"].as_f64().unwrap() > 0.0);

    // per_step.csv is tidy: parameters in their own columns, a standard error after each mean.
    let csv = std::fs::read_to_string(dir.path().join("o/per_step.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("per_step.csv lacks {name}: {header:?}"))
    };
    for name in [
        "scheme",
        "kind",
        "step",
        "rmse_position",
        "rmse_position_se",
        "payload_bits",
    ] {
        col(name);
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let sweep = header
        .iter()
        .find(|h| h.starts_with("param_"))
        .expect("a swept parameter column");
    let p = col(sweep);
    // The all-send KF has no such parameter; some swept variant has a number there.
    assert!(rows.iter().any(|r| r[p].is_empty()));
    assert!(rows.iter().any(|r| r[p].parse::<f64>().is_ok()));
    assert_eq!(rows[3][col("payload_bits")], "64");
    assert_eq!(rows[3][col("payload_bits_se")], "0");
}

/// Each bad file must exit with code 2 and name the offending field.
#[test]
fn malformed_scenarios_exit_2_and_name_the_field() {
    let cases: &[(&str, &str, &str)] = &[
        ("trials = 8", "trials = 0", "trials"),
        ("R_diag = [1.0]", "R_diag = [1.0, 2.0]", "sensors[0].R_diag"),
        ("R = [[2.0]]", "R = [[-2.0]]", "sensors[1].R"),
        ("H = [[1.0, 0.0]]", "H = [[1.0, 0.0, 0.0]]", "sensors[1].H"),
        ("observe = [0]", "observe = [5]", "sensors[0].observe"),
        (
            "cov_diag = [1.0, 1.0]",
            "cov = [[1.0, 2.0], [2.0, 1.0]]",
            "prior.cov",
        ),
        ("mean = [0.0, 1.0]", "mean = [0.0, 1.0, 2.0]", "prior.mean"),
        ("sweep.rate = [0.5, 1.0]", "sweep.rate = [0.3, 1.0]", "rate"),
        (
            "kind = \"centralized-kf\"",
            "kind = \"telepathy\"",
            "unknown scheme",
        ),
        ("R_diag = [1.0]", "R_diag = [nan]", "sensors[0].R_diag"),
        ("position = [0]", "position = [7]", "groups.position"),
        ("seed = 1\n", "", "seed"),
        ("dt = 1.0", "dt = -1.0", "model"),
        (
            "kind = \"dkf-alg1-random\"",
            "kind = \"dkf-alg1-random\"\nalpha = 3",
            "alpha",
        ),
    ];
    for (from, to, field) in cases {
        assert!(
            VALID.contains(from),
            "test case pattern {from:?} not in VALID"
        );
        let text = VALID.replacen(from, to, 1);
        let (code, stderr) = run_text(&text);
        assert_eq!(code, Some(2), "case {to:?}: stderr {stderr}");
        assert!(
            stderr.contains("scenario.toml"),
            "case {to:?}: no file name in {stderr}"
        );
        assert!(
            stderr.contains(field),
            "case {to:?}: {field:?} not named in {stderr}"
        );
        assert!(
            !stderr.contains("panicked"),
            "case {to:?} panicked: {stderr}"
        );
    }
    let (code, stderr) = run_text("this is [ not toml");
    assert_eq!(code, Some(2), "{stderr}");
}

#[test]
fn missing_file_and_unknown_builtin_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = hushfuse(&["run", "nope.toml"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let out = hushfuse(&["reproduce", "no-such-figure"], dir.path());
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn one_and_two_threads_give_identical_summaries() {
    let dir = tempfile::tempdir().unwrap();
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out_dir = format!("out{threads}");
        let out = hushfuse(
            &[
                "run",
                "default",
                "--trials",
                "24",
                "--threads",
                threads,
                "--out",
                &out_dir,
            ],
            dir.path(),
        );
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        outputs.push(std::fs::read(dir.path().join(out_dir).join("summary.json")).unwrap());
    }
    assert!(!outputs[0].is_empty());
    assert!(
        outputs[0] == outputs[1],
        "summary.json differs between 1 and 2 threads"
    );
}

#[test]
fn list_names_every_builtin() {
    let dir = tempfile::tempdir().unwrap();
    let out = hushfuse(&["list"], dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("default") && stdout.contains("dormann-fig1"),
        "{stdout}"
    );
}

#[test]
fn reproduce_prints_published_numbers_and_claims() {
    let text = format!(
        "{VALID}\n[paper]\ncitation = \"test paper, Table 9\"\n\
         [[paper.published]]\nscheme = \"Algorithm 1 (random)\"\nparams = {{ rate = 0.5 }}\n\
         metric = \"rate\"\nvalue = 0.5\nsource = \"Table 9\"\n\
         [[paper.claims]]\nkind = \"reaches-rate-below\"\ntext = \"reaches 0.75\"\n\
         scheme = \"Algorithm 1 (random)\"\nrate = 0.75\n\
         [[paper.claims]]\nkind = \"reaches-rate-below\"\ntext = \"reaches 0.1\"\n\
         scheme = \"Algorithm 1 (random)\"\nrate = 0.1\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("paper.toml");
    std::fs::write(&path, text).unwrap();
    let out = hushfuse(
        &["reproduce", path.to_str().unwrap(), "--out", "o"],
        dir.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Reproducing: test paper, Table 9"),
        "{stdout}"
    );
    assert!(
        stdout.contains("rate (Table 9): paper 0.5000, ours 0."),
        "{stdout}"
    );
    assert!(stdout.contains("[holds] reaches 0.75"), "{stdout}");
    assert!(stdout.contains("[FAILS] reaches 0.1"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap())
            .unwrap();
    assert_eq!(json["paper"]["claims"][0]["holds"], true);
    assert_eq!(json["paper"]["claims"][1]["holds"], false);
}

#[test]
fn reproduce_dormann_fig1_runs_with_few_trials() {
    let dir = tempfile::tempdir().unwrap();
    let out = hushfuse(
        &["reproduce", "dormann-fig1", "--trials", "8", "--out", "o"],
        dir.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Algorithm 2 reaches communication rates below 0.5"),
        "{stdout}"
    );
    assert!(dir.path().join("o/mse_trace_vs_rate.svg").exists());
}

#[test]
fn table_reports_reproduce_every_printed_value() {
    let dir = tempfile::tempdir().unwrap();
    for (id, expected) in [("zhang-table7", "6 of 6"), ("zhang-tables", "18 of 18")] {
        let out = hushfuse(&["reproduce", id, "--out", "o"], dir.path());
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            stdout.contains(&format!("{expected} printed values reproduced")),
            "{stdout}"
        );
    }
}

#[test]
fn zhang_fig5_runs_with_few_trials() {
    let dir = tempfile::tempdir().unwrap();
    let out = hushfuse(
        &["reproduce", "zhang-fig5", "--trials", "10", "--out", "o"],
        dir.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("close to the analog EKF"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap())
            .unwrap();
    // Three activated sensors each get y_hat and Delta: 3 x 2 x 32 downlink bits per step.
    assert_eq!(
        json["schemes"][0]["downlink_bits_per_step"]
            .as_f64()
            .unwrap(),
        192.0
    );
}

/// Bad input to the particle-filter scheme's fields gets exit code 2 and names the field.
#[test]
fn bad_censoring_parameters_exit_2() {
    let base = VALID.split("[[schemes]]").next().unwrap();
    let cases: &[(&str, &str)] = &[
        ("kind = \"censored-pf\"\nl = 3.0\n", "l"),
        ("kind = \"censored-pf\"\nl = 0.0\n", "l"),
        (
            "kind = \"censored-pf\"\nl = 1.0\nparticles = 0\n",
            "particles",
        ),
        (
            "kind = \"censored-pf\"\nl = 1.0\nfeedback = \"sometimes\"\n",
            "feedback",
        ),
        ("kind = \"censored-pf\"\npolicy = \"random\"\n", "l"),
    ];
    for (scheme, field) in cases {
        let (code, stderr) = run_text(&format!("{base}[[schemes]]\n{scheme}"));
        assert_eq!(code, Some(2), "{scheme}: {stderr}");
        assert!(
            stderr.contains(field),
            "{scheme}: {field} not named in {stderr}"
        );
    }
    // A range sensor placed on state indices the model does not have.
    let text = format!(
        "{}[[sensors]]\nkind = \"range\"\nposition = [0.0, 0.0]\nposition_indices = [0, 7]\nR_diag = [1.0]\n[[schemes]]\nkind = \"centralized-kf\"\n",
        base
    );
    let (code, stderr) = run_text(&text);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("position_indices"), "{stderr}");
}

/// One trial has no standard errors (NaN, written as null): that is no overflow, and the run
/// succeeds.
#[test]
fn a_single_trial_run_succeeds_without_standard_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scenario.toml");
    std::fs::write(&path, VALID).unwrap();
    let out = hushfuse(
        &["run", path.to_str().unwrap(), "--trials", "1", "--out", "o"],
        dir.path(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("not finite"), "{stderr}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap())
            .unwrap();
    assert!(json["schemes"][0]["anees_se"].is_null());
}
