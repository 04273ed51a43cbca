//! Checks a scenario's `[paper]` section against the scenario itself before anything runs: every
//! label names a curve, every parameter set picks exactly one variant, every metric and group
//! exists, tolerances and ranges make sense. A typo is an error, never a `FAILS` or a `null`.
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scenario::experiment::{Curve, Variant};
use crate::scenario::intermittent::{self, Arrivals, Regime, ScalarModel};
use crate::scenario::{ClaimSpec, InflationCheck, IntermittentCheck, PaperSpec, Params};
use crate::scheme::System;

struct Scope<'a> {
    ctx: &'a Ctx<'a>,
    curves: &'a [Curve],
    variants: &'a [Variant],
    groups: &'a [(String, Vec<usize>)],
}

impl Scope<'_> {
    fn curve(&self, field: &str, label: &str) -> Result<usize, ScenarioError> {
        self.curves
            .iter()
            .position(|c| c.label == label)
            .ok_or_else(|| {
                let labels: Vec<&str> = self.curves.iter().map(|c| c.label.as_str()).collect();
                self.ctx.err(
                    field,
                    format!("no scheme is labelled {label:?}; the labels are {labels:?}"),
                )
            })
    }

    /// The curve must exist and `params` must pick exactly one of its variants.
    fn variant(
        &self,
        field: &str,
        label: &str,
        params_field: &str,
        params: &Params,
    ) -> Result<(), ScenarioError> {
        let c = self.curve(field, label)?;
        let n = self
            .variants
            .iter()
            .filter(|v| {
                v.curve == c
                    && params
                        .iter()
                        .all(|(k, p)| v.params.get(k).is_some_and(|x| x.matches(p)))
            })
            .count();
        match n {
            1 => Ok(()),
            0 => Err(self.ctx.err(
                params_field,
                format!("no variant of {label:?} has these parameters"),
            )),
            n => Err(self.ctx.err(
                params_field,
                format!(
                    "{n} variants of {label:?} match; give its swept parameters ({})",
                    self.curves[c].swept.join(", ")
                ),
            )),
        }
    }

    fn group_metric(&self, field: &str, metric: &str, prefix: &str) -> Result<(), ScenarioError> {
        let group = metric.strip_prefix(prefix).unwrap_or_default();
        if self.groups.iter().any(|(g, _)| g == group) {
            Ok(())
        } else {
            let names: Vec<&str> = self.groups.iter().map(|(g, _)| g.as_str()).collect();
            Err(self.ctx.err(
                field,
                format!("unknown group {group:?} in {metric:?}; the groups are {names:?}"),
            ))
        }
    }

    fn one_of(&self, field: &str, metric: &str, allowed: &[&str]) -> Result<(), ScenarioError> {
        if allowed.contains(&metric) {
            Ok(())
        } else {
            Err(self.ctx.err(
                field,
                format!("unknown metric {metric:?}; expected one of {allowed:?}"),
            ))
        }
    }
}

fn finite_nonneg(ctx: &Ctx, field: &str, v: f64) -> Result<(), ScenarioError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ctx.err(field, format!("expected a finite number >= 0, got {v}")))
    }
}

/// Validates the `[paper]` section.
pub(crate) fn check(
    ctx: &Ctx,
    paper: &PaperSpec,
    curves: &[Curve],
    variants: &[Variant],
    groups: &[(String, Vec<usize>)],
    system: &System,
) -> Result<(), ScenarioError> {
    let s = Scope {
        ctx,
        curves,
        variants,
        groups,
    };
    for (i, p) in paper.published.iter().enumerate() {
        let at = |f: &str| format!("paper.published[{i}].{f}");
        s.variant(&at("scheme"), &p.scheme, &at("params"), &p.params)?;
        if p.metric.starts_with("rmse:") {
            s.group_metric(&at("metric"), &p.metric, "rmse:")?;
        } else {
            s.one_of(
                &at("metric"),
                &p.metric,
                &[
                    "mse",
                    "trace",
                    "rate",
                    "transmissions_per_step",
                    "rmse:<group>",
                ],
            )?;
        }
        if !p.value.is_finite() {
            return Err(ctx.err(at("value"), "expected a finite number"));
        }
        if let Some(t) = p.tolerance {
            if !(t.is_finite() && t > 0.0) {
                return Err(ctx.err(at("tolerance"), format!("expected a number > 0, got {t}")));
            }
        }
    }
    if paper.trials == Some(0) {
        return Err(ctx.err("paper.trials".to_string(), "expected at least 1 trial"));
    }
    for (i, c) in paper.claims.iter().enumerate() {
        let at = |f: &str| format!("paper.claims[{i}].{f}");
        match c {
            ClaimSpec::Below {
                a,
                b,
                metric,
                rate_range,
                ..
            } => {
                s.curve(&at("a"), a)?;
                s.curve(&at("b"), b)?;
                s.one_of(&at("metric"), metric, &["mse", "trace"])?;
                let [lo, hi] = *rate_range;
                if !(lo.is_finite() && hi.is_finite() && lo < hi && lo >= 0.0) {
                    return Err(ctx.err(
                        at("rate_range"),
                        format!("expected [lo, hi] with 0 <= lo < hi, got [{lo}, {hi}]"),
                    ));
                }
            }
            ClaimSpec::ReachesRateBelow { scheme, rate, .. } => {
                s.curve(&at("scheme"), scheme)?;
                if !(rate.is_finite() && *rate > 0.0) {
                    return Err(ctx.err(at("rate"), format!("expected a rate > 0, got {rate}")));
                }
            }
            ClaimSpec::Consistent { schemes, .. } => {
                if schemes.is_empty() {
                    return Err(ctx.err(at("schemes"), "expected at least one label"));
                }
                for (j, l) in schemes.iter().enumerate() {
                    s.curve(&format!("paper.claims[{i}].schemes[{j}]"), l)?;
                }
            }
            ClaimSpec::Better {
                a,
                a_params,
                b,
                b_params,
                metric,
                ..
            }
            | ClaimSpec::Close {
                a,
                a_params,
                b,
                b_params,
                metric,
                ..
            } => {
                s.variant(&at("a"), a, &at("a_params"), a_params)?;
                s.variant(&at("b"), b, &at("b_params"), b_params)?;
                if metric.starts_with("mse:") {
                    s.group_metric(&at("metric"), metric, "mse:")?;
                } else {
                    s.one_of(&at("metric"), metric, &["mse", "mse:<group>"])?;
                }
                if let ClaimSpec::Close {
                    within,
                    tolerance_source,
                    ..
                } = c
                {
                    finite_nonneg(ctx, &at("within"), *within)?;
                    if !(tolerance_source == "ours" || tolerance_source.starts_with("paper: ")) {
                        return Err(ctx.err(
                            at("tolerance_source"),
                            format!(
                                "{tolerance_source:?}: expected \"ours\" or \"paper: '<quote>'\""
                            ),
                        ));
                    }
                }
            }
            ClaimSpec::CloserToTarget {
                a,
                b,
                param,
                metric,
                ..
            } => {
                for (f, l) in [("a", a), ("b", b)] {
                    let ci = s.curve(&at(f), l)?;
                    if !curves[ci].swept.iter().any(|p| p == param) {
                        return Err(
                            ctx.err(at("param"), format!("curve {l:?} does not sweep `{param}`"))
                        );
                    }
                }
                s.one_of(&at("metric"), metric, &["transmissions_per_step", "rate"])?;
            }
            ClaimSpec::Intermittent { scheme, .. } => {
                let ci = s.curve(&at("scheme"), scheme)?;
                check_intermittent(ctx, &at, (ci, &curves[ci]), variants, system, c)?;
            }
            ClaimSpec::Inflation { .. } => check_inflation_claim(&s, &at, variants, system, c)?,
            ClaimSpec::EnergyRatio { a, b, at_least, .. } => {
                s.curve(&at("a"), a)?;
                s.curve(&at("b"), b)?;
                positive(ctx, &at("at_least"), *at_least)?;
            }
        }
    }
    Ok(())
}

/// A finite number > 0, or an error naming `field`.
fn positive(ctx: &Ctx, field: &str, v: f64) -> Result<(), ScenarioError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ctx.err(field, format!("expected a finite number > 0, got {v}")))
    }
}

/// An `intermittent` claim needs sensible `range`, `within` and `sequences`, the all-data Kalman filter on a scalar system, every variant's
/// link a Bernoulli or a lose-all-when-bad Gilbert–Elliott one (Bernoulli only for `bounds`),
/// and at least one variant on the side of the critical value the check is about.
fn check_intermittent(
    ctx: &Ctx,
    at: &dyn Fn(&str) -> String,
    (ci, curve): (usize, &Curve),
    variants: &[Variant],
    system: &System,
    claim: &ClaimSpec,
) -> Result<(), ScenarioError> {
    let ClaimSpec::Intermittent {
        check: what,
        within,
        sequences,
        range,
        ..
    } = *claim
    else {
        return Ok(());
    };
    if let Some([lo, hi]) = range {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(ctx.err(
                at("range"),
                format!("expected [lo, hi] with lo <= hi, got [{lo}, {hi}]"),
            ));
        }
    }
    let [lo, hi] = range.unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
    if let Some(w) = within {
        if !(w.is_finite() && w > 0.0 && w <= 1.0) {
            return Err(ctx.err(
                at("within"),
                format!("expected a relative resolution in (0, 1], got {w}"),
            ));
        }
    }
    if let Some(n) = sequences {
        if !(100..=10_000_000).contains(&n) {
            return Err(ctx.err(
                at("sequences"),
                format!("expected 100 to 10000000 arrival sequences, got {n}"),
            ));
        }
    }
    if curve.kind != intermittent::FILTER_KIND {
        return Err(ctx.err(
            at("scheme"),
            format!(
                "{:?} is a {} curve; the theory is about the Kalman filter on every measurement that arrives (kind = \"{}\")",
                curve.label,
                curve.kind,
                intermittent::FILTER_KIND
            ),
        ));
    }
    let m = ScalarModel::of(system).map_err(|e| ctx.err(at("scheme"), e))?;
    let mut in_scope = 0;
    for v in variants.iter().filter(|v| v.curve == ci) {
        let arrivals = Arrivals::of(v.channel.as_deref().map(|c| &c[0]))
            .map_err(|e| ctx.err(at("scheme"), format!("{:?}: {e}", curve.label)))?;
        if what == IntermittentCheck::Bounds && !matches!(arrivals, Arrivals::Bernoulli { .. }) {
            return Err(ctx.err(
                at("check"),
                "Sinopoli's bounds are for Bernoulli arrivals; this curve has a Gilbert–Elliott link",
            ));
        }
        let diverges = intermittent::regime(m.a, &arrivals) == Regime::Diverges;
        let x = arrivals.abscissa();
        in_scope += usize::from(
            diverges == (what == IntermittentCheck::Diverges) && x >= lo - 1e-12 && x <= hi + 1e-12,
        );
    }
    if in_scope == 0 {
        return Err(ctx.err(
            at("check"),
            format!(
                "no variant of {:?} in the claim's range is {} the critical value, where this check applies",
                curve.label,
                if what == IntermittentCheck::Diverges { "at or beyond" } else { "on the stable side of" }
            ),
        ));
    }
    Ok(())
}

/// An `inflation` claim's curve: the scalar system with H = [[1]], every variant on an ideal
/// link and quantizing into a Lloyd–Max cell count the classic factor describes (or analog).
fn check_inflation(
    s: &Scope,
    at: &dyn Fn(&str) -> String,
    ci: usize,
    system: &System,
) -> Result<(), ScenarioError> {
    let label = &s.curves[ci].label;
    ScalarModel::of(system).map_err(|e| s.ctx.err(at("scheme"), e))?;
    for v in s.variants.iter().filter(|v| v.curve == ci) {
        crate::scenario::classic::cells(v.kind, &v.params)
            .map_err(|e| s.ctx.err(at("scheme"), format!("{label:?}: {e}")))?;
        // Every message must arrive at once: an ideal link, or a lossless one without delay.
        for spec in v.channel.as_deref().into_iter().flatten() {
            if !matches!(Arrivals::of(Some(spec)), Ok(Arrivals::Bernoulli { gamma }) if gamma == 1.0)
            {
                return Err(s.ctx.err(
                    at("scheme"),
                    format!("{label:?}: the classic factor is for a link that delivers every message at once (ideal, or lossless without delay or arq); this curve's link loses or delays them"),
                ));
            }
        }
    }
    Ok(())
}

/// An `inflation` claim: its curve (and an `efficiency` claim's one-variant reference) through
/// [`check_inflation`], a reference exactly when the check needs one, `within` in (0, 1].
fn check_inflation_claim(
    s: &Scope,
    at: &dyn Fn(&str) -> String,
    variants: &[Variant],
    system: &System,
    claim: &ClaimSpec,
) -> Result<(), ScenarioError> {
    let ClaimSpec::Inflation {
        scheme,
        check: what,
        reference,
        within,
        ..
    } = claim
    else {
        return Ok(());
    };
    let ctx = s.ctx;
    let ci = s.curve(&at("scheme"), scheme)?;
    check_inflation(s, at, ci, system)?;
    match (what, reference) {
        (InflationCheck::Efficiency, Some(r)) => {
            let ri = s.curve(&at("reference"), r)?;
            if variants.iter().filter(|v| v.curve == ri).count() != 1 {
                return Err(ctx.err(
                    at("reference"),
                    format!("{r:?} must be one variant (not swept)"),
                ));
            }
            check_inflation(s, at, ri, system)?;
        }
        (InflationCheck::Efficiency, None) => {
            return Err(ctx.err(
                at("reference"),
                "an `efficiency` claim needs the label of the curve it divides by",
            ));
        }
        (_, Some(_)) => {
            return Err(ctx.err(
                at("reference"),
                "only an `efficiency` claim takes a reference",
            ));
        }
        (_, None) => {}
    }
    if let Some(w) = within {
        if !(w.is_finite() && *w > 0.0 && *w <= 1.0) {
            return Err(ctx.err(
                at("within"),
                format!("expected a relative tolerance in (0, 1], got {w}"),
            ));
        }
    }
    Ok(())
}
