//! SIMD lanes: several independent values of one scalar type computed together.
//!
//! [`F64x4`] and [`F32x4`] are [`Real`]s whose every operation acts lane by lane, so physics
//! written once as scalar code runs on four independent inputs at a time (INFORM evaluates four
//! wavelengths per call). The element-wise arithmetic compiles to SIMD instructions (two SSE2
//! operations per `F64x4` operation on the baseline x86-64 target, one with AVX), and `F64x4`'s
//! `exp` and `ln` are evaluated for all four lanes at once; other functions go lane by lane
//! through `libm`.
//!
//! [`F64x8`] is two `F64x4` halves evaluated side by side: each operation issues two independent
//! vector instructions, which keeps the processor busy where one batch's long dependency chain
//! (INFORM per wavelength is a chain of some thousand cycles) would leave it waiting. It is the
//! lanes of `f64`; duals, whose derivatives already fill the registers, keep four lanes
//! ([`DualScalar`]). These lanes are used on targets with SIMD (x86-64, AArch64); on others (the
//! Cortex-M4F) every type is its own single lane, which there runs faster and is much smaller.
//!
//! Every lane of an `F64x4` result equals, bit for bit, the `f64` result of the same operation
//! on that lane (same operations in the same order; `exp` and `ln` follow `libm`'s algorithms
//! step by step). The same holds for `F32x4` and `f32`.
//!
//! Lanes have no single value to branch on: code that may run on lanes branches through
//! [`Real::select`] (each lane takes its own branch), never on [`Real::value`], which for lanes
//! reports lane 0 only — correct when all lanes are equal, as for constants broadcast with
//! [`Lanes::splat`].

use super::{e1_f64, Real};
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A batch of values of scalar `S` computed together: [`F64x4`] for `f64`, [`F32x4`] for
/// `f32`, and a scalar itself (one lane) for types such as [`super::Dual`] that carry their own
/// parallelism (see [`Real::Lanes`]).
pub trait Lanes<S: Real>: Real {
    /// Number of lanes.
    const WIDTH: usize;
    /// Every lane equal to `v`.
    fn splat(v: S) -> Self;
    /// Lane `i` (`i < WIDTH`).
    fn lane(self, i: usize) -> S;
    /// Plain lanes holding `f(0), …, f(WIDTH − 1)`: how table columns are loaded, one
    /// wavelength per lane.
    fn plain_from_fn(f: impl FnMut(usize) -> f64) -> Self::Plain;
}

/// A plain scalar (no derivatives) that [`super::Dual`] numbers are built on, with the lanes
/// duals on it are evaluated in (at most four: a dual carries a vector per derivative).
pub trait DualScalar: Real<Plain = Self> {
    /// The lanes of a dual on this scalar: `Dual<N, DualLanes>` is its [`Real::Lanes`].
    type DualLanes: DualScalar<DualLanes = Self::DualLanes> + Lanes<Self>;
}

impl DualScalar for f64 {
    type DualLanes = DualLanesF64;
}
impl DualScalar for f32 {
    type DualLanes = DualLanesF32;
}
impl DualScalar for F64x4 {
    type DualLanes = F64x4;
}
impl DualScalar for F32x4 {
    type DualLanes = F32x4;
}
impl DualScalar for F64x8 {
    type DualLanes = F64x8;
}

/// Whether this target computes lanes with SIMD instructions (x86-64, AArch64). Elsewhere (the
/// Cortex-M4F) lanes would only multiply the code (and, for `f64`, the soft-float calls): every
/// type is then its own single lane.
macro_rules! simd_target {
    ($($item:item)*) => {
        $(#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))] $item)*
    };
}
macro_rules! scalar_target {
    ($($item:item)*) => {
        $(#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))] $item)*
    };
}

simd_target! {
    /// The lanes of `f64` ([`Real::Lanes`]): [`F64x8`] on SIMD targets, `f64` elsewhere.
    pub type LanesF64 = F64x8;
    /// The lanes of `f32`: [`F32x4`] on SIMD targets, `f32` elsewhere.
    pub type LanesF32 = F32x4;
    /// The lanes of duals on `f64`: [`F64x4`] on SIMD targets, `f64` elsewhere.
    pub type DualLanesF64 = F64x4;
    /// The lanes of duals on `f32`: [`F32x4`] on SIMD targets, `f32` elsewhere.
    pub type DualLanesF32 = F32x4;
}
scalar_target! {
    /// The lanes of `f64` ([`Real::Lanes`]): [`F64x8`] on SIMD targets, `f64` elsewhere.
    pub type LanesF64 = f64;
    /// The lanes of `f32`: [`F32x4`] on SIMD targets, `f32` elsewhere.
    pub type LanesF32 = f32;
    /// The lanes of duals on `f64`: [`F64x4`] on SIMD targets, `f64` elsewhere.
    pub type DualLanesF64 = f64;
    /// The lanes of duals on `f32`: [`F32x4`] on SIMD targets, `f32` elsewhere.
    pub type DualLanesF32 = f32;
}

/// A plain float is also a batch of one: lanes of a single value.
macro_rules! single_lane {
    ($f:ty) => {
        impl Lanes<$f> for $f {
            const WIDTH: usize = 1;
            #[inline]
            fn splat(v: $f) -> Self {
                v
            }
            #[inline]
            fn lane(self, _i: usize) -> $f {
                self
            }
            #[inline]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                f(0) as $f
            }
        }
    };
}
single_lane!(f64);
single_lane!(f32);

/// Four `f64` lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(32))]
pub struct F64x4(pub [f64; 4]);

/// Eight `f64` lanes: two [`F64x4`] halves (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F64x8(pub F64x4, pub F64x4);

/// Four `f32` lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(16))]
pub struct F32x4(pub [f32; 4]);

/// The arithmetic, comparison and per-lane function plumbing shared by both lane types.
macro_rules! lane_type {
    ($t:ident, $f:ty) => {
        impl $t {
            /// Applies `f` to every lane.
            #[inline]
            pub fn map(self, f: impl Fn($f) -> $f) -> Self {
                let a = self.0;
                $t([f(a[0]), f(a[1]), f(a[2]), f(a[3])])
            }
            /// Applies `f` lane by lane to two batches.
            #[inline]
            pub fn zip(self, o: Self, f: impl Fn($f, $f) -> $f) -> Self {
                let (a, b) = (self.0, o.0);
                $t([f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])])
            }
        }

        impl PartialOrd for $t {
            /// Ordered only when every lane compares the same way.
            #[inline]
            fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
                let first = self.0[0].partial_cmp(&o.0[0])?;
                for i in 1..4 {
                    if self.0[i].partial_cmp(&o.0[i])? != first {
                        return None;
                    }
                }
                Some(first)
            }
        }

        impl Neg for $t {
            type Output = Self;
            #[inline]
            fn neg(self) -> Self {
                self.map(|a| -a)
            }
        }

        lane_type!(@op $t, Add, add, AddAssign, add_assign, +);
        lane_type!(@op $t, Sub, sub, SubAssign, sub_assign, -);
        lane_type!(@op $t, Mul, mul, MulAssign, mul_assign, *);
        lane_type!(@op $t, Div, div, DivAssign, div_assign, /);

        impl Lanes<$t> for $t {
            const WIDTH: usize = 1;
            #[inline]
            fn splat(v: $t) -> Self {
                v
            }
            #[inline]
            fn lane(self, _i: usize) -> $t {
                self
            }
            #[inline]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                Self::c(f(0))
            }
        }

        impl Lanes<$f> for $t {
            const WIDTH: usize = 4;
            #[inline]
            fn splat(v: $f) -> Self {
                $t([v; 4])
            }
            #[inline]
            fn lane(self, i: usize) -> $f {
                self.0[i]
            }
            #[inline]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                $t([f(0) as $f, f(1) as $f, f(2) as $f, f(3) as $f])
            }
        }
    };
    (@op $t:ident, $tr:ident, $m:ident, $tra:ident, $ma:ident, $op:tt) => {
        impl $tr for $t {
            type Output = Self;
            #[inline]
            fn $m(self, o: Self) -> Self {
                let (a, b) = (self.0, o.0);
                $t([a[0] $op b[0], a[1] $op b[1], a[2] $op b[2], a[3] $op b[3]])
            }
        }
        impl $tra for $t {
            #[inline]
            fn $ma(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}

lane_type!(F64x4, f64);
lane_type!(F32x4, f32);

/// The [`Real`] items that are the same for both lane types (`$t` the lanes, `$f` one lane).
macro_rules! lane_real_common {
    ($t:ident, $f:ty) => {
        type Plain = $t;
        type Lanes = $t;
        #[inline]
        fn c(v: f64) -> Self {
            $t([v as $f; 4])
        }
        /// Lane 0 (see the module documentation: meaningful when all lanes are equal).
        #[inline]
        fn value(self) -> f64 {
            self.0[0] as f64
        }
        #[inline]
        fn scale(self, k: Self) -> Self {
            self * k
        }
        #[inline]
        fn from_plain(k: Self) -> Self {
            k
        }
        #[inline]
        fn all(self, pred: impl Fn(f64) -> bool) -> bool {
            self.0.iter().all(|&x| pred(x as f64))
        }
        #[inline]
        fn any(self, pred: impl Fn(f64) -> bool) -> bool {
            self.0.iter().any(|&x| pred(x as f64))
        }
        #[inline]
        fn select(
            self,
            pred: impl Fn(f64) -> bool,
            a: impl FnOnce() -> Self,
            b: impl FnOnce() -> Self,
        ) -> Self {
            let s = self.0;
            let take = [
                pred(s[0] as f64),
                pred(s[1] as f64),
                pred(s[2] as f64),
                pred(s[3] as f64),
            ];
            if take.iter().all(|&t| t) {
                return a();
            }
            if !take.iter().any(|&t| t) {
                return b();
            }
            let (a, b) = (a(), b());
            let pick = |i: usize| if take[i] { a.0[i] } else { b.0[i] };
            $t([pick(0), pick(1), pick(2), pick(3)])
        }
        #[inline]
        fn abs(self) -> Self {
            self.map(|x| if x < 0.0 { -x } else { x })
        }
        #[inline]
        fn max(self, o: Self) -> Self {
            self.zip(o, |a, b| if a >= b { a } else { b })
        }
        #[inline]
        fn min(self, o: Self) -> Self {
            self.zip(o, |a, b| if a <= b { a } else { b })
        }
        #[inline]
        fn is_finite(self) -> bool {
            self.0.iter().all(|x| x.is_finite())
        }
    };
}

impl Real for F64x4 {
    lane_real_common!(F64x4, f64);
    #[inline]
    fn sqrt(self) -> Self {
        self.map(libm::sqrt)
    }
    #[inline]
    fn exp(self) -> Self {
        F64x4(exp4(self.0))
    }
    #[inline]
    fn ln(self) -> Self {
        F64x4(ln4(self.0))
    }
    #[inline]
    fn sin(self) -> Self {
        self.map(libm::sin)
    }
    #[inline]
    fn cos(self) -> Self {
        self.map(libm::cos)
    }
    #[inline]
    fn tan(self) -> Self {
        self.map(libm::tan)
    }
    #[inline]
    fn acos(self) -> Self {
        self.map(libm::acos)
    }
    #[inline]
    fn asin(self) -> Self {
        self.map(libm::asin)
    }
    #[inline]
    fn atan(self) -> Self {
        self.map(libm::atan)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        self.zip(x, libm::atan2)
    }
    #[inline]
    fn powf(self, e: Self) -> Self {
        self.zip(e, libm::pow)
    }
    #[inline]
    fn powi(self, n: i32) -> Self {
        self.map(|x| libm::pow(x, n as f64))
    }
    #[inline]
    fn e1(self) -> Self {
        self.map(e1_f64)
    }
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = (-self).exp();
        (super::e1::e1_with_exp4(self, ex), ex)
    }
}

impl Real for F32x4 {
    lane_real_common!(F32x4, f32);
    #[inline]
    fn sqrt(self) -> Self {
        self.map(libm::sqrtf)
    }
    #[inline]
    fn exp(self) -> Self {
        self.map(libm::expf)
    }
    #[inline]
    fn ln(self) -> Self {
        self.map(libm::logf)
    }
    #[inline]
    fn sin(self) -> Self {
        self.map(libm::sinf)
    }
    #[inline]
    fn cos(self) -> Self {
        self.map(libm::cosf)
    }
    #[inline]
    fn tan(self) -> Self {
        self.map(libm::tanf)
    }
    #[inline]
    fn acos(self) -> Self {
        self.map(libm::acosf)
    }
    #[inline]
    fn asin(self) -> Self {
        self.map(libm::asinf)
    }
    #[inline]
    fn atan(self) -> Self {
        self.map(libm::atanf)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        self.zip(x, libm::atan2f)
    }
    #[inline]
    fn powf(self, e: Self) -> Self {
        self.zip(e, libm::powf)
    }
    #[inline]
    fn powi(self, n: i32) -> Self {
        self.map(|x| libm::powf(x, n as f32))
    }
    #[inline]
    fn e1(self) -> Self {
        self.map(|x| e1_f64(x as f64) as f32)
    }
}

impl PartialOrd for F64x8 {
    /// Ordered only when every lane compares the same way.
    #[inline]
    fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
        let a = self.0.partial_cmp(&o.0)?;
        (self.1.partial_cmp(&o.1)? == a).then_some(a)
    }
}

macro_rules! halves_op {
    ($tr:ident, $m:ident, $tra:ident, $ma:ident, $op:tt) => {
        impl $tr for F64x8 {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                F64x8(self.0 $op o.0, self.1 $op o.1)
            }
        }
        impl $tra for F64x8 {
            #[inline(always)]
            fn $ma(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}
halves_op!(Add, add, AddAssign, add_assign, +);
halves_op!(Sub, sub, SubAssign, sub_assign, -);
halves_op!(Mul, mul, MulAssign, mul_assign, *);
halves_op!(Div, div, DivAssign, div_assign, /);

impl Neg for F64x8 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        F64x8(-self.0, -self.1)
    }
}

impl Lanes<F64x8> for F64x8 {
    const WIDTH: usize = 1;
    #[inline]
    fn splat(v: Self) -> Self {
        v
    }
    #[inline]
    fn lane(self, _i: usize) -> Self {
        self
    }
    #[inline]
    fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        Self::c(f(0))
    }
}

impl Lanes<f64> for F64x8 {
    const WIDTH: usize = 8;
    #[inline]
    fn splat(v: f64) -> Self {
        F64x8(F64x4([v; 4]), F64x4([v; 4]))
    }
    #[inline]
    fn lane(self, i: usize) -> f64 {
        if i < 4 {
            self.0 .0[i]
        } else {
            self.1 .0[i - 4]
        }
    }
    #[inline]
    fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        F64x8(
            F64x4([f(0), f(1), f(2), f(3)]),
            F64x4([f(4), f(5), f(6), f(7)]),
        )
    }
}

/// Applies a method of [`Real`] to both halves.
macro_rules! halves {
    ($($m:ident),*) => {
        $(
            #[inline(always)]
            fn $m(self) -> Self {
                F64x8(self.0.$m(), self.1.$m())
            }
        )*
    };
}

impl Real for F64x8 {
    type Plain = Self;
    type Lanes = Self;
    #[inline(always)]
    fn c(v: f64) -> Self {
        F64x8(F64x4::c(v), F64x4::c(v))
    }
    /// Lane 0 (see the module documentation: meaningful when all lanes are equal).
    #[inline(always)]
    fn value(self) -> f64 {
        self.0.value()
    }
    #[inline(always)]
    fn scale(self, k: Self) -> Self {
        self * k
    }
    #[inline(always)]
    fn from_plain(k: Self) -> Self {
        k
    }
    #[inline(always)]
    fn all(self, pred: impl Fn(f64) -> bool) -> bool {
        self.0.all(&pred) && self.1.all(&pred)
    }
    #[inline(always)]
    fn any(self, pred: impl Fn(f64) -> bool) -> bool {
        self.0.any(&pred) || self.1.any(&pred)
    }
    #[inline(always)]
    fn select(
        self,
        pred: impl Fn(f64) -> bool,
        a: impl FnOnce() -> Self,
        b: impl FnOnce() -> Self,
    ) -> Self {
        if self.all(&pred) {
            return a();
        }
        if !self.any(&pred) {
            return b();
        }
        let (a, b) = (a(), b());
        F64x8(
            self.0.select(&pred, || a.0, || b.0),
            self.1.select(&pred, || a.1, || b.1),
        )
    }
    halves!(sqrt, exp, ln, sin, cos, tan, acos, asin, atan, abs, e1);
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        F64x8(self.0.atan2(x.0), self.1.atan2(x.1))
    }
    #[inline(always)]
    fn powf(self, e: Self) -> Self {
        F64x8(self.0.powf(e.0), self.1.powf(e.1))
    }
    #[inline(always)]
    fn powi(self, n: i32) -> Self {
        F64x8(self.0.powi(n), self.1.powi(n))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        F64x8(self.0.max(o.0), self.1.max(o.1))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        F64x8(self.0.min(o.0), self.1.min(o.1))
    }
    #[inline(always)]
    fn e1_and_exp(self) -> (Self, Self) {
        let (a, b) = (self.0.e1_and_exp(), self.1.e1_and_exp());
        (F64x8(a.0, b.0), F64x8(a.1, b.1))
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.0.is_finite() && self.1.is_finite()
    }
}

/// A lane mask: all bits set where `f` holds. Masks and bitwise blends (rather than `bool`s and
/// `if`) keep the lane-wise code free of branches, so it compiles to SIMD compares and blends.
#[inline(always)]
pub(crate) fn mask(x: F64x4, f: impl Fn(f64) -> bool) -> [u64; 4] {
    let m = |v: f64| if f(v) { u64::MAX } else { 0 };
    [m(x.0[0]), m(x.0[1]), m(x.0[2]), m(x.0[3])]
}

/// Whether every lane of the mask is set.
#[inline(always)]
pub(crate) fn all(m: [u64; 4]) -> bool {
    m[0] & m[1] & m[2] & m[3] == u64::MAX
}

/// Whether some lane of the mask is set.
#[inline(always)]
pub(crate) fn any(m: [u64; 4]) -> bool {
    m[0] | m[1] | m[2] | m[3] != 0
}

/// `a` in the lanes where `c` is set, else `b`.
#[inline(always)]
pub(crate) fn blend(c: [u64; 4], a: F64x4, b: F64x4) -> F64x4 {
    let pick = |i: usize| f64::from_bits((a.0[i].to_bits() & c[i]) | (b.0[i].to_bits() & !c[i]));
    F64x4([pick(0), pick(1), pick(2), pick(3)])
}

/// Lanes rounded toward zero, for magnitudes below 2^51 (as `as i32` does in `e_exp.c`).
#[inline(always)]
fn trunc_small(t: F64x4) -> F64x4 {
    // 2^52 + 2^51: adding and subtracting it rounds to the nearest integer.
    let round = F64x4::c(6_755_399_441_055_744.0);
    let n = (t + round) - round;
    let one = F64x4::c(1.0);
    let zero = F64x4::c(0.0);
    // Step back toward zero where rounding went away from it.
    let down = blend(mask(n - t, |d| d > 0.0), one, zero);
    let up = blend(mask(t - n, |d| d > 0.0), one, zero);
    let nonneg = mask(t, |v| v >= 0.0);
    n - blend(nonneg, down, zero) + blend(nonneg, zero, up)
}

/// `2^k` for integer-valued lanes `k` in [−1022, 1023], built from exponent bits.
#[inline(always)]
fn pow2(k: F64x4) -> F64x4 {
    // The low bits of 2^52 + (k + 1023) hold k + 1023; shifted into the exponent field.
    (k + F64x4::c(1023.0 + 4_503_599_627_370_496.0)).map(|v| f64::from_bits(v.to_bits() << 52))
}

/// The lanes of `x` (one function per lane) as an `F64x4`.
#[inline(always)]
pub(crate) fn ln4_of(x: F64x4) -> F64x4 {
    F64x4(ln4(x.0))
}

/// `e^x` for four lanes: `libm::exp` (FreeBSD's `e_exp.c`) step by step, with its branches as
/// blends, for |x| < 708.39; lanes outside that range (or NaN) send the batch through
/// `libm::exp`.
#[inline]
fn exp4(x: [f64; 4]) -> [f64; 4] {
    // Boundaries of e_exp.c, as |x| thresholds (its tests on the high word of |x|); its constants
    // by their bits, as e_exp.c gives them.
    const SPECIAL: f64 = f64::from_bits(0x4086_232b_0000_0000); // ≈ 708.39
    const REDUCE: f64 = f64::from_bits(0x3fd6_2e43_0000_0000); // > 0.5·ln 2
    const FAR: f64 = f64::from_bits(0x3ff0_a2b2_0000_0000); // ≥ 1.5·ln 2
    const TINY: f64 = f64::from_bits(0x3e30_0001_0000_0000); // > 2^-28
    const LN2HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const INVLN2: f64 = f64::from_bits(0x3ff7_1547_652b_82fe);
    const P1: f64 = f64::from_bits(0x3fc5_5555_5555_553e);
    const P2: f64 = f64::from_bits(0xbf66_c16c_16be_bd93);
    const P3: f64 = f64::from_bits(0x3f11_566a_af25_de2c);
    const P4: f64 = f64::from_bits(0xbebb_bd41_c5d2_6bf1);
    const P5: f64 = f64::from_bits(0x3e66_3769_72be_a4d0);
    let c = F64x4::c;
    let x = F64x4(x);
    let ax = x.map(|v| f64::from_bits(v.to_bits() & !(1 << 63)));
    if !all(mask(ax, |a| a < SPECIAL)) {
        return x.0.map(libm::exp);
    }
    // Argument reduction x = k·ln 2 + r: k = ±1 just above 0.5·ln 2, rounded x/ln 2 beyond
    // 1.5·ln 2, 0 below 0.5·ln 2.
    // ±0.5 with the sign of x.
    let half = x.map(|v| f64::from_bits(0.5f64.to_bits() | (v.to_bits() & (1 << 63))));
    let k_far = trunc_small(c(INVLN2) * x + half);
    let k = blend(
        mask(ax, |a| a >= FAR),
        k_far,
        blend(mask(ax, |a| a >= REDUCE), half + half, c(0.0)),
    );
    let hi = x - k * c(LN2HI);
    let lo = k * c(LN2LO);
    let r = hi - lo;
    let xx = r * r;
    let p = r - xx * (c(P1) + xx * (c(P2) + xx * (c(P3) + xx * (c(P4) + xx * c(P5)))));
    let y = c(1.0) + (r * p / (c(2.0) - p) - lo + hi);
    blend(mask(ax, |a| a < TINY), c(1.0) + x, y * pow2(k)).0
}

/// `ln x` for four lanes: `libm::log` (FreeBSD's `e_log.c`) step by step, for positive normal
/// finite `x`; other lanes send the batch through `libm::log`. Its constants by their bits, as
/// e_log.c gives them.
#[inline]
fn ln4(x: [f64; 4]) -> [f64; 4] {
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const LG1: f64 = f64::from_bits(0x3fe5_5555_5555_5593);
    const LG2: f64 = f64::from_bits(0x3fd9_9999_9997_fa04);
    const LG3: f64 = f64::from_bits(0x3fd2_4924_9422_9359);
    const LG4: f64 = f64::from_bits(0x3fcc_71c5_1d8e_78af);
    const LG5: f64 = f64::from_bits(0x3fc7_4664_96cb_03de);
    const LG6: f64 = f64::from_bits(0x3fc3_9a09_d078_c69f);
    const LG7: f64 = f64::from_bits(0x3fc2_f112_df3e_5244);
    let c = F64x4::c;
    let x = F64x4(x);
    if !all(mask(x, |v| (f64::MIN_POSITIVE..f64::INFINITY).contains(&v))) {
        return x.0.map(libm::log);
    }
    // x = m·2^k with m in [sqrt(2)/2, sqrt(2)], on the high word as e_log.c does: the offset
    // moves the mantissa boundary to sqrt(2)/2, the exponent field then holds k + 1023.
    const OFFSET: u64 = (0x3ff0_0000 - 0x3fe6_a09e) << 32;
    let ui = x.map(|v| f64::from_bits(v.to_bits() + OFFSET));
    // k, converted exactly through the low bits of 2^52.
    let dk = ui.map(|u| f64::from_bits((u.to_bits() >> 52) | 0x4330_0000_0000_0000))
        - c(4_503_599_627_370_496.0 + 1023.0);
    let m = ui.map(|u| f64::from_bits((u.to_bits() & 0x000f_ffff_ffff_ffff) + (0x3fe6_a09e << 32)));
    let f = m - c(1.0);
    let hfsq = c(0.5) * f * f;
    let s = f / (c(2.0) + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (c(LG2) + w * (c(LG4) + w * c(LG6)));
    let t2 = z * (c(LG1) + w * (c(LG3) + w * (c(LG5) + w * c(LG7))));
    let r = t2 + t1;
    (s * (hfsq + r) + dk * c(LN2_LO) - hfsq + f + dk * c(LN2_HI)).0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic spread of arguments (xorshift), scaled into `[lo, hi]`.
    fn spread(n: usize, lo: f64, hi: f64) -> impl Iterator<Item = f64> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        (0..n).map(move |_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
        })
    }

    /// Checks `f4` against `f` on every value of `xs`, four at a time.
    fn check4(f4: fn([f64; 4]) -> [f64; 4], f: fn(f64) -> f64, xs: impl Iterator<Item = f64>) {
        let mut a = [0.0; 4];
        let mut n = 0;
        let check = |a: &[f64; 4]| {
            for (xi, yi) in a.iter().zip(f4(*a)) {
                let want = f(*xi);
                assert!(
                    yi.to_bits() == want.to_bits() || (yi.is_nan() && want.is_nan()),
                    "x {xi:e}: {yi:e} vs {want:e}"
                );
            }
        };
        for x in xs {
            a[n] = x;
            n += 1;
            if n == 4 {
                check(&a);
                n = 0;
            }
        }
        if n > 0 {
            check(&a);
        }
    }

    #[test]
    fn exp_is_libm_bit_for_bit() {
        let special = [
            0.0,
            -0.0,
            1e-300,
            0.34657359027997264,
            1.0397207708399179,
            -1.0397207708399179,
            708.39,
            -708.39,
            -745.2,
            710.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let xs = spread(20_000, -750.0, 750.0)
            .chain(spread(20_000, -2.0, 2.0))
            .chain(spread(4_000, -1e-7, 1e-7))
            .chain(special);
        check4(exp4, libm::exp, xs);
        // One special lane among ordinary ones.
        check4(exp4, libm::exp, [0.5, f64::NAN, -3.0, 800.0].into_iter());
    }

    #[test]
    fn ln_is_libm_bit_for_bit() {
        let special = [
            1.0,
            0.0,
            -1.0,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            core::f64::consts::SQRT_2,
            core::f64::consts::FRAC_1_SQRT_2,
        ];
        let xs = spread(20_000, 0.0, 10.0)
            .chain(spread(20_000, 0.5, 2.0))
            .chain(spread(4_000, 0.0, 1e-300))
            .chain(spread(4_000, 0.0, 1e300))
            .chain(special);
        check4(ln4, libm::log, xs);
    }

    #[test]
    fn lanes_follow_their_own_branches() {
        let x = F64x4([-1.0, 0.5, 2.0, -0.0]);
        let y = x.select(|v| v > 0.0, || x.sqrt(), || F64x4::c(7.0));
        assert_eq!(y.0, [7.0, libm::sqrt(0.5), libm::sqrt(2.0), 7.0]);
        assert_eq!(x.abs().0, [1.0, 0.5, 2.0, 0.0]);
        assert_eq!(x.max(F64x4::c(0.25)).0, [0.25, 0.5, 2.0, 0.25]);
        assert!(F64x4([1.0, 2.0, 3.0, 4.0]) < F64x4::c(5.0));
        assert_eq!(
            F64x4([1.0, 6.0, 3.0, 4.0]).partial_cmp(&F64x4::c(5.0)),
            None
        );
        let f = F32x4([1.0, 2.0, 3.0, 4.0]);
        assert_eq!((f * f - f).0, [0.0, 2.0, 6.0, 12.0]);
        assert_eq!(<F32x4 as Lanes<f32>>::lane(f.exp(), 2), libm::expf(3.0));
        let p = <F64x4 as Lanes<f64>>::plain_from_fn(|i| i as f64);
        assert_eq!(p.0, [0.0, 1.0, 2.0, 3.0]);
        assert!(x.any(|v| v > 1.0) && !x.all(|v| v > 1.0));
    }

    #[test]
    fn eight_lanes_are_two_halves() {
        let x = <F64x8 as Lanes<f64>>::plain_from_fn(|i| i as f64 * 0.7 - 2.0);
        let y = x.select(|v| v > 0.0, || x.ln(), || x.exp());
        for i in 0..8 {
            let xi = i as f64 * 0.7 - 2.0;
            let want = if xi > 0.0 {
                libm::log(xi)
            } else {
                libm::exp(xi)
            };
            assert_eq!(<F64x8 as Lanes<f64>>::lane(y, i).to_bits(), want.to_bits());
        }
        assert!(x.any(|v| v > 2.0) && !x.all(|v| v > 2.0));
        let m = x.max(F64x8::c(0.1));
        for i in 0..8 {
            let xi = i as f64 * 0.7 - 2.0;
            assert_eq!(<F64x8 as Lanes<f64>>::lane(m, i), xi.max(0.1));
        }
    }
}
