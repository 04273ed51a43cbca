//! Valid input that used to be refused: a scheme that never sends over a lossy link (its loss
//! fraction is "no packets", not a non-finite result), a recording with no reading at all
//! replayed with `--truth --loss`, and `--loss` on a scenario whose entry sweeps its loss
//! awareness or already has a "… (loss-aware)" label.
use std::path::Path;
use std::process::{Command, Output};

fn hushfuse(args: &[&str], d: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .current_dir(d)
        .output()
        .unwrap()
}

fn ok(out: &Output) {
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

const SCALAR: &str = "name = \"t\"\ntrials = 4\nsteps = 20\nseed = 1\n[model]\nkind = \"matrix\"\nF = [[0.9]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n";

#[test]
fn a_scheme_that_never_sends_over_a_lossy_link_is_no_failure() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = format!(
        "{SCALAR}[[schemes]]\nkind = \"innovation-trigger-kf\"\ndelta = 1e9\n[channel]\nkind = \"bernoulli\"\nloss = 0.2\n"
    );
    std::fs::write(d.join("never.toml"), text).unwrap();
    ok(&hushfuse(&["run", "never.toml", "--out", "out"], d));
    let summary = std::fs::read_to_string(d.join("out/summary.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&summary).unwrap();
    let link = &v["schemes"][0]["link"];
    assert_eq!(link["sent"], 0.0);
    assert!(link["loss_fraction"].is_null(), "{link}");
}

#[test]
fn a_recording_without_readings_replays_over_a_lossy_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&hushfuse(
        &[
            "run",
            "arena-1d",
            "--trials",
            "1",
            "--out",
            "sim",
            "--write-trial",
            "0",
            "data",
        ],
        d,
    ));
    let m = std::fs::read_to_string(d.join("data/measurements.csv")).unwrap();
    std::fs::write(
        d.join("header.csv"),
        format!("{}\n", m.lines().next().unwrap()),
    )
    .unwrap();
    ok(&hushfuse(
        &[
            "replay",
            "arena-1d",
            "--measurements",
            "header.csv",
            "--truth",
            "data/truth.csv",
            "--loss",
            "0.2",
            "--out",
            "r",
        ],
        d,
    ));
}

#[test]
fn loss_on_sweeps_and_taken_labels_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = format!(
        "{SCALAR}[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[schemes]]\nkind = \"dkf-alg2-event\"\nalpha = 0.4\nb = 10.0\nsweep.loss_aware = [false, true]\n[[schemes]]\nkind = \"censored-pf\"\nlabel = \"PF\"\nl = 1.0\nparticles = 50\n[[schemes]]\nkind = \"censored-pf\"\nlabel = \"PF (loss-aware)\"\nl = 1.0\nparticles = 50\nlink_loss = 0.1\n"
    );
    std::fs::write(d.join("s.toml"), text).unwrap();
    let out = hushfuse(&["run", "s.toml", "--loss", "0.2", "--out", "out"], d);
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("PF (loss-aware, --loss)"), "{stdout}");
}
