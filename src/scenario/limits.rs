//! What a run will ask of the machine, estimated before it starts, and the limits above which
//! it is refused (`--allow-large` lifts them). The estimate is coarse on purpose: it exists to
//! turn `steps = 9223372036854775807` or `particles = 10^9` into a clear error instead of an
//! allocator abort or a run that never ends, not to predict run time to the second.
use crate::scenario::error::{Limit, ScenarioError};
use crate::scheme::{Scheme, System};

/// Limits of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Bytes the run may hold at once.
    pub max_memory_bytes: f64,
    /// Estimated wall-clock seconds of the whole run.
    pub max_seconds: f64,
}

/// 16 GiB: two thirds of the 24 GiB machines this project runs on.
pub const DEFAULT_MAX_MEMORY: f64 = 16.0 * 1024.0 * 1024.0 * 1024.0;
/// Environment variable that lowers the default memory ceiling to its value in bytes (never
/// raises it; for tests and shared machines).
pub const MAX_MEMORY_ENV: &str = "HUSHFUSE_MAX_MEMORY_BYTES";
// The runner's window of blocks in flight, here because the memory estimate needs them.
/// Blocks in flight at once, per worker thread, at the start of a run. Only memory, load
/// balance and speed depend on the window, never the result: blocks are merged in block order
/// whatever the window. Two keeps the in-flight sums of a 93-variant sweep (dormann-fig1) at a
/// few MB: 8 cost 17 MB more peak memory for no measurable speed.
pub const WINDOW_PER_THREAD: usize = 2;

/// Bytes of in-flight block sums the window may grow to (it never shrinks below
/// [`WINDOW_PER_THREAD`] blocks per thread), so memory stays flat in the number of trials.
/// 1 MB keeps them in a core's cache: at 4 MB the peers' KF Monte Carlo (9 KB of sums per
/// block) grew windows of some 450 blocks, each block's sums allocated and page-faulted anew.
pub const WINDOW_MAX_BYTES: usize = 1 << 20;
/// 24 hours.
pub const DEFAULT_MAX_SECONDS: f64 = 24.0 * 3600.0;
/// Cost of one scheme step beyond its arithmetic (dispatch, small allocations, metrics),
/// measured on the built-in linear scenarios: about a microsecond.
const STEP_OVERHEAD_SECONDS: f64 = 1e-6;
/// Useful floating-point operations per second and thread on these workloads.
const FLOPS_PER_SECOND: f64 = 5e8;

impl Default for Limits {
    /// 16 GiB, or less where the machine has less to give: half the process's address-space
    /// limit (`ulimit -v`; threads reserve address space beyond what they touch), 90% of a
    /// cgroup's memory limit, 90% of the memory available now. A run refused here fails with a
    /// message; one allowed past what the machine has would abort in the allocator.
    /// [`MAX_MEMORY_ENV`], when set to a number of bytes, lowers the ceiling further.
    fn default() -> Self {
        let lowered = std::env::var(MAX_MEMORY_ENV)
            .ok()
            .and_then(|v| v.trim().parse::<f64>().ok())
            .filter(|v| *v >= 0.0)
            .unwrap_or(f64::INFINITY);
        Self {
            max_memory_bytes: machine_memory_bytes()
                .map_or(DEFAULT_MAX_MEMORY, |m| m.min(DEFAULT_MAX_MEMORY))
                .min(lowered),
            max_seconds: DEFAULT_MAX_SECONDS,
        }
    }
}

/// What the machine can give this process (see [`Limits::default`]); None where it cannot be
/// read (no /proc).
pub fn machine_memory_bytes() -> Option<f64> {
    let mut best: Option<f64> = None;
    let mut take = |v: f64| best = Some(best.map_or(v, |b: f64| b.min(v)));
    if let Ok(text) = std::fs::read_to_string("/proc/meminfo") {
        if let Some(kb) = text
            .lines()
            .find_map(|l| l.strip_prefix("MemAvailable:"))
            .and_then(|r| r.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        {
            take(0.9 * kb * 1024.0);
        }
    }
    if let Ok(text) = std::fs::read_to_string("/sys/fs/cgroup/memory.max") {
        if let Ok(bytes) = text.trim().parse::<f64>() {
            take(0.9 * bytes);
        }
    }
    if let Ok(text) = std::fs::read_to_string("/proc/self/limits") {
        // "Max address space   <soft>   <hard>   bytes"
        if let Some(soft) = text
            .lines()
            .find_map(|l| l.strip_prefix("Max address space"))
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse::<f64>().ok())
        {
            take(0.5 * soft);
        }
    }
    best
}

/// Bytes per step, variant and n^2 that the linear schemes' shared per-step plans keep (the
/// covariance recursion computed once for all trials: predicted and updated covariances,
/// gains, debiasing matrices and their factors, each an n x n matrix on the heap).
const PLAN_BYTES_PER_STEP_N2: f64 = 16.0 * 8.0;
/// Heap overhead of one such matrix, per step and variant (allocation header and rounding).
const PLAN_BYTES_PER_STEP: f64 = 16.0 * 48.0;

impl Limits {
    /// No limits (`--allow-large`).
    pub fn none() -> Self {
        Self {
            max_memory_bytes: f64::INFINITY,
            max_seconds: f64::INFINITY,
        }
    }
}

/// An estimate of a run's needs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    pub memory_bytes: f64,
    /// Wall-clock seconds with all threads busy.
    pub seconds: f64,
    /// Worker threads the estimate assumes.
    pub threads: f64,
    /// The part of `seconds` that late packets and revealed gaps spend re-fusing
    /// ([`with_refusion`]).
    pub refusion_seconds: f64,
}

/// Accumulator columns per step and variant (groups, errors, traffic, consistency).
fn columns(groups: usize) -> f64 {
    groups as f64 + 12.0
}

/// What the run needs apart from the schemes themselves: the per-trial truth and measurements
/// (one trial per worker, each a heap vector), the per-step sums of every variant (the runner
/// keeps one set per block of a window of blocks, merged in block order as the window
/// finishes, plus the total: two blocks per thread, or up to [`WINDOW_MAX_BYTES`] when
/// the blocks are small) and the per-trial steady-state values kept for paired
/// comparisons.
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
    let vectors = 1.0 + system.n_sensors() as f64;
    let (steps, trials, variants) = (steps as f64, trials as f64, variants as f64);
    let workers = threads.max(1) as f64;
    let blocks = (trials / 4.0)
        .ceil()
        .min(WINDOW_PER_THREAD as f64 * workers);
    let trial_data = steps * (8.0 * (n + m) + 64.0 * vectors) * workers;
    let block = steps * columns(groups) * variants * 16.0;
    let sums = block + (block * blocks).max(WINDOW_MAX_BYTES as f64);
    let per_trial = trials * variants * (columns(groups) * 8.0 + 24.0);
    let per_step = step_seconds(system);
    Estimate {
        memory_bytes: trial_data + sums + per_trial,
        seconds: trials * steps * (variants * per_step + m * 1e-7) / workers,
        threads: workers,
        refusion_seconds: 0.0,
    }
}

/// Bytes of `count` per-step plans over `steps` steps ([`Scheme::keeps_step_plan`]): an upper
/// bound (a plan whose recursion settles stops storing steps).
pub fn plans(system: &System, count: usize, steps: usize) -> f64 {
    let n = system.state_dim() as f64;
    count as f64 * steps as f64 * (PLAN_BYTES_PER_STEP_N2 * n * n + PLAN_BYTES_PER_STEP)
}

/// Adds the plans of `count` schemes ([`plans`]).
pub fn with_plans(mut e: Estimate, system: &System, count: usize, steps: usize) -> Estimate {
    e.memory_bytes += plans(system, count, steps);
    e
}

/// Adds what each scheme declares beyond the baseline: its instances' footprint on every
/// worker (its shared plan is [`with_plans`]).
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
            e.seconds += f.flops_per_step / FLOPS_PER_SECOND * steps as f64 * trials as f64
                / threads.max(1) as f64;
        }
    }
    e
}

/// Adds the re-fusion work of links with delays or sequence numbers: a late packet, or a gap
/// that a sequence number reveals, makes the center re-fuse the trial so far
/// ([`crate::engine::link_layer`]), so a trial of T steps in which such an arrival comes at a
/// step with probability p re-fuses about p T²/2 steps. (A delay of 1 at every step over 10⁶
/// steps is 5·10¹¹ re-fused steps a trial: the work grows as steps², and a run that cannot end
/// in the time limit is refused here rather than started.) p is taken from above: every sensor
/// sending at every step, a gap at every loss.
pub fn with_refusion(
    mut e: Estimate,
    system: &System,
    variants: &[crate::scenario::experiment::Variant],
    trials: usize,
    steps: usize,
    threads: usize,
) -> Estimate {
    let step = step_seconds(system);
    for v in variants {
        let Some(specs) = v.channel.as_deref() else {
            continue;
        };
        let quiet: f64 = specs
            .iter()
            .map(|s| 1.0 - refusion_chance(s, v.sequence_bits))
            .product();
        let p = 1.0 - quiet;
        if p <= 0.0 {
            continue;
        }
        let flops = v.scheme.footprint().map_or(0.0, |f| f.flops_per_step);
        let refused = p * steps as f64 * (steps as f64 + 1.0) / 2.0;
        let seconds =
            refused * trials as f64 * (step + flops / FLOPS_PER_SECOND) / threads.max(1) as f64;
        e.seconds += seconds;
        e.refusion_seconds += seconds;
    }
    e
}

/// The chance, from above, that one sensor's packet of a step makes the center re-fuse: it is
/// late (any delay), or (with sequence numbers) it is lost, which the next arrival reveals.
fn refusion_chance(s: &crate::network::channel::ChannelSpec, sequence_bits: u32) -> f64 {
    use crate::network::channel::Delay;
    let late = match s.delay() {
        Delay::Fixed(0) => 0.0,
        Delay::Fixed(_) => 1.0,
        Delay::Geometric(g) => g.mean / (1.0 + g.mean),
    };
    let lost = match sequence_bits {
        0 => 0.0,
        _ => (s.kind.model().worst_loss)(s),
    };
    (late + lost).clamp(0.0, 1.0)
}

/// Seconds of one Kalman-sized step of `system` (prediction n³ plus an update per measured
/// component), the baseline's cost of a scheme step.
fn step_seconds(system: &System) -> f64 {
    let n = system.state_dim() as f64;
    let m: f64 = system.sensors.iter().map(|s| s.meas_dim() as f64).sum();
    let kf_flops = 2.0 * n * n * n + 4.0 * n * n * m.max(1.0);
    STEP_OVERHEAD_SECONDS + kf_flops / FLOPS_PER_SECOND
}

/// Bytes a run writes into its output folder, from above: the per-step table, the summary and
/// the plots carry every accumulator column of every variant at every step (about 70 bytes a
/// cell in the built-ins; 200 leaves room for longer names and numbers), the checkpoint
/// carries the per-trial values, and 64 KiB cover the rest (scenario copy, manifest).
pub fn output_bytes(groups: usize, variants: usize, steps: usize, trials: usize) -> f64 {
    let cells = columns(groups) * variants as f64;
    cells * (steps as f64 * 200.0 + trials as f64 * 32.0) + 64.0 * 1024.0
}

/// Bytes as GiB with one decimal.
pub fn gib(b: f64) -> String {
    format!("{:.1} GiB", b / (1024.0 * 1024.0 * 1024.0))
}

/// Refuses an estimate above the limits, with a message that says what to change.
pub fn check(e: &Estimate, limits: &Limits, file: &str) -> Result<(), ScenarioError> {
    let err = |limit: Limit, message: String| ScenarioError {
        file: file.to_string(),
        field: String::new(),
        message,
        limit: Some(limit),
    };
    // NaN (an estimate that overflowed) is refused too.
    if e.memory_bytes.is_nan() || e.memory_bytes > limits.max_memory_bytes {
        return Err(err(
            Limit::Memory,
            format!(
            "this run would hold about {} in memory, more than the limit of {}; lower `steps`, `trials` (or --trials), the number of variants or particles, or pass --allow-large",
            gib(e.memory_bytes),
            gib(limits.max_memory_bytes)
        ),
        ));
    }
    if e.seconds.is_nan() || e.seconds > limits.max_seconds {
        let why = if e.refusion_seconds > 0.5 * e.seconds {
            " (most of it re-fusing: each late packet, or gap a sequence number reveals, makes the center re-fuse the trial so far, so the work grows as steps squared; shorten `steps` or the link's `delay`)"
        } else {
            ""
        };
        return Err(err(
            Limit::Time,
            format!(
            "this run would take about {:.0} hours on {} threads{why}, more than the limit of {:.0} hours; lower `steps`, `trials` (or --trials), the number of variants or particles, or pass --allow-large",
            e.seconds / 3600.0,
            e.threads,
            limits.max_seconds / 3600.0
        ),
        ));
    }
    Ok(())
}
