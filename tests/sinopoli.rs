//! The two stability reproductions (Sinopoli et al. 2004; Gilbert–Elliott bursts, Huang and Dey
//! 2007) through the library at half their trial count: their `intermittent` claims hold where
//! they must, and the plumbing under them (a scheme entry's own link, swept by a dotted name,
//! in the variant's params) behaves.
use hushfuse::engine::runner;
use hushfuse::metrics::results::{self, Summary};
use hushfuse::output::report::{self, ClaimResult, Verdict};
use hushfuse::scenario::build::{self, Experiment, LoadOptions};
use hushfuse::scenario::builtin;

fn run(id: &str, trials: usize) -> (Experiment, Summary, Vec<ClaimResult>) {
    let text = builtin::get(id).expect("built-in");
    let opts = LoadOptions {
        trials: Some(trials),
        ..Default::default()
    };
    let exp = build::load_with(text, &format!("built-in:{id}"), &opts).unwrap();
    let sums = runner::run(&exp, runner::RunOptions { threads: 2 }, &|_| {}).unwrap();
    let summary = results::summarize(&exp, &sums);
    let claims = report::check_claims(&exp, &summary);
    for c in &claims {
        println!("[{:?}] {}\n    {}", c.verdict, c.text, c.evidence);
    }
    (exp, summary, claims)
}

#[test]
fn sinopoli_critical_claims_hold() {
    let (exp, summary, claims) = run("sinopoli-critical", 2000);
    // Every variant has its own Bernoulli link, and its swept loss is in its params.
    assert_eq!(exp.variants.len(), 13);
    for (v, s) in exp.variants.iter().zip(&summary.schemes) {
        let specs = v.channel.as_deref().expect("a lossy link");
        assert_eq!(specs.len(), 1);
        let loss = match s.params.get("channel.loss") {
            Some(hushfuse::scenario::ParamValue::Number(x)) => *x,
            other => panic!("channel.loss not in params: {other:?}"),
        };
        assert_eq!(specs[0].key("loss"), Some(loss));
        // The link delivered at its rate (3 SE over 2000 x 120 slots is below 0.004).
        let l = s.link.as_ref().expect("a link summary");
        assert!(
            (l.lost / l.sent - loss).abs() < 0.006,
            "{loss}: {}",
            l.lost / l.sent
        );
    }
    let verdicts: Vec<Verdict> = claims.iter().map(|c| c.verdict).collect();
    // Bounds, trace = recursion, MSE = recursion, divergence well below γ_c: hold.
    assert_eq!(&verdicts[..4], &[Verdict::Holds; 4], "{claims:#?}");
    // Just below γ_c nothing can be resolved, and nothing fails.
    assert_ne!(verdicts[4], Verdict::Fails, "{:#?}", claims[4]);
}

#[test]
fn gilbert_elliott_claims_hold() {
    let (_, summary, claims) = run("gilbert-elliott-stability", 2000);
    assert!(summary
        .schemes
        .iter()
        .all(|s| s.params.contains_key("channel.p_bg")));
    let verdicts: Vec<Verdict> = claims.iter().map(|c| c.verdict).collect();
    assert_eq!(&verdicts[..3], &[Verdict::Holds; 3], "{claims:#?}");
    assert_ne!(verdicts[3], Verdict::Fails, "{:#?}", claims[3]);
}

/// The scalar system with one scheme entry `entry`, optionally a scenario `[channel]`.
fn scenario(entry: &str, channel: &str) -> String {
    format!(
        r#"
name = "plumbing"
trials = 2
steps = 5
seed = 1
[model]
kind = "matrix"
F = [[1.2]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
observe = [0]
R_diag = [1.0]
{channel}
[[schemes]]
kind = "centralized-kf"
{entry}
[[schemes]]
kind = "centralized-kf"
label = "scenario link"
"#
    )
}

fn load_err(text: &str) -> build::ScenarioError {
    match build::load(text, "t") {
        Ok(_) => panic!("should be refused:\n{text}"),
        Err(e) => e,
    }
}

#[test]
fn an_entry_link_replaces_the_scenario_link_for_its_variants_only() {
    let text = scenario(
        "channel = { kind = \"bernoulli\" }\nsweep.\"channel.loss\" = [0.1, 0.3]\nsequence_bits = 8",
        "[channel]\nkind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.5",
    );
    let exp = build::load(&text, "t").unwrap();
    assert_eq!(exp.variants.len(), 3);
    for (v, loss) in exp.variants[..2].iter().zip([0.1, 0.3]) {
        assert_eq!(v.channel.as_deref().unwrap()[0].key("loss"), Some(loss));
        assert_eq!(v.sequence_bits, 8);
        assert!(v.params.contains_key("channel.loss"));
        assert!(v.params.contains_key("sequence_bits"));
    }
    // The other entry keeps the scenario's link; no sequence numbers by default.
    let other = &exp.variants[2];
    assert_eq!(other.channel.as_deref(), exp.channel.as_ref());
    assert_eq!(other.sequence_bits, 0);
    assert!(!other.params.keys().any(|k| k.starts_with("channel.")));
    // An ideal entry link leaves that entry ideal (None), whatever the scenario's.
    let text = scenario(
        "channel = { kind = \"ideal\" }",
        "[channel]\nkind = \"bernoulli\"\nloss = 0.2",
    );
    let exp = build::load(&text, "t").unwrap();
    assert!(exp.variants[0].channel.is_none());
    assert!(exp.variants[1].channel.is_some());
}

#[test]
fn entry_links_are_validated_naming_the_key() {
    let e = load_err(&scenario(
        "channel = { kind = \"bernoulli\" }\nsweep.\"channel.loss\" = [0.1, 1.5]",
        "",
    ));
    assert_eq!(
        e.field,
        "schemes[0].channel.loss (sweep point channel.loss = 1.5)"
    );
    assert!(
        e.message
            .contains("schemes[0].channel.loss = 1.5 is not a probability"),
        "{e}"
    );
    let e = load_err(&scenario("channel = { kind = \"bernoulli\" }", ""));
    assert_eq!(e.field, "schemes[0].channel.kind");
    let e = load_err(&scenario(
        "channel = { kind = \"bernoulli\", lost = 0.1 }",
        "",
    ));
    assert_eq!(e.field, "schemes[0].channel");
    let e = load_err(&scenario("sweep.\"channel.loss\" = [0.1]", ""));
    assert_eq!(e.field, "schemes[0].sweep.channel.loss");
    assert!(e.message.contains("no `channel` table"), "{e}");
    let e = load_err(&scenario(
        "channel = { kind = \"bernoulli\", loss = 0.2 }\nsweep.\"channel.loss\" = [0.1]",
        "",
    ));
    assert!(e.message.contains("base value"), "{e}");
    let e = load_err(&scenario("sweep.channel = [1]", ""));
    assert!(e.message.contains("dotted"), "{e}");
    let e = load_err(&scenario("sequence_bits = 33", ""));
    assert_eq!(e.field, "schemes[0].sequence_bits");
    let e = load_err(&scenario("sequence_bits = 1.5", ""));
    assert_eq!(e.field, "schemes[0].sequence_bits");
}

#[test]
fn intermittent_claims_are_checked_before_the_run() {
    let claim = |check: &str, extra: &str| {
        format!(
            "[paper]\ncitation = \"c\"\n[[paper.claims]]\nkind = \"intermittent\"\ntext = \"t\"\nscheme = \"Kalman filter\"\ncheck = \"{check}\"\n{extra}"
        )
    };
    let with = |entry: &str, paper: &str| {
        format!(
            "{}\n{paper}",
            scenario(&format!("label = \"Kalman filter\"\n{entry}"), "")
        )
    };
    let bern = "channel = { kind = \"bernoulli\" }\nsweep.\"channel.loss\" = [0.1, 0.8]";
    assert!(build::load(&with(bern, &claim("bounds", "")), "t").is_ok());
    // No point beyond the critical rate in range: refused, naming the field.
    let e = load_err(&with(bern, &claim("diverges", "range = [0.5, 1.0]")));
    assert_eq!(e.field, "paper.claims[0].check");
    // Bounds need Bernoulli arrivals.
    let ge =
        "channel = { kind = \"gilbert-elliott\", p_gb = 0.1 }\nsweep.\"channel.p_bg\" = [0.2, 0.8]";
    let e = load_err(&with(ge, &claim("bounds", "")));
    assert_eq!(e.field, "paper.claims[0].check");
    assert!(build::load(&with(ge, &claim("trace-recursion", "")), "t").is_ok());
    // A Gilbert–Elliott link that does not lose everything when bad.
    let soft = "channel = { kind = \"gilbert-elliott\", p_gb = 0.1, loss_bad = 0.5 }\nsweep.\"channel.p_bg\" = [0.2, 0.8]";
    let e = load_err(&with(soft, &claim("trace-recursion", "")));
    assert_eq!(e.field, "paper.claims[0].scheme");
    let e = load_err(&with(bern, &claim("bounds", "within = 0.0")));
    assert_eq!(e.field, "paper.claims[0].within");
    let e = load_err(&with(bern, &claim("bounds", "sequences = 5")));
    assert_eq!(e.field, "paper.claims[0].sequences");
}
