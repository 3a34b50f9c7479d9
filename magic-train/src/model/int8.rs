//! int8 export: every layer but the encoder head quantised (symmetric per-row weights, activation
//! scales calibrated on data), with the requantisation constants the core's kernel needs.

use super::layer::{f32_forward, OwnedLayer, OwnedWeights};
use super::OwnedModel;
use anyhow::{bail, Context, Result};
use magic_core::model_file::{Model, Variant};
use magic_core::quant::quantize_multiplier;

impl OwnedModel {
    /// Quantises to int8 every layer except the encoder head (which stays f32: an int8 sigmoid
    /// resolves only 1/256 of a variable's range). Activation scales are calibrated on `calib`
    /// (standardised observations): the largest absolute input each layer sees, over 127.
    pub fn quantize_int8(&self, calib: &[Vec<f32>]) -> Result<OwnedModel> {
        self.quantize_int8_at(calib, &[])
    }

    /// [`OwnedModel::quantize_int8`] with the calibration rows' day numbers (needed when the model
    /// declares time-dependent effects).
    pub fn quantize_int8_at(&self, calib: &[Vec<f32>], days: &[f64]) -> Result<OwnedModel> {
        if calib.is_empty() {
            bail!("int8 export needs calibration data");
        }
        let mut out = self.clone();
        // Encoder inputs per layer: a missing channel (NaN) enters as 0, the training mean, as
        // on the first pass of an inversion.
        let filled: Vec<Vec<f32>> = calib
            .iter()
            .map(|r| {
                r.iter()
                    .map(|v| if v.is_nan() { 0.0 } else { *v })
                    .collect()
            })
            .collect();
        let enc_max = max_abs_inputs(&self.encoder, &filled)?;
        let keep_f32_last = matches!(self.variant, Variant::B | Variant::C);
        let n_enc = self.encoder.len();
        out.encoder = quantize_chain(
            &self.encoder,
            &enc_max,
            if keep_f32_last { n_enc - 1 } else { n_enc },
        )?;
        if !self.decoder.is_empty() {
            // Decoder inputs: what the f32 model feeds it.
            let dec_in = self.decoder_inputs(calib, days)?;
            let dec_max = max_abs_inputs(&self.decoder, &dec_in)?;
            out.decoder = quantize_chain(&self.decoder, &dec_max, self.decoder.len())?;
        }
        Ok(out)
    }

    /// The decoder's inputs on `x` (standardised observations, on days `days`), computed with the
    /// f32 model.
    fn decoder_inputs(&self, x: &[Vec<f32>], days: &[f64]) -> Result<Vec<Vec<f32>>> {
        let bytes = self.encode()?;
        let model = Model::decode(&bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut ws = magic_core::Workspace::default();
        let mut out = Vec::with_capacity(x.len());
        for (i, row) in x.iter().enumerate() {
            let obs: Vec<f32> = row
                .iter()
                .enumerate()
                .map(|(c, v)| v * self.scale[c] + self.mean[c])
                .collect();
            let t = days.get(i).copied().unwrap_or(f64::NAN);
            let inv = magic_core::invert_at::<f64>(&model, &obs, t, &mut ws)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            out.push(match self.variant {
                Variant::A => inv.params[..inv.n_params]
                    .iter()
                    .map(|v| *v as f32)
                    .collect(),
                // C's input: F without its dated terms, as `invert::model_correction` feeds it.
                _ => {
                    let mut input = vec![0f32; inv.n_obs];
                    magic_core::invert::correction_input_of(
                        &model,
                        &inv.physics[..inv.n_obs],
                        t,
                        &mut input,
                    )
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
                    input
                }
            });
        }
        Ok(out)
    }
}

/// Largest absolute input value of each layer over the data.
fn max_abs_inputs(layers: &[OwnedLayer], data: &[Vec<f32>]) -> Result<Vec<f32>> {
    let mut m = vec![0f32; layers.len()];
    for row in data {
        let mut h = row.clone();
        for (i, l) in layers.iter().enumerate() {
            m[i] = h.iter().fold(m[i], |a, v| a.max(v.abs()));
            h = f32_forward(l, &h);
        }
    }
    Ok(m.into_iter()
        .map(|v| if v > 0.0 { v } else { 1.0 })
        .collect())
}

fn quantize_chain(layers: &[OwnedLayer], max_in: &[f32], n_int8: usize) -> Result<Vec<OwnedLayer>> {
    let mut out = Vec::new();
    for (i, l) in layers.iter().enumerate() {
        if i >= n_int8 {
            out.push(l.clone());
            continue;
        }
        let OwnedWeights::F32 { w, b } = &l.weights else {
            bail!("layer {i} is already quantised")
        };
        let in_scale = max_in[i] / 127.0;
        let out_scale = if i + 1 < n_int8 {
            max_in[i + 1] / 127.0
        } else {
            0.0
        };
        let mut qw = Vec::with_capacity(w.len());
        let (mut bias, mut w_scale, mut mult, mut shift) = (vec![], vec![], vec![], vec![]);
        for r in 0..l.rows {
            let row = &w[r * l.cols..(r + 1) * l.cols];
            let mx = row.iter().fold(0f32, |a, v| a.max(v.abs()));
            let s = if mx > 0.0 { mx / 127.0 } else { 1e-8 };
            qw.extend(
                row.iter()
                    .map(|v| (v / s).round().clamp(-127.0, 127.0) as i8),
            );
            let acc_scale = s as f64 * in_scale as f64;
            bias.push(
                (b[r] as f64 / acc_scale)
                    .round()
                    .clamp(i32::MIN as f64, i32::MAX as f64) as i32,
            );
            w_scale.push(s);
            let (m, sh) = if out_scale > 0.0 {
                quantize_multiplier(acc_scale / out_scale as f64)
                    .context("requantisation multiplier out of range")?
            } else {
                (1 << 30, 0)
            };
            mult.push(m);
            shift.push(sh);
        }
        out.push(OwnedLayer {
            rows: l.rows,
            cols: l.cols,
            act: l.act,
            weights: OwnedWeights::Int8 {
                w: qw,
                bias,
                w_scale,
                mult,
                shift,
                in_scale,
                out_scale,
            },
        });
    }
    Ok(out)
}
