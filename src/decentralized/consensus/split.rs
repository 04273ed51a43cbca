//! Consensus on information in two halves, for the lock-step loop ([`super::lockstep`]) of a
//! state of 1 to 6 dimensions: the matrices once for all trials, the vectors in every trial.
//!
//! Why: on lossless links the information matrices of Battistelli & Chisci's recursion (Table 1:
//! Ωᵢ = Ωᵢ⁻ + Uᵢ, L mixes Ωᵢ ← Σⱼ πᵢⱼ Ωⱼ, P = Ω⁻¹, P⁻ = A P Aᵀ + Q, Ω⁻ = (P⁻)⁻¹) never read a
//! reading's value, only whether it is there. In a Monte Carlo run every trial has the same
//! graph, weights, sensors, prior and readings present, so every trial computes the same
//! matrices: two SPD inverses, two products and L mixes of n² reals per node and step, where
//! the vectors (qᵢ = qᵢ⁻ + Hᵀ R⁻¹ zᵢ, L mixes of n reals, x̂ = P q, x̂⁻ = A x̂, q⁻ = Ω⁻ x̂⁻) are
//! all that differs. So the matrix half runs once into a [`Track`] (every step's P and Ω⁻ of
//! every node), kept by the thread and reused by each trial whose [`Inputs`] are the same; each
//! trial runs only the vector half. A run whose track would be too large
//! ([`MAX_TRACK_REALS`]) computes the matrices step by step in every trial instead.
//!
//! Same numbers: each half is the nodes' own operations in their order (`ConsensusNode::start`,
//! `combine`, `predict`, through the fixed-size kernels of [`crate::linalg::fixed`], which are
//! nalgebra's bit for bit), and a mix forms each entry as its own sum, so mixing the matrices
//! and the vectors in separate buffers changes no sum (tested against the graph driver, with
//! the track built and reused). A failure (a matrix not positive definite) depends on the
//! matrices alone: the track keeps it, and every trial reports it at the same step and node.
use super::mixing::{iterate, NodeWeights};
use super::ConsensusNode;
use crate::linalg::fixed;
use crate::linalg::{Matrix, Vector};
use std::cell::RefCell;
use std::rc::Rc;

/// Reals one thread keeps in its track at most (32 MB): nodes × steps × 2n² beyond it, the
/// matrices are computed again in every trial.
const MAX_TRACK_REALS: usize = 1 << 22;

thread_local! {
    /// The thread's most recent track (a run's trials on one thread share it).
    static TRACK: RefCell<Option<Rc<Track>>> = const { RefCell::new(None) };
}

/// Everything the matrix half reads, the reals as their bits (a zero's sign, or a NaN, tells
/// two inputs apart as it would the matrices): two trials that agree on it compute the same
/// matrices.
#[derive(Debug, PartialEq)]
struct Inputs {
    n: usize,
    iterations: usize,
    weights: Vec<(u64, Vec<(usize, u64)>)>,
    /// Per node, column by column: Ω⁻ of the first step, A, Aᵀ, Q, then U if it has a sensor.
    matrices: Vec<Vec<u64>>,
    /// Per step: nodes `0..heard` have a reading (those of them with a sensor add U).
    heard: Vec<usize>,
}

impl Inputs {
    fn of(nodes: &[ConsensusNode], weights: &[NodeWeights], heard: Vec<usize>, n: usize) -> Inputs {
        let matrices = nodes
            .iter()
            .map(|node| {
                let u = node.sensor.as_ref().map(|(_, u)| u.as_slice());
                let parts = [
                    node.prior.0.as_slice(),
                    node.model.a.as_slice(),
                    node.work.a_t.as_slice(),
                    node.model.q.as_slice(),
                ];
                parts
                    .into_iter()
                    .chain(u)
                    .flatten()
                    .map(|x| x.to_bits())
                    .collect()
            })
            .collect();
        Inputs {
            n,
            iterations: nodes.first().map_or(0, |node| node.iterations),
            weights: weights
                .iter()
                .map(|(own, others)| {
                    let others = others.iter().map(|&(j, w)| (j, w.to_bits())).collect();
                    (own.to_bits(), others)
                })
                .collect(),
            matrices,
            heard,
        }
    }
}

/// The matrix half of a whole run: per step, per node, P (the estimate's covariance) then Ω⁻ of
/// the next step, n² reals each, up to the first failure; and per step, per node, the factor of
/// P that NEES uses (`fixed::nees_factor`), when every node's P has one.
#[derive(Debug)]
struct Track {
    inputs: Inputs,
    steps: Vec<f64>,
    factors: Option<Vec<f64>>,
    /// (step index, node, message) of the first matrix that is not positive definite.
    failure: Option<(usize, usize, &'static str)>,
}

/// The matrix half step by step: every node's Ω⁻, and the step's P and Ω⁻ (the next step's
/// prior) of every node, 2n² reals a node.
struct Stream<const N: usize> {
    prior: Vec<f64>,
    current: Vec<f64>,
    mixed: Vec<f64>,
    out: Vec<f64>,
}

impl<const N: usize> Stream<N> {
    fn new(nodes: &[ConsensusNode]) -> Self {
        let prior = nodes
            .iter()
            .flat_map(|node| node.prior.0.as_slice().iter().copied())
            .collect();
        Stream {
            prior,
            current: vec![0.0; nodes.len() * N * N],
            mixed: vec![0.0; nodes.len() * N * N],
            out: vec![0.0; nodes.len() * 2 * N * N],
        }
    }

    /// One step with nodes `0..heard` reading: Ω = Ω⁻ + U (+ 0 without a reading or a
    /// sensor), the mixes, P = Ω⁻¹, P⁻ = A P Aᵀ + Q, Ω⁻ = (P⁻)⁻¹, into `out`. The failing node
    /// and its message on error.
    fn advance(
        &mut self,
        nodes: &[ConsensusNode],
        weights: &[NodeWeights],
        heard: usize,
    ) -> Result<(), (usize, &'static str)> {
        let nn = N * N;
        for (i, ((node, cur), prior)) in nodes
            .iter()
            .zip(self.current.chunks_exact_mut(nn))
            .zip(self.prior.chunks_exact(nn))
            .enumerate()
        {
            match (&node.sensor, i < heard) {
                (Some((_, u)), true) => add_into(cur, prior, u.as_slice()),
                _ => add_into(cur, prior, &[0.0; 36]),
            }
        }
        let iterations = nodes.first().map_or(0, |node| node.iterations);
        iterate(iterations, nn, weights, &mut self.current, &mut self.mixed);
        for (i, (((node, omega), out), prior)) in nodes
            .iter()
            .zip(self.current.chunks_exact(nn))
            .zip(self.out.chunks_exact_mut(2 * nn))
            .zip(self.prior.chunks_exact_mut(nn))
            .enumerate()
        {
            let (cov, next) = out.split_at_mut(nn);
            if !spd_inverse::<N>(omega, cov) {
                return Err((i, "the fused information is not positive definite"));
            }
            let (a, a_t) = (node.model.a.as_slice(), node.work.a_t.as_slice());
            let (mut ap, mut predicted) = ([[0.0; N]; N], [[0.0; N]; N]);
            fixed::gemm_square::<N>(ap.as_flattened_mut(), a, cov);
            fixed::gemm_square::<N>(predicted.as_flattened_mut(), ap.as_flattened(), a_t);
            let predicted = predicted.as_flattened_mut();
            for (p, q) in predicted.iter_mut().zip(node.model.q.as_slice()) {
                *p += q;
            }
            if !spd_inverse::<N>(predicted, next) {
                return Err((i, "the predicted covariance is singular"));
            }
            prior.copy_from_slice(next);
        }
        Ok(())
    }

    /// The whole run's matrix half, up to its first failure.
    fn track(mut self, nodes: &[ConsensusNode], weights: &[NodeWeights], inputs: Inputs) -> Track {
        let mut steps = Vec::with_capacity(inputs.heard.len() * self.out.len());
        let mut factors = Some(Vec::with_capacity(steps.capacity() / 2));
        let mut failure = None;
        for (j, &heard) in inputs.heard.iter().enumerate() {
            if let Err((i, message)) = self.advance(nodes, weights, heard) {
                failure = Some((j, i, message));
                break;
            }
            steps.extend_from_slice(&self.out);
            if let Some(f) = &mut factors {
                // NEES factors P as it arrives in the estimate: a matrix of its bits.
                for cov in self.out.chunks_exact(2 * N * N).map(|m| &m[..N * N]) {
                    match fixed::nees_factor(&Matrix::from_column_slice(N, N, cov)) {
                        Some(l) => f.extend_from_slice(&l),
                        None => {
                            factors = None;
                            break;
                        }
                    }
                }
            }
        }
        Track {
            inputs,
            steps,
            factors,
            failure,
        }
    }
}

/// Where a trial's matrices come from.
enum Matrices<const N: usize> {
    /// The thread's track of this run.
    Shared(Rc<Track>),
    /// Computed step by step (the track would be too large).
    Streamed(Stream<N>),
}

/// Consensus on information of an `N`-dimensional state for one trial: the shared matrices and
/// the trial's own vectors.
pub(super) struct Split<const N: usize> {
    matrices: Matrices<N>,
    sensors: usize,
    q: Vec<f64>,
    mixed: Vec<f64>,
}

impl<const N: usize> Split<N> {
    /// The trial of `nodes` (each at its first step's prior) with `weights`, reading
    /// `measurements` (`[k - 1][i]`, sensors `0..sensors`): the thread's track when it was
    /// built from the same inputs, else a new one (kept for the next trial), or the matrices
    /// streamed step by step when a track would be too large.
    pub(super) fn new(
        nodes: &[ConsensusNode],
        weights: &[NodeWeights],
        measurements: &[Vec<Vector>],
        sensors: usize,
    ) -> Self {
        Self::with_track_limit(nodes, weights, measurements, sensors, MAX_TRACK_REALS)
    }

    /// [`Split::new`] with a track of at most `max_reals` reals (the tests' way to stream).
    pub(super) fn with_track_limit(
        nodes: &[ConsensusNode],
        weights: &[NodeWeights],
        measurements: &[Vec<Vector>],
        sensors: usize,
        max_reals: usize,
    ) -> Self {
        let heard = measurements.iter().map(|z| z.len().min(sensors)).collect();
        let inputs = Inputs::of(nodes, weights, heard, N);
        let reals = inputs.heard.len() * nodes.len() * 2 * N * N;
        let matrices = if reals > max_reals {
            Matrices::Streamed(Stream::new(nodes))
        } else {
            let kept = TRACK.with(|t| t.borrow().clone());
            let track = match kept {
                Some(t) if t.inputs == inputs => t,
                _ => {
                    let t = Rc::new(Stream::<N>::new(nodes).track(nodes, weights, inputs));
                    TRACK.with(|cell| *cell.borrow_mut() = Some(Rc::clone(&t)));
                    t
                }
            };
            Matrices::Shared(track)
        };
        Split {
            matrices,
            sensors,
            q: vec![0.0; nodes.len() * N],
            mixed: vec![0.0; nodes.len() * N],
        }
    }
}

/// One trial's consensus on information in two halves, whatever the state's dimension.
pub(super) trait Halves {
    /// Step `j + 1` of every node with the step's readings `z`: q = q⁻ + Hᵀ R⁻¹ z (+ 0 without a
    /// reading), the mixes, x̂ = P q, x̂⁻ = A x̂, q⁻ = Ω⁻ x̂⁻, with the step's P and Ω⁻; each
    /// node's estimate and next prior set. Returns the estimates' NEES factors where the track
    /// has them; the failing node and its message on error.
    fn step(
        &mut self,
        j: usize,
        nodes: &mut [ConsensusNode],
        weights: &[NodeWeights],
        z: &[Vector],
    ) -> Result<Option<&[f64]>, (usize, String)>;
}

/// [`Split`] of a state of `n` = 1 to 6 dimensions, picked at run time.
pub(super) fn for_dimension(
    n: usize,
    nodes: &[ConsensusNode],
    weights: &[NodeWeights],
    measurements: &[Vec<Vector>],
    sensors: usize,
) -> Box<dyn Halves> {
    let (w, z) = (weights, measurements);
    match n {
        1 => Box::new(Split::<1>::new(nodes, w, z, sensors)),
        2 => Box::new(Split::<2>::new(nodes, w, z, sensors)),
        3 => Box::new(Split::<3>::new(nodes, w, z, sensors)),
        4 => Box::new(Split::<4>::new(nodes, w, z, sensors)),
        5 => Box::new(Split::<5>::new(nodes, w, z, sensors)),
        _ => Box::new(Split::<6>::new(nodes, w, z, sensors)),
    }
}

impl<const N: usize> Halves for Split<N> {
    fn step(
        &mut self,
        j: usize,
        nodes: &mut [ConsensusNode],
        weights: &[NodeWeights],
        z: &[Vector],
    ) -> Result<Option<&[f64]>, (usize, String)> {
        let nn = N * N;
        let per_step = nodes.len() * 2 * nn;
        let heard = z.len().min(self.sensors);
        let (matrices, factors): (&[f64], Option<&[f64]>) = match &mut self.matrices {
            Matrices::Shared(track) => match track.failure {
                Some((at, i, message)) if at == j => return Err((i, message.to_string())),
                _ => (
                    &track.steps[j * per_step..(j + 1) * per_step],
                    track.factors.as_deref().map(|f| {
                        let per = nodes.len() * nn;
                        &f[j * per..(j + 1) * per]
                    }),
                ),
            },
            Matrices::Streamed(stream) => {
                stream
                    .advance(nodes, weights, heard)
                    .map_err(|(i, m)| (i, m.to_string()))?;
                (&stream.out, None)
            }
        };
        for (i, (node, q)) in nodes.iter().zip(self.q.chunks_exact_mut(N)).enumerate() {
            let prior = node.prior.1.as_slice();
            match (&node.sensor, i < heard) {
                (Some((ht_rinv, _)), true) => {
                    let novel = fixed::mat_vec_cols::<N>(ht_rinv.as_slice(), z[i].as_slice());
                    add_into(q, prior, &novel);
                }
                _ => add_into(q, prior, &[0.0; 6]),
            }
        }
        let iterations = nodes.first().map_or(0, |node| node.iterations);
        iterate(iterations, N, weights, &mut self.q, &mut self.mixed);
        for ((node, q), m) in nodes
            .iter_mut()
            .zip(self.q.chunks_exact(N))
            .zip(matrices.chunks_exact(2 * nn))
        {
            let (cov, next) = m.split_at(nn);
            let q: &[f64; N] = q.try_into().expect("N reals");
            let mean = fixed::mat_vec::<N, N, _>(cov, q);
            let predicted_mean = fixed::mat_vec::<N, N, _>(node.model.a.as_slice(), &mean);
            let q_pred = fixed::mat_vec::<N, N, _>(next, &predicted_mean);
            node.estimate.cov.copy_from_slice(cov);
            node.estimate.mean.copy_from_slice(&mean);
            node.prior.0.copy_from_slice(next);
            node.prior.1.copy_from_slice(&q_pred);
        }
        Ok(factors)
    }
}

/// `out = a + b`, entry by entry (as many as `out` has).
fn add_into(out: &mut [f64], a: &[f64], b: &[f64]) {
    for ((x, a), b) in out.iter_mut().zip(a).zip(b) {
        *x = a + b;
    }
}

/// `linalg::spd_inverse_small_into` of the N x N column-major `a` into `out` (finite, then the
/// Cholesky factor and the symmetrized inverse from it); false where it errs.
#[inline(always)]
fn spd_inverse<const N: usize>(a: &[f64], out: &mut [f64]) -> bool {
    let mut factor = [[0.0; N]; N];
    let factor = factor.as_flattened_mut();
    factor.copy_from_slice(&a[..N * N]);
    if !fixed::all_finite(factor) || !fixed::cholesky_square::<N>(factor) {
        return false;
    }
    fixed::chol_inverse_sym_square::<N>(factor, out);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decentralized::consensus::Fusion;
    use crate::decentralized::fixture::{model, prior, sensors};

    /// Inputs compare as bits: a Q whose off-diagonal zero is negative is another run (its
    /// products can differ in the sign of a zero), so it does not take the kept track.
    #[test]
    fn inputs_tell_the_sign_of_a_zero_apart() {
        let s = sensors();
        let node = |m: crate::decentralized::Model| {
            let sensor = Some((&s[0].0, &s[0].1));
            ConsensusNode::new(Fusion::Information, m, &prior(), sensor, 1.0, vec![], 2).unwrap()
        };
        let mut signed = model();
        signed.q[(0, 1)] = -0.0;
        let weights: Vec<NodeWeights> = vec![(1.0, vec![])];
        let a = Inputs::of(&[node(model())], &weights, vec![1, 1], 2);
        let b = Inputs::of(&[node(signed)], &weights, vec![1, 1], 2);
        assert_eq!(a, Inputs::of(&[node(model())], &weights, vec![1, 1], 2));
        assert_ne!(a, b);
        // And a reading missing at one step is another run too.
        assert_ne!(a, Inputs::of(&[node(model())], &weights, vec![1, 0], 2));
    }
}
