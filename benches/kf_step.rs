//! Micro-benchmarks of single steps on Dormann et al.'s system (6-D state, 2-D measurements), and
//! issue 12's workload (a) end to end at one thread — the centralized KF Monte Carlo of the
//! numpy peers (`/work/shared/peers/kf_mc.py`, 5000 trials x 20 steps):
//! `cargo bench --bench kf_step`.
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hushfuse::engine::runner;
use hushfuse::filter::{information, kf, Gaussian};
use hushfuse::linalg::{Matrix, Vector};
use hushfuse::link::Received;
use hushfuse::model::{presets, LinearSensor, MeasurementModel};
use hushfuse::scenario::build;
use hushfuse::scheme::centralized::CentralizedScheme;
use hushfuse::scheme::distributed_kf::{DistributedKfScheme, Trigger};
use hushfuse::scheme::{Scheme, System};
use rand::SeedableRng;
use std::sync::Arc;

fn system() -> Arc<System> {
    let transition = presets::near_constant_acceleration_2d(0.25, 1.0).unwrap();
    let sensors = (0..6)
        .map(|i| {
            let mut h = Matrix::zeros(2, 6);
            h[(0, i / 2)] = 1.0;
            h[(1, 3 + i / 2)] = 1.0;
            Arc::new(LinearSensor::new(h, Matrix::identity(2, 2)).unwrap())
                as Arc<dyn MeasurementModel>
        })
        .collect();
    Arc::new(System {
        transition,
        sensors,
        prior: Gaussian::new(Vector::zeros(6), Matrix::identity(6, 6)),
    })
}

fn benches(c: &mut Criterion) {
    let sys = system();
    let z = Vector::from_vec(vec![0.3, -0.2]);
    let est = sys.prior.clone();
    c.bench_function("kf step (predict + Joseph update, 6-D state, 2-D z)", |b| {
        b.iter(|| {
            let p = kf::predict(&sys.transition, black_box(&est));
            kf::update(sys.sensors[0].as_ref(), p, black_box(&z)).unwrap()
        })
    });
    let lin: Vec<&LinearSensor> = sys.sensors.iter().map(|s| s.as_linear().unwrap()).collect();
    c.bench_function("information-form fusion of 6 sensors", |b| {
        b.iter(|| {
            let p = kf::predict(&sys.transition, black_box(&est));
            let ms: Vec<(&LinearSensor, &Vector)> = lin.iter().map(|s| (*s, &z)).collect();
            information::update(&p, &ms).unwrap()
        })
    });
    let scheme =
        DistributedKfScheme::new(sys.clone(), 1000, Trigger::Event { alpha: 0.5 }, None).unwrap();
    c.bench_function("Algorithm 1 step: 6 sensor nodes + fusion center", |b| {
        let mut inst = scheme.build().unwrap();
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
        let mut k = 0usize;
        let mut inbox = Vec::with_capacity(6);
        b.iter(|| {
            k = k % 1000 + 1;
            if k == 1 {
                inst = scheme.build().unwrap();
            }
            inbox.clear();
            for node in inst.sensors.iter_mut() {
                inbox.push(Received::from(node.step(k, &z, None, &mut rng).unwrap()));
            }
            inst.center.step(k, &inbox).unwrap();
        })
    });
}

fn step_benches(c: &mut Criterion) {
    let sys = system();
    let z = Vector::from_vec(vec![0.3, -0.2]);
    let inbox: Vec<Received> = (0..6).map(|_| Received::Measurement(z.clone())).collect();
    for (name, rate) in [
        (
            "centralized KF step, all data (shared covariance schedule)",
            1.0,
        ),
        ("centralized KF step, direct form (random-rate path)", 0.999),
    ] {
        let scheme = CentralizedScheme::new(sys.clone(), rate).unwrap();
        c.bench_function(name, |b| {
            let mut center = scheme.build().unwrap().center;
            let mut k = 0usize;
            b.iter(|| {
                k = k % 100 + 1;
                if k == 1 {
                    center = scheme.build().unwrap().center;
                }
                center.step(k, black_box(&inbox)).unwrap();
            })
        });
    }
}

/// Workload (a) of issue 12, whole runs at one thread (compare: `kf_mc.py --variants
/// np_batched,np_sharedP`).
fn kfmc(c: &mut Criterion) {
    let exp = build::load(include_str!("data/kfmc.toml"), "kfmc").unwrap();
    let mut g = c.benchmark_group("kfmc");
    g.sample_size(10);
    g.bench_function("5000 trials x 20 steps, 1 thread", |b| {
        b.iter(|| runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap())
    });
    g.finish();
}

criterion_group!(kf_benches, benches, step_benches, kfmc);
criterion_main!(kf_benches);
