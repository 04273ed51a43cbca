//! Wall time of whole built-in scenario runs, all cores: `cargo bench --bench scenarios`.
//! Default: the `dormann-fig1` sweep (93 scheme variants x 500 trials x 100 steps) and the
//! `zhang-fig5` run (4 schemes x 1000 trials x 100 steps, 50 range sensors).
//! Environment: HUSHFUSE_BENCH_SCENARIOS (comma-separated built-in names),
//! HUSHFUSE_BENCH_THREADS (pin the thread count), HUSHFUSE_BENCH_REPEATS (default 3).
use hushfuse::sim::{build, builtin, runner};
use std::time::Instant;

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let threads: usize = env("HUSHFUSE_BENCH_THREADS", 0);
    let repeats: usize = env("HUSHFUSE_BENCH_REPEATS", 3);
    let names: String = env(
        "HUSHFUSE_BENCH_SCENARIOS",
        "dormann-fig1,zhang-fig5".to_string(),
    );
    // Under `cargo test --benches` (no --bench flag) do one tiny run of each only.
    let quick = !std::env::args().any(|a| a == "--bench");
    for name in names.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let text = builtin::get(name).unwrap_or_else(|| panic!("no built-in scenario {name}"));
        let mut exp = build::load(text, name).unwrap();
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
            "{name}: {} variants x {} trials x {} steps, threads={}: min {:.2} s, median {:.2} s over {} runs",
            exp.variants.len(),
            exp.trials,
            exp.steps,
            if threads == 0 { "all".to_string() } else { threads.to_string() },
            times[0],
            times[times.len() / 2],
            times.len()
        );
    }
}
