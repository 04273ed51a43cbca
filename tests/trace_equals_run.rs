//! The trial-0 trace (`engine::trace`, the loop behind `report.html` and `replay`) of every
//! built-in equals trial 0 of the run (`engine::runner`, with its fast paths and batches) bit
//! for bit: both are the engine's one trial loop now, and this guards it.
use hushfuse::engine::replay::{self, Recorded};
use hushfuse::engine::runner;
use hushfuse::engine::trace;
use hushfuse::scenario::build::{self, FileKind, LoadOptions};
use hushfuse::scenario::builtin;

#[test]
fn the_trial_0_trace_of_every_builtin_is_trial_0_of_the_run() {
    let mut checked = 0;
    for (id, _, text) in builtin::BUILTIN {
        let source = format!("built-in:{id}");
        if build::file_kind(text, &source).unwrap() == FileKind::TableReport {
            continue;
        }
        let opts = LoadOptions {
            trials: Some(1),
            threads: 1,
            ..Default::default()
        };
        let exp = build::load_with(text, &source, &opts).unwrap();
        let run = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
        let data = runner::draw_trial(&exp, 0);
        let replayed = replay::replay(&exp, &Recorded::from_trial(&data), 0).unwrap();
        assert_eq!(
            replayed.sums.as_deref(),
            Some(run.as_slice()),
            "{id}: the trace loop's sums differ from the run's"
        );
        let t = trace::trace(&exp, 0, false).unwrap();
        for (v, (tv, rv)) in t.variants.iter().zip(&replayed.variants).enumerate() {
            assert_eq!(tv.estimates, rv.estimates, "{id}: variant {v}'s estimates");
            assert_eq!(tv.links, rv.links, "{id}: variant {v}'s links");
        }
        checked += 1;
    }
    assert!(checked >= 20, "only {checked} built-ins were checked");
}
