//! The `intermittent` claims: Kalman filtering with intermittent observations (Sinopoli et al.
//! 2004) and over Gilbert–Elliott bursts (Huang and Dey 2007), checked against an independent
//! computation.
//!
//! **The independent computation.** For each variant, [`simulate`] draws `sequences` arrival
//! sequences from its own generator (seeded here, unrelated to the run's streams): Bernoulli
//! coins, or the Gilbert–Elliott chain started in its stationary law as the link starts it. On
//! each it runs the scalar filter's data-free variance recursion and, beside it, the filter's
//! error e_k (its own Gaussian noise draws): prediction e⁻ = a e + w, P⁻ = a² P + q; on an
//! arrival K = P⁻ / (P⁻ + r), e = (1 − K) e⁻ − K v, P = (1 − K) P⁻. Each sequence gives the
//! time averages over the run's steady-state window of the posterior variance P_{k|k} (what
//! the engine's `trace` is) and of e_k² (what its MSE is): the same quantities, from the same
//! start (prior variance p0) over the same steps, so their expectations are equal to the
//! engine's exactly, with no steady-state approximation.
//!
//! **Prior and posterior.** Sinopoli's bounds are on the prior (predicted) variance
//! E[P_{k+1|k}]; on every path P_{k+1|k} = a² P_{k|k} + q, so a bound B on the prior is the bound
//! (B − q) / a² on the posterior. We compare posterior with posterior.
//!
//! **Honest standard errors.** The stationary variance has tail index α = ln(1/persistence) /
//! ln(a²) ([`crate::scenario::intermittent::tail_index`]): its mean is finite for α > 1 and its
//! variance for α > 2. Only where the variance is finite is a sample mean's standard error
//! meaningful; there the checks use it. Where the mean is finite but the variance is not, the
//! engine's per-trial squared errors are compared with the independent ones by ranks
//! (Mann–Whitney, blind to the tail): a difference beyond the quantile fails, agreement is
//! consistent but not counted as evidence for the claim. At and beyond the critical value the
//! expectation is infinite and no sample mean can show it; the `diverges` check therefore
//! reads the tail of the engine's per-trial errors (Hill's estimator of α on the largest
//! tenth): it holds when α < 1 by more than two standard errors. Family-wise, a point fails
//! only beyond the Bonferroni quantile of the points checked (5% in all).
use super::verdict::{trials_to_resolve, ClaimResult, Verdict, Z_DECIDE};
use crate::metrics::results::{SchemeSummary, Summary};
use crate::network::channel::stability;
use crate::scenario::build::Experiment;
use crate::scenario::intermittent::{regime, tail_index, Arrivals, Regime, ScalarModel};
use crate::scenario::IntermittentCheck;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Default number of independent arrival sequences per variant.
pub const DEFAULT_SEQUENCES: usize = 20_000;
/// Default relative resolution of the equality and bounds checks.
pub const DEFAULT_WITHIN: f64 = 0.05;
/// Seed of the claim checker's own generator (per variant: this plus the variant's index).
const SEED: u64 = 0x5140_2004;
/// Family-wise error rate of a failure.
const FAMILY_ALPHA: f64 = 0.05;

/// Per-sequence steady-state time averages of the independent computation.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulated {
    /// Time average of the posterior variance P_{k|k} over the window, per sequence.
    pub trace: Vec<f64>,
    /// Time average of the squared error e_k² over the window, per sequence.
    pub squared_error: Vec<f64>,
}

/// Mean and standard error of the mean.
pub fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, (var / n).sqrt())
}

/// The independent computation (module docs): `sequences` arrival sequences of `steps` steps,
/// averaged over steps `from..=steps`.
pub fn simulate(
    m: &ScalarModel,
    arrivals: &Arrivals,
    steps: usize,
    from: usize,
    sequences: usize,
    seed: u64,
) -> Simulated {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let (sq, sr, sp) = (m.q.sqrt(), m.r.sqrt(), m.p0.sqrt());
    let window = (steps + 1 - from.min(steps)) as f64;
    let mut out = Simulated {
        trace: Vec::with_capacity(sequences),
        squared_error: Vec::with_capacity(sequences),
    };
    for _ in 0..sequences {
        let mut bad = match *arrivals {
            Arrivals::GilbertElliott { p_gb, p_bg } => {
                let total = p_gb + p_bg;
                total > 0.0 && rng.random::<f64>() < p_gb / total
            }
            Arrivals::Bernoulli { .. } => false,
        };
        let (mut p, mut e) = (m.p0, sp * rng.sample::<f64, _>(StandardNormal));
        let (mut sum_p, mut sum_e) = (0.0, 0.0);
        for k in 1..=steps {
            let arrived = match *arrivals {
                Arrivals::Bernoulli { gamma } => rng.random::<f64>() < gamma,
                Arrivals::GilbertElliott { p_gb, p_bg } => {
                    let u = rng.random::<f64>();
                    bad = if bad { u >= p_bg } else { u < p_gb };
                    !bad
                }
            };
            p = m.a * m.a * p + m.q;
            e = m.a * e + sq * rng.sample::<f64, _>(StandardNormal);
            if arrived {
                let gain = p / (p + m.r);
                e = (1.0 - gain) * e - gain * sr * rng.sample::<f64, _>(StandardNormal);
                p *= 1.0 - gain;
            }
            if k >= from {
                sum_p += p;
                sum_e += e * e;
            }
        }
        out.trace.push(sum_p / window);
        out.squared_error.push(sum_e / window);
    }
    out
}

/// Sinopoli's bounds (lower, upper) on the steady-state POSTERIOR variance at arrival rate
/// `gamma`: the prior bounds B mapped by (B − q) / a²; `None` where a bound diverges.
pub fn posterior_bounds(m: &ScalarModel, gamma: f64) -> (Option<f64>, Option<f64>) {
    let post = |b: f64| (b - m.q) / (m.a * m.a);
    (
        stability::lower_bound(m.a, m.q, gamma).map(post),
        stability::upper_bound(m.a, m.q, m.r, gamma).map(post),
    )
}

/// Hill's estimator of the tail index from the `k` largest of `v` (k + 1 ≤ len), with its
/// asymptotic standard error α̂ / √k.
pub fn hill(v: &[f64], k: usize) -> Option<(f64, f64)> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| *x > 0.0).collect();
    if k < 2 || s.len() <= k {
        return None;
    }
    s.sort_by(|a, b| b.total_cmp(a));
    let threshold = s[k].ln();
    let mean_log = s[..k].iter().map(|x| x.ln() - threshold).sum::<f64>() / k as f64;
    (mean_log > 0.0).then(|| {
        let alpha = 1.0 / mean_log;
        (alpha, alpha / (k as f64).sqrt())
    })
}

/// The Mann–Whitney rank-sum statistic of `a` against `b` as a z (normal approximation,
/// continuous values): positive when `a` tends to be larger. Ranks do not care how heavy a tail
/// is, so this compares two samples of a variable whose variance is infinite.
pub fn rank_sum_z(a: &[f64], b: &[f64]) -> f64 {
    let mut all: Vec<(f64, bool)> = a
        .iter()
        .map(|&x| (x, true))
        .chain(b.iter().map(|&x| (x, false)))
        .collect();
    all.sort_by(|x, y| x.0.total_cmp(&y.0));
    let rank_sum: f64 = all
        .iter()
        .enumerate()
        .filter(|(_, (_, first))| *first)
        .map(|(i, _)| (i + 1) as f64)
        .sum();
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    let u = rank_sum - n1 * (n1 + 1.0) / 2.0;
    (u - n1 * n2 / 2.0) / (n1 * n2 * (n1 + n2 + 1.0) / 12.0).sqrt()
}

/// One variant of the claim's curve, with what the theory says of it.
pub struct Point<'a> {
    pub variant: usize,
    pub summary: &'a SchemeSummary,
    pub arrivals: Arrivals,
    pub regime: Regime,
}

/// The variants of curve `scheme`, in sweep order, with their arrival laws.
pub fn points<'a>(
    exp: &Experiment,
    summary: &'a Summary,
    scheme: &str,
) -> Result<Vec<Point<'a>>, String> {
    let m = ScalarModel::of(&exp.system)?;
    let ci = exp
        .curves
        .iter()
        .position(|c| c.label == scheme)
        .ok_or_else(|| format!("no scheme labelled {scheme:?} in this scenario"))?;
    let mut out = Vec::new();
    for (v, s) in summary.schemes.iter().enumerate() {
        if exp.variants[v].curve != ci {
            continue;
        }
        let arrivals = Arrivals::of(exp.variants[v].channel.as_deref().map(|c| &c[0]))?;
        out.push(Point {
            variant: v,
            summary: s,
            arrivals,
            regime: regime(m.a, &arrivals),
        });
    }
    Ok(out)
}

/// The independent computation of variant `v` of `exp`.
pub fn simulate_variant(
    exp: &Experiment,
    m: &ScalarModel,
    p: &Point,
    sequences: usize,
) -> Simulated {
    simulate(
        m,
        &p.arrivals,
        exp.steps,
        exp.steady_from,
        sequences,
        SEED.wrapping_add(p.variant as u64),
    )
}

/// "γ = 0.3" or "p_bg = 0.25", trimmed to six decimals.
fn abscissa_text(a: &Arrivals) -> String {
    let x = crate::scenario::ParamValue::Number(a.abscissa());
    match a {
        Arrivals::Bernoulli { .. } => format!("γ = {x}"),
        Arrivals::GilbertElliott { .. } => format!("p_bg = {x}"),
    }
}

/// How a point went: its verdict (`None`: not counted) and its words.
struct Outcome {
    verdict: Option<Verdict>,
    need: Option<usize>,
    words: String,
}

/// Checks an `intermittent` claim.
pub fn check(
    exp: &Experiment,
    summary: &Summary,
    text: &str,
    scheme: &str,
    check: IntermittentCheck,
    (within, sequences, range): (Option<f64>, Option<usize>, Option<[f64; 2]>),
) -> ClaimResult {
    let within = within.unwrap_or(DEFAULT_WITHIN);
    let sequences = sequences.unwrap_or(DEFAULT_SEQUENCES);
    let [lo, hi] = range.unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
    let (m, pts) =
        match ScalarModel::of(&exp.system).and_then(|m| Ok((m, points(exp, summary, scheme)?))) {
            Ok(x) => x,
            Err(e) => return ClaimResult::new(text, Verdict::Fails, None, e),
        };
    let in_scope = |p: &Point| {
        let x = p.arrivals.abscissa();
        (p.regime == Regime::Diverges) == (check == IntermittentCheck::Diverges)
            && x >= lo - 1e-12
            && x <= hi + 1e-12
    };
    let checked = pts.iter().filter(|p| in_scope(p)).count().max(1);
    // Two-sided Bonferroni quantile of the family of checked points.
    let z_fail = crate::stats::normal::inv_cdf(1.0 - FAMILY_ALPHA / (2.0 * checked as f64));
    let mut verdict: Option<Verdict> = None;
    let mut need: Option<usize> = None;
    let mut words = Vec::new();
    for p in &pts {
        if !in_scope(p) {
            continue;
        }
        let o = match check {
            IntermittentCheck::Diverges => diverges(exp, &m, p, z_fail),
            _ => finite(exp, &m, p, (check, within, sequences), z_fail),
        };
        if let Some(v) = o.verdict {
            verdict = Some(verdict.map_or(v, |w| w.and(v)));
            if v == Verdict::NotResolved {
                need = need.max(o.need);
            }
        }
        words.push(o.words);
    }
    let verdict = verdict.unwrap_or_else(|| {
        words.push("no point could decide the claim".into());
        Verdict::NotResolved
    });
    let criterion = match check {
        IntermittentCheck::Diverges => format!(
            "criterion: Hill's tail index of the per-trial steady-state MSE below 1 by more than {Z_DECIDE} standard errors; fails above 1 by more than {z_fail:.2}"
        ),
        _ => format!(
            "criterion where the variance is finite: within {z_fail:.2} combined standard errors (Bonferroni over {checked} points, 5%), with {z_fail:.2} standard errors at most {:.0}% of the value; heavy-tailed points: per-trial errors against the recursion's by ranks within {z_fail:.2}, not counted",
            100.0 * within
        ),
    };
    ClaimResult::new(
        text,
        verdict,
        need,
        format!("{criterion}. {}", words.join("; ")),
    )
}

/// A point where the mean is finite: bounds, or equality with the recursion.
fn finite(
    exp: &Experiment,
    m: &ScalarModel,
    p: &Point,
    (check, within, sequences): (IntermittentCheck, f64, usize),
    z_fail: f64,
) -> Outcome {
    let ss = &p.summary.steady_state;
    let sim = simulate_variant(exp, m, p, sequences);
    let (ours, ours_se) = match check {
        IntermittentCheck::MseRecursion => (ss.mse, ss.mse_se),
        _ => (ss.trace, ss.trace_se),
    };
    let (mu, mu_se) = mean_se(&sim.trace);
    let x = abscissa_text(&p.arrivals);
    if p.regime == Regime::HeavyTail {
        // Means are not comparable by standard errors here: compare the per-trial squared
        // errors with the independent ones by ranks.
        let per_trial: Vec<f64> = p.summary.per_trial.iter().map(|r| r[0]).collect();
        if per_trial.is_empty() {
            return Outcome {
                verdict: None,
                need: None,
                words: format!("{x}: heavy tail, and no per-trial values to compare (not counted)"),
            };
        }
        let z = rank_sum_z(&per_trial, &sim.squared_error);
        let fails = z.abs() > z_fail;
        return Outcome {
            verdict: fails.then_some(Verdict::Fails),
            need: None,
            words: format!(
                "{x}: ours {ours:.4}, recursion {mu:.4}; heavy tail (α = {:.2} < 2: no standard error), per-trial squared errors against the recursion's by ranks z = {z:.2}: {}",
                tail_index(m.a, &p.arrivals),
                if fails { "FAILS" } else { "consistent (not counted)" }
            ),
        };
    }
    let noise = |s: f64| -> (Verdict, Option<usize>) {
        if z_fail * s <= within * mu.abs() {
            (Verdict::Holds, None)
        } else {
            let need = (exp.trials as f64 * (z_fail * s / (within * mu.abs())).powi(2)).ceil();
            (Verdict::NotResolved, Some(need as usize))
        }
    };
    if check == IntermittentCheck::Bounds {
        let Arrivals::Bernoulli { gamma } = p.arrivals else {
            return Outcome {
                verdict: Some(Verdict::Fails),
                need: None,
                words: "Sinopoli's bounds are for Bernoulli arrivals".into(),
            };
        };
        let (lo, hi) = posterior_bounds(m, gamma);
        let (lo, hi) = (lo.unwrap_or(0.0), hi.unwrap_or(f64::INFINITY));
        // Positive when outside: how far beyond the nearer bound, in standard errors.
        let z = (lo - ours).max(ours - hi) / ours_se;
        let (v, need) = if z > z_fail {
            (Verdict::Fails, None)
        } else {
            noise(ours_se)
        };
        return Outcome {
            verdict: Some(v),
            need,
            words: format!(
                "{}: lower {lo:.4} ≤ ours {ours:.4} ± {ours_se:.4} ≤ upper {hi:.4} (posterior equivalents; recursion {mu:.4} ± {mu_se:.4}; {} by {:.1} SE): {}",
                abscissa_text(&p.arrivals),
                if z <= 0.0 { "inside" } else { "outside" },
                z.abs(),
                v.label()
            ),
        };
    }
    // E[e²] = E[P] given the arrivals: both checks compare with the recursion's mean.
    let s = ours_se.hypot(mu_se);
    let d = ours - mu;
    let z = d / s;
    let (v, need) = if z.abs() > z_fail {
        (Verdict::Fails, None)
    } else {
        noise(s)
    };
    Outcome {
        verdict: Some(v),
        need,
        words: format!(
            "{x}: ours {ours:.4} ± {ours_se:.4}, recursion {mu:.4} ± {mu_se:.4}, z = {z:.2}: {}",
            v.label()
        ),
    }
}

/// A point at or beyond the critical value: the tail of the per-trial errors.
fn diverges(exp: &Experiment, m: &ScalarModel, p: &Point, z_fail: f64) -> Outcome {
    let per_trial: Vec<f64> = p.summary.per_trial.iter().map(|r| r[0]).collect();
    let k = (per_trial.len() / 10).max(10);
    let alpha = tail_index(m.a, &p.arrivals);
    let x = abscissa_text(&p.arrivals);
    let horizon = match p.arrivals {
        // Sinopoli's lower bound recursion S_{k+1} = (1 − γ) a² S_k + q from P_{1|0}: at the
        // last step E[P_{T|T−1}] is at least this.
        Arrivals::Bernoulli { gamma } => {
            let mut s = m.a * m.a * m.p0 + m.q;
            for _ in 1..exp.steps {
                s = (1.0 - gamma) * m.a * m.a * s + m.q;
            }
            format!(
                ", E[P] at step {} ≥ {s:.3e} (lower-bound recursion)",
                exp.steps
            )
        }
        Arrivals::GilbertElliott { .. } => String::new(),
    };
    let Some((hat, se)) = hill(&per_trial, k) else {
        return Outcome {
            verdict: Some(Verdict::NotResolved),
            need: None,
            words: format!("{x}: too few positive per-trial errors for a tail index"),
        };
    };
    let z = (hat - 1.0) / se;
    let v = if z < -Z_DECIDE {
        Verdict::Holds
    } else if z > z_fail {
        Verdict::Fails
    } else {
        Verdict::NotResolved
    };
    let need = trials_to_resolve(exp.trials, z);
    Outcome {
        verdict: Some(v),
        need,
        words: format!(
            "{x}: tail index {hat:.2} ± {se:.2} from the largest {k} of {} trials (theory {alpha:.2}), z = {z:.1}; sample mean of the steady trace {:.3e}{horizon}: {}",
            per_trial.len(),
            p.summary.steady_state.trace,
            v.label()
        ),
    }
}

#[cfg(test)]
mod tests;
