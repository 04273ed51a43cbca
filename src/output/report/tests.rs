//! Tests of the comparison with the published numbers and of the claim checks.
use super::*;
use crate::engine::runner;
use crate::metrics::results;
use crate::scenario::build;

/// A summary with two schemes "A" and "B" whose per-trial MSEs are given.
fn two(a: Vec<f64>, b: Vec<f64>) -> Summary {
    let opts = build::LoadOptions {
        trials: Some(2),
        ..Default::default()
    };
    let text = crate::scenario::builtin::get("default").unwrap();
    let exp = build::load_with(text, "default", &opts).unwrap();
    let sums = runner::run(&exp, runner::RunOptions::default(), &|_| {}).unwrap();
    let mut s = results::summarize(&exp, &sums);
    s.trials = a.len();
    let mut sa = s.schemes[0].clone();
    let mut sb = s.schemes[0].clone();
    sa.name = "A".into();
    sb.name = "B".into();
    sa.per_trial = a.into_iter().map(|v| vec![v]).collect();
    sb.per_trial = b.into_iter().map(|v| vec![v]).collect();
    s.schemes = vec![sa, sb];
    s
}

fn better(s: &Summary) -> ClaimResult {
    let none = crate::scenario::Params::default();
    pairwise(
        s,
        "A beats B",
        ("A", &none),
        ("B", &none),
        "mse",
        |d, se, _, _| {
            if d == 0.0 && se == 0.0 {
                return (Verdict::Fails, None, "identical".into());
            }
            let z = d / se;
            (
                Verdict::of_z(z),
                trials_to_resolve(s.trials, z),
                String::new(),
            )
        },
    )
}

/// Per-trial values with mean 0 and standard error exactly `se` over 100 trials
/// (alternating +-sqrt(var)).
fn noise(se: f64) -> Vec<f64> {
    let n = 100.0_f64;
    // sample sd s with s / sqrt(n) = se; alternating +-c has sd c sqrt(n / (n - 1)).
    let c = se * n.sqrt() * ((n - 1.0) / n).sqrt();
    (0..100).map(|i| if i % 2 == 0 { c } else { -c }).collect()
}

#[test]
fn identical_schemes_never_beat_each_other() {
    let a: Vec<f64> = (0..100).map(|i| 1.0 + 0.01 * f64::from(i % 7)).collect();
    let s = two(a.clone(), a);
    let r = better(&s);
    assert!(!r.holds);
    assert_ne!(r.verdict, Verdict::Holds);
    // ...and in the other direction either.
    let none = crate::scenario::Params::default();
    let r2 = pairwise(
        &s,
        "B beats A",
        ("B", &none),
        ("A", &none),
        "mse",
        |d, se, _, _| (Verdict::of_z(d / se), None, String::new()),
    );
    assert_ne!(r2.verdict, Verdict::Holds);
}

#[test]
fn ten_standard_errors_hold_and_one_is_not_resolved() {
    let base: Vec<f64> = vec![2.0; 100];
    for (k, expected) in [
        (10.0, Verdict::Holds),
        (1.0, Verdict::NotResolved),
        (-10.0, Verdict::Fails),
    ] {
        let a: Vec<f64> = noise(0.01).iter().map(|e| 2.0 - k * 0.01 + e).collect();
        let r = better(&two(a, base.clone()));
        assert_eq!(r.verdict, expected, "{k} SE: {}", r.evidence);
        assert_eq!(r.holds, expected == Verdict::Holds);
        if expected == Verdict::NotResolved {
            // 1 SE at 100 trials: (2.5 / 1)^2 x 100 = 625 trials.
            assert_eq!(r.trials_to_resolve, Some(625));
            assert!(verdict_text(&r).contains("625 trials"));
        } else {
            assert_eq!(r.trials_to_resolve, None);
        }
    }
}

#[test]
fn trials_to_resolve_follows_the_square_law() {
    assert_eq!(trials_to_resolve(100, 1.25), Some(400));
    assert_eq!(trials_to_resolve(100, 0.0), None);
    assert_eq!(Verdict::of_z(-2.01), Verdict::Holds);
    assert_eq!(Verdict::of_z(1.99), Verdict::NotResolved);
    assert_eq!(Verdict::of_z(f64::NEG_INFINITY), Verdict::Holds);
}
