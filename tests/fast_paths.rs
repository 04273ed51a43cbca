//! The fast trials of the linear-Gaussian schemes (`LockstepFastPath::run_trial_fast`, reached
//! through `Scheme::fast_path`) give the generic per-step loop's numbers bit for bit: every fused
//! mean, covariance and traffic count, at every step, for every variant of the Dormann et al.
//! sweep (centralized KF at random rates, Algorithm 1 random and event-based, Algorithm 2 over
//! alpha x b) and of the peers' centralized KF, on the same data and coin streams — the variants
//! of a trial sharing one `TrialCache` as the runner shares it.
use hushfuse::engine::runner;
use hushfuse::filter::Gaussian;
use hushfuse::linalg::LinalgError;
use hushfuse::network::{self, Traffic};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use hushfuse::scheme::fast_path::{StepSink, TrialCache};

type Steps = Vec<(Vec<u64>, Vec<u64>, Traffic)>;

fn bits(est: &Gaussian) -> (Vec<u64>, Vec<u64>) {
    (
        est.mean.iter().map(|v| v.to_bits()).collect(),
        est.cov.iter().map(|v| v.to_bits()).collect(),
    )
}

struct Collect(Steps);

impl StepSink for Collect {
    fn step(&mut self, k: usize, est: &Gaussian, traffic: Traffic) -> Result<(), LinalgError> {
        assert_eq!(k, self.0.len() + 1);
        let (m, c) = bits(est);
        self.0.push((m, c, traffic));
        Ok(())
    }
}

/// The generic loop of `runner::run_variant`, for schemes without feedback or schedules.
fn generic(exp: &build::Experiment, v: usize, trial: usize, data: &runner::TrialData) -> Steps {
    let mut rng = runner::trial_rng(exp.seed, trial as u64, 1 + v as u64);
    let mut inst = exp.variants[v].scheme.build().unwrap();
    let mut inbox = Vec::new();
    let mut out = Vec::new();
    for k in 1..=exp.steps {
        let sent: Vec<_> = inst
            .sensors
            .iter_mut()
            .enumerate()
            .map(|(i, node)| {
                node.step(k, &data.measurements[k - 1][i], None, &mut rng)
                    .unwrap()
            })
            .collect();
        let traffic = network::deliver(sent, &mut inbox);
        inst.center.step(k, &inbox).unwrap();
        let (m, c) = bits(inst.center.estimate());
        out.push((m, c, traffic));
    }
    out
}

fn check(exp: &build::Experiment, trials: usize) {
    let mut fast_variants = 0;
    for trial in 0..trials {
        let data = runner::draw_trial(exp, trial);
        let mut cache = TrialCache::new();
        for v in 0..exp.variants.len() {
            let mut rng = runner::trial_rng(exp.seed, trial as u64, 1 + v as u64);
            let mut sink = Collect(Vec::new());
            let Some(fast) = exp.variants[v].scheme.fast_path() else {
                continue;
            };
            let Some(r) = fast.run_trial_fast(
                &data.measurements,
                exp.steps,
                &mut rng,
                &mut cache,
                &mut sink,
            ) else {
                continue;
            };
            r.unwrap();
            fast_variants += 1;
            let want = generic(exp, v, trial, &data);
            assert_eq!(sink.0.len(), want.len());
            for (k, (a, b)) in sink.0.iter().zip(&want).enumerate() {
                assert!(
                    a == b,
                    "{} variant {v}, trial {trial}, step {}: fast {a:?} != generic {b:?}",
                    exp.name,
                    k + 1
                );
            }
        }
    }
    assert!(fast_variants > 0, "{}: no fast path taken", exp.name);
}

#[test]
fn seed_004_sweep_fast_trials_are_bit_identical() {
    let mut exp = build::load(builtin::get("dormann-fig1").unwrap(), "dormann-fig1").unwrap();
    exp.steps = 60;
    // Every variant has a fast path here.
    check(&exp, 2);
}

#[test]
fn peers_centralized_kf_fast_trial_is_bit_identical() {
    let exp = build::load(include_str!("../benches/data/kfmc.toml"), "kfmc").unwrap();
    check(&exp, 20);
}
