//! Sine and cosine of a fraction of a turn, `sin(2πf)` and `cos(2πf)`, in any [`Real`]: the
//! seasonal terms of a GNSS model on the board, where libm's `sinf`/`cosf` would cost their f64
//! argument reduction (soft-float on a Cortex-M4F, about 3 KB of flash) for this one use.
//!
//! The phase enters as a fraction of a turn ([`Real::fraction`] of days / 365.25, exact), so no
//! reduction by π is needed: the nearest quarter turn is taken out by comparisons and the rest,
//! |x| ≤ π/4, goes through fixed Taylor polynomials. [`SIN_COS_TURN_MAX_ERROR_F64`] and
//! [`SIN_COS_TURN_MAX_ERROR_F32`] bound the absolute error, checked in the tests against
//! `TEST_VECTORS` (computed to 50 digits, stored to 21) and on a dense grid against libm.

use super::Real;

const TWO_PI: f64 = core::f64::consts::TAU;

/// Largest absolute error of [`sin_cos_turn`] in `f64`: 1.1e-16 measured on the test vectors,
/// bounded here by about one ulp of 1.0 (2.3× the measurement).
pub const SIN_COS_TURN_MAX_ERROR_F64: f64 = 2.5e-16;

/// Largest absolute error of [`sin_cos_turn`] in `f32`, for phases exact in `f32`: 9.4e-8
/// measured (4 001 phases), 0.8 ε of f32; bounded here by 1.5e-7 (1.6× the measurement).
pub const SIN_COS_TURN_MAX_ERROR_F32: f64 = 1.5e-7;

/// `x − ⌊x⌋` in `R`, exactly, by subtracting powers of two (Sterbenz: each subtraction is exact),
/// for |x| < 2³¹: no conversion to an integer, which for a generic `R` would go through `f64`
/// (soft-float on the board; `f32` converts directly, [`fraction_f32`]).
pub fn fraction_by_powers<R: Real>(x: R) -> R {
    let neg = x < R::zero();
    let mut f = if neg { -x } else { x };
    for k in (0..31).rev() {
        let p = R::c((1u32 << k) as f64);
        if f >= p {
            f -= p;
        }
    }
    if neg && f > R::zero() {
        R::one() - f
    } else {
        f
    }
}

/// [`fraction_by_powers`] for `f32`, bit for bit, by one conversion to an integer where the
/// powers of two would subtract ⌊|x|⌋, that is for |x| < 2³¹ (NaN and larger values take the
/// powers): the truncation of such an `f32` is exact, and so is the difference (Sterbenz again).
/// Zeros keep their sign as there.
#[inline]
pub fn fraction_f32(x: f32) -> f32 {
    let neg = x < 0.0;
    let f = if neg { -x } else { x };
    let small = f < 2_147_483_648.0; // (false for NaN)
    if !small {
        return fraction_by_powers(x);
    }
    let f = f - (f as u32) as f32;
    if neg && f > 0.0 {
        1.0 - f
    } else {
        f
    }
}

/// A table of constants in both precisions, for [`Real::c_pair`].
const fn paired<const N: usize>(v: [f64; N]) -> [(f64, f32); N] {
    let mut out = [(0.0, 0.0); N];
    let mut i = 0;
    while i < N {
        out[i] = (v[i], v[i] as f32);
        i += 1;
    }
    out
}

/// The bounds between quarter turns, and the quarter turns.
const QUARTER_BOUNDS: [(f64, f32); 4] = paired([0.125, 0.375, 0.625, 0.875]);
const QUARTERS: [(f64, f32); 5] = paired([0.0, 0.25, 0.5, 0.75, 1.0]);
/// 1 / ((2k)(2k + 1)), k = 1..=8: the sine's Horner factors.
const S: [(f64, f32); 8] = paired([
    1.0 / 6.0,
    1.0 / 20.0,
    1.0 / 42.0,
    1.0 / 72.0,
    1.0 / 110.0,
    1.0 / 156.0,
    1.0 / 210.0,
    1.0 / 272.0,
]);
/// 1 / ((2k − 1)(2k)), k = 1..=9: the cosine's.
const C: [(f64, f32); 9] = paired([
    1.0 / 2.0,
    1.0 / 12.0,
    1.0 / 30.0,
    1.0 / 56.0,
    1.0 / 90.0,
    1.0 / 132.0,
    1.0 / 182.0,
    1.0 / 240.0,
    1.0 / 306.0,
]);

/// `sin(2πf)` and `cos(2πf)` for a fraction of a turn `f` in [0, 1), in `R`: the nearest quarter
/// turn is taken out, and the rest, |x| ≤ π/4, goes through the Taylor series
/// up to x¹⁷ / x¹⁸ (truncation below 1e-19), evaluated in `R`. No library call: on the board
/// (`R = f32`) libm's `sinf`/`cosf` would bring their f64 argument reduction (about 3 KB of
/// flash) for this one term; on the host (`R = f64`) the result is within a few ulps of libm's.
pub fn sin_cos_turn<R: Real>(f: R) -> (R, R) {
    // The nearest quarter turn, by comparisons (the bounds are exact in binary).
    let q = QUARTER_BOUNDS
        .iter()
        .filter(|&&(b, b32)| f >= R::c_pair(b, b32))
        .count();
    let (quarter, quarter32) = QUARTERS.get(q).copied().unwrap_or((0.0, 0.0));
    let x = R::c(TWO_PI) * (f - R::c_pair(quarter, quarter32));
    let x2 = x * x;
    // Horner on x²: sin x = x (1 − x²/(2·3) (1 − x²/(4·5) (…))), cos x = 1 − x²/(1·2) (…).
    let mut s = R::one();
    for &(k, k32) in S.iter().rev() {
        s = R::one() - x2 * s * R::c_pair(k, k32);
    }
    let mut c = R::one();
    for &(k, k32) in C.iter().rev() {
        c = R::one() - x2 * c * R::c_pair(k, k32);
    }
    let s = x * s;
    match q % 4 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// `(f, sin 2πf, cos 2πf)`, f exact in f32, the values to 21 digits (mpmath, 50 digits).
    #[allow(clippy::excessive_precision, clippy::approx_constant)]
    const TEST_VECTORS: [(f64, f64, f64); 24] = [
        (0.0, 0.0, 1.0),
        (
            9.5367431640625e-07,
            5.99211245264242784288e-6,
            9.99999999982047294177e-1,
        ),
        (
            0.015625,
            9.80171403295606019942e-2,
            9.95184726672196886245e-1,
        ),
        (
            0.10000000149011612,
            5.87785259867036863441e-1,
            8.09016988871704685889e-1,
        ),
        (
            0.123046875,
            6.98376249408972853555e-1,
            7.15730825283818654126e-1,
        ),
        (
            0.12499994039535522,
            7.07106516370038629021e-1,
            7.07107046002957244155e-1,
        ),
        (0.125, 7.07106781186547524401e-1, 7.07106781186547524401e-1),
        (
            0.20000000298023224,
            9.51056522081605218138e-1,
            3.09016976566079887135e-1,
        ),
        (0.25, 1.0, 0.0),
        (
            0.30000001192092896,
            9.51056493149343653256e-1,
            -3.09017065610416488438e-1,
        ),
        (
            0.3740234375,
            7.11432195745216441522e-1,
            -7.02754744457225302453e-1,
        ),
        (0.375, 7.07106781186547524401e-1, -7.07106781186547524401e-1),
        (
            0.4000000059604645,
            5.87785221994217676828e-1,
            -8.09017016387917667772e-1,
        ),
        (0.5, 0.0, -1.0),
        (
            0.6000000238418579,
            -5.8778537348548669452e-1,
            -8.09016906323055102516e-1,
        ),
        (
            0.625,
            -7.07106781186547524401e-1,
            -7.07106781186547524401e-1,
        ),
        (
            0.699999988079071,
            -9.51056493149343653256e-1,
            -3.09017065610416488438e-1,
        ),
        (0.75, -1.0, 0.0),
        (
            0.800000011920929,
            -9.51056493149343653256e-1,
            3.09017065610416488438e-1,
        ),
        (
            0.8671875,
            -7.40951125354959091176e-1,
            6.71558954847018400625e-1,
        ),
        (0.875, -7.07106781186547524401e-1, 7.07106781186547524401e-1),
        (
            0.8999999761581421,
            -5.8778537348548669452e-1,
            8.09016906323055102516e-1,
        ),
        (
            0.9900000095367432,
            -6.27904597264293881421e-2,
            9.98026732190748310042e-1,
        ),
        (
            0.9999999403953552,
            -3.74507028292384123903e-7,
            9.99999999999929872243e-1,
        ),
    ];

    /// The conversion of `fraction_f32` against the powers of two, bit for bit: zeros of both
    /// signs, NaN, infinities, the edges around 2³¹, and a sweep over all exponents.
    #[test]
    fn fraction_f32_is_fraction_by_powers() {
        let mut xs = std::vec![
            0.0f32,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN_POSITIVE,
            2_147_483_648.0,
            2_147_483_520.0,
            4_294_967_296.0,
            16_777_217.0,
            8_388_607.5,
        ];
        let mut bits = 0x0000_0001u32;
        while bits < 0x7F80_0000 {
            xs.push(f32::from_bits(bits));
            bits = bits.wrapping_add(0x0000_3F1D);
        }
        for x in xs.clone() {
            xs.push(-x);
        }
        for x in xs {
            let (a, b) = (fraction_f32(x), fraction_by_powers(x));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e}: {a:e} vs {b:e}"
            );
        }
    }

    #[test]
    fn fractions_of_a_year() {
        for x in [
            0.0,
            0.25,
            1.0,
            54.75,
            54.999_999,
            -0.25,
            -1.0,
            -3.5,
            1e6 + 0.5,
            16_777_215.0,
        ] {
            assert_eq!(x.fraction(), x - libm::floor(x), "{x}");
            let x32 = x as f32;
            assert_eq!(x32.fraction(), x32 - libm::floorf(x32), "{x}");
        }
    }

    /// Against libm on 4 001 phases exact in f32. libm's f64 reference is off by up to the
    /// rounding of its argument 2π·f (≤ 2π · ε / 2 for f < 1, and sin, cos are 1-Lipschitz),
    /// which the f64 comparison allows for; for f32 the reference is exact enough as it is.
    #[test]
    fn matches_libm_on_a_grid() {
        const LIBM_ARGUMENT: f64 = TWO_PI * f64::EPSILON / 2.0;
        let (mut worst, mut worst32) = (0f64, 0f64);
        for i in 0..=4000 {
            let f = (i as f64 / 4000.0 * 0.999_999_9) as f32 as f64;
            let (s, c) = sin_cos_turn::<f64>(f);
            let (s32, c32) = sin_cos_turn::<f32>(f as f32);
            let (sin, cos) = (libm::sin(TWO_PI * f), libm::cos(TWO_PI * f));
            worst = worst.max((s - sin).abs()).max((c - cos).abs());
            worst32 = worst32
                .max((s32 as f64 - sin).abs())
                .max((c32 as f64 - cos).abs());
        }
        std::println!("sin_cos_turn vs libm: f64 {worst:e}, f32 {worst32:e}");
        assert!(
            worst <= SIN_COS_TURN_MAX_ERROR_F64 + LIBM_ARGUMENT,
            "{worst:e}"
        );
        assert!(worst32 <= SIN_COS_TURN_MAX_ERROR_F32, "{worst32:e}");
    }

    #[test]
    fn matches_the_test_vectors() {
        let (mut worst, mut worst32) = (0f64, 0f64);
        for (f, sin, cos) in TEST_VECTORS {
            let (s, c) = sin_cos_turn::<f64>(f);
            let (s32, c32) = sin_cos_turn::<f32>(f as f32);
            worst = worst.max((s - sin).abs()).max((c - cos).abs());
            worst32 = worst32
                .max((s32 as f64 - sin).abs())
                .max((c32 as f64 - cos).abs());
        }
        std::println!("sin_cos_turn vs test vectors: f64 {worst:e}, f32 {worst32:e}");
        assert!(worst <= SIN_COS_TURN_MAX_ERROR_F64, "{worst:e}");
        assert!(worst32 <= SIN_COS_TURN_MAX_ERROR_F32, "{worst32:e}");
    }
}
