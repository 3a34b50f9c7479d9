//! The square root the physics calls, `√x` in any [`Real`]: on the board (feature `dsp`, ARM)
//! the f32 case is the FPU's `VSQRT.F32` instead of libm's software `sqrtf`.
//!
//! Both are IEEE 754 square roots, correctly rounded: the result is the representable number
//! nearest to √x, within [`SQRT_MAX_ERROR_ULP`] of it, which the tests check on the host against
//! 40-digit test vectors in f32 and f64. `VSQRT.F32` being correctly rounded too, the board
//! computes the same bits (the firmware tests compare its inversions with the host's).

use super::Real;

/// Largest error of [`sqrt`], in units in the last place of the result: correctly rounded.
pub const SQRT_MAX_ERROR_ULP: f64 = 0.5;

/// `√x` in `R`. With the `dsp` feature on ARM (the firmware) the f32 case runs the FPU's
/// `VSQRT.F32` (bit-identical to libm's correctly rounded `sqrtf`, a software routine there):
/// `R` is f32 exactly when it is 4 bytes wide (f64 and the dual numbers are wider), and for f32
/// the conversions through `value` and `c` are identities. Elsewhere `R::sqrt`.
#[inline(always)]
pub fn sqrt<R: Real>(x: R) -> R {
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    if core::mem::size_of::<R>() == 4 {
        return R::c(crate::quant::dsp::sqrt_f32(x.value() as f32) as f64);
    }
    x.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `(x, √x)`, x exact in f32, √x to 21 digits (mpmath, 50 digits). Squared distances of the
    /// Mogi model (km²) lie around 1 to 1e4; the extremes check the whole f32 range.
    #[allow(clippy::excessive_precision, clippy::approx_constant)]
    const TEST_VECTORS: [(f64, f64); 12] = [
        (0.25, 5.0e-1),
        (2.0, 1.4142135623730950488),
        (3.0, 1.73205080756887729353),
        (10.0, 3.162277660168379332),
        (0.10000000149011612, 3.16227768372918382116e-1),
        (9.999999974752427e-07, 9.99999998737621353142e-4),
        (36.5, 6.04152298679728603414),
        (12345.677734375, 1.11111105360242906729e+2),
        (60200000.0, 7.75886589650832926419e+3),
        (1.0000000150474662e+30, 1.00000000752373308164e+15),
        (1.1754943508222875e-38, 1.08420217248550443401e-19),
        (3.3999999521443642e+38, 1.84390887848189620053e+19),
    ];

    /// The distance of `got` from `want` in ulps of `got` (`ulp` the spacing at `got`).
    fn ulps(got: f64, want: f64, ulp: f64) -> f64 {
        (got - want).abs() / ulp
    }

    #[test]
    fn correctly_rounded_on_the_test_vectors() {
        for (x, want) in TEST_VECTORS {
            // In f64 the 21-digit value read as f64 is the correctly rounded root itself.
            assert_eq!(sqrt(x), want, "f64 √{x}");
            let r32 = sqrt(x as f32);
            let ulp32 = (f32::from_bits(r32.to_bits() + 1) - r32) as f64;
            assert!(
                ulps(r32 as f64, want, ulp32) <= SQRT_MAX_ERROR_ULP,
                "f32 √{x}"
            );
        }
        assert_eq!(sqrt(0.0f32), 0.0);
        assert!(sqrt(-1.0f32).is_nan() && sqrt(f64::NAN).is_nan());
    }
}
