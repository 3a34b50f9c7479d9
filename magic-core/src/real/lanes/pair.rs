//! Two registers of lanes evaluated side by side: [`F64x8`] (two [`F64x4`]) and [`F32x16`] (two
//! [`F32x8`]).
//!
//! Each operation issues two independent vector instructions, which keeps the processor busy where
//! one register's long dependency chain (INFORM per wavelength is a chain of some thousand cycles)
//! would leave it waiting. Every item acts on both halves; a mask is the pair of the halves'
//! masks.

use super::vector::{F32x8, F64x4};
use super::Lanes;
use crate::real::{Cmp, Real};
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// `$t` holds two halves `$h` of `$w` lanes of `$f` each.
macro_rules! pair {
    ($(#[$doc:meta])* $t:ident, $h:ident, $f:ty, $w:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct $t(pub $h, pub $h);

        impl PartialOrd for $t {
            /// Ordered only when every lane compares the same way.
            #[inline]
            fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
                let a = self.0.partial_cmp(&o.0)?;
                (self.1.partial_cmp(&o.1)? == a).then_some(a)
            }
        }

        pair!(@op $t, Add, add, AddAssign, add_assign, +);
        pair!(@op $t, Sub, sub, SubAssign, sub_assign, -);
        pair!(@op $t, Mul, mul, MulAssign, mul_assign, *);
        pair!(@op $t, Div, div, DivAssign, div_assign, /);

        impl Neg for $t {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                $t(-self.0, -self.1)
            }
        }

        impl Lanes<$t> for $t {
            const WIDTH: usize = 1;
            #[inline(always)]
            fn splat(v: Self) -> Self {
                v
            }
            #[inline(always)]
            fn lane(self, _i: usize) -> Self {
                self
            }
            #[inline(always)]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                Self::c(f(0))
            }
        }

        impl Lanes<$f> for $t {
            const WIDTH: usize = 2 * $w;
            #[inline(always)]
            fn splat(v: $f) -> Self {
                let h = <$h as Lanes<$f>>::splat(v);
                $t(h, h)
            }
            #[inline(always)]
            fn lane(self, i: usize) -> $f {
                if i < $w {
                    self.0.lane(i)
                } else {
                    self.1.lane(i - $w)
                }
            }
            #[inline(always)]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                let a = <$h as Lanes<$f>>::plain_from_fn(&mut f);
                $t(a, <$h as Lanes<$f>>::plain_from_fn(|j| f($w + j)))
            }
        }

        impl Real for $t {
            type Plain = Self;
            type Lanes = Self;
            type Mask = [<$h as Real>::Mask; 2];
            #[inline(always)]
            fn c(v: f64) -> Self {
                $t($h::c(v), $h::c(v))
            }
            /// Lane 0 (meaningful when all lanes are equal).
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
            fn mask(self, cmp: Cmp) -> Self::Mask {
                [self.0.mask(cmp), self.1.mask(cmp)]
            }
            #[inline(always)]
            fn blend(m: Self::Mask, a: Self, b: Self) -> Self {
                $t($h::blend(m[0], a.0, b.0), $h::blend(m[1], a.1, b.1))
            }
            #[inline(always)]
            fn mask_all(m: Self::Mask) -> bool {
                $h::mask_all(m[0]) && $h::mask_all(m[1])
            }
            #[inline(always)]
            fn mask_any(m: Self::Mask) -> bool {
                $h::mask_any(m[0]) || $h::mask_any(m[1])
            }
            pair!(@unary sqrt, exp, ln, sin, cos, tan, acos, asin, atan, abs, e1);
            #[inline(always)]
            fn atan2(self, x: Self) -> Self {
                $t(self.0.atan2(x.0), self.1.atan2(x.1))
            }
            #[inline(always)]
            fn powf(self, e: Self) -> Self {
                $t(self.0.powf(e.0), self.1.powf(e.1))
            }
            #[inline(always)]
            fn powi(self, n: i32) -> Self {
                $t(self.0.powi(n), self.1.powi(n))
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                $t(self.0.max(o.0), self.1.max(o.1))
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                $t(self.0.min(o.0), self.1.min(o.1))
            }
            #[inline(always)]
            fn e1_and_exp(self) -> (Self, Self) {
                let (a, b) = (self.0.e1_and_exp(), self.1.e1_and_exp());
                ($t(a.0, b.0), $t(a.1, b.1))
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                self.0.is_finite() && self.1.is_finite()
            }
        }
    };
    (@op $t:ident, $tr:ident, $m:ident, $tra:ident, $ma:ident, $op:tt) => {
        impl $tr for $t {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                $t(self.0 $op o.0, self.1 $op o.1)
            }
        }
        impl $tra for $t {
            #[inline(always)]
            fn $ma(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
    (@unary $($m:ident),*) => {
        $(
            #[inline(always)]
            fn $m(self) -> Self {
                Self(self.0.$m(), self.1.$m())
            }
        )*
    };
}

pair!(
    /// Eight `f64` lanes: two [`F64x4`] halves.
    F64x8, F64x4, f64, 4
);
pair!(
    /// Sixteen `f32` lanes: two [`F32x8`] halves.
    F32x16, F32x8, f32, 8
);
