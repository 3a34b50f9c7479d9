//! SIMD lanes: several independent values of one scalar type computed together.
//!
//! [`F64x4`] and [`F32x8`] (one 256-bit register each) are [`Real`]s whose every
//! operation acts lane by lane, so physics written once as scalar code runs on several independent
//! inputs at a time (INFORM evaluates several wavelengths per call). The element-wise arithmetic
//! compiles to SIMD instructions (two SSE2 operations per operation on the baseline x86-64 target,
//! one with AVX); `exp`, `ln` and E1 are evaluated for all lanes at once; the other functions go
//! lane by lane through `libm`. Branches are masks and blends ([`Real::mask`], [`Real::blend`]).
//!
//! [`F64x8`] and [`F32x16`] are two registers evaluated side by side: the lanes of
//! `f64` and of `f32` ([`Real::Lanes`]). Duals, whose derivatives already fill the registers, use
//! one register ([`DualScalar`]). These lanes are used on targets with SIMD (x86-64, AArch64); on
//! others (the Cortex-M4F) every type is its own single lane, which there runs faster and is much
//! smaller.
//!
//! Every lane of an `F64x4` result equals, bit for bit, the `f64` result of the same operation
//! on that lane (same operations in the same order; `exp`, `ln` and E1 follow the scalar
//! algorithms step by step). The same holds for `F32x8` and `f32`.
//!
//! Lanes have no single value to branch on: code that may run on lanes branches through
//! [`Real::select`] (each lane takes its own branch), never on [`Real::value`], which for lanes
//! reports lane 0 only — correct when all lanes are equal, as for constants broadcast with
//! [`Lanes::splat`].

mod e1x4;
mod e1x8;
mod libm32;
mod libm64;
mod pair;
mod vector;

pub use pair::{F32x16, F64x8};
pub use vector::{F32x8, F64x4};

use super::Real;

/// A batch of values of scalar `S` computed together (the lane types of this module for `f64` and
/// `f32`), or a scalar itself (one lane) for types such as [`super::Dual`] that carry their own
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
/// duals on it are evaluated in (one register: a dual carries a vector per derivative).
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
impl DualScalar for F32x8 {
    type DualLanes = F32x8;
}
impl DualScalar for F64x8 {
    type DualLanes = F64x8;
}
impl DualScalar for F32x16 {
    type DualLanes = F32x16;
}

/// Items for targets that compute lanes with SIMD instructions (x86-64, AArch64). Elsewhere (the
/// Cortex-M4F) lanes would only multiply the code (and, for `f64`, the soft-float calls): every
/// type is then its own single lane.
macro_rules! simd_target {
    ($($item:item)*) => {
        $(#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))] $item)*
    };
}
/// Items for the other targets (see `simd_target`).
macro_rules! scalar_target {
    ($($item:item)*) => {
        $(#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))] $item)*
    };
}

simd_target! {
    /// The lanes of `f64` ([`Real::Lanes`]): [`F64x8`] on SIMD targets, `f64` elsewhere.
    pub type LanesF64 = F64x8;
    /// The lanes of `f32`: [`F32x16`] on SIMD targets, `f32` elsewhere.
    pub type LanesF32 = F32x16;
    /// The lanes of duals on `f64`: [`F64x4`] on SIMD targets, `f64` elsewhere.
    pub type DualLanesF64 = F64x4;
    /// The lanes of duals on `f32`: [`F32x8`] on SIMD targets, `f32` elsewhere.
    pub type DualLanesF32 = F32x8;
}
scalar_target! {
    /// The lanes of `f64` ([`Real::Lanes`]): [`F64x8`] on SIMD targets, `f64` elsewhere.
    pub type LanesF64 = f64;
    /// The lanes of `f32`: [`F32x16`] on SIMD targets, `f32` elsewhere.
    pub type LanesF32 = f32;
    /// The lanes of duals on `f64`: [`F64x4`] on SIMD targets, `f64` elsewhere.
    pub type DualLanesF64 = f64;
    /// The lanes of duals on `f32`: [`F32x8`] on SIMD targets, `f32` elsewhere.
    pub type DualLanesF32 = f32;
}

/// A plain float is also a batch of one: lanes of a single value.
macro_rules! single_lane {
    ($f:ty) => {
        impl Lanes<$f> for $f {
            const WIDTH: usize = 1;
            #[inline(always)]
            fn splat(v: $f) -> Self {
                v
            }
            #[inline(always)]
            fn lane(self, _i: usize) -> $f {
                self
            }
            #[inline(always)]
            fn plain_from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                f(0) as $f
            }
        }
    };
}
single_lane!(f64);
single_lane!(f32);

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::real::Cmp;

    /// A deterministic spread of arguments (xorshift), scaled into `[lo, hi]`.
    pub(crate) fn spread(n: usize, lo: f64, hi: f64) -> impl Iterator<Item = f64> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        (0..n).map(move |_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
        })
    }

    /// Checks the lane function `f` against the scalar `g` on every value of `xs` (rounded to
    /// `S`), a batch of lanes at a time: bit for bit, or both NaN.
    pub(crate) fn check_lanes<S: Real, L: Lanes<S> + Real<Plain = L>>(
        f: impl Fn(L) -> L,
        g: impl Fn(S) -> S,
        xs: impl Iterator<Item = f64>,
    ) {
        let w = L::WIDTH;
        let mut buf = [0.0f64; 16];
        let mut n = 0;
        let check = |buf: &[f64; 16], n: usize| {
            // Lanes past `n` repeat the first value.
            let x = L::plain_from_fn(|j| buf[if j < n { j } else { 0 }]);
            let y = f(x);
            for (j, &xj) in buf.iter().enumerate().take(n) {
                let (got, want) = (y.lane(j).value(), g(S::c(xj)).value());
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "x {xj:e}: {got:e} vs {want:e}"
                );
            }
        };
        for x in xs {
            buf[n] = x;
            n += 1;
            if n == w {
                check(&buf, n);
                n = 0;
            }
        }
        if n > 0 {
            check(&buf, n);
        }
    }

    #[test]
    fn lanes_follow_their_own_branches() {
        let x = F64x4::new([-1.0, 0.5, 2.0, -0.0]);
        let y = x.select(Cmp::Gt(0.0), || x.sqrt(), || F64x4::c(7.0));
        assert_eq!(y.to_array(), [7.0, libm::sqrt(0.5), libm::sqrt(2.0), 7.0]);
        assert_eq!(x.abs().to_array(), [1.0, 0.5, 2.0, 0.0]);
        assert_eq!(x.max(F64x4::c(0.25)).to_array(), [0.25, 0.5, 2.0, 0.25]);
        assert!(F64x4::new([1.0, 2.0, 3.0, 4.0]) < F64x4::c(5.0));
        assert_eq!(
            F64x4::new([1.0, 6.0, 3.0, 4.0]).partial_cmp(&F64x4::c(5.0)),
            None
        );
        let f = F32x8::new([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert_eq!(
            (f * f - f).to_array(),
            [0.0, 2.0, 6.0, 12.0, 20.0, 30.0, 42.0, 56.0]
        );
        assert_eq!(<F32x8 as Lanes<f32>>::lane(f.exp(), 2), libm::expf(3.0));
        assert_eq!(
            <F32x8 as Lanes<f32>>::lane(f.e1(), 6),
            crate::real::e1_f64(7.0) as f32
        );
        let p = <F64x4 as Lanes<f64>>::plain_from_fn(|i| i as f64);
        assert_eq!(p.to_array(), [0.0, 1.0, 2.0, 3.0]);
        assert!(x.any(Cmp::Gt(1.0)) && !x.all(Cmp::Gt(1.0)));
        let m = f.mask(Cmp::Gt(4.5));
        assert_eq!(F32x8::blend(m, f, -f).to_array()[3..5], [-4.0, 5.0]);
        // Constants an f32 cannot hold compare as the f64 value does: 0.1f32 > 0.1.
        let t = F32x8::c(0.1);
        assert!(t.all(Cmp::Gt(0.1)) && !t.any(Cmp::Le(0.1)) && !t.any(Cmp::Eq(0.1)));
        assert_eq!(t.all(Cmp::Gt(0.1)), 0.1f32.mask(Cmp::Gt(0.1)));
    }

    #[test]
    fn two_registers_are_two_halves() {
        let x = <F64x8 as Lanes<f64>>::plain_from_fn(|i| i as f64 * 0.7 - 2.0);
        let y = x.select(Cmp::Gt(0.0), || x.ln(), || x.exp());
        for i in 0..8 {
            let xi = i as f64 * 0.7 - 2.0;
            let want = if xi > 0.0 {
                libm::log(xi)
            } else {
                libm::exp(xi)
            };
            assert_eq!(<F64x8 as Lanes<f64>>::lane(y, i).to_bits(), want.to_bits());
        }
        assert!(x.any(Cmp::Gt(2.0)) && !x.all(Cmp::Gt(2.0)));
        let m = x.max(F64x8::c(0.1));
        for i in 0..8 {
            let xi = i as f64 * 0.7 - 2.0;
            assert_eq!(<F64x8 as Lanes<f64>>::lane(m, i), xi.max(0.1));
        }
        let z = <F32x16 as Lanes<f32>>::plain_from_fn(|i| i as f64 * 0.3 + 0.1);
        let (e1, ex) = z.e1_and_exp();
        for i in 0..16 {
            let zi = (i as f64 * 0.3 + 0.1) as f32;
            let (e, x) = zi.e1_and_exp();
            assert_eq!(<F32x16 as Lanes<f32>>::lane(e1, i).to_bits(), e.to_bits());
            assert_eq!(<F32x16 as Lanes<f32>>::lane(ex, i).to_bits(), x.to_bits());
            assert_eq!(<F32x16 as Lanes<f32>>::lane(z.ln(), i), libm::logf(zi));
        }
    }
}
