//! What a run will ask of the machine, estimated before it starts, and the limits above which
//! it is refused (`--allow-large` lifts them). The estimate is coarse on purpose: it exists to
//! turn `steps = 9223372036854775807` or `particles = 10^9` into a clear error instead of an
//! allocator abort or a run that never ends, not to predict run time to the second.
use super::build::ScenarioError;
use crate::scheme::{Scheme, System};

/// Limits of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Bytes the run may hold at once.
    pub max_memory_bytes: f64,
    /// Estimated floating-point operations of the whole run.
    pub max_flops: f64,
}

/// 16 GiB: two thirds of the 24 GiB machines this project runs on.
pub const DEFAULT_MAX_MEMORY: f64 = 16.0 * 1024.0 * 1024.0 * 1024.0;
/// 10^14 operations: more than a day of this code on one core (which reaches a few 10^8
/// useful operations per second on these workloads).
pub const DEFAULT_MAX_FLOPS: f64 = 1e14;

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_memory_bytes: DEFAULT_MAX_MEMORY,
            max_flops: DEFAULT_MAX_FLOPS,
        }
    }
}

impl Limits {
    /// No limits (`--allow-large`).
    pub fn none() -> Self {
        Self {
            max_memory_bytes: f64::INFINITY,
            max_flops: f64::INFINITY,
        }
    }
}

/// An estimate of a run's needs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    pub memory_bytes: f64,
    pub flops: f64,
}

/// Accumulator columns per step and variant (groups, errors, traffic, consistency).
fn columns(groups: usize) -> f64 {
    groups as f64 + 12.0
}

/// What the run needs apart from the schemes themselves: the per-trial truth and measurements
/// (one trial per worker), the per-step sums of every variant (one set per block in flight and
/// the total) and the per-trial steady-state values kept for paired comparisons.
pub fn baseline(
    system: &System,
    groups: usize,
    variants: usize,
    trials: usize,
    steps: usize,
    threads: usize,
) -> Estimate {
    let n = system.state_dim() as f64;
    let m: f64 = system.sensors.iter().map(|s| s.meas_dim() as f64).sum();
    let (steps, trials, variants) = (steps as f64, trials as f64, variants as f64);
    let workers = threads.max(1) as f64;
    let trial_data = steps * (n + m + 2.0 * system.n_sensors() as f64) * 8.0 * workers;
    let sums = steps * columns(groups) * variants * 8.0 * (2.0 * workers + 1.0);
    let per_trial = trials * variants * columns(groups) * 8.0;
    // A Kalman step: prediction n^3 plus an update per measured component.
    let kf_flops = 2.0 * n * n * n + 4.0 * n * n * m.max(1.0);
    Estimate {
        memory_bytes: trial_data + sums + per_trial,
        flops: trials * steps * variants * kf_flops,
    }
}

/// Adds what each scheme declares beyond the baseline.
pub fn with_schemes<'a>(
    mut e: Estimate,
    schemes: impl IntoIterator<Item = &'a dyn Scheme>,
    trials: usize,
    steps: usize,
    threads: usize,
) -> Estimate {
    for s in schemes {
        if let Some(f) = s.footprint() {
            e.memory_bytes += f.bytes * threads.max(1) as f64;
            e.flops += f.flops_per_step * steps as f64 * trials as f64;
        }
    }
    e
}

fn gib(b: f64) -> String {
    format!("{:.1} GiB", b / (1024.0 * 1024.0 * 1024.0))
}

/// Refuses an estimate above the limits, with a message that says what to change.
pub fn check(e: &Estimate, limits: &Limits, file: &str) -> Result<(), ScenarioError> {
    let err = |message: String| ScenarioError {
        file: file.to_string(),
        field: String::new(),
        message,
    };
    // NaN (an estimate that overflowed) is refused too.
    if e.memory_bytes.is_nan() || e.memory_bytes > limits.max_memory_bytes {
        return Err(err(format!(
            "this run would hold about {} in memory, more than the limit of {}; lower `steps`, `trials` (or --trials), the number of variants or particles, or pass --allow-large",
            gib(e.memory_bytes),
            gib(limits.max_memory_bytes)
        )));
    }
    if e.flops.is_nan() || e.flops > limits.max_flops {
        return Err(err(format!(
            "this run would take about {:.1e} floating-point operations (days of computing), more than the limit of {:.0e}; lower `steps`, `trials` (or --trials), the number of variants or particles, or pass --allow-large",
            e.flops, limits.max_flops
        )));
    }
    Ok(())
}
