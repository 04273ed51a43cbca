//! The classical stability checks of Kalman filtering over a lossy link, for the scalar model
//! x_{k+1} = a x_k + w_k, y_k = x_k + v_k (c = 1), q = Var w, r = Var v, where each measurement
//! arrives with probability γ (Sinopoli, Schenato, Franceschetti, Poolla, Jordan and Sastry,
//! "Kalman filtering with intermittent observations", IEEE TAC 49(9), 2004).
//!
//! All bounds are on the expected PRIOR (predicted) error variance E[P_{k|k−1}], the quantity
//! the paper's recursion P_{k+1} = a² P_k + q − γ_k a² P_k² / (P_k + r) tracks; the posterior is
//! smaller by the update of the step.

/// The critical arrival rate γ_c = 1 − 1/a², 0 when |a| ≤ 1 (Sinopoli et al. 2004, Theorems 2
/// and 3, scalar case with C invertible: the lower and upper bounds on γ_c then coincide at
/// 1 − 1/max|λ(A)|²). Above γ_c the expected prior variance
/// stays bounded for every initial condition; at or below it, it diverges.
pub fn critical_arrival_rate(a: f64) -> f64 {
    if a.abs() <= 1.0 {
        0.0
    } else {
        1.0 - 1.0 / (a * a)
    }
}

/// Lower bound on lim E[P_{k|k−1}]: the fixed point S̄ of S = (1 − γ) a² S + q (Sinopoli et al.
/// 2004, Theorem 3: the bound obtained as if every arriving measurement removed all
/// uncertainty), S̄ = q / (1 − (1 − γ) a²). `None` when (1 − γ) a² ≥ 1: the lower bound itself
/// diverges, and so does the expected variance.
pub fn lower_bound(a: f64, q: f64, gamma: f64) -> Option<f64> {
    let growth = (1.0 - gamma) * a * a;
    if growth < 1.0 {
        Some(q / (1.0 - growth))
    } else {
        None
    }
}

/// The modified algebraic Riccati map g_γ(V) = a² V + q − γ a² V² / (V + r) (Sinopoli et al.
/// 2004, eq. for V̄ in Theorem 3, scalar case with c = 1).
fn mare_map(a: f64, q: f64, r: f64, gamma: f64, v: f64) -> f64 {
    let a2 = a * a;
    a2 * v + q - gamma * a2 * v * v / (v + r)
}

/// Iterations allowed to [`upper_bound`]; near γ_c the map contracts by about (1 − γ) a² per
/// step, so this leaves room for a contraction as slow as 1 − 10⁻⁵.
const MARE_MAX_ITERATIONS: usize = 10_000_000;

/// Upper bound on lim E[P_{k|k−1}]: the fixed point V̄ of the modified algebraic Riccati equation
/// V = a² V + q − γ a² V² / (V + r) (Sinopoli et al. 2004, Theorem 3, scalar MARE), found by
/// iterating the map from V = q. The map is increasing and g(q) ≥ q, so the iterates increase
/// monotonically to the fixed point when one exists. `None` when the expected variance diverges
/// ((1 − γ) a² ≥ 1, i.e. γ ≤ γ_c for |a| > 1), when the iterates stop being finite, or when they
/// have not settled after `MARE_MAX_ITERATIONS` steps (γ within about 10⁻⁵ of γ_c).
pub fn upper_bound(a: f64, q: f64, r: f64, gamma: f64) -> Option<f64> {
    if (1.0 - gamma) * a * a >= 1.0 {
        return None;
    }
    let mut v = q;
    for _ in 0..MARE_MAX_ITERATIONS {
        let next = mare_map(a, q, r, gamma, v);
        if !next.is_finite() {
            return None;
        }
        // Relative tolerance, with an absolute floor for a variance near 0 (q = 0).
        if (next - v).abs() <= 1e-13 * next.abs().max(1e-300) {
            return Some(next);
        }
        v = next;
    }
    None
}

/// The data-free variance recursion of a Kalman filter given which measurements arrived
/// (the stochastic Riccati recursion of Sinopoli et al. 2004, scalar): at step k, the update
/// P⁺ = P − γ_k P² / (P + r), then the prediction P_next = a² P⁺ + q.
/// `p0` is the prior variance of the first step, P_{1|0}; the result has `arrivals.len() + 1`
/// entries, entry k being the prior variance after `arrivals[..k]`, P_{k+1|k}.
pub fn prior_variance_path(a: f64, q: f64, r: f64, p0: f64, arrivals: &[bool]) -> Vec<f64> {
    let mut path = Vec::with_capacity(arrivals.len() + 1);
    let mut p = p0;
    path.push(p);
    for &arrived in arrivals {
        let posterior = if arrived && p + r > 0.0 {
            p - p * p / (p + r)
        } else if arrived {
            // P = r = 0: a noiseless measurement of a known state leaves it known.
            0.0
        } else {
            p
        };
        p = a * a * posterior + q;
        path.push(p);
    }
    path
}

/// Whether the filter is stable over a Gilbert–Elliott link whose bad state loses every packet
/// and whose good state delivers: a² (1 − p_bg) < 1. A stay in the bad state lasts k steps with
/// probability p_bg (1 − p_bg)^{k−1} while the variance grows like a^{2k}, so the expected peak
/// variance is finite exactly when a² (1 − p_bg) < 1 (the scalar case of Huang and Dey,
/// "Stability of Kalman filtering with Markovian packet losses", Automatica 43(4), 2007).
/// Equivalently p_bg > 1 − 1/a² = [`critical_arrival_rate`]`(a)`.
pub fn gilbert_elliott_stable(a: f64, p_bg: f64) -> bool {
    a * a * (1.0 - p_bg) < 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn close(x: f64, y: f64, tol: f64) -> bool {
        (x - y).abs() <= tol
    }

    /// The positive root of the scalar MARE written as a quadratic: multiplying by (V + r),
    /// α V² + (r (1 − a²) − q) V − q r = 0 with α = 1 − (1 − γ) a².
    fn mare_closed_form(a: f64, q: f64, r: f64, gamma: f64) -> f64 {
        let alpha = 1.0 - (1.0 - gamma) * a * a;
        let b = r * (1.0 - a * a) - q;
        (-b + (b * b + 4.0 * alpha * q * r).sqrt()) / (2.0 * alpha)
    }

    #[test]
    fn critical_rate_hand_values() {
        // a = 1.2: 1 − 1/1.44 = 0.305555…
        assert!(close(critical_arrival_rate(1.2), 0.305_555_555_6, 1e-9));
        assert!(close(critical_arrival_rate(-2.0), 0.75, 1e-15));
        assert_eq!(critical_arrival_rate(1.0), 0.0);
        assert_eq!(critical_arrival_rate(0.5), 0.0);
    }

    #[test]
    fn lower_bound_hand_values() {
        // a = 1.2, q = 1, γ = 0.5: (1 − γ) a² = 0.72, S̄ = 1/0.28 = 3.571428…
        let s = lower_bound(1.2, 1.0, 0.5).expect("finite");
        assert!(close(s, 3.571_428_571_4, 1e-9), "{s}");
        // γ = 1: every measurement arrives, the bound is q.
        assert_eq!(lower_bound(1.2, 1.0, 1.0), Some(1.0));
        // Below the critical rate the lower bound itself diverges.
        assert_eq!(lower_bound(1.2, 1.0, 0.3), None);
        // A stable system has a finite bound even with no arrivals: q / (1 − a²).
        assert!(close(
            lower_bound(0.5, 1.0, 0.0).expect("finite"),
            4.0 / 3.0,
            1e-12
        ));
    }

    #[test]
    fn upper_bound_matches_closed_form() {
        // a = 1.2, q = r = 1, γ = 0.8: 0.712 V² − 1.44 V − 1 = 0, V = 2.5692…
        let v = upper_bound(1.2, 1.0, 1.0, 0.8).expect("converges");
        assert!(close(v, mare_closed_form(1.2, 1.0, 1.0, 0.8), 1e-9), "{v}");
        assert!(close(v, (1.44 + 4.9216f64.sqrt()) / 1.424, 1e-9), "{v}");
        for &(a, q, r, g) in &[
            (0.9, 2.0, 0.5, 0.0),
            (1.5, 0.3, 2.0, 0.7),
            (3.0, 1.0, 1.0, 0.95),
        ] {
            let v = upper_bound(a, q, r, g).expect("converges");
            let exact = mare_closed_form(a, q, r, g);
            assert!(close(v, exact, 1e-9 * exact), "a={a} γ={g}: {v} vs {exact}");
        }
    }

    #[test]
    fn upper_bound_diverges_at_and_below_critical() {
        let gc = critical_arrival_rate(1.2);
        assert_eq!(upper_bound(1.2, 1.0, 1.0, gc), None);
        assert_eq!(upper_bound(1.2, 1.0, 1.0, 0.2), None);
        assert_eq!(upper_bound(1.0, 1.0, 1.0, 0.0), None);
        // Just above the critical rate it is finite, though large.
        let v = upper_bound(1.2, 1.0, 1.0, gc + 1e-3).expect("converges");
        assert!(v > 100.0, "{v}");
    }

    #[test]
    fn upper_is_above_lower_above_critical() {
        let (a, q, r) = (1.2, 1.0, 1.0);
        for &g in &[0.31, 0.4, 0.5, 0.6, 0.8, 0.9, 0.99, 1.0] {
            let lo = lower_bound(a, q, g).expect("finite lower");
            let up = upper_bound(a, q, r, g).expect("finite upper");
            assert!(up >= lo, "γ = {g}: upper {up} < lower {lo}");
        }
    }

    #[test]
    fn upper_tends_to_the_riccati_fixed_point() {
        // γ = 1 is the standard scalar DARE P = a² P r / (P + r) + q; with a = 1.2, q = r = 1:
        // P² − 1.44 P − 1 = 0, P = (1.44 + sqrt(1.44² + 4)) / 2 = 1.952234…
        let dare = (1.44 + (1.44f64 * 1.44 + 4.0).sqrt()) / 2.0;
        assert!(close(dare, 1.952_234, 1e-6));
        let at_one = upper_bound(1.2, 1.0, 1.0, 1.0).expect("converges");
        assert!(close(at_one, dare, 1e-9), "{at_one}");
        let mut last_gap = f64::INFINITY;
        for &g in &[0.9, 0.99, 0.999, 0.9999] {
            let gap = upper_bound(1.2, 1.0, 1.0, g).expect("converges") - dare;
            assert!(gap > 0.0 && gap < last_gap, "γ = {g}: gap {gap}");
            last_gap = gap;
        }
        assert!(last_gap < 1e-3, "{last_gap}");
    }

    #[test]
    fn path_follows_the_recursion() {
        // a = 2, q = 1, r = 1, P0 = 1: arrival → P⁺ = 1 − 1/2 = 0.5, P = 4·0.5 + 1 = 3;
        // loss → P = 4·3 + 1 = 13; arrival → P⁺ = 13 − 169/14 = 13/14, P = 52/14 + 1.
        let path = prior_variance_path(2.0, 1.0, 1.0, 1.0, &[true, false, true]);
        assert_eq!(path.len(), 4);
        assert_eq!(path[0], 1.0);
        assert!(close(path[1], 3.0, 1e-12));
        assert!(close(path[2], 13.0, 1e-12));
        assert!(close(path[3], 52.0 / 14.0 + 1.0, 1e-12));
        // Always arriving, the path converges to the DARE fixed point.
        let path = prior_variance_path(1.2, 1.0, 1.0, 10.0, &[true; 200]);
        let dare = (1.44 + (1.44f64 * 1.44 + 4.0).sqrt()) / 2.0;
        assert!(close(path[200], dare, 1e-9));
        // r = 0 and P = 0: a perfect measurement of a known state.
        assert_eq!(
            prior_variance_path(1.0, 0.0, 0.0, 0.0, &[true]),
            vec![0.0, 0.0]
        );
    }

    #[test]
    fn monte_carlo_mean_lies_between_bounds() {
        let (a, q, r, gamma) = (1.2, 1.0, 1.0, 0.8);
        let lo = lower_bound(a, q, gamma).expect("finite");
        let up = upper_bound(a, q, r, gamma).expect("finite");
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x0051_AB1E);
        // Independent paths, each with a long burn-in so its last value is a draw from the
        // stationary regime ((1 − γ) a² = 0.288: the start is forgotten geometrically fast).
        let (paths, burn_in) = (20_000, 200);
        let mut arrivals = vec![false; burn_in];
        let samples: Vec<f64> = (0..paths)
            .map(|_| {
                arrivals
                    .iter_mut()
                    .for_each(|x| *x = rng.random::<f64>() < gamma);
                let path = prior_variance_path(a, q, r, q, &arrivals);
                path[burn_in]
            })
            .collect();
        let n = samples.len() as f64;
        let mean = samples.iter().sum::<f64>() / n;
        let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0);
        // Sample SE of the mean; 4 SE margin on each side (finite: (1 − γ) a⁴ = 0.41 < 1, so
        // the stationary variance has a finite second moment).
        let se = (var / n).sqrt();
        assert!(
            mean > lo - 4.0 * se && mean < up + 4.0 * se,
            "mean {mean} (se {se}) outside [{lo}, {up}]"
        );
        // The bounds are not trivially loose here: the mean is strictly inside.
        assert!(
            mean > lo && mean < up,
            "mean {mean} not strictly in [{lo}, {up}]"
        );
    }

    #[test]
    fn gilbert_elliott_flag_on_both_sides() {
        // a = 1.2: the threshold is p_bg = 1 − 1/1.44 = 0.30556.
        let threshold = critical_arrival_rate(1.2);
        assert!(gilbert_elliott_stable(1.2, threshold + 0.01));
        assert!(!gilbert_elliott_stable(1.2, threshold - 0.01));
        assert!(gilbert_elliott_stable(1.2, 1.0));
        assert!(!gilbert_elliott_stable(1.2, 0.0));
        // A stable system is stable over any link.
        assert!(gilbert_elliott_stable(0.9, 0.0));
    }
}
