//! Lanes of one SIMD register: [`F64x4`] (four `f64`, 256 bits) and [`F32x8`] (eight `f32`).
//!
//! Both wrap the vector types of the `wide` crate, which compile to one SIMD instruction per
//! operation where the target has the instructions (AVX on x86-64-v3: `vaddpd`, `vcmppd`,
//! `vblendvpd`, `vsqrtpd`, …) and to pairs of narrower ones or plain code elsewhere. One macro
//! writes both types: arithmetic, comparisons with constants ([`Cmp`]) as masks, blends, square
//! root (correctly rounded, as `libm`'s). The other functions are per type: `exp` and `ln` follow
//! `libm`'s algorithms step by step on all lanes at once (`libm64`, `libm32`), E1 takes the steps
//! of the scalar functions on all lanes (`e1x4` for `f64`, `e1x8` for `f32`), the trigonometric
//! functions go lane by lane through `libm` (they run once per spectrum, never per wavelength).

use super::e1x4::e1_with_exp4;
use super::e1x8::e1_with_exp8;
use super::libm32::{expf8, logf8};
use super::libm64::{exp4, ln4};
use super::Lanes;
use crate::real::{Cmp, Real};
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};
use wide::{f32x8, f64x4, u32x8, u64x4};

/// One lane type: `$t` holds `$w` lanes of `$f` in the `wide` vector `$v`, whose bit patterns are
/// the unsigned vector `$u`.
macro_rules! vector {
    ($(#[$doc:meta])* $t:ident, $f:ty, $v:ident, $u:ident, $w:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Default)]
        #[repr(transparent)]
        pub struct $t(pub(crate) $v);

        impl $t {
            /// Lanes holding `a`.
            #[inline(always)]
            pub fn new(a: [$f; $w]) -> Self {
                $t($v::new(a))
            }
            /// The lanes as an array.
            #[inline(always)]
            pub fn to_array(self) -> [$f; $w] {
                self.0.to_array()
            }
            /// Applies `f` to every lane (one call per lane).
            #[inline(always)]
            pub fn map(self, f: impl Fn($f) -> $f) -> Self {
                let mut a = self.to_array();
                for x in a.iter_mut() {
                    *x = f(*x);
                }
                Self::new(a)
            }
            /// Applies `f` lane by lane to two batches (one call per lane).
            #[inline(always)]
            pub fn zip(self, o: Self, f: impl Fn($f, $f) -> $f) -> Self {
                let mut a = self.to_array();
                for (x, y) in a.iter_mut().zip(o.to_array()) {
                    *x = f(*x, y);
                }
                Self::new(a)
            }
            /// The lanes' bit patterns.
            #[inline(always)]
            pub(crate) fn bits(self) -> $u {
                bytemuck::cast(self.0)
            }
            /// Lanes from bit patterns.
            #[inline(always)]
            pub(crate) fn from_bits(b: $u) -> Self {
                $t(bytemuck::cast(b))
            }
            /// Lanes equal to `v` (the vector of the `wide` crate).
            #[inline(always)]
            pub(crate) fn splat(v: $f) -> Self {
                $t($v::splat(v))
            }
        }

        impl core::fmt::Debug for $t {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.debug_tuple(stringify!($t)).field(&self.to_array()).finish()
            }
        }

        impl PartialEq for $t {
            /// Every lane equal.
            #[inline]
            fn eq(&self, o: &Self) -> bool {
                self.to_array() == o.to_array()
            }
        }

        impl PartialOrd for $t {
            /// Ordered only when every lane compares the same way.
            #[inline]
            fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
                let (a, b) = (self.to_array(), o.to_array());
                let first = a[0].partial_cmp(&b[0])?;
                for (x, y) in a.iter().zip(&b).skip(1) {
                    if x.partial_cmp(y)? != first {
                        return None;
                    }
                }
                Some(first)
            }
        }

        impl Neg for $t {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                $t(-self.0)
            }
        }

        vector!(@op $t, Add, add, AddAssign, add_assign, +);
        vector!(@op $t, Sub, sub, SubAssign, sub_assign, -);
        vector!(@op $t, Mul, mul, MulAssign, mul_assign, *);
        vector!(@op $t, Div, div, DivAssign, div_assign, /);

        impl Lanes<$t> for $t {
            const WIDTH: usize = 1;
            #[inline(always)]
            fn splat(v: $t) -> Self {
                v
            }
            #[inline(always)]
            fn lane(self, _i: usize) -> $t {
                self
            }
            #[inline(always)]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                Self::c(f(0))
            }
        }

        impl Lanes<$f> for $t {
            const WIDTH: usize = $w;
            #[inline(always)]
            fn splat(v: $f) -> Self {
                $t::splat(v)
            }
            #[inline(always)]
            fn lane(self, i: usize) -> $f {
                self.0.as_array()[i]
            }
            #[inline(always)]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                let mut a = [0.0; $w];
                for (j, x) in a.iter_mut().enumerate() {
                    *x = f(j) as $f;
                }
                Self::new(a)
            }
        }
    };
    (@op $t:ident, $tr:ident, $m:ident, $tra:ident, $ma:ident, $op:tt) => {
        impl $tr for $t {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                $t(self.0 $op o.0)
            }
        }
        impl $tra for $t {
            #[inline(always)]
            fn $ma(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}

vector!(
    /// Four `f64` lanes.
    F64x4, f64, f64x4, u64x4, 4
);
vector!(
    /// Eight `f32` lanes.
    F32x8, f32, f32x8, u32x8, 8
);

/// The [`Real`] items that are the same for both lane types (`$f` one lane), with the `libm`
/// functions of `$f` that go lane by lane.
macro_rules! vector_real_common {
    ($t:ident, $f:ty, $v:ident,
     $sin:ident, $cos:ident, $tan:ident, $acos:ident, $asin:ident, $atan:ident,
     $atan2:ident, $pow:ident) => {
        type Plain = $t;
        type Lanes = $t;
        type Mask = $v;
        #[inline(always)]
        fn c(v: f64) -> Self {
            $t::splat(v as $f)
        }
        /// Lane 0 (see the module documentation of `lanes`: meaningful when all lanes are
        /// equal).
        #[inline(always)]
        fn value(self) -> f64 {
            self.0.as_array()[0] as f64
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
        fn mask(self, cmp: Cmp) -> $v {
            let x = self.0;
            match cmp {
                Cmp::Lt(c) => x.simd_lt($v::splat(thresholds::up::<$f>(c))),
                Cmp::Le(c) => x.simd_le($v::splat(thresholds::down::<$f>(c))),
                Cmp::Gt(c) => x.simd_gt($v::splat(thresholds::down::<$f>(c))),
                Cmp::Ge(c) => x.simd_ge($v::splat(thresholds::up::<$f>(c))),
                Cmp::Eq(c) => match thresholds::exact::<$f>(c) {
                    Some(c) => x.simd_eq($v::splat(c)),
                    None => $v::splat(0.0),
                },
                Cmp::Ne(c) => match thresholds::exact::<$f>(c) {
                    Some(c) => x.simd_ne($v::splat(c)),
                    None => x.simd_eq(x) | x.simd_ne(x),
                },
                Cmp::AbsGt(c) => x.abs().simd_gt($v::splat(thresholds::down::<$f>(c))),
            }
        }
        #[inline(always)]
        fn blend(m: $v, a: Self, b: Self) -> Self {
            $t(m.select(a.0, b.0))
        }
        #[inline(always)]
        fn mask_all(m: $v) -> bool {
            m.all()
        }
        #[inline(always)]
        fn mask_any(m: $v) -> bool {
            m.any()
        }
        #[inline(always)]
        fn abs(self) -> Self {
            // (As `x < 0 ? −x : x`, so −0 stays −0 like the scalar code's lanes always did.)
            Self::blend(self.mask(Cmp::Lt(0.0)), -self, self)
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            $t(self.0.simd_ge(o.0).select(self.0, o.0))
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            $t(self.0.simd_le(o.0).select(self.0, o.0))
        }
        #[inline]
        fn is_finite(self) -> bool {
            self.0.is_finite().all()
        }
        /// Correctly rounded, as `libm`'s square root.
        #[inline(always)]
        fn sqrt(self) -> Self {
            $t(self.0.sqrt())
        }
        #[inline]
        fn sin(self) -> Self {
            self.map(libm::$sin)
        }
        #[inline]
        fn cos(self) -> Self {
            self.map(libm::$cos)
        }
        #[inline]
        fn tan(self) -> Self {
            self.map(libm::$tan)
        }
        #[inline]
        fn acos(self) -> Self {
            self.map(libm::$acos)
        }
        #[inline]
        fn asin(self) -> Self {
            self.map(libm::$asin)
        }
        #[inline]
        fn atan(self) -> Self {
            self.map(libm::$atan)
        }
        #[inline]
        fn atan2(self, x: Self) -> Self {
            self.zip(x, libm::$atan2)
        }
        #[inline]
        fn powf(self, e: Self) -> Self {
            self.zip(e, libm::$pow)
        }
        #[inline]
        fn powi(self, n: i32) -> Self {
            self.map(|x| libm::$pow(x, n as $f))
        }
    };
}

/// Constants of a [`Cmp`] in the lane type, chosen so that comparing a lane with them gives
/// what comparing the lane's value in `f64` with the constant gives (as the scalar types do).
mod thresholds {
    /// A float type the thresholds are computed for.
    pub(super) trait Float: Copy {
        /// `c` rounded to the nearest value of this type.
        fn near(c: f64) -> Self;
        /// As `f64` (exact).
        fn wide(self) -> f64;
        /// The next value below.
        fn below(self) -> Self;
        /// The next value above.
        fn above(self) -> Self;
    }
    impl Float for f64 {
        #[inline(always)]
        fn near(c: f64) -> f64 {
            c
        }
        #[inline(always)]
        fn wide(self) -> f64 {
            self
        }
        #[inline(always)]
        fn below(self) -> f64 {
            self
        }
        #[inline(always)]
        fn above(self) -> f64 {
            self
        }
    }
    impl Float for f32 {
        #[inline(always)]
        fn near(c: f64) -> f32 {
            c as f32
        }
        #[inline(always)]
        fn wide(self) -> f64 {
            self as f64
        }
        #[inline(always)]
        fn below(self) -> f32 {
            self.next_down()
        }
        #[inline(always)]
        fn above(self) -> f32 {
            self.next_up()
        }
    }
    /// The largest value ≤ `c`: `x > c ⇔ x > down(c)` and `x ≤ c ⇔ x ≤ down(c)`.
    #[inline(always)]
    pub(super) fn down<F: Float>(c: f64) -> F {
        let f = F::near(c);
        if f.wide() > c {
            f.below()
        } else {
            f
        }
    }
    /// The smallest value ≥ `c`: `x < c ⇔ x < up(c)` and `x ≥ c ⇔ x ≥ up(c)`.
    #[inline(always)]
    pub(super) fn up<F: Float>(c: f64) -> F {
        let f = F::near(c);
        if f.wide() < c {
            f.above()
        } else {
            f
        }
    }
    /// `c` when this type holds it exactly.
    #[inline(always)]
    pub(super) fn exact<F: Float>(c: f64) -> Option<F> {
        let f = F::near(c);
        (f.wide() == c).then_some(f)
    }
}

impl Real for F64x4 {
    vector_real_common!(F64x4, f64, f64x4, sin, cos, tan, acos, asin, atan, atan2, pow);
    #[inline(always)]
    fn exp(self) -> Self {
        exp4(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        ln4(self)
    }
    #[inline]
    fn e1(self) -> Self {
        e1_with_exp4(self, exp4(-self))
    }
    #[inline(always)]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = exp4(-self);
        (e1_with_exp4(self, ex), ex)
    }
}

impl Real for F32x8 {
    vector_real_common!(F32x8, f32, f32x8, sinf, cosf, tanf, acosf, asinf, atanf, atan2f, powf);
    #[inline(always)]
    fn exp(self) -> Self {
        expf8(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        logf8(self)
    }
    #[inline]
    fn e1(self) -> Self {
        e1_with_exp8(self, expf8(-self))
    }
    #[inline(always)]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = expf8(-self);
        (e1_with_exp8(self, ex), ex)
    }
}
