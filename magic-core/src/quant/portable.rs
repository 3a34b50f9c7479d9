//! The portable int8 kernels: plain Rust, the host's path and the reference the Armv7E-M kernel
//! (the `dsp` module) is held to.
//!
//! [`dot_i8`] multiplies stored weight bytes with int8 activations directly;
//! [`dot_i8_packed_portable`] and [`matvec_i8_packed_portable`] read the packed activations and
//! blocked weights of [`super::layout`] lane by lane, as `SXTB16`/`SMLAD` compute them, so that
//! the host tests pin down the integers the board computes. Sums wrap like `SMLAD`'s.

use super::{blocked_index, packed_get};

/// Integer dot product of int8 weights (as stored bytes) with int8 activations.
///
/// This is the portable inner loop of every int8 layer (the host's path). Builds with the `dsp`
/// feature for ARMv7E-M use [`pack_i8_pairs`](super::pack_i8_pairs) and [`dot_i8_packed`](super::dot_i8_packed) instead, which give the same
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

/// `SXTB16 w` and `SXTB16 w, ROR #8` in plain Rust: bytes 0 and 2, then bytes 1 and 3 of `w`,
/// each sign-extended to a 16-bit half.
#[inline(always)]
pub fn sxtb16_pair(w: u32) -> [u32; 2] {
    let sx = |v: u32| {
        (v as u8 as i8 as i16 as u16 as u32) | ((v >> 16) as u8 as i8 as i16 as u16 as u32) << 16
    };
    [sx(w), sx(w >> 8)]
}

/// [`matvec_i8_packed`](super::matvec_i8_packed) in plain Rust, lane by lane as `SXTB16`/`SMLAD` compute it.
pub fn matvec_i8_packed_portable(w: &[u8], rows: usize, cols: usize, xp: &[u32], acc: &mut [i32]) {
    let rows = rows.min(acc.len());
    for (r, a) in acc[..rows].iter_mut().enumerate() {
        *a = blocked_row_dot(w, rows, cols, r, xp);
    }
}

/// Row `r` of a blocked matrix times packed activations, lane by lane.
pub(super) fn blocked_row_dot(w: &[u8], rows: usize, cols: usize, r: usize, xp: &[u32]) -> i32 {
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

/// [`dot_i8_packed`](super::dot_i8_packed) in plain Rust, lane by lane as `SXTB16`/`SMLAD` compute it.
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

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::quant::*;
    use proptest::prelude::Strategy;
    use std::vec;

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
    fn long_slices_wrap_instead_of_panicking() {
        // Regression (fuzzing): slices far longer than a layer overflowed the i32 sum (a panic
        // in builds with overflow checks).
        let n = 300_000;
        let (w, x) = (vec![0x81u8; n], vec![-127i8; n]);
        let want = (0..n).fold(0i32, |a, _| a.wrapping_add(127 * 127));
        assert_eq!(dot_i8(&w, &x), want);
        let mut xp = vec![0u32; packed_words(n)];
        pack_i8_pairs(&x, &mut xp);
        assert_eq!(dot_i8_packed_portable(&w, &xp), want);
    }
}
