//! Per-step cost of the particle-filter machinery (`cargo bench --bench particle`), at the
//! sizes of Zheng et al.'s (2014) experiments:
//! - Section VII-A: 2-D constant velocity (rank-one Q), 2 linear sensors, 1,000 particles;
//!   target 1,000 trials x 20 steps in 0.3 s, i.e. 15 us per step;
//! - Section VII-C: 4-D constant velocity (rank-two Q), 9 received-signal-strength sensors
//!   z = sqrt(P0 / (1 + d^2)), 10,000 particles; target 200 trials x 20 steps in 2 s, i.e.
//!   500 us per step.
//!
//! A "step" is propagate + Gaussian log-likelihood of every sensor over the component slices +
//! normalize + mean and covariance + systematic resampling. The likelihood here is the plain
//! received-measurement one; censoring bands cost what the scheme's likelihood costs.
//!
//! Measured on the shared 2-core development machine (AVX2 versions picked at run time), per
//! step: VII-A 8.4 us (1,000 particles), VII-C 308 us (10,000 particles); before the AVX2
//! versions, the block normal generator and the branch-free resampling: 12.5–13.5 and 365–390 us.
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion};
use hushfuse::filter::particle::{ParticleCloud, ParticleTransition, ResamplePolicy, Resampling};
use hushfuse::filter::Gaussian;
use hushfuse::linalg::{Matrix, Vector};
use hushfuse::model::LinearTransition;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Duration;

/// White-noise acceleration per axis: F = [[1, D], [0, 1]], Q = s2 [[D^4/4, D^3/2], [D^3/2, D^2]].
fn cv(axes: usize, d: f64, s2: f64) -> LinearTransition {
    let dim = 2 * axes;
    let mut f = Matrix::zeros(dim, dim);
    let mut q = Matrix::zeros(dim, dim);
    for a in 0..axes {
        let o = 2 * a;
        f[(o, o)] = 1.0;
        f[(o, o + 1)] = d;
        f[(o + 1, o + 1)] = 1.0;
        q[(o, o)] = s2 * d.powi(4) / 4.0;
        q[(o, o + 1)] = s2 * d.powi(3) / 2.0;
        q[(o + 1, o)] = s2 * d.powi(3) / 2.0;
        q[(o + 1, o + 1)] = s2 * d * d;
    }
    LinearTransition::new(f, q).unwrap()
}

/// Section VII-A: two sensors observing the position, r = 1.
fn linear_step(
    cloud: &mut ParticleCloud,
    t: &ParticleTransition,
    z: &[f64; 2],
    rng: &mut Xoshiro256PlusPlus,
) -> Gaussian {
    cloud.propagate(t, rng).unwrap();
    let (s, lw) = cloud.states_and_log_weights_mut();
    let pos = s.component(0);
    for zi in z {
        for (l, x) in lw.iter_mut().zip(pos) {
            let e = zi - x;
            *l -= 0.5 * e * e;
        }
    }
    cloud.normalize().unwrap();
    let est = cloud.estimate().unwrap();
    cloud
        .resample_if(ResamplePolicy::Always, Resampling::Systematic, rng)
        .unwrap();
    est
}

/// Section VII-C: 9 sensors on a 3x3 grid over 20 m x 20 m, z = sqrt(P0 / (1 + d^2)) + v,
/// P0 = 1000, r = 1; state (x, vx, y, vy).
fn rss_step(
    cloud: &mut ParticleCloud,
    t: &ParticleTransition,
    sensors: &[(f64, f64, f64)],
    rng: &mut Xoshiro256PlusPlus,
) -> Gaussian {
    cloud.propagate(t, rng).unwrap();
    let (s, lw) = cloud.states_and_log_weights_mut();
    let (px, py) = (s.component(0), s.component(2));
    for &(sx, sy, z) in sensors {
        for ((l, x), y) in lw.iter_mut().zip(px).zip(py) {
            let (dx, dy) = (x - sx, y - sy);
            let h = (1000.0 / (1.0 + dx * dx + dy * dy)).sqrt();
            let e = z - h;
            *l -= 0.5 * e * e;
        }
    }
    cloud.normalize().unwrap();
    let est = cloud.estimate().unwrap();
    cloud
        .resample_if(ResamplePolicy::Always, Resampling::Systematic, rng)
        .unwrap();
    est
}

fn benches(c: &mut Criterion) {
    let mut g = c.benchmark_group("pf step");
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(3));

    // Section VII-A.
    let t2 = ParticleTransition::new(&cv(1, 1.0, 4.0)).unwrap();
    let prior2 = Gaussian::new(
        Vector::from_vec(vec![0.0, 10.0]),
        Matrix::from_diagonal(&Vector::from_vec(vec![4.0, 1.0])),
    );
    for n in [1_000, 10_000] {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let mut cloud = ParticleCloud::from_gaussian(n, &prior2, &mut rng).unwrap();
        g.bench_function(BenchmarkId::new("VII-A 2-D, 2 linear sensors", n), |b| {
            b.iter(|| {
                // Re-centre now and then so the cloud stays near the measurements.
                if rng_tick(&mut rng) {
                    cloud.init_gaussian(&prior2, &mut rng).unwrap();
                }
                linear_step(&mut cloud, &t2, black_box(&[0.3, -0.4]), &mut rng)
            })
        });
    }

    // Section VII-C.
    let t4 = ParticleTransition::new(&cv(2, 0.5, 0.1)).unwrap();
    let prior4 = Gaussian::new(
        Vector::from_vec(vec![-8.0, 2.0, -8.0, 2.0]),
        Matrix::from_diagonal(&Vector::from_vec(vec![9.0, 4.0, 9.0, 4.0])),
    );
    let sensors: Vec<(f64, f64, f64)> = (0..9)
        .map(|i| {
            let (sx, sy) = (-10.0 + 10.0 * (i % 3) as f64, -10.0 + 10.0 * (i / 3) as f64);
            let d2 = (sx + 8.0_f64).powi(2) + (sy + 8.0_f64).powi(2);
            (sx, sy, (1000.0 / (1.0 + d2)).sqrt())
        })
        .collect();
    for n in [1_000, 10_000] {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        let mut cloud = ParticleCloud::from_gaussian(n, &prior4, &mut rng).unwrap();
        g.bench_function(BenchmarkId::new("VII-C 4-D, 9 RSS sensors", n), |b| {
            b.iter(|| {
                if rng_tick(&mut rng) {
                    cloud.init_gaussian(&prior4, &mut rng).unwrap();
                }
                rss_step(&mut cloud, &t4, black_box(&sensors), &mut rng)
            })
        });
    }
    g.finish();

    // The pieces, on the 4-D cloud with 10,000 particles.
    let mut g = c.benchmark_group("pf pieces 4-D");
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(2));
    for n in [1_000, 10_000] {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut cloud = ParticleCloud::from_gaussian(n, &prior4, &mut rng).unwrap();
        g.bench_function(BenchmarkId::new("propagate", n), |b| {
            b.iter(|| cloud.propagate(&t4, &mut rng).unwrap())
        });
        let lw: Vec<f64> = (0..n)
            .map(|i| -(((i * 7919) % 1013) as f64) * 0.01)
            .collect();
        g.bench_function(BenchmarkId::new("normalize", n), |b| {
            b.iter(|| {
                cloud.log_weights_mut().copy_from_slice(&lw);
                cloud.normalize().unwrap()
            })
        });
        g.bench_function(BenchmarkId::new("estimate (mean + cov)", n), |b| {
            b.iter(|| cloud.estimate().unwrap())
        });
        for scheme in [
            Resampling::Systematic,
            Resampling::Stratified,
            Resampling::Residual,
            Resampling::Multinomial,
        ] {
            cloud.init_gaussian(&prior4, &mut rng).unwrap();
            g.bench_function(BenchmarkId::new(format!("resample {scheme:?}"), n), |b| {
                b.iter(|| {
                    cloud.log_weights_mut().copy_from_slice(&lw);
                    cloud.normalize().unwrap();
                    cloud.resample(scheme, &mut rng).unwrap()
                })
            });
        }
    }
    g.finish();
}

/// True once every 20 calls on average: a trial has 20 steps.
fn rng_tick(rng: &mut Xoshiro256PlusPlus) -> bool {
    use rand::Rng;
    rng.random::<f64>() < 0.05
}

criterion_group!(particle_benches, benches);
criterion_main!(particle_benches);
