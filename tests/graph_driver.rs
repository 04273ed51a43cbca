//! The graph driver (`network::graph`) with the star's schemes as nodes
//! (`engine::star_nodes`) against the engine's trial loop: the same estimates bit for bit, and
//! over a multi-hop network the same per-node counters, on lossy links with retries, a lossy
//! feedback path and per-source forwarding. What the adapter does not do is refused by name.
#[path = "common/cli.rs"]
mod common;

use hushfuse::engine::runner::draw_trial;
use hushfuse::engine::seeding::coin_stream;
use hushfuse::engine::star_nodes::{run_star_trial, star_nodes};
use hushfuse::engine::trial::{LoopBuffers, Trial, TrialSpec};
use hushfuse::scenario::build;

/// Every variant of `exp` but those the adapter refuses (named in `skip`), trials 0..`trials`:
/// the driver's steps equal the engine's. Returns how many variants were compared.
fn driver_equals_engine(exp: &build::Experiment, trials: usize, skip: &[usize]) -> usize {
    let mut compared = 0;
    for v in 0..exp.variants.len() {
        if skip.contains(&v) {
            continue;
        }
        compared += 1;
        for trial in 0..trials {
            let data = draw_trial(exp, trial);
            let graph = run_star_trial(exp, v, trial, coin_stream(v), &data.measurements)
                .unwrap_or_else(|e| panic!("variant {v}: {e}"));
            let mut buffers = LoopBuffers::new(exp.system.n_sensors());
            let spec = TrialSpec {
                trial,
                variant: v,
                stream: coin_stream(v),
                available: None,
            };
            let mut engine = Trial::new(exp, spec, &mut buffers, false).unwrap();
            for (k, readings) in data.measurements.iter().enumerate() {
                let s = engine.step(k + 1, readings).unwrap();
                let (estimate, counts) = &graph[k];
                let at = format!(
                    "variant {v} ({}), trial {trial}, step {}",
                    exp.variants[v].kind,
                    k + 1
                );
                assert_eq!(s.estimate.mean, estimate.mean, "{at}");
                assert_eq!(s.estimate.cov, estimate.cov, "{at}");
                if exp.network.is_some() {
                    assert_eq!(s.nodes, &counts[..], "{at}");
                }
            }
        }
    }
    compared
}

/// mesh-line with `channel` as its `[channel]` and `schemes` for its schemes.
fn mesh_line(channel: &str, schemes: Option<&str>) -> build::Experiment {
    let text = hushfuse::scenario::builtin::get("mesh-line").unwrap();
    let start = text.find("[channel]").unwrap();
    let end = text.find("[network]").unwrap();
    let mut text = format!("{}{channel}\n{}", &text[..start], &text[end..]);
    if let Some(schemes) = schemes {
        let cut = text.find("[[schemes]]").unwrap();
        text = format!("{}{schemes}", &text[..cut]);
    }
    build::load(&text, "mesh-line").unwrap_or_else(|e| panic!("{e}"))
}

const FEEDBACK_SCHEMES: &str = r#"
[[schemes]]
kind = "censored-pf"
l = 1.0
particles = 100
feedback = "prediction"

[[schemes]]
kind = "send-on-delta"
delta = 1.0
"#;

#[test]
fn the_driver_gives_the_engine_on_mesh_line() {
    // Per-source forwarding over 2 to 5 lossy hops with a retry; the all-data KF sums at the
    // relays (aggregation), which the adapter does not do.
    let exp = build::load(
        hushfuse::scenario::builtin::get("mesh-line").unwrap(),
        "mesh-line",
    )
    .unwrap();
    let aggregated: Vec<usize> = (0..exp.variants.len())
        .filter(|&v| exp.variants[v].aggregated(exp.network.as_deref()))
        .collect();
    assert_eq!(aggregated.len(), 1);
    let compared = driver_equals_engine(&exp, 2, &aggregated);
    assert_eq!(compared, exp.variants.len() - 1);
}

#[test]
fn the_driver_gives_the_engine_with_feedback_down_a_lossy_tree() {
    // Feedback down the tree over lossy downlinks (its frames, listening and holders counted),
    // bursts on the uplinks, ACKs lost on the way back.
    let channel = "[channel]\nkind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.4\nloss_good = 0.05\nloss_bad = 0.8\narq = { max_retries = 2 }\ndownlink = { kind = \"bernoulli\", loss = 0.25 }";
    let exp = mesh_line(channel, Some(FEEDBACK_SCHEMES));
    assert_eq!(driver_equals_engine(&exp, 3, &[]), 2);
}

#[test]
fn the_driver_gives_the_engine_on_a_lossy_star_with_arq_and_feedback() {
    let head = common::TINY.split("[[schemes]]").next().unwrap();
    let text = format!(
        "{head}[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = {{ max_retries = 2 }}\ndownlink = {{ kind = \"bernoulli\", loss = 0.4 }}\n{FEEDBACK_SCHEMES}\n[[schemes]]\nkind = \"round-robin-kf\"\n[[schemes]]\nkind = \"centralized-kf\"\n"
    );
    let exp = build::load(&text, "star.toml").unwrap_or_else(|e| panic!("{e}"));
    assert!(exp.network.is_none());
    assert_eq!(driver_equals_engine(&exp, 4, &[]), 4);
}

#[test]
fn the_adapter_refuses_what_it_does_not_model() {
    let head = common::TINY.split("[[schemes]]").next().unwrap();
    for (extra, word) in [
        (
            "[channel]\nkind = \"ideal\"\ndelay = 1\n[[schemes]]\nkind = \"centralized-kf\"\n",
            "delay",
        ),
        (
            "reals = \"f64\"\n[[schemes]]\nkind = \"centralized-kf\"\n",
            "f64",
        ),
        (
            "[[schemes]]\nkind = \"centralized-kf\"\nsequence_bits = 4\n",
            "sequence",
        ),
    ] {
        let text = head.replacen(
            "seed = 1\n",
            &format!(
                "seed = 1\n{}",
                if word == "f64" {
                    "reals = \"f64\"\n"
                } else {
                    ""
                }
            ),
            1,
        );
        let extra = extra.replacen("reals = \"f64\"\n", "", 1);
        let exp = build::load(&format!("{text}{extra}"), "refused.toml")
            .unwrap_or_else(|e| panic!("{word}: {e}"));
        let err = star_nodes(&exp, 0, 0, coin_stream(0))
            .err()
            .unwrap_or_else(|| panic!("{word} accepted"));
        assert!(err.contains(word), "{word}: {err}");
    }
}
