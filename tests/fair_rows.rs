//! Fair rows (issue 24, item 5): Geng et al.'s round-robin schemes have a bandwidth knob,
//! `granted` (sensors granted per step), that the calibration tunes; arena-1d's Tobit rows read
//! a censoring region that suits the target (no saturated sensor no other row has); and an
//! entry's `note` says what differs on a row, under the table and in `summary.json`.
use hushfuse::engine::calibrate::{self, Status};
use hushfuse::engine::runner;
use hushfuse::metrics::{notes, results};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;

/// The kinds of Geng et al.'s three round-robin schemes.
const GENG: [&str; 3] = ["federated-tobit", "round-robin-kf", "tobit-pf"];

/// arena-1d's system (4 scalar sensors, 100 steps) with `trials` trials and only `schemes`.
fn arena_1d_with(schemes: &str, trials: usize) -> String {
    let mut t: toml::Table = toml::from_str(builtin::get("arena-1d").unwrap()).unwrap();
    t.remove("every_scheme");
    t.remove("schemes");
    t.insert("trials".into(), toml::Value::Integer(trials as i64));
    format!("{}\n{schemes}", toml::to_string(&t).unwrap())
}

fn run(text: &str) -> results::Summary {
    let exp = build::load(text, "test").unwrap();
    let sums = runner::run(&exp, runner::RunOptions::default(), &|_| {}).unwrap();
    results::summarize(&exp, &sums)
}

fn rmse(s: &results::SchemeSummary) -> f64 {
    s.mean_rmse["position"]
}

/// `granted = N`: every sensor at every step, so the payload is the all-data KF's (4 x 32 bits)
/// and the round-robin KF *is* the all-data KF; FTKF-DB on an uncensored region (its Tobit
/// update then is the KF's) fuses to it too.
#[test]
fn granted_n_sends_every_sensor_every_step() {
    let s = run(&arena_1d_with(
        r#"
[[schemes]]
kind = "centralized-kf"
[[schemes]]
kind = "round-robin-kf"
granted = 4
[[schemes]]
kind = "federated-tobit"
granted = 4
[[schemes]]
kind = "tobit-pf"
granted = 4.0
particles = 300
"#,
        10,
    ));
    let all = &s.schemes[0];
    assert_eq!(all.bits_per_step, 128.0);
    for r in &s.schemes[1..] {
        assert_eq!(r.bits_per_step, all.bits_per_step, "{}", r.name);
        assert_eq!(r.transmissions_per_step, 4.0, "{}", r.name);
    }
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    assert!(rel(rmse(&s.schemes[1]), rmse(all)) < 1e-9, "round-robin KF");
    assert!(rel(rmse(&s.schemes[2]), rmse(all)) < 1e-6, "FTKF-DB");
    // The particle filter on the same data: within Monte Carlo error of the KF.
    assert!(rel(rmse(&s.schemes[3]), rmse(all)) < 0.1, "Exact Tobit PF");
}

/// `granted = 1` is the default, the paper's round-robin, number for number; a fraction grants
/// a sensor every 1/granted steps and more than one grants that many a step on average:
/// 32 granted payload bits per step.
#[test]
fn granted_sets_the_payload_and_one_is_the_papers_protocol() {
    let mut schemes = String::new();
    for kind in GENG {
        for g in ["", "granted = 1.0", "granted = 0.5", "granted = 2.5"] {
            let label = format!("{kind} {g}");
            schemes.push_str(&format!(
                "[[schemes]]\nkind = \"{kind}\"\nlabel = \"{label}\"\n{g}\n{}\n",
                if kind == "tobit-pf" {
                    "particles = 200"
                } else {
                    ""
                }
            ));
        }
    }
    let s = run(&arena_1d_with(&schemes, 6));
    for (i, kind) in GENG.iter().enumerate() {
        let row = &s.schemes[4 * i..4 * i + 4];
        assert_eq!(
            row[0].bits_per_step, 32.0,
            "{kind}: the paper's one reading a step"
        );
        // Default and granted = 1: the same numbers (the Tobit PF's coins come from the
        // variant's index, so only the deterministic filters are compared number for number).
        if *kind != "tobit-pf" {
            assert_eq!(row[0].mean_rmse, row[1].mean_rmse, "{kind}");
            assert_eq!(row[0].mse, row[1].mse, "{kind}");
            assert_eq!(row[0].anees_per_step, row[1].anees_per_step, "{kind}");
        }
        assert_eq!(row[1].bits_per_step, 32.0, "{kind}");
        assert_eq!(
            row[2].bits_per_step, 16.0,
            "{kind}: a sensor every other step"
        );
        assert_eq!(row[3].bits_per_step, 80.0, "{kind}: 2.5 sensors a step");
        // More readings, a smaller error.
        assert!(
            rmse(&row[3]) < rmse(&row[1]) && rmse(&row[1]) < rmse(&row[2]),
            "{kind}"
        );
    }
}

/// `granted` outside (0, N] is refused, naming the field, for each of the three kinds.
#[test]
fn granted_out_of_range_is_refused() {
    for kind in GENG {
        for g in ["0.0", "-1.0", "4.5", "nan", "\"two\""] {
            let text = arena_1d_with(
                &format!("[[schemes]]\nkind = \"{kind}\"\ngranted = {g}\n"),
                2,
            );
            let e = build::load(&text, "test").err().unwrap().to_string();
            assert!(e.contains("granted"), "{kind}, granted = {g}: {e}");
        }
    }
}

/// The calibration tunes the round-robin schemes' `granted` to a budget: 48 payload bits per
/// step is 1.5 sensors a step.
#[test]
fn calibration_tunes_the_round_robin_schemes() {
    let text = arena_1d_with(
        r#"
[[schemes]]
kind = "round-robin-kf"
[[schemes]]
kind = "federated-tobit"
tau_l = [-1000.0, -1000.0, -1000.0, -20.0]
tau_r = [1000.0, 1000.0, 1000.0, 20.0]
"#,
        8,
    );
    let out = calibrate::calibrate(&text, "test", &[48.0, 12.0], &Default::default()).unwrap();
    for (b, row) in out.rows.iter().enumerate() {
        for c in row {
            assert_eq!(c.status, Status::Calibrated, "{} at {}", c.label, c.target);
            assert_eq!(c.knob.as_deref(), Some("granted"));
            assert!(
                (c.achieved - out.budgets[b]).abs() <= out.tolerance * out.budgets[b],
                "{}: achieved {} for {}",
                c.label,
                c.achieved,
                out.budgets[b]
            );
            let g = c.value.unwrap();
            assert!(
                (g - out.budgets[b] / 32.0).abs() < 0.05,
                "{}: granted {g}",
                c.label
            );
        }
    }
}

/// arena-1d's Tobit rows no longer measure a saturated sensor: no trial diverges and their
/// error is the round-robin KF's on the same schedule (within Monte Carlo error for the
/// particle filter), a sane factor of the all-data KF's; their note says so under the table.
#[test]
fn arena_1d_tobit_rows_are_not_saturated() {
    let mut t: toml::Table = toml::from_str(builtin::get("arena-1d").unwrap()).unwrap();
    t.insert("trials".into(), toml::Value::Integer(40));
    let s = run(&toml::to_string(&t).unwrap());
    let by = |kind: &str| s.schemes.iter().find(|r| r.kind == kind).unwrap();
    let all = by("centralized-kf");
    let rr = by("round-robin-kf");
    for kind in ["federated-tobit", "tobit-pf"] {
        let r = by(kind);
        assert_eq!(r.diverged_fraction, 0.0, "{kind}");
        assert!(
            rmse(r) < 1.1 * rmse(rr),
            "{kind}: {} vs {}",
            rmse(r),
            rmse(rr)
        );
        assert!(
            rmse(r) < 3.0 * rmse(all),
            "{kind}: {} vs {}",
            rmse(r),
            rmse(all)
        );
        assert!(
            r.note.as_deref().unwrap().contains("never saturate"),
            "{kind}"
        );
    }
    let table = notes::block(&s);
    assert!(
        table.contains("\nnote: FTKF-DB: censoring region"),
        "{table}"
    );
    assert!(
        table.contains("\nnote: Exact Tobit PF: censoring region"),
        "{table}"
    );
    // Rows without a note have none, in summary.json too.
    assert!(all.note.is_none());
    let json = serde_json::to_value(&s).unwrap();
    let rows = json["schemes"].as_array().unwrap();
    assert_eq!(rows.iter().filter(|r| r.get("note").is_some()).count(), 2);
}

/// arena-tobit keeps the paper's region on its Tobit rows and says so in a note.
#[test]
fn arena_tobit_notes_its_censored_rows() {
    let exp = build::load(builtin::get("arena-tobit").unwrap(), "arena-tobit").unwrap();
    let noted: Vec<&str> = exp
        .curves
        .iter()
        .filter(|c| c.note.is_some())
        .map(|c| c.kind.as_str())
        .collect();
    assert_eq!(noted, ["federated-tobit", "tobit-pf"]);
}

/// `note` is validated like every field: a non-empty string, not swept; a misspelt key is an
/// error; a swept entry's note is printed once.
#[test]
fn note_is_validated_and_printed_once() {
    for (entry, field) in [
        ("note = 3", "schemes[0].note"),
        ("note = \"  \"", "schemes[0].note"),
        ("notes = \"x\"", "notes"),
        (
            "note = \"x\"\nsweep = { note = [\"a\", \"b\"] }",
            "schemes[0].sweep.note",
        ),
    ] {
        let text = arena_1d_with(
            &format!("[[schemes]]\nkind = \"round-robin-kf\"\n{entry}\n"),
            2,
        );
        let e = build::load(&text, "test").err().unwrap().to_string();
        assert!(e.contains(field), "{entry}: {e}");
    }
    let s = run(&arena_1d_with(
        "[[schemes]]\nkind = \"round-robin-kf\"\nnote = \"mine\"\nsweep = { granted = [1.0, 2.0] }\n",
        2,
    ));
    assert_eq!(notes::lines(&s), ["Round-robin KF (uncensored): mine"]);
    assert_eq!(
        notes::block(&s),
        "\nnote: Round-robin KF (uncensored): mine\n"
    );
}

/// The schedule behind `granted`: at 1 it grants exactly Geng et al.'s sensor (k - 1) mod N
/// (eq. (5)) at every step, at N every sensor, and over any N steps each sensor the same number
/// of times (`granted` times), whatever the fraction.
#[test]
fn granted_schedule_generalizes_the_round_robin() {
    use hushfuse::network::Schedule;
    for n in 1..=7 {
        let one = Schedule::RoundRobinGranted(1.0);
        let all = Schedule::RoundRobinGranted(n as f64);
        for k in 1..=500 {
            for i in 0..n {
                assert_eq!(
                    one.allows(k, i, n),
                    Schedule::RoundRobin.allows(k, i, n),
                    "n {n}, k {k}, i {i}"
                );
                assert!(all.allows(k, i, n), "n {n}, k {k}, i {i}");
            }
        }
        for g in [0.25, 0.5, 1.5, 2.5] {
            if g > n as f64 {
                continue;
            }
            let s = Schedule::round_robin(g);
            // 4 N steps: 4 N g slots, 4 g per sensor.
            for i in 0..n {
                let count = (1..=4 * n).filter(|&k| s.allows(k, i, n)).count();
                assert_eq!(count as f64, 4.0 * g, "n {n}, granted {g}, sensor {i}");
            }
        }
    }
    assert_eq!(Schedule::round_robin(1.0), Schedule::RoundRobin);
}

/// The notes as the user sees them: under the table of a run and of each budget of a
/// calibrated run, and in `summary.json`; the calibrated run tunes `granted`.
#[test]
fn the_cli_prints_and_keeps_the_notes() {
    let dir = tempfile::tempdir().unwrap();
    let hushfuse = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_hushfuse"))
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(0), "{args:?}: {out:?}");
        String::from_utf8(out.stdout).unwrap()
    };
    let plain = dir.path().join("plain");
    let text = hushfuse(&[
        "run",
        "arena-1d",
        "--trials",
        "4",
        "--report",
        "--out",
        plain.to_str().unwrap(),
    ]);
    assert!(
        text.contains("\nnote: FTKF-DB: censoring region +-1000"),
        "{text}"
    );
    assert!(
        text.contains("\nnote: Exact Tobit PF: censoring region"),
        "{text}"
    );
    let json = std::fs::read_to_string(plain.join("summary.json")).unwrap();
    assert_eq!(json.matches("\"note\":").count(), 2);
    let report = std::fs::read_to_string(plain.join("report.html")).unwrap();
    assert!(report.contains("<h3>Notes</h3>"), "report.html");
    assert!(
        report.contains("<li>FTKF-DB: censoring region +-1000"),
        "report.html"
    );
    let budget = dir.path().join("budget");
    let text = hushfuse(&[
        "run",
        "arena-1d",
        "--trials",
        "4",
        "--budget",
        "48",
        "--budget-axis",
        "payload",
        "--out",
        budget.to_str().unwrap(),
    ]);
    assert!(
        text.contains("\nnote: FTKF-DB: censoring region +-1000"),
        "{text}"
    );
    assert!(text.contains("granted = 1.5"), "{text}");
}
