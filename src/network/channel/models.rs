//! The link models, registered as the schemes are (`crate::scheme::SCHEMES`): each with its
//! `kind`, its keys and their documentation, its checks, the loss it puts on each step, and the
//! long-run loss a loss-aware center believes (`link_loss = "channel"`, derived here from the
//! link's own keys, never typed twice). The `[channel]` table of `docs/scenarios.md` is
//! generated from this list ([`markdown`], `hushfuse list-links --markdown`; a test keeps the
//! two equal).
//!
//! Adding a model: its `ChannelKind` variant and keys in [`super::spec`], its entry here (and
//! its per-step loss beside the others in [`super::fate`]).
use super::spec::{Arq, ChannelKind, ChannelSpec, Delay};
use rand_xoshiro::Xoshiro256PlusPlus;

/// One documented key of a link model.
#[derive(Debug, Clone, Copy)]
pub struct KeyDoc {
    pub name: &'static str,
    pub default: &'static str,
    pub meaning: &'static str,
}

/// A link's generator of slot j (a model with a hidden state draws its chain from one).
pub type Slot<'a> = &'a dyn Fn(usize) -> Xoshiro256PlusPlus;

/// A registered link model.
pub struct LinkModel {
    pub kind: ChannelKind,
    /// One line for `hushfuse list-links` and the docs.
    pub summary: &'static str,
    /// Its own keys (a key of another model is refused under this one).
    pub keys: &'static [KeyDoc],
    /// The checks of its keys' values; `path` names the table.
    pub validate: fn(&ChannelSpec, path: &str) -> Result<(), String>,
    /// The loss probability of a packet sent at each step `1..=steps`; `slot(j)` is the
    /// link's generator of slot j (a model with a hidden state draws its chain from one).
    pub loss_path: fn(&ChannelSpec, usize, Slot) -> Vec<f64>,
    /// The long-run probability that a report is lost for good (after `arq`'s retries): what a
    /// loss-aware center assumes.
    pub delivery_loss: fn(&ChannelSpec) -> f64,
}

/// Attempts of a packet on `spec`: the first and `arq`'s retries.
fn attempts(spec: &ChannelSpec) -> i32 {
    1 + spec.arq.map_or(0, |a| a.max_retries.min(Arq::MAX_RETRIES)) as i32
}

/// Every link model, in the order the docs list them.
pub const LINK_MODELS: &[LinkModel] = &[
    LinkModel {
        kind: ChannelKind::Ideal,
        summary: "every packet arrives",
        keys: &[],
        validate: |_, _| Ok(()),
        loss_path: |_, steps, _| vec![0.0; steps],
        delivery_loss: |_| 0.0,
    },
    LinkModel {
        kind: ChannelKind::Bernoulli,
        summary: "each packet lost independently with probability `loss`",
        keys: &[KeyDoc {
            name: "loss",
            default: "required",
            meaning: "probability that a packet is lost",
        }],
        validate: |s, path| {
            let loss = required(path, s.kind, "loss", s.loss)?;
            probability(path, "loss", loss)
        },
        loss_path: |s, steps, _| vec![super::gilbert_elliott::clamp_probability(s.loss.unwrap_or(0.0)); steps],
        delivery_loss: |s| s.loss.unwrap_or(0.0).powi(attempts(s)),
    },
    LinkModel {
        kind: ChannelKind::GilbertElliott,
        summary: "bursts: a two-state Markov chain (good, bad) with a loss probability per state (Gilbert 1960, Elliott 1963)",
        keys: &[
            KeyDoc {
                name: "p_gb, p_bg",
                default: "required",
                meaning: "per-step probabilities of going from good to bad and from bad to good (mean burst 1 / p_bg steps); the chain starts in its stationary distribution",
            },
            KeyDoc {
                name: "loss_good, loss_bad",
                default: "0, 1",
                meaning: "loss probability in each state",
            },
        ],
        validate: |s, path| {
            probability(path, "p_gb", required(path, s.kind, "p_gb", s.p_gb)?)?;
            probability(path, "p_bg", required(path, s.kind, "p_bg", s.p_bg)?)?;
            probability(path, "loss_good", s.loss_good())?;
            probability(path, "loss_bad", s.loss_bad())
        },
        loss_path: super::gilbert_elliott::loss_path,
        delivery_loss: |s| {
            let (gb, bg) = (s.p_gb.unwrap_or(0.0), s.p_bg.unwrap_or(0.0));
            let bad = if gb + bg > 0.0 { gb / (gb + bg) } else { 0.0 };
            let n = attempts(s);
            (1.0 - bad) * s.loss_good().powi(n) + bad * s.loss_bad().powi(n)
        },
    },
];

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
    LINK_MODELS
        .iter()
        .find(|m| m.kind == kind)
        .expect("every kind is registered")
}

/// What a link's model says of it: its checks and the loss a loss-aware center assumes.
impl ChannelSpec {
    /// The probability that an uplink packet is never delivered, in the long run: what a
    /// loss-aware center assumes for this link (`link_loss = "channel"`). Bernoulli `p`, and
    /// with `arq` of `n` retries `p^(1+n)` (each attempt draws its own loss); Gilbert–Elliott
    /// at its stationary state, `π_good loss_good^(1+n) + π_bad loss_bad^(1+n)` (the retries of
    /// a step see that step's state; π_bad = p_gb / (p_gb + p_bg), 0 when the chain never
    /// moves, as the fates take it). A delay is not a loss and counts nothing here. Assumes a
    /// validated spec.
    pub fn delivery_loss(&self) -> f64 {
        (of(self.kind).delivery_loss)(self)
    }

    /// Checks the table found at `channel`; see [`ChannelSpec::validate_at`].
    pub fn validate(&self) -> Result<(), String> {
        self.validate_at("channel")
    }

    /// Checks the keys against the kind and the values against their ranges. `path` names the
    /// table in messages (`"channel"`, `"sensors[2].channel"`, …) so the user can find the key.
    pub fn validate_at(&self, path: &str) -> Result<(), String> {
        self.check_keys_fit_kind(path)?;
        (of(self.kind).validate)(self, path)?;
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
        for owner in LINK_MODELS.iter().filter(|m| m.kind != self.kind) {
            for key in owner.keys.iter().flat_map(|k| k.name.split(", ")) {
                if self.has_key(key) {
                    return Err(format!(
                        "{path}.{key} belongs to kind = \"{}\", not \"{}\"",
                        owner.kind.name(),
                        self.kind.name()
                    ));
                }
            }
        }
        Ok(())
    }

    /// Whether the model key `key` is written in the table.
    fn has_key(&self, key: &str) -> bool {
        match key {
            "loss" => self.loss.is_some(),
            "p_gb" => self.p_gb.is_some(),
            "p_bg" => self.p_bg.is_some(),
            "loss_good" => self.loss_good.is_some(),
            "loss_bad" => self.loss_bad.is_some(),
            _ => unreachable!("every registered key is a field of ChannelSpec: {key}"),
        }
    }
}

/// The value of a key the kind needs, or an error naming it.
fn required(path: &str, kind: ChannelKind, key: &str, value: Option<f64>) -> Result<f64, String> {
    value.ok_or_else(|| format!("{path}.kind = \"{}\" needs `{key}`", kind.name()))
}

/// Checks that `value` is a probability; NaN fails the range test and is rejected too.
fn probability(path: &str, key: &str, value: f64) -> Result<(), String> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(format!(
            "{path}.{key} = {value} is not a probability in [0, 1]"
        ))
    }
}

/// The `[channel]` key table of `docs/scenarios.md`.
pub fn markdown() -> String {
    let kinds: Vec<String> = LINK_MODELS
        .iter()
        .map(|m| format!("`{}` ({})", m.kind.name(), m.summary))
        .collect();
    let mut out = String::from("| field | default | meaning |\n|---|---|---|\n");
    out.push_str(&format!("| `kind` | `ideal` | {} |\n", kinds.join("; ")));
    for m in LINK_MODELS {
        for k in m.keys {
            let names: Vec<String> = k.name.split(", ").map(|n| format!("`{n}`")).collect();
            let default = match k.default {
                "required" => format!("required for `{}`", m.kind.name()),
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
        out.push_str(&format!("{}: {}\n", m.kind.name(), m.summary));
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
        let docs = include_str!("../../../docs/scenarios.md");
        assert!(
            docs.contains(&markdown()),
            "docs/scenarios.md's [channel] table differs from `hushfuse list-links --markdown`:\n{}",
            markdown()
        );
    }

    /// Every kind is registered once, and its long-run loss is what its keys say by hand.
    #[test]
    fn every_kind_once_and_its_belief_by_hand() {
        for kind in [
            ChannelKind::Ideal,
            ChannelKind::Bernoulli,
            ChannelKind::GilbertElliott,
        ] {
            assert_eq!(LINK_MODELS.iter().filter(|m| m.kind == kind).count(), 1);
        }
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
        // Every documented key is a field the checks can see (none set in a default table).
        for key in LINK_MODELS
            .iter()
            .flat_map(|m| m.keys)
            .flat_map(|k| k.name.split(", "))
        {
            assert!(!ChannelSpec::default().has_key(key), "{key}");
        }
    }
}
