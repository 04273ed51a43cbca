//! Geng et al.'s `geng-oscillator` (1000 runs x 100 steps, every case) on one thread:
//! `cargo bench --bench federated_tobit`. One criterion sample is one whole case (all 1000
//! trials of one scheme variant); a 3-state Tobit KF should take well under a second per case.
use criterion::{criterion_group, criterion_main, Criterion};
use hushfuse::engine::runner;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use std::time::Duration;

fn oscillator(c: &mut Criterion) {
    let text = builtin::get("geng-oscillator").expect("built-in scenario");
    let full = build::load(text, "geng-oscillator").unwrap();
    let mut group = c.benchmark_group("geng-oscillator 1000x100, 1 thread");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(5));
    for v in 0..full.variants.len() {
        // One variant per case.
        let mut exp = build::load(text, "geng-oscillator").unwrap();
        let keep = exp.variants.remove(v);
        let label = format!("{} {:?}", exp.curves[keep.curve].label, keep.params);
        exp.variants = vec![keep];
        group.bench_function(label, |b| {
            b.iter(|| runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, oscillator);
criterion_main!(benches);
