//! The consensus family on a 4-node ring (three sensors and a naive node): its limits by hand
//! (CI, L → ∞: the Kalman filter with every R multiplied by N; CM, the hybrid and the ICF with
//! ω = N, L → ∞: the all-data Kalman filter; CI with L = 0 or every broadcast lost: each node's
//! local Kalman filter; the hybrid with ω = 1 is CI) and its price per edge.
use super::split::Halves;
use super::*;
use crate::decentralized::fixture::{close, model, prior, reading, reference, ring, sensors};
use crate::decentralized::weights::{WeightRule, Weights};
use crate::network::graph::driver::GraphDriver;
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::Topology;

type Nodes = Vec<Box<dyn NetworkNode<InformationPairs>>>;

fn nodes(t: &Topology, fusion: Fusion, rule: &WeightRule, iterations: usize) -> Nodes {
    unboxed(t, fusion, rule, iterations)
        .into_iter()
        .map(|n| Box::new(n) as Box<dyn NetworkNode<InformationPairs>>)
        .collect()
}

fn unboxed(
    t: &Topology,
    fusion: Fusion,
    rule: &WeightRule,
    iterations: usize,
) -> Vec<ConsensusNode> {
    let edges: Vec<(usize, usize)> = t.links.iter().map(|l| (l.a, l.b)).collect();
    let n = t.nodes.len();
    let w = Weights::new(rule, n, &edges).unwrap();
    let s = sensors();
    (0..n)
        .map(|i| {
            let neighbours = (0..n)
                .filter(|&j| j != i && t.link(i, j).is_some())
                .map(|j| (j, w.get(i, j)))
                .collect();
            let sensor = s.get(i).map(|(h, r)| (h, r));
            ConsensusNode::new(
                fusion,
                model(),
                &prior(),
                sensor,
                w.get(i, i),
                neighbours,
                iterations,
            )
            .unwrap()
        })
        .collect()
}

type Steps = Vec<(
    Vec<Gaussian>,
    Vec<crate::network::topology::tally::NodeCounts>,
)>;

/// Runs `steps` steps of `fusion` with weights `rule`; after each, every node's estimate and
/// the driver's counters.
fn run_with(
    t: &Topology,
    fusion: Fusion,
    rule: &WeightRule,
    iterations: usize,
    steps: usize,
) -> Steps {
    let mut nodes = nodes(t, fusion, rule, iterations);
    let mut d = GraphDriver::new(t, ConsensusNode::rounds(iterations), steps, 5, 0);
    (1..=steps)
        .map(|k| {
            let z: Vec<Vector> = (0..3).map(|i| reading(k, i)).collect();
            let readings: Vec<Option<&Vector>> = z.iter().map(Some).collect();
            d.step(k, &mut nodes, &readings).unwrap();
            let est = nodes
                .iter()
                .map(|x| x.estimate().unwrap().clone())
                .collect();
            (est, d.counts().to_vec())
        })
        .collect()
}

/// CI with Metropolis weights.
fn run(t: &Topology, iterations: usize, steps: usize) -> Steps {
    let rule = WeightRule::MetropolisHastings;
    run_with(t, Fusion::Information, &rule, iterations, steps)
}

#[test]
fn many_iterations_give_the_kalman_filter_with_every_r_times_n() {
    // ρ of the 4-ring is 1/3: 200 iterations leave 1e-95 of the disagreement.
    let steps = 10;
    let got = run(&ring("kind = \"ideal\""), 200, steps);
    let want = reference(&[0, 1, 2], 1.0 / 4.0, steps);
    for (k, (est, _)) in got.iter().enumerate() {
        for (i, e) in est.iter().enumerate() {
            assert!(
                close(e, &want[k], 1e-9),
                "node {i}, step {}: {e:?} vs {:?}",
                k + 1,
                want[k]
            );
        }
    }
    // Not the all-data filter (N-fold inflated R): the limit is conservative.
    let all = reference(&[0, 1, 2], 1.0, steps);
    assert!(got[steps - 1].0[0].cov[(0, 0)] > all[steps - 1].cov[(0, 0)] * 1.5);
}

#[test]
fn no_iteration_or_every_broadcast_lost_is_each_nodes_local_filter() {
    let steps = 6;
    // A parent's frames to its children cross the link's downlink (the tree's direction of the
    // feedback): both directions lose everything.
    let deaf = "kind = \"bernoulli\"\nloss = 1.0\ndownlink = { kind = \"bernoulli\", loss = 1.0 }";
    let lost = run(&ring(deaf), 3, steps);
    let silent = run(&ring("kind = \"ideal\""), 0, steps);
    for got in [&silent, &lost] {
        for (k, (est, _)) in got.iter().enumerate() {
            for (i, e) in est.iter().enumerate() {
                let local: Vec<usize> = if i < 3 { vec![i] } else { vec![] };
                let want = reference(&local, 1.0, steps);
                assert!(
                    close(e, &want[k], 1e-12),
                    "node {i}, step {}: {e:?} vs {:?}",
                    k + 1,
                    want[k]
                );
            }
        }
    }
    // Without iterations nothing goes on air.
    assert!(silent[0].1.iter().all(|c| c[0] == 0));
    // Every broadcast lost is still on air: L frames per node and step, none received.
    let (_, counts) = &lost[0];
    for c in counts {
        assert_eq!((c[0], c[2]), (3, 0));
    }
}

#[test]
fn every_iteration_is_one_broadcast_heard_by_each_neighbour() {
    // L = 2 on the ring: each node sends 2 frames a step and receives 2 from each of its 2
    // neighbours; a pair of a 2-state is 2 + 3 = 5 singles, 20 octets, in one MAC frame.
    let got = run(&ring("kind = \"ideal\""), 2, 3);
    let ppdu = mpdu_bits_for_payload(160) + PHY_OVERHEAD_BITS;
    for (_, counts) in &got {
        for c in counts {
            // sent, bits sent, received, bits received; listens (windows) last.
            assert_eq!(c[..4], [2, 2 * ppdu, 4, 4 * ppdu]);
            assert_eq!(c[11], 4);
        }
    }
}

#[test]
fn measurements_hybrid_and_icf_with_omega_n_give_the_all_data_filter() {
    let steps = 8;
    let all = reference(&[0, 1, 2], 1.0, steps);
    let ideal = ring("kind = \"ideal\"");
    let metropolis = WeightRule::MetropolisHastings;
    for (fusion, rule, what) in [
        (Fusion::Measurements { omega: 4.0 }, &metropolis, "CM"),
        (Fusion::Hybrid { omega: 4.0 }, &metropolis, "HCMCI"),
        (
            Fusion::information_weighted(4),
            &WeightRule::MaxDegree,
            "ICF",
        ),
    ] {
        let got = run_with(&ideal, fusion, rule, 300, steps);
        for (k, (est, _)) in got.iter().enumerate() {
            for (i, e) in est.iter().enumerate() {
                assert!(close(e, &all[k], 1e-9), "{what}, node {i}, step {}", k + 1);
            }
        }
    }
}

#[test]
fn the_hybrid_with_omega_one_is_consensus_on_information() {
    // Linearity: avg(Ω⁻) + avg(U) = avg(Ω⁻ + U), at any L and over lossy links alike.
    let lossy =
        ring("kind = \"bernoulli\"\nloss = 0.3\ndownlink = { kind = \"bernoulli\", loss = 0.3 }");
    let rule = WeightRule::MetropolisHastings;
    let ci = run_with(&lossy, Fusion::Information, &rule, 3, 10);
    let hybrid = run_with(&lossy, Fusion::Hybrid { omega: 1.0 }, &rule, 3, 10);
    for (k, ((a, _), (b, _))) in ci.iter().zip(&hybrid).enumerate() {
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(close(x, y, 1e-10), "node {i}, step {}", k + 1);
        }
    }
    // The hybrid's frame carries two pairs: 10 singles, 40 octets of payload.
    let ppdu = mpdu_bits_for_payload(320) + PHY_OVERHEAD_BITS;
    assert_eq!(hybrid[0].1[0][1], 3 * ppdu);
}

/// On lossless links the lock-step loop ([`lockstep`]) gives the graph driver's estimates and
/// counters bit for bit, for every member of the family.
#[test]
fn the_lock_step_loop_is_the_driver_bit_for_bit() {
    let t = ring("kind = \"ideal\"");
    let steps = 7;
    let measurements: Vec<Vec<Vector>> = (1..=steps)
        .map(|k| (0..3).map(|i| reading(k, i)).collect())
        .collect();
    let bits = |g: &Gaussian| {
        g.mean
            .iter()
            .chain(g.cov.iter())
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    };
    for fusion in [
        Fusion::Information,
        Fusion::Measurements { omega: 4.0 },
        Fusion::Hybrid { omega: 4.0 },
    ] {
        let rule = WeightRule::MetropolisHastings;
        let want = run_with(&t, fusion, &rule, 3, steps);
        let mut nodes = unboxed(&t, fusion, &rule, 3);
        assert!(lockstep::applies(&t));
        let mut got = Vec::new();
        lockstep::run(&t, &measurements, &mut nodes, &mut |_, est, counts, _| {
            got.push((
                est.iter().map(|g| bits(g)).collect::<Vec<_>>(),
                counts.to_vec(),
            ));
            Ok(())
        })
        .unwrap();
        for (k, ((est, counts), (we, wc))) in got.iter().zip(&want).enumerate() {
            let we: Vec<_> = we.iter().map(bits).collect();
            assert_eq!(est, &we, "{fusion:?}, step {}", k + 1);
            assert_eq!(counts, wc, "{fusion:?}, step {}", k + 1);
        }
    }
}

/// Consensus on information's fixed-size start and prediction in the lock-step loop (states of
/// 1 to 6 dimensions) give the graph driver's estimates, bit for bit: a coupled model, sensors
/// of one and two rows on different components, and a sensor silent at some steps.
#[test]
fn the_fixed_size_information_step_is_the_nodes_own_bit_for_bit() {
    let t = ring("kind = \"ideal\"");
    let rule = WeightRule::MetropolisHastings;
    let edges: Vec<(usize, usize)> = t.links.iter().map(|l| (l.a, l.b)).collect();
    let w = Weights::new(&rule, 4, &edges).unwrap();
    let bits = |g: &Gaussian| {
        let all = g.mean.iter().chain(g.cov.iter());
        all.map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    for d in 1..=6 {
        let model = Model {
            a: Matrix::from_fn(d, d, |r, c| match c as isize - r as isize {
                0 => 1.0,
                1 => 0.7,
                _ => 0.0,
            }),
            q: Matrix::from_fn(
                d,
                d,
                |r, c| if r == c { 0.1 + 0.03 * r as f64 } else { 0.01 },
            ),
        };
        let prior = Gaussian::new(
            Vector::from_fn(d, |r, _| 0.3 * r as f64 - 1.0),
            Matrix::from_fn(d, d, |r, c| if r == c { 4.0 + r as f64 } else { 0.5 }),
        );
        let sensors: Vec<(Matrix, Matrix)> = (0..3)
            .map(|i| {
                let rows = 1 + i % 2;
                let h = Matrix::from_fn(rows, d, |r, c| {
                    if c == (i + r) % d {
                        1.0
                    } else {
                        0.1 * (r + c) as f64
                    }
                });
                let r =
                    Matrix::from_fn(rows, rows, |a, b| if a == b { 0.5 + i as f64 } else { 0.2 });
                (h, r)
            })
            .collect();
        let make = || -> Vec<ConsensusNode> {
            (0..4)
                .map(|i| {
                    let neighbours = (0..4)
                        .filter(|&j| j != i && t.link(i, j).is_some())
                        .map(|j| (j, w.get(i, j)))
                        .collect();
                    let sensor = sensors.get(i).map(|(h, r)| (h, r));
                    let (fusion, a) = (Fusion::Information, w.get(i, i));
                    ConsensusNode::new(fusion, model.clone(), &prior, sensor, a, neighbours, 3)
                        .unwrap()
                })
                .collect()
        };
        let steps = 6;
        // Sensor 2 is silent at even steps (the lock-step loop reads a missing trailing entry).
        let measurements: Vec<Vec<Vector>> = (1..=steps)
            .map(|k| {
                let heard = if k % 2 == 0 { 2 } else { 3 };
                (0..heard)
                    .map(|i| {
                        Vector::from_fn(sensors[i].0.nrows(), |r, _| reading(k, i)[0] + r as f64)
                    })
                    .collect()
            })
            .collect();
        let mut boxed: Nodes = make()
            .into_iter()
            .map(|n| Box::new(n) as Box<dyn NetworkNode<InformationPairs>>)
            .collect();
        let mut driver = GraphDriver::new(&t, ConsensusNode::rounds(3), steps, 5, 0);
        let mut want = Vec::new();
        for (j, z) in measurements.iter().enumerate() {
            let readings: Vec<Option<&Vector>> = (0..3).map(|i| z.get(i)).collect();
            driver.step(j + 1, &mut boxed, &readings).unwrap();
            want.push(
                boxed
                    .iter()
                    .map(|x| bits(x.estimate().unwrap()))
                    .collect::<Vec<_>>(),
            );
        }
        let mut nodes = make();
        let mut got = Vec::new();
        lockstep::run(&t, &measurements, &mut nodes, &mut |_, est, _, _| {
            got.push(est.iter().map(|g| bits(g)).collect::<Vec<_>>());
            Ok(())
        })
        .unwrap();
        assert_eq!(got, want, "state of {d} dimensions");
    }
}

/// Every node's estimate, bit by bit, after each step of the graph driver on `measurements`
/// (`[k - 1][i]`; a missing trailing entry is a silent sensor).
fn driver_bits(t: &Topology, iterations: usize, measurements: &[Vec<Vector>]) -> Vec<Vec<u64>> {
    let rule = WeightRule::MetropolisHastings;
    let mut boxed = nodes(t, Fusion::Information, &rule, iterations);
    let steps = measurements.len();
    let mut driver = GraphDriver::new(t, ConsensusNode::rounds(iterations), steps, 5, 0);
    measurements
        .iter()
        .enumerate()
        .map(|(j, z)| {
            let readings: Vec<Option<&Vector>> = (0..3).map(|i| z.get(i)).collect();
            driver.step(j + 1, &mut boxed, &readings).unwrap();
            boxed
                .iter()
                .flat_map(|x| gaussian_bits(x.estimate().unwrap()))
                .collect()
        })
        .collect()
}

fn gaussian_bits(g: &Gaussian) -> Vec<u64> {
    g.mean
        .iter()
        .chain(g.cov.iter())
        .map(|v| v.to_bits())
        .collect()
}

/// Readings of trial `trial` (values shifted per trial), sensor 2 silent at the steps of
/// `silent`.
fn trial_readings(trial: usize, steps: usize, silent: &[usize]) -> Vec<Vec<Vector>> {
    (1..=steps)
        .map(|k| {
            let heard = if silent.contains(&k) { 2 } else { 3 };
            (0..heard)
                .map(|i| reading(k, i).add_scalar(0.37 * trial as f64))
                .collect()
        })
        .collect()
}

/// Consensus on information in the lock-step loop computes its matrices once per run and
/// thread ([`split`]): trials with the same readings present reuse them (a second and a third
/// trial), a trial with other readings present builds new ones, and one whose matrices are
/// streamed step by step (no track kept) gives the same numbers; each is the graph driver's
/// bit for bit.
#[test]
fn shared_matrices_give_every_trial_the_drivers_numbers() {
    let t = ring("kind = \"ideal\"");
    let rule = WeightRule::MetropolisHastings;
    let (iterations, steps) = (3, 6);
    let lockstep_bits = |z: &[Vec<Vector>]| {
        let mut nodes = unboxed(&t, Fusion::Information, &rule, iterations);
        let mut got = Vec::new();
        lockstep::run(&t, z, &mut nodes, &mut |_, est, _, factors| {
            // The shared track hands the recorder each estimate's NEES factor.
            let factors = factors.expect("the track's NEES factors");
            for (g, f) in est.iter().zip(factors.chunks_exact(4)) {
                assert_eq!(crate::linalg::fixed::nees_factor(&g.cov).unwrap(), f);
            }
            got.push(
                est.iter()
                    .flat_map(|g| gaussian_bits(g))
                    .collect::<Vec<_>>(),
            );
            Ok(())
        })
        .unwrap();
        got
    };
    // Trials 0-2 share one track; trial 3 (sensor 2 silent at step 2) needs its own; trial 4
    // goes back to the first presence (a third track, built again).
    for (trial, silent) in [
        (0, vec![]),
        (1, vec![]),
        (2, vec![]),
        (3, vec![2]),
        (4, vec![]),
    ] {
        let z = trial_readings(trial, steps, &silent);
        assert_eq!(
            lockstep_bits(&z),
            driver_bits(&t, iterations, &z),
            "trial {trial}"
        );
    }
    // Streamed: a track of at most 0 reals is never kept.
    let z = trial_readings(5, steps, &[1, 4]);
    let mut nodes = unboxed(&t, Fusion::Information, &rule, iterations);
    let weights: Vec<mixing::NodeWeights> = nodes
        .iter()
        .map(|n| (n.own_weight, n.neighbours.clone()))
        .collect();
    let mut split = split::Split::<2>::with_track_limit(&nodes, &weights, &z, 3, 0);
    let streamed: Vec<Vec<u64>> = z
        .iter()
        .enumerate()
        .map(|(j, zk)| {
            split.step(j, &mut nodes, &weights, zk).unwrap();
            nodes
                .iter()
                .flat_map(|n| gaussian_bits(&n.estimate))
                .collect()
        })
        .collect();
    assert_eq!(streamed, driver_bits(&t, iterations, &z));
}

/// A matrix that is not positive definite depends on the matrices alone: the trial that builds
/// the track, one that reuses it and one that streams its matrices all stop at the same step
/// and node with the same message, after recording the same steps.
#[test]
fn a_failure_of_the_shared_matrices_stops_every_trial_alike() {
    let t = ring("kind = \"ideal\"");
    let rule = WeightRule::MetropolisHastings;
    let z = trial_readings(0, 5, &[]);
    // Q = -P⁻ of step 2's prediction is not known in advance; a Q with a negative diagonal
    // large enough makes P⁻ = A P Aᵀ + Q indefinite at the first prediction.
    let broken = |nodes: &mut Vec<ConsensusNode>| {
        for n in nodes.iter_mut() {
            n.model.q = Matrix::from_diagonal_element(2, 2, -50.0);
        }
    };
    let run = |limit: Option<usize>| -> (usize, String) {
        let mut nodes = unboxed(&t, Fusion::Information, &rule, 2);
        broken(&mut nodes);
        let mut recorded = 0;
        let outcome = match limit {
            None => lockstep::run(&t, &z, &mut nodes, &mut |_, _, _, _| {
                recorded += 1;
                Ok(())
            }),
            Some(limit) => {
                let weights: Vec<mixing::NodeWeights> = nodes
                    .iter()
                    .map(|n| (n.own_weight, n.neighbours.clone()))
                    .collect();
                let mut split = split::Split::<2>::with_track_limit(&nodes, &weights, &z, 3, limit);
                z.iter()
                    .enumerate()
                    .try_for_each(|(j, zk)| {
                        split.step(j, &mut nodes, &weights, zk)?;
                        recorded += 1;
                        Ok::<(), (usize, String)>(())
                    })
                    .map_err(|(i, e)| format!("node {}: {e}", t.nodes[i].name))
            }
        };
        (recorded, outcome.unwrap_err())
    };
    let (built, reused, streamed) = (run(None), run(None), run(Some(0)));
    assert_eq!(built, reused);
    assert_eq!(built.0, 0, "the first prediction fails");
    assert!(
        built
            .1
            .contains("node s0, step 1, round 2: the predicted covariance is singular"),
        "{}",
        built.1
    );
    assert_eq!(
        streamed,
        (0, "node s0: the predicted covariance is singular".into())
    );
}
