//! `rand_distr::StandardNormal` on four `Xoshiro256PlusPlus` streams at once: lane j of every
//! draw is, bit for bit, the draw the crate's sampler makes from stream j. The runner draws
//! a block's four trials side by side with it ([`crate::scenario::draw`]), each trial from its
//! own stream as it always has, so every trial keeps its numbers.
//!
//! Why: one normal draw costs a generator step and a ziggurat test, two dozen instructions that
//! the scalar sampler runs once per draw; four streams side by side run them once per four
//! draws in vector registers. No crate offers it: rand_distr's sampler takes one generator.
//!
//! How, and why it cannot give other numbers: the generator step is xoshiro256++'s (Blackman
//! and Vigna), the ziggurat's fast path is rand_distr's (a layer `i` from the word's low
//! byte, `u` in [-1, 1) from its top 52 bits, `x = u X[i]`, accepted when `|x| < X[i + 1]`).
//! Every lane that the fast path does not accept is rewound to its state before the draw and
//! drawn again by rand_distr's own sampler (which makes the same first test, rejects it the
//! same way and goes on to its slow path). The layer widths `X[i]` are read from the crate's
//! sampler itself (a draw whose word puts `u` at exactly 1/2 returns `X[i] / 2`), and before
//! the lanes are ever used they are checked against the crate: seeding, many draws and the
//! words after them, on several streams. Should a future version of either crate draw
//! otherwise, the check fails and [`NormalLanes::seeded`] returns `None`: the caller then draws
//! one trial at a time, as before, with the crate's own sampler.
use crate::linalg::quad::F64x4;
use rand::RngCore;
use rand_distr::{Distribution, StandardNormal};
use std::sync::OnceLock;

/// Lanes: four streams.
const LANES: usize = F64x4::LANES;

/// Layers whose width is read from the sampler (the last layers, 254 and 255, have no
/// readable successor: their lanes always take the crate's sampler).
const FAST_LAYERS: usize = 254;

/// The widths as the fast path reads them: X[0..=254] from the sampler, then zeros (the
/// bound of layers 254 and 255, which no draw passes, so that their lanes take the crate's
/// sampler), 257 entries, so that a layer index of one byte and its successor are always in
/// range.
type Widths = [f64; 257];

/// Four xoshiro256++ streams, `s[w][j]` word w of stream j (a layout that runs the four
/// streams' steps as vector instructions).
#[derive(Clone, Debug)]
pub struct NormalLanes {
    s: [[u64; LANES]; 4],
    /// rand_distr's layer widths X[0..=254] ([`FAST_LAYERS`] + 1).
    x: &'static Widths,
}

impl NormalLanes {
    /// Four streams, lane j seeded as `Xoshiro256PlusPlus::seed_from_u64(seeds[j])` seeds it;
    /// `None` when the lanes do not draw the crates' numbers here (see the module).
    pub fn seeded(seeds: [u64; LANES]) -> Option<Self> {
        let x = checked_table()?;
        Some(Self::unchecked(seeds, x))
    }

    fn unchecked(seeds: [u64; LANES], x: &'static Widths) -> Self {
        let mut s = [[0; LANES]; 4];
        for (j, &seed) in seeds.iter().enumerate() {
            for (w, word) in splitmix_state(seed).into_iter().enumerate() {
                s[w][j] = word;
            }
        }
        Self { s, x }
    }

    /// One standard normal draw of every stream: lane j is `StandardNormal.sample` of stream j
    /// (of many, [`NormalLanes::fill`] is faster).
    pub fn normals(&mut self) -> F64x4 {
        let mut z = [F64x4::default()];
        self.fill(&mut z);
        z[0]
    }

    /// `out.len()` draws of every stream, in order: `out[t]` lane j is stream j's t-th draw
    /// from here.
    pub fn fill(&mut self, out: &mut [F64x4]) {
        fill_lanes(self, out);
    }
}

/// [`NormalLanes::fill`]: in AVX2 registers where the processor has them, else the same
/// operations lane by lane.
fn fill_lanes(lanes: &mut NormalLanes, out: &mut [F64x4]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { fill_avx2(lanes, out) };
        return;
    }
    fill_portable(lanes, out);
}

/// [`fill_lanes`] without vector instructions: each lane's step and test in turn.
fn fill_portable(lanes: &mut NormalLanes, out: &mut [F64x4]) {
    let (mut s, x) = (lanes.s, lanes.x);
    for o in out.iter_mut() {
        let words = step(&mut s);
        let mut z = [0.0; LANES];
        let mut fast = [true; LANES];
        for j in 0..LANES {
            let i = (words[j] & 0xff) as usize;
            // rand_distr's u: the top 52 bits as a float in [2, 4), minus 3.
            let u = f64::from_bits((words[j] >> 12) | (1024u64 << 52)) - 3.0;
            z[j] = u * x[i];
            fast[j] = z[j].abs() < x[i + 1];
        }
        if !(fast[0] & fast[1] & fast[2] & fast[3]) {
            // By value, in and out: a state whose address is taken lives in memory.
            (s, z) = redraw_rejected(s, fast, z);
        }
        *o = F64x4(z);
    }
    lanes.s = s;
}

/// [`fill_lanes`] in AVX2 registers: the four streams' words in four registers, the step and
/// the fast path's test four lanes at a time (the compiler left the step in scalar code,
/// through memory, at twice the scalar sampler's time). The same integer and IEEE operations
/// as [`fill_portable`]: shifts for the rotations, `u` from the word's top bits, `u X[i]`, its
/// absolute value (the sign bit cleared) against X[i + 1] (an ordered comparison, as `<`).
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fill_avx2(lanes: &mut NormalLanes, out: &mut [F64x4]) {
    use std::arch::x86_64::*;
    let load = |w: &[u64; LANES]| _mm256_loadu_si256(w.as_ptr().cast());
    let (mut s0, mut s1, mut s2, mut s3) = (
        load(&lanes.s[0]),
        load(&lanes.s[1]),
        load(&lanes.s[2]),
        load(&lanes.s[3]),
    );
    let x = lanes.x;
    let exponent = _mm256_set1_epi64x(1024 << 52);
    let three = _mm256_set1_pd(3.0);
    let magnitude = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
    let byte = _mm256_set1_epi64x(0xff);
    for o in out.iter_mut() {
        let sum = _mm256_add_epi64(s0, s3);
        let rot = _mm256_or_si256(_mm256_slli_epi64::<23>(sum), _mm256_srli_epi64::<41>(sum));
        let words = _mm256_add_epi64(rot, s0);
        let t = _mm256_slli_epi64::<17>(s1);
        s2 = _mm256_xor_si256(s2, s0);
        s3 = _mm256_xor_si256(s3, s1);
        s1 = _mm256_xor_si256(s1, s2);
        s0 = _mm256_xor_si256(s0, s3);
        s2 = _mm256_xor_si256(s2, t);
        s3 = _mm256_or_si256(_mm256_slli_epi64::<45>(s3), _mm256_srli_epi64::<19>(s3));
        let layer = _mm256_and_si256(words, byte);
        // SAFETY: layer <= 255, and the table has 257 entries.
        let (width, next) = unsafe {
            (
                _mm256_i64gather_pd::<8>(x.as_ptr(), layer),
                _mm256_i64gather_pd::<8>(x.as_ptr().add(1), layer),
            )
        };
        let float = _mm256_or_si256(_mm256_srli_epi64::<12>(words), exponent);
        let u = _mm256_sub_pd(_mm256_castsi256_pd(float), three);
        let z = _mm256_mul_pd(u, width);
        let fast = _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_and_pd(z, magnitude), next);
        let mut zs = [0.0; LANES];
        // SAFETY: `zs` holds four doubles.
        unsafe { _mm256_storeu_pd(zs.as_mut_ptr(), z) };
        let accepted = _mm256_movemask_pd(fast);
        if accepted != 0b1111 {
            let mut s = [[0u64; LANES]; 4];
            for (w, v) in s.iter_mut().zip([s0, s1, s2, s3]) {
                // SAFETY: each row holds four words.
                unsafe { _mm256_storeu_si256(w.as_mut_ptr().cast(), v) };
            }
            let fast_lanes = std::array::from_fn(|j| accepted & (1 << j) != 0);
            (s, zs) = redraw_rejected(s, fast_lanes, zs);
            (s0, s1, s2, s3) = (load(&s[0]), load(&s[1]), load(&s[2]), load(&s[3]));
        }
        *o = F64x4(zs);
    }
    for (w, v) in lanes.s.iter_mut().zip([s0, s1, s2, s3]) {
        // SAFETY: each row holds four words.
        unsafe { _mm256_storeu_si256(w.as_mut_ptr().cast(), v) };
    }
}

/// xoshiro256++'s step on four streams (`s[w][j]`: word w of stream j): the word of each.
#[inline(always)]
fn step(s: &mut [[u64; LANES]; 4]) -> [u64; LANES] {
    std::array::from_fn(|j| {
        let mut lane = Lane(std::array::from_fn(|w| s[w][j]));
        let word = lane.next_u64();
        for (w, v) in lane.0.into_iter().enumerate() {
            s[w][j] = v;
        }
        word
    })
}

/// The lanes of a draw that the fast path did not accept (`fast[j]` false): each rewound to
/// its state before the draw ([`unstep`]) and drawn by the crate's sampler from there (`s`:
/// the streams after the draw; the rejected lanes' states are replaced).
#[cold]
#[inline(never)]
fn redraw_rejected(
    mut s: [[u64; LANES]; 4],
    fast: [bool; LANES],
    mut z: [f64; LANES],
) -> ([[u64; LANES]; 4], [f64; LANES]) {
    for (j, zj) in z.iter_mut().enumerate() {
        if fast[j] {
            continue;
        }
        let mut lane = Lane(unstep(std::array::from_fn(|w| s[w][j])));
        *zj = StandardNormal.sample(&mut lane);
        for (w, word) in lane.0.into_iter().enumerate() {
            s[w][j] = word;
        }
    }
    (s, z)
}

/// The state one xoshiro256++ step before `s` (the step is a bijection): with a2 = s2 ^ s0,
/// a3 = s3 ^ s1 and t = s1 << 17, the step gives (s0 ^ a3, s1 ^ a2, a2 ^ t, rotl(a3, 45)).
fn unstep(n: [u64; 4]) -> [u64; 4] {
    let a3 = n[3].rotate_right(45);
    // s1 ^ (s1 << 17) = n1 ^ n2: undone by the xor of its shifts by 17, 34 and 51.
    let c = n[1] ^ n[2];
    let s1 = c ^ (c << 17) ^ (c << 34) ^ (c << 51);
    let a2 = n[2] ^ (s1 << 17);
    let s0 = n[0] ^ a3;
    [s0, s1, a2 ^ s0, a3 ^ s1]
}

/// One xoshiro256++ stream (for the crate's sampler on a rejected lane).
struct Lane([u64; 4]);

impl RngCore for Lane {
    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    fn next_u64(&mut self) -> u64 {
        let s = &mut self.0;
        let out = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        out
    }

    fn fill_bytes(&mut self, dest: &mut [u8]) {
        for chunk in dest.chunks_mut(8) {
            let w = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&w[..chunk.len()]);
        }
    }
}

/// The state `Xoshiro256PlusPlus::seed_from_u64(seed)` starts from: rand_xoshiro's SplitMix64
/// fills the 32 seed bytes, read as four little-endian words (checked in [`checked_table`]).
fn splitmix_state(seed: u64) -> [u64; 4] {
    use rand::SeedableRng;
    let mut bytes = [0u8; 32];
    rand_xoshiro::SplitMix64::seed_from_u64(seed).fill_bytes(&mut bytes);
    std::array::from_fn(|w| u64::from_le_bytes(bytes[8 * w..8 * w + 8].try_into().unwrap()))
}

/// The layer widths, read from rand_distr's sampler and checked (see the module); `None` when
/// the lanes do not draw the crates' numbers.
fn checked_table() -> Option<&'static Widths> {
    static TABLE: OnceLock<Option<&'static Widths>> = OnceLock::new();
    *TABLE.get_or_init(|| {
        let read = read_widths()?;
        let mut x = [0.0; 257];
        x[..=FAST_LAYERS].copy_from_slice(&read);
        let table: &'static Widths = Box::leak(Box::new(x));
        agrees_with_the_crates(|seeds| NormalLanes::unchecked(seeds, table)).then_some(table)
    })
}

/// X[i] for i = 0..=254: twice what the sampler returns for the word with layer i and u = 1/2
/// (accepted when X[i] / 2 < X[i + 1]; `None` if a layer is not, or draws again).
fn read_widths() -> Option<[f64; FAST_LAYERS + 1]> {
    /// Hands out one word, then counts further requests, answered with a word the fast path
    /// accepts (layer 1, u = 0), so that a sampler that does not accept the first ends.
    struct One(u64, usize);
    impl RngCore for One {
        fn next_u32(&mut self) -> u32 {
            (self.next_u64() >> 32) as u32
        }
        fn next_u64(&mut self) -> u64 {
            self.1 += 1;
            if self.1 == 1 {
                self.0
            } else {
                (1u64 << 63) | 1
            }
        }
        fn fill_bytes(&mut self, dest: &mut [u8]) {
            dest.fill(0);
            self.1 += 1;
        }
    }
    let mut x = [0.0; FAST_LAYERS + 1];
    for (i, xi) in x.iter_mut().enumerate() {
        // Top bits 11 then zeros: (bits >> 12) as a float in [2, 4) is 3.5, u = 1/2.
        let mut one = One((3u64 << 62) | i as u64, 0);
        let half: f64 = StandardNormal.sample(&mut one);
        if one.1 != 1 || !(half.is_finite() && half > 0.0) {
            return None;
        }
        *xi = 2.0 * half;
    }
    Some(x)
}

/// Whether the lanes `make` seeds give the crates' numbers: seeding and 20,000 draws of four
/// streams (of every seed below) against `Xoshiro256PlusPlus::seed_from_u64` and
/// `StandardNormal`, then the next word of each stream.
fn agrees_with_the_crates(make: impl Fn([u64; LANES]) -> NormalLanes) -> bool {
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;
    for base in [0u64, 1, 0x9e37_79b9_7f4a_7c15, u64::MAX - 3] {
        let seeds: [u64; LANES] = std::array::from_fn(|j| base.wrapping_add(j as u64 * 7919));
        let mut lanes = make(seeds);
        let mut crates = seeds.map(Xoshiro256PlusPlus::seed_from_u64);
        for _ in 0..5000 {
            let z = lanes.normals();
            for (zj, rng) in z.0.iter().zip(&mut crates) {
                let want: f64 = StandardNormal.sample(rng);
                if zj.to_bits() != want.to_bits() {
                    return false;
                }
            }
        }
        let words = step(&mut lanes.s);
        if words
            .iter()
            .zip(&mut crates)
            .any(|(w, rng)| *w != rng.next_u64())
        {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The lanes are available here, and draw each stream's numbers over a long run (about
    /// 2% of draws leave the fast path, so the crate's slow path and tail are reached many
    /// times), for seeds the check did not use.
    #[test]
    fn each_lane_draws_the_crates_numbers_for_its_stream() {
        let seeds = [42, 43, 1 << 40, 12345678901];
        let mut lanes = NormalLanes::seeded(seeds).expect("the lanes agree with the crates");
        let mut crates = seeds.map(Xoshiro256PlusPlus::seed_from_u64);
        let mut tail = 0;
        for _ in 0..200_000 {
            let z = lanes.normals();
            for (zj, rng) in z.0.iter().zip(&mut crates) {
                let want: f64 = StandardNormal.sample(rng);
                assert_eq!(zj.to_bits(), want.to_bits());
                tail += usize::from(want.abs() > 3.5);
            }
        }
        // P(|z| > 3.5) = 4.65e-4: about 372 of 800,000, the tail (i = 0) reached.
        assert!(tail > 250, "{tail} draws beyond 3.5");
    }

    /// The portable fill (taken on a processor without AVX2) and the AVX2 fill both draw the
    /// crate's numbers, in blocks of every length.
    #[test]
    fn both_fills_draw_the_crates_numbers() {
        let x = checked_table().expect("available");
        let seeds = [7, 8, 9, 10];
        let mut crates = seeds.map(Xoshiro256PlusPlus::seed_from_u64);
        let mut portable = NormalLanes::unchecked(seeds, x);
        let mut dispatched = portable.clone();
        for len in [1usize, 2, 7, 64, 1000] {
            let mut a = vec![F64x4::default(); len];
            let mut b = a.clone();
            fill_portable(&mut portable, &mut a);
            dispatched.fill(&mut b);
            for (za, zb) in a.iter().zip(&b) {
                for ((va, vb), rng) in za.0.iter().zip(zb.0).zip(&mut crates) {
                    let want: f64 = StandardNormal.sample(rng);
                    assert_eq!(
                        (va.to_bits(), vb.to_bits()),
                        (want.to_bits(), want.to_bits())
                    );
                }
            }
        }
    }

    /// One step back undoes one step, for states of every kind.
    #[test]
    fn unstep_undoes_a_step() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for _ in 0..1000 {
            let s: [u64; 4] = std::array::from_fn(|_| rng.next_u64());
            let mut lane = Lane(s);
            lane.next_u64();
            assert_eq!(unstep(lane.0), s);
        }
    }

    /// The widths read from the sampler are rand_distr's: decreasing from about 3.9 (the
    /// base strip's virtual width) through R = 3.654 (Marsaglia and Tsang's 256 layers).
    #[test]
    fn the_widths_read_from_the_sampler_are_a_ziggurat() {
        let x = checked_table().expect("available");
        assert!((x[0] - 3.9107579595).abs() < 1e-9, "{}", x[0]);
        assert!((x[1] - 3.6541528853).abs() < 1e-9, "{}", x[1]);
        assert!(x[..=FAST_LAYERS].windows(2).all(|w| w[1] < w[0]));
        assert_eq!(x[FAST_LAYERS + 1..], [0.0, 0.0]);
    }

    /// The check fails for lanes that draw otherwise: one bit of one stream's state, a
    /// layer width one ulp off, a generator step of another rotation.
    #[test]
    fn the_check_fails_for_lanes_that_draw_otherwise() {
        let x = checked_table().expect("available");
        assert!(agrees_with_the_crates(|seeds| NormalLanes::unchecked(
            seeds, x
        )));
        assert!(!agrees_with_the_crates(|seeds| {
            let mut lanes = NormalLanes::unchecked(seeds, x);
            lanes.s[1][2] ^= 1 << 40;
            lanes
        }));
        let mut off = *x;
        off[17] = off[17].next_up();
        let off: &'static Widths = Box::leak(Box::new(off));
        assert!(!agrees_with_the_crates(|seeds| NormalLanes::unchecked(
            seeds, off
        )));
    }
}
