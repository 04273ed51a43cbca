//! Multi-hop networks (`[network]`): every hop of a report drawn and paid, the path's delivery
//! the product of its hops', ARQ's attempts as the geometric series says, per-node energy by
//! hand, loss-aware centers consistent under path loss where the loss-unaware one is not, the
//! star unchanged, and every bad network refused with exit 2 and its field.
#[path = "common/cli.rs"]
mod cli;
#[path = "common/scalar.rs"]
mod scalar;
use hushfuse::metrics::results::{SchemeSummary, Summary};
use hushfuse::network::radio::RadioSpec;
use scalar::{scalar_system, summary};

/// `sensors` scalar sensors of x' = 0.95 x + w, `channel` on every hop, `network`, `schemes`.
fn scenario(sensors: usize, channel: &str, network: &str, schemes: &str, trials: usize) -> String {
    scalar_system(
        0.95,
        sensors,
        60,
        &format!("{channel}\n[network]\n{network}\n"),
        schemes,
        trials,
    )
}

const ALL_DATA: &str = "[[schemes]]\nkind = \"centralized-kf\"\n";

/// Sensor s0 three hops from the sink: s0 – r0 – r1 – sink.
const LINE3: &str =
    "relays = 2\nedges = [[\"s0\", \"r0\"], [\"r0\", \"r1\"], [\"r1\", \"sink\"]]\n";

fn node<'a>(s: &'a SchemeSummary, name: &str) -> &'a hushfuse::metrics::network::NodeSummary {
    let net = s.network.as_ref().expect("a network section");
    net.nodes.iter().find(|n| n.name == name).unwrap()
}

fn link_fraction(summary: &Summary, v: usize, key: &str) -> f64 {
    let json = serde_json::to_value(&summary.schemes[v]).unwrap();
    json["link"][key].as_f64().unwrap()
}

#[test]
fn a_path_delivers_with_the_product_of_its_hops() {
    // Per-hop loss 0.2 on three hops: 0.8^3 = 0.512 delivered, every report sent (the all-data
    // KF), 400 trials x 60 steps = 24000 reports, independent (Bernoulli hops).
    let text = scenario(
        1,
        "[channel]\nkind = \"bernoulli\"\nloss = 0.2\n",
        LINE3,
        ALL_DATA,
        400,
    );
    let s = summary(&text);
    let n = 24_000.0;
    let p = 0.8f64.powi(3);
    let delivered = 1.0 - link_fraction(&s, 0, "loss_fraction");
    let se = (p * (1.0 - p) / n).sqrt();
    assert!(
        (delivered - p).abs() < 4.0 * se,
        "delivered {delivered}, expected {p} ± {se}"
    );
    // Each relay forwards what reached it: r0 the 0.8, r1 the 0.64 of the reports.
    let v = &s.schemes[0];
    for (name, expected) in [("r0", 0.8), ("r1", 0.64)] {
        let f = node(v, name).forwarded_per_step;
        let se = (expected * (1.0 - expected) / n).sqrt();
        assert!((f - expected).abs() < 4.0 * se, "{name}: {f} vs {expected}");
    }
    // Every hop is paid: the payload bits on air are 32 per report and per forward.
    let forwards = node(v, "r0").forwarded_per_step + node(v, "r1").forwarded_per_step;
    assert!((v.bits_per_step - 32.0 * (1.0 + forwards)).abs() < 1e-9);
    assert_eq!(
        v.network
            .as_ref()
            .unwrap()
            .first_to_die
            .as_ref()
            .unwrap()
            .node,
        "r0"
    );
}

#[test]
fn arq_attempts_follow_the_geometric_series() {
    // Loss 0.3 per attempt, 2 retries, ideal ACKs: (1 − 0.3^3) / (1 − 0.3) = 1.39 attempts per
    // report at s0 (its own reports only), and r0 tries again only what reached it.
    let text = scenario(
        1,
        "[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 2 }\n",
        LINE3,
        ALL_DATA,
        400,
    );
    let s = summary(&text);
    let v = &s.schemes[0];
    let n = 24_000.0;
    let mean = (1.0 - 0.3f64.powi(3)) / 0.7;
    // Attempts take 1, 2, 3 with probabilities 0.7, 0.21, 0.09.
    let var = 0.7 + 4.0 * 0.21 + 9.0 * 0.09 - mean * mean;
    let se = (var / n).sqrt();
    let a = node(v, "s0").frames_sent_per_step;
    assert!(
        (a - mean).abs() < 4.0 * se,
        "s0 attempts {a}, expected {mean} ± {se}"
    );
    let reach = 1.0 - 0.3f64.powi(3);
    let r0 = node(v, "r0").frames_sent_per_step;
    assert!(
        (r0 - reach * mean).abs()
            < 4.0 * (var / (n * reach)).sqrt() + 4.0 * (reach * (1.0 - reach) / n).sqrt() * mean,
        "r0 attempts {r0}, expected {}",
        reach * mean
    );
    // Each hop delivers 1 − 0.3^3: the path (1 − 0.3^3)^3.
    let p = reach.powi(3);
    let delivered = 1.0 - link_fraction(&s, 0, "loss_fraction");
    assert!((delivered - p).abs() < 4.0 * (p * (1.0 - p) / n).sqrt());
}

#[test]
fn per_node_energy_on_an_ideal_line_by_hand() {
    // s0 → r0 → sink, ideal links, the all-data KF (no feedback): every step s0 sends one
    // 32-bit reading in a 15-octet MAC frame, 21 octets = 168 bits on air with the PHY header.
    let text = scenario(
        1,
        "",
        "relays = 1\nedges = [[\"s0\", \"r0\"], [\"r0\", \"sink\"]]\n",
        ALL_DATA,
        3,
    );
    let s = summary(&text);
    let v = &s.schemes[0];
    let radio = RadioSpec::default();
    // TX: 3 V x 17.4 mA x (672 µs on air + 192 µs turnaround) = 45.1008 µJ.
    let tx = 3.0 * 17.4 * (672.0 + 192.0) / 1000.0;
    assert!((radio.frame_tx_uj(168.0) - tx).abs() < 1e-12);
    // RX: 3 V x 18.8 mA x 672 µs = 37.9008 µJ; a node with one child listens 1000 µs a step.
    let rx = 3.0 * 18.8 * 672.0 / 1000.0;
    let listen = 3.0 * 18.8 * 1000.0 / 1000.0;
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.abs().max(1.0);
    let (s0, r0, sink) = (node(v, "s0"), node(v, "r0"), node(v, "sink"));
    assert!(close(s0.energy_parts_per_step_uj.tx, tx));
    assert_eq!(s0.energy_parts_per_step_uj.relay, 0.0);
    assert!(close(r0.energy_parts_per_step_uj.tx, tx));
    assert!(close(r0.energy_parts_per_step_uj.relay, rx));
    assert!(close(r0.energy_parts_per_step_uj.downlink, listen));
    assert!(close(sink.energy_parts_per_step_uj.relay, rx));
    // Asleep the rest of the 1 s step at 3 V x 0.02 mA.
    let awake_r0 = 864.0 + 672.0 + 1000.0;
    assert!(close(
        r0.energy_parts_per_step_uj.sleep,
        0.06 * (1e6 - awake_r0) / 1000.0
    ));
    // The network's energy leaves the mains-powered sink out; r0 dies first.
    assert!(close(
        v.energy.energy_per_step_uj,
        s0.energy_per_step_uj + r0.energy_per_step_uj
    ));
    assert!(sink.mains && sink.lifetime_days.is_none());
    assert_eq!(v.energy.lifetime_days, r0.lifetime_days);
    assert_eq!(
        (s0.hops, r0.hops, r0.parent.as_deref()),
        (2, 1, Some("sink"))
    );
}

#[test]
fn loss_aware_centers_take_the_path_loss() {
    // Per-hop loss 0.2 on three hops; the loss-aware innovation-triggered KF assumes each
    // sensor's path loss (1 − 0.8^3), the published one reads every loss as a silence.
    let schemes = "[[schemes]]\nkind = \"innovation-trigger-kf\"\ndelta = 1.0\nlabel = \"unaware\"\n\
                   [[schemes]]\nkind = \"innovation-trigger-kf\"\ndelta = 1.0\nlink_loss = \"channel\"\nlabel = \"aware\"\n";
    let net = "relays = 2\nedges = [[\"s0\", \"r0\"], [\"s1\", \"r0\"], [\"r0\", \"r1\"], [\"r1\", \"sink\"]]\n";
    let text = scenario(
        2,
        "[channel]\nkind = \"bernoulli\"\nloss = 0.2\n",
        net,
        schemes,
        200,
    );
    let s = summary(&text);
    let (unaware, aware) = (&s.schemes[0].steady_state, &s.schemes[1].steady_state);
    eprintln!(
        "unaware ANEES {:.3} ± {:.3}, aware {:.3} ± {:.3}",
        unaware.anees, unaware.anees_se, aware.anees, aware.anees_se
    );
    assert!((aware.anees - 1.0).abs() < 4.0 * aware.anees_se);
    assert!(unaware.anees > 1.0 + 4.0 * unaware.anees_se);
}

/// s0, s1 → s2; s2, s3 → r0 → sink.
const TREE: &str = "relays = 1\nedges = [[\"s0\", \"s2\"], [\"s1\", \"s2\"], [\"s2\", \"r0\"], [\"s3\", \"r0\"], [\"r0\", \"sink\"]]\n";

#[test]
fn relays_sum_the_all_data_kf_into_one_frame_per_link() {
    let aggregated = summary(&scenario(4, "", TREE, ALL_DATA, 20));
    let forwarded = summary(&scenario(
        4,
        "",
        &format!("{TREE}aggregate = false\n"),
        ALL_DATA,
        20,
    ));
    let star = summary(&scalar_system(0.95, 4, 60, "", ALL_DATA, 20));
    let (a, f) = (&aggregated.schemes[0], &forwarded.schemes[0]);
    assert!(a.network.as_ref().unwrap().aggregated);
    assert!(!f.network.as_ref().unwrap().aggregated);
    // One frame per link and step: s0, s1, s3 send their readings (32 bits), s2 and r0 sums of
    // y and Y (2 singles, 64 bits) holding 3 and 4 reports.
    for name in ["s0", "s1", "s2", "s3", "r0"] {
        assert_eq!(node(a, name).frames_sent_per_step, 1.0, "{name}");
    }
    assert_eq!(node(a, "r0").frames_received_per_step, 2.0);
    // per_step.csv's hops: 5 frames a step, 2 of them (s2's, r0's) carrying others' reports.
    let (na, nf) = (a.network.as_ref().unwrap(), f.network.as_ref().unwrap());
    assert!(na.frames_per_step.iter().all(|&x| x == 5.0));
    assert!(na.forwards_per_step.iter().all(|&x| x == 2.0));
    assert!(nf.frames_per_step.iter().all(|&x| x == 10.0));
    assert!(nf.forwards_per_step.iter().all(|&x| x == 6.0));
    assert_eq!(node(a, "sink").frames_received_per_step, 1.0);
    assert_eq!(a.bits_per_step, 3.0 * 32.0 + 2.0 * 64.0);
    // Per source: s2 forwards 2 reports, r0 forwards 4; 32 bits per report and per forward.
    assert_eq!(node(f, "r0").frames_sent_per_step, 4.0);
    assert_eq!(node(f, "sink").frames_received_per_step, 4.0);
    assert_eq!(f.bits_per_step, 32.0 * (4.0 + 2.0 + 4.0));
    assert!(a.energy.energy_per_step_uj < f.energy.energy_per_step_uj);
    // The sink's estimate is the all-data KF's: the star's, but for the singles the sums are
    // sent as (relative rounding 2^-24 per hop).
    let rel = |x: f64, y: f64| (x - y).abs() / y.abs();
    let key = star.schemes[0].mean_rmse.keys().next().unwrap().clone();
    let (ra, rs) = (a.mean_rmse[&key], star.schemes[0].mean_rmse[&key]);
    assert!(rel(ra, rs) < 1e-5, "{ra} vs {rs}");
    assert!(rel(a.steady_state.anees, star.schemes[0].steady_state.anees) < 1e-5);
    // Forwarded per source, the sink gets the very readings of the star: the same numbers.
    assert_eq!(f.mean_rmse, star.schemes[0].mean_rmse);
}

#[test]
fn summed_reports_under_loss_stay_consistent() {
    // Per-hop loss 0.2: a frame lost loses its subtree's sum for the step; the all-data KF
    // fuses what arrived, which stays exact (a missing report is no information).
    let text = scenario(
        4,
        "[channel]\nkind = \"bernoulli\"\nloss = 0.2\n",
        TREE,
        ALL_DATA,
        200,
    );
    let s = summary(&text);
    let ss = &s.schemes[0].steady_state;
    assert!(
        (ss.anees - 1.0).abs() < 4.0 * ss.anees_se,
        "ANEES {} ± {}",
        ss.anees,
        ss.anees_se
    );
    // s0's and s1's reports cross three links (delivered 0.8^3), s2's and s3's two (0.8^2):
    // (2 · 0.512 + 2 · 0.64) / 4 = 0.576 on average; 200 × 60 × 4 reports, correlated within a
    // step (one frame carries several), so the bound takes the 12000 steps as the samples.
    let delivered = 1.0 - link_fraction(&s, 0, "loss_fraction");
    let expected = (2.0 * 0.512 + 2.0 * 0.64) / 4.0;
    let se = (0.25 / 12_000.0f64).sqrt();
    assert!(
        (delivered - expected).abs() < 4.0 * se,
        "{delivered} vs {expected}"
    );
}

#[test]
fn a_star_network_is_todays_run() {
    let channel = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 1 }\n";
    let schemes = "[[schemes]]\nkind = \"send-on-delta\"\ndelta = 1.0\n";
    let plain = scalar_system(0.95, 3, 40, channel, schemes, 20);
    let star = scalar_system(
        0.95,
        3,
        40,
        &format!("{channel}\n[network]\nedges = \"star\"\n"),
        schemes,
        20,
    );
    let (a, b) = (summary(&plain), summary(&star));
    assert_eq!(
        serde_json::to_string(&a.schemes).unwrap(),
        serde_json::to_string(&b.schemes).unwrap()
    );
    assert!(a.schemes[0].network.is_none());
}

/// `broadcast_estimate = true` on s0 → r0 → sink, ideal links, the all-data KF of a scalar
/// state: after every step the sink sends its estimate (mean and variance: 2 singles, 64 bits)
/// down the tree in a frame of 136 bits of PHY and MAC overhead, 200 bits = 800 µs on air.
/// Every node holding children sends it once; every node below the sink listens one window
/// for it and receives it. The estimates do not move.
#[test]
fn the_estimate_sent_down_the_tree_by_hand() {
    let line = "relays = 1\nedges = [[\"s0\", \"r0\"], [\"r0\", \"sink\"]]\n";
    let plain = summary(&scenario(1, "", line, ALL_DATA, 3));
    let text = scenario(
        1,
        "",
        &format!("{line}broadcast_estimate = true\n"),
        ALL_DATA,
        3,
    );
    let s = summary(&text);
    let (a, b) = (&plain.schemes[0], &s.schemes[0]);
    assert_eq!(a.rmse, b.rmse);
    assert_eq!(
        (a.downlink_bits_per_step, b.downlink_bits_per_step),
        (0.0, 64.0)
    );
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.abs().max(1.0);
    let (rx_mw, tx_mw) = (3.0 * 18.8, 3.0 * 17.4);
    let down_tx = tx_mw * (800.0 + 192.0) / 1000.0;
    let part = |s: &SchemeSummary, n: &str| node(s, n).energy_parts_per_step_uj;
    // s0: one window for its parent's frame, and the frame.
    assert!(close(
        part(b, "s0").downlink,
        rx_mw * (1000.0 + 800.0) / 1000.0
    ));
    assert!(close(part(b, "s0").relay, 0.0));
    // r0: the window of its child (as before) and its parent's, the frame; it sends it down.
    assert!(close(
        part(b, "r0").downlink,
        rx_mw * (2000.0 + 800.0) / 1000.0
    ));
    assert!(close(part(b, "r0").relay - part(a, "r0").relay, down_tx));
    // The sink sends it (on mains: reported, not in the network's total).
    assert!(close(
        part(b, "sink").relay - part(a, "sink").relay,
        down_tx
    ));
    let sleep = |s: &SchemeSummary| s.energy.energy_parts_per_step_uj.sleep;
    let more = b.energy.energy_per_step_uj - a.energy.energy_per_step_uj;
    let awake_more = (1000.0 + 800.0) + (1000.0 + 800.0 + 992.0);
    assert!(close(sleep(a) - sleep(b), 0.06 * awake_more / 1000.0));
    let expected = rx_mw * 3600.0 / 1000.0 + down_tx - 0.06 * awake_more / 1000.0;
    assert!(close(more, expected), "{more} vs {expected}");
}

/// On a one-hop star the estimate goes down in one broadcast: the star keeps its numbers and
/// every sensor pays the listening and the frame; a network of peers has no sink to send it.
#[test]
fn the_estimate_sent_down_a_star_and_refused_without_a_sink() {
    let schemes = "[[schemes]]\nkind = \"send-on-delta\"\ndelta = 1.0\n";
    let plain = summary(&scalar_system(0.95, 3, 40, "", schemes, 20));
    let net = "[network]\nedges = \"star\"\nbroadcast_estimate = true\n";
    let star = summary(&scalar_system(0.95, 3, 40, net, schemes, 20));
    let (a, b) = (&plain.schemes[0], &star.schemes[0]);
    assert_eq!((a.rmse.clone(), a.rate), (b.rmse.clone(), b.rate));
    let rx_mw = 3.0 * 18.8;
    for i in 0..3 {
        let got = node(b, &format!("s{i}")).energy_parts_per_step_uj.downlink;
        assert!((got - rx_mw * 1.8).abs() < 1e-9, "s{i}: {got}");
    }
    let peers = "[network]\nsink = false\nedges = \"ring\"\nbroadcast_estimate = true\n";
    let kf = "[[schemes]]\nkind = \"peer-ci\"\n";
    let (code, err) = run_cli(&scalar_system(0.95, 3, 40, peers, kf, 2));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("network.broadcast_estimate"), "{err}");
    assert!(err.contains("needs a sink"), "{err}");
}

/// Runs `text` through the command line: (exit code, stderr).
fn run_cli(text: &str) -> (Option<i32>, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("net.toml");
    std::fs::write(&path, text).unwrap();
    let out = cli::hushfuse(&["run", path.to_str().unwrap()], dir.path());
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_networks_exit_2_naming_field_and_nodes() {
    let cases: [(&str, &str, &[&str]); 8] = [
        (
            "relays = 1\nedges = \"line\"\n[[network.links]]\nbetween = [\"r0\", \"sink\"]\nchannel = { kind = \"bernoulli\", loss = 0.1, delay = 1 }\n",
            "",
            &["network.aggregate", "r0", "sink", "aggregate = false"],
        ),
        (
            LINE3,
            "[[schemes]]\nkind = \"centralized-kf\"\nsequence_bits = 4\n",
            &["network.aggregate", "sequence_bits"],
        ),
        (
            "relays = 2\nedges = [[\"s0\", \"sink\"], [\"r0\", \"r1\"]]\n",
            "",
            &["network.edges", "r0", "r1"],
        ),
        (
            "edges = [[\"s0\", \"s0\"], [\"s0\", \"sink\"]]\n",
            "",
            &["network.edges", "s0"],
        ),
        ("edges = [[\"s0\", \"x9\"]]\n", "", &["network.edges", "x9"]),
        (
            "edges = \"radius\"\nrange = -1.0\nsink = [0.0, 0.0]\n",
            "",
            &["network.range"],
        ),
        (
            "relays = 1\nedges = [[\"s0\", \"r0\"], [\"r0\", \"sink\"], [\"s0\", \"sink\"]]\nparent = { s0 = \"r0\", r0 = \"s0\" }\n",
            "",
            &["network.parent", "r0", "s0"],
        ),
        (
            LINE3,
            "[[schemes]]\nkind = \"centralized-kf\"\nchannel = { kind = \"bernoulli\", loss = 0.1 }\n",
            &["network", "own channel"],
        ),
    ];
    for (net, schemes, words) in cases {
        let schemes = if schemes.is_empty() {
            ALL_DATA
        } else {
            schemes
        };
        let (code, err) = run_cli(&scenario(1, "", net, schemes, 2));
        assert_eq!(code, Some(2), "{net}: {err}");
        for w in words {
            assert!(err.contains(w), "{net}: {w:?} not in {err}");
        }
    }
}

#[test]
fn a_mesh_run_is_the_same_on_one_thread_or_two() {
    use hushfuse::engine::runner;
    use hushfuse::metrics::results;
    use hushfuse::scenario::{build, builtin};
    for name in ["mesh-line", "mesh-grid"] {
        let opts = build::LoadOptions {
            trials: Some(3),
            ..Default::default()
        };
        let exp = build::load_with(builtin::get(name).unwrap(), name, &opts).unwrap();
        let json = |threads| {
            let sums = runner::run(&exp, runner::RunOptions { threads }, &|_| {}).unwrap();
            serde_json::to_string(&results::summarize(&exp, &sums).schemes).unwrap()
        };
        let one = json(1);
        assert!(one.contains("first_to_die"), "{name}");
        assert_eq!(one, json(2), "{name}");
    }
}

#[test]
fn live_runs_refuse_a_multi_hop_network() {
    let dir = tempfile::tempdir().unwrap();
    let out = cli::hushfuse(&["live", "mesh-line", "--out", "live"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("multi-hop [network]"), "{err}");
}
