//! The layout the `SMLAD` kernel reads: int8 weights in blocks of four rows (the model file's
//! order since format version 5) and int8 activations packed as sign-extended 16-bit pairs.
//!
//! Both are chosen so that one `LDM` fetches the weights of two rows and one `SXTB16` pair plus
//! two `SMLAD`s perform four multiply-accumulates (the `dsp` module on ARM); the portable
//! kernels read the same layout lane by lane.

use super::pack_word;
use crate::Error;

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

/// Number of `u32` words [`pack_i8_pairs`] writes for `n` activations: two per group of four.
#[inline]
pub const fn packed_words(n: usize) -> usize {
    n.div_ceil(4) * 2
}

/// Packs int8 activations as sign-extended 16-bit pairs for [`dot_i8_packed`](super::dot_i8_packed).
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

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::quant::*;

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
}
