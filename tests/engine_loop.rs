//! The engine's one trial loop (`engine::trial`), seen from outside: the mask of recorded
//! readings, the per-sensor links and bits against the traffic, the fast-path hook against the
//! loop, and the seeding rule.
#[path = "common/cli.rs"]
mod common;

use hushfuse::engine::runner::{self, draw_trial};
use hushfuse::engine::seeding::{coin_stream, coins, sensor_coins, trial_rng, DATA_STREAM};
use hushfuse::engine::trial::{
    run_trial, Link, LoopBuffers, Observer, ObserverError, StepOutput, Trial, TrialSpec,
};
use hushfuse::filter::Gaussian;
use hushfuse::metrics::results;
use hushfuse::network::Traffic;
use hushfuse::scenario::build;
use rand::RngCore;

/// Every step as the loop reports it.
#[derive(Default)]
struct Record {
    steps: Vec<(Gaussian, Vec<Link>, Vec<u64>, Traffic)>,
}

impl Observer for Record {
    fn step(&mut self, s: &StepOutput) -> Result<(), ObserverError> {
        self.steps.push((
            s.estimate.clone(),
            s.links.to_vec(),
            s.bits.to_vec(),
            s.traffic,
        ));
        Ok(())
    }
}

fn record(
    exp: &build::Experiment,
    measurements: &[Vec<hushfuse::linalg::Vector>],
    v: usize,
    available: Option<&[Vec<bool>]>,
) -> Record {
    let mut r = Record::default();
    let spec = TrialSpec {
        trial: 0,
        variant: v,
        stream: coin_stream(v),
        available,
    };
    let mut buffers = LoopBuffers::new(exp.system.n_sensors());
    run_trial(exp, measurements, spec, &mut buffers, &mut r).unwrap();
    r
}

/// Schemes with coins, feedback, silence and a round-robin schedule, on two sensors.
fn scenario() -> build::Experiment {
    // The shared tiny model, prior and sensors, with this test's schemes.
    let head = common::TINY
        .split("[[schemes]]")
        .next()
        .unwrap()
        .replacen("name = \"tiny\"", "name = \"loop\"", 1)
        .replacen("trials = 8", "trials = 3", 1)
        .replacen("steps = 20", "steps = 30", 1)
        .replacen("seed = 1", "seed = 5", 1);
    let text = format!(
        r#"{head}[[schemes]]
kind = "centralized-kf"

[[schemes]]
kind = "dkf-alg1-random"
rate = 0.5

[[schemes]]
kind = "send-on-delta"
delta = 1.0

[[schemes]]
kind = "censored-pf"
l = 1.0
particles = 200

[[schemes]]
kind = "round-robin-kf"
"#
    );
    build::load(&text, "loop.toml").unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn an_all_true_availability_mask_is_the_loop_without_one() {
    let exp = scenario();
    let data = draw_trial(&exp, 0);
    let all = vec![vec![true; exp.system.n_sensors()]; exp.steps];
    for v in 0..exp.variants.len() {
        let a = record(&exp, &data.measurements, v, None);
        let b = record(&exp, &data.measurements, v, Some(&all));
        assert_eq!(a.steps.len(), exp.steps);
        for (k, (x, y)) in a.steps.iter().zip(&b.steps).enumerate() {
            assert_eq!(x.0.mean, y.0.mean, "variant {v}, step {}", k + 1);
            assert_eq!(x.0.cov, y.0.cov, "variant {v}, step {}", k + 1);
            assert_eq!((&x.1, &x.2, x.3), (&y.1, &y.2, y.3));
        }
    }
}

#[test]
fn a_missing_reading_is_not_scheduled_and_sends_nothing() {
    let exp = scenario();
    let data = draw_trial(&exp, 0);
    let mut avail = vec![vec![true; exp.system.n_sensors()]; exp.steps];
    avail[4][1] = false;
    let centralized = 0;
    let r = record(&exp, &data.measurements, centralized, Some(&avail));
    let (_, links, bits, traffic) = &r.steps[4];
    assert_eq!(links, &[Link::Sent, Link::NotScheduled]);
    assert_eq!(bits[1], 0);
    assert_eq!(traffic.messages, 1);
    // The estimate differs from the full data's from that step on (the reading was not used).
    let full = record(&exp, &data.measurements, centralized, None);
    assert_eq!(r.steps[3].0.mean, full.steps[3].0.mean);
    assert_ne!(r.steps[4].0.cov, full.steps[4].0.cov);
}

#[test]
fn the_links_and_bits_add_up_to_the_traffic_of_every_step() {
    let exp = scenario();
    let data = draw_trial(&exp, 0);
    let mut silences = 0;
    for v in 0..exp.variants.len() {
        for (k, (_, links, bits, traffic)) in record(&exp, &data.measurements, v, None)
            .steps
            .iter()
            .enumerate()
        {
            let sent = links.iter().filter(|l| **l == Link::Sent).count() as u64;
            assert_eq!(sent, traffic.messages, "variant {v}, step {}", k + 1);
            assert_eq!(
                bits.iter().sum::<u64>(),
                traffic.bits,
                "variant {v}, step {}",
                k + 1
            );
            for (l, b) in links.iter().zip(bits) {
                assert_eq!(*l == Link::Sent, *b > 0, "variant {v}, step {}", k + 1);
            }
            silences += links.iter().filter(|l| **l != Link::Sent).count();
        }
    }
    // Not vacuous: some sensors were silent or not scheduled.
    assert!(silences > 0);
}

/// The runner takes the schemes' fast paths (through the observer's sink); an observer without
/// one runs the loop. Their sums are the same bits.
#[test]
fn the_fast_path_hook_gives_the_loops_numbers() {
    let exp = scenario();
    let sums = runner::run(&exp, Default::default(), &|_| {}).unwrap();
    let mut looped = runner::empty_sums(&exp);
    for trial in 0..exp.trials {
        let data = draw_trial(&exp, trial);
        for (v, s) in looped.iter_mut().enumerate() {
            let opts = hushfuse::engine::trace::LoopOptions {
                trial,
                alone: false,
                available: None,
            };
            hushfuse::engine::trace::run_variant_into(
                &exp,
                &data.measurements,
                &data.truth,
                v,
                opts,
                s,
                &mut |_| Ok(()),
            )
            .unwrap();
        }
    }
    let a = serde_json::to_string(&results::summarize(&exp, &sums)).unwrap();
    let b = serde_json::to_string(&results::summarize(&exp, &looped)).unwrap();
    assert_eq!(a, b);
}

#[test]
fn the_seeding_rule_gives_data_and_each_variant_streams_of_their_own() {
    let seed = 11;
    let (mut c0, center0) = coins(seed, 3, coin_stream(0), 2);
    let (mut c1, center1) = coins(seed, 3, coin_stream(1), 2);
    let mut data = trial_rng(seed, 3, DATA_STREAM);
    let (x0, x1, d) = (c0[0].next_u64(), c1[0].next_u64(), data.next_u64());
    assert!(x0 != x1 && x0 != d && x1 != d);
    assert_ne!(center0, center1);
    // Each sensor has coins of its own, whatever the number of sensors.
    let y0 = c0[1].next_u64();
    assert!(y0 != x0 && y0 != x1 && y0 != d);
    assert_eq!(coins(seed, 3, coin_stream(0), 5).0[1].next_u64(), y0);
    assert_eq!(
        sensor_coins(seed, 3, coin_stream(0), 1).next_u64(),
        y0,
        "coins gives sensor_coins"
    );
    // The same (seed, trial, stream) gives the same coins; another trial other ones.
    assert_eq!(coins(seed, 3, coin_stream(1), 1).0[0].next_u64(), x1);
    assert_ne!(coins(seed, 4, coin_stream(1), 1).0[0].next_u64(), x1);
    assert_eq!(coin_stream(0), 1);
    assert_eq!(DATA_STREAM, 0);
}

#[test]
fn stepping_a_trial_by_hand_is_the_loop() {
    // The one stepper: a caller that feeds the readings one step at a time (as Python or a
    // live deployment would) gets the loop's every number, here over a multi-hop mesh with
    // lossy hops, retries and every scheme kind of the built-in.
    let text = hushfuse::scenario::builtin::get("mesh-line").unwrap();
    let exp = build::load(text, "mesh-line").unwrap();
    let data = draw_trial(&exp, 0);
    for v in 0..exp.variants.len() {
        let looped = record(&exp, &data.measurements, v, None);
        let mut buffers = LoopBuffers::new(exp.system.n_sensors());
        let spec = TrialSpec {
            trial: 0,
            variant: v,
            stream: coin_stream(v),
            available: None,
        };
        let mut trial = Trial::new(&exp, spec, &mut buffers, true).unwrap();
        for (k, readings) in data.measurements.iter().enumerate() {
            let s = trial.step(k + 1, readings).unwrap();
            let (est, links, bits, traffic) = &looped.steps[k];
            assert_eq!(
                (s.estimate, s.links, s.bits),
                (est, &links[..], &bits[..]),
                "v {v}, k {}",
                k + 1
            );
            assert_eq!(&s.traffic, traffic);
            assert!(!s.nodes.is_empty());
        }
    }
}
