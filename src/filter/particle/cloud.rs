//! The particle cloud itself: [`ParticleCloud`] (states, log-weights and every scratch buffer
//! a step needs) with its steps (initialization, propagation, normalization, estimates,
//! resampling), the prepared linear-Gaussian [`ParticleTransition`], the read-only
//! [`StateView`] and the square-root factor used to draw noise. Kept apart from the slice loops
//! (`lanes`) and the resampling algorithms (`resample`) it calls, so this file reads as the
//! filter's steps and nothing else.
use super::lanes::{
    axpy, dot_lanes, exp_shifted_into, gather, max_lanes, mul_into, normalize_in_place, scale_into,
    shift_into,
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
        Ok(Self {
            dim,
            rows,
            noise: SqrtColumns::new(&q_sqrt),
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
    /// `n` standard normals per noise column; sorted uniforms for multinomial resampling.
    noise: Vec<f64>,
    /// Ancestor indices of the last resampling; one extra slot for the branch-free scatter.
    ancestors: Vec<usize>,
    /// Copies per particle (residual resampling).
    counts: Vec<usize>,
    /// Whether `weights` holds the normalized `exp(log_weights)`.
    normalized: bool,
}

impl ParticleCloud {
    /// A cloud of `n` particles at the origin of a `dim`-dimensional space, equally weighted.
    /// All buffers are allocated here and never again.
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
            ancestors: (0..=n).collect(),
            counts: vec![0; n],
            normalized: true,
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

    /// Propagates every particle through `x' = F x + w` (Zheng et al. (2014), (A1.3)): `F x` as one
    /// `axpy` per nonzero entry of `F` over whole components, then one block of normal draws
    /// per column of the square root of `Q`. Weights are unchanged (bootstrap proposal).
    pub fn propagate<R: Rng + ?Sized>(
        &mut self,
        transition: &ParticleTransition,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        self.check_dim("transition", transition.dim)?;
        let n = self.n;
        for (i, row) in transition.rows.iter().enumerate() {
            let out = &mut self.spare[i * n..(i + 1) * n];
            match row.split_first() {
                None => out.fill(0.0),
                Some((&(j0, a0), rest)) => {
                    scale_into(a0, &self.states[j0 * n..(j0 + 1) * n], out);
                    for &(j, a) in rest {
                        axpy(a, &self.states[j * n..(j + 1) * n], out);
                    }
                }
            }
        }
        transition
            .noise
            .add_noise(&mut self.spare, n, &mut self.noise, rng);
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
        normalize_in_place(&mut self.weights, &mut self.log_weights, 1.0 / s, m, ln_s);
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
        Ok(1.0 / dot_lanes(&self.weights, &self.weights))
    }

    /// Weighted mean, written into `out` (length `dim`) without allocating.
    pub fn mean_into(&mut self, out: &mut [f64]) -> Result<(), ParticleError> {
        self.check_dim("mean output", out.len())?;
        self.ensure_normalized()?;
        for (j, o) in out.iter_mut().enumerate() {
            *o = dot_lanes(&self.weights, self.component(j));
        }
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
        // Centered components a_j = x_j - m_j into the spare buffer, then for each row j the
        // weighted t = w a_j into the noise buffer, and entry (j, k) = sum t a_k: two flops per
        // particle and entry instead of five for sum w (x_j - m_j)(x_k - m_k).
        let n = self.n;
        for j in 0..self.dim {
            shift_into(
                -out.mean[j],
                &self.states[j * n..(j + 1) * n],
                &mut self.spare[j * n..(j + 1) * n],
            );
        }
        let t = &mut self.noise[..n];
        for j in 0..self.dim {
            let aj = &self.spare[j * n..(j + 1) * n];
            mul_into(&self.weights, aj, t);
            for k in j..self.dim {
                let c = dot_lanes(t, &self.spare[k * n..(k + 1) * n]);
                out.cov[(j, k)] = c;
                out.cov[(k, j)] = c;
            }
        }
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
        let n = self.n;
        let anc = &mut self.ancestors;
        // The schemes overwrite the normalized weights with cumulative sums: they are not
        // needed after this step.
        match scheme {
            Resampling::Systematic => {
                systematic(&self.weights, rng.random(), &mut self.counts, anc)
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
        let n = self.n as f64;
        self.log_weights.fill(-n.ln());
        self.weights.fill(1.0 / n);
        self.normalized = true;
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{rng, ALL_SCHEMES};
    use super::*;
    use crate::filter::kf;
    use crate::linalg::matrix_from_rows;
    use crate::model::LinearSensor;
    use rand::RngCore;
    use rand_distr::Distribution;

    #[test]
    fn normalize_is_stable_for_huge_negative_log_weights() {
        let mut c = ParticleCloud::new(1, 3).unwrap();
        c.log_weights_mut()
            .copy_from_slice(&[-1000.0, -1001.0, -2000.0]);
        let log_z = c.normalize().unwrap();
        let e = (-1.0_f64).exp();
        // Exact: w = (1, e^-1, e^-1000) / (1 + e^-1 + e^-1000), and e^-1000 underflows.
        assert!((log_z - (-1000.0 + (1.0 + e).ln())).abs() < 1e-12);
        let w = c.weights().unwrap().to_vec();
        assert!(w.iter().all(|v| v.is_finite()));
        assert!((w[0] - 1.0 / (1.0 + e)).abs() < 1e-15);
        assert!((w[1] / w[0] - e).abs() < 1e-15);
        assert_eq!(w[2], 0.0);
        // The log-weights are now normalized: they sum to one in the linear domain.
        let s: f64 = c.log_weights().iter().map(|l| l.exp()).sum();
        assert!((s - 1.0).abs() < 1e-15);
        // Normalizing again changes nothing and reports log Z = 0.
        assert!(c.normalize().unwrap().abs() < 1e-15);
    }

    #[test]
    fn degenerate_weights_are_errors_and_leave_log_weights_alone() {
        let mut c = ParticleCloud::new(1, 3).unwrap();
        for bad in [
            [f64::NEG_INFINITY; 3],
            [0.0, f64::NAN, 1.0],
            [0.0, f64::INFINITY, 1.0],
        ] {
            c.log_weights_mut().copy_from_slice(&bad);
            assert_eq!(c.normalize(), Err(ParticleError::DegenerateWeights));
            assert_eq!(c.ess(), Err(ParticleError::DegenerateWeights));
            assert_eq!(
                c.resample(Resampling::Systematic, &mut rng(0)),
                Err(ParticleError::DegenerateWeights)
            );
            let kept = c.log_weights();
            assert!(kept
                .iter()
                .zip(&bad)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

    #[test]
    fn ess_of_equal_and_of_single_weight() {
        let n = 1000;
        let mut c = ParticleCloud::new(1, n).unwrap();
        c.log_weights_mut().fill(-3.7);
        assert!((c.ess().unwrap() - n as f64).abs() < 1e-9);
        let lw = c.log_weights_mut();
        lw.fill(f64::NEG_INFINITY);
        lw[417] = -5.0;
        assert_eq!(c.ess().unwrap(), 1.0);
        // Two equal weights among zeros: ESS 2.
        let lw = c.log_weights_mut();
        lw[3] = lw[417];
        assert!((c.ess().unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn normalize_returns_the_evidence_after_resampling() {
        // After resampling the log-weights are -ln n, so adding log-likelihoods ln(1..4) and
        // normalizing returns ln of their average, (1 + 2 + 3 + 4) / 4.
        let mut c = ParticleCloud::new(1, 4).unwrap();
        c.log_weights_mut().copy_from_slice(&[0.0, -1.0, 2.0, 0.5]);
        c.resample(Resampling::Systematic, &mut rng(3)).unwrap();
        for (l, v) in c.log_weights_mut().iter_mut().zip([1.0_f64, 2.0, 3.0, 4.0]) {
            *l += v.ln();
        }
        assert!((c.normalize().unwrap() - 2.5_f64.ln()).abs() < 1e-15);
    }

    #[test]
    fn resample_if_follows_the_policy() {
        let mut c = ParticleCloud::new(1, 100).unwrap();
        let mut r = rng(4);
        // Equal weights: ESS = n, not below half.
        assert!(!c
            .resample_if(
                ResamplePolicy::EssBelow(0.5),
                Resampling::Systematic,
                &mut r
            )
            .unwrap());
        // One dominant particle: ESS near 1.
        c.log_weights_mut()[10] = 50.0;
        for (i, x) in c.component_mut(0).iter_mut().enumerate() {
            *x = i as f64;
        }
        assert!(c
            .resample_if(
                ResamplePolicy::EssBelow(0.5),
                Resampling::Systematic,
                &mut r
            )
            .unwrap());
        assert!(c.component(0).iter().all(|x| *x == 10.0));
        assert!(c
            .resample_if(ResamplePolicy::Always, Resampling::Systematic, &mut r)
            .unwrap());
        for bad in [-0.1, 1.5, f64::NAN] {
            assert!(matches!(
                c.resample_if(
                    ResamplePolicy::EssBelow(bad),
                    Resampling::Systematic,
                    &mut r
                ),
                Err(ParticleError::Threshold(_))
            ));
        }
    }

    #[test]
    fn single_particle_cloud_works() {
        let mut c = ParticleCloud::new(2, 1).unwrap();
        c.component_mut(1)[0] = 3.0;
        for s in ALL_SCHEMES {
            c.log_weights_mut()[0] = -12.0;
            c.resample(s, &mut rng(5)).unwrap();
            assert_eq!(c.ancestors(), &[0]);
            assert_eq!(c.component(1), &[3.0]);
        }
        assert_eq!(c.ess().unwrap(), 1.0);
    }

    fn sample_moments_within_mc_error(c: &mut ParticleCloud, m: &Vector, p: &Matrix) {
        // With n independent draws from N(m, P): the sample mean of component j has standard
        // error sqrt(P_jj / n) and the sample covariance entry (j, k) has standard error
        // sqrt((P_jj P_kk + P_jk^2) / n) (Isserlis). 4 standard errors each.
        let n = c.len() as f64;
        let est = c.estimate().unwrap();
        for j in 0..m.len() {
            let se = (p[(j, j)] / n).sqrt();
            assert!(
                (est.mean[j] - m[j]).abs() <= 4.0 * se,
                "mean[{j}] {} vs {}",
                est.mean[j],
                m[j]
            );
            for k in 0..m.len() {
                let se = ((p[(j, j)] * p[(k, k)] + p[(j, k)].powi(2)) / n).sqrt();
                assert!(
                    (est.cov[(j, k)] - p[(j, k)]).abs() <= 4.0 * se,
                    "cov[{j},{k}] {} vs {}",
                    est.cov[(j, k)],
                    p[(j, k)]
                );
            }
        }
    }

    #[test]
    fn gaussian_initialization_has_the_right_moments() {
        let m = Vector::from_vec(vec![1.0, -2.0, 0.5]);
        let p = matrix_from_rows(&[
            vec![4.0, 1.2, -0.5],
            vec![1.2, 2.0, 0.3],
            vec![-0.5, 0.3, 1.0],
        ]);
        let prior = Gaussian::new(m.clone(), p.clone());
        let mut c = ParticleCloud::from_gaussian(100_000, &prior, &mut rng(11)).unwrap();
        sample_moments_within_mc_error(&mut c, &m, &p);
        // estimate() agrees with mean() and covariance().
        let est = c.estimate().unwrap();
        assert_eq!(est.mean, c.mean().unwrap());
        assert_eq!(est.cov, c.covariance().unwrap());
    }

    #[test]
    fn singular_prior_puts_particles_on_a_line() {
        // P = g g^T with g = (1, 2): every particle satisfies x_1 - m_1 = 2 (x_0 - m_0).
        let prior = Gaussian::new(
            Vector::from_vec(vec![3.0, -1.0]),
            matrix_from_rows(&[vec![1.0, 2.0], vec![2.0, 4.0]]),
        );
        let c = ParticleCloud::from_gaussian(1000, &prior, &mut rng(12)).unwrap();
        for (x0, x1) in c.component(0).iter().zip(c.component(1)) {
            assert!(((x1 + 1.0) - 2.0 * (x0 - 3.0)).abs() < 1e-12);
        }
        assert!(c.component(0).iter().any(|x| (x - 3.0).abs() > 0.5));
    }

    /// Zheng et al. (2014), Section VII-A: white-noise acceleration, D = 1, sigma^2 = 4. Q is rank one.
    fn paper_cv() -> LinearTransition {
        let d = 1.0_f64;
        let s2 = 4.0;
        LinearTransition::new(
            matrix_from_rows(&[vec![1.0, d], vec![0.0, 1.0]]),
            matrix_from_rows(&[
                vec![s2 * d.powi(4) / 4.0, s2 * d.powi(3) / 2.0],
                vec![s2 * d.powi(3) / 2.0, s2 * d * d],
            ]),
        )
        .unwrap()
    }

    #[test]
    fn propagation_matches_the_linear_gaussian_moments() {
        let model = paper_cv();
        let t = ParticleTransition::new(&model).unwrap();
        assert_eq!(t.noise_rank(), 1);
        let prior = Gaussian::new(
            Vector::from_vec(vec![0.0, 10.0]),
            matrix_from_rows(&[vec![4.0, 1.0], vec![1.0, 1.0]]),
        );
        let n = 100_000;
        let mut c = ParticleCloud::from_gaussian(n, &prior, &mut rng(13)).unwrap();
        let before = c.estimate().unwrap();
        let (x0, x1) = (c.component(0).to_vec(), c.component(1).to_vec());
        c.propagate(&t, &mut rng(14)).unwrap();
        // Given the cloud, F m_hat and F P_hat F^T are exact; only the noise is random. Its
        // contribution to the errors (sample mean of w, cross terms F x w^T, sample
        // covariance of w) is bounded by the error of a full sample from N(F m, F P F^T + Q),
        // which is what the helper checks against.
        let f = model.f();
        let m = f * &before.mean;
        let p = f * &before.cov * f.transpose() + model.q();
        sample_moments_within_mc_error(&mut c, &m, &p);
        // The noise is sigma (D^2 / 2, D) z: position noise is exactly half the velocity noise.
        for i in 0..n {
            let w0 = c.component(0)[i] - (x0[i] + x1[i]);
            let w1 = c.component(1)[i] - x1[i];
            assert!((w0 - 0.5 * w1).abs() < 1e-12, "particle {i}: {w0} vs {w1}");
        }
    }

    #[test]
    fn bootstrap_filter_tracks_the_kalman_filter() {
        // x' = 0.9 x + w (q = 0.5), z = x + v (r = 1), prior N(0, 1), 20 steps.
        let (a, q, r) = (0.9, 0.5, 1.0);
        let model =
            LinearTransition::new(Matrix::from_element(1, 1, a), Matrix::from_element(1, 1, q))
                .unwrap();
        let sensor = LinearSensor::new(
            Matrix::from_element(1, 1, 1.0),
            Matrix::from_element(1, 1, r),
        )
        .unwrap();
        let prior = Gaussian::new(Vector::zeros(1), Matrix::identity(1, 1));
        let mut truth_rng = rng(20);
        let mut x = Vector::from_element(1, rand_distr::StandardNormal.sample(&mut truth_rng));
        let zs: Vec<Vector> = (0..20)
            .map(|_| {
                x = model.sample_next(&x, &mut truth_rng);
                crate::model::MeasurementModel::sample(&sensor, &x, &mut truth_rng)
            })
            .collect();
        let t = ParticleTransition::new(&model).unwrap();
        let n = 20_000;
        for (s, scheme) in ALL_SCHEMES.into_iter().enumerate() {
            let mut pf_rng = rng(30 + s as u64);
            let mut cloud = ParticleCloud::from_gaussian(n, &prior, &mut pf_rng).unwrap();
            let mut est = prior.clone();
            let (mut log_z_pf, mut log_z_kf) = (0.0, 0.0);
            for (k, z) in zs.iter().enumerate() {
                let pred = kf::predict(&model, &est);
                let s_k = pred.cov[(0, 0)] + r;
                log_z_kf += -0.5
                    * ((z[0] - pred.mean[0]).powi(2) / s_k
                        + (2.0 * std::f64::consts::PI * s_k).ln());
                est = kf::step(&model, &est, &[(&sensor, z)]).unwrap();

                cloud.propagate(&t, &mut pf_rng).unwrap();
                let (states, lw) = cloud.states_and_log_weights_mut();
                let c0 = -0.5 * (2.0 * std::f64::consts::PI * r).ln();
                for (l, xi) in lw.iter_mut().zip(states.component(0)) {
                    *l += c0 - 0.5 * (z[0] - xi).powi(2) / r;
                }
                log_z_pf += cloud.normalize().unwrap();
                let g = cloud.estimate().unwrap();
                let ess = cloud.ess().unwrap();
                // A weighted mean of particles drawn from the prediction has variance about
                // P_k / ESS (the self-normalized importance sampling rule; ESS rather than N
                // because one outlying z can cut the ESS to a few percent). The particles
                // themselves carry the Monte Carlo error of earlier steps, which resampling
                // re-injects and the dynamics damp by a^2 = 0.81 per step: a geometric sum
                // below 5. So sd <= sqrt(5 P_k / ESS), and we allow 4 sd. The weighted
                // variance has relative sd about sqrt(2 * 5 / ESS) on the same argument.
                let p = est.cov[(0, 0)];
                let sd = (5.0 * p / ess).sqrt();
                assert!(
                    (g.mean[0] - est.mean[0]).abs() <= 4.0 * sd,
                    "{scheme:?} step {k}: PF {} vs KF {} (sd {sd})",
                    g.mean[0],
                    est.mean[0]
                );
                let rel = (g.cov[(0, 0)] - p).abs() / p;
                assert!(
                    rel <= 4.0 * (10.0 / ess).sqrt(),
                    "{scheme:?} step {k}: PF var {} vs KF {p}",
                    g.cov[(0, 0)]
                );
                cloud
                    .resample_if(ResamplePolicy::Always, scheme, &mut pf_rng)
                    .unwrap();
            }
            // The product of the normalizing constants estimates p(z_1:20) (the returned log
            // Z is the per-step evidence because weights stay normalized). Its log has
            // variance about sum_k (E[w^2]/E[w]^2 - 1) / N ~ 20 * 0.12 / N; with the same 5x
            // allowance for resampling, 4 sd is under 0.1 nats.
            assert!(
                (log_z_pf - log_z_kf).abs() < 0.1,
                "{scheme:?}: log evidence PF {log_z_pf} vs KF {log_z_kf}"
            );
        }
    }

    fn run_a_few_steps(seed: u64, scheme: Resampling) -> (Vec<u64>, Vec<u64>) {
        let model = paper_cv();
        let t = ParticleTransition::new(&model).unwrap();
        let prior = Gaussian::new(
            Vector::from_vec(vec![0.0, 10.0]),
            Matrix::identity(2, 2) * 3.0,
        );
        let mut r = rng(seed);
        // Through a trait object, as a scheme holding `&mut dyn RngCore` would call it.
        let r: &mut dyn RngCore = &mut r;
        let mut c = ParticleCloud::from_gaussian(500, &prior, r).unwrap();
        for k in 0..5 {
            c.propagate(&t, r).unwrap();
            let (s, lw) = c.states_and_log_weights_mut();
            for (l, x) in lw.iter_mut().zip(s.component(0)) {
                *l += -0.5 * (x - 10.0 * k as f64).powi(2);
            }
            c.normalize().unwrap();
            c.resample_if(ResamplePolicy::EssBelow(0.6), scheme, r)
                .unwrap();
        }
        c.log_weights_mut()[0] += 0.25;
        c.normalize().unwrap();
        let states = (0..2)
            .flat_map(|j| {
                c.component(j)
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            })
            .collect();
        let weights = c.weights().unwrap().iter().map(|v| v.to_bits()).collect();
        (states, weights)
    }

    #[test]
    fn same_seed_gives_bit_identical_clouds() {
        for scheme in ALL_SCHEMES {
            let a = run_a_few_steps(42, scheme);
            assert_eq!(a, run_a_few_steps(42, scheme), "{scheme:?}");
            assert_ne!(a, run_a_few_steps(43, scheme), "{scheme:?}");
        }
    }

    #[test]
    fn noiseless_model_propagates_deterministically() {
        // Q = 0: no normal draws at all, x' = F x exactly.
        let model = LinearTransition::new(
            matrix_from_rows(&[vec![1.0, 0.5], vec![0.0, 1.0]]),
            Matrix::zeros(2, 2),
        )
        .unwrap();
        let t = ParticleTransition::new(&model).unwrap();
        assert_eq!(t.noise_rank(), 0);
        let prior = Gaussian::new(Vector::from_vec(vec![1.0, 2.0]), Matrix::identity(2, 2));
        let mut c = ParticleCloud::from_gaussian(100, &prior, &mut rng(15)).unwrap();
        let mut before = [0.0; 2];
        c.copy_particle(7, &mut before).unwrap();
        c.propagate(&t, &mut rng(16)).unwrap();
        let mut after = [0.0; 2];
        c.copy_particle(7, &mut after).unwrap();
        assert_eq!(after, [before[0] + 0.5 * before[1], before[1]]);
        assert!(matches!(
            c.copy_particle(100, &mut after),
            Err(ParticleError::Index {
                index: 100,
                len: 100
            })
        ));
    }

    #[test]
    fn dimension_mismatches_are_errors() {
        assert_eq!(ParticleCloud::new(0, 10).unwrap_err(), ParticleError::Empty);
        assert_eq!(ParticleCloud::new(2, 0).unwrap_err(), ParticleError::Empty);
        let mut c = ParticleCloud::new(3, 10).unwrap();
        let t = ParticleTransition::new(&paper_cv()).unwrap();
        assert!(matches!(
            c.propagate(&t, &mut rng(0)),
            Err(ParticleError::Dimension {
                expected: 3,
                got: 2,
                ..
            })
        ));
        let prior = Gaussian::new(Vector::zeros(2), Matrix::identity(2, 2));
        assert!(matches!(
            c.init_gaussian(&prior, &mut rng(0)),
            Err(ParticleError::Dimension { .. })
        ));
        let not_psd = Gaussian::new(
            Vector::zeros(3),
            matrix_from_rows(&[
                vec![1.0, 2.0, 0.0],
                vec![2.0, 1.0, 0.0],
                vec![0.0, 0.0, 1.0],
            ]),
        );
        assert!(matches!(
            c.init_gaussian(&not_psd, &mut rng(0)),
            Err(ParticleError::Matrix { .. })
        ));
        let mut out = [0.0; 2];
        assert!(matches!(
            c.mean_into(&mut out),
            Err(ParticleError::Dimension { .. })
        ));
    }
}
