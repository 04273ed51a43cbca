use super::cost::{expected_attempts, hop, per_report};
use super::spec::NetworkSpec;
use super::*;
use crate::network::radio::RadioSpec;

fn spec(text: &str) -> NetworkSpec {
    toml::from_str(text).unwrap_or_else(|e| panic!("{text}: {e}"))
}

fn channel(text: &str) -> ChannelSpec {
    toml::from_str(text).unwrap()
}

fn build(text: &str, sensors: &[Option<[f64; 2]>]) -> Result<Topology, TopologyError> {
    Topology::build(&spec(text), sensors, None)
}

fn error(text: &str, sensors: usize) -> String {
    build(text, &vec![None; sensors]).unwrap_err().to_string()
}

#[test]
fn without_a_table_it_is_the_star() {
    let t = build("", &[None, None, None]).unwrap();
    assert!(t.is_star());
    assert_eq!(t.nodes.len(), 4);
    assert_eq!(t.nodes[3].name, "sink");
    assert_eq!(t.parent, vec![Some(3), Some(3), Some(3), None]);
    assert!(t.sink_mains);
    assert!(build("edges = \"star\"", &[None]).unwrap().is_star());
}

#[test]
fn a_line_routes_through_every_node_in_order() {
    let t = build("relays = 2\nedges = \"line\"", &[None, None]).unwrap();
    // s0 – s1 – r0 – r1 – sink
    assert_eq!(t.route(0), vec![0, 1, 2, 3, 4]);
    assert_eq!(t.hops(1), 3);
    assert!(!t.is_star());
    let names: Vec<&str> = t.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["s0", "s1", "r0", "r1", "sink"]);
}

/// Three hops at loss 0.2 each: the report arrives with probability 0.8³.
#[test]
fn the_path_loss_is_one_minus_the_product_of_the_hops_deliveries() {
    let t = Topology::build(
        &spec("relays = 2\nedges = \"line\""),
        &[None],
        Some(&channel("kind = \"bernoulli\"\nloss = 0.2")),
    )
    .unwrap();
    assert!((t.path_loss(0) - (1.0 - 0.8f64.powi(3))).abs() < 1e-15);
    assert!((t.path_loss(2) - 0.2).abs() < 1e-15);
    // With 3 retries per hop each hop loses 0.2⁴.
    let arq = Topology::build(
        &spec("relays = 2\nedges = \"line\""),
        &[None],
        Some(&channel(
            "kind = \"bernoulli\"\nloss = 0.2\narq = { max_retries = 3 }",
        )),
    )
    .unwrap();
    let hop = 1.0 - 0.2f64.powi(4);
    assert!((arq.path_loss(0) - (1.0 - hop.powi(3))).abs() < 1e-15);
}

/// By hand, with the CC2420 defaults (3.0 V; TX 17.4 mA = 52.2 mW, RX 18.8 mA = 56.4 mW; 4 µs a
/// bit; turnaround 192 µs; ACK 88 bits = 352 µs; ACK wait 864 µs): a 25-octet MAC frame is 31
/// octets = 248 bits = 992 µs on air.
/// - send: 52.2 mW × (992 + 192) µs = 61.8048 µJ; hear the ACK: 56.4 × (192 + 352) = 30.6816;
///   wait for an ACK that does not come: 56.4 × 864 = 48.7296;
/// - receive: 56.4 × 992 = 55.9488; send the ACK: 52.2 × (192 + 352) = 28.3968.
///
/// Sensor → relay → sink, no loss: the sensor 92.4864, the relay 84.3456 + 92.4864 = 176.832,
/// the sink 84.3456. With loss 0.5 and one retry on the sensor's hop: 1.5 attempts, delivered
/// 0.75: the sensor 1.5 × 61.8048 + 0.75 × 30.6816 + 0.75 × 48.7296 = 152.2656, the relay
/// receives 0.75 × 84.3456 = 63.2592 and forwards 0.75 × 92.4864 = 69.3648.
#[test]
fn hop_energy_by_hand_on_a_three_node_line() {
    let radio = RadioSpec::default();
    let bits = 8.0 * (25.0 + 6.0);
    let ideal = channel("kind = \"ideal\"\narq = { max_retries = 3 }");
    let c = hop(&radio, bits, &ideal);
    assert!((c.sender_uj - 92.4864).abs() < 1e-9, "{c:?}");
    assert!((c.receiver_uj - 84.3456).abs() < 1e-9, "{c:?}");
    let t = Topology::build(&spec("relays = 1\nedges = \"line\""), &[None], Some(&ideal)).unwrap();
    let e = per_report(&t, &radio, bits);
    for (got, want) in e.iter().zip([92.4864, 176.832, 84.3456]) {
        assert!((got - want).abs() < 1e-9, "{e:?}");
    }
    let lossy = spec(
        "relays = 1\nedges = \"line\"\n[[links]]\nbetween = [\"s0\", \"r0\"]\nchannel = { kind = \"bernoulli\", loss = 0.5, arq = { max_retries = 1 } }",
    );
    let t = Topology::build(&lossy, &[None], Some(&ideal)).unwrap();
    let e = per_report(&t, &radio, bits);
    let want = [152.2656, 63.2592 + 69.3648, 0.75 * 84.3456];
    for (got, want) in e.iter().zip(want) {
        assert!((got - want).abs() < 1e-9, "{e:?}");
    }
}

#[test]
fn arq_attempts_are_the_geometric_sum() {
    for (p, r) in [(0.2, 3), (0.5, 1), (0.0, 7), (0.9, 0)] {
        let closed = (1.0 - f64::powi(p, r as i32 + 1)) / (1.0 - p);
        assert!((expected_attempts(p, r) - closed).abs() < 1e-12);
    }
    // The notes' figure: 1.248 at p = 0.2, r = 3.
    assert!((expected_attempts(0.2, 3) - 1.248).abs() < 1e-12);
}

/// A lossy direct link (0.8) and a clean detour through a relay: by hops the report goes
/// straight, by expected transmissions (5 against 2) around.
#[test]
fn etx_routes_around_a_bad_link_where_hops_do_not() {
    let text = |rule: &str| {
        format!(
            "relays = 1\nroutes = \"{rule}\"\nedges = [[\"s0\", \"sink\"], [\"s0\", \"r0\"], [\"r0\", \"sink\"]]\n[[links]]\nbetween = [\"sink\", \"s0\"]\nchannel = {{ kind = \"bernoulli\", loss = 0.8 }}"
        )
    };
    let by_hops = build(&text("hops"), &[None]).unwrap();
    assert_eq!(by_hops.route(0), vec![0, 2]);
    let by_etx = build(&text("etx"), &[None]).unwrap();
    assert_eq!(by_etx.route(0), vec![0, 1, 2]);
}

#[test]
fn geometric_rules_link_by_distance() {
    let sensors = [Some([0.0, 0.0]), Some([10.0, 0.0]), Some([20.0, 0.0])];
    let t = build(
        "sink = [30.0, 0.0]\nedges = \"radius\"\nrange = 10.5",
        &sensors,
    )
    .unwrap();
    assert_eq!(t.links.len(), 3);
    assert_eq!(t.route(0), vec![0, 1, 2, 3]);
    // A 2 x 2 lattice: 4-neighbours only (no diagonals).
    let grid = build(
        "relays = [[0.0, 5.0]]\nsink = [5.0, 5.0]\nedges = \"grid\"",
        &[Some([0.0, 0.0]), Some([5.0, 0.0])],
    )
    .unwrap();
    assert_eq!(grid.links.len(), 4);
    assert_eq!(grid.hops(0), 2);
}

#[test]
fn given_parents_are_the_routes() {
    let t = build(
        "relays = 1\nedges = \"complete\"\nparent = { s0 = \"r0\", s1 = \"sink\", r0 = \"s1\" }",
        &[None, None],
    )
    .unwrap();
    assert_eq!(t.route(0), vec![0, 2, 1, 3]);
}

/// Every bad topology: a message naming the field and the nodes.
#[test]
fn bad_topologies_are_named() {
    let cases: &[(&str, usize, &[&str])] = &[
        (
            "relays = 1\nedges = [[\"s0\", \"sink\"]]",
            1,
            &["network.edges", "disconnected", "r0"],
        ),
        (
            "edges = [[\"s0\", \"s0\"], [\"s0\", \"sink\"]]",
            1,
            &["network.edges[0]", "s0 is linked to itself"],
        ),
        (
            "edges = [[\"s0\", \"sink\"], [\"sink\", \"s0\"]]",
            1,
            &["network.edges[1]", "sink – s0 is given twice"],
        ),
        (
            "edges = [[\"s0\", \"r7\"]]",
            1,
            &["network.edges[0]", "unknown node \"r7\""],
        ),
        (
            "relays = 2\nedges = \"complete\"\nparent = { s0 = \"r0\", r0 = \"r1\", r1 = \"r0\" }",
            1,
            &["network.parent", "r0 → r1 → r0 is a cycle"],
        ),
        (
            "relays = 1\nedges = \"line\"\nparent = { s0 = \"sink\", r0 = \"sink\" }",
            1,
            &["network.parent.s0", "s0 and sink are not linked"],
        ),
        (
            "relays = 1\nedges = \"line\"\nparent = { s0 = \"r0\" }",
            1,
            &["network.parent", "missing: r0"],
        ),
        (
            "edges = \"radius\"\nrange = -1.0",
            1,
            &["network.range", "positive"],
        ),
        ("edges = \"radius\"", 1, &["network.range", "needs a range"]),
        ("range = 3.0", 1, &["network.range", "only for edges = \"radius\""]),
        (
            "edges = \"radius\"\nrange = 3.0",
            2,
            &["network.edges", "needs every node's position", "s0, s1, sink"],
        ),
        (
            "sink = [nan, 0.0]",
            1,
            &["network.sink", "finite"],
        ),
        (
            "relays = [[0.0, inf]]",
            1,
            &["network.relays[0]", "finite"],
        ),
        (
            "relays = 5000",
            1,
            &["network.relays", "at most 4096 nodes"],
        ),
        (
            "relays = 1\n[[links]]\nbetween = [\"s0\", \"r0\"]\nchannel = { kind = \"ideal\" }",
            1,
            &["network.links[0].between", "s0 and r0 are not linked"],
        ),
        (
            "[[links]]\nbetween = [\"s0\", \"sink\"]\nchannel = { kind = \"bernoulli\", loss = 1.5 }",
            1,
            &["network.links[0].channel"],
        ),
    ];
    for (text, sensors, want) in cases {
        let e = error(text, *sensors);
        for w in *want {
            assert!(e.contains(w), "{text}:\n  {e}\n  lacks {w:?}");
        }
    }
}

#[test]
fn distance_sets_each_links_loss_and_etx_routes_around_a_weak_link() {
    // s0 at 0, r0 at 60 m, sink at 120 m: two 60 m hops (PRR ≈ 1) against one 120 m hop
    // (PRR 0.188, loss 0.81): ETX goes through r0, hops straight to the sink.
    let text = |routes: &str| {
        format!(
            "relays = [[60.0, 0.0]]\nsink = [120.0, 0.0]\nedges = \"complete\"\nroutes = \"{routes}\"\n[distance_loss]\n"
        )
    };
    let sensors = [Some([0.0, 0.0])];
    let etx = build(&text("etx"), &sensors).unwrap();
    assert_eq!(etx.route(0), vec![0, 1, 2]);
    let direct = etx.link(0, 2).unwrap();
    let expected = 1.0 - etx_model().prr(120.0, 0.0);
    assert_eq!(direct.channel.kind.name(), "bernoulli");
    assert!((direct.channel.key("loss").unwrap() - expected).abs() < 1e-15);
    assert!((expected - (1.0 - 0.188_425_861_181)).abs() < 1e-9);
    assert!(etx.link(0, 1).unwrap().channel.key("loss").unwrap() < 1e-6);
    let hops = build(&text("hops"), &sensors).unwrap();
    assert_eq!(hops.route(0), vec![0, 2]);
    // A link given its own channel keeps it; shadowing moves losses, from its own seed.
    let own = build(
        &format!("{}[[links]]\nbetween = [\"s0\", \"sink\"]\nchannel = {{ kind = \"bernoulli\", loss = 0.5 }}\n", text("hops")),
        &sensors,
    )
    .unwrap();
    assert_eq!(own.link(0, 2).unwrap().channel.key("loss"), Some(0.5));
    let shadowed = |seed: u64| {
        build(
            &format!("{}shadowing_db = 4.0\nseed = {seed}\n", text("hops")),
            &sensors,
        )
        .unwrap()
        .link(0, 2)
        .unwrap()
        .channel
        .key("loss")
        .unwrap()
    };
    assert_eq!(shadowed(1), shadowed(1));
    assert_ne!(shadowed(1), shadowed(2));
    // Positions are needed; a Gilbert–Elliott channel is refused; numbers are checked.
    let e = build("edges = \"line\"\n[distance_loss]\n", &[None])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("network.distance_loss") && e.contains("s0"),
        "{e}"
    );
    let ge = channel("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.5\n");
    let e = Topology::build(&spec(&text("hops")), &sensors, Some(&ge)).unwrap_err();
    assert!(e.to_string().contains("gilbert-elliott"), "{e}");
    let e = build(&format!("{}exponent = -1.0\n", text("hops")), &sensors).unwrap_err();
    assert!(
        e.to_string().contains("network.distance_loss.exponent"),
        "{e}"
    );
}

fn etx_model() -> super::distance::DistanceLoss {
    toml::from_str("").unwrap()
}

#[test]
fn random_relays_are_placed_by_their_own_seed_inside_the_area() {
    let text = |seed: u64| {
        format!("relays = {{ count = 20, area = [[100.0, 0.0], [0.0, 50.0]], seed = {seed} }}\nedges = \"complete\"\n")
    };
    let a = build(&text(3), &[None]).unwrap();
    let relays: Vec<[f64; 2]> = a.nodes[1..21].iter().map(|n| n.position.unwrap()).collect();
    assert!(relays
        .iter()
        .all(|p| (0.0..=100.0).contains(&p[0]) && (0.0..=50.0).contains(&p[1])));
    let again = build(&text(3), &[None]).unwrap();
    assert_eq!(a.nodes, again.nodes);
    assert_ne!(a.nodes, build(&text(4), &[None]).unwrap().nodes);
    assert_eq!(a.nodes[5].name, "r4");
    let e = error(
        "relays = { count = 2, area = [[0.0, 0.0]] }\nedges = \"complete\"\n",
        1,
    );
    assert!(e.contains("network.relays.area"), "{e}");
}
