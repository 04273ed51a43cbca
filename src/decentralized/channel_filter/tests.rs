//! The channel filter: the hub of a star tree is the all-data filter at every step (its leaves
//! one hop away, their channels subtracting the shared prior and past once); loops and lossy
//! links refused by name; one broadcast a node and step.
use super::*;
use crate::decentralized::fixture::{
    close, model, network, prior, reading, reference, ring, sensors,
};
use crate::linalg::Vector;
use crate::network::graph::driver::GraphDriver;
use crate::network::radio::PHY_OVERHEAD_BITS;

type Steps = Vec<(
    Vec<Gaussian>,
    Vec<crate::network::topology::tally::NodeCounts>,
)>;

fn run(t: &Topology, steps: usize) -> Steps {
    check_network(t).unwrap();
    let n = t.nodes.len();
    let s = sensors();
    let mut nodes: Vec<Box<dyn NetworkNode<InformationEstimate>>> = (0..n)
        .map(|i| {
            let neighbours = (0..n)
                .filter(|&j| j != i && t.link(i, j).is_some())
                .collect();
            let sensor = s.get(i).map(|(h, r)| (h, r));
            Box::new(ChannelFilterNode::new(model(), &prior(), sensor, neighbours).unwrap())
                as Box<dyn NetworkNode<InformationEstimate>>
        })
        .collect();
    let mut d = GraphDriver::new(t, ROUNDS, steps, 2, 0);
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
fn the_hub_of_a_star_is_the_all_data_filter() {
    let steps = 10;
    let got = run(&network("\"star\"", "kind = \"ideal\""), steps);
    let all = reference(&[0, 1, 2], 1.0, steps);
    for (k, (est, counts)) in got.iter().enumerate() {
        assert!(
            close(&est[3], &all[k], 1e-9),
            "step {}: {:?} vs {:?}",
            k + 1,
            est[3],
            all[k]
        );
        // A leaf holds at least its own data: never worse than its local filter.
        for (i, e) in est.iter().take(3).enumerate() {
            let own = &reference(&[i], 1.0, steps)[k];
            assert!(
                e.cov.trace() <= own.cov.trace() + 1e-12,
                "leaf {i}, step {}",
                k + 1
            );
        }
        // One broadcast each; a 2-state pair is 5 singles.
        let ppdu = mpdu_bits_for_payload(160) + PHY_OVERHEAD_BITS;
        assert!(counts.iter().all(|c| c[..2] == [1, ppdu]));
    }
    // Without the channels' subtraction the shared prior would be counted four times at the
    // hub at step 1: its information is the all-data filter's, not more.
    assert!(close(&got[0].0[3], &all[0], 1e-9));
}

#[test]
fn loops_and_lossy_links_are_refused_by_name() {
    let e = check_network(&ring("kind = \"ideal\"")).unwrap_err();
    assert!(
        e.starts_with("network.edges: the channel filter needs a tree, but 4 nodes have 4 links"),
        "{e}"
    );
    let lossy = network("\"star\"", "kind = \"bernoulli\"\nloss = 0.1");
    let e = check_network(&lossy).unwrap_err();
    assert!(
        e.contains("needs lossless links") && e.contains("s0 – sink"),
        "{e}"
    );
}
