//! The ideal link: every packet arrives (the link of a scenario without `[channel]`; with a
//! `delay` or `arq` it is late or acknowledged, never lossy).
use super::{Arrivals, LinkModel};

/// Its `kind`.
pub const NAME: &str = "ideal";

pub const MODEL: LinkModel = LinkModel {
    name: NAME,
    summary: "every packet arrives",
    keys: &[],
    validate: |_, _| Ok(()),
    draws_loss: false,
    loss_path: |_, steps, _| vec![0.0; steps],
    delivery_loss: |_| 0.0,
    loses: |_| false,
    worst_loss: |_| 0.0,
    expected_attempts: |_, _| 1.0,
    arrivals: |_| Ok(Arrivals::Bernoulli { gamma: 1.0 }),
};
