//! The link models, registered as the schemes are (`crate::scheme::SCHEMES`): each with its
//! `kind`, its keys and their documentation, its checks, the loss it puts on each step, and the
//! long-run loss a loss-aware center believes (`link_loss = "channel"`, derived here from the
//! link's own keys, never typed twice). The `[channel]` table of `docs/scenarios.md` is
//! generated from this list ([`markdown`], `hushfuse list-links --markdown`; a test keeps the
//! two equal).
//!
//! Adding a model: its `ChannelKind` variant and keys in [`super::spec`], its entry here (and
//! its per-step loss beside the others in [`super::fate`]).
use super::spec::{Arq, ChannelKind, ChannelSpec};
use rand_xoshiro::Xoshiro256PlusPlus;

/// One documented key of a link model.
#[derive(Debug, Clone, Copy)]
pub struct KeyDoc {
    pub name: &'static str,
    pub default: &'static str,
    pub meaning: &'static str,
}

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
    pub loss_path: fn(&ChannelSpec, usize, &dyn Fn(usize) -> Xoshiro256PlusPlus) -> Vec<f64>,
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
            let loss = super::spec::required(path, s.kind, "loss", s.loss)?;
            super::spec::probability(path, "loss", loss)
        },
        loss_path: |s, steps, _| vec![super::fate::clamp_probability(s.loss.unwrap_or(0.0)); steps],
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
            use super::spec::{probability, required};
            probability(path, "p_gb", required(path, s.kind, "p_gb", s.p_gb)?)?;
            probability(path, "p_bg", required(path, s.kind, "p_bg", s.p_bg)?)?;
            probability(path, "loss_good", s.loss_good())?;
            probability(path, "loss_bad", s.loss_bad())
        },
        loss_path: super::fate::gilbert_elliott_loss_path,
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
    }
}
