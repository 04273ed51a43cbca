//! The arena (issue 11): calibration reaches its budget for every tunable scheme of an arena,
//! and the reported point is what the scheme does when run on its own at the calibrated knob.
#[path = "common/cli.rs"]
mod common;

use hushfuse::engine::calibrate::{self, Status};
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::output::{arena_files, OutputDir};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;

/// Every scheme of `arena-1d` whose knob can reach the budget is within the tolerance of it,
/// and rerunning each calibrated scheme alone from the scenario text as run gives the same
/// bits per step (the number in the table is a real run, not a pilot estimate).
#[test]
fn calibration_reaches_every_budget_of_arena_1d() {
    let text = builtin::get("arena-1d").unwrap();
    let opts = calibrate::Options {
        load: build::LoadOptions {
            trials: Some(16),
            ..Default::default()
        },
        ..Default::default()
    };
    let budgets = [12.0, 24.0];
    let out = calibrate::calibrate(text, "built-in:arena-1d", &budgets, &opts).unwrap();
    // The kinds whose knob reaches 12 and 24 payload bits per step on this system.
    let reachable = [
        "centralized-kf-random",
        "censored-pf",
        "innovation-trigger-kf",
        "stochastic-trigger-open",
        "stochastic-trigger-closed",
        "send-on-delta",
        "ci-fusion",
        "naive-fusion",
        // Geng et al.'s round-robin schemes, by the sensors granted per step.
        "federated-tobit",
        "round-robin-kf",
        "tobit-pf",
    ];
    for (b, row) in out.rows.iter().enumerate() {
        for c in row {
            let tunable = reachable.contains(&c.kind.as_str());
            if tunable {
                assert_eq!(
                    c.status,
                    Status::Calibrated,
                    "{} at {}",
                    c.label,
                    budgets[b]
                );
                assert!(
                    (c.achieved - budgets[b]).abs() <= out.tolerance * budgets[b],
                    "{}: achieved {} for target {}",
                    c.label,
                    c.achieved,
                    budgets[b]
                );
            }
            if c.status == Status::Calibrated {
                assert!((c.achieved - c.target).abs() <= out.tolerance * c.target);
            }
            if c.kind == "centralized-kf" {
                assert_eq!(c.status, Status::NoKnob);
            }
        }
        // Rerun every scheme alone from the scenario as run: the same bits per step.
        let table: toml::Table = toml::from_str(&out.texts[b]).unwrap();
        let entries = table["schemes"].as_array().unwrap().clone();
        for (e, c) in entries.iter().zip(row) {
            let mut t = table.clone();
            t.insert("schemes".into(), toml::Value::Array(vec![e.clone()]));
            let exp = build::load(&toml::to_string(&t).unwrap(), "rerun").unwrap();
            let sums = runner::run(&exp, runner::RunOptions::default(), &|_| {}).unwrap();
            let s = results::summarize(&exp, &sums);
            assert_eq!(s.schemes[0].bits_per_step, c.achieved, "{}", c.label);
        }
    }
}

/// A budget no knob range can meet is reported as out of range, not silently missed.
#[test]
fn unreachable_budgets_are_marked() {
    let text = builtin::get("arena-1d").unwrap();
    let opts = calibrate::Options {
        load: build::LoadOptions {
            trials: Some(8),
            ..Default::default()
        },
        ..Default::default()
    };
    let out = calibrate::calibrate(text, "built-in:arena-1d", &[12.0], &opts).unwrap();
    let alg1 = out.rows[0]
        .iter()
        .find(|c| c.kind == "dkf-alg1-random")
        .unwrap();
    // Algorithm 1 sends at least every other step: never 12 bits per step here.
    assert_eq!(alg1.status, Status::OutOfRange);
    assert!(alg1.achieved > 12.0);
}

/// On the energy axis (`--budget-axis energy`) every scheme whose knob reaches the budget
/// spends it within tolerance, in µJ of radio energy per step, and that figure is the
/// `energy_per_step_uj` of its summary.
#[test]
fn calibration_on_the_energy_axis_reaches_its_budget() {
    let text = builtin::get("arena-1d").unwrap();
    let opts = calibrate::Options {
        load: build::LoadOptions {
            trials: Some(8),
            ..Default::default()
        },
        axis: calibrate::Axis::Energy,
        ..Default::default()
    };
    // Four sensors asleep cost 4 × 3.0 V × 0.02 mA × 1 s ≈ 240 µJ per step; the all-data KF
    // (four frames every step) about 360 µJ: a budget of 300 µJ lies between.
    let budget = 300.0;
    let out = calibrate::calibrate(text, "built-in:arena-1d", &[budget], &opts).unwrap();
    let mut calibrated = 0;
    for (c, s) in out.rows[0].iter().zip(&out.summaries[0].schemes) {
        assert_eq!(c.achieved, s.energy.energy_per_step_uj, "{}", c.label);
        if c.kind == "centralized-kf-random" || c.kind == "send-on-delta" {
            assert_eq!(c.status, Status::Calibrated, "{}", c.label);
        }
        if c.status == Status::Calibrated {
            calibrated += 1;
            assert!(
                (c.achieved - budget).abs() <= out.tolerance * budget,
                "{}: {} µJ for {budget}",
                c.label,
                c.achieved
            );
        }
    }
    assert!(calibrated >= 2);
    assert_eq!(
        calibrate::Axis::parse("energy"),
        Ok(calibrate::Axis::Energy)
    );
}

/// The arena's folder written by the library ([`arena_files`], what the Python package calls)
/// is the command line's `run --budgets --report --out`, file for file and byte for byte (the
/// manifest of kind `arena` and its hash included), but for the seconds the calibration took.
#[test]
fn the_library_writes_the_arena_folder_of_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = [
        "run",
        "arena-1d",
        "--budgets",
        "270,330",
        "--trials",
        "8",
        "--report",
        "--out",
        "cli",
    ];
    let o = common::hushfuse(&args, d);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let text = builtin::get("arena-1d").unwrap();
    let source = "built-in:arena-1d";
    let budgets = [270.0, 330.0];
    let opts = calibrate::Options {
        axis: calibrate::Axis::Energy,
        load: build::LoadOptions {
            trials: Some(8),
            ..Default::default()
        },
        ..Default::default()
    };
    let out = calibrate::calibrate(text, source, &budgets, &opts).unwrap();
    assert!(arena_files::non_finite(&out).is_empty());
    let mut out_dir = OutputDir::open(&d.join("lib")).unwrap();
    let listed = arena_files::stage(&mut out_dir, &out, 1.0, (source, &opts.load), true).unwrap();
    // The rate–distortion figure needs the vector floor, which needs OpenBLAS (build.rs).
    let floor = cfg!(hushfuse_blas);
    let mut expected = vec![
        "calibration.json",
        "best_per_budget.md",
        "budget-270/",
        "budget-330/",
        "rmse_position_vs_bits.svg",
        "anees_vs_bits.svg",
    ];
    expected.extend(floor.then_some("mse_vs_r_eff.svg"));
    expected.push("report.html");
    assert_eq!(listed, expected);
    let hash = arena_files::inputs_sha256(text, source, &budgets, &opts);
    let files = arena_files::commit(out_dir, &out, &hash).unwrap();
    assert_eq!(files.len(), 11 + usize::from(floor), "{files:?}");

    let manifest = std::fs::read_to_string(d.join("lib/hushfuse-manifest.json")).unwrap();
    assert!(manifest.contains("\"kind\": \"arena\""), "{manifest}");
    for f in files
        .iter()
        .map(String::as_str)
        .chain(["hushfuse-manifest.json"])
    {
        let cli = std::fs::read(d.join("cli").join(f)).unwrap();
        let lib = std::fs::read(d.join("lib").join(f)).unwrap();
        if f != "calibration.json" {
            assert!(cli == lib, "{f} differs");
            continue;
        }
        let [mut cli, mut lib] =
            [cli, lib].map(|b| serde_json::from_slice::<serde_json::Value>(&b).unwrap());
        assert_eq!(lib["seconds"], 1.0);
        for j in [&mut cli, &mut lib] {
            j.as_object_mut().unwrap().remove("seconds");
        }
        assert_eq!(cli, lib);
        assert_eq!(lib["rows"].as_array().unwrap().len(), 2);
    }
}
