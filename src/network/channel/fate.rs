//! The fate of every (sensor, step) slot of a trial, drawn once before any scheme runs: whether
//! a packet sent in that slot is lost and, if not, how many steps it takes. Drawing the table up
//! front from generators of the link's own stream ([`seeding::slot_rng`]) means every scheme that
//! sends in a slot meets the same fate (a paired comparison across schemes), and no fate depends
//! on which schemes ran, how often they sent, or in which order.
//!
//! # Retransmission (`arq`)
//!
//! With `arq = { max_retries = n }` a packet is sent up to 1 + n times within its step, as the
//! IEEE 802.15.4 MAC does: each attempt draws its own loss; after an attempt that arrives the
//! receiver sends an acknowledgment (ACK) frame on the downlink, which the downlink's model may
//! lose too (an absent `downlink` is ideal); a sender that hears no ACK tries again while it has
//! retries left. An attempt whose data arrived but whose ACK was lost makes the sender repeat a
//! packet the center already has: a duplicate, which the center discards (counted).
//!
//! The draws of a slot with ARQ, all from the slot's own generator: first the first attempt's
//! loss coin and the delay, exactly as without `arq` (a slot drawn without `arq` is the same
//! slot's first attempt with it); then, attempt after attempt, further numbers of the same
//! generator: the ACK's loss coin after an attempt that arrived, the next attempt's loss coin
//! before a retry. The numbers depend on the slot only, so every scheme that sends in a slot
//! meets the same attempts too. The delay, one per slot, applies to the attempt that arrived.
//!
//! - Bernoulli: each retry is an independent coin with the link's `loss`, so a packet is lost
//!   with probability p^(1+n) and a sent packet takes p (1 − p^n) / (1 − p) retries on average
//!   (ideal ACKs).
//! - Gilbert–Elliott: the retries of a step see the step's channel state (the chain moves once
//!   a step, the MAC retries within milliseconds). In the bad state with `loss_bad = 1` every
//!   retry fails: bursts defeat ARQ, which only helps against the losses within a state.
//! - ACKs on a Gilbert–Elliott downlink see the downlink chain's state of that step (the same
//!   chain that decides the feedback's fate), each ACK with its own coin.
use rand::Rng;
use rand_distr::Distribution;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::spec::{Arq, ChannelSpec, Delay};
use crate::stats::seeding;

pub use super::models::gilbert_elliott::CHAIN_STEP;

/// What happens to a packet sent in one slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fate {
    /// The packet never arrives.
    pub lost: bool,
    /// Steps between sending and arrival (0 = same step). 0 when `lost`.
    pub delay: u32,
    /// ARQ: attempts after the first (0 without `arq`).
    pub retries: u32,
    /// ARQ: acknowledgment frames the receiver sent, one per attempt that arrived (0 without
    /// `arq`); every one after the first acknowledges a duplicate.
    pub acks: u32,
    /// Over a multi-hop route ([`super::route`]): the hops after the first that the packet was
    /// sent over (each one frame more, its retries in `retries`, its ACKs in `acks`). 0 on a
    /// one-hop link.
    pub relayed: u32,
}

impl Fate {
    /// Times the packet went on air: the first attempt and the retries.
    pub fn attempts(&self) -> u32 {
        1 + self.relayed + self.retries
    }

    /// Attempts that arrived after one had already arrived (their ACK was lost): copies the
    /// center discards.
    pub fn duplicates(&self) -> u32 {
        // Every hop crossed has one ACK that was not a duplicate's: the hops before the last
        // one tried, and that one too when the packet got through.
        self.acks
            .saturating_sub(self.relayed + u32::from(!self.lost))
    }
}

/// The fates of all slots of one trial and one direction, sensor-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FateTable {
    sensors: usize,
    steps: usize,
    fates: Vec<Fate>,
}

impl FateTable {
    /// Draws the fates of `specs.len()` sensors over steps `1..=steps` of trial `trial`.
    /// With `downlink = false` the table is the uplink's (each sensor's own spec); with
    /// `downlink = true` it is the feedback link's, using each spec's `downlink` model (absent =
    /// ideal), drawn from the generators of the downlink slots.
    ///
    /// An uplink with `arq` also draws its retransmissions (see the module's documentation);
    /// the losses of its ACKs follow the downlink's model, whose Gilbert–Elliott state is the
    /// downlink table's. A downlink has no retransmission.
    ///
    /// The specs are expected to have passed [`ChannelSpec::validate`]; out-of-range values are
    /// clamped into range rather than trusted (a NaN probability counts as 0, `max_retries`
    /// above [`Arq::MAX_RETRIES`] counts as the maximum).
    pub fn draw(
        specs: &[ChannelSpec],
        steps: usize,
        seed: u64,
        trial: u64,
        downlink: bool,
    ) -> FateTable {
        let mut fates = Vec::with_capacity(specs.len() * steps);
        for (sensor, spec) in specs.iter().enumerate() {
            let slot = seeding::sensor_slots(seed, trial, sensor, downlink);
            if downlink {
                draw_sensor(&spec.downlink_spec(), steps, slot, None, &mut fates);
            } else {
                let arq = spec.arq.map(|arq| {
                    let down = seeding::sensor_slots(seed, trial, sensor, true);
                    Retries {
                        max: arq.max_retries.min(Arq::MAX_RETRIES),
                        ack_loss: loss_path(&spec.downlink_spec(), steps, down),
                    }
                });
                draw_sensor(spec, steps, slot, arq.as_ref(), &mut fates);
            }
        }
        FateTable {
            sensors: specs.len(),
            steps,
            fates,
        }
    }

    /// A table of given fates, sensor-major (`fates[sensor * steps + step - 1]`): composed
    /// routes ([`super::route`]) and hand-built links for the link layer's tests.
    pub(crate) fn from_fates(sensors: usize, steps: usize, fates: Vec<Fate>) -> FateTable {
        assert_eq!(fates.len(), sensors * steps);
        FateTable {
            sensors,
            steps,
            fates,
        }
    }

    /// The fate of a packet sent by `sensor` at step `step` (1-based, as in the engine's
    /// [`crate::network::Schedule::allows`]). Panics outside the drawn table: that is a bug in
    /// the caller, not a property of the input.
    pub fn get(&self, sensor: usize, step: usize) -> Fate {
        assert!(
            sensor < self.sensors && (1..=self.steps).contains(&step),
            "slot (sensor {sensor}, step {step}) outside the fate table ({} sensors, steps 1..={})",
            self.sensors,
            self.steps
        );
        self.fates[sensor * self.steps + (step - 1)]
    }

    /// Number of sensors in the table.
    pub fn sensors(&self) -> usize {
        self.sensors
    }

    /// Number of steps in the table (steps run 1..=steps).
    pub fn steps(&self) -> usize {
        self.steps
    }
}

/// The retransmission rule of an uplink: at most `max` retries, and the probability that the
/// ACK of an attempt at step k is lost, `ack_loss[k - 1]`.
struct Retries {
    max: u32,
    ack_loss: Vec<f64>,
}

/// Appends the fates of one sensor's steps `1..=steps`. `slot(k)` is the generator of slot k;
/// each slot's loss coin, delay and (with `arq`) retries come from its own generator, the
/// Gilbert–Elliott state from `slot(CHAIN_STEP)` ([`loss_path`]).
fn draw_sensor(
    spec: &ChannelSpec,
    steps: usize,
    slot: impl Fn(usize) -> Xoshiro256PlusPlus,
    arq: Option<&Retries>,
    out: &mut Vec<Fate>,
) {
    let losses = loss_path(spec, steps, &slot);
    for k in 1..=steps {
        let arq = arq.map(|r| (r.max, r.ack_loss[k - 1]));
        out.push(slot_fate(spec, losses[k - 1], || slot(k), arq));
    }
}

/// The fate of one packet on the link `spec` whose loss at its step is `loss` (the state's,
/// for Gilbert–Elliott), drawn from `slot()`: the loss coin, then the delay and the retries
/// ([`fate`]). An ideal link draws no loss coin (its first attempt always arrives); one of fixed
/// delay without `arq` draws nothing, and its generator is not even made. `arq`: (retry limit,
/// probability an ACK is lost).
pub(crate) fn slot_fate(
    spec: &ChannelSpec,
    loss: f64,
    slot: impl FnOnce() -> Xoshiro256PlusPlus,
    arq: Option<(u32, f64)>,
) -> Fate {
    let delay = spec.delay();
    if !spec.kind.model().draws_loss {
        return match (&delay, arq) {
            (Delay::Fixed(d), None) => Fate {
                delay: *d,
                ..Fate::default()
            },
            _ => fate(false, 0.0, &delay, &mut slot(), arq),
        };
    }
    let mut rng = slot();
    let lost = rng.random::<f64>() < loss;
    // Retries within the step see the same state, hence the same loss.
    fate(lost, loss, &delay, &mut rng, arq)
}

/// The loss probability of a packet sent at each step `1..=steps` on the link `spec`: constant
/// for ideal and Bernoulli links, the state's for Gilbert–Elliott, whose chain is drawn from
/// `slot(CHAIN_STEP)` exactly as [`draw_sensor`] draws it (so the ACKs of an uplink see the
/// states that decide its downlink's feedback).
pub(crate) fn loss_path(
    spec: &ChannelSpec,
    steps: usize,
    slot: impl Fn(usize) -> Xoshiro256PlusPlus,
) -> Vec<f64> {
    (spec.kind.model().loss_path)(spec, steps, &slot)
}

/// A slot's fate. `lost` is the first attempt's coin, already drawn from `rng`; the delay is
/// drawn next, even when the packet is lost, so that a slot's generator is always used the same
/// way, then reported as 0 for a lost packet. With `arq = Some((max_retries, ack_loss))` the
/// retries follow from further numbers of `rng` ([`retransmit`]), each attempt lost with
/// probability `loss`.
fn fate(
    lost: bool,
    loss: f64,
    delay: &Delay,
    rng: &mut Xoshiro256PlusPlus,
    arq: Option<(u32, f64)>,
) -> Fate {
    let d = draw_delay(delay, rng);
    let (lost, retries, acks) = match arq {
        None => (lost, 0, 0),
        Some((max_retries, ack_loss)) => retransmit(lost, loss, max_retries, ack_loss, rng),
    };
    Fate {
        lost,
        delay: if lost { 0 } else { d },
        retries,
        acks,
        relayed: 0,
    }
}

/// The attempts of one packet under ARQ, from the first attempt's outcome (`first_lost`): after
/// an attempt that arrives the receiver sends an ACK, lost with probability `ack_loss` (one coin
/// of `rng`); the sender stops at the first ACK it hears, else retries while it has retries left,
/// each retry lost with probability `loss` (one coin of `rng`). Returns (lost: no attempt
/// arrived, retries, ACKs sent).
fn retransmit(
    first_lost: bool,
    loss: f64,
    max_retries: u32,
    ack_loss: f64,
    rng: &mut Xoshiro256PlusPlus,
) -> (bool, u32, u32) {
    let mut attempt_lost = first_lost;
    let (mut retries, mut acks) = (0, 0);
    loop {
        if !attempt_lost {
            acks += 1;
            let ack_lost = rng.random::<f64>() < ack_loss;
            if !ack_lost {
                break;
            }
        }
        if retries == max_retries {
            break;
        }
        retries += 1;
        attempt_lost = rng.random::<f64>() < loss;
    }
    (acks == 0, retries, acks)
}

/// Below this success probability (a mean delay above 1e9 steps) a geometric delay is drawn by
/// inverting its CDF, see [`draw_delay`].
const TINY_SUCCESS: f64 = 1e-9;

/// A delay in steps. Geometric with mean μ: the number of failures before the first success of
/// trials with success probability p = 1/(1+μ), whose mean is (1−p)/p = μ; μ = 0 gives 0.
fn draw_delay(delay: &Delay, rng: &mut Xoshiro256PlusPlus) -> u32 {
    match delay {
        Delay::Fixed(d) => *d,
        Delay::Geometric(g) => {
            let mean = if g.mean.is_finite() {
                g.mean.max(0.0)
            } else {
                0.0
            };
            if mean == 0.0 {
                return 0;
            }
            let p = 1.0 / (1.0 + mean);
            if p < TINY_SUCCESS {
                // `rand_distr`'s sampler loops for ever where 1 − p rounds to 1 (a mean of
                // 1e17 steps). Such a delay outlasts any run (at most 1e7 steps) with
                // probability above 0.99: invert the CDF instead, P(D ≥ n) = (1 − p)^n, with
                // ln(1 − p) taken exactly for tiny p. One uniform, never a loop.
                let u: f64 = 1.0 - rng.random::<f64>(); // in (0, 1]
                let d = (u.ln() / (-p).ln_1p()).floor();
                return if d.is_finite() && d < f64::from(u32::MAX) {
                    d as u32
                } else {
                    u32::MAX
                };
            }
            match rand_distr::Geometric::new(p) {
                Ok(geo) => u32::try_from(geo.sample(rng)).unwrap_or(u32::MAX),
                // Unreachable for a finite mean > 0 (p lies in (0, 1)); no delay is the safe
                // reading of a value validation should have rejected.
                Err(_) => 0,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::spec::{DelayKind, GeometricDelay};
    use super::*;

    const SEED: u64 = 0x5EED_CAFE;

    fn bernoulli(loss: f64) -> ChannelSpec {
        ChannelSpec::of_kind("bernoulli", &[("loss", loss)])
    }

    fn gilbert_elliott(p_gb: f64, p_bg: f64, loss_good: f64, loss_bad: f64) -> ChannelSpec {
        let keys = [
            ("p_gb", p_gb),
            ("p_bg", p_bg),
            ("loss_good", loss_good),
            ("loss_bad", loss_bad),
        ];
        ChannelSpec::of_kind("gilbert-elliott", &keys)
    }

    fn geometric(mean: f64) -> Delay {
        Delay::Geometric(GeometricDelay {
            kind: DelayKind::Geometric,
            mean,
            horizon: None,
        })
    }

    /// Every fate of the table, sensor-major.
    fn all(t: &FateTable) -> impl Iterator<Item = Fate> + '_ {
        (0..t.sensors()).flat_map(move |i| (1..=t.steps()).map(move |k| t.get(i, k)))
    }

    fn loss_rate(t: &FateTable) -> f64 {
        all(t).filter(|f| f.lost).count() as f64 / (t.sensors() * t.steps()) as f64
    }

    #[test]
    fn ideal_loses_nothing_and_has_no_delay() {
        let t = FateTable::draw(&vec![ChannelSpec::default(); 3], 500, SEED, 0, false);
        assert!(all(&t).all(|f| f == Fate::default()));
        // An absent downlink is ideal even when the uplink is not.
        let t = FateTable::draw(&[bernoulli(0.9)], 500, SEED, 0, true);
        assert!(all(&t).all(|f| f == Fate::default()));
    }

    #[test]
    fn fixed_delay_applies_to_every_delivered_packet() {
        let spec = ChannelSpec {
            delay: Some(Delay::Fixed(3)),
            ..bernoulli(0.5)
        };
        let t = FateTable::draw(&[spec], 1000, SEED, 0, false);
        assert!(all(&t).all(|f| if f.lost { f.delay == 0 } else { f.delay == 3 }));
    }

    #[test]
    fn bernoulli_loss_rate_matches() {
        let p = 0.3;
        let t = FateTable::draw(&vec![bernoulli(p); 20], 10_000, SEED, 7, false);
        let n = (t.sensors() * t.steps()) as f64;
        // Independent slots: SE = sqrt(p(1−p)/n) ≈ 0.00102 for n = 2·10^5; tolerance 4 SE.
        let se = (p * (1.0 - p) / n).sqrt();
        let rate = loss_rate(&t);
        assert!((rate - p).abs() < 4.0 * se, "rate {rate}, p {p}, se {se}");
    }

    #[test]
    fn gilbert_elliott_long_run_loss_rate_matches() {
        let (p_gb, p_bg, lg, lb) = (0.05, 0.2, 0.05, 0.9);
        let t = FateTable::draw(
            &vec![gilbert_elliott(p_gb, p_bg, lg, lb); 50],
            4_000,
            SEED,
            3,
            false,
        );
        let pi_bad = p_gb / (p_gb + p_bg);
        let expected = (1.0 - pi_bad) * lg + pi_bad * lb;
        // Losses are correlated through the state, whose autocorrelation at lag j is λ^j with
        // λ = 1 − p_gb − p_bg. Per-slot variance of the mean, long-run: the binomial part
        // E[ℓ(1−ℓ)] plus (lb − lg)² π_bad π_good (1+λ)/(1−λ) from the state. With these numbers
        // SE ≈ sqrt(0.865 / 2·10^5) ≈ 0.0021; tolerance 4 SE.
        let lambda = 1.0 - p_gb - p_bg;
        let binomial = (1.0 - pi_bad) * lg * (1.0 - lg) + pi_bad * lb * (1.0 - lb);
        let state = (lb - lg).powi(2) * pi_bad * (1.0 - pi_bad) * (1.0 + lambda) / (1.0 - lambda);
        let n = (t.sensors() * t.steps()) as f64;
        let se = ((binomial + state) / n).sqrt();
        let rate = loss_rate(&t);
        assert!(
            (rate - expected).abs() < 4.0 * se,
            "rate {rate}, expected {expected}, se {se}"
        );
    }

    #[test]
    fn gilbert_elliott_mean_burst_is_one_over_p_bg() {
        // loss_good = 0, loss_bad = 1: a run of losses is exactly a stay in the bad state, whose
        // length is geometric on {1, 2, …} with mean 1/p_bg and variance (1 − p_bg)/p_bg².
        let (p_gb, p_bg) = (0.05, 0.2);
        let t = FateTable::draw(
            &vec![gilbert_elliott(p_gb, p_bg, 0.0, 1.0); 50],
            4_000,
            SEED,
            11,
            false,
        );
        let mut bursts = Vec::new();
        for i in 0..t.sensors() {
            let mut run = 0usize;
            for k in 1..=t.steps() {
                if t.get(i, k).lost {
                    run += 1;
                } else if run > 0 {
                    bursts.push(run as f64);
                    run = 0;
                }
            }
            // A run still open at the last step is cut short; it is left out. (A run open at
            // step 1 is not biased: the stay's remaining length is memoryless.)
        }
        let m = bursts.len() as f64;
        let mean = bursts.iter().sum::<f64>() / m;
        // About 8000 bursts: SE = sqrt((1 − p_bg)/p_bg² / m) ≈ 0.05; tolerance 4 SE.
        let se = ((1.0 - p_bg) / (p_bg * p_bg) / m).sqrt();
        assert!(
            (mean - 1.0 / p_bg).abs() < 4.0 * se,
            "mean burst {mean}, expected {}, se {se}, {m} bursts",
            1.0 / p_bg
        );
    }

    #[test]
    fn geometric_delay_mean_matches() {
        let mu = 2.5;
        let spec = ChannelSpec {
            delay: Some(geometric(mu)),
            ..ChannelSpec::default()
        };
        let t = FateTable::draw(&vec![spec; 20], 10_000, SEED, 5, false);
        let n = (t.sensors() * t.steps()) as f64;
        let mean = all(&t).map(|f| f.delay as f64).sum::<f64>() / n;
        // Geometric (failures before success) with p = 1/(1+μ): variance (1−p)/p² = μ(1+μ).
        // SE = sqrt(8.75 / 2·10^5) ≈ 0.0066; tolerance 4 SE.
        let se = (mu * (1.0 + mu) / n).sqrt();
        assert!(
            (mean - mu).abs() < 4.0 * se,
            "mean {mean}, mu {mu}, se {se}"
        );
        // Mean 0 means no delay at all.
        let spec = ChannelSpec {
            delay: Some(geometric(0.0)),
            ..ChannelSpec::default()
        };
        let t = FateTable::draw(&[spec], 1000, SEED, 5, false);
        assert!(all(&t).all(|f| f.delay == 0));
    }

    #[test]
    fn same_seed_same_table_and_sensors_differ() {
        let specs = vec![
            bernoulli(0.5),
            bernoulli(0.5),
            gilbert_elliott(0.3, 0.3, 0.1, 0.9),
        ];
        let a = FateTable::draw(&specs, 300, SEED, 2, false);
        let b = FateTable::draw(&specs, 300, SEED, 2, false);
        assert_eq!(a, b);
        let lost =
            |t: &FateTable, i: usize| (1..=300).map(|k| t.get(i, k).lost).collect::<Vec<_>>();
        assert_ne!(lost(&a, 0), lost(&a, 1), "same spec, different sensors");
        let other_trial = FateTable::draw(&specs, 300, SEED, 3, false);
        assert_ne!(lost(&a, 0), lost(&other_trial, 0), "different trials");
        let other_seed = FateTable::draw(&specs, 300, SEED + 1, 2, false);
        assert_ne!(lost(&a, 0), lost(&other_seed, 0), "different seeds");
    }

    #[test]
    fn fates_do_not_depend_on_other_sensors_or_horizon() {
        // A sensor's fates depend only on its own slots: adding a sensor or lengthening the
        // trial changes none of the existing fates (the Gilbert–Elliott chain included).
        let specs = vec![gilbert_elliott(0.1, 0.3, 0.0, 1.0), bernoulli(0.4)];
        let short = FateTable::draw(&specs[..1], 200, SEED, 1, false);
        let long = FateTable::draw(&specs, 400, SEED, 1, false);
        for k in 1..=200 {
            assert_eq!(short.get(0, k), long.get(0, k));
        }
    }

    #[test]
    fn downlink_uses_its_own_model_and_draws() {
        let spec = ChannelSpec {
            downlink: Some(Box::new(bernoulli(0.5))),
            ..bernoulli(0.5)
        };
        let up = FateTable::draw(std::slice::from_ref(&spec), 2000, SEED, 0, false);
        let down = FateTable::draw(std::slice::from_ref(&spec), 2000, SEED, 0, true);
        assert_ne!(
            up, down,
            "the two directions draw from different generators"
        );
        let rate = loss_rate(&down);
        // SE = sqrt(0.25/2000) ≈ 0.011; tolerance 4 SE.
        assert!(
            (rate - 0.5).abs() < 4.0 * (0.25f64 / 2000.0).sqrt(),
            "{rate}"
        );
    }

    #[test]
    fn degenerate_chains() {
        // Both transition probabilities 0: π_bad = 0, the chain stays good forever.
        let t = FateTable::draw(&[gilbert_elliott(0.0, 0.0, 0.0, 1.0)], 500, SEED, 0, false);
        assert!(all(&t).all(|f| !f.lost));
        // p_gb = 1, p_bg = 0: bad from step 1 on, every packet lost.
        let t = FateTable::draw(&[gilbert_elliott(1.0, 0.0, 0.0, 1.0)], 500, SEED, 0, false);
        assert!(all(&t).all(|f| f.lost));
    }

    fn with_arq(spec: ChannelSpec, max_retries: u32) -> ChannelSpec {
        ChannelSpec {
            arq: Some(Arq { max_retries }),
            ..spec
        }
    }

    #[test]
    fn a_sensors_slots_are_the_slot_generators() {
        for (sensor, downlink) in [(0, false), (3, true)] {
            let slots = seeding::sensor_slots(SEED, 5, sensor, downlink);
            for step in [1, 2, 77, CHAIN_STEP] {
                let (mut a, mut b) = (
                    slots(step),
                    seeding::slot_rng(SEED, 5, sensor, step, downlink),
                );
                assert_eq!(a.random::<u64>(), b.random::<u64>());
            }
        }
    }

    #[test]
    fn arq_keeps_the_first_attempts_draws() {
        // Losses, geometric delays and a lossy ACK path: a slot whose first attempt arrived has
        // the fate it has without ARQ (same delay), only with its ACKs counted; a slot lost
        // without ARQ is the one that retries.
        let plain = ChannelSpec {
            delay: Some(geometric(1.5)),
            downlink: Some(Box::new(bernoulli(0.3))),
            ..bernoulli(0.4)
        };
        let arq = with_arq(plain.clone(), 3);
        let a = FateTable::draw(std::slice::from_ref(&plain), 2000, SEED, 4, false);
        let b = FateTable::draw(std::slice::from_ref(&arq), 2000, SEED, 4, false);
        let (mut retried, mut rescued) = (0, 0);
        for k in 1..=2000 {
            let (x, y) = (a.get(0, k), b.get(0, k));
            assert_eq!((x.retries, x.acks), (0, 0), "no ARQ, no attempts counted");
            if x.lost {
                assert!(y.retries >= 1, "step {k}: a lost first attempt is retried");
                retried += 1;
                rescued += usize::from(!y.lost);
            } else {
                assert!(
                    !y.lost && y.delay == x.delay && y.acks >= 1,
                    "step {k}: {y:?}"
                );
            }
            assert!(y.retries <= 3 && y.acks <= y.attempts());
            assert_eq!(y.lost, y.acks == 0);
        }
        // A lost first attempt is rescued by one of 3 retries with probability 1 − 0.4³.
        assert!(retried > 600 && rescued as f64 > 0.85 * retried as f64);
        // The downlink table does not change with the uplink's ARQ.
        assert_eq!(
            FateTable::draw(std::slice::from_ref(&plain), 300, SEED, 4, true),
            FateTable::draw(std::slice::from_ref(&arq), 300, SEED, 4, true)
        );
    }

    #[test]
    fn retry_draws_follow_the_acknowledgements() {
        use rand::SeedableRng;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        // Every ACK lost on a loss-free uplink: all 1 + 4 attempts arrive, 4 duplicates.
        let (lost, retries, acks) = retransmit(false, 0.0, 4, 1.0, &mut rng);
        assert_eq!((lost, retries, acks), (false, 4, 5));
        // Every attempt lost: no ACK, all retries spent.
        assert_eq!(retransmit(true, 1.0, 4, 0.0, &mut rng), (true, 4, 0));
        // First attempt arrives and its ACK too: done.
        assert_eq!(retransmit(false, 1.0, 4, 0.0, &mut rng), (false, 0, 1));
        // No retries allowed: the first attempt decides, its ACK is still sent.
        assert_eq!(retransmit(true, 0.0, 0, 0.0, &mut rng), (true, 0, 0));
        assert_eq!(retransmit(false, 0.0, 0, 1.0, &mut rng), (false, 0, 1));
        // Lost once, then through: one retry, one ACK.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        assert_eq!(retransmit(true, 0.0, 4, 0.0, &mut rng), (false, 1, 1));
        // The draws are the slot's: the same generator state gives the same attempts.
        let spec = with_arq(bernoulli(0.6), 2);
        let t = FateTable::draw(std::slice::from_ref(&spec), 500, SEED, 9, false);
        assert_eq!(
            t,
            FateTable::draw(std::slice::from_ref(&spec), 500, SEED, 9, false)
        );
        assert!(all(&t).any(|f| f.retries == 2 && f.lost));
        assert!(all(&t).any(|f| f.retries == 1 && !f.lost));
    }

    #[test]
    fn bernoulli_retries_are_independent_coins() {
        // P(lost) = p^(1+n), E[retries] = p (1 − p^n) / (1 − p) with ideal ACKs.
        let (p, n) = (0.5, 2);
        let t = FateTable::draw(&vec![with_arq(bernoulli(p), n); 10], 5000, SEED, 1, false);
        let slots = (t.sensors() * t.steps()) as f64;
        let lost = p.powi(n as i32 + 1);
        let se = (lost * (1.0 - lost) / slots).sqrt();
        assert!((loss_rate(&t) - lost).abs() < 4.0 * se, "{}", loss_rate(&t));
        let retries = all(&t).map(|f| f.retries as f64).sum::<f64>() / slots;
        let want = p * (1.0 - p.powi(n as i32)) / (1.0 - p);
        // Retries take 0, 1, 2 with probabilities 1/2, 1/4, 1/4: variance 11/16.
        let se = (11.0f64 / 16.0 / slots).sqrt();
        assert!((retries - want).abs() < 4.0 * se, "{retries} vs {want}");
        // Ideal ACKs: exactly one per packet that arrived, no duplicates.
        assert!(all(&t).all(|f| f.acks == u32::from(!f.lost) && f.duplicates() == 0));
    }

    #[test]
    fn gilbert_elliott_bursts_defeat_retries() {
        // loss_good = 0, loss_bad = 1: the first attempt arrives exactly in the good state and
        // every retry of a bad step fails, so ARQ rescues nothing: the same slots are lost.
        let ge = gilbert_elliott(0.1, 0.3, 0.0, 1.0);
        let a = FateTable::draw(std::slice::from_ref(&ge), 3000, SEED, 2, false);
        let b = FateTable::draw(&[with_arq(ge, 5)], 3000, SEED, 2, false);
        assert!(all(&a).any(|f| f.lost));
        for k in 1..=3000 {
            let (x, y) = (a.get(0, k), b.get(0, k));
            assert_eq!(x.lost, y.lost, "step {k}");
            let expected = if x.lost { (5, 0) } else { (0, 1) };
            assert_eq!((y.retries, y.acks), expected, "step {k}");
        }
    }

    #[test]
    fn acks_see_the_downlink_chain_of_their_step() {
        // A loss-free uplink whose downlink loses everything in its bad state: the ACKs of a
        // step are lost exactly when the downlink table loses that step's feedback.
        let spec = with_arq(
            ChannelSpec {
                downlink: Some(Box::new(gilbert_elliott(0.2, 0.2, 0.0, 1.0))),
                ..ChannelSpec::default()
            },
            2,
        );
        let up = FateTable::draw(std::slice::from_ref(&spec), 2000, SEED, 6, false);
        let down = FateTable::draw(std::slice::from_ref(&spec), 2000, SEED, 6, true);
        assert!(all(&down).any(|f| f.lost) && all(&down).any(|f| !f.lost));
        for k in 1..=2000 {
            let f = up.get(0, k);
            assert!(!f.lost);
            let expected = if down.get(0, k).lost { (2, 3) } else { (0, 1) };
            assert_eq!((f.retries, f.acks), expected, "step {k}");
        }
    }

    #[test]
    #[should_panic(expected = "outside the fate table")]
    fn step_zero_is_outside_the_table() {
        let t = FateTable::draw(&[ChannelSpec::default()], 10, SEED, 0, false);
        let _ = t.get(0, 0);
    }
}
