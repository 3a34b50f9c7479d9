//! Quantisation: real values to symmetric int8, real multipliers to integer ones, and the
//! requantisation of an i32 accumulator back to int8.
//!
//! Weights are int8, symmetric per output channel (`w ≈ q · s_w[r]`); activations entering an
//! int8 layer are int8, symmetric per tensor (`x ≈ q · s_x`). A layer that feeds another int8
//! layer requantises its accumulator with an integer multiplier `m · 2^−(31+shift)`,
//! `m ∈ [2³⁰, 2³¹)`, encoding `s_w[r] · s_x / s_y`; [`requantize`] applies it without floating
//! point, and [`requantize_reference`] is the plain formula it is held to.

/// Quantises a real value to symmetric int8 with scale `s` (round half away from zero, clamp
/// to ±127). NaN maps to 0.
#[inline]
pub fn quantize(x: f32, inv_s: f32) -> i8 {
    let v = x * inv_s;
    let r = if v >= 0.0 { v + 0.5 } else { v - 0.5 };
    // `as` saturates and maps NaN to 0.
    let q = r as i32;
    q.clamp(-127, 127) as i8
}

/// Splits a positive real multiplier into `(m, shift)` with `m ∈ [2³⁰, 2³¹)` so that
/// `x · mult ≈ x · m · 2^−(31+shift)`. Returns `None` for non-positive, non-finite or extreme values.
pub fn quantize_multiplier(mult: f64) -> Option<(i32, i8)> {
    if !(mult.is_finite() && mult > 0.0) {
        return None;
    }
    let (mut f, mut e) = frexp(mult); // mult = f · 2^e, f ∈ [0.5, 1)
    let mut m = libm::round(f * 2147483648.0) as i64;
    if m == 1 << 31 {
        m /= 2;
        e += 1;
        f = 0.5;
    }
    let _ = f;
    let shift = -e;
    if !(-30..=30).contains(&shift) {
        return None;
    }
    Some((m as i32, shift as i8))
}

fn frexp(x: f64) -> (f64, i32) {
    libm::frexp(x)
}

/// Applies an integer requantisation multiplier: `round(acc · m · 2^−(31+shift))` (halves
/// rounded up), saturated to int8 (±127). `shift` lies in −30..=30 (checked when the model is
/// loaded); a shift outside that range is clamped to it rather than overflowing the bit shift.
///
/// Computed as `⌊(⌊acc · m / 2^k⌋ + 1) / 2⌋` with `k = 30 + shift`, which equals
/// `⌊(acc · m + 2^k) / 2^(k+1)⌋` exactly (no rounding constant to build); for `k ≥ 32` only the high
/// word of the product is needed (one `SMULL` and one shift on Arm), and `⌊acc · m / 2^k⌋` is
/// saturated to ±256 before the halving, which leaves the int8 result unchanged.
#[inline]
pub fn requantize(acc: i32, m: i32, shift: i8) -> i8 {
    requantize_floor(acc, m, shift, -127)
}

/// [`requantize`] followed by `max(floor)` (`floor` −127, or 0 for a ReLU), in one clamp.
///
/// The clamp comes before the halving: `⌊(t + 1) / 2⌋` lies in `[floor, 127]` exactly when `t`
/// lies in `[2 · floor − 1, 254]`, so clamping `t` there gives the result of saturating `t` to
/// ±256, halving and clamping to `[floor, 127]` (one clamp instead of two: about 4 instructions
/// a row on the board; the test `final_clamp_is_the_two_clamps` holds them equal).
#[inline(always)]
pub fn requantize_floor(acc: i32, m: i32, shift: i8, floor: i8) -> i8 {
    let prod = acc as i64 * m as i64;
    let s = (shift as i32).wrapping_sub(2);
    let t = if (s as u32) <= 28 {
        // The usual case, shift in 2..=30 (k = 30 + shift ≥ 32): the high word, shifted.
        ((prod >> 32) as i32) >> s
    } else {
        let k = (30 + shift as i32).clamp(0, 60) as u32;
        if k >= 32 {
            ((prod >> 32) as i32) >> (k - 32)
        } else {
            (prod >> k).clamp(-256, 255) as i32
        }
    };
    // (`max`/`min` rather than `clamp`: no bound check to prove.)
    ((t.max(2 * floor.max(-127) as i32 - 1).min(254) + 1) >> 1) as i8
}

/// The reference requantisation (`round(acc · m · 2^−(31+shift))` with an i64 rounding constant),
/// which [`requantize`] matches bit for bit (held by tests).
pub fn requantize_reference(acc: i32, m: i32, shift: i8) -> i8 {
    let total = 31 + shift.clamp(-30, 30) as i32; // 1..=61
    let prod = acc as i64 * m as i64;
    let round = 1i64 << (total - 1);
    let y = (prod + round) >> total;
    y.clamp(-127, 127) as i8
}

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::quant::*;

    #[test]
    fn quantize_rounds_and_saturates() {
        assert_eq!(quantize(0.26, 4.0), 1);
        assert_eq!(quantize(-0.26, 4.0), -1);
        assert_eq!(quantize(1000.0, 1.0), 127);
        assert_eq!(quantize(-1000.0, 1.0), -127);
        assert_eq!(quantize(f32::NAN, 1.0), 0);
    }

    #[test]
    fn multiplier_round_trip() {
        for &m in &[1e-6, 0.0123, 0.5, 0.999_999_9, 1.0, 3.7, 1000.0] {
            let (q, s) = quantize_multiplier(m).unwrap();
            assert!(q >= 1 << 30);
            let back = q as f64 * libm::pow(2.0, -(31.0 + s as f64));
            // m ∈ [2³⁰, 2³¹) rounded to an integer: at most 2⁻³¹ relative (analytic).
            assert!(
                (back - m).abs() / m <= 1.0 / (1u64 << 31) as f64,
                "{m} -> {back}"
            );
        }
        assert!(quantize_multiplier(0.0).is_none());
        assert!(quantize_multiplier(f64::NAN).is_none());
        assert!(quantize_multiplier(1e-30).is_none());
    }

    #[test]
    fn requantize_matches_float() {
        let (m, s) = quantize_multiplier(0.0371).unwrap();
        for acc in [-5000, -27, 0, 13, 999, 3400] {
            let want = (acc as f64 * 0.0371).round().clamp(-127.0, 127.0) as i8;
            assert_eq!(requantize(acc, m, s), want, "acc {acc}");
        }
    }

    proptest::proptest! {
        #[test]
        fn requantize_matches_the_reference(acc in proptest::num::i32::ANY, m in proptest::num::i32::ANY, shift in proptest::num::i8::ANY) {
            proptest::prop_assert_eq!(requantize(acc, m, shift), requantize_reference(acc, m, shift));
        }
    }

    #[test]
    fn requantize_matches_the_reference_at_the_edges() {
        for shift in i8::MIN..=i8::MAX {
            for acc in [
                i32::MIN,
                -1 << 22,
                -12345,
                -256,
                -1,
                0,
                1,
                255,
                98765,
                1 << 22,
                i32::MAX,
            ] {
                for m in [i32::MIN, -1, 0, 1, 1 << 30, (1 << 30) + 12345, i32::MAX] {
                    assert_eq!(
                        requantize(acc, m, shift),
                        requantize_reference(acc, m, shift),
                        "acc {acc} m {m} shift {shift}"
                    );
                }
            }
        }
    }

    /// The single clamp of [`requantize_floor`] against the saturation, halving and clamp it
    /// replaces, for every floor and every scaled product around the int8 range.
    #[test]
    fn final_clamp_is_the_two_clamps() {
        for floor in i8::MIN..=i8::MAX {
            for t in (-70_000..70_000).chain([i32::MIN, i32::MIN + 1, i32::MAX - 1, i32::MAX]) {
                let two = ((t.clamp(-256, 255) + 1) >> 1).clamp(floor.max(-127) as i32, 127);
                let one = (t.max(2 * floor.max(-127) as i32 - 1).min(254) + 1) >> 1;
                assert_eq!(one, two, "t {t} floor {floor}");
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn requantize_relu_matches_the_reference(acc in proptest::num::i32::ANY, m in proptest::num::i32::ANY, shift in proptest::num::i8::ANY) {
            proptest::prop_assert_eq!(requantize_floor(acc, m, shift, 0), requantize_reference(acc, m, shift).max(0));
        }
    }

    #[test]
    fn out_of_range_shifts_do_not_panic() {
        // Regression (fuzzing): shifts outside -30..=30 overflowed the bit shift (a panic in
        // builds with overflow checks).
        for shift in i8::MIN..=i8::MAX {
            for (acc, m) in [
                (i32::MIN, i32::MIN),
                (i32::MAX, i32::MAX),
                (1, 1 << 30),
                (-5, -7),
            ] {
                let q = requantize(acc, m, shift);
                assert!((-127..=127).contains(&q));
            }
        }
        assert_eq!(
            requantize(1000, 1 << 30, -31),
            requantize(1000, 1 << 30, -30)
        );
    }
}
