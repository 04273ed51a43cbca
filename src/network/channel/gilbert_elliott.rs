//! The Gilbert–Elliott link (Gilbert 1960, Elliott 1963): a two-state Markov chain (good, bad)
//! with a loss probability per state, started in its stationary distribution. Its per-step loss
//! is a path of the chain, drawn from the link's generator of slot [`CHAIN_STEP`].
use super::spec::ChannelSpec;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The step index given to [`crate::stats::seeding::slot_rng`] for a sensor's Gilbert–Elliott state chain.
/// No real step reaches it, so the chain's generator is distinct from every slot's, and the
/// chain (which must be drawn in order) does not shift any slot's draws.
pub const CHAIN_STEP: usize = usize::MAX;

/// The parameters of a Gilbert–Elliott chain.
#[derive(Debug, Clone, Copy)]
pub(super) struct GilbertElliott {
    p_gb: f64,
    p_bg: f64,
    loss_good: f64,
    loss_bad: f64,
}

impl GilbertElliott {
    pub(super) fn from_spec(spec: &ChannelSpec) -> Self {
        Self {
            p_gb: clamp_probability(spec.p_gb.unwrap_or(0.0)),
            p_bg: clamp_probability(spec.p_bg.unwrap_or(0.0)),
            loss_good: clamp_probability(spec.loss_good()),
            loss_bad: clamp_probability(spec.loss_bad()),
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
    pub(super) fn states(&self, mut rng: Xoshiro256PlusPlus) -> States {
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

    pub(super) fn loss(&self, bad: bool) -> f64 {
        if bad {
            self.loss_bad
        } else {
            self.loss_good
        }
    }
}

/// The states of a Gilbert–Elliott chain, step by step.
pub(super) struct States {
    chain: GilbertElliott,
    rng: Xoshiro256PlusPlus,
    bad: bool,
}

impl States {
    /// Whether the chain is bad at the next step.
    pub(super) fn next_bad(&mut self) -> bool {
        self.bad = self.chain.transition(self.bad, &mut self.rng);
        self.bad
    }
}

pub(super) fn clamp_probability(p: f64) -> f64 {
    if p.is_nan() {
        0.0
    } else {
        p.clamp(0.0, 1.0)
    }
}

/// The Gilbert–Elliott link's loss per step: its chain, drawn from `slot(CHAIN_STEP)`.
pub(super) fn loss_path(
    spec: &ChannelSpec,
    steps: usize,
    slot: &dyn Fn(usize) -> Xoshiro256PlusPlus,
) -> Vec<f64> {
    let chain = GilbertElliott::from_spec(spec);
    let mut states = chain.states(slot(CHAIN_STEP));
    (0..steps).map(|_| chain.loss(states.next_bad())).collect()
}
