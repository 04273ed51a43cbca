//! Wall time of the whole `dormann-fig1` sweep (93 scheme variants x 500 trials x 100 steps),
//! all cores: `cargo bench --bench dormann_sweep`. Set HUSHFUSE_BENCH_THREADS to pin the
//! thread count and HUSHFUSE_BENCH_REPEATS for more repetitions (default 3).
use hushfuse::sim::{build, builtin, runner};
use std::time::Instant;

fn main() {
    let threads: usize = std::env::var("HUSHFUSE_BENCH_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let repeats: usize = std::env::var("HUSHFUSE_BENCH_REPEATS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    // `cargo test --benches` runs this with --bench absent: do one tiny run only.
    let quick = !std::env::args().any(|a| a == "--bench");
    let mut exp = build::load(
        builtin::get("dormann-fig1").unwrap(),
        "built-in:dormann-fig1",
    )
    .unwrap();
    if quick {
        exp.trials = 2;
    }
    let mut times = Vec::new();
    for _ in 0..if quick { 1 } else { repeats } {
        let t = Instant::now();
        let sums = runner::run(&exp, runner::RunOptions { threads }, &|_| {}).unwrap();
        times.push(t.elapsed().as_secs_f64());
        std::hint::black_box(sums);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "dormann-fig1 sweep: {} variants x {} trials x {} steps, threads={}: min {:.2} s, median {:.2} s over {} runs",
        exp.variants.len(),
        exp.trials,
        exp.steps,
        if threads == 0 { "all".to_string() } else { threads.to_string() },
        times[0],
        times[times.len() / 2],
        times.len()
    );
}
