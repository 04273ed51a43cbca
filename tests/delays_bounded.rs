//! Delays that never end: a geometric delay of mean 1e17 or 1e100 steps used to hang a 4-trial,
//! 50-step run (the geometric sampler looped for ever where 1 − p rounds to 1); now the run
//! ends, every such packet later than the run. A delay of 1 over 10⁶ steps re-fuses the trial
//! so far at every step (work as steps²): refused by the time estimate, naming the re-fusion.
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;

fn scenario(steps: usize, channel: &str) -> String {
    format!(
        "name = \"d\"\ntrials = 4\nsteps = {steps}\nseed = 1\n[model]\nkind = \"matrix\"\nF = [[0.9]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[schemes]]\nkind = \"centralized-kf\"\n[channel]\n{channel}\n"
    )
}

#[test]
fn enormous_geometric_delays_end_and_lose_every_late_packet() {
    for mean in ["1e17", "1e100"] {
        let text = scenario(
            50,
            &format!("kind = \"bernoulli\"\nloss = 0.1\ndelay = {{ kind = \"geometric\", mean = {mean} }}"),
        );
        let exp = build::load_with(&text, "d.toml", &Default::default()).unwrap();
        let sums = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
        let s = results::summarize(&exp, &sums);
        let link = s.schemes[0].link.as_ref().expect("a link section");
        // A delay of mean 1e17 steps exceeds 50 steps with probability 1 - 5e-16: nothing sent
        // arrives: every packet is lost, or later than the run (dropped).
        assert_eq!(link.sent, 2.0, "mean {mean}");
        assert_eq!(link.delivered, 0.0, "mean {mean}");
        assert!(
            (link.lost + link.dropped_late - link.sent).abs() < 1e-12,
            "mean {mean}: {link:?}"
        );
    }
}

#[test]
fn a_delay_at_every_step_of_a_long_run_is_refused_by_its_refusion_work() {
    let text = scenario(1_000_000, "delay = 1");
    let e = build::load_with(&text, "d.toml", &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("re-fusing") && e.contains("steps squared"),
        "{e}"
    );
    // The same link over 1000 steps is fine.
    build::load_with(&scenario(1000, "delay = 1"), "d.toml", &Default::default()).unwrap();
}
