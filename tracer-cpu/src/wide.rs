//! Arithmetic that runs on one ray or on a block of eight: the shading formulas ([`crate::shade`])
//! are written once over [`Real`], and instantiated with `f32` for a single ray and with 8-lane
//! types ([`Lanes`]) for the 4 x 2 pixel blocks the renderer shades: `Avx8` (one AVX instruction
//! per operation, used where the CPU has AVX2) or [`F8`] (plain arrays, anywhere).
//!
//! Every lane operation is the `f32` operation (IEEE add, subtract, multiply, divide and square
//! root are correctly rounded, and Rust never fuses a multiply with an add), so a lane computes
//! exactly what a single ray does, bit for bit. Branches become selects: both sides are computed
//! and the mask picks, so a lane never sees the other side's value. `max` is defined as
//! `if a > b { a } else { b }` everywhere (what the x86 `max` instructions compute), so that no
//! lane type depends on how `f32::max` breaks a tie between +0 and -0.
//!
//! A closure is compiled with the target features of the function that defines it, not of the
//! AVX2 function it is finally inlined into, so code generic over [`Lanes`] never performs a lane
//! operation inside a closure (it would become a call to an out-of-line intrinsic).

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
    /// `if self > o { self } else { o }`: `f32::max`, except that a tie of +0 and -0 gives `o`
    /// and a NaN `o` is kept.
    fn max(self, o: Self) -> Self;
    /// `if self < o { self } else { o }` (what the x86 `min` instructions compute): a NaN `o`
    /// is kept.
    fn min(self, o: Self) -> Self;
    /// `render_spec::phong_pow` in the lanes of `m`, 1 elsewhere (none computed when no lane is live).
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
        if self > o { self } else { o }
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        if self < o { self } else { o }
    }
    #[inline(always)]
    fn powf_in(self, e: Self, m: bool) -> Self {
        if m { render_spec::phong_pow(self, e) } else { 1.0 }
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

/// Eight lanes: what the block shading needs beyond [`Real`] (moving values in and out of lanes).
pub trait Lanes: Real {
    fn from_array(a: [f32; LANES]) -> Self;
    fn to_array(self) -> [f32; LANES];
    fn mask(b: [bool; LANES]) -> Self::Mask;
    fn bools(m: Self::Mask) -> [bool; LANES];
    /// Each lane rounded toward zero to an integer; only for lanes well inside the `i32` range.
    fn trunc(self) -> [i32; LANES];
    /// Lanes where `m` holds.
    #[inline(always)]
    fn count(m: Self::Mask) -> usize {
        Self::bools(m).iter().filter(|&&b| b).count()
    }
    #[inline(always)]
    fn from_fn(f: impl FnMut(usize) -> f32) -> Self {
        Self::from_array(std::array::from_fn(f))
    }
    /// [`crate::geometry::offset_origin`] lane by lane.
    #[inline(always)]
    fn offset_origin(p: V3<Self>, n: V3<Self>) -> V3<Self> {
        let (p, n) = (p.to_arrays(), n.to_arrays());
        let mut o = [[0.0; LANES]; 3];
        for i in 0..LANES {
            let v = |a: &[[f32; LANES]; 3]| Vec3::new(a[0][i], a[1][i], a[2][i]);
            let r = crate::geometry::offset_origin(v(&p), v(&n));
            (o[0][i], o[1][i], o[2][i]) = (r.x, r.y, r.z);
        }
        V3::from_arrays(&o)
    }
    /// `a` in the lanes where `m` holds, else 0.
    #[inline(always)]
    fn keep_u32(m: Self::Mask, a: &[u32; LANES]) -> [u32; LANES] {
        let m = Self::bools(m);
        std::array::from_fn(|i| if m[i] { a[i] } else { 0 })
    }
    /// The pixel coordinates of a 4 x 2 block whose top-left pixel is (`x0`, `y0`), as floats:
    /// `x0 + i % 4` and `y0 + i / 4` in lane `i` (integers below 2^31, rounded to the nearest
    /// float as `as f32` rounds them).
    #[inline(always)]
    fn block_xy(x0: u32, y0: u32) -> (Self, Self) {
        (Self::from_fn(|i| (x0 + i as u32 % 4) as f32), Self::from_fn(|i| (y0 + i as u32 / 4) as f32))
    }
    /// The four components of a 16-byte row per lane (a triangle's corner with its padding word,
    /// a material's row).
    #[inline(always)]
    fn gather4(v: [&[f32; 4]; LANES]) -> [Self; 4] {
        let mut a = [[0.0; LANES]; 4];
        for i in 0..LANES {
            for (c, a) in a.iter_mut().enumerate() {
                a[i] = v[i][c];
            }
        }
        [Self::from_array(a[0]), Self::from_array(a[1]), Self::from_array(a[2]), Self::from_array(a[3])]
    }
    /// The 8-bit colours of the lanes, from red, green and blue already in `[0, 256)`: each
    /// truncated (`as u8`), laid out as the block's two rows of four pixels (lanes 0-3 and 4-7),
    /// three bytes per pixel in bytes 0..12 of each row.
    #[inline(always)]
    fn rgb_rows(r: Self, g: Self, b: Self) -> [[u8; 16]; 2] {
        let (r, g, b) = (r.trunc(), g.trunc(), b.trunc());
        let mut rows = [[0u8; 16]; 2];
        for i in 0..LANES {
            let row = &mut rows[i / 4][3 * (i % 4)..3 * (i % 4) + 3];
            row.copy_from_slice(&[r[i] as u8, g[i] as u8, b[i] as u8]);
        }
        rows
    }
    /// The first three components of a 16-byte vector per lane (triangle edges, vertex normals).
    #[inline(always)]
    fn gather3(v: [&[f32; 4]; LANES]) -> V3<Self> {
        let mut a = [[0.0; LANES]; 3];
        for i in 0..LANES {
            (a[0][i], a[1][i], a[2][i]) = (v[i][0], v[i][1], v[i][2]);
        }
        V3::from_arrays(&a)
    }
}

/// Eight lanes of `f32` in a plain array: the lane type for CPUs without AVX2.
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
}

impl Lanes for F8 {
    #[inline(always)]
    fn from_array(a: [f32; LANES]) -> Self {
        F8(a)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; LANES] {
        self.0
    }
    #[inline(always)]
    fn mask(b: [bool; LANES]) -> M8 {
        M8(b)
    }
    #[inline(always)]
    fn bools(m: M8) -> [bool; LANES] {
        m.0
    }
    #[inline(always)]
    fn trunc(self) -> [i32; LANES] {
        self.0.map(|x| x as i32)
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
        self.zip(o, <f32 as Real>::max)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.zip(o, <f32 as Real>::min)
    }
    #[inline(always)]
    fn powf_in(self, e: Self, m: M8) -> Self {
        F8(std::array::from_fn(|i| if m.0[i] { render_spec::phong_pow(self.0[i], e.0[i]) } else { 1.0 }))
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
    pub fn mul_each(self, o: Self) -> Self {
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

impl<L: Lanes> V3<L> {
    /// From a vector per lane (`f` must not touch lanes itself: see the module's note on
    /// closures).
    #[inline(always)]
    pub fn from_lanes(f: impl Fn(usize) -> Vec3) -> Self {
        let v: [Vec3; LANES] = std::array::from_fn(f);
        Self::from_arrays(&[v.map(|v| v.x), v.map(|v| v.y), v.map(|v| v.z)])
    }
    /// From three arrays of lanes, as [`crate::packet::Rays`] stores origins and directions.
    #[inline(always)]
    pub fn from_arrays(a: &[[f32; LANES]; 3]) -> Self {
        Self::new(L::from_array(a[0]), L::from_array(a[1]), L::from_array(a[2]))
    }
    #[inline(always)]
    pub fn to_arrays(self) -> [[f32; LANES]; 3] {
        [self.x.to_array(), self.y.to_array(), self.z.to_array()]
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use avx::{Avx8, bools_of};

/// Lanes in AVX registers. Only code compiled for AVX2 and entered after `packet::available()`
/// may use them: each operation is an AVX intrinsic.
#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{LANES, Lanes, Mask, Real, V3};
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

    #[derive(Clone, Copy, Debug)]
    pub struct Avx8(__m256);

    /// All ones in the lanes where the condition holds.
    #[derive(Clone, Copy, Debug)]
    pub struct AvxMask(__m256);

    /// The lanes whose sign bit is set in `m` (what `_mm256_movemask_ps` reads), as 8 bools
    /// made in a register and stored at once. Written byte by byte, they stalled the next
    /// 8-byte read of them (a packet's live lanes, [`crate::packet::Rays::count`], a mask of the
    /// hits): a load that spans several stores is not forwarded from them and waits until they
    /// reach the cache, at each stage of every block.
    #[inline(always)]
    pub(crate) fn bools_of(m: __m256) -> [bool; LANES] {
        // SAFETY: register arithmetic on a CPU with AVX2 (see the module's documentation); the
        // eight bytes are each 0 or 1, valid bools.
        unsafe {
            let ones = _mm256_srai_epi32(_mm256_castps_si256(m), 31);
            let words = _mm_packs_epi32(_mm256_castsi256_si128(ones), _mm256_extracti128_si256(ones, 1));
            let bytes = _mm_and_si128(_mm_packs_epi16(words, words), _mm_set1_epi8(1));
            std::mem::transmute::<u64, [bool; LANES]>(_mm_cvtsi128_si64(bytes) as u64)
        }
    }

    // SAFETY (every `unsafe` block below): register arithmetic on a CPU with AVX2, which the
    // callers of these types guarantee (see the type's documentation).
    macro_rules! op {
        ($tr:ident, $f:ident, $intr:ident) => {
            impl $tr for Avx8 {
                type Output = Avx8;
                #[inline(always)]
                fn $f(self, o: Avx8) -> Avx8 {
                    Avx8(unsafe { $intr(self.0, o.0) })
                }
            }
        };
    }
    op!(Add, add, _mm256_add_ps);
    op!(Sub, sub, _mm256_sub_ps);
    op!(Mul, mul, _mm256_mul_ps);
    op!(Div, div, _mm256_div_ps);

    impl Neg for Avx8 {
        type Output = Avx8;
        #[inline(always)]
        fn neg(self) -> Avx8 {
            Avx8(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
        }
    }

    impl BitAnd for AvxMask {
        type Output = AvxMask;
        #[inline(always)]
        fn bitand(self, o: AvxMask) -> AvxMask {
            AvxMask(unsafe { _mm256_and_ps(self.0, o.0) })
        }
    }

    impl BitOr for AvxMask {
        type Output = AvxMask;
        #[inline(always)]
        fn bitor(self, o: AvxMask) -> AvxMask {
            AvxMask(unsafe { _mm256_or_ps(self.0, o.0) })
        }
    }

    impl Not for AvxMask {
        type Output = AvxMask;
        #[inline(always)]
        fn not(self) -> AvxMask {
            AvxMask(unsafe { _mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) })
        }
    }

    impl Mask for AvxMask {
        #[inline(always)]
        fn any(self) -> bool {
            unsafe { _mm256_movemask_ps(self.0) != 0 }
        }
    }

    impl Avx8 {
        #[inline(always)]
        fn cmp<const P: i32>(self, o: Avx8) -> AvxMask {
            AvxMask(unsafe { _mm256_cmp_ps::<P>(self.0, o.0) })
        }
    }

    impl Real for Avx8 {
        type Mask = AvxMask;
        #[inline(always)]
        fn splat(v: f32) -> Self {
            Avx8(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            Avx8(unsafe { _mm256_sqrt_ps(self.0) })
        }
        /// `maxps(a, b)` is `a > b ? a : b`, exactly [`Real::max`].
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            Avx8(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        /// `minps(a, b)` is `a < b ? a : b`, exactly [`Real::min`].
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Avx8(unsafe { _mm256_min_ps(self.0, o.0) })
        }
        /// `render_spec::phong_pow` eight lanes at a time: the same operations in the same order,
        /// its branches as selects (each IEEE operation rounds alike in a lane and in a scalar).
        #[inline(always)]
        fn powf_in(self, e: Self, m: AvxMask) -> Self {
            if !m.any() {
                return Self::splat(1.0);
            }
            Self::select(m, pow(self, e), Self::splat(1.0))
        }
        // Ordered, quiet comparisons: false where either side is NaN, as Rust's are.
        #[inline(always)]
        fn lt(self, o: Self) -> AvxMask {
            self.cmp::<_CMP_LT_OQ>(o)
        }
        #[inline(always)]
        fn le(self, o: Self) -> AvxMask {
            self.cmp::<_CMP_LE_OQ>(o)
        }
        #[inline(always)]
        fn gt(self, o: Self) -> AvxMask {
            self.cmp::<_CMP_GT_OQ>(o)
        }
        #[inline(always)]
        fn ge(self, o: Self) -> AvxMask {
            self.cmp::<_CMP_GE_OQ>(o)
        }
        #[inline(always)]
        fn eq(self, o: Self) -> AvxMask {
            self.cmp::<_CMP_EQ_OQ>(o)
        }
        #[inline(always)]
        fn is_finite(self) -> AvxMask {
            let abs = Avx8(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) });
            abs.lt(Avx8::splat(f32::INFINITY))
        }
        #[inline(always)]
        fn select(m: AvxMask, a: Self, b: Self) -> Self {
            Avx8(unsafe { _mm256_blendv_ps(b.0, a.0, m.0) })
        }
    }

    /// [`render_spec::phong_pow`] in every lane.
    #[inline(always)]
    fn pow(x: Avx8, n: Avx8) -> Avx8 {
        use render_spec::constants::{POW_EXP2, POW_LOG2};
        #[inline(always)]
        fn int(v: i32) -> __m256i {
            unsafe { _mm256_set1_epi32(v) }
        }
        #[inline(always)]
        fn as_f32(v: __m256i) -> Avx8 {
            Avx8(unsafe { _mm256_castsi256_ps(v) })
        }
        /// `2^v` for integers `v` of the normal range, as the bits of a float.
        #[inline(always)]
        fn scale(v: __m256i) -> Avx8 {
            as_f32(unsafe { _mm256_slli_epi32::<23>(_mm256_add_epi32(v, int(127))) })
        }
        unsafe {
            // x NaN or <= 0: 0.
            let none = !x.gt(Avx8::splat(0.0));
            // log2(x): a subnormal is scaled into the normal range first (exact).
            let sub = x.lt(Avx8::splat(f32::MIN_POSITIVE));
            let xs = Avx8::select(sub, x * Avx8::splat(18446744073709551616.0), x);
            let e = _mm256_and_si256(int(-64), _mm256_castps_si256(sub.0));
            let bits = _mm256_castps_si256(xs.0);
            let e = _mm256_add_epi32(e, _mm256_sub_epi32(_mm256_srli_epi32::<23>(bits), int(127)));
            let m = as_f32(_mm256_or_si256(_mm256_and_si256(bits, int(0x007f_ffff)), int(0x3f80_0000)));
            let big = m.gt(Avx8::splat(std::f32::consts::SQRT_2));
            let m = Avx8::select(big, m * Avx8::splat(0.5), m);
            // `big` is all ones (-1) where it holds: subtracting it adds 1.
            let e = _mm256_sub_epi32(e, _mm256_castps_si256(big.0));
            let t = m - Avx8::splat(1.0);
            let mut p = Avx8::splat(POW_LOG2[8]);
            for k in (0..8).rev() {
                p = p * t + Avx8::splat(POW_LOG2[k]);
            }
            let y = n * (t * p + Avx8(_mm256_cvtepi32_ps(e)));
            // exp2(y).
            let i = Avx8(_mm256_floor_ps((y + Avx8::splat(0.5)).0));
            let f = y - i;
            let mut q = Avx8::splat(POW_EXP2[6]);
            for k in (0..6).rev() {
                q = q * f + Avx8::splat(POW_EXP2[k]);
            }
            // 2^i in two factors, so that results below the normal range come out subnormal.
            let i = _mm256_cvttps_epi32(i.0);
            let small = _mm256_cmpgt_epi32(int(-126), i);
            let a = _mm256_add_epi32(i, _mm256_and_si256(small, int(64)));
            let b = _mm256_and_si256(small, int(-64));
            let r = q * scale(a) * scale(b);
            let r = Avx8::select(y.gt(Avx8::splat(128.0)), Avx8::splat(f32::INFINITY), r);
            let r = Avx8::select(y.lt(Avx8::splat(-150.0)), Avx8::splat(0.0), r);
            let r = Avx8::select(y.eq(Avx8::splat(0.0)), Avx8::splat(1.0), r);
            Avx8::select(none, Avx8::splat(0.0), r)
        }
    }

    impl Lanes for Avx8 {
        #[inline(always)]
        fn from_array(a: [f32; LANES]) -> Self {
            Avx8(unsafe { _mm256_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn to_array(self) -> [f32; LANES] {
            let mut a = [0f32; LANES];
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        fn mask(b: [bool; LANES]) -> AvxMask {
            let bytes = u64::from_le_bytes(b.map(u8::from));
            unsafe {
                let wide = _mm256_cvtepu8_epi32(_mm_set_epi64x(0, bytes as i64));
                AvxMask(_mm256_castsi256_ps(_mm256_cmpgt_epi32(wide, _mm256_setzero_si256())))
            }
        }
        #[inline(always)]
        fn bools(m: AvxMask) -> [bool; LANES] {
            bools_of(m.0)
        }
        /// `offset_origin`'s integer step and float step, 8-wide.
        #[inline(always)]
        fn offset_origin(p: V3<Self>, n: V3<Self>) -> V3<Self> {
            #[inline(always)]
            fn axis(p: __m256, n: __m256) -> __m256 {
                unsafe {
                    // `(n * 256.0) as i32`: truncation, saturating, NaN to 0 (cvtt gives i32::MIN
                    // for NaN and for anything out of range).
                    let scaled = _mm256_mul_ps(n, _mm256_set1_ps(render_spec::constants::OFFSET_INT_SCALE));
                    let mut o = _mm256_cvttps_epi32(scaled);
                    let too_big = _mm256_cmp_ps::<_CMP_GE_OQ>(scaled, _mm256_set1_ps(2147483648.0));
                    o = _mm256_castps_si256(_mm256_blendv_ps(
                        _mm256_castsi256_ps(o),
                        _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX)),
                        too_big,
                    ));
                    o = _mm256_and_si256(o, _mm256_castps_si256(_mm256_cmp_ps::<_CMP_ORD_Q>(scaled, scaled)));
                    // Away from zero by `o` units in the last place, whichever the sign.
                    let bits = _mm256_castps_si256(p);
                    let negative = _mm256_cmp_ps::<_CMP_LT_OQ>(p, _mm256_setzero_ps());
                    let stepped = _mm256_blendv_ps(
                        _mm256_castsi256_ps(_mm256_add_epi32(bits, o)),
                        _mm256_castsi256_ps(_mm256_sub_epi32(bits, o)),
                        negative,
                    );
                    // Near the origin a fixed float step instead.
                    let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), p);
                    let near = _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(render_spec::constants::OFFSET_ORIGIN));
                    let float_step =
                        _mm256_add_ps(p, _mm256_mul_ps(_mm256_set1_ps(render_spec::constants::OFFSET_FLOAT_SCALE), n));
                    _mm256_blendv_ps(stepped, float_step, near)
                }
            }
            V3::new(Avx8(axis(p.x.0, n.x.0)), Avx8(axis(p.y.0, n.y.0)), Avx8(axis(p.z.0, n.z.0)))
        }
        /// [`Self::gather4`]'s transpose without its fourth row (the compiler drops that shuffle).
        #[inline(always)]
        fn gather3(v: [&[f32; 4]; LANES]) -> V3<Self> {
            let [x, y, z, _] = Self::gather4(v);
            V3::new(x, y, z)
        }
        /// One load, an and and one store instead of a branch or a select per lane.
        #[inline(always)]
        fn keep_u32(m: AvxMask, a: &[u32; LANES]) -> [u32; LANES] {
            let mut out = [0u32; LANES];
            unsafe {
                let kept = _mm256_and_si256(_mm256_loadu_si256(a.as_ptr().cast()), _mm256_castps_si256(m.0));
                _mm256_storeu_si256(out.as_mut_ptr().cast(), kept);
            }
            out
        }
        /// Two integer additions and conversions instead of 16 scalar conversions and inserts.
        #[inline(always)]
        fn block_xy(x0: u32, y0: u32) -> (Self, Self) {
            debug_assert!(x0 < 1 << 31 && y0 < 1 << 31);
            unsafe {
                let x = _mm256_add_epi32(_mm256_set1_epi32(x0 as i32), _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3));
                let y = _mm256_add_epi32(_mm256_set1_epi32(y0 as i32), _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1));
                (Avx8(_mm256_cvtepi32_ps(x)), Avx8(_mm256_cvtepi32_ps(y)))
            }
        }
        /// Eight 4-float loads and a transpose instead of 32 single-float inserts.
        #[inline(always)]
        fn gather4(v: [&[f32; 4]; LANES]) -> [Self; 4] {
            #[inline(always)]
            fn pair(lo: &[f32; 4], hi: &[f32; 4]) -> __m256 {
                unsafe {
                    _mm256_insertf128_ps::<1>(
                        _mm256_castps128_ps256(_mm_loadu_ps(lo.as_ptr())),
                        _mm_loadu_ps(hi.as_ptr()),
                    )
                }
            }
            unsafe {
                let (t0, t1, t2, t3) = (pair(v[0], v[4]), pair(v[1], v[5]), pair(v[2], v[6]), pair(v[3], v[7]));
                let xy01 = _mm256_unpacklo_ps(t0, t1);
                let zw01 = _mm256_unpackhi_ps(t0, t1);
                let xy23 = _mm256_unpacklo_ps(t2, t3);
                let zw23 = _mm256_unpackhi_ps(t2, t3);
                [
                    Avx8(_mm256_shuffle_ps::<0x44>(xy01, xy23)),
                    Avx8(_mm256_shuffle_ps::<0xEE>(xy01, xy23)),
                    Avx8(_mm256_shuffle_ps::<0x44>(zw01, zw23)),
                    Avx8(_mm256_shuffle_ps::<0xEE>(zw01, zw23)),
                ]
            }
        }
        /// Truncation, the three channels merged into one 32-bit word per lane (`r | g << 8 |
        /// b << 16`) and each 128-bit half (one row of the block) shuffled into 12 bytes.
        #[inline(always)]
        fn rgb_rows(r: Self, g: Self, b: Self) -> [[u8; 16]; 2] {
            unsafe {
                let (r, g, b) = (_mm256_cvttps_epi32(r.0), _mm256_cvttps_epi32(g.0), _mm256_cvttps_epi32(b.0));
                let word = _mm256_or_si256(r, _mm256_or_si256(_mm256_slli_epi32::<8>(g), _mm256_slli_epi32::<16>(b)));
                let pick = _mm256_setr_epi8(
                    0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1, 0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1,
                    -1, -1, -1,
                );
                let mut rows = [[0u8; 16]; 2];
                _mm256_storeu_si256(rows.as_mut_ptr().cast(), _mm256_shuffle_epi8(word, pick));
                rows
            }
        }
        #[inline(always)]
        fn trunc(self) -> [i32; LANES] {
            let mut a = [0i32; LANES];
            unsafe { _mm256_storeu_si256(a.as_mut_ptr().cast(), _mm256_cvttps_epi32(self.0)) };
            a
        }
        #[inline(always)]
        fn count(m: AvxMask) -> usize {
            unsafe { _mm256_movemask_ps(m.0) }.count_ones() as usize
        }
    }
}

#[cfg(test)]
mod tests {
    //! Every shading formula gives the same bits on one ray and on each kind of lanes.

    use super::*;
    use crate::shade;
    use render_spec::constants::STOP_CONTRIBUTION;

    /// Deterministic numbers, with the values that break formulas mixed in: zeros of both signs,
    /// tiny and huge magnitudes, infinities and NaN.
    struct Gen(::tests::Rng);

    impl Gen {
        fn new(seed: u64) -> Gen {
            Gen(::tests::Rng(seed))
        }

        fn next(&mut self) -> f32 {
            const SPECIAL: [f32; 12] =
                [0.0, -0.0, 1.0, -1.0, 1e-30, -1e30, 1e30, 3e9, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 0.5];
            match self.0.below(16) {
                0 => SPECIAL[self.0.below(SPECIAL.len())],
                _ => self.0.signed() * 2.0,
            }
        }
        fn v(&mut self) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next())
        }
    }

    /// Bits of a number, every NaN alike: which NaN an operation on two NaNs returns depends on
    /// the order of its operands, which the compiler is free to swap (and no output depends on it).
    fn bits1(f: f32) -> u32 {
        if f.is_nan() { u32::MAX } else { f.to_bits() }
    }

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(bits1)
    }

    /// A formula's outputs flattened to floats and flags.
    type Out = (Vec<f32>, Vec<bool>);

    /// Runs `f` on lanes of `L`, filled lane by lane from `inputs`, and returns lane `i`'s outputs.
    fn check<L: Lanes>(
        name: &str,
        inputs: &[Vec<Vec3>],
        one: impl Fn(&[V3<f32>]) -> Out,
        many: impl Fn(&[V3<L>]) -> (Vec<L>, Vec<L::Mask>),
    ) {
        for chunk in inputs.chunks(LANES).filter(|c| c.len() == LANES) {
            let args: Vec<V3<L>> = (0..chunk[0].len()).map(|k| V3::from_lanes(|i| chunk[i][k])).collect();
            let (floats, masks) = many(&args);
            for (i, input) in chunk.iter().enumerate() {
                let scalar: Vec<V3<f32>> = input.iter().map(|&v| v.into()).collect();
                let (want_f, want_m) = one(&scalar);
                let got_f: Vec<f32> = floats.iter().map(|f| f.to_array()[i]).collect();
                let got_m: Vec<bool> = masks.iter().map(|&m| L::bools(m)[i]).collect();
                let (a, b): (Vec<u32>, Vec<u32>) =
                    (want_f.iter().map(|&f| bits1(f)).collect(), got_f.iter().map(|&f| bits1(f)).collect());
                assert_eq!((a, want_m), (b, got_m), "{name}, lane {i}, inputs {input:?}");
            }
        }
    }

    fn flat<R: Real>(vs: &[V3<R>]) -> Vec<R> {
        vs.iter().flat_map(|v| [v.x, v.y, v.z]).collect()
    }

    fn all_formulas<L: Lanes>() {
        let mut g = Gen::new(0x9e37_79b9_7f4a_7c15);
        let inputs: Vec<Vec<Vec3>> = (0..4096).map(|_| (0..8).map(|_| g.v()).collect()).collect();
        // Inputs: 0 e1, 1 e2, 2-4 normals, 5 origin, 6 dir, 7 (t, u, v).
        check::<L>(
            "surface",
            &inputs,
            |a| {
                let s = shade::surface_of(a[0], a[1], [a[2], a[3], a[4]], a[5], a[6], a[7].x, a[7].y, a[7].z);
                (flat(&[s.point, s.geometric, s.shading]), vec![s.front])
            },
            |a| {
                let s = shade::surface_of(a[0], a[1], [a[2], a[3], a[4]], a[5], a[6], a[7].x, a[7].y, a[7].z);
                (flat(&[s.point, s.geometric, s.shading]), vec![s.front])
            },
        );
        // A flat triangle's surface without the interpolation is the surface with zero normals.
        let zero = V3::splat(Vec3::ZERO);
        check::<L>(
            "flat surface",
            &inputs,
            |a| {
                let s = shade::surface_of(a[0], a[1], [zero; 3], a[5], a[6], a[7].x, a[7].y, a[7].z);
                (flat(&[s.point, s.geometric, s.shading]), vec![s.front])
            },
            |a| {
                let s = shade::flat_surface_of(a[0], a[1], a[5], a[6], a[7].x);
                (flat(&[s.point, s.geometric, s.shading]), vec![s.front])
            },
        );
        // Inputs: 0 kd, 1 ks, 2 shading normal, 3 dir, 4 to light, 5 (shininess, kr, kt), 6 ior.
        check::<L>(
            "cast, phong, secondary",
            &inputs,
            |a| {
                let c = shade::cast_of(a[0], a[2], a[3]);
                let p = shade::phong_of(a[0], a[1], a[5].x, a[2], a[3], a[4], true);
                let front = a[6].y.lt(0.0);
                let s = shade::secondary_of(a[5].y, a[5].z, a[6].x, a[2], front, a[3]);
                let w = shade::worth_of(
                    a[6].z,
                    &render_spec::BounceStop { bound: 1.5, k_max: 0.5, cutoff: STOP_CONTRIBUTION },
                    2.0,
                );
                let mut f = flat(&[c, p, s.dir, a[4].normalize_or_zero()]);
                f.push(s.factor);
                (f, vec![s.same_side, s.exists, w, a[4].is_zero()])
            },
            |a| {
                let c = shade::cast_of(a[0], a[2], a[3]);
                let all = L::splat(0.0).eq(L::splat(0.0));
                let p = shade::phong_of(a[0], a[1], a[5].x, a[2], a[3], a[4], all);
                let front = a[6].y.lt(L::splat(0.0));
                let s = shade::secondary_of(a[5].y, a[5].z, a[6].x, a[2], front, a[3]);
                let w = shade::worth_of(
                    a[6].z,
                    &render_spec::BounceStop { bound: 1.5, k_max: 0.5, cutoff: STOP_CONTRIBUTION },
                    2.0,
                );
                let mut f = flat(&[c, p, s.dir, a[4].normalize_or_zero()]);
                f.push(s.factor);
                (f, vec![s.same_side, s.exists, w, a[4].is_zero()])
            },
        );
    }

    /// `reflection_of` on lanes is `secondary_of` on one ray wherever no lane is glass (`kt`
    /// made `-kt * kt`: zero, negative or NaN): the same `exists` everywhere, the same ray where
    /// one exists.
    fn reflections_like_one_ray<L: Lanes>() {
        let mut g = Gen::new(0x5eed_0f9a);
        let inputs: Vec<Vec<Vec3>> = (0..4096).map(|_| (0..4).map(|_| g.v()).collect()).collect();
        // Inputs: 0 shading normal, 1 dir, 2 (kr, kt, ior), 3 (front when y < 0).
        check::<L>(
            "reflection",
            &inputs,
            |a| {
                let not_glass = -(a[2].y * a[2].y);
                let s = shade::secondary_of(a[2].x, not_glass, a[2].z, a[0], a[3].y.lt(0.0), a[1]);
                let e = s.exists;
                let dir = if e { s.dir } else { V3::zero() };
                (flat(&[dir]).into_iter().chain([if e { s.factor } else { 0.0 }]).collect(), vec![e, e && s.same_side])
            },
            |a| {
                let s = shade::reflection_of(a[2].x, a[0], a[1]);
                let e = s.exists;
                let dir = V3::select(e, s.dir, V3::zero());
                (
                    flat(&[dir]).into_iter().chain([L::select(e, s.factor, L::splat(0.0))]).collect(),
                    vec![e, e & s.same_side],
                )
            },
        );
    }

    /// Radiance to 8 bits on lanes, against the scalar conversion, over every float of a range
    /// sampled densely and the special values.
    fn quantize_like_one_ray<L: Lanes>() {
        let mut g = Gen::new(3);
        let mut values: Vec<f32> = (0..20000).map(|i| i as f32 / 16000.0 - 0.1).collect();
        values.extend((0..4000).map(|_| g.next()));
        values.extend([f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 0.0, 1.0, 1.0 + f32::EPSILON]);
        values.extend([0.5 / 255.0, 1.5 / 255.0, 254.5 / 255.0, f32::MIN_POSITIVE, -f32::MIN_POSITIVE]);
        for chunk in values.chunks(LANES).filter(|c| c.len() == LANES) {
            let v = V3::<L>::new(L::from_fn(|i| chunk[i]), L::from_fn(|i| chunk[(i + 3) % LANES]), L::splat(0.25));
            let got = shade::to_u8_lanes(v);
            let rows = shade::to_rgb_rows(v);
            for i in 0..LANES {
                assert_eq!(got[i], shade::to_u8(Vec3::new(chunk[i], chunk[(i + 3) % LANES], 0.25)), "{}", chunk[i]);
                let at = 3 * (i % 4);
                assert_eq!(rows[i / 4][at..at + 3], got[i], "{}: the row layout", chunk[i]);
            }
        }
    }

    /// The Phong power on lanes against `render_spec::phong_pow`: every 1021st positive float
    /// (zero, subnormals, the normal range, infinity, NaN) and their negatives, at exponents from
    /// below 1 to far past the dragon's 60, in lanes that take the power and lanes that must give 1.
    fn power_like_one_ray<L: Lanes>() {
        let mut x: Vec<f32> = (0..=0x7fc0_0000u32).step_by(1021).map(f32::from_bits).collect();
        x.extend([1.0, f32::MIN_POSITIVE, std::f32::consts::SQRT_2, 0.5, 0.999_999_9, f32::NAN, f32::INFINITY]);
        let negatives: Vec<f32> = x.iter().step_by(97).map(|v| -v).collect();
        x.extend(negatives);
        let live = L::mask([true, true, false, true, true, true, true, false]);
        for n in [0.5f32, 1.0, 2.0, 7.5, 40.0, 60.0, 128.0, 1000.0] {
            for chunk in x.chunks(LANES).filter(|c| c.len() == LANES) {
                let got = L::from_fn(|i| chunk[i]).powf_in(L::splat(n), live).to_array();
                for i in 0..LANES {
                    let want = if L::bools(live)[i] { render_spec::phong_pow(chunk[i], n) } else { 1.0 };
                    assert_eq!(bits1(got[i]), bits1(want), "{}^{n}", chunk[i]);
                }
            }
        }
    }

    fn offsets_like_one_ray<L: Lanes>() {
        let mut g = Gen::new(11);
        for _ in 0..20000 {
            let p: [Vec3; LANES] = std::array::from_fn(|_| g.v() * [1.0, 1e-3, 1e3, 0.01][g.0.below(4)]);
            let n: [Vec3; LANES] = std::array::from_fn(|_| g.v());
            let got = L::offset_origin(V3::from_lanes(|i| p[i]), V3::from_lanes(|i| n[i])).to_arrays();
            for i in 0..LANES {
                let want = crate::geometry::offset_origin(p[i], n[i]);
                assert_eq!(bits(Vec3::new(got[0][i], got[1][i], got[2][i])), bits(want), "{:?} {:?}", p[i], n[i]);
            }
        }
    }

    /// Every one of the 256 masks of eight lanes out of a comparison and back: the bools, the
    /// count (also [`crate::packet::Rays::count`] of those bools), the triangles kept.
    fn masks_round_trip<L: Lanes>() {
        let tri: [u32; LANES] = std::array::from_fn(|i| 0x8000_0001 + 77 * i as u32);
        for bits in 0u32..256 {
            let want: [bool; LANES] = std::array::from_fn(|i| bits >> i & 1 != 0);
            // A comparison's mask (and a NaN lane that compares false).
            let x = L::from_fn(|i| {
                if want[i] {
                    1.0
                } else if i % 2 == 0 {
                    0.0
                } else {
                    f32::NAN
                }
            });
            let m = x.gt(L::splat(0.5));
            assert_eq!(L::bools(m), want, "{bits:08b}");
            assert_eq!(L::bools(L::mask(want)), want, "{bits:08b}");
            assert_eq!(L::count(m), bits.count_ones() as usize);
            let rays = crate::packet::Rays { valid: want, ..Default::default() };
            assert_eq!(rays.count(), bits.count_ones() as usize);
            let kept = L::keep_u32(m, &tri);
            assert_eq!(kept, std::array::from_fn(|i| if want[i] { tri[i] } else { 0 }), "{bits:08b}");
        }
    }

    #[test]
    fn portable_lanes_match_one_ray_bit_for_bit() {
        masks_round_trip::<F8>();
        all_formulas::<F8>();
        reflections_like_one_ray::<F8>();
        quantize_like_one_ray::<F8>();
        power_like_one_ray::<F8>();
        offsets_like_one_ray::<F8>();
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_lanes_match_one_ray_bit_for_bit() {
        assert!(crate::packet::available(), "this test needs a CPU with AVX2");
        masks_round_trip::<Avx8>();
        all_formulas::<Avx8>();
        reflections_like_one_ray::<Avx8>();
        quantize_like_one_ray::<Avx8>();
        power_like_one_ray::<Avx8>();
        offsets_like_one_ray::<Avx8>();
    }

    #[test]
    fn the_scalar_functions_are_the_formulas_on_one_lane() {
        let mut g = Gen::new(7);
        for _ in 0..2000 {
            let (a, b, c) = (g.v(), g.v(), g.v());
            assert_eq!(bits(shade::reflect(a, b)), bits(shade::reflect_of(a.into(), b.into()).into()));
            // glam's own normalisation, which the rest of the tracer uses, agrees with ours.
            let (n, ok) = V3::from(a).try_normalize();
            assert_eq!(a.try_normalize().map(bits), ok.then(|| bits(n.into())), "{a:?}");
            assert_eq!(bits(a.normalize_or_zero()), bits(V3::from(a).normalize_or_zero().into()));
            assert_eq!(bits1(a.dot(b)), bits1(V3::from(a).dot(b.into())));
            assert_eq!(bits(a.cross(c)), bits(V3::from(a).cross(c.into()).into()));
        }
    }
}
