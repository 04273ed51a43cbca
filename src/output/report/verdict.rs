//! A claim's verdict from Monte Carlo standard errors, and the result a claim check returns.
use serde::Serialize;

/// Standard errors beyond which a difference decides a verdict: a claim holds (or fails) when
/// the Monte Carlo z of its deciding quantity is beyond +-`Z_DECIDE`, and is "not resolved at
/// this trial count" in between.
pub const Z_DECIDE: f64 = 2.0;
/// Standard errors that the trial count suggested for an unresolved claim aims at:
/// trials x (`Z_TARGET` / |z|)^2 would put the same difference `Z_TARGET` standard errors out.
pub const Z_TARGET: f64 = 2.5;

/// A claim's verdict.
#[derive(Debug, Clone, Copy, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    Holds,
    Fails,
    /// Within the Monte Carlo noise at this trial count.
    NotResolved,
}

impl Verdict {
    /// `z` of the deciding quantity, signed so that negative supports the claim.
    pub(crate) fn of_z(z: f64) -> Self {
        if z < -Z_DECIDE {
            Verdict::Holds
        } else if z > Z_DECIDE {
            Verdict::Fails
        } else {
            Verdict::NotResolved
        }
    }
    pub(crate) fn label(self) -> &'static str {
        match self {
            Verdict::Holds => "holds",
            Verdict::Fails => "FAILS",
            Verdict::NotResolved => "not resolved",
        }
    }
    /// Combines per-point verdicts: any failure fails, else any unresolved point leaves the
    /// claim unresolved.
    pub(crate) fn and(self, o: Verdict) -> Verdict {
        match (self, o) {
            (Verdict::Fails, _) | (_, Verdict::Fails) => Verdict::Fails,
            (Verdict::NotResolved, _) | (_, Verdict::NotResolved) => Verdict::NotResolved,
            _ => Verdict::Holds,
        }
    }
}

/// Trials at which a difference `z` standard errors out (at `trials`) would be `Z_TARGET` out.
pub fn trials_to_resolve(trials: usize, z: f64) -> Option<usize> {
    if !z.is_finite() || z == 0.0 {
        return None;
    }
    let t = trials as f64 * (Z_TARGET / z.abs()).powi(2);
    Some(t.ceil().max(trials as f64 + 1.0) as usize)
}

/// A claim and whether it holds in our run.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ClaimResult {
    pub text: String,
    /// `verdict == holds`.
    pub holds: bool,
    pub verdict: Verdict,
    /// For an unresolved claim: trials that would resolve it (from the standard error), if the
    /// difference is not exactly zero.
    pub trials_to_resolve: Option<usize>,
    /// Where the claim's tolerance comes from (`close` claims): the paper's words or ours.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tolerance_source: Option<String>,
    /// The numbers behind the verdict.
    pub evidence: String,
}

impl ClaimResult {
    pub(crate) fn new(
        text: &str,
        verdict: Verdict,
        trials_to_resolve: Option<usize>,
        evidence: String,
    ) -> Self {
        Self {
            text: text.to_string(),
            holds: verdict == Verdict::Holds,
            verdict,
            trials_to_resolve: if verdict == Verdict::NotResolved {
                trials_to_resolve
            } else {
                None
            },
            tolerance_source: None,
            evidence,
        }
    }
}
