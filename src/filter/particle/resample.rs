//! The resampling algorithms behind [`Resampling`](super::Resampling): systematic (branch
//! free, with segmented running sums), stratified and multinomial (sorted positions merged
//! against cumulative weights; multinomial through sorted uniforms from exponential spacings)
//! and residual, all producing sorted ancestor indices. Zheng et al. (2014), Algorithm 1, (A1.6). They
//! work on the cloud's buffers as plain slices, apart from the cloud so that each algorithm and
//! its statistical tests sit together.
use super::ParticleError;
use multiversion::multiversion;
use rand::Rng;
use rand_distr::{Distribution, Exp1};

/// Replaces `w` by its running sums; returns the total and the index of the last particle with
/// positive weight (rounding in the sums must never hand a position to a zero-weight particle
/// after it). Normalized weights always have a positive finite total; the check keeps this
/// function honest on its own.
pub(super) fn cumulative_in_place(w: &mut [f64]) -> Result<(f64, usize), ParticleError> {
    let mut c = 0.0;
    let mut last = 0;
    for (i, v) in w.iter_mut().enumerate() {
        last = if *v > 0.0 { i } else { last };
        c += *v;
        *v = c;
    }
    if c.is_finite() && c > 0.0 {
        Ok((c, last))
    } else {
        Err(ParticleError::DegenerateWeights)
    }
}

/// Systematic resampling over the normalized weights, with no data-dependent branch. With
/// `v` uniform on [0, 1), the positions are `(k + 1 - v) / n`, `k = 0..n`, and particle `i`
/// owns those in `(C_{i-1}, C_i]` (C the running sum of the weights): the first
/// `N_i = floor(n C_i + v)` positions lie at or below `C_i`, so particle `i` gets slots
/// `N_{i-1}..N_i` — `floor(n w_i)` or `ceil(n w_i)` of them. The ends `N_i` go to `ends`, and
/// [`ancestors_from_ends`] turns them into ancestors. If rounding leaves `n C_n + v` a hair
/// below `n`, the last slots go to the last particle with positive weight.
/// `anc` has `n + 1` slots so a run may start at `n`. `w` is left holding the running sums.
///
/// The running sum is the slow part: one chain of dependent additions, 4 cycles each. It is
/// computed as [`SEGMENTS`] chains in parallel, one per contiguous segment, each segment's
/// partial sums added to its offset (the rounded sum of the totals before it): the last
/// cumulative sum of a segment is then exactly the next segment's offset, so the `C_i` never
/// decrease and no run overlaps another. The sums go back into `w` in that pass, and the ends
/// come from them in a pass of their own, which vectorizes (in the summing pass they were
/// four scalar chains).
#[multiversion(targets("x86_64+avx2"))]
pub(super) fn systematic(w: &mut [f64], v: f64, ends: &mut [usize], anc: &mut [usize]) {
    let n = w.len();
    let nf = n as f64;
    // floor(n C_i + v) for n C_i + v in [0, 2^52): adding 2^52 to the (integral) floor leaves
    // it in the low mantissa bits, cheaper than a checked float-to-int conversion. `min`
    // absorbs a total a few ulp above 1.
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    let end_of = |c: f64| {
        let bits = ((c * nf + v).floor() + TWO_52).to_bits() & ((1u64 << 52) - 1);
        (bits as usize).min(n)
    };
    let last_positive = w.iter().rposition(|&wi| wi > 0.0).unwrap_or(0);
    let len = n / SEGMENTS;
    let (body, tail) = w.split_at_mut(len * SEGMENTS);
    // The segments as slices of one length, walked by zipped iterators: no bounds checks.
    let (mut partial, mut offset, mut p) = ([0.0; SEGMENTS], [0.0; SEGMENTS], [0.0; SEGMENTS]);
    if len > 0 {
        let [w0, w1, w2, w3] = segments(body, len);
        // Pass 1: each segment's partial sums (the last segment also takes the tail), in lanes.
        for (((a, b), c), d) in w0.iter().zip(w1).zip(w2).zip(w3) {
            partial[0] += a;
            partial[1] += b;
            partial[2] += c;
            partial[3] += d;
        }
    }
    for wi in tail.iter() {
        partial[SEGMENTS - 1] += wi;
    }
    for s in 1..SEGMENTS {
        offset[s] = offset[s - 1] + partial[s - 1];
    }
    if len > 0 {
        // Pass 2: the running sums C_i, the same partial sums recomputed in the same order.
        let [w0, w1, w2, w3] = segments_mut(body, len);
        let weights = w0
            .iter_mut()
            .zip(w1.iter_mut())
            .zip(w2.iter_mut())
            .zip(w3.iter_mut());
        for (((a, b), c), d) in weights {
            p[0] += *a;
            p[1] += *b;
            p[2] += *c;
            p[3] += *d;
            *a = offset[0] + p[0];
            *b = offset[1] + p[1];
            *c = offset[2] + p[2];
            *d = offset[3] + p[3];
        }
    }
    // The last segment's partial sum continues through the tail.
    let last = SEGMENTS - 1;
    for wi in tail.iter_mut() {
        p[last] += *wi;
        *wi = offset[last] + p[last];
    }
    // Pass 3: the ends.
    for (e, &c) in ends[..n].iter_mut().zip(w.iter()) {
        *e = end_of(c);
    }
    ancestors_from_ends(ends, last_positive, anc);
}

/// Independent running sums in [`systematic`].
const SEGMENTS: usize = 4;

/// The `SEGMENTS` consecutive slices of `len` values that make up `body`.
#[inline(always)]
fn segments<T>(body: &[T], len: usize) -> [&[T]; SEGMENTS] {
    let (a, rest) = body.split_at(len);
    let (b, rest) = rest.split_at(len);
    let (c, d) = rest.split_at(len);
    [a, b, c, d]
}

/// [`segments`], mutable.
#[inline(always)]
fn segments_mut<T>(body: &mut [T], len: usize) -> [&mut [T]; SEGMENTS] {
    let (a, rest) = body.split_at_mut(len);
    let (b, rest) = rest.split_at_mut(len);
    let (c, d) = rest.split_at_mut(len);
    [a, b, c, d]
}

/// Sorted ancestors from the ends of the particles' runs of slots (particle `i` owns slots
/// `ends[i-1]..ends[i]`, ends non-decreasing and at most `n`): the owner of slot `k` is the
/// first particle whose run ends after `k`, i.e. one more than the largest `i` with
/// `ends[i] <= k`. Each particle stores `i + 1` at its end (plain stores in order, so the last
/// writer of a slot is the largest such `i`) and a running maximum spreads the owners over the
/// slots. No branch depends on the data (filling each run in a loop would mispredict on every
/// other particle) and no store depends on a load (a read-modify-write per particle chains
/// through memory when runs are empty). A particle with an empty run never owns a slot; if
/// rounding leaves the runs short of `n`, the remaining slots go to `last`, the last particle
/// with positive weight. `anc` has `n + 1` slots (a run may end at `n`).
fn ancestors_from_ends(ends: &[usize], last: usize, anc: &mut [usize]) {
    let n = anc.len() - 1;
    anc.fill(0);
    for (i, &e) in ends.iter().enumerate() {
        anc[e] = i + 1;
    }
    let mut owner = 0usize;
    for a in anc[..n].iter_mut() {
        owner = owner.max(*a);
        *a = owner.min(last);
    }
}

/// Ancestors of sorted positions `pos` (in the units of the cumulative sums `cum`): particle
/// `i` takes the positions in `[cum[i-1], cum[i])`. Never moves past `last`, the last particle
/// with positive weight.
pub(super) fn merge(cum: &[f64], last: usize, pos: &[f64], anc: &mut [usize]) {
    let mut i = 0usize;
    for (a, &u) in anc.iter_mut().zip(pos) {
        while i < last && cum[i] <= u {
            i += 1;
        }
        *a = i;
    }
}

/// Fills `out` with the order statistics of `out.len()` uniforms on `[0, total)` in O(n): if
/// `E_0, ..., E_n` are i.i.d. exponential, the partial sums `S_k / S_n` are distributed as
/// sorted uniforms — no sort needed.
pub(super) fn sorted_uniforms<R: Rng + ?Sized>(out: &mut [f64], total: f64, rng: &mut R) {
    let mut s = 0.0;
    for v in out.iter_mut() {
        s += <Exp1 as Distribution<f64>>::sample(&Exp1, rng);
        *v = s;
    }
    s += <Exp1 as Distribution<f64>>::sample(&Exp1, rng);
    let scale = total / s;
    for v in out.iter_mut() {
        *v *= scale;
    }
}

/// Residual resampling: `floor(n w_i)` deterministic copies of particle `i`, then the
/// remaining `R = n - sum floor(n w_i)` drawn multinomially from the fractional parts `n w_i -
/// floor(n w_i)` (sorted uniforms merged against their running sums), then the copies expanded
/// into sorted ancestors. `w` holds the normalized weights on entry and the cumulative
/// fractional parts on exit; `noise` receives the sorted uniforms.
///
/// `n w_i` within 1e-9 below an integer counts as that integer: equal weights `1/n` multiply
/// back to `1 - 1e-16` for some `n`, and without the snap every particle would go through the
/// random part instead of being kept. The bias is below 1e-9 copies per particle.
pub(super) fn residual<R: Rng + ?Sized>(
    w: &mut [f64],
    noise: &mut [f64],
    counts: &mut [usize],
    anc: &mut [usize],
    rng: &mut R,
) -> Result<(), ParticleError> {
    let n = w.len();
    let total: f64 = w.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return Err(ParticleError::DegenerateWeights);
    }
    let scale = n as f64 / total;
    let mut frac_sum = 0.0;
    let mut deterministic = 0usize;
    let mut last_frac = 0usize;
    let mut last = 0usize;
    for (i, (wi, k)) in w.iter_mut().zip(counts.iter_mut()).enumerate() {
        last = if *wi > 0.0 { i } else { last };
        let nw = *wi * scale;
        let f = (nw + 1e-9).floor();
        *k = f as usize;
        deterministic += *k;
        let r = (nw - f).max(0.0);
        last_frac = if r > 0.0 { i } else { last_frac };
        frac_sum += r;
        *wi = frac_sum;
    }
    // sum floor(n w_i) <= n up to the snap and rounding; any excess is taken back from the
    // last particles.
    let mut excess = deterministic.saturating_sub(n);
    for k in counts.iter_mut().rev() {
        let take = excess.min(*k);
        *k -= take;
        excess -= take;
    }
    let remaining = n - deterministic.min(n);
    if remaining > 0 {
        if frac_sum > 0.0 {
            let pos = &mut noise[..remaining];
            sorted_uniforms(pos, frac_sum, rng);
            let mut i = 0usize;
            for &u in pos.iter() {
                while i < last_frac && w[i] <= u {
                    i += 1;
                }
                counts[i] += 1;
            }
        } else {
            // Only reachable through rounding (the fractional parts sum to R >= 1 exactly).
            counts[last] += remaining;
        }
    }
    expand_counts(counts, anc);
    Ok(())
}

/// Sorted ancestors from copies per particle (`counts` becomes the runs' ends).
fn expand_counts(counts: &mut [usize], anc: &mut [usize]) {
    let last = counts.iter().rposition(|&c| c > 0).unwrap_or(0);
    let mut end = 0usize;
    for c in counts.iter_mut() {
        end += *c;
        *c = end;
    }
    ancestors_from_ends(counts, last, anc);
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{rng, ALL_SCHEMES};
    use super::super::{ParticleCloud, Resampling};

    /// Raw weights with zeros at the front, in the middle and at the end; n w_i is never an
    /// integer, so floor and ceil differ for every positive weight.
    fn test_weights() -> Vec<f64> {
        let raw = [0.0, 0.5, 2.95, 0.0, 1.7, 0.05, 2.2, 0.9, 0.0, 1.3, 0.4, 0.0];
        let s: f64 = raw.iter().sum();
        raw.iter().map(|r| r / s).collect()
    }

    /// Counts of each index over `reps` resamplings with fixed weights; also checks, on every
    /// repetition, the structural properties all schemes share.
    fn resampling_counts(scheme: Resampling, reps: usize, seed: u64) -> Vec<Vec<usize>> {
        let w = test_weights();
        let n = w.len();
        let mut c = ParticleCloud::new(1, n).unwrap();
        let mut r = rng(seed);
        let mut counts = Vec::with_capacity(reps);
        for _ in 0..reps {
            for (i, x) in c.component_mut(0).iter_mut().enumerate() {
                *x = i as f64;
            }
            for (l, wi) in c.log_weights_mut().iter_mut().zip(&w) {
                *l = wi.ln() + 7.0; // any constant offset
            }
            c.resample(scheme, &mut r).unwrap();
            let anc = c.ancestors().to_vec();
            assert!(anc.windows(2).all(|p| p[0] <= p[1]), "{scheme:?}: unsorted");
            // The gather moved the states: particle k now holds the old particle anc[k].
            assert!(c
                .component(0)
                .iter()
                .zip(&anc)
                .all(|(x, &a)| *x == a as f64));
            assert!(c.log_weights().iter().all(|l| *l == -(n as f64).ln()));
            assert!(c.weights().unwrap().iter().all(|v| *v == 1.0 / n as f64));
            let mut k = vec![0usize; n];
            for a in anc {
                assert!(w[a] > 0.0, "{scheme:?} picked zero-weight particle {a}");
                k[a] += 1;
            }
            counts.push(k);
        }
        counts
    }

    fn mean_var(counts: &[Vec<usize>], i: usize) -> (f64, f64) {
        let r = counts.len() as f64;
        let m = counts.iter().map(|k| k[i] as f64).sum::<f64>() / r;
        let v = counts
            .iter()
            .map(|k| (k[i] as f64 - m).powi(2))
            .sum::<f64>()
            / (r - 1.0);
        (m, v)
    }

    #[test]
    fn every_scheme_is_unbiased() {
        // The mean count over R repetitions has standard error sd_i / sqrt(R), sd_i the
        // sample standard deviation of the count. 4 standard errors: a false alarm among the
        // 48 comparisons has probability about 48 * 6e-5 = 3e-3 (and the seed is fixed).
        let reps = 20_000;
        let w = test_weights();
        let n = w.len() as f64;
        for (s, scheme) in ALL_SCHEMES.into_iter().enumerate() {
            let counts = resampling_counts(scheme, reps, 100 + s as u64);
            for (i, wi) in w.iter().enumerate() {
                let (m, v) = mean_var(&counts, i);
                let se = (v / reps as f64).sqrt();
                assert!(
                    (m - n * wi).abs() <= 4.0 * se,
                    "{scheme:?} index {i}: mean count {m} vs n w = {} (se {se})",
                    n * wi
                );
            }
        }
    }

    /// The segmented sums of `systematic` for any length, a multiple of the segments or not and
    /// shorter than them: the ancestors are those of the sequential running sum (positions
    /// `(k + 1 - v) / n` against `C_i`). Weights that are multiples of 2^-10 and `v` a multiple
    /// of 1/8 keep every sum exact, so any order of the additions gives the same ends.
    #[test]
    fn systematic_is_the_sequential_rule_for_any_length() {
        for n in [1usize, 2, 3, 4, 5, 7, 8, 13, 64, 101, 255] {
            // Units of 2^-10, uneven (a fifth of them zero) and of the order of 1/n each, the
            // last weight taking what makes the sum 1.
            let scale = 1024 / (4 * n);
            let mut units: Vec<usize> = (0..n).map(|i| (i * 7 + 3) % 5 * scale).collect();
            units[n - 1] += 1024 - units.iter().sum::<usize>();
            let w: Vec<f64> = units.iter().map(|&u| u as f64 / 1024.0).collect();
            for v in [0.0, 0.125, 0.5, 0.875] {
                let (mut ends, mut anc) = (vec![0; n], vec![0; n + 1]);
                super::systematic(&mut w.clone(), v, &mut ends, &mut anc);
                let mut want = Vec::new();
                let mut c = 0.0;
                for (i, wi) in w.iter().enumerate() {
                    c += wi;
                    let end = ((c * n as f64 + v).floor() as usize).min(n);
                    while want.len() < end {
                        want.push(i);
                    }
                }
                let last = w.iter().rposition(|&x| x > 0.0).unwrap();
                want.resize(n, last);
                assert_eq!(&anc[..n], &want[..], "n = {n}, v = {v}");
            }
        }
    }

    /// Equal weights `1/k` rarely sum to exactly 1: where they fall short, `n C_n + v` stays a
    /// hair below `n` at `v = 0` and the last slot must still go to a particle with weight,
    /// not to the zero-weight particles after them.
    #[test]
    fn systematic_never_hands_a_slot_to_trailing_zero_weights() {
        let mut short = 0;
        for k in 3..200 {
            let mut w = vec![1.0 / k as f64; k];
            short += usize::from(w.iter().sum::<f64>() < 1.0);
            w.extend([0.0; 3]);
            let n = w.len();
            let (mut ends, mut anc) = (vec![0; n], vec![0; n + 1]);
            super::systematic(&mut w.clone(), 0.0, &mut ends, &mut anc);
            assert!(anc[..n].iter().all(|&a| a < k), "k = {k}: {:?}", &anc[..n]);
        }
        assert!(
            short > 0,
            "no sum fell short of 1: the case is not exercised"
        );
    }

    #[test]
    fn systematic_counts_are_floor_or_ceil() {
        let w = test_weights();
        let n = w.len() as f64;
        for k in resampling_counts(Resampling::Systematic, 5000, 7) {
            for (c, wi) in k.iter().zip(&w) {
                let nw = n * wi;
                assert!(
                    *c as f64 == nw.floor() || *c as f64 == nw.ceil(),
                    "{c} vs {nw}"
                );
            }
        }
    }

    #[test]
    fn stratified_counts_are_within_two_of_expectation() {
        // Particle i's interval has length n w_i in stratum units: it lies fully inside at least
        // floor(n w_i) - 1 strata (each gives it exactly one copy) and touches at most
        // ceil(n w_i) + 1, so |count - n w_i| < 2. Both bounds are attained.
        let w = test_weights();
        let n = w.len() as f64;
        let mut spread = [0usize; 2];
        for k in resampling_counts(Resampling::Stratified, 5000, 8) {
            for (c, wi) in k.iter().zip(&w) {
                let d = *c as f64 - n * wi;
                assert!(d.abs() < 2.0, "{c} vs {}", n * wi);
                if d.abs() > 1.0 {
                    spread[usize::from(d > 0.0)] += 1;
                }
            }
        }
        // Stratified is not systematic: it does leave the floor/ceil band sometimes.
        assert!(spread[0] + spread[1] > 0);
    }

    #[test]
    fn residual_keeps_the_deterministic_copies_and_has_multinomial_remainder() {
        let w = test_weights();
        let n = w.len() as f64;
        let reps = 20_000;
        let counts = resampling_counts(Resampling::Residual, reps, 9);
        let floors: Vec<f64> = w.iter().map(|wi| (n * wi).floor()).collect();
        for k in &counts {
            for (c, f) in k.iter().zip(&floors) {
                assert!(*c as f64 >= *f);
            }
        }
        // The remainder is multinomial(R, r_i / R): variance R p (1 - p). The sample variance
        // of 20,000 binomial counts has relative standard error sqrt((2 + kurtosis) / reps),
        // below 4% for these p; 20% is more than 5 standard errors.
        let rem = n - floors.iter().sum::<f64>();
        for (i, wi) in w.iter().enumerate() {
            let p = (n * wi - floors[i]) / rem;
            let expected = rem * p * (1.0 - p);
            let (_, v) = mean_var(&counts, i);
            assert!(
                (v - expected).abs() <= 0.2 * expected + 1e-12,
                "index {i}: variance {v} vs {expected}"
            );
        }
    }

    #[test]
    fn residual_keeps_every_particle_of_equal_weights() {
        // n w_i = 1 for all i, even when 1/n rounds (49 * (1/49) = 1 - 1e-16).
        for n in [49, 1000] {
            let mut c = ParticleCloud::new(1, n).unwrap();
            c.log_weights_mut().fill(-2.5);
            c.resample(Resampling::Residual, &mut rng(17)).unwrap();
            assert!(c.ancestors().iter().enumerate().all(|(k, &a)| a == k));
        }
    }

    #[test]
    fn multinomial_counts_have_binomial_variance() {
        // Sorted uniforms built from exponential spacings must be exactly as good as sorting
        // n independent uniforms: count i is Binomial(n, w_i). Same tolerance argument as the
        // residual test.
        let w = test_weights();
        let n = w.len() as f64;
        let counts = resampling_counts(Resampling::Multinomial, 20_000, 10);
        for (i, wi) in w.iter().enumerate() {
            let expected = n * wi * (1.0 - wi);
            let (_, v) = mean_var(&counts, i);
            assert!(
                (v - expected).abs() <= 0.2 * expected + 1e-12,
                "index {i}: variance {v} vs {expected}"
            );
        }
    }
}
