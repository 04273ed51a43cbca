//! Four numbers side by side: the four trials of a runner block in the lanes of one AVX2
//! register ([`F64x4`]), and the scalar interface ([`Real`]) that lets the fixed-size kernels
//! of [`crate::linalg::fixed`] run on one trial (`f64`) or on four at once (`F64x4`) with one
//! source. Every operation of `F64x4` is the IEEE operation of `f64` lane by lane, so lane j
//! of a kernel's result is, bit for bit, what the kernel gives on lane j's numbers alone.
use std::ops::{Add, Mul, Neg, Sub};

/// Four `f64`, one per lane. Aligned to a register so that loads and stores are whole.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[repr(C, align(32))]
pub struct F64x4(pub [f64; 4]);

impl F64x4 {
    /// Lanes of an `F64x4`.
    pub const LANES: usize = 4;

    /// Every lane `v`.
    #[inline(always)]
    pub const fn splat(v: f64) -> Self {
        Self([v; 4])
    }

    /// `f` of every lane.
    #[inline(always)]
    pub fn map(self, f: impl Fn(f64) -> f64) -> Self {
        Self([f(self.0[0]), f(self.0[1]), f(self.0[2]), f(self.0[3])])
    }

    /// `f` of every pair of lanes.
    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self([
            f(self.0[0], o.0[0]),
            f(self.0[1], o.0[1]),
            f(self.0[2], o.0[2]),
            f(self.0[3], o.0[3]),
        ])
    }

    /// 1 where `self <= bound`, else 0 (NaN: 0), lane by lane.
    #[inline(always)]
    pub fn flag_le(self, bound: f64) -> Self {
        self.map(|v| f64::from(u8::from(v <= bound)))
    }

    /// Whether every lane is finite.
    #[inline(always)]
    pub fn all_finite(self) -> bool {
        self.0.iter().fold(true, |a, v| a & v.is_finite())
    }
}

impl Add for F64x4 {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }
}

impl Sub for F64x4 {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }
}

impl Mul for F64x4 {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
}

impl Neg for F64x4 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
}

/// What the fixed-size kernels need of a number: `f64` itself, or four of them in lanes.
/// The operations with a matrix entry (`f64`) keep the operand order of the scalar code, so
/// that even the payload of a NaN is the scalar code's.
pub trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self>
{
    /// +0 in every lane.
    const ZERO: Self;
    /// `a * x`, the matrix entry `a` the left operand.
    fn scaled(a: f64, x: Self) -> Self;
    /// `self * a`, the matrix entry `a` the right operand.
    fn times(self, a: f64) -> Self;
    /// `self / d`.
    fn over(self, d: f64) -> Self;
    /// `f` of every lane (of the one number of an `f64`).
    fn each(self, f: impl Fn(f64) -> f64) -> Self;
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    #[inline(always)]
    fn scaled(a: f64, x: Self) -> Self {
        a * x
    }
    #[inline(always)]
    fn times(self, a: f64) -> Self {
        self * a
    }
    #[inline(always)]
    fn over(self, d: f64) -> Self {
        self / d
    }
    #[inline(always)]
    fn each(self, f: impl Fn(f64) -> f64) -> Self {
        f(self)
    }
}

impl Real for F64x4 {
    const ZERO: Self = F64x4::splat(0.0);
    #[inline(always)]
    fn scaled(a: f64, x: Self) -> Self {
        x.map(|v| a * v)
    }
    #[inline(always)]
    fn times(self, a: f64) -> Self {
        self.map(|v| v * a)
    }
    #[inline(always)]
    fn over(self, d: f64) -> Self {
        self.map(|v| v / d)
    }
    #[inline(always)]
    fn each(self, f: impl Fn(f64) -> f64) -> Self {
        self.map(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::fixed;
    use rand::{Rng, SeedableRng};

    /// Four numbers of every kind: ordinary, tiny, huge, zero of both signs, NaN and infinity
    /// turn up among the lanes.
    fn lanes(rng: &mut impl Rng) -> F64x4 {
        F64x4(std::array::from_fn(|_| match rng.random_range(0..12) {
            0 => 0.0,
            1 => -0.0,
            2 => 1e-300 * rng.random_range(-1.0..1.0),
            3 => 1e300 * rng.random_range(-1.0..1.0),
            4 if rng.random_bool(0.1) => f64::NAN,
            5 if rng.random_bool(0.1) => f64::INFINITY,
            _ => rng.random_range(-10.0..10.0),
        }))
    }

    /// Lane `j` of each entry.
    fn lane<const N: usize>(v: &[F64x4; N], j: usize) -> [f64; N] {
        v.map(|x| x.0[j])
    }

    /// Bits, so that NaNs compare (payload included) and -0 differs from +0.
    fn bits<const N: usize>(v: [f64; N]) -> [u64; N] {
        v.map(f64::to_bits)
    }

    /// The kernels the all-data KF runs side by side give, in every lane, the bits they give
    /// on that lane's numbers alone: a matrix times a vector, the Cholesky solve, a sensor's
    /// columns times its reading as it arrives, and the NEES by a factor (a zero diagonal
    /// refused for all four lanes at once).
    #[test]
    fn every_lane_is_the_scalar_kernel_on_its_numbers() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
        for round in 0..400 {
            let a: [f64; 9] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
            // A lower factor with a positive diagonal (the upper triangle left dirty).
            let mut l = a;
            for i in 0..3 {
                l[i * 3 + i] = rng.random_range(0.1..3.0);
            }
            if round % 50 == 0 {
                l[4] = 0.0;
            }
            let x: [F64x4; 3] = std::array::from_fn(|_| lanes(&mut rng));
            let z: [F64x4; 2] = std::array::from_fn(|_| lanes(&mut rng));
            let y: [F64x4; 3] = fixed::mat_vec(&a, &x);
            let mut solved = x;
            fixed::chol_solve_array(&l, &mut solved);
            let sent = |v: f64| v as f32 as f64;
            let cols: [F64x4; 3] = fixed::mat_vec_cols_by(&a[..6], &z, |v: F64x4| v.each(sent));
            let nees = fixed::mahalanobis_factored_array(x, &l);
            for j in 0..4 {
                let xj = lane(&x, j);
                assert_eq!(
                    bits(lane(&y, j)),
                    bits(fixed::mat_vec::<3, 3, f64>(&a, &xj))
                );
                let mut sj = xj;
                fixed::chol_solve_array(&l, &mut sj);
                assert_eq!(bits(lane(&solved, j)), bits(sj));
                let cj: [f64; 3] = fixed::mat_vec_cols_by(&a[..6], &lane(&z, j), sent);
                assert_eq!(bits(lane(&cols, j)), bits(cj));
                let nj = fixed::mahalanobis_factored_array(xj, &l);
                assert_eq!(nees.map(|v| v.0[j].to_bits()), nj.map(f64::to_bits));
            }
            assert_eq!(nees.is_none(), l[4] == 0.0, "round {round}");
        }
    }

    /// The flags and the finiteness check, lane by lane (NaN is never within a bound).
    #[test]
    fn flags_and_finiteness_are_per_lane() {
        let v = F64x4([1.0, 2.0, f64::NAN, -0.0]);
        assert_eq!(v.flag_le(1.0).0, [1.0, 0.0, 0.0, 1.0]);
        assert!(!v.all_finite());
        assert!(F64x4([1.0, -2.0, 0.0, 1e308]).all_finite());
        assert!(!F64x4([1.0, -2.0, f64::NEG_INFINITY, 1e308]).all_finite());
    }
}
