//! What an `intermittent` claim ([`crate::scenario::ClaimSpec::Intermittent`]) is about: a
//! scalar linear system x' = a x + w, y = x + v observed over one lossy link, the setting of
//! Sinopoli, Schenato, Franceschetti, Poolla, Jordan and Sastry, "Kalman filtering with
//! intermittent observations", IEEE TAC 49(9), 2004 (Bernoulli arrivals) and of Huang and Dey,
//! "Stability of Kalman filtering with Markovian packet losses", Automatica 43(4), 2007
//! (Gilbert–Elliott bursts). Read from the scenario and checked before anything runs; the
//! claim's independent computation lives with its verdict (`output::report`).
use crate::network::channel::ChannelSpec;
use crate::scheme::System;

/// The scheme kind the claim is about: the Kalman filter on every measurement that arrives,
/// whose error variance is the data-free recursion the theory studies.
pub const FILTER_KIND: &str = "centralized-kf";

/// The scalar model: x_{k+1} = a x_k + w_k (Var w = q), y_k = x_k + v_k (Var v = r), prior
/// variance `p0` of x_0 (the filter's first step predicts it to a² p0 + q).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarModel {
    pub a: f64,
    pub q: f64,
    pub r: f64,
    pub p0: f64,
}

impl ScalarModel {
    /// The scalar model of `system`, or why it is not one (one state, one linear sensor with
    /// H = \[1\]).
    pub fn of(system: &System) -> Result<Self, String> {
        if system.state_dim() != 1 || system.n_sensors() != 1 {
            return Err(format!(
                "needs a scalar system with one sensor (state dimension {}, {} sensors)",
                system.state_dim(),
                system.n_sensors()
            ));
        }
        let Some(lin) = system.sensors[0].as_linear() else {
            return Err("needs a linear sensor (y = x + v)".into());
        };
        let h = lin.h()[(0, 0)];
        if h != 1.0 {
            return Err(format!(
                "needs H = [[1]] (the theory's y = x + v), got H = [[{h}]]"
            ));
        }
        Ok(Self {
            a: system.transition.f()[(0, 0)],
            q: system.transition.q()[(0, 0)],
            r: system.sensors[0].noise_cov()[(0, 0)],
            p0: system.prior.cov[(0, 0)],
        })
    }
}

/// How measurements arrive: the law of the link's losses (each link model says its own).
pub use crate::network::channel::models::Arrivals;

impl Arrivals {
    /// The arrival law of a variant's link (`None`: ideal), or why the claim cannot use it: no
    /// delay, no retransmission, and for Gilbert–Elliott `loss_good = 0`, `loss_bad = 1` (the
    /// case whose stability condition is known in closed form).
    pub fn of(spec: Option<&ChannelSpec>) -> Result<Self, String> {
        let Some(spec) = spec else {
            return Ok(Arrivals::Bernoulli { gamma: 1.0 });
        };
        if !spec.delay().is_zero() || spec.arq.is_some() {
            return Err("needs a link without delay and without arq".into());
        }
        (spec.kind.model().arrivals)(spec)
    }

    /// The probability that a loss run goes on one more step: 1 − γ (Bernoulli), 1 − p_bg
    /// (Gilbert–Elliott: the bad state's persistence). During a run the variance grows by a²
    /// per step, so the k-th moment of the stationary variance is finite exactly when
    /// `persistence` · a^{2k} < 1 (k = 1: Sinopoli et al. 2004, Theorem 2, scalar; Huang and Dey
    /// 2007 for the bursts).
    pub fn persistence(&self) -> f64 {
        match *self {
            Arrivals::Bernoulli { gamma } => 1.0 - gamma,
            Arrivals::GilbertElliott { p_bg, .. } => 1.0 - p_bg,
        }
    }

    /// The swept quantity the theory is stated in: γ (Bernoulli) or p_bg (Gilbert–Elliott).
    pub fn abscissa(&self) -> f64 {
        match *self {
            Arrivals::Bernoulli { gamma } => gamma,
            Arrivals::GilbertElliott { p_bg, .. } => p_bg,
        }
    }
}

/// Where a variant stands with respect to the theory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    /// Finite mean and finite variance: a Monte Carlo mean has a valid standard error.
    FiniteVariance,
    /// Finite mean, infinite variance: the mean exists but a standard error does not describe
    /// the noise of a sample mean.
    HeavyTail,
    /// At or beyond the critical value: the expected error variance grows without bound.
    Diverges,
}

/// The regime of `arrivals` on a system with growth `a`: the mean is finite when
/// persistence · a² < 1, the variance when persistence · a⁴ < 1.
pub fn regime(a: f64, arrivals: &Arrivals) -> Regime {
    let p = arrivals.persistence();
    let a2 = a * a;
    if p * a2 >= 1.0 {
        Regime::Diverges
    } else if p * a2 * a2 >= 1.0 {
        Regime::HeavyTail
    } else {
        Regime::FiniteVariance
    }
}

/// The tail index α of the stationary error variance: P(P > x) decays like x^(−α), with
/// α = ln(1 / persistence) / ln(a²) (a loss run of length L, probability persistence^L,
/// multiplies the variance by a^{2L}). The mean is finite iff α > 1, the variance iff α > 2.
/// Infinite for |a| ≤ 1 or a link that never loses a run.
pub fn tail_index(a: f64, arrivals: &Arrivals) -> f64 {
    let p = arrivals.persistence();
    let a2 = a * a;
    if a2 <= 1.0 || p <= 0.0 {
        f64::INFINITY
    } else {
        (1.0 / p).ln() / a2.ln()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regimes_of_the_built_in_system() {
        // a = 1.2: the mean diverges for γ ≤ 1 − 1/1.44 = 0.3056, the variance for
        // γ ≤ 1 − 1/1.44² = 0.5177.
        let b = |gamma| regime(1.2, &Arrivals::Bernoulli { gamma });
        assert_eq!(b(0.6), Regime::FiniteVariance);
        assert_eq!(b(0.5), Regime::HeavyTail);
        assert_eq!(b(0.32), Regime::HeavyTail);
        assert_eq!(b(0.3), Regime::Diverges);
        let ge = |p_bg| regime(1.2, &Arrivals::GilbertElliott { p_gb: 0.1, p_bg });
        assert_eq!(ge(0.6), Regime::FiniteVariance);
        assert_eq!(ge(0.4), Regime::HeavyTail);
        assert_eq!(ge(0.25), Regime::Diverges);
        // The tail index is 1 at the critical rate, 2 where the variance stops being finite.
        let gc = 1.0 - 1.0 / 1.44;
        assert!((tail_index(1.2, &Arrivals::Bernoulli { gamma: gc }) - 1.0).abs() < 1e-12);
        let g2 = 1.0 - 1.0 / (1.44 * 1.44);
        assert!((tail_index(1.2, &Arrivals::Bernoulli { gamma: g2 }) - 2.0).abs() < 1e-12);
        assert_eq!(
            tail_index(0.9, &Arrivals::Bernoulli { gamma: 0.1 }),
            f64::INFINITY
        );
    }
}
