//! Loss-aware fusion under a lossy link: the event-triggered Kalman filters (Wu et al.'s
//! innovation trigger, Han et al.'s stochastic triggers, send-on-delta) and Zheng et al.'s
//! censored particle filter read "nothing arrived" as a silence or a loss (`link_loss`) and
//! stay consistent where the published centers, which read every lost packet as a silence,
//! are overconfident; with `link_loss` absent or 0 the published numbers are unchanged, bit
//! for bit; and the exact Tobit particle filter and the federated Tobit KF (round-robin, zero-
//! order hold: a scheduled sensor always sends) take a lost reading as no information.
use hushfuse::engine::runner;
use hushfuse::engine::seeding::{coin_stream, coins};
use hushfuse::engine::trace::{self, Link};
use hushfuse::link::{Message, Received, Transmission};
use hushfuse::metrics::results;
use hushfuse::scenario::build;
#[path = "common/scalar.rs"]
mod scalar;
use scalar::{scalar_system, summary};

/// A stable scalar state x' = 0.95 x + w (q = 1) seen by two sensors y = x + v (r = 1).
fn scalar(channel: &str, schemes: &str, trials: usize) -> String {
    scalar_system(0.95, 2, 60, channel, schemes, trials)
}

const LOSSY: &str = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\n";

/// A scheme table of `kind` with its knob, `extra` keys and a label.
fn scheme(kind: &str, knob: &str, extra: &str, label: &str) -> String {
    format!("[[schemes]]\nkind = \"{kind}\"\n{knob}\n{extra}label = \"{label}\"\n")
}

/// The event-triggered kinds with their knob (send rates at loss 0.3: 0.34, 0.70, 0.48, 0.58).
const KINDS: [(&str, &str); 4] = [
    ("innovation-trigger-kf", "delta = 1.0"),
    ("stochastic-trigger-open", "tau = 1.0"),
    ("stochastic-trigger-closed", "tau = 1.0"),
    ("send-on-delta", "delta = 1.0"),
];

/// `(ANEES, SE, coverage of the 95% NEES interval, SE)` of a scheme's summary, printed.
fn consistency(s: &results::SchemeSummary) -> (f64, f64, f64, f64) {
    let ss = &s.steady_state;
    eprintln!(
        "{:28} ANEES {:.3} ± {:.3}, 95% coverage {:.3} ± {:.3}, steady-state MSE {:.3}",
        s.name, ss.anees, ss.anees_se, s.nees_coverage_95, s.nees_coverage_95_se, ss.mse
    );
    (
        ss.anees,
        ss.anees_se,
        s.nees_coverage_95,
        s.nees_coverage_95_se,
    )
}

/// Consistent: ANEES within 4 SE of 1 and the 95% coverage within 4 SE of 0.95.
fn assert_consistent(s: &results::SchemeSummary) {
    let (anees, se, cov, cov_se) = consistency(s);
    assert!(
        (anees - 1.0).abs() < 4.0 * se,
        "{}: ANEES {anees} ± {se}",
        s.name
    );
    assert!(
        (cov - 0.95).abs() < 4.0 * cov_se,
        "{}: coverage {cov} ± {cov_se}",
        s.name
    );
}

/// Overconfident: ANEES above 1 by more than 4 SE and the 95% coverage below 0.95 by more than
/// 4 SE.
fn assert_overconfident(s: &results::SchemeSummary) {
    let (anees, se, cov, cov_se) = consistency(s);
    assert!(anees > 1.0 + 4.0 * se, "{}: ANEES {anees} ± {se}", s.name);
    assert!(
        cov < 0.95 - 4.0 * cov_se,
        "{}: coverage {cov} ± {cov_se}",
        s.name
    );
}

/// Bernoulli loss 0.3, 400 trials of 60 steps (steady state from the scenario's default), the
/// published center and the loss-aware one (`link_loss = 0.3`) of every event-triggered kind.
/// The standard errors are those of the per-trial means over the 400 trials: ANEES SE 0.015 to
/// 0.10, coverage SE 0.002. `cargo test --release --test channel_loss_aware -- --nocapture`
/// prints the figures. Seen (published / loss-aware ANEES; 95% coverage):
/// innovation trigger 1.45 ± 0.02 / 0.99 ± 0.02 (0.899 / 0.950); stochastic open loop
/// 2.70 ± 0.10 / 0.99 ± 0.02 (0.817 / 0.948); closed loop 1.44 ± 0.03 / 1.00 ± 0.02 (0.898 /
/// 0.948); send-on-delta 2.41 ± 0.07 / 1.01 ± 0.02 (0.823 / 0.946). A loss-aware center told
/// `link_loss = 0` is the published one, bit for bit (below), so it fails like it.
#[test]
fn the_loss_aware_event_triggered_centers_are_consistent_where_the_published_ones_are_not() {
    let mut schemes = String::new();
    for (kind, knob) in KINDS {
        schemes += &scheme(kind, knob, "", &format!("{kind} published"));
        schemes += &scheme(kind, knob, "link_loss = 0.3\n", &format!("{kind} aware"));
    }
    let s = summary(&scalar(LOSSY, &schemes, 400));
    for pair in s.schemes.chunks(2) {
        assert_overconfident(&pair[0]);
        assert_consistent(&pair[1]);
    }
}

/// Zheng et al.'s CFwMD center at loss 0.3 (the channel test has 0.5): the published
/// likelihood fails the 95% NEES coverage test, the loss-aware one passes it. 200 trials,
/// coverage SE about 0.003.
#[test]
fn the_loss_aware_censored_pf_passes_the_coverage_test_at_loss_0_3() {
    let pf = |link_loss: f64| {
        scheme(
            "censored-pf",
            "l = 1.0\nparticles = 400",
            &format!("link_loss = {link_loss}\n"),
            &format!("censored-pf p{link_loss}"),
        )
    };
    let s = summary(&scalar(LOSSY, &(pf(0.0) + &pf(0.3)), 200));
    assert_overconfident(&s.schemes[0]);
    assert_consistent(&s.schemes[1]);
}

/// `link_loss` absent and `link_loss = 0` give the same numbers, bit for bit (0 runs the
/// published code), on an ideal link and on a lossy one; so does `link_loss = 0.3` with
/// send-on-delta's silences ignored (a loss does not change how they are read). Two runs with
/// the variants in the same places, so each meets the same coins; the published runs
/// themselves are pinned by the golden tests.
#[test]
fn link_loss_absent_or_zero_is_the_published_center_bit_for_bit() {
    let ignore = "silence = \"ignore\"\n";
    for channel in ["", LOSSY] {
        let (mut absent, mut zero) = (String::new(), String::new());
        for (kind, knob) in KINDS {
            absent += &scheme(kind, knob, "", kind);
            zero += &scheme(kind, knob, "link_loss = 0.0\n", kind);
        }
        absent += &scheme("send-on-delta", "delta = 1.0", ignore, "ignore");
        zero += &scheme(
            "send-on-delta",
            "delta = 1.0",
            &format!("{ignore}link_loss = 0.3\n"),
            "ignore",
        );
        let (a, b) = (
            summary(&scalar(channel, &absent, 20)),
            summary(&scalar(channel, &zero, 20)),
        );
        for (x, y) in a.schemes.iter().zip(&b.schemes) {
            let [mut x, mut y] = [x, y].map(|s| serde_json::to_value(s).unwrap());
            for v in [&mut x, &mut y] {
                v.as_object_mut().unwrap().remove("params");
            }
            assert!(x == y, "{} differs ({channel})", x["name"]);
        }
    }
}

#[test]
fn a_link_loss_that_is_not_a_probability_below_one_is_refused_naming_the_key() {
    for (kind, knob) in KINDS {
        for bad in ["1.0", "-0.2", "1.5"] {
            let text = scalar(
                "",
                &scheme(kind, knob, &format!("link_loss = {bad}\n"), "x"),
                2,
            );
            let e = build::load(&text, "scalar.toml").unwrap_err();
            assert!(e.to_string().contains("link_loss"), "{kind} {bad}: {e}");
        }
    }
}

/// Round-robin with the zero-order hold: a scheduled sensor always sends, so P(silent | x) = 0
/// and the exact likelihood of nothing arriving is the constant p: no information. The exact
/// Tobit particle filter and the federated Tobit KF take a lost reading so (neither refuses
/// it nor reads it as a fresh one): every estimate of a lossy run is that of a center given
/// the readings that arrived and nothing for the lost ones (`NotScheduled`, the held value,
/// which is not data), with the same seed.
#[test]
fn a_lost_reading_is_no_information_for_the_tobit_pf_and_the_federated_tobit_kf() {
    let schemes = scheme("tobit-pf", "tau = 1.5\nparticles = 300", "", "pf")
        + &scheme("federated-tobit", "tau = 1.5", "", "ftkf");
    let text = scalar(LOSSY, &schemes, 3);
    let exp = build::load(&text, "scalar.toml").unwrap();
    let mut lost = 0;
    for trial in 0..exp.trials {
        let t = trace::trace(&exp, trial, false).unwrap();
        let data = runner::draw_trial(&exp, trial);
        for (v, variant) in t.variants.iter().enumerate() {
            let (_, center_seed) = coins(exp.seed, trial, coin_stream(v), 0);
            let mut inst = exp.variants[v].scheme.build_with_seed(center_seed).unwrap();
            for k in 1..=exp.steps {
                let inbox: Vec<Received> = (0..2)
                    .map(|i| match variant.links[k - 1][i] {
                        // As it crosses the network: a single per component.
                        Link::Sent => Received::from(Transmission::Send(Message::Measurement(
                            data.measurements[k - 1][i].clone(),
                        ))),
                        Link::Lost => {
                            lost += 1;
                            Received::NotScheduled
                        }
                        Link::NotScheduled => Received::NotScheduled,
                        other => panic!("round-robin sensors send when scheduled: {other:?}"),
                    })
                    .collect();
                inst.center.step(k, &inbox).unwrap();
                let (got, want) = (&variant.estimates[k - 1], inst.center.estimate());
                assert_eq!(got, want, "variant {v}, trial {trial}, step {k}");
            }
        }
    }
    assert!(lost > 20, "only {lost} lost readings");
    // And the runs complete, with the losses counted.
    let s = summary(&scalar(LOSSY, &schemes, 20));
    for sc in &s.schemes {
        let link = sc.link.as_ref().unwrap();
        assert!(
            (link.loss_fraction.unwrap() - 0.3).abs() < 0.1,
            "{:?}",
            link.loss_fraction
        );
        assert!(sc.steady_state.anees.is_finite());
    }
}

/// Three sensors, one behind a link that loses 60% of its packets and two on ideal links
/// (per-sensor `channel` tables). A center that assumes 60% for every sensor reads the clean
/// sensors' silences as maybe lost and is underconfident (ANEES below 1 by more than 4 SE);
/// each sensor's own loss, written as a list or taken from the links (`link_loss =
/// "channel"`, the same numbers bit for bit), is consistent. 400 trials of 60 steps: ANEES SE
/// about 0.02. Seen (uniform / per sensor): printed by `cargo test --release --test
/// channel_loss_aware -- --nocapture`.
#[test]
fn each_sensor_s_own_loss_is_consistent_where_one_loss_for_all_is_not() {
    let schemes = |per_sensor: &str| {
        let mut schemes = String::new();
        for (kind, knob) in KINDS {
            for (value, name) in [("0.6", "all"), (per_sensor, "own")] {
                schemes += &scheme(
                    kind,
                    knob,
                    &format!("link_loss = {value}\n"),
                    &format!("{kind} {name}"),
                );
            }
        }
        schemes
    };
    let plain = "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n";
    let lossy = format!("{plain}channel = {{ kind = \"bernoulli\", loss = 0.6 }}\n");
    let sensors = lossy + plain + plain;
    let listed = summary(&scalar_system(
        0.95,
        0,
        60,
        &sensors,
        &schemes("[0.6, 0.0, 0.0]"),
        400,
    ));
    for pair in listed.schemes.chunks(2) {
        let (anees, se, _, _) = consistency(&pair[0]);
        // The open-loop stochastic trigger's silences say little either way: its uniform
        // center stays consistent (ANEES 1.00), at a larger MSE (0.51 against 0.38).
        assert!(
            pair[0].name.starts_with("stochastic-trigger-open") || anees < 1.0 - 4.0 * se,
            "{}: ANEES {anees} ± {se}",
            pair[0].name
        );
        assert_consistent(&pair[1]);
    }
    // The same run with the losses taken from the links: the same numbers, bit for bit.
    let from_links = summary(&scalar_system(
        0.95,
        0,
        60,
        &sensors,
        &schemes("\"channel\""),
        400,
    ));
    for (a, b) in listed.schemes.iter().zip(&from_links.schemes) {
        let [mut a, mut b] = [a, b].map(|s| serde_json::to_value(s).unwrap());
        for v in [&mut a, &mut b] {
            v.as_object_mut().unwrap().remove("params");
        }
        assert!(a == b, "{}: \"channel\" differs from the list", a["name"]);
    }
}

/// `link_loss = "channel"` takes each link's long-run loss: a Gilbert–Elliott link at its
/// stationary state and ARQ's repeated attempts (`p^(1+n)`), as the engine's fates draw them.
#[test]
fn the_channel_s_loss_is_the_long_run_loss_of_each_link() {
    use hushfuse::network::channel::ChannelSpec;
    let spec = |t: &str| toml::from_str::<ChannelSpec>(t).unwrap();
    assert_eq!(spec("kind = \"ideal\"").delivery_loss(), 0.0);
    assert!((spec("kind = \"bernoulli\"\nloss = 0.3").delivery_loss() - 0.3).abs() < 1e-15);
    let arq = spec("kind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 2 }");
    assert!((arq.delivery_loss() - 0.027).abs() < 1e-15);
    // π_bad = 0.1 / (0.1 + 0.3) = 1/4: 3/4 · 0.1 + 1/4 · 0.9 = 0.3.
    let ge =
        spec("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.3\nloss_good = 0.1\nloss_bad = 0.9");
    assert!((ge.delivery_loss() - 0.3).abs() < 1e-15);
    // With one retry each state squares its loss: 3/4 · 0.01 + 1/4 · 0.81 = 0.21.
    let ge_arq = spec("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.3\nloss_good = 0.1\nloss_bad = 0.9\narq = { max_retries = 1 }");
    assert!((ge_arq.delivery_loss() - 0.21).abs() < 1e-15);
}

/// Zheng et al.'s censored PF takes per-sensor losses too (a list, or the links' own, the
/// same numbers), and its exact fusion, which has no loss-aware likelihood, refuses a loss
/// instead of ignoring it.
#[test]
fn the_censored_pf_takes_each_sensor_s_loss_and_its_exact_fusion_refuses_one() {
    let plain = "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n";
    let lossy = format!("{plain}channel = {{ kind = \"bernoulli\", loss = 0.6 }}\n");
    let sensors = lossy + plain;
    let pf = |value: &str| {
        scheme(
            "censored-pf",
            "l = 1.0\nparticles = 200",
            &format!("link_loss = {value}\n"),
            "pf",
        )
    };
    let [a, b, uniform] = ["[0.6, 0.0]", "\"channel\"", "0.6"]
        .map(|v| summary(&scalar_system(0.95, 0, 40, &sensors, &pf(v), 20)));
    let json = |s: &results::Summary| {
        let mut v = serde_json::to_value(&s.schemes[0]).unwrap();
        v.as_object_mut().unwrap().remove("params");
        v
    };
    assert_eq!(json(&a), json(&b));
    assert_ne!(
        json(&a),
        json(&uniform),
        "the per-sensor losses were not used"
    );
    let exact = scheme(
        "censored-pf",
        "l = 1.0\nparticles = 50\nfeedback = \"none\"\nfusion = \"exact\"",
        "link_loss = 0.3\n",
        "exact",
    );
    let e = build::load(&scalar_system(0.95, 0, 10, &sensors, &exact, 2), "x.toml").unwrap_err();
    assert!(e.to_string().contains("no loss-aware likelihood"), "{e}");
}
