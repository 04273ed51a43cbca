//! The consensus iterations of the lock-step loop ([`super::lockstep`], [`super::split`]) on
//! flat buffers: every node's row of reals mixed with its neighbours' rows, each entry its own
//! sum, in the order of `ConsensusNode::combine` (own weight first, then the neighbours in the
//! node's order), so the numbers are the nodes' own whatever the row holds.
use multiversion::multiversion;

/// A node's consensus weights: πᵢᵢ and (j, πᵢⱼ) for every neighbour j.
pub(super) type NodeWeights = (f64, Vec<(usize, f64)>);

/// `iterations` consensus iterations on `current` (rows of `stride` reals), `mixed` the work
/// space. The common strides (one pair of a 1- to 4-dimensional state, two for the hybrid; the
/// vectors of 1 to 3 and the matrices of 2 to 4 dimensions of [`super::split`]) as fixed-size
/// rows the compiler unrolls, any other in slices: the same sums. Compiled also for AVX2 and
/// picked at run time (the same IEEE operations on wider vectors, so the same bits).
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn iterate(
    iterations: usize,
    stride: usize,
    weights: &[NodeWeights],
    current: &mut Vec<f64>,
    mixed: &mut Vec<f64>,
) {
    for _ in 0..iterations {
        match stride {
            1 => mix::<1>(weights, current, mixed),
            2 => mix::<2>(weights, current, mixed),
            3 => mix::<3>(weights, current, mixed),
            4 => mix::<4>(weights, current, mixed),
            6 => mix::<6>(weights, current, mixed),
            9 => mix::<9>(weights, current, mixed),
            12 => mix::<12>(weights, current, mixed),
            16 => mix::<16>(weights, current, mixed),
            20 => mix::<20>(weights, current, mixed),
            24 => mix::<24>(weights, current, mixed),
            40 => mix::<40>(weights, current, mixed),
            _ => mix_any(stride, weights, current, mixed),
        }
        std::mem::swap(current, mixed);
    }
}

/// One consensus iteration of rows of `S` reals: row i of `mixed` is πᵢᵢ times row i of
/// `current` plus πᵢⱼ times row j for each neighbour j in order (`ConsensusNode::combine`).
#[inline(always)]
fn mix<const S: usize>(weights: &[NodeWeights], current: &[f64], mixed: &mut [f64]) {
    let row_of =
        |n: usize| -> &[f64; S] { current[n * S..(n + 1) * S].try_into().expect("S reals") };
    for (i, ((own, others), out)) in weights.iter().zip(mixed.chunks_exact_mut(S)).enumerate() {
        let mut row = [0.0; S];
        for (x, y) in row.iter_mut().zip(row_of(i)) {
            *x = y * own;
        }
        for &(n, w) in others {
            for (x, y) in row.iter_mut().zip(row_of(n)) {
                *x += y * w;
            }
        }
        out.copy_from_slice(&row);
    }
}

/// [`mix`] for any row length.
#[inline(always)]
fn mix_any(stride: usize, weights: &[NodeWeights], current: &[f64], mixed: &mut [f64]) {
    for (i, ((own, others), out)) in weights
        .iter()
        .zip(mixed.chunks_exact_mut(stride))
        .enumerate()
    {
        for (x, y) in out.iter_mut().zip(&current[i * stride..(i + 1) * stride]) {
            *x = y * own;
        }
        for &(n, w) in others {
            for (x, y) in out.iter_mut().zip(&current[n * stride..(n + 1) * stride]) {
                *x += y * w;
            }
        }
    }
}
