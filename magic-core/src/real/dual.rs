//! Forward-mode dual numbers: a value and `N` exact partial derivatives.

use super::{e1_f64, e1_with_exp, Lanes, Real};
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A forward-mode dual number `v + Σ dᵢ εᵢ` with `N` independent infinitesimals.
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
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// The partial derivatives.
    pub d: [f64; N],
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
    /// Applies the chain rule for a scalar function with value `f` and derivative `df` at `self.v`.
    #[inline]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut d = self.d;
        for x in d.iter_mut() {
            *x *= df;
        }
        Dual { v: f, d }
    }
}

impl<const N: usize> PartialOrd for Dual<N> {
    #[inline]
    fn partial_cmp(&self, o: &Self) -> Option<core::cmp::Ordering> {
        self.v.partial_cmp(&o.v)
    }
}

impl<const N: usize> Add for Dual<N> {
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

impl<const N: usize> Sub for Dual<N> {
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

impl<const N: usize> Mul for Dual<N> {
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

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline]
    fn div(mut self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let q = self.v * inv;
        for (a, b) in self.d.iter_mut().zip(o.d.iter()) {
            *a = (*a - q * *b) * inv;
        }
        self.v = q;
        self
    }
}

impl<const N: usize> Neg for Dual<N> {
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
        impl<const N: usize> $tr for Dual<N> {
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

impl<const N: usize> Real for Dual<N> {
    type Plain = f64;
    type Lanes = Self;
    #[inline]
    fn c(v: f64) -> Self {
        Self::constant(v)
    }
    #[inline]
    fn scale(mut self, k: f64) -> Self {
        self.v *= k;
        for a in self.d.iter_mut() {
            *a *= k;
        }
        self
    }
    #[inline]
    fn from_plain(k: f64) -> Self {
        Self::constant(k)
    }
    #[inline]
    fn apply(self, f: impl Fn(f64) -> (f64, f64)) -> Self {
        let (g, dg) = f(self.v);
        self.chain(g, dg)
    }
    #[inline]
    fn value(self) -> f64 {
        self.v
    }
    #[inline]
    fn sqrt(self) -> Self {
        let s = libm::sqrt(self.v);
        self.chain(s, 0.5 / s)
    }
    #[inline]
    fn exp(self) -> Self {
        let e = libm::exp(self.v);
        self.chain(e, e)
    }
    #[inline]
    fn ln(self) -> Self {
        self.chain(libm::log(self.v), 1.0 / self.v)
    }
    #[inline]
    fn sin(self) -> Self {
        self.chain(libm::sin(self.v), libm::cos(self.v))
    }
    #[inline]
    fn cos(self) -> Self {
        self.chain(libm::cos(self.v), -libm::sin(self.v))
    }
    #[inline]
    fn tan(self) -> Self {
        let t = libm::tan(self.v);
        self.chain(t, 1.0 + t * t)
    }
    #[inline]
    fn acos(self) -> Self {
        self.chain(libm::acos(self.v), -1.0 / libm::sqrt(1.0 - self.v * self.v))
    }
    #[inline]
    fn asin(self) -> Self {
        self.chain(libm::asin(self.v), 1.0 / libm::sqrt(1.0 - self.v * self.v))
    }
    #[inline]
    fn atan(self) -> Self {
        self.chain(libm::atan(self.v), 1.0 / (1.0 + self.v * self.v))
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        // d atan2(y, x) = (x dy − y dx) / (x² + y²)
        let r2 = self.v * self.v + x.v * x.v;
        let mut d = [0.0; N];
        for (i, slot) in d.iter_mut().enumerate() {
            *slot = (x.v * self.d[i] - self.v * x.d[i]) / r2;
        }
        Dual {
            v: libm::atan2(self.v, x.v),
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
        let p = libm::pow(self.v, n as f64);
        let dp = if n == 0 {
            0.0
        } else {
            n as f64 * libm::pow(self.v, (n - 1) as f64)
        };
        self.chain(p, dp)
    }
    #[inline]
    fn abs(self) -> Self {
        if self.v < 0.0 {
            -self
        } else {
            self
        }
    }
    #[inline]
    fn e1(self) -> Self {
        self.chain(e1_f64(self.v), -libm::exp(-self.v) / self.v)
    }
    #[inline]
    fn e1_and_exp(self) -> (Self, Self) {
        let ex = libm::exp(-self.v);
        let e1 = e1_with_exp(self.v, ex);
        (self.chain(e1, -ex / self.v), self.chain(ex, -ex))
    }
    #[inline]
    fn is_finite(self) -> bool {
        self.v.is_finite() && self.d.iter().all(|x| x.is_finite())
    }
}

/// A dual is its own single lane: its derivative array is already computed element-wise.
impl<const N: usize> Lanes<Dual<N>> for Dual<N> {
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
    fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> f64 {
        f(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(f: impl Fn(Dual<1>) -> Dual<1>, g: impl Fn(f64) -> f64, x: f64) {
        let d = f(Dual::var(x, 0));
        let h = 1e-6 * (1.0 + libm::fabs(x));
        let fd = (g(x + h) - g(x - h)) / (2.0 * h);
        assert!((d.v - g(x)).abs() < 1e-12 * (1.0 + g(x).abs()));
        assert!(
            (d.d[0] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
            "x={x}: {} vs {fd}",
            d.d[0]
        );
    }

    #[test]
    fn elementary_derivatives_match_central_differences() {
        for &x in &[0.3, 0.7, 1.3, 2.5] {
            check(|v| v.sqrt(), |v| v.sqrt(), x);
            check(|v| v.exp(), |v| v.exp(), x);
            check(|v| v.ln(), |v| v.ln(), x);
            check(|v| v.sin(), |v| v.sin(), x);
            check(|v| v.cos(), |v| v.cos(), x);
            check(|v| v.tan(), |v| v.tan(), x);
            check(|v| v.atan(), |v| v.atan(), x);
            check(|v| v.e1(), e1_f64, x);
            check(|v| v.powi(3), |v| v * v * v, x);
            check(|v| v.powf(Dual::c(1.7)), |v| v.powf(1.7), x);
            check(|v| v / (v + Dual::c(1.0)), |v| v / (v + 1.0), x);
            check(|v| v.atan2(Dual::c(0.4)), |v| v.atan2(0.4), x);
        }
        for &x in &[-0.5, 0.2, 0.8] {
            check(|v| v.acos(), |v| v.acos(), x);
            check(|v| v.asin(), |v| v.asin(), x);
        }
    }

    #[test]
    fn out_of_range_var_is_constant() {
        let c = Dual::<2>::var(1.0, 5);
        assert_eq!(c.d, [0.0, 0.0]);
    }
}
