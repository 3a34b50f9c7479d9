//! Dense layers and the multilayer perceptrons built from them (encoder E, correction C).
//!
//! A [`Layer`] is either f32 (weights as little-endian bytes) or int8 (see [`crate::quant`]). An MLP
//! is a slice of layers run by [`run`] with caller-provided [`Scratch`] buffers of the compiled
//! width [`MAX_WIDTH`], so nothing is allocated and the stack use is fixed. Chains of int8 layers
//! stay in int8 between layers (integer requantisation); an int8 layer followed by an f32 layer,
//! or the last layer, dequantises to f32.

#[cfg(not(all(feature = "dsp", target_arch = "arm")))]
use crate::quant::dot_i8;
use crate::quant::{quantize, requantize, LeF32, LeI32};
use crate::Error;
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
        /// Weights, row-major `rows × cols`, one byte each (two's complement).
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
    pub fn validate(&self) -> Result<(), Error> {
        let (r, c) = (self.rows as usize, self.cols as usize);
        if r == 0 || c == 0 || r > MAX_WIDTH || c > MAX_WIDTH {
            return Err(Error::InvalidModel(
                "layer size is zero or wider than the compiled MAX_WIDTH",
            ));
        }
        let len = |what, bytes: usize, n: usize| {
            if bytes != n {
                Err(Error::SizeMismatch {
                    what,
                    expected: n,
                    found: bytes,
                })
            } else {
                Ok(())
            }
        };
        match self.weights {
            Weights::F32 { w, bias } => {
                len("f32 layer weight bytes", w.0.len(), 4 * r * c)?;
                len("f32 layer bias bytes", bias.0.len(), 4 * r)?;
                if !w.iter().chain(bias.iter()).all(f32::is_finite) {
                    return Err(Error::InvalidModel("non-finite f32 weight"));
                }
            }
            Weights::Int8 {
                w,
                bias,
                w_scale,
                mult,
                shift,
                in_scale,
                out_scale,
            } => {
                len("int8 layer weight bytes", w.len(), r * c)?;
                len("int8 layer bias bytes", bias.0.len(), 4 * r)?;
                len("int8 layer scale bytes", w_scale.0.len(), 4 * r)?;
                len("int8 layer multiplier bytes", mult.0.len(), 4 * r)?;
                len("int8 layer shift bytes", shift.len(), r)?;
                let ok_scale = |s: f32| s.is_finite() && s > 0.0;
                if !ok_scale(in_scale) || !(out_scale.is_finite() && out_scale >= 0.0) {
                    return Err(Error::InvalidModel(
                        "int8 activation scale not positive and finite",
                    ));
                }
                if !w_scale.iter().all(ok_scale) {
                    return Err(Error::InvalidModel(
                        "int8 weight scale not positive and finite",
                    ));
                }
                if w.iter().any(|&b| b == 0x80) {
                    return Err(Error::InvalidModel(
                        "int8 weight -128 (symmetric range is ±127)",
                    ));
                }
                for &s in shift {
                    if !(-30..=30).contains(&(s as i8)) {
                        return Err(Error::InvalidModel("requantisation shift outside -30..=30"));
                    }
                }
                if (0..r).any(|i| mult.get(i) < 0) {
                    return Err(Error::InvalidModel("negative requantisation multiplier"));
                }
            }
        }
        Ok(())
    }
}

/// Checks that a chain of layers is valid and maps `input` values to `output` values; int8 layers
/// that feed int8 layers must agree on the activation scale.
pub fn validate_chain(layers: &[Layer<'_>], input: usize, output: usize) -> Result<(), Error> {
    if layers.is_empty() {
        return Err(Error::InvalidModel("empty network"));
    }
    let mut width = input;
    for (i, l) in layers.iter().enumerate() {
        l.validate()?;
        if l.cols as usize != width {
            return Err(Error::SizeMismatch {
                what: "layer inputs",
                expected: width,
                found: l.cols as usize,
            });
        }
        if let (
            Weights::Int8 { out_scale, .. },
            Some(Layer {
                weights: Weights::Int8 { in_scale, .. },
                ..
            }),
        ) = (l.weights, layers.get(i + 1))
        {
            if out_scale != *in_scale {
                return Err(Error::InvalidModel(
                    "int8 layer output scale differs from next input scale",
                ));
            }
        }
        if l.is_int8()
            && l.act == Activation::Sigmoid
            && layers.get(i + 1).is_some_and(|n| n.is_int8())
        {
            return Err(Error::InvalidModel(
                "sigmoid between int8 layers is not supported",
            ));
        }
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

/// Working memory for [`run`]: two f32 and two int8 buffers of [`MAX_WIDTH`] (and, with the
/// `dsp` feature on ARM, the int8 activations packed in pairs for the `SMLAD` kernel).
#[derive(Clone, Debug)]
pub struct Scratch {
    f: [[f32; MAX_WIDTH]; 2],
    q: [[i8; MAX_WIDTH]; 2],
    #[cfg(all(feature = "dsp", target_arch = "arm"))]
    xp: [u32; crate::quant::packed_words(MAX_WIDTH)],
}

impl Default for Scratch {
    fn default() -> Self {
        Scratch {
            f: [[0.0; MAX_WIDTH]; 2],
            q: [[0; MAX_WIDTH]; 2],
            #[cfg(all(feature = "dsp", target_arch = "arm"))]
            xp: [0; crate::quant::packed_words(MAX_WIDTH)],
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

/// Runs a validated chain of layers on `input`, writing the last layer's outputs to `output`.
///
/// Layers must have passed [`validate_chain`]; sizes are checked again here (cheaply) so that a
/// mistake returns an error instead of reading out of bounds.
pub fn run(
    layers: &[Layer<'_>],
    input: &[f32],
    output: &mut [f32],
    s: &mut Scratch,
) -> Result<(), Error> {
    let n_in = input.len();
    if n_in > MAX_WIDTH {
        return Err(Error::SizeMismatch {
            what: "network input",
            expected: MAX_WIDTH,
            found: n_in,
        });
    }
    s.f[0][..n_in].copy_from_slice(input);
    // Which representation holds the current activations: f32 buffer `cur` or int8 buffer `cur`.
    let mut cur = 0usize;
    let mut in_int8 = false;
    let mut width = n_in;
    for (i, l) in layers.iter().enumerate() {
        let (rows, cols) = (l.rows as usize, l.cols as usize);
        if cols != width || rows > MAX_WIDTH {
            return Err(Error::SizeMismatch {
                what: "layer inputs",
                expected: width,
                found: cols,
            });
        }
        let next_int8 = layers.get(i + 1).is_some_and(|n| n.is_int8());
        let nxt = 1 - cur;
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
                let (a, b) = s.f.split_at_mut(1);
                let (src, dst) = if cur == 0 {
                    (&a[0], &mut b[0])
                } else {
                    (&b[0], &mut a[0])
                };
                for r in 0..rows {
                    let mut acc = bias.get(r);
                    let row = &w.0[4 * r * cols..4 * (r + 1) * cols];
                    for (wb, x) in row.chunks_exact(4).zip(&src[..cols]) {
                        acc += f32::from_le_bytes([wb[0], wb[1], wb[2], wb[3]]) * x;
                    }
                    dst[r] = activate(acc, l.act);
                }
                if next_int8 {
                    if let Some(Layer {
                        weights: Weights::Int8 { in_scale, .. },
                        ..
                    }) = layers.get(i + 1)
                    {
                        let inv = 1.0 / in_scale;
                        for r in 0..rows {
                            s.q[nxt][r] = quantize(s.f[nxt][r], inv);
                        }
                    }
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
                if w.len() < rows * cols {
                    return Err(Error::SizeMismatch {
                        what: "int8 layer weight bytes",
                        expected: rows * cols,
                        found: w.len(),
                    });
                }
                if next_int8 && shift.len() < rows {
                    return Err(Error::SizeMismatch {
                        what: "int8 layer shift bytes",
                        expected: rows,
                        found: shift.len(),
                    });
                }
                if !in_int8 {
                    let inv = 1.0 / in_scale;
                    for c in 0..cols {
                        s.q[cur][c] = quantize(s.f[cur][c], inv);
                    }
                }
                #[cfg(all(feature = "dsp", target_arch = "arm"))]
                crate::quant::pack_i8_pairs(&s.q[cur][..cols], &mut s.xp);
                for r in 0..rows {
                    let row = &w[r * cols..(r + 1) * cols];
                    #[cfg(all(feature = "dsp", target_arch = "arm"))]
                    let dot = crate::quant::dot_i8_packed(row, &s.xp);
                    #[cfg(not(all(feature = "dsp", target_arch = "arm")))]
                    let dot = dot_i8(row, &s.q[cur][..cols]);
                    let acc = dot.saturating_add(bias.get(r));
                    if next_int8 {
                        let sh = shift[r] as i8;
                        let mut q = requantize(acc, mult.get(r), sh);
                        if l.act == Activation::Relu && q < 0 {
                            q = 0;
                        }
                        s.q[nxt][r] = q;
                    } else {
                        let y = acc as f32 * (w_scale.get(r) * in_scale);
                        s.f[nxt][r] = activate(y, l.act);
                    }
                }
                in_int8 = next_int8;
            }
        }
        cur = nxt;
        width = rows;
    }
    if in_int8 {
        return Err(Error::InvalidModel("network ends in int8"));
    }
    if output.len() != width {
        return Err(Error::SizeMismatch {
            what: "network output",
            expected: width,
            found: output.len(),
        });
    }
    output.copy_from_slice(&s.f[cur][..width]);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_answers_unvalidated_layers_with_errors() {
        // Regression (fuzzing): `run` indexed weight and shift bytes without checking their
        // lengths, so a layer that skipped `validate` panicked instead of returning an error.
        let (w, b) = ([0u8; 4 * 3], [0u8; 4 * 2]);
        let short_f32 = Layer {
            rows: 2,
            cols: 2,
            act: Activation::Linear,
            weights: Weights::F32 {
                w: LeF32(&w),
                bias: LeF32(&b),
            },
        };
        let mut out = [0f32; 2];
        let e = run(&[short_f32], &[1.0, 2.0], &mut out, &mut Scratch::default());
        assert_eq!(
            e,
            Err(Error::SizeMismatch {
                what: "f32 layer weight bytes",
                expected: 16,
                found: 12
            })
        );

        let int8 = |w: &'static [u8], shift: &'static [u8]| Layer {
            rows: 2,
            cols: 2,
            act: Activation::Relu,
            weights: Weights::Int8 {
                w,
                bias: LeI32(&[]),
                w_scale: LeF32(&[]),
                mult: LeI32(&[]),
                shift,
                in_scale: 1.0,
                out_scale: 1.0,
            },
        };
        let e = run(
            &[int8(&[1u8; 3], &[0u8; 2])],
            &[1.0, 2.0],
            &mut out,
            &mut Scratch::default(),
        );
        assert!(
            matches!(
                e,
                Err(Error::SizeMismatch {
                    what: "int8 layer weight bytes",
                    ..
                })
            ),
            "{e:?}"
        );
        let e = run(
            &[int8(&[1u8; 4], &[0u8; 1]), int8(&[1u8; 4], &[0u8; 2])],
            &[1.0, 2.0],
            &mut out,
            &mut Scratch::default(),
        );
        assert!(
            matches!(
                e,
                Err(Error::SizeMismatch {
                    what: "int8 layer shift bytes",
                    ..
                })
            ),
            "{e:?}"
        );
        // The same layers with whole byte arrays run.
        assert!(run(
            &[int8(&[1u8; 4], &[0u8; 2]), int8(&[1u8; 4], &[0u8; 2])],
            &[1.0, 2.0],
            &mut out,
            &mut Scratch::default()
        )
        .is_ok());
    }
}
