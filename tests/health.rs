//! Scheme health is reported: a particle filter too small for its model is flagged as
//! diverged (issue 14), and the same filter with enough particles is not.
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;

const SCENARIO: &str = r#"
name = "pf6"
description = "Dormann et al. schemes at a few communication rates (a quick look at dormann-fig1)"
trials = 100
steps = 100
seed = 2018
steady_state_from = 51

[model]
kind = "near-constant-acceleration-2d"   # row 5 of the printed A has a typo; see model/presets.rs
dt = 0.25
sigma2 = 1.0                              # the printed C^w has unit intensity

[prior]
mean = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
cov_diag = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]

[groups]
position = [0, 3]
velocity = [1, 4]
acceleration = [2, 5]

[[sensors]]
name = "position-1"
observe = [0, 3]
R_diag = [1.0, 1.0]
[[sensors]]
name = "position-2"
observe = [0, 3]
R_diag = [1.0, 1.0]
[[sensors]]
name = "velocity-1"
observe = [1, 4]
R_diag = [1.0, 1.0]
[[sensors]]
name = "velocity-2"
observe = [1, 4]
R_diag = [1.0, 1.0]
[[sensors]]
name = "acceleration-1"
observe = [2, 5]
R_diag = [1.0, 1.0]
[[sensors]]
name = "acceleration-2"
observe = [2, 5]
R_diag = [1.0, 1.0]


[[schemes]]
kind = "centralized-kf"

[[schemes]]
kind = "censored-pf"
label = "PF"
policy = "all"
sweep.particles = [10, 20000]
"#;

#[test]
fn ten_particles_on_a_6d_model_diverge_and_enough_particles_do_not() {
    let opts = build::LoadOptions {
        trials: Some(12),
        ..Default::default()
    };
    let exp = build::load_with(SCENARIO, "pf6.toml", &opts).unwrap();
    let sums = runner::run(&exp, runner::RunOptions::default(), &|_| {}).unwrap();
    let summary = results::summarize(&exp, &sums);
    let find = |p: i64| {
        summary
            .schemes
            .iter()
            .find(|s| {
                s.params
                    .get("particles")
                    .is_some_and(|v| v.to_string() == p.to_string())
            })
            .unwrap_or_else(|| panic!("no variant with {p} particles"))
    };
    let kf = &summary.schemes[0];
    assert_eq!(kf.diverged_fraction, 0.0);
    assert!(kf.ess.is_none());
    let small = find(10);
    assert_eq!(small.diverged_fraction, 1.0, "{:?}", small.consistency);
    let ess = small
        .ess
        .as_ref()
        .expect("a particle filter reports its ESS");
    assert!(ess.mean <= 10.0 && ess.min >= 1.0 - 1e-9);
    let large = find(20000);
    assert_eq!(large.diverged_fraction, 0.0, "{:?}", large.consistency);
    assert!(large.ess.as_ref().unwrap().mean > 1000.0);
    // The table shows the column and warns about the small filter only.
    let table = results::table(&summary);
    assert!(table.contains("diverged"), "{table}");
    let warnings = results::warnings(&summary);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("particles=10") && warnings[0].contains("more particles"));
}
