//! `[security]` in the simulation (issue 41): every data frame and the step's feedback frame grow
//! by the auxiliary security header and the MIC, priced in frame bits, feedback bits and energy
//! by hand, on the star and per hop and per node on a graph; payload bits and estimates do not
//! move; what cannot be priced is refused.
use hushfuse::metrics::results;
use hushfuse::scenario::build;
#[path = "common/scalar.rs"]
mod scalar;
use scalar::{scalar_system, summary};

const KF: &str = "[[schemes]]\nkind = \"centralized-kf\"\n";
const CLOSED: &str = "[[schemes]]\nkind = \"stochastic-trigger-closed\"\ntau = 1.0\n";

fn run(extra: &str, schemes: &str) -> results::Summary {
    summary(&scalar_system(0.95, 2, 10, extra, schemes, 3))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

/// By hand, at `mic-32` with a key index (the default key identifier mode): each sensor's frame
/// of one 32-bit reading, 15 octets unsecured, gains the auxiliary security header (security
/// control 1 + frame counter 4 + key index 1) and a 4-octet MIC: 25 octets, 200 frame bits.
/// On air 31 octets = 248 bits = 992 µs at 250 kb/s; with the 192 µs turnaround 1184 µs at
/// 52.2 mW = 61.8048 µJ a frame, 123.6096 µJ a step for the two sensors (unsecured: 90.2016).
/// Asleep 2 s − 2 × 1184 µs = 1 997 632 µs at 0.06 mW = 119.85792 µJ.
#[test]
fn mic_32_by_hand() {
    let s = run("[security]\nlevel = \"mic-32\"\n", KF);
    let (sch, plain) = (&s.schemes[0], &run("", KF).schemes[0]);
    assert_eq!(sch.frame_bits_per_step, 2.0 * 200.0);
    let e = &sch.energy.energy_parts_per_step_uj;
    assert!(close(e.tx, 123.6096), "{e:?}");
    assert!(close(e.sleep, 119.85792), "{e:?}");
    // Security adds no information: the payload bits and every estimate are the same.
    assert_eq!(sch.bits_per_step, plain.bits_per_step);
    assert_eq!(sch.mse, plain.mse);
    assert_eq!(sch.anees, plain.anees);
    let json = hushfuse::metrics::summary_json(&s).unwrap();
    assert_eq!(json["security"]["level"], "mic-32");
    let unsecured = hushfuse::metrics::summary_json(&run("", KF)).unwrap();
    assert!(unsecured.get("security").is_none());
}

/// Every level and key identifier mode: a frame grows by 5 + (0, 1, 5, 9) octets of auxiliary
/// header and (4, 8, 16) of MIC, and its TX energy by that many bits of airtime at 52.2 mW
/// (4 µs a bit); `none` is the unsecured run exactly.
#[test]
fn every_level_costs_its_octets_in_frame_bits_and_energy() {
    let plain = run("", KF);
    let p = &plain.schemes[0];
    for (level, mic) in [
        ("mic-32", 4),
        ("mic-64", 8),
        ("mic-128", 16),
        ("enc-mic-32", 4),
        ("enc-mic-64", 8),
        ("enc-mic-128", 16),
    ] {
        for (mode, key_id) in [
            ("implicit", 0),
            ("index", 1),
            ("source4", 5),
            ("source8", 9),
        ] {
            let extra = format!("[security]\nlevel = \"{level}\"\nkey_id_mode = \"{mode}\"\n");
            let s = run(&extra, KF);
            let sch = &s.schemes[0];
            let octets = (5 + key_id + mic) as f64;
            assert_eq!(
                sch.frame_bits_per_step,
                p.frame_bits_per_step + 2.0 * 8.0 * octets,
                "{level} {mode}"
            );
            let more_tx = 2.0 * 8.0 * octets * 4.0 * 52.2 / 1000.0;
            let got = sch.energy.energy_parts_per_step_uj.tx - p.energy.energy_parts_per_step_uj.tx;
            assert!(close(got, more_tx), "{level} {mode}: {got} vs {more_tx}");
        }
    }
    let none = run("[security]\nlevel = \"none\"\n", KF);
    assert_eq!(
        hushfuse::metrics::summary_json(&none).unwrap(),
        hushfuse::metrics::summary_json(&plain).unwrap()
    );
}

/// The step's feedback frame is secured by default (each listening sensor receives its
/// auxiliary header and MIC) and not with `secure_feedback = false`; a retransmitted frame pays
/// for every attempt, an ACK nothing more.
#[test]
fn feedback_and_retransmissions_pay_for_their_security() {
    let plain = run("", CLOSED);
    let secured = run("[security]\nlevel = \"mic-64\"\n", CLOSED);
    let open_feedback = run(
        "[security]\nlevel = \"mic-64\"\nsecure_feedback = false\n",
        CLOSED,
    );
    let overhead = 8.0 * (6.0 + 8.0);
    let (p, s, o) = (
        &plain.schemes[0],
        &secured.schemes[0],
        &open_feedback.schemes[0],
    );
    assert!(p.downlink_bits_per_step > 0.0);
    assert_eq!(
        s.downlink_bits_per_step,
        p.downlink_bits_per_step + overhead
    );
    assert_eq!(o.downlink_bits_per_step, p.downlink_bits_per_step);
    // Two listeners each receive the 112 more bits: 2 × 112 × 4 µs at 56.4 mW.
    let more =
        s.energy.energy_parts_per_step_uj.downlink - p.energy.energy_parts_per_step_uj.downlink;
    assert!(close(more, 2.0 * overhead * 4.0 * 56.4 / 1000.0), "{more}");
    assert_eq!(s.mse, p.mse);

    let arq = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 2 }\n";
    let plain = run(arq, KF);
    let secured = run(&format!("{arq}[security]\nlevel = \"mic-32\"\n"), KF);
    let (p, s) = (&plain.schemes[0], &secured.schemes[0]);
    let attempts = p.transmissions_per_step + p.link.as_ref().unwrap().retransmissions;
    assert!(close(
        s.frame_bits_per_step,
        p.frame_bits_per_step + attempts * 8.0 * 10.0
    ));
    let ack = |x: &results::SchemeSummary| x.energy.energy_parts_per_step_uj.ack;
    assert_eq!(ack(s), ack(p));
}

/// What cannot be priced is refused naming `security.level`: a secured frame that no longer
/// fits 127 octets; `enc` (level 4) and unknown names are refused with the reason.
#[test]
fn what_security_cannot_price_is_refused() {
    let err = |extra: &str, schemes: &str| {
        let text = scalar_system(0.95, 2, 10, extra, schemes, 3);
        build::load(&text, "scalar.toml").unwrap_err()
    };
    let e = err("[security]\nlevel = \"enc\"\n", KF);
    assert!(e.to_string().contains("authenticates nothing"), "{e}");
    let e = err("[security]\nlevel = \"mic-16\"\n", KF);
    assert!(e.to_string().contains("mic-32"), "{e}");
    // 29 readings of one sensor: 116 octets fill an unsecured frame, not a secured one.
    let big = format!(
        r#"
name = "big"
trials = 1
steps = 2
seed = 1
[model]
kind = "matrix"
F = [[1.0]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
H = [{}]
R = [{}]
[security]
level = "mic-32"
{KF}"#,
        vec!["[1.0]"; 29].join(", "),
        (0..29)
            .map(|i| {
                let row: Vec<&str> = (0..29)
                    .map(|j| if i == j { "1.0" } else { "0.0" })
                    .collect();
                format!("[{}]", row.join(", "))
            })
            .collect::<Vec<_>>()
            .join(", ")
    );
    let e = build::load(&big, "big.toml").unwrap_err();
    assert_eq!(e.field, "security.level", "{e}");
    assert!(e.to_string().contains("at most 106 octets"), "{e}");
}

fn graph(network: &str, schemes: &str, security: &str, sensors: usize) -> results::Summary {
    let extra = format!("[network]\n{network}\n{security}");
    summary(&scalar_system(0.95, sensors, 10, &extra, schemes, 3))
}

fn node<'a>(
    s: &'a results::SchemeSummary,
    name: &str,
) -> &'a hushfuse::metrics::network::NodeSummary {
    let net = s.network.as_ref().expect("a network section");
    net.nodes.iter().find(|n| n.name == name).unwrap()
}

/// On the line s0 – r0 – sink at `mic-32` (80 more bits a frame), by hand: s0 and r0 each send
/// a 15-octet frame a step, now 31 octets on air = 992 µs, + 192 µs turnaround at 52.2 mW =
/// 61.8048 µJ; r0 and the sink receive it, 992 µs at 56.4 mW = 55.9488 µJ. With the estimate
/// sent back down the tree its frame grows by the same 80 bits at every receiver.
#[test]
fn every_hop_pays_for_security_on_a_graph() {
    let line = "relays = 1\nedges = [[\"s0\", \"r0\"], [\"r0\", \"sink\"]]\n";
    let secured = "[security]\nlevel = \"mic-32\"\n";
    let s = graph(line, KF, secured, 1);
    let v = &s.schemes[0];
    let part = |n: &str| node(v, n).energy_parts_per_step_uj;
    assert!(close(part("s0").tx, 61.8048), "{:?}", part("s0"));
    assert!(close(part("r0").tx, 61.8048), "{:?}", part("r0"));
    assert!(close(part("r0").relay, 55.9488), "{:?}", part("r0"));
    assert!(close(part("sink").relay, 55.9488), "{:?}", part("sink"));
    // Frame bits count every hop: two 25-octet frames a step (two 15-octet ones unsecured).
    let plain = graph(line, KF, "", 1);
    assert_eq!(plain.schemes[0].frame_bits_per_step, 240.0);
    assert_eq!(v.frame_bits_per_step, 400.0);
    assert_eq!(v.mse, plain.schemes[0].mse);

    let back = format!("{line}broadcast_estimate = true\n");
    let (a, b) = (graph(&back, KF, "", 1), graph(&back, KF, secured, 1));
    let down = |s: &results::Summary| node(&s.schemes[0], "s0").energy_parts_per_step_uj.downlink;
    assert!(close(down(&b) - down(&a), 80.0 * 4.0 * 56.4 / 1000.0));
    let open = graph(
        &back,
        KF,
        "[security]\nlevel = \"mic-32\"\nsecure_feedback = false\n",
        1,
    );
    assert!(close(down(&open), down(&a)));
}

/// Consensus on information on a ring of three peers at `mic-64` (112 more bits a frame): each
/// of the L = 2 broadcasts a step costs its sender 112 × 4 µs more at 52.2 mW and each of its
/// two neighbours 112 × 4 µs more at 56.4 mW; the estimates do not move.
#[test]
fn consensus_broadcasts_pay_for_security_per_edge() {
    let ring = "sink = false\nedges = \"ring\"\n";
    let ci = "[[schemes]]\nkind = \"consensus-information\"\nL = 2\n";
    let plain = graph(ring, ci, "", 3);
    let secured = graph(ring, ci, "[security]\nlevel = \"mic-64\"\n", 3);
    let (p, s) = (&plain.schemes[0], &secured.schemes[0]);
    assert_eq!(p.mse, s.mse);
    for name in ["s0", "s1", "s2"] {
        let (a, b) = (
            node(p, name).energy_parts_per_step_uj,
            node(s, name).energy_parts_per_step_uj,
        );
        assert!(
            close(b.tx - a.tx, 2.0 * 112.0 * 4.0 * 52.2 / 1000.0),
            "{name}: {a:?} {b:?}"
        );
        assert!(
            close(b.relay - a.relay, 2.0 * 2.0 * 112.0 * 4.0 * 56.4 / 1000.0),
            "{name}: {a:?} {b:?}"
        );
    }
}
