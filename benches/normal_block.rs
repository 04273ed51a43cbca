//! Standard-normal blocks (`cargo bench --bench normal_block`): the particle filter's noise
//! draws, for blocks of 1,000 and 10,000, from `Xoshiro256PlusPlus` (rand_xoshiro 0.7):
//! * `rand_distr` — a loop over `rand_distr::StandardNormal.sample(rng)` (rand_distr 0.5,
//!   256-layer ziggurat, what the filters call today);
//! * `fill_standard_normal` — `hushfuse::stats::normal_block` (1024-layer ziggurat, one
//!   `u64` per draw on the fast path, 99.57% of draws);
//! * `normal_lanes` — `hushfuse::stats::normal_lanes::NormalLanes::fill`: rand_distr's draws on
//!   four streams at once (the runner's blocks of four trials side by side), a quarter of the
//!   calls, four draws each;
//! * `raw_u64` — a loop that only stores `next_u64` (the floor: the generator itself).
//!
//! Throughput is per draw. The generator is seeded once per benchmark and runs on, so every
//! iteration sees fresh words (the fast-path misses happen at their natural rate).
//!
//! Measured on the shared 2-core development machine (AMD EPYC, x86-64 baseline target,
//! i.e. SSE2), one thread, criterion medians in ns per draw over two runs, n = 1,000 / 10,000:
//! rand_distr 2.59-2.65 / 2.58-2.59, fill_standard_normal 1.31 / 1.30, raw_u64 0.85-0.86 /
//! 0.85. On 2026-12-08 (the same machine): rand_distr 2.60, normal_lanes 2.39 / 2.23.
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hushfuse::stats::normal_block::fill_standard_normal;
use hushfuse::stats::normal_lanes::NormalLanes;
use rand::{RngCore, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Duration;

fn bench(cr: &mut Criterion) {
    let mut g = cr.benchmark_group("standard_normal");
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(2));
    for n in [1_000usize, 10_000] {
        let mut out = vec![0.0; n];
        let mut words = vec![0u64; n];
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        g.throughput(Throughput::Elements(n as u64));
        g.bench_function(BenchmarkId::new("rand_distr", n), |bn| {
            bn.iter(|| {
                for o in out.iter_mut() {
                    *o = StandardNormal.sample(&mut rng);
                }
                black_box(&mut out);
            })
        });
        g.bench_function(BenchmarkId::new("fill_standard_normal", n), |bn| {
            bn.iter(|| {
                fill_standard_normal(&mut out, &mut rng);
                black_box(&mut out);
            })
        });
        // Four streams side by side (the runner's blocks of the all-data KF): a quarter of
        // the calls, four draws each.
        let mut lanes = NormalLanes::seeded([1, 2, 3, 4]).expect("lanes agree with the crates");
        let mut quads = vec![hushfuse::linalg::quad::F64x4::default(); n / 4];
        g.bench_function(BenchmarkId::new("normal_lanes", n), |bn| {
            bn.iter(|| {
                lanes.fill(&mut quads);
                black_box(&mut quads);
            })
        });
        g.bench_function(BenchmarkId::new("raw_u64", n), |bn| {
            bn.iter(|| {
                for w in words.iter_mut() {
                    *w = rng.next_u64();
                }
                black_box(&mut words);
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
