//! Decentralized schemes from scenario files: a network of peers (`sink = false`) where every
//! node estimates, each node's numbers beside the scheme's row (their mean), the exact limit
//! (the hybrid consensus with ω = N and many iterations is the all-data KF that a sink computes
//! on the same data), bit-identical results on 1 and 2 threads, and bad input refused by field.
use hushfuse::engine::runner;
use hushfuse::metrics::results::{self, Summary};
use hushfuse::scenario::build;

/// A 1-D constant-velocity target watched by four sensors (three of the position, one of the
/// velocity), with `network` and `schemes`.
fn scenario(network: &str, schemes: &str, trials: usize) -> String {
    format!(
        r#"
name = "peers"
trials = {trials}
steps = 40
seed = 77
[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1
[prior]
mean = [0.0, 1.0]
cov_diag = [10.0, 1.0]
[[sensors]]
H = [[1.0, 0.0]]
R = [[1.0]]
[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]
[[sensors]]
H = [[1.0, 0.0]]
R = [[4.0]]
[[sensors]]
H = [[0.0, 1.0]]
R = [[0.5]]
[network]
{network}
{schemes}
"#
    )
}

fn run(text: &str, threads: usize) -> Summary {
    let exp = build::load(text, "peers.toml").unwrap();
    let sums = runner::run(&exp, runner::RunOptions { threads }, &|_| {}).unwrap();
    results::summarize(&exp, &sums)
}

fn refused(text: &str) -> String {
    build::load(text, "peers.toml").unwrap_err().to_string()
}

const RING: &str = "sink = false\nedges = \"ring\"\n";

#[test]
fn every_peer_estimates_and_the_row_is_their_mean() {
    let schemes = "[[schemes]]\nkind = \"consensus-information\"\nL = 3\n\
                   [[schemes]]\nkind = \"peer-ci\"\n[[schemes]]\nkind = \"diffusion-kf\"\n";
    let s = run(&scenario(RING, schemes, 24), 2);
    for v in &s.schemes {
        assert!(v.failed.is_none(), "{}: {:?}", v.name, v.failed);
        let e = v.estimators.as_ref().expect("every node estimates");
        let names: Vec<&str> = e.nodes.iter().map(|n| n.node.as_str()).collect();
        assert_eq!(
            names,
            ["s0", "s1", "s2", "s3"],
            "no sink in a network of peers"
        );
        let mean = e.nodes.iter().map(|n| n.steady_mse).sum::<f64>() / 4.0;
        let row = v.steady_state.mse;
        assert!(
            (mean - row).abs() < 1e-12 * row,
            "{}: {mean} vs {row}",
            v.name
        );
        let worst = e.nodes.iter().map(|n| n.steady_mse).fold(0.0, f64::max);
        assert_eq!(e.worst.steady_mse, worst);
        assert!(e
            .nodes
            .iter()
            .all(|n| n.steady_mse_se > 0.0 && n.energy_per_step_uj > 0.0));
        assert!(e.disagreement > 0.0 && e.disagreement_se > 0.0);
        // Every node broadcasts: its frames and their receivers are paid on every node.
        let net = v.network.as_ref().expect("the graph's nodes");
        assert!(net.nodes.iter().all(|n| n.frames_sent_per_step >= 1.0));
    }
    // Consensus on information: L = 3 broadcasts of every node a step, 4 nodes.
    assert_eq!(s.schemes[0].transmissions_per_step, 12.0);
}

#[test]
fn the_hybrid_with_many_iterations_is_the_all_data_filter_the_sink_computes() {
    // A ring through a sink without a sensor: the centralized KF at the sink over lossless hops
    // is the all-data KF; the hybrid consensus with omega = N = 5 (the sink a node without a
    // sensor) and L = 300 reaches it at every node, on the same data.
    let network = "edges = \"ring\"\n";
    let schemes = "[[schemes]]\nkind = \"centralized-kf\"\n\
                   [[schemes]]\nkind = \"consensus-hybrid\"\nL = 300\n";
    let s = run(&scenario(network, schemes, 8), 2);
    let (kf, hybrid) = (&s.schemes[0], &s.schemes[1]);
    // The sink fuses the readings as the singles that crossed the air (relative rounding
    // 6e-8); the consensus nodes' pairs are carried exactly: they agree to 1e-6.
    for (a, b) in kf.mse.iter().zip(&hybrid.mse) {
        assert!((a - b).abs() < 1e-6 * a.max(1.0), "per-step MSE {a} vs {b}");
    }
    for (a, b) in kf.trace.iter().zip(&hybrid.trace) {
        assert!(
            (a - b).abs() < 1e-9 * a.max(1.0),
            "per-step trace {a} vs {b}"
        );
    }
    let e = hybrid.estimators.as_ref().unwrap();
    assert_eq!(e.nodes.len(), 5);
    assert!(e.disagreement < 1e-18, "{}", e.disagreement);
}

#[test]
fn one_or_two_threads_give_the_same_bits() {
    let schemes = "[[schemes]]\nkind = \"consensus-measurements\"\nL = 2\n\
                   [[schemes]]\nkind = \"kalman-consensus\"\n";
    let network = "sink = false\nedges = \"ring\"\n[channel]\nkind = \"bernoulli\"\nloss = 0.3\n";
    let text = scenario(network, schemes, 13);
    let one = serde_json::to_string(&run(&text, 1)).unwrap();
    let two = serde_json::to_string(&run(&text, 2)).unwrap();
    assert_eq!(one, two);
}

#[test]
fn bad_networks_and_parameters_are_refused_by_field() {
    let ci = "[[schemes]]\nkind = \"consensus-information\"\nL = 2\n";
    let cases = [
        (RING, "[[schemes]]\nkind = \"centralized-kf\"\n", "network.sink"),
        ("sink = false\n", ci, "network.edges"),
        ("sink = false\nedges = [[\"s0\", \"s1\"], [\"s2\", \"s3\"]]\n", ci, "disconnected"),
        ("sink = false\nedges = \"line\"\nparent = { s0 = \"s1\" }\n", ci, "network.parent"),
        (RING, "[[schemes]]\nkind = \"channel-filter\"\n", "needs a tree"),
        (RING, "[[schemes]]\nkind = \"consensus-information\"\nL = 0\n", "schemes[0].L"),
        (RING, "[[schemes]]\nkind = \"consensus-information\"\nL = 20000\n", "schemes[0].L"),
        (RING, "[[schemes]]\nkind = \"consensus-hybrid\"\nL = 2\nomega = -1.0\n", "omega"),
        (
            RING,
            "[[schemes]]\nkind = \"consensus-information\"\nL = 2\nweights = [[0.5, 0.5, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0], [0.0, 0.0, 0.5, 0.5], [0.0, 0.0, 0.5, 0.4]]\n",
            "weights",
        ),
        (RING, "[[schemes]]\nkind = \"kalman-consensus\"\ngamma = -1.0\n", "gamma"),
        (RING, "[[schemes]]\nkind = \"diffusion-kf\"\norder = \"sideways\"\n", "order"),
    ];
    for (network, schemes, expected) in cases {
        let e = refused(&scenario(network, schemes, 2));
        assert!(e.contains(expected), "{network} {schemes}: {e}");
    }
}

#[test]
fn two_peers_run_the_channel_filter_as_the_all_data_filter() {
    // s0 – s1, lossless: the channel filter at each node is the all-data KF (Grime &
    // Durrant-Whyte on two nodes), which the hybrid consensus with omega = N = 2 and L = 200
    // also is; both carry their pairs exactly, so they agree to rounding.
    let text = scenario(
        "sink = false\nedges = \"line\"\n",
        "[[schemes]]\nkind = \"channel-filter\"\n\
                   [[schemes]]\nkind = \"consensus-hybrid\"\nL = 200\n",
        6,
    )
    .replace(
        "[[sensors]]\nH = [[1.0, 0.0]]\nR = [[4.0]]\n[[sensors]]\nH = [[0.0, 1.0]]\nR = [[0.5]]\n",
        "",
    );
    let s = run(&text, 2);
    let (cf, hybrid) = (&s.schemes[0], &s.schemes[1]);
    assert_eq!(cf.estimators.as_ref().unwrap().nodes.len(), 2);
    for (a, b) in cf.mse.iter().zip(&hybrid.mse) {
        assert!((a - b).abs() < 1e-9 * a.max(1.0), "per-step MSE {a} vs {b}");
    }
    // ... where consensus on information (a KF with every R doubled as L grows) is not.
    let ci = run(
        &text.replace(
            "L = 200",
            "L = 200\n[[schemes]]\nkind = \"consensus-information\"\nL = 200",
        ),
        2,
    );
    let far = ci.schemes[2]
        .trace
        .iter()
        .zip(&cf.trace)
        .any(|(a, b)| (a - b).abs() > 1e-3 * b);
    assert!(
        far,
        "consensus on information should not be the all-data filter"
    );
}

/// The `energy-ratio` claims of `consensus-energy-ring` hold (each energy equal to the checker's
/// independent count of frames, windows and sleep); they fail when a measured energy is 1e-6
/// off its count, when the ratio falls short of the claim, and on a lossy network (the count
/// assumes every frame arrives).
#[test]
fn the_consensus_energy_claims_hold_and_can_fail() {
    use hushfuse::output::report::{self, Verdict};
    let text = hushfuse::scenario::builtin::get("consensus-energy-ring").unwrap();
    let text = text
        .replace("trials = 20", "trials = 2")
        .replace("steps = 40", "steps = 22");
    let exp = hushfuse::scenario::build::load(&text, "ring.toml").unwrap();
    let sums = hushfuse::engine::runner::run(&exp, Default::default(), &|_| {}).unwrap();
    let summary = hushfuse::metrics::results::summarize(&exp, &sums);
    let claims = report::check_claims(&exp, &summary);
    let v: Vec<Verdict> = claims.iter().map(|c| c.verdict).collect();
    assert_eq!(&v[..2], &[Verdict::Holds, Verdict::Holds], "{claims:#?}");
    assert!(
        claims[0].evidence.contains("ratio 164.2"),
        "{}",
        claims[0].evidence
    );
    let mut off = summary.clone();
    off.schemes[0].energy.energy_per_step_uj *= 1.0 + 1e-6;
    assert_eq!(report::check_claims(&exp, &off)[0].verdict, Verdict::Fails);
    let higher = text.replace("at_least = 100.0", "at_least = 170.0");
    let exp2 = hushfuse::scenario::build::load(&higher, "ring.toml").unwrap();
    assert_eq!(
        report::check_claims(&exp2, &summary)[0].verdict,
        Verdict::Fails
    );
    let lossy = text.replace(
        "[network]",
        "[channel]\nkind = \"bernoulli\"\nloss = 0.1\n\n[network]",
    );
    let exp3 = hushfuse::scenario::build::load(&lossy, "ring.toml").unwrap();
    let c = &report::check_claims(&exp3, &summary)[0];
    assert_eq!(c.verdict, Verdict::Fails);
    assert!(c.evidence.contains("lossy"), "{}", c.evidence);
}

/// et-ddf on the built-in tree (30 agents, 4 sensors, 40 trials): on lossless links every
/// trigger keeps the agents consistent (steady-state ANEES at most 1 + 3 standard errors, as a
/// CI-fused filter should be); at drop 0.5 a lost reading read as silence makes delta = 1
/// overconfident by far more than its error (ANEES above 1 + 3 standard errors), while CI every
/// step stays consistent.
#[test]
fn et_ddf_is_consistent_on_lossless_links_and_not_when_silence_is_misread() {
    let text = hushfuse::scenario::builtin::get("et-ddf-tree").unwrap();
    let run = |text: &str| {
        let exp = hushfuse::scenario::build::load(text, "tree.toml").unwrap();
        let sums = hushfuse::engine::runner::run(&exp, Default::default(), &|_| {}).unwrap();
        hushfuse::metrics::results::summarize(&exp, &sums)
    };
    let clean = run(text);
    for s in &clean.schemes {
        let ss = &s.steady_state;
        assert!(
            ss.anees <= 1.0 + 3.0 * ss.anees_se,
            "{} {:?}: {}",
            s.name,
            s.params,
            ss.anees
        );
    }
    let lossy = run(&text.replace("kind = \"ideal\"", "kind = \"bernoulli\"\nloss = 0.5"));
    let at = |delta: f64| {
        lossy
            .schemes
            .iter()
            .find(|s| {
                matches!(s.params.get("delta"), Some(hushfuse::scenario::ParamValue::Number(d)) if *d == delta)
            })
            .unwrap()
    };
    let d1 = &at(1.0).steady_state;
    assert!(d1.anees > 1.0 + 3.0 * d1.anees_se, "{}", d1.anees);
    let ci = &lossy.schemes.last().unwrap().steady_state;
    assert!(ci.anees <= 1.0 + 3.0 * ci.anees_se, "{}", ci.anees);
}
