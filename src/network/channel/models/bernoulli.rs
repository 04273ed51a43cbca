//! The Bernoulli link: each packet lost independently with probability `loss` (the erasure
//! channel of Sinopoli et al. 2004); with `arq` each retry draws its own coin.
use super::{attempt_loss, attempts, clamp_probability, probability, required};
use super::{expected_attempts, Arrivals, KeyDoc, LinkModel};
use crate::network::channel::ChannelSpec;

/// Its `kind`.
pub const NAME: &str = "bernoulli";

/// The loss as written (0 before validation).
fn loss(s: &ChannelSpec) -> f64 {
    s.key("loss").unwrap_or(0.0)
}

pub const MODEL: LinkModel = LinkModel {
    name: NAME,
    summary: "each packet lost independently with probability `loss`",
    keys: &[KeyDoc {
        name: "loss",
        default: "required",
        meaning: "probability that a packet is lost",
    }],
    validate: |s, path| probability(path, "loss", required(path, s, "loss")?),
    draws_loss: true,
    loss_path: |s, steps, _| vec![clamp_probability(loss(s)); steps],
    delivery_loss: |s| loss(s).powi(attempts(s)),
    loses: |s| loss(s) != 0.0,
    worst_loss: loss,
    expected_attempts: |s, r| expected_attempts(attempt_loss(s), r),
    arrivals: |s| {
        Ok(Arrivals::Bernoulli {
            gamma: 1.0 - loss(s),
        })
    },
};
