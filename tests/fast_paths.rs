//! The fast trials of the linear-Gaussian schemes (`LockstepFastPath::run_trial_fast`, reached
//! through `Scheme::fast_path`) give the generic per-step loop's numbers bit for bit: every fused
//! mean, covariance and traffic count, at every step, for every variant of the Dormann et al.
//! sweep (centralized KF at random rates, Algorithm 1 random and event-based, Algorithm 2 over
//! alpha x b) and of the peers' centralized KF, on the same data and coin streams — the variants
//! of a trial sharing one `TrialCache` as the runner shares it. On a link that loses packets
//! the engine's trial with the fast paths equals its generic loop, the losses applied by each.
use hushfuse::engine::runner;
use hushfuse::engine::seeding::{self, coin_stream};
use hushfuse::engine::trial::{
    run_trial, LoopBuffers, Observer, ObserverError, StepOutput, TrialSpec,
};
use hushfuse::filter::Gaussian;
use hushfuse::linalg::LinalgError;
use hushfuse::network::{self, Traffic};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use hushfuse::scheme::fast_path::{BatchSink, TrialCache};

type Steps = Vec<(Vec<u64>, Vec<u64>, Traffic)>;

fn bits(est: &Gaussian) -> (Vec<u64>, Vec<u64>) {
    (
        est.mean.iter().map(|v| v.to_bits()).collect(),
        est.cov.iter().map(|v| v.to_bits()).collect(),
    )
}

struct Collect(Steps);

impl BatchSink for Collect {
    fn step(
        &mut self,
        j: usize,
        k: usize,
        est: &Gaussian,
        _factor: Option<&[f64]>,
        traffic: Traffic,
    ) -> Result<(), LinalgError> {
        assert_eq!((j, k), (0, self.0.len() + 1));
        let (m, c) = bits(est);
        self.0.push((m, c, traffic));
        Ok(())
    }
}

/// The generic loop of `runner::run_variant`, for schemes without feedback or schedules.
fn generic(exp: &build::Experiment, v: usize, trial: usize, data: &runner::TrialData) -> Steps {
    let ns = exp.system.n_sensors();
    let (mut coins, _) = seeding::coins(exp.seed, trial, coin_stream(v), ns);
    let mut inst = exp.variants[v].scheme.build().unwrap();
    let mut inbox = Vec::new();
    let mut out = Vec::new();
    for k in 1..=exp.steps {
        let sent: Vec<_> = inst
            .sensors
            .iter_mut()
            .zip(&mut coins)
            .enumerate()
            .map(|(i, (node, rng))| {
                node.step(k, &data.measurements[k - 1][i], None, rng)
                    .unwrap()
            })
            .collect();
        let mut traffic = network::deliver(sent, &mut inbox);
        // Every sensor is scheduled (no schedule, no recorded gaps), as the engine marks it.
        traffic.scheduled = network::all_sensors(exp.system.n_sensors());
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
            let ns = exp.system.n_sensors();
            let (mut coins, _) = seeding::coins(exp.seed, trial, coin_stream(v), ns);
            let mut sink = Collect(Vec::new());
            let Some(fast) = exp.variants[v].scheme.fast_path() else {
                continue;
            };
            let Some(r) = fast.run_trial_fast(
                &data.measurements,
                exp.steps,
                None,
                &mut coins,
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

/// What the engine's trial reports, with (`fast`) or without its schemes' fast paths.
struct Record {
    steps: Steps,
    fast: bool,
    /// Steps that came through the fast path's sink.
    via_fast: usize,
}

impl Observer for Record {
    fn needs_links(&self) -> bool {
        false
    }

    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError> {
        let (m, c) = bits(s.estimate);
        self.steps.push((m, c, s.traffic));
        Ok(())
    }

    fn fast_sink(&mut self) -> Option<&mut dyn BatchSink> {
        if self.fast {
            Some(self)
        } else {
            None
        }
    }
}

impl BatchSink for Record {
    fn step(
        &mut self,
        j: usize,
        k: usize,
        est: &Gaussian,
        _factor: Option<&[f64]>,
        traffic: Traffic,
    ) -> Result<(), LinalgError> {
        assert_eq!((j, k), (0, self.steps.len() + 1));
        self.via_fast += 1;
        let (m, c) = bits(est);
        self.steps.push((m, c, traffic));
        Ok(())
    }
}

/// `text` with a Bernoulli `[channel]` of loss `p` (what `--loss p` writes in).
fn with_loss(text: &str, p: f64) -> String {
    let mut table: toml::Table = toml::from_str(text).unwrap();
    let mut channel = toml::Table::new();
    channel.insert("kind".into(), toml::Value::String("bernoulli".into()));
    channel.insert("loss".into(), toml::Value::Float(p));
    table.insert("channel".into(), toml::Value::Table(channel));
    toml::to_string(&table).unwrap()
}

/// Every variant of `exp` with a fast path, trials `0..trials`: the engine's trial with the
/// fast paths equals its generic loop bit for bit. Returns the packets lost in the fast runs
/// of the variants that have a fast path.
fn check_lossy(exp: &build::Experiment, trials: usize) -> u64 {
    let mut lost = 0;
    let mut buffers = LoopBuffers::new(exp.system.n_sensors());
    for trial in 0..trials {
        let data = runner::draw_trial(exp, trial);
        for v in 0..exp.variants.len() {
            if exp.variants[v].scheme.fast_path().is_none() {
                continue;
            }
            let spec = TrialSpec {
                trial,
                variant: v,
                stream: coin_stream(v),
                available: None,
            };
            let run = |fast: bool, buffers: &mut LoopBuffers| {
                let mut r = Record {
                    steps: Vec::new(),
                    fast,
                    via_fast: 0,
                };
                run_trial(exp, &data.measurements, spec, buffers, &mut r).unwrap();
                (r.steps, r.via_fast)
            };
            let ((fast, via_fast), (generic, _)) =
                (run(true, &mut buffers), run(false, &mut buffers));
            // Every scheme with a fast path here takes it on this link.
            assert_eq!(
                via_fast, exp.steps,
                "{}: {}",
                exp.name, exp.variants[v].curve
            );
            for (k, (a, b)) in fast.iter().zip(&generic).enumerate() {
                assert!(
                    a == b,
                    "{} variant {v} ({}), trial {trial}, step {}: fast {a:?} != generic {b:?}",
                    exp.name,
                    exp.variants[v].curve,
                    k + 1
                );
            }
            lost += fast.iter().map(|s| s.2.lost).sum::<u64>();
        }
    }
    lost
}

#[test]
fn fast_trials_apply_a_lossy_link_as_the_generic_loop_does() {
    // Dormann et al.'s sweep: Algorithm 1's loss fallback (an estimate missing twice) and
    // Algorithm 2's extrapolation from the last estimate to arrive; the centralized KF's
    // schedule left at the first loss.
    let text = with_loss(builtin::get("dormann-fig1").unwrap(), 0.2);
    let mut exp = build::load(&text, "dormann-fig1").unwrap();
    exp.steps = 40;
    assert!(check_lossy(&exp, 2) > 0);
    // The arena: the full-rate distributed KF, both algorithms, both centralized KFs.
    let text = with_loss(builtin::get("arena-1d").unwrap(), 0.3);
    let mut exp = build::load(&text, "arena-1d").unwrap();
    exp.steps = 50;
    assert!(check_lossy(&exp, 3) > 0);
    // A link that loses nothing in these trials: the ideal link's fast trials, all-data batch
    // schedule included.
    let text = with_loss(include_str!("../benches/data/kfmc.toml"), 1e-12);
    let exp = build::load(&text, "kfmc").unwrap();
    assert_eq!(check_lossy(&exp, 5), 0);
}

/// Every trial's steps, in the order a batch reports them.
struct CollectBatch(Vec<Steps>);

impl BatchSink for CollectBatch {
    fn step(
        &mut self,
        j: usize,
        k: usize,
        est: &Gaussian,
        _factor: Option<&[f64]>,
        traffic: Traffic,
    ) -> Result<(), LinalgError> {
        assert_eq!(k, self.0[j].len() + 1, "trial {j}: steps in order");
        let (m, c) = bits(est);
        self.0[j].push((m, c, traffic));
        Ok(())
    }
}

/// A lockstep batch (of the runner's four trials, or of any other size) reports for each trial what that trial's fast trial reports
/// alone, for batches of 1 to 9 trials, on the data of the peers' KF Monte Carlo and on the
/// all-data variant of the Dormann et al. sweep (several sensors, a 4-state model).
#[test]
fn lockstep_batches_of_any_size_give_each_trial_its_own_numbers() {
    let kfmc = build::load(include_str!("../benches/data/kfmc.toml"), "kfmc").unwrap();
    let mut dormann = build::load(builtin::get("dormann-fig1").unwrap(), "dormann-fig1").unwrap();
    dormann.steps = 30;
    let mut batched = 0;
    for exp in [&kfmc, &dormann] {
        let data: Vec<_> = (0..9).map(|t| runner::draw_trial(exp, t)).collect();
        for v in 0..exp.variants.len() {
            let Some(fast) = exp.variants[v].scheme.fast_path().filter(|f| f.batches()) else {
                continue;
            };
            let alone: Vec<Steps> = data
                .iter()
                .enumerate()
                .map(|(trial, d)| {
                    let ns = exp.system.n_sensors();
                    let (mut coins, _) = seeding::coins(exp.seed, trial, coin_stream(v), ns);
                    let mut sink = Collect(Vec::new());
                    let mut cache = TrialCache::new();
                    fast.run_trial_fast(
                        &d.measurements,
                        exp.steps,
                        None,
                        &mut coins,
                        &mut cache,
                        &mut sink,
                    )
                    .expect("a fast trial")
                    .unwrap();
                    sink.0
                })
                .collect();
            for size in 1..=9 {
                let trials: Vec<&[Vec<_>]> = data[..size]
                    .iter()
                    .map(|d| d.measurements.as_slice())
                    .collect();
                let mut sink = CollectBatch(vec![Vec::new(); size]);
                fast.run_batch_fast(&trials, exp.steps, &mut TrialCache::new(), &mut sink)
                    .expect("a batch")
                    .unwrap();
                for (j, (got, want)) in sink.0.iter().zip(&alone).enumerate() {
                    assert!(
                        got == want,
                        "{} variant {v}, batch of {size}, trial {j}",
                        exp.name
                    );
                }
                batched += 1;
            }
        }
    }
    assert!(batched >= 18, "both scenarios batch ({batched} batches)");
}

/// The runner's blocks of four run side by side (drawn into lanes, the all-data KF's means and
/// the recording four trials at a time) give the sums of running each trial alone and folding
/// the blocks in order, serialized bit for bit: the peers' KF Monte Carlo with a short last
/// block, a 3-state model with three groups, steady state from step 4 and two all-data variants,
/// the same with readings sent as doubles, and a model whose readings overflow a single (every
/// trial fails, as the one-at-a-time loop reports it).
#[test]
fn blocks_side_by_side_give_the_sums_of_each_trial_alone() {
    let three = |extra: &str, r: &str| {
        format!(
            "{extra}name = \"t\"\ntrials = 11\nsteps = 25\nseed = 9\nsteady_state_from = 4\n\
             [model]\nkind = \"matrix\"\nF = [[0.9, 0.2, 0.0], [0.0, 0.95, 0.1], [0.05, 0.0, 0.8]]\n\
             Q = [[1.0, 0.1, 0.0], [0.1, 0.5, 0.0], [0.0, 0.0, 0.2]]\n\
             [prior]\nmean = [0.0, 1.0, -1.0]\ncov_diag = [1.0, 2.0, 0.5]\n\
             [groups]\na = [0]\nb = [1, 2]\nall = [0, 1, 2]\n\
             [[sensors]]\nobserve = [0]\nR_diag = [{r}]\n[[sensors]]\nobserve = [2]\nR_diag = [0.5]\n\
             [[schemes]]\nkind = \"centralized-kf\"\nlabel = \"first\"\n\
             [[schemes]]\nkind = \"centralized-kf\"\nlabel = \"second\"\n"
        )
    };
    let mut kfmc = build::load(include_str!("../benches/data/kfmc.toml"), "kfmc").unwrap();
    kfmc.trials = 14;
    let cases = [
        kfmc,
        build::load(&three("", "2.0"), "t").unwrap(),
        build::load(&three("reals = \"f64\"\n", "2.0"), "t").unwrap(),
        build::load(&three("", "1e78"), "t").unwrap(),
    ];
    for exp in &cases {
        let opts = runner::RunOptions { threads: 1 };
        let run = runner::run(exp, opts, &|_| {}).unwrap();
        let mut folded = runner::empty_sums(exp);
        for b in 0..runner::n_blocks(exp.trials) {
            let mut block = runner::empty_sums(exp);
            for trial in runner::block_trials(b, exp.trials) {
                let data = runner::draw_trial(exp, trial);
                runner::run_trial_on(exp, trial, &data, &mut block).unwrap();
                if exp.reals.is_f32() {
                    let mut peaks = Vec::new();
                    hushfuse::metrics::precision::note_peaks(&data.measurements, &mut peaks);
                    block.iter_mut().for_each(|s| s.merge_peaks(&peaks));
                }
            }
            runner::fold_block(&mut folded, &block);
        }
        let json = |s: &[hushfuse::metrics::Sums]| serde_json::to_string(s).unwrap();
        assert_eq!(json(&run), json(&folded), "{}", exp.name);
    }
    let overflow = runner::run(&cases[3], runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    assert!(
        overflow.iter().all(|s| s.failure.is_some()),
        "readings beyond a single fail"
    );
    assert!(cases[1].reals.is_f32() && !cases[2].reals.is_f32());
}
