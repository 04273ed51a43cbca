//! The Gilbert–Elliott link (Gilbert 1960, Elliott 1963): a two-state Markov chain (good, bad)
//! with a loss probability per state, started in its stationary distribution. Its per-step loss
//! is a path of the chain, drawn from the link's generator of slot [`CHAIN_STEP`]; the retries
//! of a step see that step's state.
use super::{attempts, clamp_probability, expected_attempts, probability, required};
use super::{Arrivals, KeyDoc, LinkModel};
use crate::network::channel::ChannelSpec;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Its `kind`.
pub const NAME: &str = "gilbert-elliott";

/// The keys as written: (p_gb, p_bg, loss_good, loss_bad), with their defaults (the
/// transitions 0 before validation, loss_good 0, loss_bad 1).
fn keys(s: &ChannelSpec) -> (f64, f64, f64, f64) {
    (
        s.key("p_gb").unwrap_or(0.0),
        s.key("p_bg").unwrap_or(0.0),
        s.key("loss_good").unwrap_or(0.0),
        s.key("loss_bad").unwrap_or(1.0),
    )
}

/// π_bad = p_gb / (p_gb + p_bg) of the keys as written (0 when the chain never moves).
fn bad_share(s: &ChannelSpec) -> f64 {
    let (gb, bg, _, _) = keys(s);
    if gb + bg > 0.0 {
        gb / (gb + bg)
    } else {
        0.0
    }
}

pub const MODEL: LinkModel = LinkModel {
    name: NAME,
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
        probability(path, "p_gb", required(path, s, "p_gb")?)?;
        probability(path, "p_bg", required(path, s, "p_bg")?)?;
        let (_, _, good, bad) = keys(s);
        probability(path, "loss_good", good)?;
        probability(path, "loss_bad", bad)
    },
    draws_loss: true,
    loss_path,
    delivery_loss: |s| {
        let (_, _, good, bad) = keys(s);
        let (share, n) = (bad_share(s), attempts(s));
        (1.0 - share) * good.powi(n) + share * bad.powi(n)
    },
    loses: |s| {
        let (_, _, good, bad) = keys(s);
        good != 0.0 || bad != 0.0
    },
    worst_loss: |s| {
        let (_, _, good, bad) = keys(s);
        good.max(bad)
    },
    // A hop retries in one state: the attempts of each state's loss, weighted by its share.
    expected_attempts: |s, r| {
        let (_, _, good, bad) = keys(s);
        let share = bad_share(s);
        (1.0 - share) * expected_attempts(good, r) + share * expected_attempts(bad, r)
    },
    arrivals: |s| {
        let (p_gb, p_bg, good, bad) = keys(s);
        if good != 0.0 || bad != 1.0 {
            return Err(format!(
                "a Gilbert–Elliott link needs loss_good = 0 and loss_bad = 1 (got {good} and {bad})"
            ));
        }
        Ok(Arrivals::GilbertElliott { p_gb, p_bg })
    },
};

/// The step index given to [`crate::stats::seeding::slot_rng`] for a sensor's Gilbert–Elliott state chain.
/// No real step reaches it, so the chain's generator is distinct from every slot's, and the
/// chain (which must be drawn in order) does not shift any slot's draws.
pub const CHAIN_STEP: usize = usize::MAX;

/// The parameters of a Gilbert–Elliott chain.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GilbertElliott {
    p_gb: f64,
    p_bg: f64,
    loss_good: f64,
    loss_bad: f64,
}

impl GilbertElliott {
    pub(crate) fn from_spec(spec: &ChannelSpec) -> Self {
        let (p_gb, p_bg, good, bad) = keys(spec);
        Self {
            p_gb: clamp_probability(p_gb),
            p_bg: clamp_probability(p_bg),
            loss_good: clamp_probability(good),
            loss_bad: clamp_probability(bad),
        }
    }

    /// Stationary probability of the bad state, π_bad = p_gb / (p_gb + p_bg); 0 when both are 0
    /// (the chain never moves, and it is taken to start good).
    fn stationary_bad(&self) -> f64 {
        let total = self.p_gb + self.p_bg;
        if total > 0.0 {
            self.p_gb / total
        } else {
            0.0
        }
    }

    /// The state before step 1, from the stationary distribution, so the link is in its long-run
    /// regime from the first step on (no warm-up transient in short trials).
    fn initial_bad(&self, rng: &mut Xoshiro256PlusPlus) -> bool {
        rng.random::<f64>() < self.stationary_bad()
    }

    /// The chain's states at steps 1, 2, … drawn from `rng` (the initial state, then one
    /// transition per step).
    pub(crate) fn states(&self, mut rng: Xoshiro256PlusPlus) -> States {
        let bad = self.initial_bad(&mut rng);
        States {
            chain: *self,
            rng,
            bad,
        }
    }

    /// One step of the chain.
    fn transition(&self, bad: bool, rng: &mut Xoshiro256PlusPlus) -> bool {
        let u = rng.random::<f64>();
        if bad {
            u >= self.p_bg
        } else {
            u < self.p_gb
        }
    }

    pub(crate) fn loss(&self, bad: bool) -> f64 {
        if bad {
            self.loss_bad
        } else {
            self.loss_good
        }
    }
}

/// The states of a Gilbert–Elliott chain, step by step.
pub(crate) struct States {
    chain: GilbertElliott,
    rng: Xoshiro256PlusPlus,
    bad: bool,
}

impl States {
    /// Whether the chain is bad at the next step.
    pub(crate) fn next_bad(&mut self) -> bool {
        self.bad = self.chain.transition(self.bad, &mut self.rng);
        self.bad
    }
}

/// The Gilbert–Elliott link's loss per step: its chain, drawn from `slot(CHAIN_STEP)`.
fn loss_path(spec: &ChannelSpec, steps: usize, slot: super::Slot) -> Vec<f64> {
    let chain = GilbertElliott::from_spec(spec);
    let mut states = chain.states(slot(CHAIN_STEP));
    (0..steps).map(|_| chain.loss(states.next_bad())).collect()
}
