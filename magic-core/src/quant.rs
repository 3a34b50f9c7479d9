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

use crate::Error;
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
        self.0.chunks_exact(4).map(|b| match *b {
            [b0, b1, b2, b3] => f32::from_le_bytes([b0, b1, b2, b3]),
            _ => 0.0,
        })
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

/// Byte offset of weight `(r, c)` of a `rows × cols` int8 layer in the model file's blocked
/// layout (format version 5).
///
/// Rows are stored in blocks of four (the last block holds the `rows % 4` left over, if any);
/// within a block of `b` rows, for each whole group of four columns, the group's four bytes of
/// each row of the block, row after row (`4 · b` bytes per group); then the columns past the last
/// whole group (`cols % 4` of them), row after row. A block is thus `b · cols` bytes and the
/// matrix `rows · cols` bytes, as in row-major order. With this layout the `SMLAD` kernel loads
/// the weights of two rows with one `LDM` and each activation word once for four rows.
#[inline]
pub fn blocked_index(rows: usize, cols: usize, r: usize, c: usize) -> usize {
    let blk = r / 4;
    let b = rows.saturating_sub(4 * blk).min(4);
    let (i, whole) = (r % 4, cols / 4 * 4);
    let base = 4 * blk * cols;
    if c < whole {
        base + (c / 4) * 4 * b + 4 * i + c % 4
    } else {
        base + whole * b + i * (cols - whole) + (c - whole)
    }
}

/// Rearranges a row-major `rows × cols` int8 matrix into the blocked layout of
/// [`blocked_index`] (`src` and `dst` both `rows · cols` bytes).
pub fn block_rows(src: &[u8], rows: usize, cols: usize, dst: &mut [u8]) -> Result<(), Error> {
    let n = rows
        .checked_mul(cols)
        .ok_or(Error::BufferTooSmall { needed: usize::MAX })?;
    if src.len() != n || dst.len() != n {
        return Err(Error::SizeMismatch {
            what: "int8 weight bytes",
            expected: n,
            found: src.len().min(dst.len()),
        });
    }
    for r in 0..rows {
        for c in 0..cols {
            if let (Some(d), Some(&v)) = (
                dst.get_mut(blocked_index(rows, cols, r, c)),
                src.get(r * cols + c),
            ) {
                *d = v;
            }
        }
    }
    Ok(())
}

/// The inverse of [`block_rows`]: blocked layout back to row-major.
pub fn unblock_rows(src: &[u8], rows: usize, cols: usize, dst: &mut [u8]) -> Result<(), Error> {
    let n = rows
        .checked_mul(cols)
        .ok_or(Error::BufferTooSmall { needed: usize::MAX })?;
    if src.len() != n || dst.len() != n {
        return Err(Error::SizeMismatch {
            what: "int8 weight bytes",
            expected: n,
            found: src.len().min(dst.len()),
        });
    }
    for r in 0..rows {
        blocked_row(src, rows, cols, r, &mut dst[r * cols..(r + 1) * cols]);
    }
    Ok(())
}

/// Row `r` of a blocked `rows × cols` matrix into `out` (`out.len()` columns; bytes missing from
/// `w` read as 0).
pub fn blocked_row(w: &[u8], rows: usize, cols: usize, r: usize, out: &mut [u8]) {
    for (c, o) in out.iter_mut().enumerate() {
        *o = w.get(blocked_index(rows, cols, r, c)).copied().unwrap_or(0);
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

/// [`matvec_i8_packed`] in plain Rust, lane by lane as `SXTB16`/`SMLAD` compute it.
pub fn matvec_i8_packed_portable(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
    let rows = rows.min(acc.len());
    for (r, a) in acc[..rows].iter_mut().enumerate() {
        *a = blocked_row_dot(w, rows, cols, r, xp);
    }
}

/// Row `r` of a blocked matrix times packed activations, lane by lane.
fn blocked_row_dot(w: &[u8], rows: usize, cols: usize, r: usize, xp: &[u32]) -> i32 {
    let lane = |word: u32, hi: bool| (if hi { word >> 16 } else { word }) as u16 as i16 as i32;
    let at = |c: usize| {
        w.get(blocked_index(rows, cols, r, c))
            .map_or(0, |&b| b as i8 as i32)
    };
    let mut acc = 0i32;
    for g in 0..cols / 4 {
        let e = xp.get(2 * g).copied().unwrap_or(0);
        let o = xp.get(2 * g + 1).copied().unwrap_or(0);
        let c = 4 * g;
        // SMLAD(SXTB16(w), e) then SMLAD(SXTB16(w, ROR 8), o); the running sum wraps as SMLAD's.
        acc = acc.wrapping_add(at(c) * lane(e, false) + at(c + 2) * lane(e, true));
        acc = acc.wrapping_add(at(c + 1) * lane(o, false) + at(c + 3) * lane(o, true));
    }
    for c in cols / 4 * 4..cols {
        acc = acc.wrapping_add(at(c) * packed_get(xp, c));
    }
    acc
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

    /// The FPU's square root (`VSQRT.F32`, correctly rounded like libm's `sqrtf`, which on this
    /// target is a software routine of about 80 instructions and 480 bytes). Used through
    /// [`crate::mogi::sqrt`].
    #[inline(always)]
    pub fn sqrt_f32(x: f32) -> f32 {
        let y: u32;
        // SAFETY: register moves and one FPU instruction; no memory, no stack. `s0` is the
        // scratch register (the `sreg` operand class needs a target feature this target does
        // not name), declared clobbered.
        unsafe {
            asm!(
                "vmov s0, {x}",
                "vsqrt.f32 s0, s0",
                "vmov {y}, s0",
                x = in(reg) x.to_bits(),
                y = lateout(reg) y,
                out("s0") _,
                options(pure, nomem, nostack),
            );
        }
        f32::from_bits(y)
    }

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

    /// See [`super::matvec_i8_packed`]: every full block of four rows in one `asm!` block.
    ///
    /// Per group of four columns and block of four rows (16 multiply-accumulates): one `LDM`
    /// of two activation words, two `LDM` of two weight words (rows 0–1, rows 2–3: the blocked
    /// layout puts them side by side), 8 `SXTB16`, 8 `SMLAD`; four groups per loop iteration
    /// (`CMP`, `BNE`): 1.22 instructions per MAC. Groups left over from the loop of four (the
    /// first `groups % 4` of a block; all of them when the weights are not word aligned) run one
    /// by one first, with `LDR`. The loop over the blocks is in the assembly too (about 25
    /// instructions per block; its state in a small context on the stack). Columns past the last
    /// whole group, and a last block of fewer than four rows, run in Rust.
    pub fn matvec_i8_packed(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
        let rows = rows.min(acc.len());
        let groups = cols / 4;
        let full = rows / 4;
        let whole = 4 * groups;
        let tail = cols - whole;
        // The kernel needs every whole group's activation words and every full block's bytes.
        if 2 * groups > xp.len() || w.len() < 4 * full * cols {
            return super::matvec_i8_packed_portable(w, rows, cols, xp, acc);
        }
        if full > 0 {
            // `LDM` needs word-aligned weights: the exporter aligns every int8 layer's weights
            // in the file (and the firmware the file), and a block's size 4 · cols keeps the
            // alignment when cols % 4 == 0. Otherwise every group runs in the `LDR` loop.
            let aligned = (w.as_ptr() as usize) % 4 == 0 && tail == 0;
            let (single16, quads64) = if aligned {
                (16 * (groups % 4), 64 * (groups / 4))
            } else {
                (16 * groups, 0)
            };
            // The context: activations, output pointer, blocks left, loop lengths, tail bytes.
            let mut ctx: [usize; 6] = [
                xp.as_ptr() as usize,
                acc.as_mut_ptr() as usize,
                full,
                single16,
                quads64,
                4 * tail,
            ];
            // SAFETY: for each block `blk < full` (4 · full · cols ≤ w.len(), checked above) the
            // assembly reads bytes [4 · blk · cols, 4 · blk · cols + 16 · groups) of `w` (then
            // skips the 4 · tail bytes of the block's tail columns, so that the next block starts
            // at 4 · (blk + 1) · cols) — by `LDR` (unaligned allowed) in the one-group loop and
            // by `LDM` in the four-group loop, entered only when `w` and the block size are word
            // aligned — and words [0, 2 · groups) of `xp` (2 · groups ≤ xp.len(), checked above;
            // a `u32` slice, hence aligned), and writes the block's four sums to
            // acc[4 · blk .. 4 · blk + 4] (4 · full ≤ rows ≤ acc.len()), through the context
            // `ctx`, which it reads and updates (output pointer, blocks left). It pushes one word
            // (the context pointer) and pops it before the end. Every register written is an
            // output.
            unsafe {
                asm!(
                    "push {{{ctx}}}",
                    "2:",
                    // A block: the context, zero accumulators.
                    "ldr {t}, [sp]",
                    "ldr {xp}, [{t}]",
                    "ldr {end}, [{t}, #12]",
                    "add {end}, {end}, {wp}",
                    "ldr r4, [{t}, #16]",
                    "movs r8, #0",
                    "movs r9, #0",
                    "movs r10, #0",
                    "movs r11, #0",
                    "cmp {wp}, {end}",
                    "beq 4f",
                    "3:",
                    // One group at a time (weights by LDR, which may be unaligned).
                    "ldm {xp}!, {{r2, r3}}",
                    "ldr r5, [{wp}], #4",
                    "sxtb16 {t}, r5",
                    "smlad r8, {t}, r2, r8",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r8, r5, r3, r8",
                    "ldr r5, [{wp}], #4",
                    "sxtb16 {t}, r5",
                    "smlad r9, {t}, r2, r9",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r9, r5, r3, r9",
                    "ldr r5, [{wp}], #4",
                    "sxtb16 {t}, r5",
                    "smlad r10, {t}, r2, r10",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r10, r5, r3, r10",
                    "ldr r5, [{wp}], #4",
                    "sxtb16 {t}, r5",
                    "smlad r11, {t}, r2, r11",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r11, r5, r3, r11",
                    "cmp {wp}, {end}",
                    "bne 3b",
                    "4:",
                    "add {end}, {end}, r4",
                    "cmp {wp}, {end}",
                    "beq 6f",
                    "5:",
                    // Four groups per iteration, weights by LDM (word aligned).
                    "ldm {xp}!, {{r2, r3}}",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r8, {t}, r2, r8",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r8, r4, r3, r8",
                    "sxtb16 {t}, r5",
                    "smlad r9, {t}, r2, r9",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r9, r5, r3, r9",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r10, {t}, r2, r10",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r10, r4, r3, r10",
                    "sxtb16 {t}, r5",
                    "smlad r11, {t}, r2, r11",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r11, r5, r3, r11",
                    "ldm {xp}!, {{r2, r3}}",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r8, {t}, r2, r8",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r8, r4, r3, r8",
                    "sxtb16 {t}, r5",
                    "smlad r9, {t}, r2, r9",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r9, r5, r3, r9",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r10, {t}, r2, r10",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r10, r4, r3, r10",
                    "sxtb16 {t}, r5",
                    "smlad r11, {t}, r2, r11",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r11, r5, r3, r11",
                    "ldm {xp}!, {{r2, r3}}",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r8, {t}, r2, r8",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r8, r4, r3, r8",
                    "sxtb16 {t}, r5",
                    "smlad r9, {t}, r2, r9",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r9, r5, r3, r9",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r10, {t}, r2, r10",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r10, r4, r3, r10",
                    "sxtb16 {t}, r5",
                    "smlad r11, {t}, r2, r11",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r11, r5, r3, r11",
                    "ldm {xp}!, {{r2, r3}}",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r8, {t}, r2, r8",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r8, r4, r3, r8",
                    "sxtb16 {t}, r5",
                    "smlad r9, {t}, r2, r9",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r9, r5, r3, r9",
                    "ldm {wp}!, {{r4, r5}}",
                    "sxtb16 {t}, r4",
                    "smlad r10, {t}, r2, r10",
                    "sxtb16 r4, r4, ror #8",
                    "smlad r10, r4, r3, r10",
                    "sxtb16 {t}, r5",
                    "smlad r11, {t}, r2, r11",
                    "sxtb16 r5, r5, ror #8",
                    "smlad r11, r5, r3, r11",
                    "cmp {wp}, {end}",
                    "bne 5b",
                    "6:",
                    // Store the four sums, skip the tail columns, next block.
                    "ldr {t}, [sp]",
                    "ldr r2, [{t}, #4]",
                    "stm r2!, {{r8, r9, r10, r11}}",
                    "str r2, [{t}, #4]",
                    "ldr r2, [{t}, #20]",
                    "add {wp}, {wp}, r2",
                    "ldr r2, [{t}, #8]",
                    "subs r2, r2, #1",
                    "str r2, [{t}, #8]",
                    "bne 2b",
                    "add sp, sp, #4",
                    wp = inout(reg) w.as_ptr() => _,
                    ctx = in(reg) ctx.as_mut_ptr(),
                    xp = out(reg) _,
                    end = out(reg) _,
                    t = out(reg) _,
                    out("r2") _,
                    out("r3") _,
                    out("r4") _,
                    out("r5") _,
                    out("r8") _,
                    out("r9") _,
                    out("r10") _,
                    out("r11") _,
                );
            }
        }
        if tail > 0 {
            // Columns past the last whole group: `tail` bytes per row after a block's groups.
            for (blk, out) in acc.chunks_exact_mut(4).take(full).enumerate() {
                let at = 4 * blk * cols + 4 * whole;
                for (i, a) in out.iter_mut().enumerate() {
                    for j in 0..tail {
                        let wv = w.get(at + i * tail + j).map_or(0, |&b| b as i8 as i32);
                        *a = a.wrapping_add(wv * packed_get(xp, whole + j));
                    }
                }
            }
        }
        for r in 4 * full..rows {
            if let Some(o) = acc.get_mut(r) {
                *o = super::blocked_row_dot(w, rows, cols, r, xp);
            }
        }
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
        fn blocked_matvec_matches_the_rows(
            (rows, cols, seed) in (0usize..=13, 0usize..=41, proptest::num::u64::ANY)
        ) {
            let mut x = seed | 1;
            let mut next = move || { x ^= x << 13; x ^= x >> 7; x ^= x << 17; x };
            let w: std::vec::Vec<u8> = (0..rows * cols).map(|_| ((next() % 255) as i32 - 127) as i8 as u8).collect();
            let xs: std::vec::Vec<i8> = (0..cols).map(|_| ((next() % 255) as i32 - 127) as i8).collect();
            let mut xp = [0u32; packed_words(crate::nn::MAX_WIDTH)];
            pack_i8_pairs(&xs, &mut xp);
            let mut blocked = std::vec![0u8; rows * cols];
            block_rows(&w, rows, cols, &mut blocked).unwrap();
            let mut back = std::vec![0u8; rows * cols];
            unblock_rows(&blocked, rows, cols, &mut back).unwrap();
            proptest::prop_assert_eq!(&back, &w);
            let want: std::vec::Vec<i32> = (0..rows).map(|r| naive(&w[r * cols..(r + 1) * cols], &xs)).collect();
            let mut acc = std::vec![0i32; rows];
            matvec_i8_packed_portable(&blocked, rows, cols, &xp[..packed_words(cols)], &mut acc);
            proptest::prop_assert_eq!(&acc, &want);
            let mut acc = std::vec![0i32; rows];
            matvec_i8_packed(&blocked, rows, cols, &xp[..packed_words(cols)], &mut acc);
            proptest::prop_assert_eq!(&acc, &want);
            let mut row = std::vec![0u8; cols];
            for r in 0..rows {
                blocked_row(&blocked, rows, cols, r, &mut row);
                proptest::prop_assert_eq!(&row[..], &w[r * cols..(r + 1) * cols]);
            }
        }
    }

    #[test]
    fn blocked_layout_example() {
        // 5 rows × 6 columns: one block of four rows, then a block of one; one whole group of
        // four columns and two tail columns per row.
        let (rows, cols) = (5, 6);
        let at = |r: usize, c: usize| blocked_index(rows, cols, r, c);
        assert_eq!(
            (0..4).map(|c| at(0, c)).collect::<std::vec::Vec<_>>(),
            [0, 1, 2, 3]
        );
        assert_eq!(
            (0..4).map(|c| at(1, c)).collect::<std::vec::Vec<_>>(),
            [4, 5, 6, 7]
        );
        assert_eq!(at(3, 3), 15);
        assert_eq!((at(0, 4), at(0, 5), at(1, 4), at(3, 5)), (16, 17, 18, 23));
        assert_eq!((at(4, 0), at(4, 3), at(4, 4), at(4, 5)), (24, 27, 28, 29));
        let mut seen = [false; 30];
        for r in 0..rows {
            for c in 0..cols {
                assert!(!seen[at(r, c)], "({r}, {c})");
                seen[at(r, c)] = true;
            }
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
        for (k, &v) in x.iter().enumerate() {
            assert_eq!(packed_get(&want, k), v as i32);
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
