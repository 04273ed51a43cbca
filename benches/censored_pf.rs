//! Zheng et al.'s (2014) particle-filter fusion center, exactly the work of the benchmarks:
//! (b) the scalar censored filter, 1,000 particles, 2 sensors, 1,000 trials x 20 steps;
//! (c) the nonlinear one, 10,000 particles, 9 RSS sensors, 200 trials x 20 steps;
//! both CFwMD with feedback (the full likelihood of every silent sensor); and (d) the cost of
//! CFwMD-exact's augmented particles against CFoMD on the same non-feedback run. One thread unless
//! HUSHFUSE_BENCH_THREADS says otherwise. `cargo bench --bench censored_pf [-- b c d]`.
use hushfuse::engine::runner;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use std::time::Instant;

fn scenario(name: &str, trials: usize, keep: &str) -> build::Experiment {
    let text = builtin::get(name)
        .unwrap()
        .replace("sweep.l = [1.0, 2.0]", "l = 2.0");
    let head = text.split("[[schemes]]").next().unwrap();
    let scheme = text
        .split("[[schemes]]")
        .find(|s| s.contains(&format!("label = \"{keep}\"")))
        .unwrap();
    let scheme = scheme.split("[paper]").next().unwrap();
    let mut exp = build::load(&format!("{head}[[schemes]]{scheme}"), name).unwrap();
    exp.trials = trials;
    exp
}

fn main() {
    let threads: usize = std::env::var("HUSHFUSE_BENCH_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let quick = !std::env::args().any(|a| a == "--bench");
    let cases = [
        (
            "(b) scalar: 1000 particles, 2 sensors, 1000 trials x 20 steps",
            scenario("zheng-fig1", if quick { 2 } else { 1000 }, "CFwMD"),
        ),
        (
            "(c) nonlinear: 10^4 particles, 9 RSS sensors, 200 trials x 20 steps",
            scenario("zheng-fig8", if quick { 1 } else { 200 }, "CFwMD"),
        ),
        (
            "(d) CFoMD, no feedback, N = 4, l = 2, 1000 particles, 1000 trials x 20 steps",
            scenario("zheng-nofb-n4", if quick { 2 } else { 1000 }, "CFoMD"),
        ),
        (
            "(d) CFwMD-exact, same work with copies of the 4 sensors' filters",
            scenario("zheng-nofb-n4", if quick { 2 } else { 1000 }, "CFwMD-exact"),
        ),
    ];
    // `cargo bench --bench censored_pf -- b` runs only the cases whose name starts with "(b)".
    let only: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    for (name, exp) in &cases {
        if !only.is_empty() && !only.iter().any(|o| name.starts_with(&format!("({o})"))) {
            continue;
        }
        let mut times = Vec::new();
        for _ in 0..if quick { 1 } else { 3 } {
            let t = Instant::now();
            let sums = runner::run(exp, runner::RunOptions { threads }, &|_| {}).unwrap();
            times.push(t.elapsed().as_secs_f64());
            std::hint::black_box(sums);
        }
        times.sort_by(f64::total_cmp);
        println!(
            "{name}, threads={threads}: min {:.3} s, median {:.3} s",
            times[0],
            times[times.len() / 2]
        );
    }
}
