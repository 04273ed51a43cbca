//! The 2-D vector-measurement likelihood `ln P(q^T q < eta)`, `q ~ N(m, C)`:
//! `stats::quadform2d::EllipseBand2::add_log_prob_below` against the loop over
//! `stats::quadform::QuadFormCdf::prob_below_slice` it replaces
//! (`cargo bench --bench quadform2d`). 1000 means per call (one sensor, one step of a
//! 1000-particle filter), `C = rot(0.5) diag(0.3, 0.9) rot(0.5)^T`, `eta = 1.4` (chi-square(2)
//! upper quantile for l/N = 0.5), means uniform in angle with radius uniform in
//! near [0, 3), mid [3, 8) and far [8, 40). Throughput is per mean. Construction of
//! `EllipseBand2` is inside the timed loop (it happens once per sensor and step).
//!
//! Measured on the shared 2-core development machine (AMD EPYC, AVX2 path), one thread,
//! per mean: near 43.8 ns (QuadFormCdf loop 329 ns), mid 61.4 ns (421 ns), far 172 ns
//! (1443 ns). Far means cost more because the series needs ~60-120 terms there (and the
//! eight lanes of a block run as long as the slowest) or, beyond `P < e^-720`, a Newton
//! solve for the saddlepoint.
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hushfuse::stats::quadform::QuadFormCdf;
use hushfuse::stats::quadform2d::EllipseBand2;
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Duration;

const N: usize = 1000;

fn means(seed: u64, r0: f64, r1: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    (0..N)
        .map(|_| {
            let r = rng.random_range(r0..r1);
            let th = rng.random_range(0.0..std::f64::consts::TAU);
            (r * th.cos(), r * th.sin())
        })
        .unzip()
}

fn covariance() -> DMatrix<f64> {
    let (s, c) = 0.5f64.sin_cos();
    let u = DMatrix::from_row_slice(2, 2, &[c, -s, s, c]);
    &u * DMatrix::from_row_slice(2, 2, &[0.3, 0.0, 0.0, 0.9]) * u.transpose()
}

fn bench(cr: &mut Criterion) {
    let c = covariance();
    let eta = 1.4;
    let mut g = cr.benchmark_group("quadform2d_1k");
    g.throughput(Throughput::Elements(N as u64));
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(2));
    for (name, r0, r1) in [("near", 0.0, 3.0), ("mid", 3.0, 8.0), ("far", 8.0, 40.0)] {
        let (m0, m1) = means(11, r0, r1);
        let mut out = vec![0.0; N];
        g.bench_with_input(BenchmarkId::new("ellipse_band2", name), &(), |bn, _| {
            bn.iter(|| {
                let k = EllipseBand2::new(black_box(&c), black_box(eta)).unwrap();
                k.add_log_prob_below(&m0, &m1, &mut out);
            })
        });
        g.bench_with_input(BenchmarkId::new("quadform_cdf", name), &(), |bn, _| {
            bn.iter(|| {
                let q = QuadFormCdf::new(black_box(&c)).unwrap();
                for i in 0..N {
                    let p = q.prob_below_slice(&[m0[i], m1[i]], eta).unwrap();
                    out[i] += p.max(f64::MIN_POSITIVE).ln();
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
