//! The particle cloud itself: [`ParticleCloud`] (states, log-weights and every scratch buffer
//! a step needs) with its steps (initialization, propagation, normalization, estimates,
//! resampling), the prepared linear-Gaussian [`ParticleTransition`], the read-only
//! [`StateView`] and the square-root factor used to draw noise. Kept apart from the slice loops
//! (`lanes`) and the resampling algorithms (`resample`) it calls, so this file reads as the
//! filter's steps and nothing else.
use super::lanes::{
    axpy, combine_rows, dot_lanes, exp_shifted_into, gather, max_lanes, normalize_in_place,
    weighted_covariance, weighted_mean, LaneSums,
};
use super::resample::{cumulative_in_place, merge, residual, sorted_uniforms, systematic};
use super::{ParticleError, ResamplePolicy, Resampling};
use crate::filter::Gaussian;
use crate::linalg::{LinalgError, Matrix, Vector};
use crate::model::transition::psd_sqrt;
use crate::model::LinearTransition;
use crate::stats::normal_block::fill_standard_normal;
use rand::Rng;

/// A square-root factor `L` (with `L L^T = A`) kept as the non-negligible columns and their
/// nonzero entries, so sampling `L z` costs one block of normal draws per kept column and one
/// `axpy` per nonzero entry.
#[derive(Debug, Clone)]
struct SqrtColumns {
    /// For each kept column: (row, coefficient) of its nonzero entries.
    columns: Vec<Vec<(usize, f64)>>,
}

impl SqrtColumns {
    /// Keeps the columns carrying more than 1e-12 of the total variance `trace(L L^T)`. A
    /// singular covariance (Zheng et al.'s (2014) white-noise-acceleration `Q = sigma^2 G G^T` has rank
    /// one per axis) factors with columns that are zero up to rounding; drawing normals for
    /// them would double the cost of propagation and change the covariance by less than the
    /// rounding of the filter's own sums.
    fn new(l: &Matrix) -> Self {
        let total: f64 = l.iter().map(|v| v * v).sum();
        let columns = (0..l.ncols())
            .filter_map(|c| {
                let col = l.column(c);
                let energy: f64 = col.iter().map(|v| v * v).sum();
                if total > 0.0 && energy > 1e-12 * total {
                    Some(
                        col.iter()
                            .enumerate()
                            .filter(|(_, v)| **v != 0.0)
                            .map(|(r, v)| (r, *v))
                            .collect(),
                    )
                } else {
                    None
                }
            })
            .collect();
        Self { columns }
    }

    /// Adds `L z` to the component-major `states` (`n` particles), drawing `z` one block of
    /// `n` standard normals per kept column into `noise`.
    fn add_noise<R: Rng + ?Sized>(
        &self,
        states: &mut [f64],
        n: usize,
        noise: &mut [f64],
        rng: &mut R,
    ) {
        let noise = &mut noise[..n];
        for col in &self.columns {
            fill_standard_normal(noise, rng);
            for &(row, coef) in col {
                axpy(coef, noise, &mut states[row * n..(row + 1) * n]);
            }
        }
    }
}

/// Linear-Gaussian transition `x' = F x + w`, `w ~ N(0, Q)`, prepared for propagating a cloud:
/// the nonzero entries of `F` per row and a square root of `Q` (`Q` may be singular). Built
/// once per model, so the per-step propagation does no factorization and no allocation.
#[derive(Debug, Clone)]
pub struct ParticleTransition {
    dim: usize,
    /// For each row `i` of `F`: (column, coefficient) of its nonzero entries.
    rows: Vec<Vec<(usize, f64)>>,
    noise: SqrtColumns,
    /// For each row `i`: (kept column of the square root, coefficient) of its nonzero noise
    /// entries, in column order — the noise terms [`ParticleCloud::propagate`] adds to row `i`.
    noise_rows: Vec<Vec<(usize, f64)>>,
}

impl ParticleTransition {
    /// Prepares `model` for propagation (a positive semi-definite square root of `Q`).
    pub fn new(model: &LinearTransition) -> Result<Self, ParticleError> {
        let f = model.f();
        let dim = model.dim();
        let rows = (0..dim)
            .map(|i| {
                (0..dim)
                    .filter(|&j| f[(i, j)] != 0.0)
                    .map(|j| (j, f[(i, j)]))
                    .collect()
            })
            .collect();
        let q_sqrt = psd_sqrt(model.q()).map_err(|source| ParticleError::Matrix {
            what: "process noise Q",
            source,
        })?;
        let noise = SqrtColumns::new(&q_sqrt);
        let mut noise_rows = vec![Vec::new(); dim];
        for (c, column) in noise.columns.iter().enumerate() {
            for &(row, coef) in column {
                noise_rows[row].push((c, coef));
            }
        }
        Ok(Self {
            dim,
            rows,
            noise,
            noise_rows,
        })
    }

    /// State dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of standard normal draws per particle and step (the numerical rank of `Q`).
    pub fn noise_rank(&self) -> usize {
        self.noise.columns.len()
    }
}

/// Read-only view of the particle states, component-major. Returned together with the mutable
/// log-weights by [`ParticleCloud::states_and_log_weights_mut`] so that likelihood code can
/// read states and write weights at the same time.
#[derive(Debug, Clone, Copy)]
pub struct StateView<'a> {
    data: &'a [f64],
    n: usize,
}

impl<'a> StateView<'a> {
    /// Component `j` of every particle, contiguous.
    #[inline]
    pub fn component(&self, j: usize) -> &'a [f64] {
        &self.data[j * self.n..(j + 1) * self.n]
    }
    /// Number of particles.
    #[inline]
    pub fn len(&self) -> usize {
        self.n
    }
    /// Always false: a cloud has at least one particle.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    /// State dimension.
    #[inline]
    pub fn dim(&self) -> usize {
        self.data.len() / self.n
    }
}

/// `n` weighted particles in `dim` dimensions, stored component-major, with every scratch
/// buffer a filter step needs (see the module documentation for why).
///
/// Weights live in the log domain (`log_weights`), where likelihoods of many sensors add
/// without underflow. [`normalize`](Self::normalize) turns them into normalized weights;
/// estimates and resampling normalize first if the log-weights changed since.
#[derive(Debug, Clone)]
pub struct ParticleCloud {
    dim: usize,
    n: usize,
    /// `dim * n` values; component `j` of particle `i` at `j * n + i`.
    states: Vec<f64>,
    /// Same shape as `states`: target of propagation and of the resampling gather, swapped in
    /// afterwards.
    spare: Vec<f64>,
    log_weights: Vec<f64>,
    /// Normalized weights when `normalized`; resampling reuses it for cumulative sums.
    weights: Vec<f64>,
    /// `n` standard normals (initialization); sorted uniforms for multinomial resampling.
    noise: Vec<f64>,
    /// `n` standard normals per kept noise column of the transition (grown on the first
    /// propagation).
    draws: Vec<f64>,
    /// Lane accumulators of the covariance (`lanes::weighted_covariance`).
    cov_sums: Vec<LaneSums>,
    /// Ancestor indices of the last resampling; one extra slot for the branch-free scatter.
    ancestors: Vec<usize>,
    /// Copies per particle (residual resampling).
    counts: Vec<usize>,
    /// Whether `weights` holds the normalized `exp(log_weights)`.
    normalized: bool,
    /// `sum w_i^2` of the normalized weights, as [`normalize`](Self::normalize) found it
    /// (`None` until then, and after anything else sets the weights).
    sum_sq: Option<f64>,
}

impl ParticleCloud {
    /// A cloud of `n` particles at the origin of a `dim`-dimensional space, equally weighted.
    /// All buffers are allocated here (the noise draws and the covariance's sums at their first
    /// use) and never again.
    pub fn new(dim: usize, n: usize) -> Result<Self, ParticleError> {
        if dim == 0 || n == 0 {
            return Err(ParticleError::Empty);
        }
        let inv_n = 1.0 / n as f64;
        Ok(Self {
            dim,
            n,
            states: vec![0.0; dim * n],
            spare: vec![0.0; dim * n],
            log_weights: vec![-(n as f64).ln(); n],
            weights: vec![inv_n; n],
            noise: vec![0.0; n],
            draws: Vec::new(),
            cov_sums: Vec::new(),
            ancestors: (0..=n).collect(),
            counts: vec![0; n],
            normalized: true,
            sum_sq: None,
        })
    }

    /// `n` equally weighted particles drawn from `prior` (Zheng et al. (2014) initializes the fusion
    /// center's filter from the prior of x_0).
    pub fn from_gaussian<R: Rng + ?Sized>(
        n: usize,
        prior: &Gaussian,
        rng: &mut R,
    ) -> Result<Self, ParticleError> {
        let mut cloud = Self::new(prior.dim(), n)?;
        cloud.init_gaussian(prior, rng)?;
        Ok(cloud)
    }

    /// Redraws every particle from `prior` and resets the weights to equal, reusing the
    /// buffers (one cloud can serve every Monte Carlo trial). The covariance may be singular
    /// (a known component): a positive semi-definite square root is used. Draws are made one
    /// block of `n` normals per column of the square root.
    pub fn init_gaussian<R: Rng + ?Sized>(
        &mut self,
        prior: &Gaussian,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        self.check_dim("prior mean", prior.mean.len())?;
        self.check_dim("prior covariance rows", prior.cov.nrows())?;
        self.check_dim("prior covariance columns", prior.cov.ncols())?;
        let sqrt = psd_sqrt(&prior.cov).map_err(|source| ParticleError::Matrix {
            what: "prior covariance",
            source,
        })?;
        if prior.mean.iter().any(|v| !v.is_finite()) {
            return Err(ParticleError::Matrix {
                what: "prior mean",
                source: LinalgError::NonFinite,
            });
        }
        let n = self.n;
        for (j, &m) in prior.mean.iter().enumerate() {
            self.states[j * n..(j + 1) * n].fill(m);
        }
        SqrtColumns::new(&sqrt).add_noise(&mut self.states, n, &mut self.noise, rng);
        self.set_equal_weights();
        for (k, a) in self.ancestors.iter_mut().enumerate() {
            *a = k;
        }
        Ok(())
    }

    fn check_dim(&self, what: &'static str, got: usize) -> Result<(), ParticleError> {
        if got == self.dim {
            Ok(())
        } else {
            Err(ParticleError::Dimension {
                what,
                expected: self.dim,
                got,
            })
        }
    }

    /// Number of particles.
    #[inline]
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always false: a cloud has at least one particle.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// State dimension.
    #[inline]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Component `j` of every particle, contiguous.
    #[inline]
    pub fn component(&self, j: usize) -> &[f64] {
        &self.states[j * self.n..(j + 1) * self.n]
    }

    /// Mutable component `j` of every particle (weights are unaffected).
    #[inline]
    pub fn component_mut(&mut self, j: usize) -> &mut [f64] {
        &mut self.states[j * self.n..(j + 1) * self.n]
    }

    /// All states as a read-only component-major view.
    #[inline]
    pub fn states(&self) -> StateView<'_> {
        StateView {
            data: &self.states,
            n: self.n,
        }
    }

    /// Copies particle `i` into `out` (length `dim`), for per-particle code that wants the
    /// state as one vector.
    pub fn copy_particle(&self, i: usize, out: &mut [f64]) -> Result<(), ParticleError> {
        self.check_dim("particle output", out.len())?;
        if i >= self.n {
            return Err(ParticleError::Index {
                index: i,
                len: self.n,
            });
        }
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.states[j * self.n + i];
        }
        Ok(())
    }

    /// The log-weights (unnormalized until [`normalize`](Self::normalize)).
    #[inline]
    pub fn log_weights(&self) -> &[f64] {
        &self.log_weights
    }

    /// The log-weights, for adding per-particle log-likelihoods. Marks the normalized weights
    /// stale.
    #[inline]
    pub fn log_weights_mut(&mut self) -> &mut [f64] {
        self.normalized = false;
        &mut self.log_weights
    }

    /// The states (read-only) and the log-weights (mutable) at once: a likelihood reads the
    /// former and adds to the latter. Marks the normalized weights stale.
    #[inline]
    pub fn states_and_log_weights_mut(&mut self) -> (StateView<'_>, &mut [f64]) {
        self.normalized = false;
        (
            StateView {
                data: &self.states,
                n: self.n,
            },
            &mut self.log_weights,
        )
    }

    /// Ancestor indices chosen by the last resampling (particle `k` is a copy of the previous
    /// particle `ancestors()[k]`), sorted; the identity before any resampling. Schemes that
    /// keep per-particle data beside the states permute it with these.
    #[inline]
    pub fn ancestors(&self) -> &[usize] {
        &self.ancestors[..self.n]
    }

    /// Propagates every particle through `x' = F x + w` (Zheng et al. (2014), (A1.3)): one
    /// block of `n` normal draws per kept column of the square root `L` of `Q`, then each
    /// component as `sum_j F_ij x_j + sum_c L_ic z_c` over its nonzero entries, in one pass over
    /// the particles (`lanes::combine_rows`). Weights are unchanged (bootstrap proposal).
    pub fn propagate<R: Rng + ?Sized>(
        &mut self,
        transition: &ParticleTransition,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        self.check_dim("transition", transition.dim)?;
        let n = self.n;
        let columns = &transition.noise.columns;
        if self.draws.len() < columns.len() * n {
            self.draws.resize(columns.len() * n, 0.0);
        }
        for z in self.draws.chunks_exact_mut(n).take(columns.len()) {
            fill_standard_normal(z, rng);
        }
        combine_rows(
            &transition.rows,
            &self.states,
            &transition.noise_rows,
            &self.draws,
            n,
            &mut self.spare,
        );
        std::mem::swap(&mut self.states, &mut self.spare);
        Ok(())
    }

    /// Normalizes the weights: subtracts the largest log-weight before exponentiating (so
    /// nothing overflows and the largest weight is exactly representable), stores normalized
    /// weights, shifts the log-weights so that `sum exp(log_weights) = 1`, and returns the log
    /// of the normalizing constant, `ln sum_i exp(l_i)` of the log-weights as they were.
    ///
    /// Because resampling leaves the log-weights normalized too (`-ln n` each), after adding a
    /// step's log-likelihoods the returned value is the log of the particle estimate of
    /// `p(z_k | z_{1:k-1})`, whether or not the previous step resampled.
    ///
    /// Fails with [`ParticleError::DegenerateWeights`] if every log-weight is `-inf` or any is
    /// NaN or `+inf`; the log-weights are then left untouched.
    pub fn normalize(&mut self) -> Result<f64, ParticleError> {
        let m = max_lanes(&self.log_weights);
        if !m.is_finite() {
            return Err(ParticleError::DegenerateWeights);
        }
        let s = exp_shifted_into(&self.log_weights, m, &mut self.weights);
        // s >= 1 (the largest particle contributes exp(0) = 1) unless a NaN got in.
        if !s.is_finite() {
            return Err(ParticleError::DegenerateWeights);
        }
        let ln_s = s.ln();
        self.sum_sq = Some(normalize_in_place(
            &mut self.weights,
            &mut self.log_weights,
            1.0 / s,
            m,
            ln_s,
        ));
        self.normalized = true;
        Ok(m + ln_s)
    }

    /// Normalizes if the log-weights changed since the last normalization.
    fn ensure_normalized(&mut self) -> Result<(), ParticleError> {
        if !self.normalized {
            self.normalize()?;
        }
        Ok(())
    }

    /// Normalized weights (normalizing first if needed).
    pub fn weights(&mut self) -> Result<&[f64], ParticleError> {
        self.ensure_normalized()?;
        Ok(&self.weights)
    }

    /// Effective sample size `1 / sum w_i^2`: `n` for equal weights, 1 when one particle
    /// carries all the weight.
    pub fn ess(&mut self) -> Result<f64, ParticleError> {
        self.ensure_normalized()?;
        let sum_sq = match self.sum_sq {
            Some(s) => s,
            None => *self.sum_sq.insert(dot_lanes(&self.weights, &self.weights)),
        };
        Ok(1.0 / sum_sq)
    }

    /// Weighted mean, written into `out` (length `dim`) without allocating.
    pub fn mean_into(&mut self, out: &mut [f64]) -> Result<(), ParticleError> {
        self.check_dim("mean output", out.len())?;
        self.ensure_normalized()?;
        weighted_mean(&self.weights, &self.states, out);
        Ok(())
    }

    /// Weighted mean.
    pub fn mean(&mut self) -> Result<Vector, ParticleError> {
        let mut m = Vector::zeros(self.dim);
        self.mean_into(m.as_mut_slice())?;
        Ok(m)
    }

    /// Weighted covariance `sum w_i (x_i - m)(x_i - m)^T` about the weighted mean, computed
    /// from centered products (not `E[x x^T] - m m^T`, which cancels catastrophically when the
    /// spread is small against the mean). With normalized weights it has no `n / (n - 1)`
    /// correction: after resampling it is the population covariance of the cloud.
    pub fn covariance(&mut self) -> Result<Matrix, ParticleError> {
        Ok(self.estimate()?.cov)
    }

    /// Weighted mean and covariance at once (what a fusion center reports each step).
    pub fn estimate(&mut self) -> Result<Gaussian, ParticleError> {
        let mut g = Gaussian::new(Vector::zeros(self.dim), Matrix::zeros(self.dim, self.dim));
        self.estimate_into(&mut g)?;
        Ok(g)
    }

    /// Weighted mean and covariance into an existing `Gaussian` of the right dimension,
    /// without allocating.
    pub fn estimate_into(&mut self, out: &mut Gaussian) -> Result<(), ParticleError> {
        self.check_dim("estimate covariance rows", out.cov.nrows())?;
        self.check_dim("estimate covariance columns", out.cov.ncols())?;
        self.mean_into(out.mean.as_mut_slice())?;
        weighted_covariance(
            &self.weights,
            &self.states,
            out.mean.as_slice(),
            &mut self.cov_sums,
            out.cov.as_mut_slice(),
        );
        Ok(())
    }

    /// Resamples if `policy` asks for it (Zheng et al. (2014), (A1.6)); returns whether it did.
    pub fn resample_if<R: Rng + ?Sized>(
        &mut self,
        policy: ResamplePolicy,
        scheme: Resampling,
        rng: &mut R,
    ) -> Result<bool, ParticleError> {
        match policy {
            ResamplePolicy::Always => {}
            ResamplePolicy::EssBelow(fraction) => {
                if !(0.0..=1.0).contains(&fraction) {
                    return Err(ParticleError::Threshold(fraction));
                }
                if self.ess()? >= fraction * self.n as f64 {
                    return Ok(false);
                }
            }
        }
        self.resample(scheme, rng)?;
        Ok(true)
    }

    /// Draws `n` ancestors with `scheme` (normalizing first if needed), gathers the states
    /// component by component into the spare buffer, swaps it in and sets all weights equal
    /// (log-weights `-ln n`, already normalized; see [`normalize`](Self::normalize) for why not
    /// 0).
    pub fn resample<R: Rng + ?Sized>(
        &mut self,
        scheme: Resampling,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        self.ensure_normalized()?;
        // The schemes below overwrite the weights: the cached sum of squares goes with them.
        self.sum_sq = None;
        let n = self.n;
        let anc = &mut self.ancestors;
        // The schemes overwrite the normalized weights with cumulative sums: they are not
        // needed after this step.
        match scheme {
            Resampling::Systematic => {
                systematic(&mut self.weights, rng.random(), &mut self.counts, anc)
            }
            Resampling::Stratified => {
                let (total, last) = cumulative_in_place(&mut self.weights)?;
                let step = total / n as f64;
                for (k, u) in self.noise.iter_mut().enumerate() {
                    *u = (k as f64 + rng.random::<f64>()) * step;
                }
                merge(&self.weights, last, &self.noise, anc);
            }
            Resampling::Multinomial => {
                let (total, last) = cumulative_in_place(&mut self.weights)?;
                sorted_uniforms(&mut self.noise, total, rng);
                merge(&self.weights, last, &self.noise, anc);
            }
            Resampling::Residual => residual(
                &mut self.weights,
                &mut self.noise,
                &mut self.counts,
                anc,
                rng,
            )?,
        }
        for j in 0..self.dim {
            gather(
                &self.states[j * n..(j + 1) * n],
                &anc[..n],
                &mut self.spare[j * n..(j + 1) * n],
            );
        }
        std::mem::swap(&mut self.states, &mut self.spare);
        self.set_equal_weights();
        Ok(())
    }

    fn set_equal_weights(&mut self) {
        self.sum_sq = None;
        let n = self.n as f64;
        self.log_weights.fill(-n.ln());
        self.weights.fill(1.0 / n);
        self.normalized = true;
    }
}

#[cfg(test)]
mod tests;
