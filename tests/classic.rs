//! The classic quantized-innovation reproductions (Ribeiro et al. 2006, Msechu et al. 2008,
//! Stein et al. 2015) through the library at their full (small) trial counts: their `inflation`
//! claims hold; the same checks fail when the numbers are not the factor's (a summary with
//! another variant's numbers in the place of the sign filter's); and the claims are validated
//! at load.
use hushfuse::engine::runner;
use hushfuse::metrics::results::{self, Summary};
use hushfuse::output::report::{self, ClaimResult, Verdict};
use hushfuse::scenario::build::{self, Experiment};
use hushfuse::scenario::builtin;

fn run(id: &str) -> (Experiment, Summary, Vec<ClaimResult>) {
    let text = builtin::get(id).expect("built-in");
    let exp = build::load(text, &format!("built-in:{id}")).unwrap();
    let sums = runner::run(&exp, runner::RunOptions { threads: 2 }, &|_| {}).unwrap();
    let summary = results::summarize(&exp, &sums);
    let claims = report::check_claims(&exp, &summary);
    for c in &claims {
        println!("[{:?}] {}\n    {}", c.verdict, c.text, c.evidence);
    }
    (exp, summary, claims)
}

fn verdicts(claims: &[ClaimResult]) -> Vec<Verdict> {
    claims.iter().map(|c| c.verdict).collect()
}

/// The index of the variant of curve `label`.
fn variant(summary: &Summary, label: &str) -> usize {
    summary
        .schemes
        .iter()
        .position(|s| s.name == label)
        .unwrap_or_else(|| panic!("no {label}"))
}

#[test]
fn soi_kf_and_msechu_factors_hold_and_a_wrong_factor_fails() {
    let (exp, summary, claims) = run("classic-quantized-kf");
    assert_eq!(verdicts(&claims), vec![Verdict::Holds; 5], "{claims:#?}");
    // The evidence names the independent factors.
    assert!(claims[0].evidence.contains("c = 0.636620 (2 cells)"));
    assert!(claims[2].evidence.contains("c = 0.882518 (4 cells)"));
    assert!(claims[2].evidence.contains("c = 0.990499 (16 cells)"));
    // The 2-bit filter's numbers in the sign filter's place: its covariance and MSE are those
    // of c = 0.8825, not 2/π, and both claims on the sign filter must fail.
    let sign = variant(&summary, "SOI-KF (sign)");
    let two_bits = sign + 1;
    let mut wrong = summary.clone();
    let name = wrong.schemes[sign].name.clone();
    let params = wrong.schemes[sign].params.clone();
    wrong.schemes[sign] = summary.schemes[two_bits].clone();
    wrong.schemes[sign].name = name;
    wrong.schemes[sign].params = params;
    let bad = report::check_claims(&exp, &wrong);
    assert_eq!(bad[0].verdict, Verdict::Fails, "{:#?}", bad[0]);
    assert_eq!(bad[1].verdict, Verdict::Fails, "{:#?}", bad[1]);
    // A covariance 1% off the 2/π recursion fails the exact claim; 1e-7 off still holds.
    for (scale, want) in [(1.01, Verdict::Fails), (1.0 + 1e-7, Verdict::Holds)] {
        let mut off = summary.clone();
        off.schemes[sign].steady_state.trace *= scale;
        assert_eq!(report::check_claims(&exp, &off)[0].verdict, want, "{scale}");
    }
    // The multi-bit filter's MSE 10% above its recursion fails (the tolerance is 5%).
    let mut off = summary.clone();
    for s in off.schemes.iter_mut().filter(|s| s.name == "Msechu et al.") {
        s.steady_state.mse *= 1.10;
    }
    assert_eq!(report::check_claims(&exp, &off)[3].verdict, Verdict::Fails);
}

#[test]
fn one_bit_static_efficiency_holds_and_fails_without_the_loss() {
    let (exp, summary, claims) = run("classic-one-bit-static");
    assert_eq!(verdicts(&claims), vec![Verdict::Holds; 2], "{claims:#?}");
    assert!(claims[1].evidence.contains("π/2 = 1.5708"));
    // A one-bit filter as good as the all-data one (the Kalman filter's numbers in its place)
    // has ratio 1, not about π/2: the efficiency claim fails.
    let sign = variant(&summary, "SOI-KF (sign)");
    let kf = variant(&summary, "Kalman filter");
    let mut wrong = summary.clone();
    wrong.schemes[sign].steady_state = summary.schemes[kf].steady_state.clone();
    wrong.schemes[sign].per_trial = summary.schemes[kf].per_trial.clone();
    let bad = report::check_claims(&exp, &wrong);
    assert_eq!(bad[1].verdict, Verdict::Fails, "{:#?}", bad[1]);
}

#[test]
fn one_bit_tracking_efficiency_is_root_half_pi() {
    let (exp, summary, claims) = run("classic-one-bit-tracking");
    assert_eq!(verdicts(&claims), vec![Verdict::Holds; 2], "{claims:#?}");
    assert!(claims[0].evidence.contains("√(π/2) = 1.2533"));
    // The static loss π/2 in place of √(π/2): a one-bit MSE 1.5708 / 1.2666 times too large
    // fails.
    let sign = variant(&summary, "SOI-KF (sign)");
    let mut wrong = summary.clone();
    let scale = std::f64::consts::FRAC_PI_2 / 1.2666;
    wrong.schemes[sign].steady_state.mse *= scale;
    for t in &mut wrong.schemes[sign].per_trial {
        t[0] *= scale;
    }
    let bad = report::check_claims(&exp, &wrong);
    assert_eq!(bad[0].verdict, Verdict::Fails, "{:#?}", bad[0]);
    assert_eq!(bad[1].verdict, Verdict::Fails, "{:#?}", bad[1]);
}

/// The static built-in with its claims replaced by `claim` (and `extra` appended to the file).
fn with_claim(claim: &str, extra: &str) -> String {
    let text = builtin::get("classic-one-bit-static").unwrap();
    let head = &text[..text.find("[[paper.claims]]").unwrap()];
    format!("{head}[[paper.claims]]\n{claim}\n{extra}")
}

fn refused(text: &str) -> String {
    match build::load(text, "t") {
        Ok(_) => panic!("should be refused:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn inflation_claims_are_validated_at_load() {
    let ok = "kind = \"inflation\"\ntext = \"t\"\nscheme = \"SOI-KF (sign)\"\n";
    build::load(
        &with_claim(&format!("{ok}check = \"trace-recursion\""), ""),
        "t",
    )
    .unwrap();
    let cases = [
        (format!("{ok}check = \"trace-recursoin\""), "", "trace-recursoin"),
        (format!("{ok}check = \"efficiency\""), "", "reference"),
        (
            format!("{ok}check = \"efficiency\"\nreference = \"Kalman\""),
            "",
            "reference",
        ),
        (
            format!("{ok}check = \"mse-recursion\"\nreference = \"Kalman filter\""),
            "",
            "reference",
        ),
        (
            format!("{ok}check = \"mse-recursion\"\nwithin = 0"),
            "",
            "within",
        ),
        (
            format!("{ok}check = \"mse-recursion\"\nwihtin = 0.1"),
            "",
            "wihtin",
        ),
        (
            "kind = \"inflation\"\ntext = \"t\"\nscheme = \"Zhang\"\ncheck = \"mse-recursion\""
                .to_string(),
            "[[schemes]]\nkind = \"quantized-innovation\"\nlabel = \"Zhang\"\nquantizer = \"zhang\"\nbits = 1\n",
            "zhang-table7",
        ),
        (
            "kind = \"inflation\"\ntext = \"t\"\nscheme = \"Lossy\"\ncheck = \"mse-recursion\""
                .to_string(),
            "[[schemes]]\nkind = \"quantized-innovation\"\nlabel = \"Lossy\"\nquantizer = \"sign\"\nchannel = { kind = \"bernoulli\", loss = 0.1 }\n",
            "delivers every message",
        ),
    ];
    for (claim, extra, needle) in cases {
        // Extra scheme entries go before [paper] (TOML tables after [[paper.claims]] would
        // belong to it).
        let text = with_claim(&claim, "");
        let text = text.replacen("[paper]", &format!("{extra}\n[paper]"), 1);
        let e = refused(&text);
        assert!(e.contains(needle), "{needle}: {e}");
    }
}
