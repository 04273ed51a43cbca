//! A multi-hop network's cost: `cargo bench --bench mesh`.
//!
//! Random geometric graphs of 250, 500 and 1000 nodes (scalar sensors placed uniformly in a
//! 1 km square by a seeded generator, the sink at the centre, nodes within range linked so that
//! the mean degree is about 20), the all-data KF at the sink over lossy hops (Bernoulli 0.1, one
//! retry) on one thread:
//! - aggregated (the relays sum the reports, one frame per link and step), 100 trials × 100
//!   steps: time should grow linearly in nodes × steps × trials (O(nodes) per step);
//! - every report forwarded along its fewest-hops route (`aggregate = false`), 10 trials × 100
//!   steps: O(Σ route lengths) per step, which grows as nodes^1.5 on these graphs.
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use hushfuse::engine::runner;
use hushfuse::scenario::build;
use rand::{Rng, SeedableRng};

/// The scenario text of a random geometric graph of `sensors` sensors.
fn scenario(sensors: usize, trials: usize, aggregate: bool) -> String {
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
    let mut at: Vec<[f64; 2]> = (0..sensors)
        .map(|_| [rng.random::<f64>() * 1000.0, rng.random::<f64>() * 1000.0])
        .collect();
    at.push([500.0, 500.0]);
    let name = |i: usize| {
        if i == sensors {
            "sink".to_string()
        } else {
            format!("s{i}")
        }
    };
    // Mean degree about 20: n π r² / 1e6 = 20.
    let range = (20.0e6 / (std::f64::consts::PI * sensors as f64)).sqrt();
    let mut edges = Vec::new();
    for i in 0..at.len() {
        for j in i + 1..at.len() {
            let d = (at[i][0] - at[j][0]).hypot(at[i][1] - at[j][1]);
            if d <= range {
                edges.push(format!("[\"{}\", \"{}\"]", name(i), name(j)));
            }
        }
    }
    let sensor = "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n".repeat(sensors);
    format!(
        "name = \"mesh-bench\"\ntrials = {trials}\nsteps = 100\nseed = 1\n[model]\nkind = \"matrix\"\nF = [[0.95]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n{sensor}\n[channel]\nkind = \"bernoulli\"\nloss = 0.1\narq = {{ max_retries = 1 }}\n[network]\naggregate = {aggregate}\nedges = [{}]\n[[schemes]]\nkind = \"centralized-kf\"\n",
        edges.join(", ")
    )
}

fn benches(c: &mut Criterion) {
    let mut g = c.benchmark_group("mesh");
    g.sample_size(10);
    let cases = [
        (
            "all-data KF aggregated, 100 trials x 100 steps, nodes",
            100,
            true,
        ),
        (
            "all-data KF per source, 10 trials x 100 steps, nodes",
            10,
            false,
        ),
    ];
    for (name, trials, aggregate) in cases {
        for nodes in [250, 500, 1000] {
            let text = scenario(nodes - 1, trials, aggregate);
            let exp = build::load(&text, "mesh-bench").unwrap_or_else(|e| panic!("{e}"));
            g.bench_with_input(BenchmarkId::new(name, nodes), &exp, |b, exp| {
                b.iter(|| runner::run(exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap())
            });
        }
    }
    g.finish();
}

criterion_group!(mesh, benches);
criterion_main!(mesh);
