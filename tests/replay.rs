//! `hushfuse replay`: recorded data through every scheme. Data written from a simulation
//! replays to that simulation's summary.json; a missing reading is a sensor not scheduled;
//! every kind of bad data gets an error naming the file, the line (data row) and the column.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;
use hushfuse::engine::replay::{self, DataError, ReplayError, ReplayOptions};
use hushfuse::engine::runner;
use hushfuse::scenario::build;
use std::path::Path;
use std::process::Output;

const SCENARIO: &str = include_str!("../examples/replay/scenario.toml");

/// The example's model with a censoring particle filter, a scheme with feedback and one
/// with a round-robin schedule as well.
fn scenario_with_more_schemes() -> String {
    format!(
        "{SCENARIO}\n[[schemes]]\nkind = \"censored-pf\"\nl = 1.0\nparticles = 200\nfeedback = \"prediction\"\n\
         \n[[schemes]]\nkind = \"round-robin-kf\"\n\
         \n[[schemes]]\nkind = \"centralized-kf-random\"\nrate = 0.5\n"
    )
    .replace(
        "[[sensors]]\nname = \"pos-vel\"\nobserve = [0, 1]\nR_diag = [1.5, 0.5]\n\n[[sensors]]\nname = \"pos-vel-b\"\nobserve = [0, 1]\nR_diag = [3.0, 1.0]\n",
        "",
    )
}

fn ok(out: &Output) {
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `run --trials 1 --write-trial 0 DIR`, then `replay` of DIR's CSV files: the same
/// summary.json, number for number (schemes with coins, feedback, a particle filter and a
/// round-robin schedule among them).
#[test]
fn replay_of_simulated_trial_reproduces_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("s.toml"), scenario_with_more_schemes()).unwrap();
    ok(&hushfuse(
        &[
            "run",
            "s.toml",
            "--trials",
            "1",
            "--seed",
            "11",
            "--out",
            "run",
            "--write-trial",
            "0",
            "data",
        ],
        d,
    ));
    ok(&hushfuse(
        &[
            "replay",
            "s.toml",
            "--seed",
            "11",
            "--measurements",
            "data/measurements.csv",
            "--truth",
            "data/truth.csv",
            "--out",
            "rep",
        ],
        d,
    ));
    let mut run = json(&d.join("run/summary.json"));
    run.as_object_mut().unwrap().remove("paper");
    let rep = json(&d.join("rep/summary.json"));
    assert_eq!(run["schemes"].as_array().unwrap().len(), 8);
    assert_eq!(run, rep);
    // per_step.csv too, and estimates.csv has one row per variant and step.
    assert_eq!(
        std::fs::read_to_string(d.join("run/per_step.csv")).unwrap(),
        std::fs::read_to_string(d.join("rep/per_step.csv")).unwrap()
    );
    let est = std::fs::read_to_string(d.join("rep/estimates.csv")).unwrap();
    assert_eq!(est.lines().count(), 1 + 8 * 40);
    // A different seed gives the schemes other coins: the summary changes (so the equality
    // above is not vacuous).
    ok(&hushfuse(
        &[
            "replay",
            "s.toml",
            "--seed",
            "12",
            "--measurements",
            "data/measurements.csv",
            "--truth",
            "data/truth.csv",
            "--out",
            "rep12",
        ],
        d,
    ));
    assert_ne!(
        run["schemes"],
        json(&d.join("rep12/summary.json"))["schemes"]
    );
}

/// Trial K's data replays with trial K's coins (`--trial K`) to the estimates of trial K.
#[test]
fn replay_of_a_later_trial_uses_that_trials_coins() {
    let text = scenario_with_more_schemes();
    let exp = build::load(&text, "s.toml").unwrap();
    let data = runner::draw_trial(&exp, 3);
    let (m, t) = (
        replay::measurements_csv(&exp, &data),
        replay::truth_csv(&data),
    );
    let opts = |trial| ReplayOptions {
        trial,
        ..Default::default()
    };
    let r3 = replay::replay_csv(&text, "s", (&m, "m"), Some((&t, "t")), &opts(3)).unwrap();
    let direct = replay::replay(&exp, &replay::Recorded::from_trial(&data), 3).unwrap();
    let r0 = replay::replay_csv(&text, "s", (&m, "m"), Some((&t, "t")), &opts(0)).unwrap();
    for (v, vr) in direct.variants.iter().enumerate() {
        assert_eq!(
            vr.estimates, r3.replayed.variants[v].estimates,
            "variant {v}"
        );
    }
    // The censored PF (variant 5) and the random scheme (7) draw coins: trial 0's differ.
    assert_ne!(
        direct.variants[7].estimates,
        r0.replayed.variants[7].estimates
    );
}

/// A sensor without readings is a sensor the network never scheduled: the centralized KF on
/// two sensors with the second always missing equals the KF of the first sensor alone, bit for
/// bit; the missing sensor sends nothing and is marked `missing`.
#[test]
fn missing_readings_are_not_scheduled() {
    let two = scenario_with_more_schemes();
    let exp = build::load(&two, "two").unwrap();
    let data = runner::draw_trial(&exp, 0);
    let full = replay::measurements_csv(&exp, &data);
    let only0: String = full
        .lines()
        .filter(|l| !l.starts_with("step") && l.split(',').nth(1) == Some("0"))
        .map(|l| format!("{l}\n"))
        .collect();
    let with_header = format!("step,sensor,z0\n{only0}");
    let truth = replay::truth_csv(&data);
    let a = replay::replay_csv(
        &two,
        "two",
        (&with_header, "m"),
        Some((&truth, "t")),
        &ReplayOptions::default(),
    )
    .unwrap();
    let one = two.replace(
        "[[sensors]]\nname = \"pos-b\"\nobserve = [0]\nR_diag = [2.0]\n",
        "",
    );
    assert_ne!(one, two);
    let b = replay::replay_csv(
        &one,
        "one",
        (&with_header, "m"),
        Some((&truth, "t")),
        &ReplayOptions::default(),
    )
    .unwrap();
    assert_eq!(
        a.replayed.variants[0].estimates,
        b.replayed.variants[0].estimates
    );
    let csv = replay::estimates_csv(&a.exp, &a.recorded, &a.replayed);
    let row1 = csv.lines().nth(1).unwrap();
    assert!(row1.ends_with(",sent,32,missing,0"), "{row1}");
    // And the whole-data replay is different (the second sensor was used there).
    let c = replay::replay_csv(
        &two,
        "two",
        (&full, "m"),
        Some((&truth, "t")),
        &ReplayOptions::default(),
    )
    .unwrap();
    assert_ne!(
        a.replayed.variants[0].estimates,
        c.replayed.variants[0].estimates
    );
}

/// Runs a replay of the example scenario on the given texts and returns the input error.
fn data_error(meas: &str, truth: Option<&str>) -> String {
    match replay::replay_csv(
        SCENARIO,
        "scenario.toml",
        (meas, "m.csv"),
        truth.map(|t| (t, "t.csv")),
        &ReplayOptions::default(),
    ) {
        Err(ReplayError::Run(m)) => panic!("expected an input error, got a run error: {m}"),
        Err(e) => e.to_string(),
        Ok(_) => panic!("expected an error for\n{meas}"),
    }
}

const HEAD: &str = "step,sensor,z0,z1\n";
const TRUTH_HEAD: &str = "step,x0,x1\n";

/// Every kind of bad data, with the file, line, data row and column it must name.
#[test]
fn bad_data_errors_name_file_row_and_column() {
    let cases: &[(&str, Option<&str>, &str)] = &[
        // non-numeric
        (
            "1,0,1.0\n1,1,abc\n",
            None,
            "m.csv: line 3 (data row 2), column 3 (z0): expected a number, got \"abc\"",
        ),
        // non-finite
        (
            "1,0,1.0\n1,2,0.5,inf\n",
            None,
            "m.csv: line 3 (data row 2), column 4 (z1): \"inf\" is not a finite number",
        ),
        (
            "1,0,NaN\n",
            None,
            "m.csv: line 2 (data row 1), column 3 (z0): \"NaN\" is not a finite number",
        ),
        // a sensor the scenario does not have
        (
            "1,0,1.0\n2,4,1.0\n",
            None,
            "m.csv: line 3 (data row 2), column 2 (sensor): the scenario has no sensor 4 (it has 4: indices 0 to 3)",
        ),
        (
            "1,-1,1.0\n",
            None,
            "m.csv: line 2 (data row 1), column 2 (sensor): expected a sensor index as a whole number >= 0, got \"-1\"",
        ),
        // wrong number of components: too many, too few
        (
            "1,0,1.0\n1,1,1.0,2.0\n",
            None,
            "m.csv: line 3 (data row 2), column 4 (z1): sensor 1 measures 1 component, this row has 2",
        ),
        (
            "1,2,1.0\n",
            None,
            "m.csv: line 2 (data row 1), column 4 (z1): sensor 2 measures 2 components, this row has 1",
        ),
        (
            "1,2,,1.0\n",
            None,
            "m.csv: line 2 (data row 1), column 3 (z0): empty field before further components",
        ),
        (
            "1,2\n",
            None,
            "m.csv: line 2 (data row 1), column 3 (z0): no components",
        ),
        // steps out of order, duplicated, not a step
        (
            "1,0,1.0\n3,0,1.0\n2,0,1.0\n",
            None,
            "m.csv: line 4 (data row 3), column 1 (step): step 2 after step 3: steps out of order",
        ),
        (
            "1,0,1.0\n1,1,1.0\n1,0,2.0\n",
            None,
            "m.csv: line 4 (data row 3), column 2 (sensor): sensor 0 at step 1 is duplicated (first on line 2)",
        ),
        (
            "0,0,1.0\n",
            None,
            "m.csv: line 2 (data row 1), column 1 (step): a step must be at least 1, got 0",
        ),
        (
            "1.5,0,1.0\n",
            None,
            "m.csv: line 2 (data row 1), column 1 (step): expected a step as a whole number >= 1, got \"1.5\"",
        ),
        // a measurement beyond the truth
        (
            "1,0,1.0\n3,0,1.0\n",
            Some("1,0,1\n2,0,1\n"),
            "m.csv: line 3 (data row 2), column 1 (step): step 3 is beyond the last step of the truth (t.csv, 2 steps)",
        ),
        // truth of the wrong dimension, too few and too many
        (
            "1,0,1.0\n",
            Some("1,0.5\n"),
            "t.csv: line 2 (data row 1), column 3 (x1): the state has 2 components, this row has 1",
        ),
        (
            "1,0,1.0\n",
            Some("1,0,1\n2,0,1,7\n"),
            "t.csv: line 3 (data row 2), column 4 (beyond the header): the state has 2 components, this row has 3",
        ),
        // truth steps duplicated, with a gap, non-numeric
        (
            "1,0,1.0\n",
            Some("1,0,1\n1,0,1\n"),
            "t.csv: line 3 (data row 2), column 1 (step): expected step 2 here, got 1 (out of order or duplicated)",
        ),
        (
            "1,0,1.0\n",
            Some("1,0,1\n3,0,1\n"),
            "t.csv: line 3 (data row 2), column 1 (step): expected step 2 here, got 3 (a gap)",
        ),
        (
            "1,0,1.0\n",
            Some("1,0,x\n"),
            "t.csv: line 2 (data row 1), column 3 (x1): expected a number, got \"x\"",
        ),
    ];
    for (rows, truth, expected) in cases {
        let meas = format!("{HEAD}{rows}");
        let truth = truth.map(|t| format!("{TRUTH_HEAD}{t}"));
        let got = data_error(&meas, truth.as_deref());
        assert!(
            got.starts_with(expected),
            "data\n{meas}{}\nexpected: {expected}\ngot:      {got}",
            truth.unwrap_or_default()
        );
    }
}

/// A file without the header, or with another one, is refused at line 1.
#[test]
fn header_is_required() {
    let got = data_error("1,0,1.0\n2,0,1.0\n", None);
    assert!(
        got.starts_with(
            "m.csv: line 1, column 1 (1): expected the header row to start with `step,sensor,...`"
        ),
        "{got}"
    );
    let e: DataError = replay::parse_truth("time,x0\n1,0\n", "t.csv").unwrap_err();
    assert_eq!((e.line, e.column.map(|c| c.0)), (Some(1), Some(1)));
}

/// Through the command line: bad data exits with code 2 and names the file; the shipped
/// example replays.
#[test]
fn cli_bad_data_exits_2_and_example_replays() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("bad.csv"), "step,sensor,z0\n1,0,oops\n").unwrap();
    let root = env!("CARGO_MANIFEST_DIR");
    let scen = format!("{root}/examples/replay/scenario.toml");
    let out = hushfuse(&["replay", &scen, "--measurements", "bad.csv"], d);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "bad.csv: line 2 (data row 1), column 3 (z0): expected a number, got \"oops\""
        ),
        "{err}"
    );
    let out = hushfuse(
        &[
            "replay",
            &scen,
            "--measurements",
            &format!("{root}/examples/replay/measurements.csv"),
            "--truth",
            &format!("{root}/examples/replay/truth.csv"),
            "--out",
            "ex",
        ],
        d,
    );
    ok(&out);
    let est = std::fs::read_to_string(d.join("ex/estimates.csv")).unwrap();
    assert_eq!(est.lines().count(), 1 + 5 * 40);
    assert!(est.contains(",missing,0"));
    assert!(d.join("ex/summary.json").exists());
}
