//! What the link tests share: the scalar system of Sinopoli et al. (x' = a x + w, y_i = x + v_i,
//! q = r = 1, prior N(0, 1), seed 2004) with a link and schemes of the test's choosing, and its
//! run's summary.
#![allow(dead_code)] // each test file uses what it needs

use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;

/// The scenario text: `sensors` scalar sensors, `steps` steps, then `channel` and `schemes`.
pub fn scalar_system(
    a: f64,
    sensors: usize,
    steps: usize,
    channel: &str,
    schemes: &str,
    trials: usize,
) -> String {
    let sensor = "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n".repeat(sensors);
    format!(
        r#"
name = "scalar"
trials = {trials}
steps = {steps}
seed = 2004
[model]
kind = "matrix"
F = [[{a:?}]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
{sensor}
{channel}
{schemes}
"#
    )
}

/// The summary of a run of `text` on two threads.
pub fn summary(text: &str) -> results::Summary {
    let exp = build::load(text, "scalar.toml").unwrap();
    let sums = runner::run(&exp, runner::RunOptions { threads: 2 }, &|_| {}).unwrap();
    results::summarize(&exp, &sums)
}
