//! Wall time of whole built-in scenario runs: `cargo bench --bench scenarios`.
//! Default: issue 12's workloads at one thread — `kfmc` (the peers' centralized KF Monte Carlo,
//! 5000 trials x 20 steps, `benches/data/kfmc.toml` = `/work/shared/peers/kfmc.toml`) and the
//! `dormann-fig1` sweep (93 scheme variants x 500 trials x 100 steps) — then `dormann-fig1`
//! on two threads (the scaling target) and the `zhang-fig5` run (4 schemes x 1000 trials x
//! 100 steps, 50 range sensors) on one and two threads. Each line prints the time and the
//! trial-steps per second. Compare with the numpy peers (`/work/shared/peers/README.md`) in the same minute.
//! Environment: HUSHFUSE_BENCH_SCENARIOS (comma-separated names, `name@threads` pins the
//! thread count of one entry), HUSHFUSE_BENCH_THREADS (pin the thread count of the others),
//! HUSHFUSE_BENCH_REPEATS (default 3).
//!
//! A name `S+lossP` runs scenario S with a Bernoulli `[channel]` of loss P written in (what
//! `--loss P` does), so `arena-1d+loss0` beside `arena-1d` measures what a link that loses
//! nothing costs: `cargo bench --bench scenarios -- arena-1d` runs the entries of
//! [`DEFAULT`] and [`EXTRA`] whose names contain the filter.
use hushfuse::engine::runner;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use std::time::Instant;

/// The peers' workload (a): centralized KF, 1-D constant velocity, 2 position sensors.
const KFMC: &str = include_str!("data/kfmc.toml");

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// CPU seconds of this process so far (user + system, every thread), from `/proc/self/stat`
/// (NaN where there is none): on a machine shared with other work, the CPU time of a run
/// varies much less than its wall time.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name in parentheses; utime and stime are the 14th and 15th.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or("", |(_, rest)| rest)
        .split_whitespace()
        .collect();
    let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok());
    match (ticks(11), ticks(12)) {
        // Clock ticks of 1/100 s (USER_HZ on Linux).
        (Some(u), Some(s)) => (u + s) / 100.0,
        _ => f64::NAN,
    }
}

/// The entries run by default.
const DEFAULT: &str = "kfmc@1,dormann-fig1@1,dormann-fig1@2,zhang-fig5@1,zhang-fig5@2";
/// Entries run only when a filter names them: the cost of a link.
/// `+loss0` is a lossless link, which the engine runs as an ideal one; `+loss1e-12` is a link
/// that does its work (fate tables, the link layer of the generic loop, the fast paths' loss
/// masks) and in practice loses nothing.
const EXTRA: &str =
    "arena-1d@1,arena-1d+loss0@1,arena-1d+loss1e-12@1,kfmc+loss0@1,kfmc+loss1e-12@1";

/// The text of entry `name`: a built-in scenario, the peers' workload, or `S+lossP`.
fn scenario_text(name: &str) -> String {
    if let Some((base, p)) = name.split_once("+loss") {
        let p: f64 = p.parse().expect("S+lossP: P a probability");
        let mut table: toml::Table = toml::from_str(&scenario_text(base)).unwrap();
        let mut channel = toml::Table::new();
        channel.insert("kind".into(), toml::Value::String("bernoulli".into()));
        channel.insert("loss".into(), toml::Value::Float(p));
        table.insert("channel".into(), toml::Value::Table(channel));
        return toml::to_string(&table).unwrap();
    }
    if name == "kfmc" {
        return KFMC.to_string();
    }
    builtin::get(name)
        .unwrap_or_else(|| panic!("no built-in scenario {name}"))
        .to_string()
}

fn main() {
    let threads: usize = env("HUSHFUSE_BENCH_THREADS", 0);
    let repeats: usize = env("HUSHFUSE_BENCH_REPEATS", 3);
    // A positional argument filters the default and extra entries by name.
    let filter = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let names: String = match (std::env::var("HUSHFUSE_BENCH_SCENARIOS"), &filter) {
        (Ok(names), _) => names,
        (Err(_), Some(f)) => format!("{DEFAULT},{EXTRA}")
            .split(',')
            .filter(|e| e.contains(f.as_str()))
            .collect::<Vec<_>>()
            .join(","),
        (Err(_), None) => DEFAULT.to_string(),
    };
    // Under `cargo test --benches` (no --bench flag) do one tiny run of each only.
    let quick = !std::env::args().any(|a| a == "--bench");
    for entry in names.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, threads) = match entry.split_once('@') {
            Some((n, t)) => (n, t.parse().expect("name@threads")),
            None => (entry, threads),
        };
        let text = scenario_text(name);
        let mut exp = build::load(&text, name).unwrap();
        if quick {
            exp.trials = 2;
        }
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        for _ in 0..if quick { 1 } else { repeats } {
            let (t, c) = (Instant::now(), cpu_seconds());
            let sums = runner::run(&exp, runner::RunOptions { threads }, &|_| {}).unwrap();
            times.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c);
            std::hint::black_box(sums);
        }
        times.sort_by(f64::total_cmp);
        cpu.sort_by(f64::total_cmp);
        // Trial-steps: one trial's step of every variant (the data drawn once) counts once;
        // variant-trial-steps count each variant's step.
        let trial_steps = (exp.trials * exp.steps) as f64;
        let variant_steps = trial_steps * exp.variants.len() as f64;
        println!(
            "{name}: {} variants x {} trials x {} steps, threads={}: min {:.4} s, median {:.4} s over {} runs; \
             {:.3e} trial-steps/s, {:.3e} variant-trial-steps/s (at the min); CPU min {:.2} s, median {:.2} s",
            exp.variants.len(),
            exp.trials,
            exp.steps,
            if threads == 0 { "all".to_string() } else { threads.to_string() },
            times[0],
            times[times.len() / 2],
            times.len(),
            trial_steps / times[0],
            variant_steps / times[0],
            cpu[0],
            cpu[cpu.len() / 2],
        );
    }
}
