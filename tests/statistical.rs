//! Statistical properties with fixed seeds; tolerances come from the sampling distribution,
//! not from trial and error.
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use statrs::distribution::{ChiSquared, ContinuousCDF};

fn experiment(schemes: &str, trials: usize, seed: u64) -> build::Experiment {
    // The dormann-fig1 system with the given schemes.
    let base = builtin::get("dormann-fig1").unwrap();
    let head = base.split("[[schemes]]").next().unwrap();
    let text = head
        .replace("trials = 500", &format!("trials = {trials}"))
        .replace("seed = 2018", &format!("seed = {seed}"));
    build::load(&format!("{text}{schemes}"), "test").unwrap()
}

fn run(exp: &build::Experiment) -> results::Summary {
    let sums = runner::run(exp, runner::RunOptions { threads: 0 }, &|_| {}).unwrap();
    results::summarize(exp, &sums)
}

/// The all-send KF is consistent: at a fixed step k, the NEES summed over M independent trials
/// is chi-square with n M degrees of freedom, so M n ANEES_k must lie in its 99% interval.
#[test]
fn all_send_kf_anees_is_in_the_chi_square_interval() {
    let trials = 300;
    let exp = experiment("[[schemes]]\nkind = \"centralized-kf\"\n", trials, 11);
    let s = run(&exp);
    let n = s.state_dim as f64;
    let dof = n * trials as f64;
    let chi = ChiSquared::new(dof).unwrap();
    let (lo, hi) = (chi.inverse_cdf(0.005), chi.inverse_cdf(0.995));
    for k in [10usize, 100] {
        let stat = s.schemes[0].anees_per_step[k - 1] * dof;
        assert!(
            stat > lo && stat < hi,
            "step {k}: M n ANEES = {stat:.1} outside [{lo:.1}, {hi:.1}]"
        );
    }
}

/// A deliberately mis-specified filter must fail the same test (so the test can fail): the
/// filter believes R is 4x smaller than the truth.
#[test]
fn anees_test_detects_an_overconfident_filter() {
    let trials = 300;
    let base = builtin::get("dormann-fig1").unwrap();
    let head = base.split("[[schemes]]").next().unwrap();
    let truth = hushfuse::scenario::build::load(
        &format!(
            "{}[[schemes]]\nkind = \"centralized-kf\"\n",
            head.replace("trials = 500", "trials = 300")
        ),
        "truth",
    )
    .unwrap();
    let filter_text = format!(
        "{}[[schemes]]\nkind = \"centralized-kf\"\n",
        head.replace("trials = 500", "trials = 300")
            .replace("R_diag = [1.0, 1.0]", "R_diag = [0.25, 0.25]")
    );
    let believed = hushfuse::scenario::build::load(&filter_text, "believed").unwrap();
    // Run the believed filter on the true system's data by swapping the scheme in.
    let mut exp = truth;
    exp.variants = believed.variants;
    let s = run(&exp);
    let dof = s.state_dim as f64 * trials as f64;
    let hi = ChiSquared::new(dof).unwrap().inverse_cdf(0.995);
    let stat = s.schemes[0].anees_per_step[99] * dof;
    assert!(
        stat > hi,
        "overconfident filter passed: {stat:.1} <= {hi:.1}"
    );
}

/// Algorithm 2 is consistent (Section IV): steady-state MSE <= trace of its inflated covariance,
/// up to 3 Monte Carlo standard errors of the MSE, including at rates below 0.5.
#[test]
fn algorithm2_is_consistent_at_low_rates() {
    let exp = experiment(
        "[[schemes]]\nkind = \"dkf-alg2-event\"\nsweep.alpha = [1.5, 3.0]\nsweep.b = [1.0, 10.0]\n",
        200,
        5,
    );
    let s = run(&exp);
    let mut below_half = false;
    for v in &s.schemes {
        let ss = &v.steady_state;
        below_half |= ss.rate < 0.5;
        assert!(
            ss.mse <= ss.trace + 3.0 * ss.mse_se,
            "{:?}: MSE {} ± {} > trace {}",
            v.params,
            ss.mse,
            ss.mse_se,
            ss.trace
        );
    }
    assert!(below_half, "no variant below rate 0.5");
}

/// Algorithm 1's fused estimate is the centralized KF's for the same subset, so it is
/// consistent: ANEES in the chi-square interval at a fixed step.
#[test]
fn algorithm1_random_is_consistent() {
    let trials = 300;
    let exp = experiment(
        "[[schemes]]\nkind = \"dkf-alg1-random\"\nrate = 0.6\n",
        trials,
        3,
    );
    let s = run(&exp);
    let dof = s.state_dim as f64 * trials as f64;
    let chi = ChiSquared::new(dof).unwrap();
    let stat = s.schemes[0].anees_per_step[79] * dof;
    assert!(
        stat > chi.inverse_cdf(0.005) && stat < chi.inverse_cdf(0.995),
        "{stat}"
    );
    // The realized rate matches the target within binomial error of 300 x 100 x 6 decisions
    // (correlated in pairs; 0.01 is more than 5 standard errors).
    assert!(
        (s.schemes[0].rate - 0.6).abs() < 0.01,
        "rate {}",
        s.schemes[0].rate
    );
}

/// The particle filter with all data converges to the Kalman filter as particles grow: with
/// 4000 particles the position MSE is within 2% of the KF's (paired over the same trials),
/// with 20 particles it is clearly worse — the comparison can fail.
#[test]
fn particle_filter_approaches_the_kalman_filter() {
    let base = builtin::get("zheng-fig1").unwrap();
    let head = base.split("[[schemes]]").next().unwrap();
    let text = format!(
        "{}[[schemes]]\nkind = \"censored-pf\"\nlabel = \"pf20\"\npolicy = \"all\"\nparticles = 20\n\
         [[schemes]]\nkind = \"censored-pf\"\nlabel = \"pf4000\"\npolicy = \"all\"\nparticles = 4000\n\
         [[schemes]]\nkind = \"centralized-kf\"\nlabel = \"kf\"\n",
        head.replace("trials = 5000", "trials = 300")
    );
    let exp = build::load(&text, "pf-vs-kf").unwrap();
    let s = run(&exp);
    let mse = |i: usize| s.schemes[i].steady_state.mse;
    let (coarse, fine, kf) = (mse(0), mse(1), mse(2));
    // Paired standard error of the fine PF vs KF difference.
    let d: Vec<f64> = s.schemes[1]
        .per_trial
        .iter()
        .zip(&s.schemes[2].per_trial)
        .map(|(a, b)| a[0] - b[0])
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let se = (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    assert!(
        mean.abs() < (3.0 * se).max(0.02 * kf),
        "4000 particles: {fine} vs KF {kf} (diff {mean} ± {se})"
    );
    assert!(
        coarse > 1.1 * kf,
        "20 particles should be clearly worse: {coarse} vs KF {kf}"
    );
}
