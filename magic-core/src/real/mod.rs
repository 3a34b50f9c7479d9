//! The scalar the physics is written against.
//!
//! Every forward model in this crate (Mogi, PROSPECT-D, 4SAIL, INFORM) is generic over [`Real`], so
//! one piece of code serves three purposes:
//!
//! * `f32` — the microcontroller path (hardware single precision on a Cortex-M4F);
//! * `f64` — the host path, held to the reference outputs to 1e-9;
//! * [`Dual<N>`] — forward-mode automatic differentiation: a value with `N` exact partial
//!   derivatives, so a model evaluated on duals returns its Jacobian with no finite differences.
//!
//! Branches in the physics (numerical guards, series switches) look at [`Real::value`], the primal
//! value, so all three scalars take the same branch for the same input.
//!
//! The lane types of [`lanes`] ([`F64x4`], [`F64x8`], [`F32x8`], [`F32x16`]) are `Real`s too:
//! several independent values computed together, which is how INFORM evaluates several
//! wavelengths per call. Code that may run on lanes branches through [`Real::select`], where each
//! lane takes its own branch.

mod dual;
mod e1;
pub mod lanes;
pub mod sin_cos;
pub mod sqrt;

pub use dual::Dual;
pub use e1::{
    e1_f32, e1_f64, e1_with_exp, e1_with_exp_f32, E1_F32_MAX_REL_ERROR, E1_MAX_REL_ERROR,
};
pub use lanes::{DualScalar, F32x16, F32x8, F64x4, F64x8, Lanes};

use core::fmt::Debug;

/// A comparison of a value with a constant: what [`Real::mask`] and [`Real::select`] test (for
/// lanes: every lane, with one vector comparison). Scalars compare their `f64` value; lanes of
/// `f32` compare with constants chosen so that the answer is the same.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cmp {
    /// `v < c`.
    Lt(f64),
    /// `v ≤ c`.
    Le(f64),
    /// `v > c`.
    Gt(f64),
    /// `v ≥ c`.
    Ge(f64),
    /// `v = c`.
    Eq(f64),
    /// `v ≠ c` (true for NaN).
    Ne(f64),
    /// `|v| > c`.
    AbsGt(f64),
}

impl Cmp {
    /// Whether `v` passes.
    ///
    /// ```
    /// use magic_core::real::Cmp;
    /// assert!(Cmp::AbsGt(1e-3).test(-0.5) && !Cmp::Gt(0.0).test(f64::NAN));
    /// ```
    #[inline(always)]
    pub fn test(self, v: f64) -> bool {
        match self {
            Cmp::Lt(c) => v < c,
            Cmp::Le(c) => v <= c,
            Cmp::Gt(c) => v > c,
            Cmp::Ge(c) => v >= c,
            Cmp::Eq(c) => v == c,
            Cmp::Ne(c) => v != c,
            Cmp::AbsGt(c) => libm::fabs(v) > c,
        }
    }
}
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real scalar: `f32`, `f64` or a forward-mode [`Dual`] number.
pub trait Real:
    Copy
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
{
    /// The same kind of number without derivatives, for constants that multiply it (table values,
    /// precomputed factors): `f64` for `f64` and [`Dual`], `f32` for `f32`, the lanes themselves
    /// for lanes.
    type Plain: Real;
    /// Several values of this type computed together: on targets with SIMD (x86-64, AArch64)
    /// [`F64x8`] for `f64`, [`F32x16`] for `f32`, duals on [`F64x4`] for duals on `f64`; elsewhere
    /// (the Cortex-M4F) each type is its own single lane, as lanes are for themselves.
    type Lanes: Lanes<Self>;

    /// Which values pass a comparison ([`Real::mask`]): a `bool` for scalars and duals on them,
    /// one all-ones or all-zeros pattern per lane for lanes.
    type Mask: Copy;

    /// A constant (derivatives zero).
    fn c(v: f64) -> Self;
    /// A constant given in both precisions, `v` and `v_f32` = `v as f32` (a table rounded when
    /// compiled): `c(v)`, except for `f32`, which takes `v_f32` as it is. The same value either
    /// way; on the Cortex-M4F the conversion `c(v)` makes at run time is a software call (about
    /// thirty instructions) wherever the compiler cannot fold it, as in a loop over a table.
    ///
    /// ```
    /// use magic_core::Real;
    /// const V: f64 = 1.0 / 3.0;
    /// assert_eq!(<f32 as Real>::c_pair(V, V as f32), <f32 as Real>::c(V));
    /// assert_eq!(<f64 as Real>::c_pair(V, V as f32), V);
    /// ```
    #[inline(always)]
    fn c_pair(v: f64, v_f32: f32) -> Self {
        let _ = v_f32;
        Self::c(v)
    }
    /// A constant from an `f32` (a model file's parameter): `c(v as f64)`, exact in every type,
    /// and for `f32` the value itself, without the round trip through `f64`.
    #[inline(always)]
    fn c_f32(v: f32) -> Self {
        Self::c(v as f64)
    }
    /// `self − ⌊self⌋`, exactly, for |self| < 2³¹, by comparisons with powers of two
    /// ([`sin_cos::fraction_by_powers`]);
    /// `f32` computes the same value from a conversion to an integer, which the Cortex-M4F does
    /// in one instruction (the powers of two cost it about 370 instructions per call).
    #[inline(always)]
    fn fraction(self) -> Self {
        sin_cos::fraction_by_powers(self)
    }
    /// `self · k` for a plain factor `k`; for a dual this scales the derivatives, where
    /// `self * Self::from_plain(k)` would apply the product rule to zero derivatives.
    fn scale(self, k: Self::Plain) -> Self;
    /// A plain value as a constant of this type.
    fn from_plain(k: Self::Plain) -> Self;
    /// Where `cmp` holds for the primal value (lane by lane for lanes).
    fn mask(self, cmp: Cmp) -> Self::Mask;
    /// `a` where `m` is set, else `b` (lane by lane for lanes; derivatives follow their value).
    fn blend(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Whether every lane of `m` is set (a scalar's mask: whether it is set).
    fn mask_all(m: Self::Mask) -> bool;
    /// Whether some lane of `m` is set.
    fn mask_any(m: Self::Mask) -> bool;
    /// `a()` where `cmp` holds for the value, else `b()` — by the primal value for scalars and duals
    /// (only the chosen branch is evaluated), lane by lane for lanes (a branch is evaluated when
    /// some lane takes it, and the lanes are blended by one mask). Physics that may run on lanes
    /// branches this way rather than on [`Real::value`].
    #[inline(always)]
    fn select(self, cmp: Cmp, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self {
        let m = self.mask(cmp);
        if Self::mask_all(m) {
            a()
        } else if !Self::mask_any(m) {
            b()
        } else {
            Self::blend(m, a(), b())
        }
    }
    /// Whether `cmp` holds for the value (for lanes: for every lane).
    #[inline(always)]
    fn all(self, cmp: Cmp) -> bool {
        Self::mask_all(self.mask(cmp))
    }
    /// Whether `cmp` holds for the value (for lanes: for some lane).
    #[inline(always)]
    fn any(self, cmp: Cmp) -> bool {
        Self::mask_any(self.mask(cmp))
    }
    /// The primal value as `f64` (for branching and reporting).
    fn value(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Natural exponential.
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// Tangent (radians).
    fn tan(self) -> Self;
    /// Arc cosine (radians).
    fn acos(self) -> Self;
    /// Arc sine (radians).
    fn asin(self) -> Self;
    /// Arc tangent (radians).
    fn atan(self) -> Self;
    /// Four-quadrant arc tangent of `self / x`.
    fn atan2(self, x: Self) -> Self;
    /// `self` raised to a real power (`self > 0`).
    fn powf(self, e: Self) -> Self;
    /// `self` raised to an integer power.
    fn powi(self, n: i32) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// The exponential integral E1(x) = ∫₁^∞ e^(−xt)/t dt for x > 0 (derivative −e^(−x)/x).
    fn e1(self) -> Self;
    /// `(E1(x), e^(−x))`: E1 needs e^(−x) for x > 1, so callers that use both get them together.
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        (self.e1(), (-self).exp())
    }

    /// Zero.
    #[inline]
    fn zero() -> Self {
        Self::c(0.0)
    }
    /// One.
    #[inline]
    fn one() -> Self {
        Self::c(1.0)
    }
    /// Whether the value (and every derivative, for duals) is finite.
    fn is_finite(self) -> bool;
    /// The larger of two values (by primal value).
    #[inline]
    fn max(self, o: Self) -> Self {
        if self.value() >= o.value() {
            self
        } else {
            o
        }
    }
    /// The smaller of two values (by primal value).
    #[inline]
    fn min(self, o: Self) -> Self {
        if self.value() <= o.value() {
            self
        } else {
            o
        }
    }
    /// The square.
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
}

/// The mask items of [`Real`] for a plain scalar: a `bool`.
macro_rules! scalar_mask {
    () => {
        #[inline(always)]
        fn mask(self, cmp: Cmp) -> bool {
            cmp.test(self.value())
        }
        #[inline(always)]
        fn blend(m: bool, a: Self, b: Self) -> Self {
            if m {
                a
            } else {
                b
            }
        }
        #[inline(always)]
        fn mask_all(m: bool) -> bool {
            m
        }
        #[inline(always)]
        fn mask_any(m: bool) -> bool {
            m
        }
    };
}

impl Real for f64 {
    type Plain = f64;
    type Lanes = lanes::LanesF64;
    type Mask = bool;
    scalar_mask!();
    #[inline]
    fn c(v: f64) -> Self {
        v
    }
    #[inline]
    fn scale(self, k: f64) -> Self {
        self * k
    }
    #[inline]
    fn from_plain(k: f64) -> Self {
        k
    }
    #[inline]
    fn value(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    #[inline]
    fn ln(self) -> Self {
        libm::log(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    #[inline]
    fn tan(self) -> Self {
        libm::tan(self)
    }
    #[inline]
    fn acos(self) -> Self {
        libm::acos(self)
    }
    #[inline]
    fn asin(self) -> Self {
        libm::asin(self)
    }
    #[inline]
    fn atan(self) -> Self {
        libm::atan(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2(self, x)
    }
    #[inline]
    fn powf(self, e: Self) -> Self {
        libm::pow(self, e)
    }
    #[inline]
    fn powi(self, n: i32) -> Self {
        libm::pow(self, n as f64)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn e1(self) -> Self {
        e1_f64(self)
    }
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = libm::exp(-self);
        (e1_with_exp(self, ex), ex)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
}

impl Real for f32 {
    type Plain = f32;
    type Lanes = lanes::LanesF32;
    type Mask = bool;
    scalar_mask!();
    #[inline]
    fn c(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn c_pair(_: f64, v_f32: f32) -> Self {
        v_f32
    }
    #[inline(always)]
    fn c_f32(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn fraction(self) -> Self {
        sin_cos::fraction_f32(self)
    }
    #[inline]
    fn scale(self, k: f32) -> Self {
        self * k
    }
    #[inline]
    fn from_plain(k: f32) -> Self {
        k
    }
    #[inline]
    fn value(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::expf(self)
    }
    #[inline]
    fn ln(self) -> Self {
        libm::logf(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sinf(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cosf(self)
    }
    #[inline]
    fn tan(self) -> Self {
        libm::tanf(self)
    }
    #[inline]
    fn acos(self) -> Self {
        libm::acosf(self)
    }
    #[inline]
    fn asin(self) -> Self {
        libm::asinf(self)
    }
    #[inline]
    fn atan(self) -> Self {
        libm::atanf(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2f(self, x)
    }
    #[inline]
    fn powf(self, e: Self) -> Self {
        libm::powf(self, e)
    }
    #[inline]
    fn powi(self, n: i32) -> Self {
        libm::powf(self, n as f32)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn e1(self) -> Self {
        e1_f32(self)
    }
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = libm::expf(-self);
        (e1_with_exp_f32(self, ex), ex)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
}
