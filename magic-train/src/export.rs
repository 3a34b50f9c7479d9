//! Model files from the host side: owned layers built from a trained [`Net`], int8 quantisation
//! with calibration, and encoding through magic-core's [`Model`].

use crate::nets::{Mlp, Net};
use anyhow::{bail, Context, Result};
use magic_core::effects::Effect;
use magic_core::model_file::{Model, Problem, Variant};
use magic_core::nn::{Activation, Layer, Weights};
use magic_core::quant::{quantize_multiplier, LeF32, LeI32};

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

/// A declared effect owned by the host (see `magic_core::effects::Effect`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "family", rename_all = "snake_case")]
pub enum OwnedEffect {
    /// Daily network translation (3 latent variables).
    CommonMode,
    /// Vertical term linear in elevation (1 latent variable).
    Elevation {
        /// Reference elevation (km).
        z_ref_km: f32,
    },
    /// Second Mogi source at a fixed position (1 latent variable: its ΔV).
    SecondSource {
        /// East (km).
        x_km: f32,
        /// North (km).
        y_km: f32,
        /// Depth (km).
        depth_km: f32,
    },
    /// Per-channel annual + semiannual coefficients (4 per channel).
    Seasonal {
        /// Coefficients (mm).
        coef: Vec<f32>,
    },
    /// A step at one station.
    Step {
        /// Station index.
        station: u16,
        /// First day with the offset.
        epoch_day: f32,
        /// Offset (mm, E N U).
        offset_mm: [f32; 3],
    },
    /// Per-channel drift.
    Drift {
        /// Reference day.
        t0_day: f32,
        /// Rates (mm/yr).
        rate: Vec<f32>,
    },
    /// RTM: each spectrum's true sun from its date (see `magic_core::effects`).
    Illumination {
        /// Site latitude (degrees north).
        lat_deg: f32,
        /// Site longitude (degrees east).
        lon_deg: f32,
        /// Acquisition time (hours UTC).
        utc_hours: f32,
        /// Sensor view azimuth (degrees).
        view_azimuth_deg: f32,
    },
    /// RTM: a constant reflectance per observed band.
    BandOffset {
        /// Offsets (reflectance), one per observed band.
        offset: Vec<f32>,
    },
}

impl OwnedEffect {
    /// Little-endian bytes of the effect's arrays (empty for effects without arrays).
    pub fn bytes(&self) -> Vec<u8> {
        match self {
            OwnedEffect::Seasonal { coef } => f32_bytes(coef),
            OwnedEffect::Drift { rate, .. } => f32_bytes(rate),
            OwnedEffect::BandOffset { offset } => f32_bytes(offset),
            _ => vec![],
        }
    }

    /// The core's view, borrowing `bytes` (from [`OwnedEffect::bytes`]).
    pub fn borrow<'a>(&self, bytes: &'a [u8]) -> Effect<'a> {
        match *self {
            OwnedEffect::CommonMode => Effect::CommonMode,
            OwnedEffect::Elevation { z_ref_km } => Effect::Elevation { z_ref_km },
            OwnedEffect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            },
            OwnedEffect::Seasonal { .. } => Effect::Seasonal { coef: LeF32(bytes) },
            OwnedEffect::Step {
                station,
                epoch_day,
                offset_mm,
            } => Effect::Step {
                station,
                epoch_day,
                offset_mm,
            },
            OwnedEffect::Drift { t0_day, .. } => Effect::Drift {
                t0_day,
                rate: LeF32(bytes),
            },
            OwnedEffect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            } => Effect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            },
            OwnedEffect::BandOffset { .. } => Effect::BandOffset {
                offset: LeF32(bytes),
            },
        }
    }

    /// Copies a core effect.
    pub fn from_core(e: &Effect<'_>) -> OwnedEffect {
        match *e {
            Effect::CommonMode => OwnedEffect::CommonMode,
            Effect::Elevation { z_ref_km } => OwnedEffect::Elevation { z_ref_km },
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => OwnedEffect::SecondSource {
                x_km,
                y_km,
                depth_km,
            },
            Effect::Seasonal { coef } => OwnedEffect::Seasonal {
                coef: coef.iter().collect(),
            },
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } => OwnedEffect::Step {
                station,
                epoch_day,
                offset_mm,
            },
            Effect::Drift { t0_day, rate } => OwnedEffect::Drift {
                t0_day,
                rate: rate.iter().collect(),
            },
            Effect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            } => OwnedEffect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            },
            Effect::BandOffset { offset } => OwnedEffect::BandOffset {
                offset: offset.iter().collect(),
            },
        }
    }

    /// Number of latent variables.
    pub fn n_latent(&self) -> usize {
        self.borrow(&[]).n_latent()
    }

    /// Family name.
    pub fn family(&self) -> &'static str {
        self.borrow(&[]).family()
    }
}

/// A model owned by the host, convertible to and from model-file bytes.
#[derive(Clone, Debug)]
pub struct OwnedModel {
    /// Paper variant.
    pub variant: Variant,
    /// Problem description (RTM table bytes interned: see `data::rtm_tables::intern`).
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

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}
fn i32_bytes(v: &[i32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

struct LayerBytes {
    /// An int8 layer's bytes.
    int8: bool,
    /// Alignment padding before the int8 weights (see `OwnedModel::encode`).
    pad: usize,
    a: Vec<u8>,
    b: Vec<u8>,
    c: Vec<u8>,
    d: Vec<u8>,
    e: Vec<u8>,
}

fn layer_bytes(l: &OwnedLayer) -> LayerBytes {
    match &l.weights {
        OwnedWeights::F32 { w, b } => LayerBytes {
            int8: false,
            pad: 0,
            a: f32_bytes(w),
            b: f32_bytes(b),
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
            b: i32_bytes(bias),
            c: f32_bytes(w_scale),
            d: i32_bytes(mult),
            e: shift.iter().map(|x| *x as u8).collect(),
        },
    }
}

fn borrow_layer<'a>(l: &OwnedLayer, b: &'a LayerBytes) -> Layer<'a> {
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
        let mean = f32_bytes(&self.mean);
        let scale = f32_bytes(&self.scale);
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
                + crate::data::rtm_tables::problem_bytes(&self.problem)
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
        let own = |l: &Layer<'_>| {
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
        };
        OwnedModel {
            variant: m.variant,
            problem: crate::data::rtm_tables::owned_problem(&m.problem),
            mean: m.obs_mean.iter().collect(),
            scale: m.obs_scale.iter().collect(),
            bounds: m.bounds.iter().copied().collect(),
            encoder: m.encoder.iter().map(own).collect(),
            decoder: m.decoder.iter().map(own).collect(),
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
        // Encoder inputs per layer.
        let enc_max = max_abs_inputs(&self.encoder, calib)?;
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
                _ => (0..inv.n_obs)
                    .map(|c| ((inv.physics[c] - self.mean[c] as f64) / self.scale[c] as f64) as f32)
                    .collect(),
            });
        }
        Ok(out)
    }
}

fn f32_forward(l: &OwnedLayer, x: &[f32]) -> Vec<f32> {
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
