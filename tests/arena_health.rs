//! Health in budget mode (issue 24): `--budget` prints the warnings a plain run prints, the
//! best-per-budget tables mark a scheme that diverged in more than 1% of its trials, the report
//! has the diverged and NEES-coverage columns and the warnings; and an integer knob whose range
//! cannot reach a budget is "out of range" at the end it was left at, never "nearest integer".
#[path = "common/cli.rs"]
mod common;

use common::hushfuse;
use hushfuse::engine::calibrate::{self, End, Status};
use hushfuse::metrics::results::{self, Summary};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;

/// `arena-1d`'s system (its every-scheme list dropped) with `schemes` (TOML) as its schemes.
fn arena_1d_with(name: &str, schemes: &str) -> String {
    let text = builtin::get("arena-1d").unwrap();
    let head = &text[..text.find("[[schemes]]").unwrap()];
    let head = head
        .replace("every_scheme = true\n", "")
        .replace("name = \"arena-1d\"", &format!("name = \"{name}\""));
    format!("{head}{schemes}")
}

/// Send-on-delta calibrated to 12 bits diverges in 2 of 20 trials of `arena-1d` (its delta of
/// ~15 leaves the center predicting for long stretches); FTKF-DB has no knob and spends 32.
const DIVERGING: &str = r#"
[[schemes]]
kind = "send-on-delta"
delta = 1.0

[[schemes]]
kind = "federated-tobit"
tau = 5.0
"#;

fn stdout(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The budget run prints every warning of its budget's summary, worded as a plain run words it
/// (the same function), marks the diverging best scheme with † and explains the mark; the
/// report has the columns, the warnings and the legend.
#[test]
fn a_budget_run_prints_and_reports_the_health_of_its_schemes() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("div.toml"), arena_1d_with("div", DIVERGING)).unwrap();
    let args = [
        "run",
        "div.toml",
        "--budget",
        "12",
        "--budget-axis",
        "payload",
        "--trials",
        "20",
        "--report",
        "--out",
        "o",
    ];
    let o = hushfuse(&args, d.path());
    let out = stdout(&o);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let json = std::fs::read_to_string(d.path().join("o/budget-12/summary.json")).unwrap();
    let summary: Summary = serde_json::from_str(&json).unwrap();
    let sod = summary
        .schemes
        .iter()
        .find(|s| s.kind == "send-on-delta")
        .unwrap();
    assert!(sod.diverged_fraction > 0.01, "{}", sod.diverged_fraction);
    let warnings = results::warnings(&summary);
    assert!(
        warnings.iter().any(|w| w.starts_with("Send-on-delta")),
        "{warnings:?}"
    );
    for w in &warnings {
        assert!(out.contains(&format!("warning: {w}\n")), "{w}\n---\n{out}");
    }
    // The best scheme at 12 is the diverging send-on-delta (FTKF-DB spends 32): marked.
    let best = out
        .lines()
        .find(|l| l.starts_with("12 "))
        .expect("a best-per-budget row");
    assert!(best.contains("Send-on-delta †"), "{best}");
    let legend = format!(
        "† diverged in more than 1% of its trials (NEES above the chi-square 99.9% quantile for 10 steps in a row, or not finite): Send-on-delta at budget 12 ({:.1}%)",
        100.0 * sod.diverged_fraction
    );
    assert!(out.contains(&legend), "{out}");
    let md = std::fs::read_to_string(d.path().join("o/best_per_budget.md")).unwrap();
    assert!(
        md.contains("Send-on-delta †") && md.contains(&legend),
        "{md}"
    );

    let html = std::fs::read_to_string(d.path().join("o/report.html")).unwrap();
    let calibration = &html[html.find("<h2>Calibration</h2>").unwrap()..];
    let calibration = &calibration[..calibration[4..].find("<h2>").unwrap() + 4];
    for col in ["NEES&lt;95%", "NEES&lt;99%", "diverged"] {
        assert!(calibration.contains(&format!("<th>{col}</th>")), "{col}");
    }
    assert!(
        calibration.contains(&format!("{:.1}%", 100.0 * sod.diverged_fraction)),
        "{calibration}"
    );
    assert!(calibration.contains("<ul class=\"warnings\">"));
    for w in &warnings {
        let w = w
            .replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;");
        assert!(calibration.contains(&format!("<li>{w}</li>")), "{w}");
    }
    assert!(html.contains("Send-on-delta †"));
    assert!(html.contains("<p class=\"legend\">† diverged in more than 1%"));
}

/// Healthy schemes: no warning, no mark, no legend.
#[test]
fn a_healthy_budget_run_has_no_warning_and_no_mark() {
    let d = tempfile::tempdir().unwrap();
    let text = arena_1d_with(
        "ok",
        "[[schemes]]\nkind = \"centralized-kf-random\"\nrate = 0.5\n",
    );
    std::fs::write(d.path().join("ok.toml"), text).unwrap();
    let args = [
        "run",
        "ok.toml",
        "--budget",
        "24",
        "--budget-axis",
        "payload",
        "--trials",
        "8",
        "--out",
        "o",
    ];
    let o = hushfuse(&args, d.path());
    let out = stdout(&o);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!out.contains("warning:") && !out.contains('†'), "{out}");
}

/// `quantized-innovation` on `arena-1d` reaches 3.3 to 31.8 payload bits per step with
/// `bits` = 1..=8: 48 is beyond the upper end, 1 below the lower one, 12 between two integers.
#[test]
fn an_integer_knob_beyond_its_range_is_out_of_range_at_that_end() {
    let text = arena_1d_with(
        "qi",
        "[[schemes]]\nkind = \"quantized-innovation\"\nquantizer = \"you\"\nbits = 2\n",
    );
    let opts = calibrate::Options {
        load: build::LoadOptions {
            trials: Some(4),
            ..Default::default()
        },
        ..Default::default()
    };
    let budgets = [1.0, 12.0, 48.0];
    let out = calibrate::calibrate(&text, "qi.toml", &budgets, &opts).unwrap();
    let at = |b: usize| &out.rows[b][0];
    assert_eq!(
        (at(2).status, at(2).end, at(2).value),
        (Status::OutOfRange, Some(End::Upper), Some(8.0))
    );
    assert!(at(2).achieved < 40.0, "{}", at(2).achieved);
    assert_eq!(at(2).status_text(), "out of range (upper end)");
    assert_eq!(
        (at(0).status, at(0).end, at(0).value),
        (Status::OutOfRange, Some(End::Lower), Some(1.0))
    );
    assert_eq!(at(0).status_text(), "out of range (lower end)");
    // 12 lies between what 3 and 4 bits spend: the nearest integer, no end.
    assert_eq!((at(1).status, at(1).end), (Status::NearestInteger, None));
    assert_eq!(at(1).status_text(), "nearest integer");
    let table = hushfuse::output::arena::budget_table(&out, 2, "position");
    assert!(
        table.contains("out of range (upper end)") && !table.contains("nearest integer"),
        "{table}"
    );
}
