//! The link models, registered as the schemes are (`crate::scheme::SCHEMES`): each in a file
//! of its own here, with its `kind`, its keys and their documentation, its checks, the loss it
//! puts on each step, and what the rest of hushfuse asks of a link (the long-run loss a
//! loss-aware center believes, `link_loss = "channel"`, derived from the link's own keys and
//! never typed twice; the attempts a hop's energy budget expects; the arrival law a stability
//! claim needs). The `[channel]` table of `docs/scenarios.md` is generated from this list
//! ([`markdown`], `hushfuse list-links --markdown`; a test keeps the two equal).
//!
//! Adding a model: a file here with its [`LinkModel`] (its keys are read by name from
//! [`ChannelSpec::key`]), and its line in [`LINK_MODELS`]. Nothing else names a model.
pub mod bernoulli;
pub mod gilbert_elliott;
pub mod ideal;

use super::spec::{Arq, ChannelKind, ChannelSpec, Delay};
use rand_xoshiro::Xoshiro256PlusPlus;

/// One documented key of a link model (`name` may list several, comma-separated).
#[derive(Debug, Clone, Copy)]
pub struct KeyDoc {
    pub name: &'static str,
    pub default: &'static str,
    pub meaning: &'static str,
}

/// A link's generator of slot j (a model with a hidden state draws its chain from one).
pub type Slot<'a> = &'a dyn Fn(usize) -> Xoshiro256PlusPlus;

/// How packets arrive over a link without delay or retransmission: the law a stability claim
/// (`crate::scenario::intermittent`) is stated for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Arrivals {
    /// Each arrives independently with probability `gamma` (1 − loss).
    Bernoulli { gamma: f64 },
    /// A two-state chain started in its stationary law (as the link draws it): good → bad with
    /// probability `p_gb`, bad → good with `p_bg`; the good state delivers every packet and
    /// the bad state loses every packet.
    GilbertElliott { p_gb: f64, p_bg: f64 },
}

/// A registered link model.
pub struct LinkModel {
    /// Its `kind` in the scenario file.
    pub name: &'static str,
    /// One line for `hushfuse list-links` and the docs.
    pub summary: &'static str,
    /// Its own keys (a key of another model is refused under this one).
    pub keys: &'static [KeyDoc],
    /// The checks of its keys' values; `path` names the table.
    pub validate: fn(&ChannelSpec, path: &str) -> Result<(), String>,
    /// Whether a packet's slot draws a loss coin (first from the slot's generator): every model
    /// that may lose one. An ideal link draws none, so its slots' other draws come first.
    pub draws_loss: bool,
    /// The loss probability of a packet sent at each step `1..=steps`; `slot(j)` is the
    /// link's generator of slot j (a model with a hidden state draws its chain from one).
    pub loss_path: fn(&ChannelSpec, usize, Slot) -> Vec<f64>,
    /// The long-run probability that a report is lost for good (after `arq`'s retries): what a
    /// loss-aware center assumes.
    pub delivery_loss: fn(&ChannelSpec) -> f64,
    /// Whether the link may lose a packet with these keys (else it is lossless).
    pub loses: fn(&ChannelSpec) -> bool,
    /// The largest loss of a packet at any step (a bound the run-time estimate uses).
    pub worst_loss: fn(&ChannelSpec) -> f64,
    /// Expected attempts of a frame with up to `r` retries (each stopped by the first
    /// acknowledgement, ACKs taken as heard), in the long run.
    pub expected_attempts: fn(&ChannelSpec, u32) -> f64,
    /// The arrival law of the link, or why a stability claim cannot use it.
    pub arrivals: fn(&ChannelSpec) -> Result<Arrivals, String>,
}

/// Every link model, in the order the docs list them.
pub const LINK_MODELS: &[&LinkModel] = &[&ideal::MODEL, &bernoulli::MODEL, &gilbert_elliott::MODEL];

/// Every model key of every model, in the registry's order.
pub fn model_keys() -> impl Iterator<Item = &'static str> {
    LINK_MODELS
        .iter()
        .flat_map(|m| m.keys)
        .flat_map(|k| k.name.split(", "))
}

/// Attempts of a packet on `spec`: the first and `arq`'s retries.
pub(crate) fn attempts(spec: &ChannelSpec) -> i32 {
    1 + spec.arq.map_or(0, |a| a.max_retries.min(Arq::MAX_RETRIES)) as i32
}

/// Expected attempts of a frame with up to `r` retries when each attempt is lost with
/// probability `p`: Σ_{j=0}^{r} p^j = (1 − p^{r+1}) / (1 − p).
pub fn expected_attempts(p: f64, r: u32) -> f64 {
    (0..=r as i32).map(|j| p.powi(j)).sum()
}

/// The loss of one attempt on `spec` in the long run (its `arq` set aside).
pub(crate) fn attempt_loss(spec: &ChannelSpec) -> f64 {
    (spec.kind.model().delivery_loss)(&ChannelSpec {
        arq: None,
        ..spec.clone()
    })
}

/// The value of a key the kind needs, or an error naming it.
pub(crate) fn required(path: &str, spec: &ChannelSpec, key: &str) -> Result<f64, String> {
    spec.key(key)
        .ok_or_else(|| format!("{path}.kind = \"{}\" needs `{key}`", spec.kind.name()))
}

/// Checks that `value` is a probability; NaN fails the range test and is rejected too.
pub(crate) fn probability(path: &str, key: &str, value: f64) -> Result<(), String> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(format!(
            "{path}.{key} = {value} is not a probability in [0, 1]"
        ))
    }
}

/// A probability as a chain or a coin uses it: NaN as 0, the rest clamped to [0, 1].
pub(crate) fn clamp_probability(p: f64) -> f64 {
    if p.is_nan() {
        0.0
    } else {
        p.clamp(0.0, 1.0)
    }
}

/// The keys every model has.
pub const COMMON_KEYS: &[KeyDoc] = &[
    KeyDoc {
        name: "delay",
        default: "0",
        meaning: "steps a delivered packet is late: an integer, or `{ kind = \"geometric\", mean = …, horizon = … }`; the center re-fuses a late packet when it arrives if it is at most `horizon` steps late (a fixed delay: the delay itself; geometric: default the 99.9% quantile), and drops later ones (counted `dropped_late`); the horizon never exceeds the run's steps. Each late arrival re-fuses the trial so far, so the work grows as steps² (a delay of 1 over 10⁶ steps): it is counted in the run's time estimate, and a run past 24 hours is refused. Not on a `downlink` (refused: feedback arrives at its step or is lost)",
    },
    KeyDoc {
        name: "downlink",
        default: "ideal",
        meaning: "the same model for the feedback link (`downlink = { kind = \"bernoulli\", loss = 0.1 }`)",
    },
    KeyDoc {
        name: "arq",
        default: "none",
        meaning: "`{ max_retries = n }`, n in 0..=7 (`macMaxFrameRetries` of IEEE 802.15.4): acknowledged retransmission of the uplink's packets, below; not allowed on a `downlink`",
    },
];

/// The registered model of `kind`.
pub fn of(kind: ChannelKind) -> &'static LinkModel {
    LINK_MODELS[kind.0]
}

impl std::fmt::Debug for ChannelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ChannelKind({:?})", self.name())
    }
}

impl ChannelKind {
    /// The registered model called `name`.
    pub fn named(name: &str) -> Option<Self> {
        LINK_MODELS
            .iter()
            .position(|m| m.name == name)
            .map(ChannelKind)
    }

    /// The name used in the scenario file.
    pub fn name(self) -> &'static str {
        self.model().name
    }

    /// Its registered model.
    pub fn model(self) -> &'static LinkModel {
        of(self)
    }
}

/// What a link's model says of it: its checks and the loss a loss-aware center assumes.
impl ChannelSpec {
    /// Whether every packet of this link arrives at once and nothing is counted but what an
    /// ideal link counts: a model that loses nothing with these keys (an ideal kind, a Bernoulli
    /// link of loss 0, a Gilbert–Elliott link that loses nothing in either state); zero delay;
    /// no `arq` (whose acknowledgements are counted); and a downlink that is lossless too. Such
    /// a link draws no fate that changes a number, so the engine may run it as an ideal one (its
    /// fast paths included).
    pub fn is_lossless(&self) -> bool {
        !(self.kind.model().loses)(self)
            && self.delay().is_zero()
            && self.arq.is_none()
            && self
                .downlink
                .as_deref()
                .is_none_or(ChannelSpec::is_lossless)
    }

    /// The probability that an uplink packet is never delivered, in the long run: what a
    /// loss-aware center assumes for this link (`link_loss = "channel"`). Bernoulli `p`, and
    /// with `arq` of `n` retries `p^(1+n)` (each attempt draws its own loss); Gilbert–Elliott
    /// at its stationary state, `π_good loss_good^(1+n) + π_bad loss_bad^(1+n)` (the retries of
    /// a step see that step's state; π_bad = p_gb / (p_gb + p_bg), 0 when the chain never
    /// moves, as the fates take it). A delay is not a loss and counts nothing here. Assumes a
    /// validated spec.
    pub fn delivery_loss(&self) -> f64 {
        (self.kind.model().delivery_loss)(self)
    }

    /// Checks the table found at `channel`; see [`ChannelSpec::validate_at`].
    pub fn validate(&self) -> Result<(), String> {
        self.validate_at("channel")
    }

    /// Checks the keys against the kind and the values against their ranges. `path` names the
    /// table in messages (`"channel"`, `"sensors[2].channel"`, …) so the user can find the key.
    pub fn validate_at(&self, path: &str) -> Result<(), String> {
        self.check_keys_fit_kind(path)?;
        (self.kind.model().validate)(self, path)?;
        if let Some(Delay::Geometric(g)) = &self.delay {
            if !(g.mean.is_finite() && g.mean >= 0.0) {
                return Err(format!(
                    "{path}.delay.mean = {} must be a finite number of steps >= 0",
                    g.mean
                ));
            }
        }
        if let Some(arq) = &self.arq {
            if arq.max_retries > Arq::MAX_RETRIES {
                return Err(format!(
                    "{path}.arq.max_retries = {} is out of range: 0 to {} (macMaxFrameRetries of IEEE 802.15.4)",
                    arq.max_retries,
                    Arq::MAX_RETRIES
                ));
            }
        }
        if let Some(down) = &self.downlink {
            // A feedback link has no feedback link of its own.
            if down.downlink.is_some() {
                return Err(format!(
                    "{path}.downlink.downlink is not allowed: a downlink has no downlink"
                ));
            }
            // Feedback is not retransmitted: the downlink carries the uplink's acknowledgements.
            if down.arq.is_some() {
                return Err(format!(
                    "{path}.downlink.arq is not allowed: retransmission applies to the uplink (its acknowledgements travel on the downlink)"
                ));
            }
            // Feedback is read at the step it is sent or not at all (a lost one leaves the
            // sensor with what it last heard): a delay on it was accepted and ignored before.
            if !down.delay().is_zero() {
                return Err(format!(
                    "{path}.downlink.delay is not supported: feedback reaches a sensor at its step or is lost (the sensor keeps what it last heard); remove the delay, or model a slow downlink by its loss"
                ));
            }
            down.validate_at(&format!("{path}.downlink"))?;
        }
        Ok(())
    }

    /// Rejects keys of another kind: a `loss` under `kind = "gilbert-elliott"` would otherwise be
    /// silently ignored, and the user would believe it was used.
    fn check_keys_fit_kind(&self, path: &str) -> Result<(), String> {
        // The owner of each key is the model that documents it.
        for owner in LINK_MODELS.iter().filter(|m| m.name != self.kind.name()) {
            for key in owner.keys.iter().flat_map(|k| k.name.split(", ")) {
                if self.keys.contains_key(key) {
                    return Err(format!(
                        "{path}.{key} belongs to kind = \"{}\", not \"{}\"",
                        owner.name,
                        self.kind.name()
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The `[channel]` key table of `docs/scenarios.md`.
pub fn markdown() -> String {
    let kinds: Vec<String> = LINK_MODELS
        .iter()
        .map(|m| format!("`{}` ({})", m.name, m.summary))
        .collect();
    let mut out = String::from("| field | default | meaning |\n|---|---|---|\n");
    out.push_str(&format!("| `kind` | `ideal` | {} |\n", kinds.join("; ")));
    for m in LINK_MODELS {
        for k in m.keys {
            let names: Vec<String> = k.name.split(", ").map(|n| format!("`{n}`")).collect();
            let default = match k.default {
                "required" => format!("required for `{}`", m.name),
                d => d.to_string(),
            };
            out.push_str(&format!(
                "| {} | {default} | {} |\n",
                names.join(", "),
                k.meaning
            ));
        }
    }
    for k in COMMON_KEYS {
        out.push_str(&format!(
            "| `{}` | {} | {} |\n",
            k.name, k.default, k.meaning
        ));
    }
    out
}

/// The link models as `hushfuse list-links` prints them: each kind, what it does, its keys.
pub fn describe() -> String {
    let mut out = String::new();
    for m in LINK_MODELS {
        out.push_str(&format!("{}: {}\n", m.name, m.summary));
        for k in m.keys {
            out.push_str(&format!("    {} ({}): {}\n", k.name, k.default, k.meaning));
        }
    }
    out.push_str("every kind:\n");
    for k in COMMON_KEYS {
        out.push_str(&format!("    {} ({}): {}\n", k.name, k.default, k.meaning));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `[channel]` table of docs/scenarios.md is the registry's, as generated.
    #[test]
    fn the_docs_table_is_generated_from_the_registry() {
        let docs = include_str!("../../../../docs/scenarios.md");
        assert!(
            docs.contains(&markdown()),
            "docs/scenarios.md's [channel] table differs from `hushfuse list-links --markdown`:\n{}",
            markdown()
        );
    }

    /// Every kind is registered once, and its long-run loss is what its keys say by hand.
    #[test]
    fn every_kind_once_and_its_belief_by_hand() {
        assert_eq!(ChannelKind::IDEAL.name(), "ideal");
        for m in LINK_MODELS {
            assert_eq!(LINK_MODELS.iter().filter(|n| n.name == m.name).count(), 1);
            assert_eq!(ChannelKind::named(m.name).map(|k| k.name()), Some(m.name));
        }
        // No key belongs to two models (the checks name a key's one owner).
        let keys: Vec<&str> = model_keys().collect();
        let mut unique = keys.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), keys.len(), "{keys:?}");
        let spec = |t: &str| -> ChannelSpec { toml::from_str(t).unwrap() };
        // Bernoulli 0.3 with two retries: 0.3^3.
        let b = spec("kind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 2 }");
        assert!((b.delivery_loss() - 0.027).abs() < 1e-15);
        // GE: stationary bad share 0.1 / (0.1 + 0.4) = 0.2; 0.8 · 0.05 + 0.2 · 0.9 = 0.22.
        let ge = spec(
            "kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.4\nloss_good = 0.05\nloss_bad = 0.9",
        );
        assert!((ge.delivery_loss() - 0.22).abs() < 1e-15);
        assert_eq!(spec("").delivery_loss(), 0.0);
        // Every documented key parses under its own kind and is read back by name.
        for m in LINK_MODELS {
            for key in m.keys.iter().flat_map(|k| k.name.split(", ")) {
                let s = spec(&format!("kind = \"{}\"\n{key} = 0.5", m.name));
                assert_eq!(s.key(key), Some(0.5), "{key}");
            }
        }
    }
}
