use super::*;

const M: ScalarModel = ScalarModel {
    a: 1.2,
    q: 1.0,
    r: 1.0,
    p0: 1.0,
};

/// The scalar DARE's prior fixed point for a = 1.2, q = r = 1: P² − 1.44 P − 1 = 0.
fn dare_prior() -> f64 {
    (1.44 + (1.44f64 * 1.44 + 4.0).sqrt()) / 2.0
}

#[test]
fn every_arrival_gives_the_riccati_fixed_point() {
    let sim = simulate(&M, &Arrivals::Bernoulli { gamma: 1.0 }, 200, 101, 50, 1);
    // Posterior of the DARE: P⁻ r / (P⁻ + r) = 1.952234 / 2.952234 = 0.661275…
    let post = dare_prior() / (dare_prior() + 1.0);
    assert!((post - 0.661_275).abs() < 1e-5, "{post}");
    for t in &sim.trace {
        assert!((t - post).abs() < 1e-12, "{t} vs {post}");
    }
    // γ = 1: the upper bound is the DARE, the lower bound q (posterior: 0).
    let (lo, hi) = posterior_bounds(&M, 1.0);
    assert_eq!(lo, Some(0.0));
    assert!((hi.expect("finite") - post).abs() < 1e-9);
    // The mapping is exact: (P⁻ − q) / a² is the posterior of the fixed point.
    assert!(((dare_prior() - 1.0) / 1.44 - post).abs() < 1e-12);
}

#[test]
fn no_arrival_is_the_open_loop_recursion() {
    // γ = 0: P_k = a^2k p0 + q (a^2k − 1)/(a² − 1), by hand for two steps (1, 2):
    // P1 = 1.44 + 1 = 2.44, P2 = 1.44 · 2.44 + 1 = 4.5136.
    let sim = simulate(&M, &Arrivals::Bernoulli { gamma: 0.0 }, 2, 1, 3, 2);
    assert!(sim
        .trace
        .iter()
        .all(|t| (t - (2.44 + 4.5136) / 2.0).abs() < 1e-12));
}

#[test]
fn bounds_near_the_critical_rate() {
    let gc = stability::critical_arrival_rate(1.2);
    // At γ_c the upper bound diverges; the lower bound's 1 − (1 − γ) a² rounds to about 1e-16
    // there, so it is either absent or astronomically large.
    let (lo, hi) = posterior_bounds(&M, gc);
    assert_eq!(hi, None);
    assert!(lo.is_none_or(|v| v > 1e12), "{lo:?}");
    assert_eq!(posterior_bounds(&M, 0.2), (None, None));
    // Just above: both finite and large, the lower one q(1 − γ)/(1 − (1 − γ)a²) by hand.
    let g = gc + 0.01;
    let (lo, hi) = posterior_bounds(&M, g);
    let (lo, hi) = (lo.expect("finite"), hi.expect("finite"));
    let by_hand = (1.0 - g) / (1.0 - (1.0 - g) * 1.44);
    assert!((lo - by_hand).abs() < 1e-9 * by_hand, "{lo} vs {by_hand}");
    assert!(lo > 40.0 && hi > lo, "{lo} {hi}");
}

#[test]
fn the_simulated_mean_lies_between_the_bounds_and_the_error_matches_it() {
    for gamma in [0.6, 0.8, 0.95] {
        let sim = simulate(&M, &Arrivals::Bernoulli { gamma }, 300, 101, 20_000, 3);
        let (mu, se) = mean_se(&sim.trace);
        let (lo, hi) = posterior_bounds(&M, gamma);
        let (lo, hi) = (lo.expect("finite"), hi.expect("finite"));
        assert!(
            mu > lo && mu < hi + 3.0 * se,
            "γ = {gamma}: {lo} < {mu} ± {se} < {hi}"
        );
        // E[e²] = E[P]: the simulated errors are consistent.
        let (e2, e2_se) = mean_se(&sim.squared_error);
        assert!(
            (e2 - mu).abs() < 4.0 * e2_se.hypot(se),
            "γ = {gamma}: {e2} ± {e2_se} vs {mu}"
        );
    }
}

#[test]
fn the_chain_starts_stationary() {
    // p_gb = 0.1, p_bg = 0.4: the bad state is occupied 0.2 of the time from the first step
    // on (the chain starts in its stationary law, as the link's does).
    let m = ScalarModel {
        a: 1.0,
        q: 1.0,
        r: 1e-12,
        p0: 1.0,
    };
    // With r ≈ 0 an arrival leaves P ≈ 0, a loss leaves P⁻ = p0 + q = 2: the mean posterior of
    // step 1 is P(bad at step 1) · 2 = 0.4.
    let sim = simulate(
        &m,
        &Arrivals::GilbertElliott {
            p_gb: 0.1,
            p_bg: 0.4,
        },
        1,
        1,
        200_000,
        4,
    );
    let (mu, se) = mean_se(&sim.trace);
    assert!((mu - 0.4).abs() < 4.0 * se, "{mu} ± {se}");
}

#[test]
fn rank_sum_sees_a_shift_and_not_a_tail() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(8);
    let pareto = |rng: &mut Xoshiro256PlusPlus, alpha: f64, scale: f64| -> Vec<f64> {
        (0..2000)
            .map(|_| scale * (1.0 - rng.random::<f64>()).powf(-1.0 / alpha))
            .collect()
    };
    // Same law, infinite variance: no difference.
    let (a, b) = (pareto(&mut rng, 1.2, 1.0), pareto(&mut rng, 1.2, 1.0));
    assert!(rank_sum_z(&a, &b).abs() < 3.0);
    // Scaled by 1.2: seen, and with the sign of the first sample's excess.
    let c = pareto(&mut rng, 1.2, 1.2);
    assert!(rank_sum_z(&c, &a) > 3.0);
    assert!(rank_sum_z(&a, &c) < -3.0);
    // By hand: [1, 2] against [3]: rank sum 3, U = 0, mean 1, sd sqrt(2·1·4/12).
    let z = rank_sum_z(&[1.0, 2.0], &[3.0]);
    assert!((z - (0.0 - 1.0) / (8.0f64 / 12.0).sqrt()).abs() < 1e-12);
}

#[test]
fn hill_recovers_a_pareto_index() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    for alpha in [0.7, 1.5] {
        let v: Vec<f64> = (0..5000)
            .map(|_| (1.0 - rng.random::<f64>()).powf(-1.0 / alpha))
            .collect();
        let (hat, se) = hill(&v, 500).expect("enough");
        assert!((hat - alpha).abs() < 3.0 * se, "{alpha}: {hat} ± {se}");
    }
    assert_eq!(hill(&[1.0, 2.0], 5), None);
}

#[test]
fn hill_on_the_recursion_separates_the_two_sides() {
    // What the `diverges` check reads, on the independent errors of 1000 trials: the tail
    // index below 1 well beyond the critical rate, above 1 where the mean is finite.
    let idx = |gamma: f64| {
        let sim = simulate(&M, &Arrivals::Bernoulli { gamma }, 400, 101, 1000, 6);
        hill(&sim.squared_error, 100).expect("enough")
    };
    let (lo, lo_se) = idx(0.2);
    assert!(lo + 2.0 * lo_se < 1.0, "γ = 0.2: {lo} ± {lo_se}");
    let (hi, hi_se) = idx(0.6);
    assert!(hi - 2.0 * hi_se > 1.0, "γ = 0.6: {hi} ± {hi_se}");
}
