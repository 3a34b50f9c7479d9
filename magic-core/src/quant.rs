//! int8 arithmetic: symmetric quantisation, integer dot products and requantisation.
//!
//! Weights are int8, symmetric per output channel (`w ≈ q · s_w[r]`); activations entering an
//! int8 layer are int8, symmetric per tensor (`x ≈ q · s_x`). A row accumulates `Σ q_w q_x` in i32
//! (exact: 127² · 256 columns stays far below 2³¹), adds an i32 bias in accumulator units, and
//! either
//! * **requantises** to int8 for the next int8 layer with an integer multiplier
//!   `y = round(acc · m · 2^−(31+shift))`, `m ∈ [2³⁰, 2³¹)`, encoding `s_w[r] · s_x / s_y`; or
//! * **dequantises** to f32 (`acc · s_w[r] · s_x`) for an f32 layer or the network output.
//!
//! Multi-byte values live in the model file as little-endian byte slices (weights borrowed straight
//! from flash, no alignment requirement); [`LeF32`] and [`LeI32`] read them.

use serde::{Deserialize, Serialize};

/// A borrowed little-endian `f32` array inside a model file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct LeF32<'a>(#[serde(borrow)] pub &'a [u8]);

/// A borrowed little-endian `i32` array inside a model file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct LeI32<'a>(#[serde(borrow)] pub &'a [u8]);

impl<'a> LeF32<'a> {
    /// Number of elements (trailing partial bytes are ignored; validation rejects them).
    #[inline]
    pub fn len(&self) -> usize {
        self.0.len() / 4
    }
    /// Whether empty.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Element `i`, or 0 past the end (callers validate lengths first).
    #[inline]
    pub fn get(&self, i: usize) -> f32 {
        match self.0.get(4 * i..4 * i + 4) {
            Some(b) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            None => 0.0,
        }
    }
    /// Iterator over the elements.
    pub fn iter(&self) -> impl Iterator<Item = f32> + 'a {
        self.0.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
}

impl<'a> LeI32<'a> {
    /// Number of elements.
    #[inline]
    pub fn len(&self) -> usize {
        self.0.len() / 4
    }
    /// Whether empty.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Element `i`, or 0 past the end (callers validate lengths first).
    #[inline]
    pub fn get(&self, i: usize) -> i32 {
        match self.0.get(4 * i..4 * i + 4) {
            Some(b) => i32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            None => 0,
        }
    }
}

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

/// Applies an integer requantisation multiplier: `round(acc · m · 2^−(31+shift))`, saturated to
/// int8 (±127). `shift` must lie in −30..=30 (checked when the model is loaded).
#[inline]
pub fn requantize(acc: i32, m: i32, shift: i8) -> i8 {
    let total = 31 + shift as i32; // 1..=61
    let prod = acc as i64 * m as i64;
    let round = 1i64 << (total - 1);
    let y = (prod + round) >> total;
    y.clamp(-127, 127) as i8
}

/// Integer dot product of int8 weights (as stored bytes) with int8 activations.
///
/// This is the inner loop of every int8 layer; on a Cortex-M4 the firmware's build replaces the
/// portable version with one using the DSP extension (see `dot_i8` in the firmware crate's docs).
#[inline]
pub fn dot_i8(w: &[u8], x: &[i8]) -> i32 {
    let mut acc0 = 0i32;
    let mut acc1 = 0i32;
    let mut wc = w.chunks_exact(2);
    let mut xc = x.chunks_exact(2);
    for (a, b) in (&mut wc).zip(&mut xc) {
        acc0 += (a[0] as i8 as i32) * (b[0] as i32);
        acc1 += (a[1] as i8 as i32) * (b[1] as i32);
    }
    for (a, b) in wc.remainder().iter().zip(xc.remainder()) {
        acc0 += (*a as i8 as i32) * (*b as i32);
    }
    acc0 + acc1
}

#[cfg(test)]
mod tests {
    use super::*;

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
            assert!((back - m).abs() / m < 1e-9, "{m} -> {back}");
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

    #[test]
    fn dot_matches_naive() {
        let w: [u8; 5] = [1, 255, 127, 128, 3];
        let x: [i8; 5] = [4, 5, -6, 2, -7];
        let naive: i32 = w.iter().zip(&x).map(|(a, b)| (*a as i8 as i32) * (*b as i32)).sum();
        assert_eq!(dot_i8(&w, &x), naive);
    }
}
