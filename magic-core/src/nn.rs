//! Dense layers and the multilayer perceptrons built from them (encoder E, correction C).
//!
//! A [`Layer`] is either f32 (weights as little-endian bytes) or int8 (see [`crate::quant`]). An MLP
//! is a slice of layers run by [`run`] with caller-provided [`Scratch`] buffers of the compiled
//! width [`MAX_WIDTH`], so nothing is allocated and the stack use is fixed. Chains of int8 layers
//! stay in int8 between layers (integer requantisation); an int8 layer followed by an f32 layer,
//! or the last layer, dequantises to f32.

use crate::quant::{
    matvec_i8_packed, pack_word, packed_set, packed_words, quantize, requantize_floor, LeF32, LeI32,
};
use crate::{Error, LayerArray, LayerFault, Net};
use serde::{Deserialize, Serialize};

/// The widest layer input or output the compiled core supports.
pub const MAX_WIDTH: usize = 256;

/// Largest number of layers in one MLP.
pub const MAX_LAYERS: usize = 8;

/// Element-wise activation after a layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activation {
    /// Identity.
    Linear,
    /// max(0, x).
    Relu,
    /// 1 / (1 + e^(−x)).
    Sigmoid,
}

/// The weights of a layer.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Weights<'a> {
    /// f32 weights, row-major `rows × cols`, and f32 bias.
    F32 {
        /// Weights.
        #[serde(borrow)]
        w: LeF32<'a>,
        /// Bias, one per row.
        #[serde(borrow)]
        bias: LeF32<'a>,
    },
    /// int8 weights, symmetric per output row.
    Int8 {
        /// Alignment padding (0 to 3 bytes, contents ignored): the exporter chooses its length so
        /// that `w` starts at a multiple of four bytes from the start of the model file, which
        /// lets the `SMLAD` kernel load weights with `LDM` (an embedded file is word aligned).
        #[serde(borrow)]
        pad: &'a [u8],
        /// Weights `rows × cols`, one byte each (two's complement), in blocks of four rows
        /// interleaved by groups of four columns: see [`crate::quant::blocked_index`].
        #[serde(borrow)]
        w: &'a [u8],
        /// Bias in accumulator units (`bias / (w_scale[r] · in_scale)`).
        #[serde(borrow)]
        bias: LeI32<'a>,
        /// Weight scale per row.
        #[serde(borrow)]
        w_scale: LeF32<'a>,
        /// Requantisation multiplier per row (see [`crate::quant::requantize`]).
        #[serde(borrow)]
        mult: LeI32<'a>,
        /// Requantisation shift per row (two's complement bytes).
        #[serde(borrow)]
        shift: &'a [u8],
        /// Scale of the int8 input activations.
        in_scale: f32,
        /// Scale of the int8 output activations when the next layer is int8.
        out_scale: f32,
    },
}

/// One dense layer `y = act(W x + b)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layer<'a> {
    /// Outputs.
    pub rows: u16,
    /// Inputs.
    pub cols: u16,
    /// Activation applied to the outputs.
    pub act: Activation,
    /// Weights and biases.
    #[serde(borrow)]
    pub weights: Weights<'a>,
}

impl Layer<'_> {
    /// Whether the layer is int8.
    pub fn is_int8(&self) -> bool {
        matches!(self.weights, Weights::Int8 { .. })
    }

    /// Checks byte lengths, finiteness of scales and requantisation shifts.
    pub fn validate(&self) -> Result<(), LayerFault> {
        let (r, c) = (self.rows as usize, self.cols as usize);
        if r == 0 || c == 0 || r > MAX_WIDTH || c > MAX_WIDTH {
            return Err(LayerFault::Size);
        }
        match self.weights {
            Weights::F32 { w, bias } => {
                bytes(LayerArray::Weights, w.0.len(), 4 * r * c)?;
                bytes(LayerArray::Bias, bias.0.len(), 4 * r)?;
                if !w.iter().chain(bias.iter()).all(f32::is_finite) {
                    return Err(LayerFault::NonFiniteWeight);
                }
                Ok(())
            }
            Weights::Int8 { .. } => self.validate_int8(),
        }
    }

    /// The checks of an int8 layer.
    fn validate_int8(&self) -> Result<(), LayerFault> {
        let Weights::Int8 {
            pad,
            w,
            bias,
            w_scale,
            mult,
            shift,
            in_scale,
            out_scale,
        } = self.weights
        else {
            return Ok(());
        };
        let (r, c) = (self.rows as usize, self.cols as usize);
        if pad.len() > 3 {
            return Err(LayerFault::Padding);
        }
        bytes(LayerArray::Weights, w.len(), r * c)?;
        bytes(LayerArray::Bias, bias.0.len(), 4 * r)?;
        // The weight scales serve a layer whose outputs are dequantised, the multipliers and
        // shifts one whose outputs are requantised for the next int8 layer: each may be left
        // out (empty) where the chain does not use it (`validate_chain`).
        let opt = |array, found: usize, n: usize| {
            if found == 0 {
                Ok(())
            } else {
                bytes(array, found, n)
            }
        };
        opt(LayerArray::Scales, w_scale.0.len(), 4 * r)?;
        opt(LayerArray::Multipliers, mult.0.len(), 4 * r)?;
        opt(LayerArray::Shifts, shift.len(), r)?;
        let ok_scale = |s: f32| s.is_finite() && s > 0.0;
        if !ok_scale(in_scale) || !out_scale.is_finite() || out_scale < 0.0 {
            return Err(LayerFault::ActivationScale);
        }
        if !w_scale.iter().all(ok_scale) {
            return Err(LayerFault::WeightScale);
        }
        // (A plain loop, not `contains`: its word-at-a-time search is 186 bytes of the board's
        // flash, for a check made once per model.)
        #[allow(clippy::manual_contains)]
        let minus_128 = w.iter().any(|&b| b == 0x80);
        if minus_128 {
            return Err(LayerFault::WeightMinus128);
        }
        if shift.iter().any(|&s| !(-30..=30).contains(&(s as i8))) {
            return Err(LayerFault::Shift);
        }
        if (0..r).any(|i| mult.get(i) < 0) {
            return Err(LayerFault::NegativeMultiplier);
        }
        Ok(())
    }
}

/// `Ok` when one of a layer's arrays has the bytes required, else [`LayerFault::Bytes`].
fn bytes(array: LayerArray, found: usize, expected: usize) -> Result<(), LayerFault> {
    if found == expected {
        Ok(())
    } else {
        Err(LayerFault::Bytes {
            array,
            expected,
            found,
        })
    }
}

/// Checks that a chain of layers (the model's `net`) is valid and maps `input` values to `output`
/// values; int8 layers that feed int8 layers must agree on the activation scale.
pub fn validate_chain(
    layers: &[Layer<'_>],
    input: usize,
    output: usize,
    net: Net,
) -> Result<(), Error> {
    if layers.is_empty() {
        return Err(Error::CountOutOfRange {
            what: match net {
                Net::Encoder => "encoder layers",
                Net::Decoder => "decoder layers",
            },
            found: 0,
            min: 1,
            max: MAX_LAYERS as u16,
        });
    }
    let mut width = input;
    for (i, l) in layers.iter().enumerate() {
        let next = layers.get(i + 1);
        link_fault(l, next, width).map_err(|fault| Error::InvalidLayer {
            net,
            layer: i as u8, // i < MAX_LAYERS
            fault,
        })?;
        width = l.rows as usize;
    }
    if width != output {
        return Err(Error::SizeMismatch {
            what: "network outputs",
            expected: output,
            found: width,
        });
    }
    Ok(())
}

/// The checks of layer `l` in its chain: its own ([`Layer::validate`]), its input count
/// against the previous `width`, and its fit with the `next` layer.
fn link_fault(l: &Layer<'_>, next: Option<&Layer<'_>>, width: usize) -> Result<(), LayerFault> {
    l.validate()?;
    let next_int8 = next.is_some_and(|n| n.is_int8());
    if let Weights::Int8 {
        w_scale,
        mult,
        shift,
        ..
    } = l.weights
    {
        let r = l.rows as usize;
        if next_int8 {
            bytes(LayerArray::Multipliers, mult.0.len(), 4 * r)?;
            bytes(LayerArray::Shifts, shift.len(), r)?;
        } else {
            bytes(LayerArray::Scales, w_scale.0.len(), 4 * r)?;
        }
    }
    if l.cols as usize != width {
        return Err(LayerFault::Inputs {
            expected: width.min(u16::MAX as usize) as u16,
            found: l.cols,
        });
    }
    if let (
        Weights::Int8 { out_scale, .. },
        Some(Layer {
            weights: Weights::Int8 { in_scale, .. },
            ..
        }),
    ) = (l.weights, next)
    {
        if out_scale != *in_scale {
            return Err(LayerFault::ScaleChain);
        }
    }
    if l.is_int8() && l.act == Activation::Sigmoid && next_int8 {
        return Err(LayerFault::SigmoidBetweenInt8);
    }
    Ok(())
}

/// Working memory for [`run`]: two f32 buffers of [`MAX_WIDTH`], two buffers of int8
/// activations of [`MAX_WIDTH`], packed as sign-extended 16-bit pairs (the layout of
/// [`crate::quant::pack_i8_pairs`], which the `SMLAD` kernel reads; the same layout on every
/// target, so the board and the host run the same code), and the i32 accumulators of a layer.
#[derive(Clone, Debug)]
pub struct Scratch {
    f: [[f32; MAX_WIDTH]; 2],
    q: [[u32; packed_words(MAX_WIDTH)]; 2],
    acc: [i32; MAX_WIDTH],
}

impl Scratch {
    /// Zeroed working memory (`const`: a static can hold it without building it on the stack).
    pub const fn new() -> Self {
        Scratch {
            f: [[0.0; MAX_WIDTH]; 2],
            q: [[0; packed_words(MAX_WIDTH)]; 2],
            acc: [0; MAX_WIDTH],
        }
    }
}

impl Default for Scratch {
    // Not `Scratch::new()`: through the const fn, LLVM builds the firmware's run-time singleton
    // of the working memory from two stack copies (a 7 KiB frame, `sub sp, #7176`), which
    // overflows the board's 8 KiB stack at start-up (a hard fault); this constructor is built in
    // place.
    fn default() -> Self {
        Scratch {
            f: [[0.0; MAX_WIDTH]; 2],
            q: [[0; packed_words(MAX_WIDTH)]; 2],
            acc: [0; MAX_WIDTH],
        }
    }
}

#[inline]
fn activate(x: f32, act: Activation) -> f32 {
    match act {
        Activation::Linear => x,
        Activation::Relu => {
            if x > 0.0 {
                x
            } else {
                0.0
            }
        }
        Activation::Sigmoid => 1.0 / (1.0 + libm::expf(-x)),
    }
}

/// Quantises `x` (f32) with the inverse scale `inv` into packed int8 activations `xp`.
fn quantize_packed(x: &[f32], inv: f32, xp: &mut [u32]) {
    let mut groups = x.chunks_exact(4);
    let mut words = xp.chunks_exact_mut(2);
    for (g, w) in (&mut groups).zip(&mut words) {
        let q = |j: usize| quantize(g[j], inv) as u8;
        let word = u32::from_le_bytes([q(0), q(1), q(2), q(3)]);
        [w[0], w[1]] = pack_word(word);
    }
    let base = x.len() - groups.remainder().len();
    for (k, &v) in groups.remainder().iter().enumerate() {
        packed_set(xp, base + k, quantize(v, inv));
    }
}

/// Little-endian i32 of four bytes (a chunk of exactly four; anything else reads as 0).
#[inline(always)]
fn le_i32(b: &[u8]) -> i32 {
    match *b {
        [b0, b1, b2, b3] => i32::from_le_bytes([b0, b1, b2, b3]),
        _ => 0,
    }
}

/// Where an int8 layer writes its rows.
enum Dest<'a> {
    /// Requantised int8 for the next int8 layer (packed), with ReLU when `relu`.
    Int8 { xp: &'a mut [u32], relu: bool },
    /// Dequantised f32, then the activation.
    F32 { y: &'a mut [f32], act: Activation },
}

/// One int8 layer: `rows × cols` weights `w` (row-major; byte lengths checked by the caller) on
/// packed activations `xp`. First every row's dot product into `acc` (the row-blocked kernel,
/// two rows per activation load), then one pass over the rows adding the bias and requantising
/// (then packed, four rows per pair of words: [`requantize_packed`]) or dequantising.
#[allow(clippy::too_many_arguments)]
fn int8_layer(
    w: &[u8],
    rows: usize,
    cols: usize,
    xp: &[u32],
    acc: &mut [i32],
    bias: &[u8],
    mult: &[u8],
    shift: &[u8],
    w_scale: &[u8],
    in_scale: f32,
    dest: Dest<'_>,
) {
    let rows = rows.min(acc.len());
    matvec_i8_packed(w, rows, cols, xp, acc);
    let acc = &mut acc[..rows];
    match dest {
        Dest::Int8 { xp: out, relu } => {
            requantize_packed(acc, bias, mult, shift, relu, out);
        }
        Dest::F32 { y, act } => {
            for (((o, &a), b), ws) in y
                .iter_mut()
                .zip(acc.iter())
                .zip(bias.chunks_exact(4))
                .zip(w_scale.chunks_exact(4))
            {
                let a = a.saturating_add(le_i32(b));
                let s = f32::from_bits(le_i32(ws) as u32);
                *o = activate(a as f32 * (s * in_scale), act);
            }
        }
    }
}

/// Requantises the accumulators `acc` of an int8 layer (plus `bias`, by the multipliers `mult`
/// and shifts `shift`: four bytes, four bytes and one byte per row; lengths checked by the
/// caller) into the next layer's packed activations `out` (the layout of
/// [`crate::quant::pack_i8_pairs`]), with ReLU when `relu`. The int8 values go back into `acc`,
/// one per row, and are packed from there, four rows per pair of words (zeros past the last
/// row): no int8 buffer to clear first.
fn requantize_packed(
    acc: &mut [i32],
    bias: &[u8],
    mult: &[u8],
    shift: &[u8],
    relu: bool,
    out: &mut [u32],
) {
    let floor = if relu { 0 } else { -127 };
    for ((a, b), (m, &sh)) in acc
        .iter_mut()
        .zip(bias.chunks_exact(4))
        .zip(mult.chunks_exact(4).zip(shift))
    {
        *a = requantize_floor(a.saturating_add(le_i32(b)), le_i32(m), sh as i8, floor) as i32;
    }
    let half = |v: i32| v as u32 & 0xFFFF;
    let groups = acc.chunks_exact(4);
    let tail = groups.remainder();
    let mut words = out.chunks_exact_mut(2);
    for (g, pair) in groups.zip(&mut words) {
        if let [a0, a1, a2, a3] = *g {
            pair[0] = half(a0) | ((a2 as u32) << 16);
            pair[1] = half(a1) | ((a3 as u32) << 16);
        }
    }
    if let (false, Some(pair)) = (tail.is_empty(), words.next()) {
        let at = |j: usize| tail.get(j).copied().unwrap_or(0);
        pair[0] = half(at(0)) | ((at(2) as u32) << 16);
        pair[1] = half(at(1)) | ((at(3) as u32) << 16);
    }
}

impl Scratch {
    /// The input buffer of [`run_scratch`]: write the network's inputs to its first entries.
    pub fn input(&mut self) -> &mut [f32; MAX_WIDTH] {
        &mut self.f[0]
    }
}

/// Runs a validated chain of layers on `input`, writing the last layer's outputs to `output`.
///
/// Layers must have passed [`validate_chain`]; sizes and byte lengths are checked again here
/// (cheaply) so that a mistake returns an error instead of reading out of bounds.
pub fn run(
    layers: &[Layer<'_>],
    input: &[f32],
    output: &mut [f32],
    s: &mut Scratch,
) -> Result<(), Error> {
    let n_in = input.len();
    let Some(dst) = s.input().get_mut(..n_in) else {
        return Err(Error::SizeMismatch {
            what: "network input",
            expected: MAX_WIDTH,
            found: n_in,
        });
    };
    dst.copy_from_slice(input);
    let y = run_scratch(layers, n_in, s)?;
    if output.len() != y.len() {
        return Err(Error::SizeMismatch {
            what: "network output",
            expected: y.len(),
            found: output.len(),
        });
    }
    output.copy_from_slice(y);
    Ok(())
}

/// An f32 layer of `cols` inputs: `dst[r] = act(bias[r] + Σ w[r][c] · src[c])`, `w` row-major.
#[inline(always)]
fn f32_layer(
    (w, bias, act): (LeF32<'_>, LeF32<'_>, Activation),
    cols: usize,
    src: &[f32],
    dst: &mut [f32],
) {
    for (r, (d, row)) in dst.iter_mut().zip(w.0.chunks_exact(4 * cols)).enumerate() {
        let mut acc = bias.get(r);
        for (wb, x) in row.chunks_exact(4).zip(src) {
            acc += f32::from_le_bytes([wb[0], wb[1], wb[2], wb[3]]) * x;
        }
        *d = activate(acc, act);
    }
}

/// Whether the byte arrays an int8 layer of `rows × cols` reads are whole (checked once per layer
/// by [`run_scratch`]; `next_int8` when its outputs are requantised for an int8 layer).
#[inline(always)]
fn int8_bytes_whole(
    weights: &Weights<'_>,
    rows: usize,
    cols: usize,
    next_int8: bool,
) -> Result<(), Error> {
    let Weights::Int8 {
        w,
        bias,
        w_scale,
        mult,
        shift,
        ..
    } = *weights
    else {
        return Ok(());
    };
    let (what, have, need) = if w.len() < rows * cols {
        ("int8 layer weight bytes", w.len(), rows * cols)
    } else if bias.0.len() < 4 * rows {
        ("int8 layer bias bytes", bias.0.len(), 4 * rows)
    } else if next_int8 && shift.len() < rows {
        ("int8 layer shift bytes", shift.len(), rows)
    } else if next_int8 && mult.0.len() < 4 * rows {
        ("int8 layer multiplier bytes", mult.0.len(), 4 * rows)
    } else if !next_int8 && w_scale.0.len() < 4 * rows {
        ("int8 layer scale bytes", w_scale.0.len(), 4 * rows)
    } else {
        ("", 0, 0)
    };
    if have < need {
        return Err(Error::SizeMismatch {
            what,
            expected: need,
            found: have,
        });
    }
    Ok(())
}

/// [`run`] on the first `n_in` entries of [`Scratch::input`], returning the outputs in place (a
/// slice of the working memory, valid until its next use).
pub fn run_scratch<'s>(
    layers: &[Layer<'_>],
    n_in: usize,
    s: &'s mut Scratch,
) -> Result<&'s [f32], Error> {
    if n_in > MAX_WIDTH {
        return Err(Error::SizeMismatch {
            what: "network input",
            expected: MAX_WIDTH,
            found: n_in,
        });
    }
    // Which buffer holds the current activations, and whether they are the int8 (packed) ones.
    let mut cur = 0usize;
    let mut in_int8 = false;
    let mut width = n_in;
    for (i, l) in layers.iter().enumerate() {
        let (rows, cols) = (l.rows as usize, l.cols as usize);
        if cols != width || rows > MAX_WIDTH || cols > MAX_WIDTH || cols == 0 {
            return Err(Error::SizeMismatch {
                what: "layer inputs",
                expected: width,
                found: cols,
            });
        }
        let next = layers.get(i + 1);
        let next_int8 = next.is_some_and(|n| n.is_int8());
        let [f0, f1] = &mut s.f;
        let [q0, q1] = &mut s.q;
        let acc = &mut s.acc;
        let ((f_src, f_dst), (q_src, q_dst)) = if cur == 0 {
            ((f0, f1), (q0, q1))
        } else {
            ((f1, f0), (q1, q0))
        };
        match l.weights {
            Weights::F32 { w, bias } => {
                if in_int8 {
                    return Err(Error::InvalidModel("f32 layer after int8 output"));
                }
                if w.0.len() < 4 * rows * cols {
                    return Err(Error::SizeMismatch {
                        what: "f32 layer weight bytes",
                        expected: 4 * rows * cols,
                        found: w.0.len(),
                    });
                }
                // (Checked slicing: no panic paths; `rows`, `cols` ≤ MAX_WIDTH was checked.)
                let src = f_src.get(..cols).unwrap_or(&[]);
                let dst = f_dst.get_mut(..rows).unwrap_or(&mut []);
                f32_layer((w, bias, l.act), cols, src, dst);
                if let Some(Layer {
                    weights: Weights::Int8 { in_scale, .. },
                    ..
                }) = next
                {
                    quantize_packed(f_dst.get(..rows).unwrap_or(&[]), 1.0 / in_scale, q_dst);
                    in_int8 = true;
                }
            }
            Weights::Int8 {
                w,
                bias,
                w_scale,
                mult,
                shift,
                in_scale,
                ..
            } => {
                int8_bytes_whole(&l.weights, rows, cols, next_int8)?;
                if !in_int8 {
                    quantize_packed(f_src.get(..cols).unwrap_or(&[]), 1.0 / in_scale, q_src);
                }
                let dest = if next_int8 {
                    Dest::Int8 {
                        xp: q_dst,
                        relu: l.act == Activation::Relu,
                    }
                } else {
                    Dest::F32 {
                        y: f_dst.get_mut(..rows).unwrap_or(&mut []),
                        act: l.act,
                    }
                };
                int8_layer(
                    w,
                    rows,
                    cols,
                    q_src.get(..packed_words(cols)).unwrap_or(&[]),
                    acc,
                    bias.0,
                    mult.0,
                    shift,
                    w_scale.0,
                    in_scale,
                    dest,
                );
                in_int8 = next_int8;
            }
        }
        cur = 1 - cur;
        width = rows;
    }
    if in_int8 {
        return Err(Error::InvalidModel("network ends in int8"));
    }
    let [f0, f1] = &s.f;
    Ok((if cur == 0 { f0 } else { f1 }).get(..width).unwrap_or(&[]))
}

#[cfg(test)]
mod tests;
