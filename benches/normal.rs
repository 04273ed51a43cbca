//! The censored-sensor band likelihood kernel `stats::band_kernel::add_log_band_probability`
//! (`cargo bench --bench normal`): 10,000 particles per call, as in Zheng et al.'s (2014) Section VII-C
//! filter, with realistic inputs — innovation means `mu` mostly within a few units of 0
//! (90% N(0, 2^2)) and a tail of particles far out (10% uniform on [-50, 50]); band
//! half-widths `c` in [0.1, 5] and inverse noise sd `s` in [0.5, 2]. Throughput is per element
//! (one particle x one silent sensor). For comparison, the accurate scalar `log_q_band` over
//! the same band, which is what the kernel did per element before it was tabulated.
//!
//! Measured on the shared 2-core development machine (x86-64 baseline target, i.e. SSE2), one
//! thread: kernel 29.6-30.5 us per 10,000 (2.96-3.05 ns per element; the c-sweep 3.00 ns,
//! table construction included, ~7% of it); scalar `log_q_band` 394 us (39 ns per element).
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hushfuse::stats::band_kernel::add_log_band_probability;
use hushfuse::stats::normal::log_q_band;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Duration;

const N: usize = 10_000;

fn innovations(seed: u64) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let near = Normal::new(0.0, 2.0).unwrap();
    (0..N)
        .map(|_| {
            if rng.random::<f64>() < 0.9 {
                near.sample(&mut rng)
            } else {
                rng.random_range(-50.0..50.0)
            }
        })
        .collect()
}

fn bench(cr: &mut Criterion) {
    let mu = innovations(7);
    let mut out = vec![0.0; N];
    let mut g = cr.benchmark_group("band_likelihood_10k");
    g.throughput(Throughput::Elements(N as u64));
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(2));
    for (c, s) in [(0.1, 1.0), (1.0, 1.0), (5.0, 1.0), (1.0, 0.5), (2.0, 2.0)] {
        let id = format!("c={c},s={s}");
        g.bench_with_input(BenchmarkId::new("kernel", &id), &(c, s), |bn, &(c, s)| {
            bn.iter(|| {
                add_log_band_probability(black_box(&mu), black_box(c), black_box(s), &mut out);
            })
        });
    }
    // Sweep of c over [0.1, 5]: one call per band, as the filter makes them.
    let cs: Vec<f64> = (0..50).map(|i| 0.1 + 0.1 * i as f64).collect();
    g.throughput(Throughput::Elements((N * cs.len()) as u64));
    g.bench_function("kernel/c-sweep", |bn| {
        bn.iter(|| {
            for &c in &cs {
                add_log_band_probability(black_box(&mu), black_box(c), 1.0, &mut out);
            }
        })
    });
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("scalar_log_q_band/c=1,s=1", |bn| {
        bn.iter(|| {
            for (o, m) in out.iter_mut().zip(&mu) {
                *o += log_q_band((-1.0 - m) * black_box(1.0), (1.0 - m) * 1.0);
            }
        })
    });
    g.finish();
    black_box(&out);
}

criterion_group!(benches, bench);
criterion_main!(benches);
