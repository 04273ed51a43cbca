//! The seeding rule of every trial, written once: truth and measurements come from stream
//! [`DATA_STREAM`] of (seed, trial); variant v's coins from stream [`coin_stream`]`(v)`, so every
//! variant of a trial sees the same data (common random numbers) and no variant's coins depend
//! on another's. Within a variant each sensor has coins of its own ([`sensor_coins`]). The fusion center's own generator (particle filters) has a seed of its own
//! derived from the same stream.
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The stream of a trial's truth and measurements.
pub const DATA_STREAM: u64 = 0;

/// The coin stream of variant `v` of an experiment.
pub fn coin_stream(v: usize) -> u64 {
    1 + v as u64
}

/// The coins of one variant's trial: one generator per sensor ([`sensor_coins`]) and the
/// fusion center's seed.
pub fn coins(
    seed: u64,
    trial: usize,
    stream: u64,
    n_sensors: usize,
) -> (Vec<Xoshiro256PlusPlus>, u64) {
    let sensors = (0..n_sensors)
        .map(|i| sensor_coins(seed, trial as u64, stream, i))
        .collect();
    (sensors, center_seed(seed, trial as u64, stream))
}

/// Sensor `sensor`'s coins in the trial of coin stream `stream`: a generator of its own,
/// derived from the trial's stream seed and the sensor's index by splitmix steps (after a tag
/// of its own, so no sensor's seed is the center's or the stream's). A sensor's draws then
/// depend on (seed, trial, stream, sensor) only, never on how many draws the other sensors
/// made: a node running in its own process draws exactly what it draws in the simulation.
pub fn sensor_coins(seed: u64, trial: u64, stream: u64, sensor: usize) -> Xoshiro256PlusPlus {
    let tagged = splitmix64(trial_seed(seed, trial, stream) ^ 0x5851_F42D_4C95_7F2D);
    Xoshiro256PlusPlus::seed_from_u64(splitmix64(tagged ^ sensor as u64))
}

/// The generator of stream `stream` of trial `trial` (see [`DATA_STREAM`] and [`coin_stream`]).
pub fn trial_rng(seed: u64, trial: u64, stream: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(trial_seed(seed, trial, stream))
}

/// The seed of the fusion center's own generator (particle filters) for the variant whose coin
/// stream is `stream`: independent of the coins, and the same wherever a trial is replayed
/// (`trace`, calibration).
pub fn center_seed(seed: u64, trial: u64, stream: u64) -> u64 {
    splitmix64(trial_seed(seed, trial, stream) ^ 0xC3A5_C85C_97CB_3127)
}

/// The stream of the network link's draws (packet losses, delays, Gilbert–Elliott states; see
/// `crate::network::channel`). The link has a stream of its own, far from the data stream (0) and
/// the coin streams (1 + v), so adding or changing a channel changes no other draw: the truth, the
/// measurements and every variant's coins stay exactly what they were without a channel.
pub const LINK_STREAM: u64 = u64::MAX - 1;

/// The generator of one link slot: sensor `sensor`, step `step`, uplink (`downlink = false`) or
/// feedback link (`downlink = true`) of trial `trial`. Derived from the trial's seed on
/// [`LINK_STREAM`] by further splitmix steps, one per coordinate, so each slot's draws depend only
/// on (seed, trial, sensor, step, direction): every scheme that sends in a slot meets the same
/// fate, whichever schemes ran and in whatever order the slots are visited.
pub fn slot_rng(
    seed: u64,
    trial: u64,
    sensor: usize,
    step: usize,
    downlink: bool,
) -> Xoshiro256PlusPlus {
    sensor_slots(seed, trial, sensor, downlink)(step)
}

/// [`slot_rng`] of every step of one sensor and direction: the same generators, with the
/// coordinates shared by the steps derived once (a trial's fate table makes one per slot).
pub fn sensor_slots(
    seed: u64,
    trial: u64,
    sensor: usize,
    downlink: bool,
) -> impl Fn(usize) -> Xoshiro256PlusPlus {
    let sensor_seed = splitmix64(trial_seed(seed, trial, LINK_STREAM) ^ sensor as u64);
    move |step| {
        Xoshiro256PlusPlus::seed_from_u64(splitmix64(
            splitmix64(sensor_seed ^ step as u64) ^ downlink as u64,
        ))
    }
}

/// The key of the `m`-th message (m ≥ 1) a node sends on one directed link in one step, from
/// the key `key` of its first ([`sensor_slots`]' `sensor`): a splitmix step of both, so every
/// message has coins of its own and the first keeps the key's (the star's and the mesh's
/// draws stay what they were). `m = 0` gives `key`.
pub fn message_key(key: usize, m: u64) -> usize {
    if m == 0 {
        key
    } else {
        splitmix64(splitmix64(key as u64) ^ m) as usize
    }
}

pub(crate) fn trial_seed(seed: u64, trial: u64, stream: u64) -> u64 {
    splitmix64(splitmix64(splitmix64(seed) ^ trial) ^ stream)
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
