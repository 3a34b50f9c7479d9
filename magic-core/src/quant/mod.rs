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
//! One concept per file:
//! * [`bytes`] — little-endian views of the model file's arrays ([`LeF32`], [`LeI32`]);
//! * [`quantize`](mod@quantize) — real ↔ int8, integer multipliers, requantisation;
//! * [`layout`] — blocked weights and packed activations, the order the kernels read;
//! * [`portable`] — the kernels in plain Rust (the host, and the reference);
//! * `dsp` — the Armv7E-M kernels in inline assembly (feature `dsp`, ARM only), the crate's only
//!   `unsafe` code.
//!
//! The functions below pick the kernel of the build; every item is also re-exported here, at the
//! paths the rest of the workspace uses.

pub mod bytes;
#[cfg(all(feature = "dsp", target_arch = "arm"))]
#[allow(unsafe_code)]
pub mod dsp;
pub mod layout;
pub mod portable;
pub mod quantize;

pub use bytes::{LeF32, LeI32};
pub use layout::{
    block_rows, blocked_index, blocked_row, pack4, pack_i8_pairs, packed_get, packed_set,
    packed_words, unblock_rows,
};
pub use portable::{dot_i8, dot_i8_packed_portable, matvec_i8_packed_portable};
pub use quantize::{
    quantize, quantize_multiplier, requantize, requantize_floor, requantize_reference,
};

/// The two packed words of four int8 activations given as one little-endian word
/// (`x0 | x1 << 8 | x2 << 16 | x3 << 24`): `SXTB16 w` and `SXTB16 w, ROR #8`.
#[inline(always)]
pub fn pack_word(w: u32) -> [u32; 2] {
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    {
        dsp::sxtb16_pair(w)
    }
    #[cfg(not(all(feature = "dsp", target_arch = "arm")))]
    {
        portable::sxtb16_pair(w)
    }
}

/// Integer dot product of int8 weights with activations packed by [`pack_i8_pairs`].
///
/// Returns exactly [`dot_i8`] of the unpacked activations (i32 arithmetic cannot overflow:
/// |Σ| ≤ 127² · [`crate::nn::MAX_WIDTH`]). With the `dsp` feature on ARM this runs the `SMLAD`
/// kernel of the `dsp` module; elsewhere [`dot_i8_packed_portable`], which performs the same lane
/// arithmetic in plain Rust (and is what the host tests hold to [`dot_i8`]).
#[inline]
pub fn dot_i8_packed(w: &[u8], xp: &[u32]) -> i32 {
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    {
        dsp::dot_i8_packed(w, xp)
    }
    #[cfg(not(all(feature = "dsp", target_arch = "arm")))]
    {
        dot_i8_packed_portable(w, xp)
    }
}
/// All rows of a `rows × cols` int8 matrix `w` in the blocked layout of [`blocked_index`] times
/// packed activations `xp`: `acc[r] = dot_i8(row r, x)` for `r < min(rows, acc.len())`
/// (exactly; sums wrap like `SMLAD`'s). Weights missing from `w` and activation words missing
/// from `xp` count as 0.
///
/// With the `dsp` feature on ARM this is the `SMLAD` kernel of the `dsp` module, four rows per
/// pass over the activations; elsewhere [`matvec_i8_packed_portable`].
pub fn matvec_i8_packed(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    {
        dsp::matvec_i8_packed(w, rows, cols, xp, acc)
    }
    #[cfg(not(all(feature = "dsp", target_arch = "arm")))]
    {
        matvec_i8_packed_portable(w, rows, cols, xp, acc)
    }
}
