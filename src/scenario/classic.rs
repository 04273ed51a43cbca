//! What an `inflation` claim ([`crate::scenario::ClaimSpec::Inflation`]) is about: Kalman
//! filtering with quantized innovations on a scalar system x' = a x + w, y = x + v, where the
//! classic papers reduce the filter to the Kalman filter's variance recursion with the update
//! scaled by a factor c:
//!
//!   P+ = P- − c · P-² / (P- + r),
//!
//! c = 2/π for the sign of the innovation (Ribeiro, Giannakis and Roumeliotis, "SOI-KF:
//! distributed Kalman filtering with low-cost communications using the sign of innovations",
//! IEEE TSP 54(12), 2006), c = 1 − D_N for an N-cell quantizer of the normalized innovation with
//! MSE distortion D_N on N(0, 1) (Msechu, Roumeliotis, Ribeiro and Giannakis, "Decentralized
//! quantized Kalman filtering with scalable communication cost", IEEE TSP 56(8), 2008; the
//! MSE-optimal cells are Lloyd–Max's), c = 1 for analog data. Equivalently the Kalman filter
//! with the measurement noise inflated to r' = (P- + r) / c − P-.
//!
//! This module reads, from a variant's scheme parameters, how many Lloyd–Max cells it
//! quantizes into; the factor itself and the recursion are computed by the claim checker
//! (`output::report::classic`), by its own numerical integration.
use crate::scenario::{ParamValue, Params};

/// The scheme kinds an `inflation` claim can be about: Zhang et al.'s (2016) quantized-
/// innovation fusion (whose `sign`, `msechu`, `you` and `lloyd-max` quantizers are the
/// classic ones), and the Kalman filter on all data (c = 1).
pub const KINDS: [&str; 2] = ["quantized-innovation", "centralized-kf"];

/// Largest cell count the claim checker designs a quantizer for.
pub const MAX_CELLS: usize = 64;

/// The number of Lloyd–Max cells of N(0, 1) that a variant of `kind` with `params` quantizes
/// its normalized innovation into; `None` for analog data (c = 1). An error says why the
/// classic factor does not describe the variant.
pub fn cells(kind: &str, params: &Params) -> Result<Option<usize>, String> {
    if kind == "centralized-kf" {
        return Ok(None);
    }
    if kind != KINDS[0] {
        return Err(format!(
            "a {kind} curve; the classic factor is about {:?} (quantized-innovation, centralized-kf)",
            KINDS
        ));
    }
    let number = |name: &str| match params.get(name) {
        Some(ParamValue::Number(x)) if *x >= 1.0 && x.fract() == 0.0 => Ok(*x as usize),
        _ => Err(format!("needs an integer `{name}`")),
    };
    let quantizer = match params.get("quantizer") {
        Some(ParamValue::Text(q)) => q.as_str(),
        _ => return Err("needs a `quantizer`".into()),
    };
    let n = match quantizer {
        "analog" => return Ok(None),
        "sign" => 2,
        // 2^c cells, all sent (c = 1 is the sign).
        "msechu" => 1usize.checked_shl(number("bits")?.min(31) as u32).unwrap_or(usize::MAX),
        // 2^c + 1 cells, the centre one silent: on an ideal link silence is its own message.
        "you" => 1usize
            .checked_shl(number("bits")?.min(31) as u32)
            .map_or(usize::MAX, |n| n + 1),
        "lloyd-max" => number("levels")?,
        other => {
            return Err(format!(
                "quantizer {other:?}: the classic factor describes Lloyd–Max quantizers with a fixed cell count (sign, msechu, you, lloyd-max, analog); Zhang et al.'s dynamic strategy is checked by zhang-table7"
            ))
        }
    };
    if !(2..=MAX_CELLS).contains(&n) {
        return Err(format!(
            "a quantizer of {n} cells; the claim checker designs 2 to {MAX_CELLS}"
        ));
    }
    Ok(Some(n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pairs: &[(&str, ParamValue)]) -> Params {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn cell_counts_of_the_quantizers() {
        let q = |name: &str| ("quantizer", ParamValue::Text(name.into()));
        let bits = |b: f64| ("bits", ParamValue::Number(b));
        let kind = KINDS[0];
        assert_eq!(cells(kind, &params(&[q("sign")])), Ok(Some(2)));
        assert_eq!(cells(kind, &params(&[q("msechu"), bits(3.0)])), Ok(Some(8)));
        assert_eq!(cells(kind, &params(&[q("you"), bits(2.0)])), Ok(Some(5)));
        assert_eq!(
            cells(
                kind,
                &params(&[q("lloyd-max"), ("levels", ParamValue::Number(7.0))])
            ),
            Ok(Some(7))
        );
        assert_eq!(cells(kind, &params(&[q("analog")])), Ok(None));
        assert_eq!(cells("centralized-kf", &Params::new()), Ok(None));
        assert!(cells(kind, &params(&[q("zhang"), bits(1.0)])).is_err());
        assert!(cells(kind, &params(&[q("msechu"), bits(7.0)])).is_err());
        assert!(cells(kind, &params(&[q("msechu")])).is_err());
        assert!(cells("event-triggered", &Params::new()).is_err());
    }
}
