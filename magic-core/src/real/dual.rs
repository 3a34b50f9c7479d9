//! Forward-mode dual numbers: a value and `N` exact partial derivatives.
//!
//! A dual is built on a plain scalar `T`: `f64` by default, or lanes ([`super::F64x4`]), which
//! make `Dual<N, F64x4>` four duals computed together, stored as one vector per derivative. A
//! dual's [`Real::Lanes`] is that lane form ([`DualScalar`]), so physics evaluated on lanes of
//! wavelengths carries its derivatives the same way.

use super::{Cmp, DualScalar, Lanes, Real};
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A forward-mode dual number `v + Σ dᵢ εᵢ` with `N` independent infinitesimals, on the plain
/// scalar `T` (`f64`, or lanes of it).
///
/// Evaluating a model on `Dual<N>` inputs seeded with [`Dual::var`] gives the model's value and
/// its exact Jacobian column by column.
///
/// ```
/// use magic_core::{Dual, Real};
/// let x = Dual::<2>::var(3.0, 0);
/// let y = Dual::<2>::var(2.0, 1);
/// let f = x * x * y; // f = x²y
/// assert_eq!(f.v, 18.0);
/// assert_eq!(f.d, [12.0, 9.0]); // ∂f/∂x = 2xy, ∂f/∂y = x²
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize, T = f64> {
    /// The value.
    pub v: T,
    /// The partial derivatives.
    pub d: [T; N],
}

impl<const N: usize> Dual<N> {
    /// A constant (all derivatives zero).
    #[inline]
    pub const fn constant(v: f64) -> Self {
        Dual { v, d: [0.0; N] }
    }
    /// The `i`-th independent variable with value `v` (∂/∂xᵢ = 1). An `i ≥ N` gives a constant.
    #[inline]
    pub fn var(v: f64, i: usize) -> Self {
        let mut d = [0.0; N];
        if let Some(slot) = d.get_mut(i) {
            *slot = 1.0;
        }
        Dual { v, d }
    }
}

impl<const N: usize, T: Real<Plain = T>> Dual<N, T> {
    /// The `i`-th independent variable with value `v` on any plain scalar (lanes: every lane).
    #[inline]
    pub fn seed(v: T, i: usize) -> Self {
        let mut d = [T::zero(); N];
        if let Some(slot) = d.get_mut(i) {
            *slot = T::one();
        }
        Dual { v, d }
    }
    /// Applies the chain rule for a scalar function with value `f` and derivative `df` at `self.v`.
    #[inline]
    fn chain(self, f: T, df: T) -> Self {
        let mut d = self.d;
        for x in d.iter_mut() {
            *x *= df;
        }
        Dual { v: f, d }
    }
}

impl<const N: usize, T: PartialOrd> PartialOrd for Dual<N, T> {
    #[inline]
    fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
        self.v.partial_cmp(&o.v)
    }
}

impl<const N: usize, T: Real<Plain = T>> Add for Dual<N, T> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for (a, b) in self.d.iter_mut().zip(o.d.iter()) {
            *a += *b;
        }
        self
    }
}

impl<const N: usize, T: Real<Plain = T>> Sub for Dual<N, T> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: Self) -> Self {
        self.v -= o.v;
        for (a, b) in self.d.iter_mut().zip(o.d.iter()) {
            *a -= *b;
        }
        self
    }
}

impl<const N: usize, T: Real<Plain = T>> Mul for Dual<N, T> {
    type Output = Self;
    #[inline]
    fn mul(mut self, o: Self) -> Self {
        for (a, b) in self.d.iter_mut().zip(o.d.iter()) {
            *a = *a * o.v + self.v * *b;
        }
        self.v *= o.v;
        self
    }
}

impl<const N: usize, T: Real<Plain = T>> Div for Dual<N, T> {
    type Output = Self;
    #[inline]
    fn div(mut self, o: Self) -> Self {
        let inv = T::one() / o.v;
        let q = self.v * inv;
        for (a, b) in self.d.iter_mut().zip(o.d.iter()) {
            *a = (*a - q * *b) * inv;
        }
        self.v = q;
        self
    }
}

impl<const N: usize, T: Real<Plain = T>> Neg for Dual<N, T> {
    type Output = Self;
    #[inline]
    fn neg(mut self) -> Self {
        self.v = -self.v;
        for a in self.d.iter_mut() {
            *a = -*a;
        }
        self
    }
}

macro_rules! assign_op {
    ($tr:ident, $m:ident, $op:tt) => {
        impl<const N: usize, T: Real<Plain = T>> $tr for Dual<N, T> {
            #[inline]
            fn $m(&mut self, o: Self) {
                *self = *self $op o;
            }
        }
    };
}
assign_op!(AddAssign, add_assign, +);
assign_op!(SubAssign, sub_assign, -);
assign_op!(MulAssign, mul_assign, *);
assign_op!(DivAssign, div_assign, /);

impl<const N: usize, T: DualScalar> Real for Dual<N, T> {
    type Plain = T;
    type Lanes = Dual<N, T::DualLanes>;
    type Mask = T::Mask;
    #[inline]
    fn c(v: f64) -> Self {
        Self::from_plain(T::c(v))
    }
    #[inline]
    fn scale(mut self, k: T) -> Self {
        self.v *= k;
        for a in self.d.iter_mut() {
            *a *= k;
        }
        self
    }
    #[inline]
    fn from_plain(k: T) -> Self {
        Dual {
            v: k,
            d: [T::zero(); N],
        }
    }
    #[inline(always)]
    fn mask(self, cmp: Cmp) -> T::Mask {
        self.v.mask(cmp)
    }
    #[inline(always)]
    fn blend(m: T::Mask, a: Self, b: Self) -> Self {
        let mut d = a.d;
        for (x, y) in d.iter_mut().zip(b.d) {
            *x = T::blend(m, *x, y);
        }
        Dual {
            v: T::blend(m, a.v, b.v),
            d,
        }
    }
    #[inline(always)]
    fn mask_all(m: T::Mask) -> bool {
        T::mask_all(m)
    }
    #[inline(always)]
    fn mask_any(m: T::Mask) -> bool {
        T::mask_any(m)
    }
    #[inline]
    fn value(self) -> f64 {
        self.v.value()
    }
    #[inline]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, T::c(0.5) / s)
    }
    #[inline]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    #[inline]
    fn ln(self) -> Self {
        self.chain(self.v.ln(), T::one() / self.v)
    }
    #[inline]
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    #[inline]
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    #[inline]
    fn tan(self) -> Self {
        let t = self.v.tan();
        self.chain(t, T::one() + t * t)
    }
    #[inline]
    fn acos(self) -> Self {
        let one = T::one();
        self.chain(self.v.acos(), -one / (one - self.v * self.v).sqrt())
    }
    #[inline]
    fn asin(self) -> Self {
        let one = T::one();
        self.chain(self.v.asin(), one / (one - self.v * self.v).sqrt())
    }
    #[inline]
    fn atan(self) -> Self {
        let one = T::one();
        self.chain(self.v.atan(), one / (one + self.v * self.v))
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        // d atan2(y, x) = (x dy − y dx) / (x² + y²)
        let r2 = self.v * self.v + x.v * x.v;
        let mut d = [T::zero(); N];
        for (i, slot) in d.iter_mut().enumerate() {
            *slot = (x.v * self.d[i] - self.v * x.d[i]) / r2;
        }
        Dual {
            v: self.v.atan2(x.v),
            d,
        }
    }
    #[inline]
    fn powf(self, e: Self) -> Self {
        // x^e = exp(e ln x)
        (e * self.ln()).exp()
    }
    #[inline]
    fn powi(self, n: i32) -> Self {
        let p = self.v.powi(n);
        let dp = if n == 0 {
            T::zero()
        } else {
            T::c(n as f64) * self.v.powi(n - 1)
        };
        self.chain(p, dp)
    }
    #[inline]
    fn abs(self) -> Self {
        self.select(Cmp::Lt(0.0), || -self, || self)
    }
    #[inline]
    fn max(self, o: Self) -> Self {
        Self::blend((self.v - o.v).mask(Cmp::Ge(0.0)), self, o)
    }
    #[inline]
    fn min(self, o: Self) -> Self {
        Self::blend((self.v - o.v).mask(Cmp::Le(0.0)), self, o)
    }
    #[inline]
    fn e1(self) -> Self {
        self.chain(self.v.e1(), -(-self.v).exp() / self.v)
    }
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        let (e1, ex) = self.v.e1_and_exp();
        (self.chain(e1, -ex / self.v), self.chain(ex, -ex))
    }
    #[inline]
    fn is_finite(self) -> bool {
        self.v.is_finite() && self.d.iter().all(|x| x.is_finite())
    }
}

/// The lane form of a dual: lane `i` holds the value and every derivative of dual `i`.
impl<const N: usize, T: DualScalar> Lanes<Dual<N, T>> for Dual<N, T::DualLanes> {
    const WIDTH: usize = <T::DualLanes as Lanes<T>>::WIDTH;
    #[inline]
    fn splat(x: Dual<N, T>) -> Self {
        Dual {
            v: <T::DualLanes as Lanes<T>>::splat(x.v),
            d: x.d.map(<T::DualLanes as Lanes<T>>::splat),
        }
    }
    #[inline]
    fn lane(self, i: usize) -> Dual<N, T> {
        Dual {
            v: self.v.lane(i),
            d: self.d.map(|x| x.lane(i)),
        }
    }
    #[inline]
    fn plain_from_fn(f: impl FnMut(usize) -> f64) -> T::DualLanes {
        <T::DualLanes as Lanes<T>>::plain_from_fn(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::e1_f64;

    /// A dual's value against the plain function, relative to 1 + |value|: measured 1.6e-16;
    /// about 4 ulps.
    const VALUE_MAX_REL_ERROR: f64 = 1e-15;
    /// A dual's derivative against a central difference (step 1e-6), relative to
    /// 1 + |difference|: measured 6.9e-11, the difference's own error; 10× that.
    const DERIVATIVE_MAX_REL_ERROR: f64 = 7e-10;

    /// Checks one function at `x`; returns the value's and the derivative's relative errors.
    fn check(f: impl Fn(Dual<1>) -> Dual<1>, g: impl Fn(f64) -> f64, x: f64) -> (f64, f64) {
        let d = f(Dual::var(x, 0));
        let h = 1e-6 * (1.0 + libm::fabs(x));
        let fd = (g(x + h) - g(x - h)) / (2.0 * h);
        let value = (d.v - g(x)).abs() / (1.0 + g(x).abs());
        let derivative = (d.d[0] - fd).abs() / (1.0 + fd.abs());
        assert!(value <= VALUE_MAX_REL_ERROR, "x={x}: {} vs {}", d.v, g(x));
        assert!(
            derivative <= DERIVATIVE_MAX_REL_ERROR,
            "x={x}: {} vs {fd}",
            d.d[0]
        );
        (value, derivative)
    }

    #[test]
    fn elementary_derivatives_match_central_differences() {
        extern crate std;
        let (mut value, mut derivative) = (0f64, 0f64);
        let mut worst = |(v, d): (f64, f64)| {
            value = value.max(v);
            derivative = derivative.max(d);
        };
        for &x in &[0.3, 0.7, 1.3, 2.5] {
            worst(check(|v| v.sqrt(), |v| v.sqrt(), x));
            worst(check(|v| v.exp(), |v| v.exp(), x));
            worst(check(|v| v.ln(), |v| v.ln(), x));
            worst(check(|v| v.sin(), |v| v.sin(), x));
            worst(check(|v| v.cos(), |v| v.cos(), x));
            worst(check(|v| v.tan(), |v| v.tan(), x));
            worst(check(|v| v.atan(), |v| v.atan(), x));
            worst(check(|v| v.e1(), e1_f64, x));
            worst(check(|v| v.powi(3), |v| v * v * v, x));
            worst(check(|v| v.powf(Dual::c(1.7)), |v| v.powf(1.7), x));
            worst(check(|v| v / (v + Dual::c(1.0)), |v| v / (v + 1.0), x));
            worst(check(|v| v.atan2(Dual::c(0.4)), |v| v.atan2(0.4), x));
        }
        for &x in &[-0.5, 0.2, 0.8] {
            worst(check(|v| v.acos(), |v| v.acos(), x));
            worst(check(|v| v.asin(), |v| v.asin(), x));
        }
        std::eprintln!("dual numbers: value {value:.2e}, derivative {derivative:.2e} (relative)");
    }

    #[test]
    fn lanes_of_duals_are_duals_lane_by_lane() {
        use crate::real::F64x4;
        let xs = [0.3, 0.7, 1.3, 2.5];
        let x = Dual::<2, F64x4>::seed(F64x4::new(xs), 0);
        let y = Dual::<2, F64x4>::seed(F64x4::new([2.0, -1.0, 0.5, 3.0]), 1);
        let f = |x: Dual<2, F64x4>, y: Dual<2, F64x4>| {
            (x * y).exp() / (x + y.abs()).sqrt() + x.e1_and_exp().0 - x.max(y)
        };
        let g = f(x, y);
        for (i, &xi) in xs.iter().enumerate() {
            let (x1, y1) = (Dual::<2>::var(xi, 0), Dual::<2>::var(y.v.to_array()[i], 1));
            let want = (x1 * y1).exp() / (x1 + y1.abs()).sqrt() + x1.e1_and_exp().0 - x1.max(y1);
            assert_eq!(g.lane(i), want);
        }
        // A select whose lanes disagree takes each lane's own branch, derivatives included.
        let s = x.select(Cmp::Gt(1.0), || x * x, || -x);
        assert_eq!(s.lane(0), -Dual::<2>::var(0.3, 0));
        assert_eq!(s.lane(3), Dual::<2>::var(2.5, 0) * Dual::<2>::var(2.5, 0));
    }

    #[test]
    fn out_of_range_var_is_constant() {
        let c = Dual::<2>::var(1.0, 5);
        assert_eq!(c.d, [0.0, 0.0]);
    }
}
