//! Loss-aware fusion under a lossy link (scratch: figures).
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;

fn scenario(channel: &str, schemes: &str, trials: usize) -> String {
    format!(
        r#"
name = "scalar"
trials = {trials}
steps = 60
seed = 2004
[model]
kind = "matrix"
F = [[0.95]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
H = [[1.0]]
R = [[1.0]]
[[sensors]]
H = [[1.0]]
R = [[1.0]]
{channel}
{schemes}
"#
    )
}

fn summary(text: &str) -> results::Summary {
    let exp = build::load(text, "scalar.toml").unwrap();
    let sums = runner::run(&exp, runner::RunOptions { threads: 2 }, &|_| {}).unwrap();
    results::summarize(&exp, &sums)
}

#[test]
fn figures() {
    let kinds = [
        ("innovation-trigger-kf", "delta = 1.0"),
        ("stochastic-trigger-open", "tau = 1.0"),
        ("stochastic-trigger-closed", "tau = 1.0"),
        ("send-on-delta", "delta = 1.0"),
    ];
    let mut schemes = String::new();
    for (kind, knob) in kinds {
        for ll in ["", "link_loss = 0.3\n"] {
            schemes += &format!("[[schemes]]\nkind = \"{kind}\"\n{knob}\n{ll}label = \"{kind}{}\"\n", if ll.is_empty() {" pub"} else {" aware"});
        }
    }
    for loss in [0.0, 0.3] {
        let s = summary(&scenario(&format!("[channel]\nkind = \"bernoulli\"\nloss = {loss}\n"), &schemes, 400));
        for sc in &s.schemes {
            let ss = &sc.steady_state;
            eprintln!("loss {loss} {:40} ANEES {:.3} ± {:.3} cov95 {:.3} ± {:.3} MSE {:.3} rate {:.3}", sc.name, ss.anees, ss.anees_se, sc.nees_coverage_95, sc.nees_coverage_95_se, ss.mse, sc.rate);
        }
    }
}
