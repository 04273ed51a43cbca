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
