//! The Kalman consensus filter: γ = 0 gives the local filters; one step with γ > 0 by hand from
//! them; one broadcast of n singles a step.
use super::*;
use crate::decentralized::fixture::{close, model, prior, reading, reference, ring, sensors};
use crate::network::graph::driver::GraphDriver;
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::Topology;

type Steps = Vec<(
    Vec<Gaussian>,
    Vec<crate::network::topology::tally::NodeCounts>,
)>;

fn run(t: &Topology, gamma: f64, steps: usize) -> Steps {
    let n = t.nodes.len();
    let s = sensors();
    let mut nodes: Vec<Box<dyn NetworkNode<Prediction>>> = (0..n)
        .map(|i| {
            let neighbours = (0..n)
                .filter(|&j| j != i && t.link(i, j).is_some())
                .collect();
            let sensor = s.get(i).map(|(h, r)| (h, r));
            Box::new(
                KalmanConsensusNode::new(model(), &prior(), sensor, gamma, neighbours).unwrap(),
            ) as Box<dyn NetworkNode<Prediction>>
        })
        .collect();
    let mut d = GraphDriver::new(t, ROUNDS, steps, 9, 0);
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

#[test]
fn without_consensus_gain_each_node_is_its_local_filter() {
    let steps = 6;
    let got = run(&ring("kind = \"ideal\""), 0.0, steps);
    for (k, (est, counts)) in got.iter().enumerate() {
        for (i, e) in est.iter().enumerate() {
            let local: Vec<usize> = if i < 3 { vec![i] } else { vec![] };
            assert!(
                close(e, &reference(&local, 1.0, steps)[k], 1e-10),
                "node {i}, step {}",
                k + 1
            );
        }
        // x̄ of a 2-state: 2 singles in one frame a step, heard by both neighbours.
        let ppdu = mpdu_bits_for_payload(64) + PHY_OVERHEAD_BITS;
        for c in counts {
            assert_eq!(c[..4], [1, ppdu, 2, 2 * ppdu]);
        }
    }
}

#[test]
fn one_step_of_the_consensus_term_by_hand() {
    // Step 1: every prediction is the prior, so the consensus term is 0 and every node is its
    // local filter. Step 2, node s0 (neighbours s1 and the sink): its local update plus
    // C (x̄₁ − x̄₀ + x̄_sink − x̄₀), C = γP/(1 + ‖P‖_F), from the local filters' step 1.
    let gamma = 0.5;
    let got = run(&ring("kind = \"ideal\""), gamma, 2);
    let m = model();
    let local = |which: &[usize]| reference(which, 1.0, 2);
    let step1 = [
        local(&[0])[0].clone(),
        local(&[1])[0].clone(),
        local(&[2])[0].clone(),
        local(&[])[0].clone(),
    ];
    let xbar = |j: usize| &m.a * &step1[j].mean;
    let p0 = &m.a * &step1[0].cov * m.a.transpose() + &m.q;
    let c = &p0 * (gamma / (1.0 + p0.norm()));
    let pull = (xbar(1) - xbar(0)) + (xbar(3) - xbar(0));
    let want_mean = &local(&[0])[1].mean + c * pull;
    let e = &got[1].0[0];
    assert!(
        (&e.mean - &want_mean).amax() < 1e-10,
        "{e:?} vs {want_mean:?}"
    );
    assert!((&e.cov - &local(&[0])[1].cov).amax() < 1e-10);
    assert!(
        (&e.mean - &local(&[0])[1].mean).amax() > 1e-3,
        "the term moved the estimate"
    );
}

#[test]
fn a_negative_gain_is_refused() {
    let e = KalmanConsensusNode::new(model(), &prior(), None, -1.0, vec![])
        .err()
        .unwrap();
    assert!(e.contains("gamma = -1"), "{e}");
}
