//! The engine's lockstep fast path: a scheme whose whole trial (or a block of trials) can run
//! without the generic per-step loop of [`crate::engine::trial`], with the same numbers. A
//! scheme author never needs it; a [`Scheme`] offers it through [`Scheme::fast_path`].
use crate::filter::Gaussian;
use crate::linalg::quad::F64x4;
use crate::linalg::{LinalgError, Matrix, Vector};
use crate::network::channel::FateTable;
#[cfg(doc)]
use crate::scheme::Scheme;
use crate::scheme::SchemeError;
use rand_xoshiro::Xoshiro256PlusPlus;

/// An engine hook: a scheme whose whole trial can run without the generic per-step loop,
/// reporting each step to a sink with the numbers that loop gives. Offered by
/// [`Scheme::fast_path`]; the engine makes one virtual call per trial (per batch) through it.
pub trait LockstepFastPath: Send + Sync {
    /// Runs one whole trial on `measurements` (`measurements[k - 1][i]` = z_k^i, k = 1..=steps)
    /// without the generic per-step loop, reporting each step's fused estimate and traffic to
    /// `sink` as trial 0 of a batch of one (one sink trait for a trial and a batch), with the same coin draws (sensor i's from `coins[i]`) and the same numbers as
    /// that loop gives: what reaches the center rounded as [`crate::link::as_sent`] rounds it.
    /// `cache` lives for one trial and is shared by its variants (work that depends on the
    /// data but not on the variant is done once). `None`: no fast path for this scheme or this
    /// data (nothing has been drawn from `coins`; the generic loop runs).
    ///
    /// `losses`: the packets a lossy link loses in this trial ([`Losses`]), which the fast
    /// path must apply as the generic loop does; `None` on an ideal link. A fast path that
    /// cannot apply them returns `None`.
    fn run_trial_fast(
        &self,
        measurements: &[Vec<Vector>],
        steps: usize,
        losses: Option<&Losses>,
        coins: &mut [Xoshiro256PlusPlus],
        cache: &mut TrialCache,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        let _ = (measurements, steps, losses, coins, cache, sink);
        None
    }
    /// Whether [`LockstepFastPath::run_batch_fast`] may take several trials at once (the
    /// runner then draws a block's trials before running them).
    fn batches(&self) -> bool {
        false
    }
    /// Runs several trials in lockstep (`trials[j][k - 1][i]` = z_k^i of trial j), reporting
    /// every trial's step k to `sink` in trial order before any trial's step k + 1: the
    /// numbers of [`LockstepFastPath::run_trial_fast`] on each trial, while the dependent
    /// chains of different trials (divisions, square roots) overlap in the processor. Only for
    /// schemes whose trial draws no coins. `None`: not for this data (nothing was reported; the
    /// runner runs the trials one at a time). After an error the runner reruns the trials
    /// one at a time, so that the run fails with the error the one-at-a-time loop reports.
    fn run_batch_fast(
        &self,
        trials: &[&[Vec<Vector>]],
        steps: usize,
        cache: &mut TrialCache,
        sink: &mut dyn BatchSink,
    ) -> Option<Result<(), FastTrialError>> {
        let _ = (trials, steps, cache, sink);
        None
    }
    /// Whether [`LockstepFastPath::run_quad_fast`] may take a block drawn side by side.
    fn quads(&self) -> bool {
        false
    }
    /// Runs the four trials of a runner block side by side (`block`, lane j: trial j),
    /// reporting each step of the four at once to it: lane j is what
    /// [`LockstepFastPath::run_batch_fast`] gives trial j. The same conditions as a batch (no
    /// coins drawn). `None` (nothing reported): not for this block; after an error the runner
    /// runs the trials one at a time, so that the run fails with the error the one-at-a-time
    /// loop reports.
    fn run_quad_fast(
        &self,
        block: &mut dyn QuadBlock,
        steps: usize,
    ) -> Option<Result<(), FastTrialError>> {
        let _ = (block, steps);
        None
    }
}

/// The runner's side of a block of four trials run side by side
/// ([`LockstepFastPath::run_quad_fast`]; lane j of every [`F64x4`]: trial j): it hands out each
/// step's readings (their arithmetic done when first asked for, on normals drawn for the whole
/// block at its start) and records each step's estimates.
pub trait QuadBlock {
    /// The state's components and the sensors, each sensor linear and scalar.
    fn shape(&self) -> (usize, usize);

    /// z_k^i of the four trials at step `k` (1-based), sensors in order: each the number the
    /// runner's drawer gives that trial alone.
    fn readings(&mut self, k: usize) -> &[F64x4];

    /// Step `k` of the four trials: their means (component c: `means[c]`), the covariance they
    /// share with its Cholesky factor as [`crate::linalg::fixed::nees_factor`] makes it (when
    /// the scheme has it), and the step's traffic (each trial's). An error when the step
    /// cannot be recorded side by side: the runner then runs the block's trials one at a time.
    fn step_quad(
        &mut self,
        k: usize,
        means: &[F64x4],
        cov: &Matrix,
        factor: Option<&[f64]>,
        traffic: crate::network::Traffic,
    ) -> Result<(), LinalgError>;
}

/// The packets a lossy link loses in one trial, as a fast path applies them: a packet that
/// sensor i sends at step k never reaches the center when [`Losses::lost`]`(i, k)`; the center
/// sees a silence, and the packet keeps its bits and frame and is counted in
/// [`crate::network::Traffic::lost`]. The engine hands a fast path the losses only when that is
/// all the link does (no delay, no retransmission, no sequence numbers: those are the generic
/// loop's, [`crate::engine::link_layer`]), and the schemes with a fast path send no feedback,
/// so a lost downlink changes nothing for them.
#[derive(Debug, Clone, Copy)]
pub struct Losses<'a> {
    uplink: &'a FateTable,
}

impl<'a> Losses<'a> {
    /// The losses of an uplink fate table (only its `lost` flags are read).
    pub fn new(uplink: &'a FateTable) -> Self {
        Self { uplink }
    }

    /// Whether a packet sent by `sensor` at step `k` (1-based) is lost.
    #[inline]
    pub fn lost(&self, sensor: usize, k: usize) -> bool {
        self.uplink.get(sensor, k).lost
    }

    /// Whether any slot of steps `1..=steps` loses its packet (a trial without one runs as on
    /// an ideal link).
    pub fn any(&self, steps: usize) -> bool {
        (0..self.uplink.sensors()).any(|i| (1..=steps).any(|k| self.lost(i, k)))
    }
}

/// Receives the steps of a fast path: a [`LockstepFastPath::run_batch_fast`] batch, or a
/// [`LockstepFastPath::run_trial_fast`] trial as trial 0 of a batch of one.
pub trait BatchSink {
    /// The fused estimate of batch trial `j` after step `k` (1-based) and the traffic of the
    /// step, with the Cholesky factor of its covariance when the scheme has it at hand (a
    /// covariance shared by every trial): the dirty column-major lower factor that
    /// `fixed::nees_factor` computes from exactly these covariance bits, so a sink that needs
    /// NEES need not factor the covariance again.
    fn step(
        &mut self,
        j: usize,
        k: usize,
        estimate: &Gaussian,
        factor: Option<&[f64]>,
        traffic: crate::network::Traffic,
    ) -> Result<(), LinalgError>;

    /// Step `k` of every trial of the batch at once, when their estimates share one
    /// covariance: `shared.cov` (with its factor when the scheme has it) and trial j's mean
    /// `means[j * n..(j + 1) * n]` (`shared.mean` is work space). The default hands the
    /// trials to [`BatchSink::step`] one by one, in order.
    fn step_shared(
        &mut self,
        k: usize,
        means: &[f64],
        shared: &mut Gaussian,
        factor: Option<&[f64]>,
        traffic: crate::network::Traffic,
    ) -> Result<(), LinalgError> {
        let n = shared.mean.len();
        for (j, mean) in means.chunks_exact(n).enumerate() {
            shared.mean.as_mut_slice().copy_from_slice(mean);
            self.step(j, k, shared, factor, traffic)?;
        }
        Ok(())
    }
}

/// Why a fast trial stopped: the scheme failed at step `k`, or the sink refused step `k`.
#[derive(Debug, Clone, PartialEq)]
pub enum FastTrialError {
    Scheme { k: usize, source: SchemeError },
    Sink { k: usize, source: LinalgError },
}

/// Per-trial memory shared by the variants of one trial, by key (see
/// [`LockstepFastPath::run_trial_fast`]). A few entries at most: a linear search.
///
/// It also keeps work space that outlives the trial ([`TrialCache::scratch`]): buffers a fast
/// trial would otherwise allocate every trial.
#[derive(Default)]
pub struct TrialCache {
    entries: Vec<(CacheKey, Box<dyn std::any::Any + Send>)>,
    scratch: Vec<(CacheKey, Box<dyn std::any::Any + Send>)>,
}

/// Key of a [`TrialCache`] entry: which shared object (an address) and which data.
pub type CacheKey = (usize, usize);

impl TrialCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// The entry of `key`, made by `make` if absent (or of another type).
    pub fn get_or_insert_with<T: std::any::Any + Send>(
        &mut self,
        key: CacheKey,
        make: impl FnOnce() -> T,
    ) -> &mut T {
        let pos = self
            .entries
            .iter()
            .position(|(k, v)| *k == key && v.is::<T>());
        let pos = pos.unwrap_or_else(|| {
            self.entries.push((key, Box::new(make())));
            self.entries.len() - 1
        });
        self.entries[pos]
            .1
            .downcast_mut::<T>()
            .expect("checked type")
    }

    /// Forgets every entry (a new trial); the scratch space stays.
    pub fn clear(&mut self) {
        self.entries.clear();
    }

    /// Work space of `key`, made by `make` if absent, kept from trial to trial (and from
    /// variant to variant: it must hold buffers only, whose contents a trial overwrites before
    /// it reads them, never results).
    pub fn scratch<T: std::any::Any + Send>(
        &mut self,
        key: CacheKey,
        make: impl FnOnce() -> T,
    ) -> &mut T {
        let pos = self
            .scratch
            .iter()
            .position(|(k, v)| *k == key && v.is::<T>());
        let pos = pos.unwrap_or_else(|| {
            self.scratch.push((key, Box::new(make())));
            self.scratch.len() - 1
        });
        self.scratch[pos]
            .1
            .downcast_mut::<T>()
            .expect("checked type")
    }
}
