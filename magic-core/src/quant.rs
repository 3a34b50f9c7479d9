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
        match self.0.get(4 * i..).and_then(<[u8]>::first_chunk::<4>) {
            Some(b) => f32::from_le_bytes(*b),
            None => 0.0,
        }
    }
    /// Iterator over the elements.
    pub fn iter(&self) -> impl Iterator<Item = f32> + 'a {
        self.0
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
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
        match self.0.get(4 * i..).and_then(<[u8]>::first_chunk::<4>) {
            Some(b) => i32::from_le_bytes(*b),
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
    ((t.clamp(-256, 255) + 1) >> 1).clamp(floor.max(-127) as i32, 127) as i8
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

/// Integer dot product of int8 weights (as stored bytes) with int8 activations.
///
/// This is the portable inner loop of every int8 layer (the host's path). Builds with the `dsp`
/// feature for ARMv7E-M use [`pack_i8_pairs`] and [`dot_i8_packed`] instead, which give the same
/// integer for the same inputs.
#[inline]
pub fn dot_i8(w: &[u8], x: &[i8]) -> i32 {
    let mut acc0 = 0i32;
    let mut acc1 = 0i32;
    let mut wc = w.chunks_exact(2);
    let mut xc = x.chunks_exact(2);
    // Wrapping sums: a layer (at most MAX_WIDTH inputs) cannot overflow, and a longer slice wraps
    // like the DSP kernel instead of panicking in builds with overflow checks.
    for (a, b) in (&mut wc).zip(&mut xc) {
        acc0 = acc0.wrapping_add((a[0] as i8 as i32) * (b[0] as i32));
        acc1 = acc1.wrapping_add((a[1] as i8 as i32) * (b[1] as i32));
    }
    for (a, b) in wc.remainder().iter().zip(xc.remainder()) {
        acc0 = acc0.wrapping_add((*a as i8 as i32) * (*b as i32));
    }
    acc0.wrapping_add(acc1)
}

/// Number of `u32` words [`pack_i8_pairs`] writes for `n` activations: two per group of four.
#[inline]
pub const fn packed_words(n: usize) -> usize {
    n.div_ceil(4) * 2
}

/// Packs int8 activations as sign-extended 16-bit pairs for [`dot_i8_packed`].
///
/// Activations are taken in groups of four `x0 x1 x2 x3` (the last group padded with zeros) and
/// each group becomes two words, `x0 | x2 << 16` then `x1 | x3 << 16` (16-bit two's complement
/// halves): the pairs that the Armv7E-M instruction `SXTB16` extracts from four int8 weights
/// (`SXTB16 w` gives bytes 0 and 2, `SXTB16 w, ROR #8` bytes 1 and 3), so that one `SMLAD`
/// performs two multiply-accumulates. The activations are packed once per layer and reused by
/// every row. Writes [`packed_words`]`(x.len())` words; stops early if `out` is shorter.
pub fn pack_i8_pairs(x: &[i8], out: &mut [u32]) {
    let half = |v: i8| v as i16 as u16 as u32;
    let groups = x.chunks_exact(4);
    let tail = groups.remainder();
    let mut words = out.chunks_exact_mut(2);
    for (g, pair) in groups.zip(&mut words) {
        // The four activations as one little-endian word: bytes x0 x1 x2 x3.
        let w = u32::from_le_bytes([g[0] as u8, g[1] as u8, g[2] as u8, g[3] as u8]);
        [pair[0], pair[1]] = pack_word(w);
    }
    if let (false, Some(pair)) = (tail.is_empty(), words.next()) {
        let at = |j: usize| pair_get(tail, j);
        pair[0] = half(at(0)) | (half(at(2)) << 16);
        pair[1] = half(at(1)) | (half(at(3)) << 16);
    }
}

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
        let sx = |v: u32| {
            (v as u8 as i8 as i16 as u16 as u32)
                | ((v >> 16) as u8 as i8 as i16 as u16 as u32) << 16
        };
        [sx(w), sx(w >> 8)]
    }
}

#[inline]
fn pair_get(g: &[i8], j: usize) -> i8 {
    g.get(j).copied().unwrap_or(0)
}

/// Writes activation `k` into the packing of [`pack_i8_pairs`] (nothing past the end of `xp`).
#[inline]
pub fn packed_set(xp: &mut [u32], k: usize, q: i8) {
    if let Some(word) = xp.get_mut(2 * (k / 4) + (k & 1)) {
        let sh = if k & 2 == 0 { 0 } else { 16 };
        *word = (*word & !(0xFFFF << sh)) | ((q as i16 as u16 as u32) << sh);
    }
}

/// The two packed words of four consecutive activations `q[0..4]` (see [`pack_i8_pairs`]).
#[inline]
pub fn pack4(q: [i8; 4]) -> [u32; 2] {
    let half = |v: i8| v as i16 as u16 as u32;
    [
        half(q[0]) | (half(q[2]) << 16),
        half(q[1]) | (half(q[3]) << 16),
    ]
}

/// The activation `k` back from the packing of [`pack_i8_pairs`] (0 past the end).
#[inline]
pub fn packed_get(xp: &[u32], k: usize) -> i32 {
    let word = xp.get(2 * (k / 4) + (k & 1)).copied().unwrap_or(0);
    let half = if k & 2 == 0 { word } else { word >> 16 };
    half as u16 as i16 as i32
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

/// Integer dot products of two consecutive rows of `cols` int8 weights (`w[..cols]` and
/// `w[cols..2 · cols]`) with the same packed activations: `[dot_i8_packed(row 0, xp),
/// dot_i8_packed(row 1, xp)]`, exactly. Rows missing from `w` give 0.
///
/// With the `dsp` feature on ARM this is the row-blocked `SMLAD` kernel of the `dsp` module (each
/// activation word is loaded once for both rows); elsewhere [`dot2_i8_packed_portable`].
#[inline]
pub fn dot2_i8_packed(w: &[u8], cols: usize, xp: &[u32]) -> [i32; 2] {
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    {
        dsp::dot2_i8_packed(w, cols, xp)
    }
    #[cfg(not(all(feature = "dsp", target_arch = "arm")))]
    {
        dot2_i8_packed_portable(w, cols, xp)
    }
}

/// All rows of a `rows × cols` int8 matrix `w` (row-major) times packed activations `xp`:
/// `acc[r] = dot_i8_packed(row r, xp)` for `r < min(rows, acc.len())`, rows two at a time with
/// [`dot2_i8_packed`]. Rows missing from `w` give 0.
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

/// [`matvec_i8_packed`] in plain Rust.
pub fn matvec_i8_packed_portable(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
    let rows = rows.min(acc.len());
    for (p, out) in acc[..rows].chunks_mut(2).enumerate() {
        let r = 2 * p;
        let rest = w.get(r * cols..).unwrap_or(&[]);
        match out {
            [a0, a1] => [*a0, *a1] = dot2_i8_packed_portable(rest, cols, xp),
            [a0] => *a0 = dot_i8_packed(rest.get(..cols).unwrap_or(&[]), xp),
            _ => {}
        }
    }
}

/// [`dot2_i8_packed`] in plain Rust (two calls of [`dot_i8_packed_portable`]).
pub fn dot2_i8_packed_portable(w: &[u8], cols: usize, xp: &[u32]) -> [i32; 2] {
    let row = |r: usize| {
        w.get(r * cols..(r + 1) * cols)
            .map_or(0, |row| dot_i8_packed_portable(row, xp))
    };
    [row(0), row(1)]
}

/// [`dot_i8_packed`] in plain Rust, lane by lane as `SXTB16`/`SMLAD` compute it.
pub fn dot_i8_packed_portable(w: &[u8], xp: &[u32]) -> i32 {
    let lane = |word: u32, hi: bool| (if hi { word >> 16 } else { word }) as u16 as i16 as i32;
    let mut acc = 0i32;
    let groups = w.chunks_exact(4);
    let tail = groups.remainder();
    for (g, b) in groups.enumerate() {
        // Words missing from `xp` stand for zero activations.
        let e = xp.get(2 * g).copied().unwrap_or(0);
        let o = xp.get(2 * g + 1).copied().unwrap_or(0);
        let (w0, w1, w2, w3) = (
            b[0] as i8 as i32,
            b[1] as i8 as i32,
            b[2] as i8 as i32,
            b[3] as i8 as i32,
        );
        // SMLAD(SXTB16(w), e) then SMLAD(SXTB16(w, ROR 8), o)
        // Products of int8 values and pairs of them fit in i32; the running sum wraps as SMLAD's.
        acc = acc.wrapping_add(w0 * lane(e, false) + w2 * lane(e, true));
        acc = acc.wrapping_add(w1 * lane(o, false) + w3 * lane(o, true));
    }
    let base = w.len() - tail.len();
    for (j, &b) in tail.iter().enumerate() {
        acc = acc.wrapping_add((b as i8 as i32) * packed_get(xp, base + j));
    }
    acc
}

/// The Armv7E-M DSP kernel (Cortex-M4/M7): two 16-bit multiply-accumulates per `SMLAD`.
///
/// The portable [`dot_i8`] costs about 5.6 executed instructions per multiply-accumulate on a
/// Cortex-M4F; this kernel's loop costs 1.5 (per 16 weights: 4 `LDR`, 2 `LDM`, 8 `SXTB16`, 8
/// `SMLAD`, `CMP`, `BNE`). Measured under QEMU (`mps2-an386`, `-icount shift=0`) on the 36-input
/// Akutan model C (int8): encoder 47.5 k → 23.8 k instructions, correction 92.8 k → 40.3 k, a
/// whole inversion 176 k → 99 k. Inline assembly is the only way to these instructions on stable
/// Rust (the `dsp` target feature is not stable), hence the crate's only `unsafe` code. The firmware checks this kernel
/// against [`dot_i8`] on every row of its model at start-up; the host tests hold
/// [`dot_i8_packed_portable`] (same lanes, plain Rust) to [`dot_i8`].
#[cfg(all(feature = "dsp", target_arch = "arm"))]
#[allow(unsafe_code)]
pub mod dsp {
    use super::packed_get;
    use core::arch::asm;

    /// See [`super::pack_word`].
    #[inline(always)]
    pub fn sxtb16_pair(w: u32) -> [u32; 2] {
        let (e, o): (u32, u32);
        // SAFETY: register-only arithmetic; no memory, no stack.
        unsafe {
            asm!(
                "sxtb16 {e}, {w}",
                "sxtb16 {o}, {w}, ror #8",
                w = in(reg) w,
                e = out(reg) e,
                o = out(reg) o,
                options(pure, nomem, nostack),
            );
        }
        [e, o]
    }

    /// See [`super::matvec_i8_packed`]: the rows two at a time, one `asm!` block per pair (the
    /// loop over the pair's columns in assembly: groups of four columns left over after the
    /// 16-column blocks first, then the blocks), so that a pair costs about a dozen
    /// instructions besides its multiply-accumulates.
    pub fn matvec_i8_packed(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
        let rows = rows.min(acc.len());
        let groups = (cols / 4).min(xp.len() / 2);
        // Pairs of rows that `w` holds whole.
        let pairs = (rows / 2).min(w.len().checked_div(2 * cols).unwrap_or(0));
        if cols == 0 || pairs == 0 || 4 * groups != cols {
            return super::matvec_i8_packed_portable(w, rows, cols, xp, acc);
        }
        let single4 = 4 * (groups % 4); // bytes per row in the single-group loop
        let blocks16 = 16 * (groups / 4); // bytes per row in the 16-column loop
        let mut wp = w.as_ptr();
        for out in acc.chunks_exact_mut(2).take(pairs) {
            let (acc0, acc1): (i32, i32);
            // SAFETY: for pair p (p < pairs, so 2 · cols · (p + 1) ≤ w.len()) `wp` is
            // w + 2 · cols · p; the block reads bytes [wp, wp + cols) and [wp + cols,
            // wp + 2 · cols) (single4 + blocks16 = 4 · groups = cols) and words [0, 2 · groups)
            // of `xp` (2 · groups ≤ xp.len()). `LDR` may be unaligned (Armv7-M allows it;
            // UNALIGN_TRP is clear at reset); `LDM` reads `xp`, a `u32` slice, hence word
            // aligned. No memory is written, the stack is not used, and every register written
            // is an output.
            unsafe {
                asm!(
                    "movs {acc0}, #0",
                    "movs {acc1}, #0",
                    "cmp {wp}, {end}",
                    "beq 3f",
                    "2:",
                    "ldm {xp}!, {{r2, r3}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "cmp {wp}, {end}",
                    "bne 2b",
                    "3:",
                    "add {end}, {end}, r4",
                    "cmp {wp}, {end}",
                    "beq 5f",
                    "4:",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r4, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r5, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r4, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r5, {acc0}",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r4, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r5, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r4, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r5, {acc0}",
                    "cmp {wp}, {end}",
                    "bne 4b",
                    "5:",
                    wp = inout(reg) wp,
                    xp = inout(reg) xp.as_ptr() => _,
                    st = in(reg) cols,
                    end = inout(reg) wp.wrapping_add(single4) => _,
                    acc0 = out(reg) acc0,
                    acc1 = out(reg) acc1,
                    a = out(reg) _,
                    b = out(reg) _,
                    out("r2") _,
                    out("r3") _,
                    inout("r4") blocks16 => _,
                    out("r5") _,
                    options(pure, readonly, nostack),
                );
            }
            out[0] = acc0;
            out[1] = acc1;
            // `wp` stopped at the end of the pair's first row: skip its second row.
            wp = wp.wrapping_add(cols);
        }
        if rows % 2 == 1 || pairs < rows / 2 {
            for r in 2 * pairs..rows {
                let row = w.get(r * cols..(r + 1) * cols).unwrap_or(&[]);
                if let Some(a) = acc.get_mut(r) {
                    *a = super::dot_i8_packed(row, xp);
                }
            }
        }
    }

    /// See [`super::dot2_i8_packed`]: two consecutive rows, each activation word loaded once.
    ///
    /// Per 16 columns of both rows (32 multiply-accumulates): 2 `LDM` (8 activation words), 8
    /// `LDR` (weights), 16 `SXTB16`, 16 `SMLAD`, `CMP`, `BNE`: 1.375 instructions per MAC, and one
    /// call per pair of rows. Groups of four columns left over run in a second loop; columns
    /// beyond the last whole group (when `cols % 4 != 0`) in Rust.
    #[inline]
    pub fn dot2_i8_packed(w: &[u8], cols: usize, xp: &[u32]) -> [i32; 2] {
        // Whole groups of four columns that both rows and `xp` cover.
        let rows_ok = cols.checked_mul(2).is_some_and(|n| n <= w.len());
        if !rows_ok {
            return super::dot2_i8_packed_portable(w, cols, xp);
        }
        let groups = (cols / 4).min(xp.len() / 2);
        let blocks = groups / 4; // 16 columns each
        let single = groups % 4;
        let (mut acc0, mut acc1) = (0i32, 0i32);
        let mut wp = w.as_ptr();
        let mut xq = xp.as_ptr();
        if blocks > 0 {
            let end = wp.wrapping_add(16 * blocks);
            // SAFETY: reads bytes [0, 16 · blocks) and [cols, cols + 16 · blocks) of `w`
            // (16 · blocks ≤ 4 · groups ≤ cols and 2 · cols ≤ w.len(), checked above) and words
            // [0, 8 · blocks) of `xp` (8 · blocks ≤ 2 · groups ≤ xp.len()). `LDR` may be unaligned
            // (Armv7-M allows it; UNALIGN_TRP is clear at reset); `LDM` reads `xp`, a `u32` slice,
            // hence word aligned. No memory is written, the stack is not used, and every register
            // written is an output.
            unsafe {
                asm!(
                    "2:",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r4, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r5, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r4, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r5, {acc0}",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r4, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r5, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r4, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r5, {acc0}",
                    "cmp {wp}, {end}",
                    "bne 2b",
                    wp = inout(reg) wp,
                    xp = inout(reg) xq,
                    st = in(reg) cols,
                    end = in(reg) end,
                    acc0 = inout(reg) acc0,
                    acc1 = inout(reg) acc1,
                    a = out(reg) _,
                    b = out(reg) _,
                    out("r2") _,
                    out("r3") _,
                    out("r4") _,
                    out("r5") _,
                    options(pure, readonly, nostack),
                );
            }
        }
        if single > 0 {
            let end = wp.wrapping_add(4 * single);
            // SAFETY: continues where the loop above stopped: `single` more groups of four bytes
            // of both rows and two words of `xp`, all within the bounds established above
            // (4 · groups ≤ cols, 2 · groups ≤ xp.len()); same alignment and register rules.
            unsafe {
                asm!(
                    "2:",
                    "ldm {xp}!, {{r2, r3}}",
                    "ldr {b}, [{wp}, {st}]",
                    "sxtb16 {a}, {b}",
                    "smlad {acc1}, {a}, r2, {acc1}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc1}, {b}, r3, {acc1}",
                    "ldr {b}, [{wp}], #4",
                    "sxtb16 {a}, {b}",
                    "smlad {acc0}, {a}, r2, {acc0}",
                    "sxtb16 {b}, {b}, ror #8",
                    "smlad {acc0}, {b}, r3, {acc0}",
                    "cmp {wp}, {end}",
                    "bne 2b",
                    wp = inout(reg) wp => _,
                    xp = inout(reg) xq => _,
                    st = in(reg) cols,
                    end = in(reg) end,
                    acc0 = inout(reg) acc0,
                    acc1 = inout(reg) acc1,
                    a = out(reg) _,
                    b = out(reg) _,
                    out("r2") _,
                    out("r3") _,
                    options(pure, readonly, nostack),
                );
            }
        }
        // Columns past the last whole group (none when cols is a multiple of 4).
        for k in 4 * groups..cols {
            let x = packed_get(xp, k);
            let (a, b) = (w.get(k).copied(), w.get(cols + k).copied());
            acc0 = acc0.wrapping_add(a.map_or(0, |v| v as i8 as i32) * x);
            acc1 = acc1.wrapping_add(b.map_or(0, |v| v as i8 as i32) * x);
        }
        [acc0, acc1]
    }

    /// See [`super::dot_i8_packed`].
    #[inline]
    pub fn dot_i8_packed(w: &[u8], xp: &[u32]) -> i32 {
        // Whole groups of four that both slices cover; the kernel never reads past them.
        let groups = (w.len() / 4).min(xp.len() / 2);
        let blocks = groups / 4; // 16 weights each
        let mut acc = 0i32;
        if blocks > 0 {
            let end = w.as_ptr().wrapping_add(16 * blocks);
            // SAFETY: reads 16 · blocks bytes from `w` and 8 · blocks words from `xp`, both
            // within the slices (blocks ≤ w.len() / 16 and 8 · blocks ≤ xp.len()); `LDR` from
            // `w` may be unaligned, which Armv7-M allows for LDR (UNALIGN_TRP is clear at
            // reset); `LDM` reads `xp`, a `u32` slice, hence word aligned. No memory is written,
            // the stack is not used, the scratch registers are declared as clobbered.
            unsafe {
                asm!(
                    "2:",
                    "ldr {w0}, [{wp}], #4",
                    "ldr {w1}, [{wp}], #4",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "sxtb16 {t}, {w0}",
                    "smlad {acc}, {t}, r2, {acc}",
                    "sxtb16 {t}, {w0}, ror #8",
                    "smlad {acc}, {t}, r3, {acc}",
                    "sxtb16 {t}, {w1}",
                    "smlad {acc}, {t}, r4, {acc}",
                    "sxtb16 {t}, {w1}, ror #8",
                    "smlad {acc}, {t}, r5, {acc}",
                    "ldr {w0}, [{wp}], #4",
                    "ldr {w1}, [{wp}], #4",
                    "ldm {xp}!, {{r2, r3, r4, r5}}",
                    "sxtb16 {t}, {w0}",
                    "smlad {acc}, {t}, r2, {acc}",
                    "sxtb16 {t}, {w0}, ror #8",
                    "smlad {acc}, {t}, r3, {acc}",
                    "sxtb16 {t}, {w1}",
                    "smlad {acc}, {t}, r4, {acc}",
                    "sxtb16 {t}, {w1}, ror #8",
                    "smlad {acc}, {t}, r5, {acc}",
                    "cmp {wp}, {end}",
                    "bne 2b",
                    wp = inout(reg) w.as_ptr() => _,
                    xp = inout(reg) xp.as_ptr() => _,
                    end = in(reg) end,
                    acc = inout(reg) acc,
                    w0 = out(reg) _,
                    w1 = out(reg) _,
                    t = out(reg) _,
                    out("r2") _,
                    out("r3") _,
                    out("r4") _,
                    out("r5") _,
                    options(pure, readonly, nostack),
                );
            }
        }
        for g in 4 * blocks..groups {
            let word = u32::from_le_bytes([w[4 * g], w[4 * g + 1], w[4 * g + 2], w[4 * g + 3]]);
            let (e, o) = (xp[2 * g], xp[2 * g + 1]);
            // SAFETY: register-only arithmetic (SXTB16, SMLAD); no memory, no stack.
            unsafe {
                asm!(
                    "sxtb16 {t}, {w}",
                    "smlad {acc}, {t}, {e}, {acc}",
                    "sxtb16 {t}, {w}, ror #8",
                    "smlad {acc}, {t}, {o}, {acc}",
                    w = in(reg) word,
                    e = in(reg) e,
                    o = in(reg) o,
                    acc = inout(reg) acc,
                    t = out(reg) _,
                    options(pure, nomem, nostack),
                );
            }
        }
        for (j, &b) in w[4 * groups..].iter().enumerate() {
            acc += (b as i8 as i32) * packed_get(xp, 4 * groups + j);
        }
        acc
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::Strategy;
    use std::vec;

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

    /// The reference: a plain sum of products.
    fn naive(w: &[u8], x: &[i8]) -> i32 {
        w.iter()
            .zip(x)
            .map(|(a, b)| (*a as i8 as i32) * (*b as i32))
            .sum()
    }

    proptest::proptest! {
        #[test]
        fn dot_kernels_match_reference(
            (w, x) in (0usize..=crate::nn::MAX_WIDTH).prop_flat_map(|n| (
                proptest::collection::vec(proptest::num::u8::ANY.prop_filter("-128", |b| *b != 0x80), n),
                proptest::collection::vec(-127i8..=127, n),
            ))
        ) {
            let want = naive(&w, &x);
            proptest::prop_assert_eq!(dot_i8(&w, &x), want);
            let mut xp = [0u32; packed_words(crate::nn::MAX_WIDTH)];
            pack_i8_pairs(&x, &mut xp);
            proptest::prop_assert_eq!(dot_i8_packed_portable(&w, &xp[..packed_words(x.len())]), want);
            proptest::prop_assert_eq!(dot_i8_packed(&w, &xp), want);
        }
    }

    proptest::proptest! {
        #[test]
        fn requantize_matches_the_reference(acc in proptest::num::i32::ANY, m in proptest::num::i32::ANY, shift in proptest::num::i8::ANY) {
            proptest::prop_assert_eq!(requantize(acc, m, shift), requantize_reference(acc, m, shift));
        }

        #[test]
        fn row_blocked_dot_matches_two_rows(
            (w, x) in (0usize..=crate::nn::MAX_WIDTH).prop_flat_map(|n| (
                proptest::collection::vec(proptest::num::u8::ANY.prop_filter("-128", |b| *b != 0x80), 2 * n),
                proptest::collection::vec(-127i8..=127, n),
            ))
        ) {
            let n = x.len();
            let mut xp = [0u32; packed_words(crate::nn::MAX_WIDTH)];
            pack_i8_pairs(&x, &mut xp);
            let want = [naive(&w[..n], &x), naive(&w[n..], &x)];
            proptest::prop_assert_eq!(dot2_i8_packed_portable(&w, n, &xp), want);
            proptest::prop_assert_eq!(dot2_i8_packed(&w, n, &xp[..packed_words(n)]), want);
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

    #[test]
    fn packed_set_and_pack4_agree_with_pack_i8_pairs() {
        let x: std::vec::Vec<i8> = (0..11).map(|i| (i * 37 % 255 - 127) as i8).collect();
        let mut want = [0u32; 6];
        pack_i8_pairs(&x, &mut want);
        let mut got = [0xDEAD_BEEFu32; 6];
        for (k, &v) in x.iter().enumerate() {
            packed_set(&mut got, k, v);
        }
        got[5] &= 0xFFFF; // the pad of the last group is not written by packed_set
        want[5] &= 0xFFFF;
        assert_eq!(got[..5], want[..5]);
        assert_eq!(pack4([x[0], x[1], x[2], x[3]]), [want[0], want[1]]);
        for k in 0..11 {
            assert_eq!(packed_get(&want, k), x[k] as i32);
        }
    }

    #[test]
    fn packed_extremes_and_short_packing() {
        for n in [0usize, 1, 3, 4, 5, 15, 16, 17, 36, 64, 144, 256] {
            let w = vec![0x81u8; n]; // -127
            let x = vec![-127i8; n];
            let mut xp = [0u32; packed_words(crate::nn::MAX_WIDTH)];
            pack_i8_pairs(&x, &mut xp);
            assert_eq!(
                dot_i8_packed_portable(&w, &xp),
                127 * 127 * n as i32,
                "n {n}"
            );
            assert_eq!(dot_i8(&w, &x), 127 * 127 * n as i32);
        }
        // Missing packed words stand for zero activations.
        let w = [1u8, 2, 3, 4, 5, 6, 7, 8, 9];
        let mut xp = [0u32; 2];
        pack_i8_pairs(&[1, 1, 1, 1, 1, 1, 1, 1, 1], &mut xp);
        assert_eq!(dot_i8_packed_portable(&w, &xp), 1 + 2 + 3 + 4);
    }

    #[test]
    fn dot_matches_naive() {
        let w: [u8; 5] = [1, 255, 127, 128, 3];
        let x: [i8; 5] = [4, 5, -6, 2, -7];
        let naive: i32 = w
            .iter()
            .zip(&x)
            .map(|(a, b)| (*a as i8 as i32) * (*b as i32))
            .sum();
        assert_eq!(dot_i8(&w, &x), naive);
    }

    #[test]
    fn out_of_contract_inputs_do_not_panic() {
        // Regression (fuzzing): shifts outside -30..=30 overflowed the bit shift, and slices far
        // longer than a layer overflowed the i32 sum (panics in builds with overflow checks).
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
        let n = 300_000;
        let (w, x) = (vec![0x81u8; n], vec![-127i8; n]);
        let want = (0..n).fold(0i32, |a, _| a.wrapping_add(127 * 127));
        assert_eq!(dot_i8(&w, &x), want);
        let mut xp = vec![0u32; packed_words(n)];
        pack_i8_pairs(&x, &mut xp);
        assert_eq!(dot_i8_packed_portable(&w, &xp), want);
    }
}
