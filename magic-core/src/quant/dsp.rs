//! The Armv7E-M DSP kernel (Cortex-M4/M7): two 16-bit multiply-accumulates per `SMLAD`.
//!
//! The portable [`super::dot_i8`] costs about 5.6 executed instructions per multiply-accumulate on a
//! Cortex-M4F; this kernel's loop costs 1.5 (per 16 weights: 4 `LDR`, 2 `LDM`, 8 `SXTB16`, 8
//! `SMLAD`, `CMP`, `BNE`). Measured under QEMU (`mps2-an386`, `-icount shift=0`) on the 36-input
//! Akutan model C (int8): encoder 47.5 k → 23.8 k instructions, correction 92.8 k → 40.3 k, a
//! whole inversion 176 k → 99 k. Inline assembly is the only way to these instructions on stable
//! Rust (the `dsp` target feature is not stable), hence the crate's only `unsafe` code. The firmware checks this kernel
//! against [`super::dot_i8`] on every row of its model at start-up; the host tests hold
//! [`super::dot_i8_packed_portable`] (same lanes, plain Rust) to [`super::dot_i8`].
use super::packed_get;
use core::arch::asm;

// The loop bodies of the kernels below, written once. Each expands to assembly text (one
// instruction per line) through `concat!`, so the kernels' instructions are exactly those
// written out: the instruction counts measured under QEMU do not depend on the macros.

/// One row of a group of four columns: the row's four weights in register `$w` (bytes 0–3),
/// the group's packed activations in `r2` (x0, x2) and `r3` (x1, x3); two `SMLAD`s add the four
/// products to accumulator `$acc`. `$w` is overwritten.
#[rustfmt::skip]
macro_rules! row_mac {
    ($acc:literal, $w:literal) => {
        concat!(
            "sxtb16 {t}, ", $w, "\n",
            "smlad ", $acc, ", {t}, r2, ", $acc, "\n",
            "sxtb16 ", $w, ", ", $w, ", ror #8\n",
            "smlad ", $acc, ", ", $w, ", r3, ", $acc, "\n",
        )
    };
}

/// One group of four columns for a block of four rows (accumulators `r8`–`r11`), the weights
/// loaded word by word with `LDR` (which may be unaligned).
macro_rules! group_ldr {
    () => {
        concat!(
            "ldm {xp}!, {{r2, r3}}\n",
            "ldr r5, [{wp}], #4\n",
            row_mac!("r8", "r5"),
            "ldr r5, [{wp}], #4\n",
            row_mac!("r9", "r5"),
            "ldr r5, [{wp}], #4\n",
            row_mac!("r10", "r5"),
            "ldr r5, [{wp}], #4\n",
            row_mac!("r11", "r5"),
        )
    };
}

/// One group of four columns for a block of four rows (accumulators `r8`–`r11`), the weights of
/// two rows at a time loaded with `LDM` (word aligned).
macro_rules! group_ldm {
    () => {
        concat!(
            "ldm {xp}!, {{r2, r3}}\n",
            "ldm {wp}!, {{r4, r5}}\n",
            row_mac!("r8", "r4"),
            row_mac!("r9", "r5"),
            "ldm {wp}!, {{r4, r5}}\n",
            row_mac!("r10", "r4"),
            row_mac!("r11", "r5"),
        )
    };
}

/// Two groups of four columns of one row (eight weights by two `LDR`, four activation words by
/// one `LDM`) into `{acc}`.
macro_rules! two_groups {
    () => {
        concat!(
            "ldr {w0}, [{wp}], #4\n",
            "ldr {w1}, [{wp}], #4\n",
            "ldm {xp}!, {{r2, r3, r4, r5}}\n",
            "sxtb16 {t}, {w0}\n",
            "smlad {acc}, {t}, r2, {acc}\n",
            "sxtb16 {t}, {w0}, ror #8\n",
            "smlad {acc}, {t}, r3, {acc}\n",
            "sxtb16 {t}, {w1}\n",
            "smlad {acc}, {t}, r4, {acc}\n",
            "sxtb16 {t}, {w1}, ror #8\n",
            "smlad {acc}, {t}, r5, {acc}\n",
        )
    };
}

/// The FPU's square root (`VSQRT.F32`, correctly rounded like libm's `sqrtf`, which on this
/// target is a software routine of about 80 instructions and 480 bytes). Used through
/// [`crate::real::sqrt::sqrt`].
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
        let aligned = (w.as_ptr() as usize) & 3 == 0 && tail == 0;
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
                group_ldr!(),
                "cmp {wp}, {end}",
                "bne 3b",
                "4:",
                "add {end}, {end}, r4",
                "cmp {wp}, {end}",
                "beq 6f",
                "5:",
                // Four groups per iteration, weights by LDM (word aligned).
                group_ldm!(),
                group_ldm!(),
                group_ldm!(),
                group_ldm!(),
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
            *o = super::portable::blocked_row_dot(w, rows, cols, r, xp);
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
                two_groups!(),
                two_groups!(),
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
