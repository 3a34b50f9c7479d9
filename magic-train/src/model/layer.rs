//! Dense layers owned by the host: f32 or int8 weights, their model-file bytes, and an f32
//! forward pass for calibration.

use super::{le_f32_bytes, le_i32_bytes};
use magic_core::nn::{Activation, Layer, Weights};
use magic_core::quant::{LeF32, LeI32};

/// Layer weights owned by the host.
#[derive(Clone, Debug)]
pub enum OwnedWeights {
    /// f32 weights (row-major) and bias.
    F32 {
        /// Weights.
        w: Vec<f32>,
        /// Bias.
        b: Vec<f32>,
    },
    /// int8 layer (see `magic_core::quant`).
    Int8 {
        /// Weights.
        w: Vec<i8>,
        /// Bias in accumulator units.
        bias: Vec<i32>,
        /// Per-row weight scale.
        w_scale: Vec<f32>,
        /// Per-row requantisation multiplier.
        mult: Vec<i32>,
        /// Per-row requantisation shift.
        shift: Vec<i8>,
        /// Input activation scale.
        in_scale: f32,
        /// Output activation scale (when the next layer is int8).
        out_scale: f32,
    },
}

/// A layer owned by the host.
#[derive(Clone, Debug)]
pub struct OwnedLayer {
    /// Outputs.
    pub rows: usize,
    /// Inputs.
    pub cols: usize,
    /// Activation.
    pub act: Activation,
    /// Weights.
    pub weights: OwnedWeights,
}

impl OwnedLayer {
    /// Copies a decoded layer (int8 weights back to row-major order).
    pub fn from_core(l: &Layer<'_>) -> OwnedLayer {
        let weights = match l.weights {
            Weights::F32 { w, bias } => OwnedWeights::F32 {
                w: w.iter().collect(),
                b: bias.iter().collect(),
            },
            Weights::Int8 {
                w,
                bias,
                w_scale,
                mult,
                shift,
                in_scale,
                out_scale,
                ..
            } => OwnedWeights::Int8 {
                w: {
                    let (r, c) = (l.rows as usize, l.cols as usize);
                    let mut row_major = vec![0u8; w.len()];
                    if magic_core::quant::unblock_rows(w, r, c, &mut row_major).is_err() {
                        row_major.copy_from_slice(w);
                    }
                    row_major.iter().map(|x| *x as i8).collect()
                },
                bias: (0..bias.len()).map(|i| bias.get(i)).collect(),
                w_scale: w_scale.iter().collect(),
                mult: (0..mult.len()).map(|i| mult.get(i)).collect(),
                shift: shift.iter().map(|x| *x as i8).collect(),
                in_scale,
                out_scale,
            },
        };
        OwnedLayer {
            rows: l.rows as usize,
            cols: l.cols as usize,
            act: l.act,
            weights,
        }
    }
}

pub(crate) struct LayerBytes {
    /// An int8 layer's bytes.
    pub(crate) int8: bool,
    /// Alignment padding before the int8 weights (see `OwnedModel::encode`).
    pub(crate) pad: usize,
    pub(crate) a: Vec<u8>,
    pub(crate) b: Vec<u8>,
    pub(crate) c: Vec<u8>,
    pub(crate) d: Vec<u8>,
    pub(crate) e: Vec<u8>,
}

pub(crate) fn layer_bytes(l: &OwnedLayer) -> LayerBytes {
    match &l.weights {
        OwnedWeights::F32 { w, b } => LayerBytes {
            int8: false,
            pad: 0,
            a: le_f32_bytes(w),
            b: le_f32_bytes(b),
            c: vec![],
            d: vec![],
            e: vec![],
        },
        OwnedWeights::Int8 {
            w,
            bias,
            w_scale,
            mult,
            shift,
            ..
        } => LayerBytes {
            int8: true,
            pad: 0,
            // The model file's blocked layout (magic_core::quant::blocked_index); a weight count
            // that does not match rows × cols is left row-major for validation to reject.
            a: {
                let row_major: Vec<u8> = w.iter().map(|x| *x as u8).collect();
                let mut blocked = vec![0u8; row_major.len()];
                match magic_core::quant::block_rows(&row_major, l.rows, l.cols, &mut blocked) {
                    Ok(()) => blocked,
                    Err(_) => row_major,
                }
            },
            b: le_i32_bytes(bias),
            c: le_f32_bytes(w_scale),
            d: le_i32_bytes(mult),
            e: shift.iter().map(|x| *x as u8).collect(),
        },
    }
}

pub(crate) fn borrow_layer<'a>(l: &OwnedLayer, b: &'a LayerBytes) -> Layer<'a> {
    let weights = match &l.weights {
        OwnedWeights::F32 { .. } => Weights::F32 {
            w: LeF32(&b.a),
            bias: LeF32(&b.b),
        },
        OwnedWeights::Int8 {
            in_scale,
            out_scale,
            ..
        } => Weights::Int8 {
            pad: &[0u8; 3][..b.pad.min(3)],
            w: &b.a,
            bias: LeI32(&b.b),
            w_scale: LeF32(&b.c),
            mult: LeI32(&b.d),
            shift: &b.e,
            in_scale: *in_scale,
            out_scale: *out_scale,
        },
    };
    Layer {
        rows: l.rows as u16,
        cols: l.cols as u16,
        act: l.act,
        weights,
    }
}

/// The f32 layer on one input row (empty for an int8 layer).
pub(crate) fn f32_forward(l: &OwnedLayer, x: &[f32]) -> Vec<f32> {
    let OwnedWeights::F32 { w, b } = &l.weights else {
        return vec![];
    };
    (0..l.rows)
        .map(|r| {
            let mut acc = b[r];
            for c in 0..l.cols {
                acc += w[r * l.cols + c] * x[c];
            }
            match l.act {
                Activation::Linear => acc,
                Activation::Relu => acc.max(0.0),
                Activation::Sigmoid => 1.0 / (1.0 + (-acc).exp()),
            }
        })
        .collect()
}
