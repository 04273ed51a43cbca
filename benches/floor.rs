//! The rate–distortion floor's cost: `cargo bench --bench floor`.
//! - `floor_of(dormann-fig1)`: the curve of Dormann et al.'s 6-state system (two independent
//!   3-state axes, one program of two parts), solved once per run; target at most 50 ms.
//! - `mse_at` between the curve's points: one program of its own, or none where the curve's
//!   tangents bound the floor tightly.
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hushfuse::metrics::floor::floor_of;
use hushfuse::scenario::{build, builtin};

fn benches(c: &mut Criterion) {
    let text = builtin::get("dormann-fig1").expect("built-in dormann-fig1");
    let exp = build::load(text, "dormann-fig1").unwrap();
    let mut g = c.benchmark_group("floor");
    g.sample_size(20);
    g.bench_function("floor_of dormann-fig1 (6 states, 12 rates)", |b| {
        b.iter(|| floor_of(black_box(&exp)))
    });
    let floor = floor_of(&exp).expect("dormann-fig1 has a floor");
    g.bench_function(
        "mse_at dormann-fig1, 10 rates between the curve's points",
        |b| {
            b.iter(|| {
                (0..10)
                    .map(|k| floor.0.mse_at(black_box(0.8 + 1.7 * k as f64)).unwrap())
                    .sum::<f64>()
            })
        },
    );
    g.finish();
}

criterion_group!(floor, benches);
criterion_main!(floor);
