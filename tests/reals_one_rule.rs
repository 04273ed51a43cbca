//! One rule decides whether a trial takes a fast path or a block runs as a batch
//! (`engine::link_layer::route`), asked by the runner and by the trial loop alike. Before it,
//! the runner batched `reals = "f64"` scenarios on ideal links (the batches deliver singles and
//! price 32 bits), while the trial loop sent them to the generic loop: the same file gave
//! other numbers with and without a `[channel]`. Here every built-in with `reals = "f64"` run by
//! the runner (blocks that could batch) gives the generic loop's numbers (replay's, which never
//! takes a fast path), and the rounding warning of the singles appears where it should.
use hushfuse::engine::replay::{self, Recorded};
use hushfuse::engine::runner;
use hushfuse::metrics::{results, Sums};
use hushfuse::scenario::build::{self, FileKind, LoadOptions};
use hushfuse::scenario::builtin;

fn load(text: &str, source: &str, trials: usize) -> Result<build::Experiment, String> {
    let opts = LoadOptions {
        trials: Some(trials),
        threads: 1,
        ..Default::default()
    };
    build::load_with(text, source, &opts).map_err(|e| e.to_string())
}

/// The runner's sums (threads 1) and, trial by trial, the generic loop's, merged.
fn runner_and_generic(exp: &build::Experiment) -> (Vec<Sums>, Vec<Sums>) {
    let run = runner::run(exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    let mut generic = runner::empty_sums(exp);
    for trial in 0..exp.trials {
        let data = runner::draw_trial(exp, trial);
        let r = replay::replay(exp, &Recorded::from_trial(&data), trial).unwrap();
        runner::fold_block(&mut generic, r.sums.as_deref().unwrap());
    }
    (run, generic)
}

/// Every per-step sum equal to 1e-12 relative (the two add the same numbers, maybe in another
/// order); counts of bits exactly.
fn assert_close(id: &str, a: &[Sums], b: &[Sums]) {
    for (v, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.trials, y.trials, "{id} variant {v}: trials");
        assert_eq!(x.sensors, y.sensors, "{id} variant {v}: per-sensor sends");
        assert_eq!(x.reading_peaks, y.reading_peaks, "{id} variant {v}: peaks");
        for (i, (p, q)) in x.per_step.iter().zip(&y.per_step).enumerate() {
            let tol = 1e-12 * p.abs().max(q.abs()).max(1e-300);
            assert!(
                (p - q).abs() <= tol,
                "{id} variant {v}: per-step sum {i}: runner {p}, generic loop {q}"
            );
        }
    }
}

/// The case: a = 1.2, q = r = 1, 100 steps, the all-data KF, no `[channel]`. With
/// doubles every reading costs 64 bits and the KF is consistent (MSE = its own covariance); with
/// singles the readings reach about 1e8, where a single rounds by several units, and the
/// summary warns, naming the sensor.
#[test]
fn doubles_on_an_ideal_link_are_priced_and_fused_as_doubles() {
    let text = |reals: &str| {
        format!(
            "name = \"a12\"\ntrials = 40\nsteps = 100\nseed = 1\n{reals}\n[model]\nkind = \"matrix\"\nF = [[1.2]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[schemes]]\nkind = \"centralized-kf\"\n"
        )
    };
    let exp = load(&text("reals = \"f64\""), "a12.toml", 40).unwrap();
    let (run, generic) = runner_and_generic(&exp);
    assert_close("a12", &run, &generic);
    let s = results::summarize(&exp, &run);
    let kf = &s.schemes[0];
    assert_eq!(kf.bits_per_step, 64.0, "one reading as a double per step");
    // A KF on exact readings: its steady-state MSE is its trace to within a few standard
    // errors (the singles gave 1.05 against 0.661).
    let (mse, se, trace) = (
        kf.steady_state.mse,
        kf.steady_state.mse_se,
        kf.steady_state.trace,
    );
    assert!(
        (mse - trace).abs() < 4.0 * se,
        "MSE {mse} ± {se}, trace {trace}"
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);

    let singles = load(&text(""), "a12.toml", 40).unwrap();
    let run = runner::run(&singles, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    let s = results::summarize(&singles, &run);
    assert_eq!(s.schemes[0].bits_per_step, 32.0);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    let w = &s.warnings[0];
    assert!(w.starts_with("sensor 0: readings reach"), "{w}");
    assert!(w.contains("reals = \"f64\""), "{w}");
    // Printed with the schemes' warnings, and written into summary.json.
    assert!(results::warnings(&s).contains(w));
    let json = serde_json::to_string(&s).unwrap();
    assert!(
        json.contains("\"warnings\":[\"sensor 0: readings reach"),
        "{json}"
    );
}

/// Every built-in scenario with `reals = "f64"` (where the scenario takes it: not with sequence
/// numbers, delays or ARQ): the runner's numbers, from blocks of 2 trials that the batches
/// would take, are the generic loop's.
#[test]
fn every_builtin_with_doubles_gives_the_generic_loops_numbers() {
    let mut checked = 0;
    for (id, _, text) in builtin::BUILTIN {
        let source = format!("built-in:{id}");
        if build::file_kind(text, &source).unwrap() == FileKind::TableReport {
            continue;
        }
        let doubled = if text.contains("\nreals = ") {
            text.to_string()
        } else {
            format!("reals = \"f64\"\n{text}")
        };
        let exp = match load(&doubled, &source, 2) {
            Ok(e) => e,
            Err(e) if e.contains("reals") => continue,
            Err(e) => panic!("{id}: {e}"),
        };
        let (run, generic) = runner_and_generic(&exp);
        assert_close(id, &run, &generic);
        // No variant that sends readings as reals is charged 32 bits for one: the payload of
        // the doubles' run is never below the singles' run's.
        let singles = load(text, &source, 2).unwrap();
        let single_run = runner::run(&singles, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
        let (d, s) = (
            results::summarize_schemes(&exp, &run),
            results::summarize_schemes(&singles, &single_run),
        );
        for (a, b) in d.schemes.iter().zip(&s.schemes) {
            if text.contains("\nreals = ") {
                assert_eq!(a.bits_per_step, b.bits_per_step, "{id}: {}", a.name);
            } else {
                assert!(a.bits_per_step >= b.bits_per_step, "{id}: {}", a.name);
            }
        }
        checked += 1;
    }
    assert!(
        checked >= 15,
        "only {checked} built-ins took reals = \"f64\""
    );
}
