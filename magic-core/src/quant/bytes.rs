//! Byte views: little-endian `f32` and `i32` arrays borrowed from a model file.
//!
//! A model's weights, scales and biases stay where they are (in flash on the board): these views
//! read them element by element, with no alignment requirement and no copy.

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_read_little_endian_and_zero_past_the_end() {
        let mut b = [0u8; 9];
        b[..4].copy_from_slice(&1.5f32.to_le_bytes());
        b[4..8].copy_from_slice(&(-7i32).to_le_bytes());
        let (f, i) = (LeF32(&b), LeI32(&b[4..]));
        assert_eq!((f.len(), i.len()), (2, 1));
        assert_eq!((f.get(0), i.get(0)), (1.5, -7));
        assert_eq!((f.get(2), i.get(1)), (0.0, 0));
        assert_eq!(f.iter().count(), 2);
        assert!(LeF32(&b[..3]).is_empty() && !i.is_empty());
    }
}
