//! The diffusion Kalman filter's limits by hand (complete graph, c = 1/N: the all-data filter;
//! C = I: each node's neighbourhood filter) and its price: two broadcasts a step
//! adapt-then-combine, one combine-then-adapt.
use super::*;
use crate::decentralized::fixture::{close, model, network, prior, reading, reference, sensors};
use crate::network::graph::driver::GraphDriver;
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::Topology;

type Steps = Vec<(
    Vec<Gaussian>,
    Vec<crate::network::topology::tally::NodeCounts>,
)>;

/// Every node of `t` (three sensors and the sink), combination weights `c(i, j)`.
fn run(t: &Topology, order: Order, c: impl Fn(usize, usize) -> f64, steps: usize) -> Steps {
    run_triggered(t, order, c, None, steps)
}

/// [`run`] with the event trigger at `threshold` (`None`: untriggered).
fn run_triggered(
    t: &Topology,
    order: Order,
    c: impl Fn(usize, usize) -> f64,
    threshold: Option<f64>,
    steps: usize,
) -> Steps {
    let n = t.nodes.len();
    let mut all: Vec<Option<(Matrix, Matrix)>> = sensors().into_iter().map(Some).collect();
    all.push(None);
    let mut nodes: Vec<Box<dyn NetworkNode<DiffusionMessage>>> = (0..n)
        .map(|i| {
            let neighbours = (0..n)
                .filter(|&j| j != i && t.link(i, j).is_some())
                .map(|j| (j, c(j, i)))
                .collect();
            let node =
                DiffusionNode::new(order, model(), &prior(), &all, i, c(i, i), neighbours).unwrap();
            let node = match threshold {
                Some(t) => node.triggered(t).unwrap(),
                None => node,
            };
            Box::new(node) as Box<dyn NetworkNode<DiffusionMessage>>
        })
        .collect();
    let mut d = GraphDriver::new(t, DiffusionNode::rounds(order), steps, 3, 0);
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

const COMPLETE: &str = "\"complete\"";
/// s0 – s1 – s2 – sink: a line.
const LINE: &str = "[[\"s0\", \"s1\"], [\"s1\", \"s2\"], [\"s2\", \"sink\"]]";

#[test]
fn a_complete_graph_with_equal_weights_is_the_all_data_filter() {
    let steps = 8;
    let t = network(COMPLETE, "kind = \"ideal\"");
    let got = run(&t, Order::AdaptThenCombine, |_, _| 0.25, steps);
    let all = reference(&[0, 1, 2], 1.0, steps);
    for (k, (est, counts)) in got.iter().enumerate() {
        for (i, e) in est.iter().enumerate() {
            assert!(close(e, &all[k], 1e-10), "node {i}, step {}", k + 1);
        }
        // Sensors send a measurement (1 single) and ψ (2 singles); the sink only ψ.
        let (z, psi) = (
            mpdu_bits_for_payload(32) + PHY_OVERHEAD_BITS,
            mpdu_bits_for_payload(64) + PHY_OVERHEAD_BITS,
        );
        for (i, c) in counts.iter().enumerate() {
            let sent = if i < 3 { [2, z + psi] } else { [1, psi] };
            assert_eq!(c[..2], sent, "node {i}");
        }
    }
}

#[test]
fn without_combination_each_node_is_its_neighbourhoods_filter() {
    // C = I on the line: s0 fuses s0, s1; s1 all three; s2 s1, s2; the sink s2's.
    let steps = 6;
    let t = network(LINE, "kind = \"ideal\"");
    let identity = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
    for order in [Order::AdaptThenCombine, Order::CombineThenAdapt] {
        let got = run(&t, order, identity, steps);
        let want = [
            reference(&[0, 1], 1.0, steps),
            reference(&[0, 1, 2], 1.0, steps),
            reference(&[1, 2], 1.0, steps),
            reference(&[2], 1.0, steps),
        ];
        for (k, (est, _)) in got.iter().enumerate() {
            for (i, e) in est.iter().enumerate() {
                assert!(
                    close(e, &want[i][k], 1e-10),
                    "{order:?}, node {i}, step {}",
                    k + 1
                );
            }
        }
    }
}

#[test]
fn combine_then_adapt_sends_one_frame_a_step() {
    // The complete graph with c = 1/N: after the first step every node's prediction is the
    // same, so combining changes nothing and the filter is the all-data one too.
    let steps = 5;
    let t = network(COMPLETE, "kind = \"ideal\"");
    let got = run(&t, Order::CombineThenAdapt, |_, _| 0.25, steps);
    let all = reference(&[0, 1, 2], 1.0, steps);
    for (k, (est, counts)) in got.iter().enumerate() {
        for e in est {
            assert!(close(e, &all[k], 1e-10), "step {}", k + 1);
        }
        for (i, c) in counts.iter().enumerate() {
            let singles = if i < 3 { 3 } else { 2 };
            let ppdu = mpdu_bits_for_payload(32 * singles) + PHY_OVERHEAD_BITS;
            // One frame; heard by the 3 others; one window per neighbour.
            assert_eq!((c[0], c[1], c[2], c[11]), (1, ppdu, 3, 3), "node {i}");
        }
    }
}

#[test]
fn the_trigger_at_zero_is_the_untriggered_filter_and_never_is_the_local_one() {
    let steps = 8;
    let t = network(LINE, "kind = \"ideal\"");
    let c = |a: usize, b: usize| if a == b { 0.5 } else { 0.25 };
    for order in [Order::AdaptThenCombine, Order::CombineThenAdapt] {
        let plain = run(&t, order, c, steps);
        let zero = run_triggered(&t, order, c, Some(0.0), steps);
        for (k, ((a, ca), (b, cb))) in plain.iter().zip(&zero).enumerate() {
            assert_eq!(a, b, "{order:?}, step {}", k + 1);
            assert_eq!(ca, cb);
        }
        // A threshold no covariance reaches: nothing on air, nobody listening, local filters.
        let never = run_triggered(&t, order, c, Some(1e12), steps);
        for (k, (est, counts)) in never.iter().enumerate() {
            assert!(counts.iter().all(|x| x[0] == 0 && x[11] == 0));
            for (i, e) in est.iter().enumerate() {
                let local: Vec<usize> = if i < 3 { vec![i] } else { vec![] };
                assert!(
                    close(e, &reference(&local, 1.0, steps)[k], 1e-10),
                    "node {i}, step {}",
                    k + 1
                );
            }
        }
        // In between: the nodes whose prediction is uncertain talk, the others save frames.
        let some = run_triggered(&t, order, c, Some(1.0), steps);
        let frames = |r: &Steps| {
            r.iter()
                .flat_map(|(_, c)| c.iter().map(|x| x[0]))
                .sum::<u64>()
        };
        assert!(
            0 < frames(&some) && frames(&some) < frames(&plain),
            "{order:?}"
        );
    }
    assert!(DiffusionNode::new(
        Order::AdaptThenCombine,
        model(),
        &prior(),
        &[],
        0,
        1.0,
        vec![]
    )
    .unwrap()
    .triggered(-1.0)
    .is_err());
}
