//! Arithmetic that runs on one ray or on a block of eight: the shading formulas ([`crate::shade`])
//! are written once over [`Real`], and instantiated with `f32` for a single ray and with [`F8`]
//! for the 8 lanes of a 4 x 2 pixel block, where the compiler turns each operation into one AVX
//! instruction (the renderer calls the block code through a function compiled for AVX2).
//!
//! Every operation of [`F8`] is the `f32` operation lane by lane (IEEE add, subtract, multiply,
//! divide and square root are correctly rounded, and Rust never fuses a multiply with an add), so
//! a lane computes exactly what a single ray does, bit for bit. Branches become selects: both
//! sides are computed and the mask picks, so a lane never sees the other side's value.

use glam::Vec3;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Lanes of a block.
pub const LANES: usize = 8;

/// A mask: which lanes a condition holds in.
pub trait Mask: Copy + BitAnd<Output = Self> + BitOr<Output = Self> + Not<Output = Self> {
    fn any(self) -> bool;
}

/// A number, or lanes of numbers, with the operations the shading formulas use.
pub trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    type Mask: Mask;
    fn splat(v: f32) -> Self;
    fn sqrt(self) -> Self;
    /// `f32::max` lane by lane (a NaN loses to a number).
    fn max(self, o: Self) -> Self;
    /// `f32::powf` in the lanes of `m`, 1 elsewhere (pow is costly: idle lanes skip it).
    fn powf_in(self, e: Self, m: Self::Mask) -> Self;
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    fn eq(self, o: Self) -> Self::Mask;
    fn is_finite(self) -> Self::Mask;
    /// `a` where `m` holds, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
}

impl Mask for bool {
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
}

impl Real for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    #[inline(always)]
    fn powf_in(self, e: Self, m: bool) -> Self {
        if m { self.powf(e) } else { 1.0 }
    }
    #[inline(always)]
    fn lt(self, o: Self) -> bool {
        self < o
    }
    #[inline(always)]
    fn le(self, o: Self) -> bool {
        self <= o
    }
    #[inline(always)]
    fn gt(self, o: Self) -> bool {
        self > o
    }
    #[inline(always)]
    fn ge(self, o: Self) -> bool {
        self >= o
    }
    #[inline(always)]
    fn eq(self, o: Self) -> bool {
        self == o
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m { a } else { b }
    }
}

/// Eight lanes of `f32`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F8(pub [f32; LANES]);

/// Eight lanes of a condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct M8(pub [bool; LANES]);

impl F8 {
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        F8(std::array::from_fn(|i| f(self.0[i])))
    }
    #[inline(always)]
    fn zip(self, o: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        F8(std::array::from_fn(|i| f(self.0[i], o.0[i])))
    }
    #[inline(always)]
    fn test(self, o: F8, f: impl Fn(f32, f32) -> bool) -> M8 {
        M8(std::array::from_fn(|i| f(self.0[i], o.0[i])))
    }
    /// Lane `i` of each of eight values.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f32) -> F8 {
        F8(std::array::from_fn(f))
    }
}

impl M8 {
    pub const NONE: M8 = M8([false; LANES]);
    #[inline(always)]
    pub fn count(self) -> usize {
        self.0.iter().filter(|&&b| b).count()
    }
}

impl Mask for M8 {
    #[inline(always)]
    fn any(self) -> bool {
        self.0.contains(&true)
    }
}

impl BitAnd for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitand(self, o: M8) -> M8 {
        M8(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
}

impl BitOr for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitor(self, o: M8) -> M8 {
        M8(std::array::from_fn(|i| self.0[i] | o.0[i]))
    }
}

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        M8(self.0.map(|b| !b))
    }
}

macro_rules! f8_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                self.zip(o, |a, b| a $op b)
            }
        }
    };
}
f8_op!(Add, add, +);
f8_op!(Sub, sub, -);
f8_op!(Mul, mul, *);
f8_op!(Div, div, /);

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|a| -a)
    }
}

impl Real for F8 {
    type Mask = M8;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        F8([v; LANES])
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.zip(o, f32::max)
    }
    #[inline(always)]
    fn powf_in(self, e: Self, m: M8) -> Self {
        F8(std::array::from_fn(|i| if m.0[i] { self.0[i].powf(e.0[i]) } else { 1.0 }))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> M8 {
        self.test(o, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, o: Self) -> M8 {
        self.test(o, |a, b| a <= b)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> M8 {
        self.test(o, |a, b| a > b)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> M8 {
        self.test(o, |a, b| a >= b)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> M8 {
        self.test(o, |a, b| a == b)
    }
    #[inline(always)]
    fn is_finite(self) -> M8 {
        M8(self.0.map(f32::is_finite))
    }
    #[inline(always)]
    fn select(m: M8, a: Self, b: Self) -> Self {
        F8(std::array::from_fn(|i| if m.0[i] { a.0[i] } else { b.0[i] }))
    }
}

/// A vector of three [`Real`]s, with glam's `Vec3` operations in glam's order of operations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct V3<R> {
    pub x: R,
    pub y: R,
    pub z: R,
}

/// Eight vectors, one per lane.
pub type V8 = V3<F8>;

impl<R: Real> V3<R> {
    #[inline(always)]
    pub fn new(x: R, y: R, z: R) -> Self {
        Self { x, y, z }
    }
    /// The same vector in every lane.
    #[inline(always)]
    pub fn splat(v: Vec3) -> Self {
        Self::new(R::splat(v.x), R::splat(v.y), R::splat(v.z))
    }
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(Vec3::ZERO)
    }
    #[inline(always)]
    pub fn dot(self, o: Self) -> R {
        (self.x * o.x) + (self.y * o.y) + (self.z * o.z)
    }
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        Self::new(self.y * o.z - o.y * self.z, self.z * o.x - o.z * self.x, self.x * o.y - o.x * self.y)
    }
    #[inline(always)]
    pub fn length(self) -> R {
        self.dot(self).sqrt()
    }
    /// `glam::Vec3::normalize`: no check.
    #[inline(always)]
    pub fn normalize(self) -> Self {
        self * (R::splat(1.0) / self.length())
    }
    /// `glam::Vec3::try_normalize`: the unit vector, and where it exists (the inverse length is
    /// finite and positive).
    #[inline(always)]
    pub fn try_normalize(self) -> (Self, R::Mask) {
        let rcp = R::splat(1.0) / self.length();
        (self * rcp, rcp.is_finite() & rcp.gt(R::splat(0.0)))
    }
    /// `glam::Vec3::normalize_or_zero`.
    #[inline(always)]
    pub fn normalize_or_zero(self) -> Self {
        let (n, ok) = self.try_normalize();
        Self::select(ok, n, Self::zero())
    }
    /// Component by component (`glam::Vec3 * Vec3`).
    #[inline(always)]
    pub fn mul(self, o: Self) -> Self {
        Self::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
    #[inline(always)]
    pub fn select(m: R::Mask, a: Self, b: Self) -> Self {
        Self::new(R::select(m, a.x, b.x), R::select(m, a.y, b.y), R::select(m, a.z, b.z))
    }
    /// Where every component is zero.
    #[inline(always)]
    pub fn is_zero(self) -> R::Mask {
        let z = R::splat(0.0);
        self.x.eq(z) & self.y.eq(z) & self.z.eq(z)
    }
}

impl<R: Real> Add for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl<R: Real> Sub for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl<R: Real> Neg for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

/// `v * s`, each component times the scalar (`glam`'s `s * v` and `v * s` alike: IEEE
/// multiplication commutes).
impl<R: Real> Mul<R> for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, s: R) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}

impl From<Vec3> for V3<f32> {
    #[inline(always)]
    fn from(v: Vec3) -> Self {
        Self::new(v.x, v.y, v.z)
    }
}

impl From<V3<f32>> for Vec3 {
    #[inline(always)]
    fn from(v: V3<f32>) -> Self {
        Vec3::new(v.x, v.y, v.z)
    }
}

impl V8 {
    /// Lane `i`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }
    /// From a vector per lane.
    #[inline(always)]
    pub fn from_lanes(f: impl Fn(usize) -> Vec3) -> Self {
        let v: [Vec3; LANES] = std::array::from_fn(f);
        Self::new(F8::from_fn(|i| v[i].x), F8::from_fn(|i| v[i].y), F8::from_fn(|i| v[i].z))
    }
    /// From three arrays of lanes, as [`crate::packet::Rays`] stores origins and directions.
    #[inline(always)]
    pub fn from_arrays(a: &[[f32; LANES]; 3]) -> Self {
        Self::new(F8(a[0]), F8(a[1]), F8(a[2]))
    }
    #[inline(always)]
    pub fn to_arrays(self) -> [[f32; LANES]; 3] {
        [self.x.0, self.y.0, self.z.0]
    }
}
