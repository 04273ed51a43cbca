//! et-ddf by hand and against independent computations: the implicit update's moments against
//! quadrature over the state, δ = 0 as each node's neighbourhood Kalman filter, the frames a
//! silent sensor saves, and the silence read as information keeping a blind node consistent.
use super::*;
use crate::decentralized::fixture::{close, model, network, prior, reading, reference, sensors};
use crate::network::graph::driver::GraphDriver;
use crate::network::topology::Topology;
use crate::stats::normal::cdf;

type Steps = Vec<(
    Vec<Gaussian>,
    Vec<crate::network::topology::tally::NodeCounts>,
)>;

/// Every node of `t` (three sensors and the sink) with trigger `delta` and CI threshold `tau`,
/// on `readings(k, i)`.
fn run(
    t: &Topology,
    (delta, tau): (f64, Option<f64>),
    readings: &dyn Fn(usize, usize) -> Vector,
    steps: usize,
) -> Steps {
    let n = t.nodes.len();
    let mut all: Vec<Option<Elements>> = sensors()
        .iter()
        .map(|(h, r)| Some(elements(h, r).unwrap()))
        .collect();
    all.push(None);
    let mut nodes: Vec<Box<dyn NetworkNode<EtDdfMessage>>> = (0..n)
        .map(|i| {
            let node = EtDdfNode::new(model(), &prior(), &all, i, t.neighbours(i), (delta, tau));
            Box::new(node) as Box<dyn NetworkNode<EtDdfMessage>>
        })
        .collect();
    let mut d = GraphDriver::new(t, ROUNDS, steps, 3, 0);
    (1..=steps)
        .map(|k| {
            let z: Vec<Vector> = (0..3).map(|i| readings(k, i)).collect();
            let zs: Vec<Option<&Vector>> = z.iter().map(Some).collect();
            d.step(k, &mut nodes, &zs).unwrap();
            let est = nodes
                .iter()
                .map(|x| x.estimate().unwrap().clone())
                .collect();
            (est, d.counts().to_vec())
        })
        .collect()
}

/// s0 – s1 – s2 – sink: a line.
const LINE: &str = "[[\"s0\", \"s1\"], [\"s1\", \"s2\"], [\"s2\", \"sink\"]]";

/// The moments of x ~ N(1, 2) given z = x + v ∈ [0.3, 2], v ~ N(0, 0.5), by Simpson's rule over
/// x with P(band | x) = Φ((2 − x)/√0.5) − Φ((0.3 − x)/√0.5): the implicit update's mean and
/// variance to 1e-9.
#[test]
fn the_implicit_update_has_the_bands_moments() {
    let (m, p, r, lo, hi): (f64, f64, f64, f64, f64) = (1.0, 2.0, 0.5, 0.3, 2.0);
    let w = |x: f64| {
        let density = (-(x - m) * (x - m) / (2.0 * p)).exp();
        density * (cdf((hi - x) / r.sqrt()) - cdf((lo - x) / r.sqrt()))
    };
    let (a, b, steps) = (m - 14.0, m + 14.0, 20_000);
    let h = (b - a) / steps as f64;
    let mut sums = [0.0; 3];
    for i in 0..=steps {
        let x = a + i as f64 * h;
        let c = if i == 0 || i == steps {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let f = c * w(x);
        sums[0] += f;
        sums[1] += f * x;
        sums[2] += f * x * x;
    }
    let mean = sums[1] / sums[0];
    let var = sums[2] / sums[0] - mean * mean;
    let mut g = Gaussian::new(Vector::from_element(1, m), Matrix::from_element(1, 1, p));
    implicit(&mut g, &(Vector::from_element(1, 1.0), r), lo, hi).unwrap();
    assert!((g.mean[0] - mean).abs() < 1e-9, "{} vs {mean}", g.mean[0]);
    assert!(
        (g.cov[(0, 0)] - var).abs() < 1e-9,
        "{} vs {var}",
        g.cov[(0, 0)]
    );
}

/// δ = 0 sends every element: without CI each node is the Kalman filter of its closed
/// neighbourhood's readings (s0: s0, s1; s1: all; s2: s1, s2; the sink: s2), to 1e-10.
#[test]
fn a_trigger_of_zero_is_the_neighbourhood_filter() {
    let steps = 6;
    let t = network(LINE, "kind = \"ideal\"");
    let got = run(&t, (0.0, None), &reading, steps);
    let want = [
        reference(&[0, 1], 1.0, steps),
        reference(&[0, 1, 2], 1.0, steps),
        reference(&[1, 2], 1.0, steps),
        reference(&[2], 1.0, steps),
    ];
    for (k, (est, counts)) in got.iter().enumerate() {
        for (i, e) in est.iter().enumerate() {
            assert!(close(e, &want[i][k], 1e-10), "node {i}, step {}", k + 1);
        }
        // Every sensor sends its scalar element, the sink nothing.
        let sent: Vec<u64> = counts.iter().map(|c| c[0]).collect();
        assert_eq!(sent, vec![1, 1, 1, 0]);
    }
}

/// Readings that stay within δ of every prediction: no sensor ever sends, and the nodes are
/// not where the filters without readings would be (the silences moved them).
#[test]
fn silent_sensors_send_nothing_and_still_inform() {
    let steps = 5;
    let t = network(LINE, "kind = \"ideal\"");
    // Readings equal to the prior's prediction: inside any band.
    let on_track = |k: usize, i: usize| {
        let x = model().a.pow(k as u32 - 1) * prior().mean;
        &sensors()[i].0 * x
    };
    let got = run(&t, (1.0, None), &on_track, steps);
    for (est, counts) in &got {
        assert!(counts.iter().all(|c| c[0] == 0), "a silent sensor sent");
        // The sink hears s2's silence: its variance shrinks below the prior's prediction.
        assert!(est[3].cov[(0, 0)] < reference(&[], 1.0, 1)[0].cov[(0, 0)] + 1e-12);
    }
    let blind = reference(&[], 1.0, steps);
    assert!(got[steps - 1].0[3].cov.trace() < 0.5 * blind[steps - 1].cov.trace());
}
