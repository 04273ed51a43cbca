// Temporary probe (not committed): per-variant wall time of arena-1d with and without a
// lossless channel, interleaved.
use hushfuse::engine::runner;
use hushfuse::scenario::{build, builtin};
use std::time::Instant;
/// CPU seconds of this process so far (user + system, all threads).
fn cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let rest = &s[s.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split(' ').collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0
}
fn main() {
    let text = builtin::get("arena-1d").unwrap();
    let loss = std::env::var("PROBE_LOSS").unwrap_or("0.0".into());
    let lossy = format!("{text}\n[channel]\nkind = \"bernoulli\"\nloss = {loss}\n");
    let reps: usize = std::env::args().nth(1).map_or(3, |s| s.parse().unwrap());
    let a = build::load(text, "a").unwrap();
    let n = a.variants.len();
    let mut best = vec![(f64::INFINITY, f64::INFINITY); n];
    let only = std::env::args().nth(2);
    let which: Vec<usize> = std::env::args()
        .nth(3)
        .map_or(vec![0, 1], |s| vec![s.parse().unwrap()]);
    for _ in 0..reps {
        for v in 0..n {
            if only.as_deref().is_some_and(|o| o != a.variants[v].kind) {
                continue;
            }
            for (j, t) in [text, lossy.as_str()].iter().enumerate() {
                if !which.contains(&j) {
                    continue;
                }
                let mut e = build::load(t, "a").unwrap();
                let keep = e.variants.swap_remove(v);
                e.variants = vec![keep];
                let _t0 = Instant::now();
                let c0 = cpu();
                let s = runner::run(&e, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
                let dt = cpu() - c0;
                std::hint::black_box(s);
                let b = &mut best[v];
                if b.0.is_infinite() {
                    *b = (0.0, 0.0)
                }
                if j == 0 {
                    b.0 += dt
                } else {
                    b.1 += dt
                }
            }
        }
    }
    let (mut ta, mut tb) = (0.0, 0.0);
    for v in 0..n {
        let (x, y) = best[v];
        ta += x;
        tb += y;
        println!(
            "{:28} {:8.4} {:8.4} {:+6.1}%",
            a.variants[v].kind,
            x,
            y,
            100.0 * (y / x - 1.0)
        );
    }
    println!(
        "{:28} {:8.4} {:8.4} {:+6.1}%",
        "total",
        ta,
        tb,
        100.0 * (tb / ta - 1.0)
    );
}
