//! Integer knobs: a short range (quantizer bits) tried value by value, a long one (consensus
//! iterations, 1..=1000) by bisection on its monotone spend, each budget getting the integer
//! whose spend is nearest.
use super::{Choice, End, Evaluator, Pilot, Setup, Status};

/// Ranges of at most this many values are tried value by value (what they cost is a few
/// pilot runs, and a value that does not build ends the range).
const EVERY_VALUE_UP_TO: f64 = 32.0;

/// The integer per budget: every value of a short range, bisection on a long one.
pub(super) fn choose_integer(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    label: &str,
) -> Result<Vec<Choice>, String> {
    match p.range.hi {
        Some(hi) if hi - p.range.lo > EVERY_VALUE_UP_TO => bisect(ev, s, p, label, hi),
        _ => every_integer(ev, s, p, label),
    }
}

/// A long range: its two ends, then per budget a bisection between the integers whose spends
/// straddle it (the spend is monotone in the knob, [`crate::scheme::registry::Direction`]),
/// the nearer of the last two. A budget beyond both ends is out of range at the nearer end.
fn bisect(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    label: &str,
    hi: f64,
) -> Result<Vec<Choice>, String> {
    let (axis, tol, lo) = (s.axis, s.tol, p.range.lo);
    let mut spend = |ev: &mut Evaluator, x: f64| {
        p.eval(ev, x)
            .map(|r| (axis.of(&r), r))
            .map_err(|e| format!("{label}: `{}` = {x}: {e}", p.knob))
    };
    let (at_lo, at_hi) = (spend(ev, lo)?.0, spend(ev, hi)?.0);
    let rising = at_hi >= at_lo;
    let mut chosen = Vec::new();
    for &b in s.budgets {
        let (mut l, mut h) = (lo, hi);
        let beyond = b <= at_lo.min(at_hi) || b >= at_lo.max(at_hi);
        while !beyond && h - l > 1.0 {
            let m = ((l + h) / 2.0).floor();
            if (spend(ev, m)?.0 < b) == rising {
                l = m;
            } else {
                h = m;
            }
        }
        let (sl, rl) = spend(ev, l)?;
        let (sh, rh) = spend(ev, h)?;
        let (x, got, r) = if (sl - b).abs() <= (sh - b).abs() {
            (l, sl, rl)
        } else {
            (h, sh, rh)
        };
        let (st, end) = if (got - b).abs() <= tol * b {
            (Status::Calibrated, None)
        } else if beyond {
            (Status::OutOfRange, Some(End::of(x, lo, hi)))
        } else {
            (Status::NearestInteger, None)
        };
        chosen.push((x, r, st, end));
    }
    Ok(chosen)
}

/// An integer knob: every integer of the range (a value that does not build ends it), and the
/// nearest per budget. A budget beyond what the first and last integers reach is out of range
/// at the nearer end; only one the integers straddle is a "nearest integer".
fn every_integer(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    label: &str,
) -> Result<Vec<Choice>, String> {
    let (axis, tol, knob, range) = (s.axis, s.tol, p.knob, p.range);
    let mut chosen = Vec::new();
    let mut points = Vec::new();
    let mut first_err: Option<(f64, String)> = None;
    let mut x = range.lo;
    while x <= range.hi.unwrap_or(range.lo) + 0.5 {
        match p.eval(ev, x) {
            Ok(s) => points.push((x, s)),
            Err(e) if points.is_empty() => {
                first_err.get_or_insert((x, e));
            }
            Err(_) => break,
        }
        x += 1.0;
    }
    if points.is_empty() {
        let cause = first_err
            .map(|(x, e)| format!(" (`{knob}` = {x}: {e})"))
            .unwrap_or_default();
        return Err(format!("{label}: no value of `{knob}` builds{cause}"));
    }
    let reach = points.iter().map(|p| axis.of(&p.1));
    let (min, max) = reach.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, c), v| {
        (a.min(v), c.max(v))
    });
    let (first, last) = (points[0].0, points[points.len() - 1].0);
    for &b in s.budgets {
        let (x, s) = points
            .iter()
            .min_by(|p, q| {
                (axis.of(&p.1) - b)
                    .abs()
                    .total_cmp(&(axis.of(&q.1) - b).abs())
            })
            .expect("non-empty");
        let (st, end) = if (axis.of(s) - b).abs() <= tol * b {
            (Status::Calibrated, None)
        } else if b < min || b > max {
            (Status::OutOfRange, Some(End::of(*x, first, last)))
        } else {
            (Status::NearestInteger, None)
        };
        chosen.push((*x, s.clone(), st, end));
    }
    Ok(chosen)
}
