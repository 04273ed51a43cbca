//! Loss from distance (`[network.distance_loss]`): each link's packet loss from the distance
//! between its nodes, by the log-distance path-loss model with optional log-normal shadowing and
//! the bit error rate of IEEE 802.15.4's 2.4 GHz O-QPSK PHY:
//!
//! ```text
//! received power  P_r(d) = P_t − PL(d0) − 10 η log10(d / d0) + X_σ      (dBm; d0 = 1 m)
//! SNR             γ = 10^((P_r − N) / 10)                               (N: noise floor, dBm)
//! BER             (8/15) (1/16) Σ_{k=2}^{16} (−1)^k C(16, k) exp(20 γ (1/k − 1))
//! PRR             (1 − BER)^(8 L)                                       (L: frame octets)
//! ```
//!
//! The BER is IEEE Std 802.15.4-2011, Annex E.4.1.8 (the 2450 MHz O-QPSK PHY, γ the SINR); the
//! log-distance model with shadowing is the one Zuniga and Krishnamachari (2004) use for the
//! transitional region of low-power links. A link's loss is 1 − PRR: a Bernoulli loss on a
//! frame of `frame_octets` octets (the frames of a run differ in length; one length per link
//! keeps the loss a property of the link, as the `[channel]` models have it). The shadowing of
//! each link is drawn once, from the model's own `seed`, in link order, so the network stays
//! the same whatever the run's seed.
use super::{err, Link, Node, TopologyError};
use crate::network::channel::ChannelSpec;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// `[network.distance_loss]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DistanceLoss {
    /// Transmit power, dBm (CC2420's highest setting: 0 dBm).
    #[serde(default)]
    pub tx_power_dbm: f64,
    /// Path loss at the reference distance of 1 m, dB (free space at 2.4 GHz: 40 dB).
    #[serde(default = "reference_loss_db")]
    pub reference_loss_db: f64,
    /// Path-loss exponent η (2 in free space, 3 to 4 indoors and near the ground).
    #[serde(default = "exponent")]
    pub exponent: f64,
    /// Noise floor, dBm (thermal noise over 2 MHz with a 10 dB noise figure: about −100 dBm).
    #[serde(default = "noise_floor_dbm")]
    pub noise_floor_dbm: f64,
    /// Standard deviation of the log-normal shadowing, dB (0: none).
    #[serde(default)]
    pub shadowing_db: f64,
    /// Seed of the shadowing draws (independent of the scenario's seed).
    #[serde(default)]
    pub seed: u64,
    /// Octets of the frame the loss is computed for (PHY header included).
    #[serde(default = "frame_octets")]
    pub frame_octets: u32,
}

fn reference_loss_db() -> f64 {
    40.0
}
fn exponent() -> f64 {
    3.0
}
fn noise_floor_dbm() -> f64 {
    -100.0
}
fn frame_octets() -> u32 {
    25
}

/// The bit error rate of 802.15.4's O-QPSK PHY at SNR `snr` (a ratio, not dB): 1/2 at 0, falling
/// to 0 as the SNR grows.
pub fn ber_oqpsk(snr: f64) -> f64 {
    let mut sum = 0.0;
    let mut binom = 1.0; // C(16, 0)
    for k in 1..=16u32 {
        binom *= f64::from(17 - k) / f64::from(k);
        if k >= 2 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            sum += sign * binom * (20.0 * snr * (1.0 / f64::from(k) - 1.0)).exp();
        }
    }
    (8.0 / 15.0 / 16.0 * sum).clamp(0.0, 0.5)
}

impl DistanceLoss {
    /// Checks the numbers (`network.distance_loss.*`).
    pub fn validate(&self) -> Result<(), TopologyError> {
        let field = |k: &str| format!("distance_loss.{k}");
        for (k, v) in [
            ("tx_power_dbm", self.tx_power_dbm),
            ("reference_loss_db", self.reference_loss_db),
            ("noise_floor_dbm", self.noise_floor_dbm),
        ] {
            if !v.is_finite() {
                return Err(err(field(k), format!("expected a finite number, got {v}")));
            }
        }
        if !(self.exponent.is_finite() && self.exponent > 0.0) {
            return Err(err(field("exponent"), "expected a number > 0"));
        }
        if !(self.shadowing_db.is_finite() && self.shadowing_db >= 0.0) {
            return Err(err(field("shadowing_db"), "expected a number >= 0"));
        }
        if self.frame_octets == 0 || self.frame_octets > 133 {
            return Err(err(
                field("frame_octets"),
                "expected 1 to 133 octets (an 802.15.4 PPDU)",
            ));
        }
        Ok(())
    }

    /// The packet reception rate at `d` metres with shadowing `shadow_db`.
    pub fn prr(&self, d: f64, shadow_db: f64) -> f64 {
        let d = d.max(1.0); // the model holds beyond its reference distance
        let received =
            self.tx_power_dbm - self.reference_loss_db - 10.0 * self.exponent * d.log10()
                + shadow_db;
        let snr = 10f64.powf((received - self.noise_floor_dbm) / 10.0);
        (1.0 - ber_oqpsk(snr)).powi(8 * self.frame_octets as i32)
    }

    /// Sets the loss of every link of `links` from its length: the link's channel (the
    /// scenario's `[channel]`) becomes Bernoulli with loss 1 − PRR, keeping its delay, ARQ and
    /// downlink. Both nodes of every link need a position; a Gilbert–Elliott channel is refused
    /// (its loss is a chain's, not one number).
    pub fn apply(&self, links: &mut [Link], nodes: &[Node]) -> Result<(), TopologyError> {
        self.validate()?;
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(self.seed);
        let shadow = Normal::new(0.0, self.shadowing_db).expect("checked: finite, >= 0");
        for l in links.iter_mut() {
            let (Some(a), Some(b)) = (nodes[l.a].position, nodes[l.b].position) else {
                return Err(err(
                    "distance_loss",
                    format!(
                        "the link {} – {} needs both nodes' positions",
                        nodes[l.a].name, nodes[l.b].name
                    ),
                ));
            };
            let kind = l.channel.kind.name();
            if kind != "ideal" && kind != "bernoulli" {
                return Err(err(
                    "distance_loss",
                    format!("sets a Bernoulli loss per link; the [channel] is {kind}"),
                ));
            }
            // Drawn for every link, shadowed or not, so a link's draw does not move.
            let x = if self.shadowing_db > 0.0 {
                shadow.sample(&mut rng)
            } else {
                0.0
            };
            let d = (a[0] - b[0]).hypot(a[1] - b[1]);
            l.channel = with_loss(&l.channel, 1.0 - self.prr(d, x));
        }
        Ok(())
    }
}

/// `c` with a Bernoulli loss of `p` in place of its own.
fn with_loss(c: &ChannelSpec, p: f64) -> ChannelSpec {
    c.as_kind("bernoulli", &[("loss", p.clamp(0.0, 1.0))])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> DistanceLoss {
        toml::from_str("").expect("every key has a default")
    }

    #[test]
    fn the_ber_by_hand() {
        // γ = 0: the alternating sum Σ_{k=2}^{16} (−1)^k C(16, k) = 15, times 8/(15·16) = 1/2.
        assert!((ber_oqpsk(0.0) - 0.5).abs() < 1e-12);
        // γ = 1 (0 dB): the sum in full (Python's math.comb gives 1.6152668792e-4).
        let by_hand: f64 = (2..=16)
            .map(|k: i32| {
                let c = (1..=k).fold(1.0, |a, j| a * f64::from(17 - j) / f64::from(j));
                (-1f64).powi(k) * c * (20.0 * (1.0 / f64::from(k) - 1.0)).exp()
            })
            .sum::<f64>()
            * 8.0
            / 15.0
            / 16.0;
        assert!((ber_oqpsk(1.0) - by_hand).abs() < 1e-15);
        assert!((ber_oqpsk(1.0) - 1.615_266_879_2e-4).abs() < 1e-13);
        assert!(ber_oqpsk(10.0) < 1e-40); // 1.5e-43 (Python)
    }

    #[test]
    fn reception_falls_with_distance() {
        let m = model();
        // 0 dBm − 40 dB − 30 log10(d) against −100 dBm: SNR 0 dB at d = 100 m, where a 25-octet
        // frame arrives with (1 − BER(1))^200 = 0.96821 (Python); the transitional region is
        // 100 to 130 m (0.44 at 115 m, 0.0072 at 130 m).
        assert!(m.prr(80.0, 0.0) > 0.999_99);
        assert!((m.prr(100.0, 0.0) - 0.968_208_379_346).abs() < 1e-9);
        assert!((m.prr(115.0, 0.0) - 0.441_241_491_380).abs() < 1e-9);
        assert!((m.prr(130.0, 0.0) - 0.007_233_737_208).abs() < 1e-9);
        let mut last = 1.0;
        for d in (10..200).map(f64::from) {
            let p = m.prr(d, 0.0);
            assert!(p <= last && (0.0..=1.0).contains(&p));
            last = p;
        }
        // 3 dB of shadowing gain is the same as a link 10^(3/30) shorter.
        let d = 90.0;
        let shorter = d / 10f64.powf(3.0 / 30.0);
        assert!((m.prr(d, 3.0) - m.prr(shorter, 0.0)).abs() < 1e-12);
    }
}
