//! Model files from the host side: owned layers and effects, a model built from a trained
//! [`Net`], encoding through magic-core's [`Model`] (and back), and int8 export.

mod effect;
mod int8;
mod layer;
mod spec;

pub use effect::{OwnedEffect, SAME_SOURCE_KM, SAME_STEP_DAYS};
pub use layer::{OwnedLayer, OwnedWeights};
pub use spec::{intern, owned_problem, problem_bytes};

use crate::nets::{Mlp, Net};
use anyhow::Result;
use layer::{borrow_layer, layer_bytes, LayerBytes};
use magic_core::model_file::{Model, Problem, Variant};
use magic_core::nn::Weights;
use magic_core::quant::LeF32;
use magic_core::{invert_at, Workspace};

/// A model owned by the host, convertible to and from model-file bytes.
#[derive(Clone, Debug)]
pub struct OwnedModel {
    /// Paper variant.
    pub variant: Variant,
    /// Problem description (RTM table bytes interned: see [`intern`]).
    pub problem: Problem<'static>,
    /// Observation mean.
    pub mean: Vec<f32>,
    /// Observation scale.
    pub scale: Vec<f32>,
    /// Variable bounds.
    pub bounds: Vec<[f32; 2]>,
    /// Encoder.
    pub encoder: Vec<OwnedLayer>,
    /// Correction / decoder.
    pub decoder: Vec<OwnedLayer>,
    /// Residual flag threshold (standardised RMS).
    pub residual_threshold: f32,
    /// Declared effects.
    pub effects: Vec<OwnedEffect>,
}

/// Little-endian bytes of f32 values.
pub(crate) fn le_f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Little-endian bytes of i32 values.
pub(crate) fn le_i32_bytes(v: &[i32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Offsets from the start of `bytes` (an encoded model) of every int8 layer's weights, encoder
/// first, in file order.
fn int8_weight_offsets(bytes: &[u8]) -> Result<Vec<usize>> {
    let m = Model::decode(bytes)
        .map_err(|e| anyhow::anyhow!("the encoded model does not validate: {e}"))?;
    let start = bytes.as_ptr() as usize;
    Ok(m.encoder
        .iter()
        .chain(m.decoder.iter())
        .filter_map(|l| match l.weights {
            Weights::Int8 { w, .. } => Some(w.as_ptr() as usize - start),
            Weights::F32 { .. } => None,
        })
        .collect())
}

impl OwnedModel {
    /// Encodes to model-file bytes (validated by decoding them again). Every int8 layer's
    /// weights start at a multiple of four bytes from the start of the file (the padding before
    /// them is chosen after a first encoding), so that the board's kernel can load them by words.
    pub fn encode(&self) -> Result<Vec<u8>> {
        let mut enc_b: Vec<LayerBytes> = self.encoder.iter().map(layer_bytes).collect();
        let mut dec_b: Vec<LayerBytes> = self.decoder.iter().map(layer_bytes).collect();
        // An int8 layer feeding an int8 layer needs its multipliers and shifts, one whose outputs
        // are dequantised its weight scales: the other arrays are left out (1.2 KB of the
        // board's 20 KB model).
        for bytes in [&mut enc_b, &mut dec_b] {
            let int8: Vec<bool> = bytes.iter().map(|b| b.int8).collect();
            for (i, b) in bytes.iter_mut().enumerate() {
                if b.int8 {
                    if int8.get(i + 1).copied().unwrap_or(false) {
                        b.c.clear();
                    } else {
                        b.d.clear();
                        b.e.clear();
                    }
                }
            }
        }
        let first = self.encode_bytes(&enc_b, &dec_b)?;
        let offsets = int8_weight_offsets(&first)?;
        // A padding's length prefix is one byte whatever its length (0–3): each padding shifts
        // only what follows it, by its length.
        let mut shift = 0;
        for (b, off) in enc_b
            .iter_mut()
            .chain(dec_b.iter_mut())
            .filter(|b| b.int8)
            .zip(&offsets)
        {
            b.pad = (4 - (off + shift) % 4) % 4;
            shift += b.pad;
        }
        let bytes = self.encode_bytes(&enc_b, &dec_b)?;
        if int8_weight_offsets(&bytes)?.iter().any(|o| o % 4 != 0) {
            anyhow::bail!("internal error: int8 weights not aligned in the encoded model");
        }
        Ok(bytes)
    }

    fn encode_bytes(&self, enc_b: &[LayerBytes], dec_b: &[LayerBytes]) -> Result<Vec<u8>> {
        let mean = le_f32_bytes(&self.mean);
        let scale = le_f32_bytes(&self.scale);
        let mut encoder = heapless::Vec::new();
        for (l, b) in self.encoder.iter().zip(enc_b) {
            encoder
                .push(borrow_layer(l, b))
                .map_err(|_| anyhow::anyhow!("too many encoder layers"))?;
        }
        let mut decoder = heapless::Vec::new();
        for (l, b) in self.decoder.iter().zip(dec_b) {
            decoder
                .push(borrow_layer(l, b))
                .map_err(|_| anyhow::anyhow!("too many decoder layers"))?;
        }
        let mut bounds = heapless::Vec::new();
        for b in &self.bounds {
            bounds
                .push(*b)
                .map_err(|_| anyhow::anyhow!("too many variables"))?;
        }
        let eff_b: Vec<Vec<u8>> = self.effects.iter().map(OwnedEffect::bytes).collect();
        let mut effects = heapless::Vec::new();
        for (e, b) in self.effects.iter().zip(&eff_b) {
            effects
                .push(e.borrow(b))
                .map_err(|_| anyhow::anyhow!("too many effects"))?;
        }
        let model = Model {
            effects,
            variant: self.variant,
            problem: self.problem.clone(),
            obs_mean: LeF32(&mean),
            obs_scale: LeF32(&scale),
            bounds,
            encoder,
            decoder,
            residual_threshold: self.residual_threshold,
        };
        let mut buf = vec![
            0u8;
            64 * 1024
                + problem_bytes(&self.problem)
                + 8 * mean.len()
                + eff_b.iter().map(Vec::len).sum::<usize>()
                + enc_b
                    .iter()
                    .chain(dec_b)
                    .map(|b| b.a.len() + b.b.len() + b.c.len() + b.d.len() + b.e.len() + 64)
                    .sum::<usize>()
        ];
        let n = model
            .encode(&mut buf)
            .map_err(|e| anyhow::anyhow!("encoding the model: {e}"))?;
        buf.truncate(n);
        Model::decode(&buf)
            .map_err(|e| anyhow::anyhow!("the encoded model does not validate: {e}"))?;
        Ok(buf)
    }

    /// Copies a decoded model into owned form.
    pub fn from_model(m: &Model<'_>) -> OwnedModel {
        OwnedModel {
            variant: m.variant,
            problem: owned_problem(&m.problem),
            mean: m.obs_mean.iter().collect(),
            scale: m.obs_scale.iter().collect(),
            bounds: m.bounds.iter().copied().collect(),
            encoder: m.encoder.iter().map(OwnedLayer::from_core).collect(),
            decoder: m.decoder.iter().map(OwnedLayer::from_core).collect(),
            residual_threshold: m.residual_threshold,
            effects: m.effects.iter().map(OwnedEffect::from_core).collect(),
        }
    }

    /// Builds the f32 model of a trained network (with the effects its physics declares).
    pub fn from_net(
        net: &Net,
        problem: Problem<'static>,
        effects: Vec<OwnedEffect>,
    ) -> Result<OwnedModel> {
        let layers = |m: &Mlp| -> Result<Vec<OwnedLayer>> {
            m.layers
                .iter()
                .map(|l| {
                    let w = l.w.as_tensor().to_vec2::<f32>()?;
                    let b = l.b.as_tensor().to_vec1::<f32>()?;
                    Ok(OwnedLayer {
                        rows: w.len(),
                        cols: w[0].len(),
                        act: l.act,
                        weights: OwnedWeights::F32 { w: w.concat(), b },
                    })
                })
                .collect()
        };
        Ok(OwnedModel {
            variant: net.variant,
            problem,
            mean: net.mean.iter().map(|v| *v as f32).collect(),
            scale: net.scale.iter().map(|v| *v as f32).collect(),
            bounds: net
                .bounds
                .iter()
                .map(|b| [b[0] as f32, b[1] as f32])
                .collect(),
            encoder: layers(&net.encoder)?,
            decoder: match &net.decoder {
                Some(d) => layers(d)?,
                None => vec![],
            },
            residual_threshold: 0.0,
            effects,
        })
    }
}

impl OwnedModel {
    /// The 99th percentile of the standardised residual RMS of the model's own inversions of
    /// `split` (physics in f64): inversions above it are flagged as unexplained.
    pub fn residual_threshold(&self, split: &crate::data::Split) -> Result<f32> {
        let bytes = self.encode()?;
        let m = Model::decode(&bytes)?;
        let mut ws = Workspace::default();
        let mut r = Vec::with_capacity(split.len());
        for (row, t) in split.x.iter().zip(split.days()) {
            let obs: Vec<f32> = row
                .iter()
                .enumerate()
                .map(|(c, v)| v * self.scale[c] + self.mean[c])
                .collect();
            r.push(invert_at::<f64>(&m, &obs, t, &mut ws)?.residual_rms_std);
        }
        if r.is_empty() {
            return Ok(0.0);
        }
        r.sort_by(f64::total_cmp);
        Ok(r[((r.len() - 1) as f64 * 0.99) as usize] as f32)
    }
}
