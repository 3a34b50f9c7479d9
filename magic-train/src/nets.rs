//! The paper's networks in candle: dense layers with seeded initialisation, the encoder, the
//! correction C (eq. 5) and the plain autoencoder's decoder, and the four model variants.

use crate::data::Dataset;
use crate::physics::{Physics, PhysicsOp};
use candle_core::{DType, Device, Result, Tensor, Var, D};
use magic_core::nn::Activation;
use magic_core::Variant;
use rand::rngs::StdRng;
use rand::Rng;
use std::sync::Arc;

/// A dense layer `act(x Wᵀ + b)`.
pub struct Dense {
    /// Weights `(out, in)`.
    pub w: Var,
    /// Bias `(out)`.
    pub b: Var,
    /// Activation.
    pub act: Activation,
}

/// A stack of dense layers.
pub struct Mlp {
    /// Layers in order.
    pub layers: Vec<Dense>,
}

impl Mlp {
    /// Layers of the given widths, PyTorch's default initialisation (uniform ±1/√fan_in), hidden
    /// activation `hidden`, last activation `last`.
    pub fn new(
        sizes: &[usize],
        hidden: Activation,
        last: Activation,
        rng: &mut StdRng,
        dev: &Device,
    ) -> Result<Mlp> {
        let mut layers = Vec::new();
        for (i, win) in sizes.windows(2).enumerate() {
            let (n_in, n_out) = (win[0], win[1]);
            let bound = 1.0 / (n_in as f32).sqrt();
            let w: Vec<f32> = (0..n_in * n_out)
                .map(|_| rng.random_range(-bound..bound))
                .collect();
            let b: Vec<f32> = (0..n_out)
                .map(|_| rng.random_range(-bound..bound))
                .collect();
            let act = if i + 2 == sizes.len() { last } else { hidden };
            layers.push(Dense {
                w: Var::from_vec(w, (n_out, n_in), dev)?,
                b: Var::from_vec(b, n_out, dev)?,
                act,
            });
        }
        Ok(Mlp { layers })
    }

    /// Forward pass on `(batch, in)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        for l in &self.layers {
            h = h
                .matmul(&l.w.as_tensor().t()?)?
                .broadcast_add(l.b.as_tensor())?;
            h = match l.act {
                Activation::Linear => h,
                Activation::Relu => h.relu()?,
                Activation::Sigmoid => candle_nn::ops::sigmoid(&h)?,
            };
        }
        Ok(h)
    }

    /// Trainable variables.
    pub fn vars(&self) -> Vec<Var> {
        self.layers
            .iter()
            .flat_map(|l| [l.w.clone(), l.b.clone()])
            .collect()
    }

    /// A copy of the current weights.
    pub fn snapshot(&self) -> Result<Vec<(Tensor, Tensor)>> {
        self.layers
            .iter()
            .map(|l| Ok((l.w.as_tensor().copy()?, l.b.as_tensor().copy()?)))
            .collect()
    }

    /// Restores weights from [`Mlp::snapshot`].
    pub fn restore(&self, snap: &[(Tensor, Tensor)]) -> Result<()> {
        for (l, (w, b)) in self.layers.iter().zip(snap) {
            l.w.set(w)?;
            l.b.set(b)?;
        }
        Ok(())
    }
}

/// Outputs of one forward pass (all in standardised units).
pub struct Outputs {
    /// Final reconstruction.
    pub recon: Tensor,
    /// F(Z) standardised (B, C).
    pub physics: Option<Tensor>,
}

/// A copy of a [`Net`]'s weights: the encoder's layers, and the decoder's if any.
pub type Snapshot = (Vec<(Tensor, Tensor)>, Option<Vec<(Tensor, Tensor)>>);

/// A trainable model: encoder, optional physics, optional correction / decoder.
pub struct Net {
    /// Paper variant.
    pub variant: Variant,
    /// Encoder E.
    pub encoder: Mlp,
    /// Correction C (variant C) or decoder (variant A).
    pub decoder: Option<Mlp>,
    /// Forward model F (B, C).
    pub physics: Option<Arc<dyn Physics>>,
    /// Variable bounds.
    pub bounds: Vec<[f64; 2]>,
    /// Observation mean and scale (physical units) for standardising F's output.
    pub mean: Vec<f64>,
    /// See `mean`.
    pub scale: Vec<f64>,
    lo: Tensor,
    span: Tensor,
    mean_t: Tensor,
    scale_t: Tensor,
}

/// Hidden widths of the paper's encoder for `n_obs` inputs and `n_out` variables: 36-64-32-16-4
/// for the GNSS network.
pub fn encoder_sizes(n_obs: usize, n_out: usize) -> Vec<usize> {
    vec![n_obs, 64, 32, 16, n_out]
}

impl Net {
    /// Builds a model of `variant` for `data`'s channels and standardisation. `physics` and
    /// `bounds` are required for B and C; `latent` is A's code size.
    pub fn new(
        variant: Variant,
        data: &Dataset,
        physics: Option<Arc<dyn Physics>>,
        bounds: Vec<[f64; 2]>,
        latent: usize,
        rng: &mut StdRng,
    ) -> Result<Net> {
        let dev = Device::Cpu;
        let (n_obs, mean, scale) = (data.n_obs(), data.mean.clone(), data.scale.clone());
        let (encoder, decoder) = match variant {
            Variant::A => {
                let enc = Mlp::new(
                    &encoder_sizes(n_obs, latent),
                    Activation::Relu,
                    Activation::Linear,
                    rng,
                    &dev,
                )?;
                let mut dec_sizes = encoder_sizes(n_obs, latent);
                dec_sizes.reverse();
                let dec = Mlp::new(&dec_sizes, Activation::Relu, Activation::Linear, rng, &dev)?;
                (enc, Some(dec))
            }
            Variant::B | Variant::C => {
                let n_par = bounds.len();
                let enc = Mlp::new(
                    &encoder_sizes(n_obs, n_par),
                    Activation::Relu,
                    Activation::Sigmoid,
                    rng,
                    &dev,
                )?;
                let dec = if variant == Variant::C {
                    Some(Mlp::new(
                        &[n_obs, 4 * n_obs, n_obs],
                        Activation::Relu,
                        Activation::Linear,
                        rng,
                        &dev,
                    )?)
                } else {
                    None
                };
                (enc, dec)
            }
        };
        let lo: Vec<f32> = bounds.iter().map(|b| b[0] as f32).collect();
        let span: Vec<f32> = bounds.iter().map(|b| (b[1] - b[0]) as f32).collect();
        let nb = bounds.len();
        Ok(Net {
            variant,
            encoder,
            decoder,
            physics,
            lo: Tensor::from_vec(lo, (1, nb), &dev)?,
            span: Tensor::from_vec(span, (1, nb), &dev)?,
            mean_t: Tensor::from_vec(mean.iter().map(|v| *v as f32).collect(), (1, n_obs), &dev)?,
            scale_t: Tensor::from_vec(scale.iter().map(|v| *v as f32).collect(), (1, n_obs), &dev)?,
            bounds,
            mean,
            scale,
        })
    }

    /// Physical variables from the encoder's sigmoid outputs.
    pub fn variables(&self, x: &Tensor) -> Result<Tensor> {
        let u = self.encoder.forward(x)?;
        u.broadcast_mul(&self.span)?.broadcast_add(&self.lo)
    }

    /// Forward pass on standardised observations `(batch, n_obs)` made on days `days` `(batch, 1)`
    /// (day numbers; NaN where unknown).
    pub fn forward(&self, x: &Tensor, days: &Tensor) -> Result<Outputs> {
        match self.variant {
            Variant::A => {
                let z = self.encoder.forward(x)?;
                let recon = self
                    .decoder
                    .as_ref()
                    .expect("variant A has a decoder")
                    .forward(&z)?;
                Ok(Outputs {
                    recon,
                    physics: None,
                })
            }
            Variant::B | Variant::C => {
                let z = self.variables(x)?;
                let phys = self
                    .physics
                    .as_ref()
                    .expect("variants B and C have physics");
                let zt = Tensor::cat(&[&z, &days.to_dtype(z.dtype())?], 1)?;
                let mm = zt.apply_op1(PhysicsOp(phys.clone()))?;
                let fz = mm
                    .broadcast_sub(&self.mean_t)?
                    .broadcast_div(&self.scale_t)?;
                let recon = match &self.decoder {
                    // C corrects F without its dated terms and adds them after (as the core
                    // does, `magic_core::invert::model_correction`).
                    Some(c) => match self.dated(phys.as_ref(), days)? {
                        Some(d) => {
                            let d = d.to_dtype(fz.dtype())?;
                            (c.forward(&(&fz - &d)?)? + d)?
                        }
                        None => c.forward(&fz)?,
                    },
                    None => fz.clone(),
                };
                Ok(Outputs {
                    recon,
                    physics: Some(fz),
                })
            }
        }
    }

    /// F's dated terms on each of `days` `(batch, 1)`, standardised (divided by the scale, no
    /// mean): `(batch, n_obs)`, or `None` where they are zero on every day.
    fn dated(&self, phys: &dyn Physics, days: &Tensor) -> Result<Option<Tensor>> {
        if !phys.has_dated() {
            return Ok(None);
        }
        let days = days.flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
        let n = self.scale.len();
        let mut d = vec![0f32; days.len() * n];
        let mut row = vec![0f64; n];
        for (t, out) in days.iter().zip(d.chunks_exact_mut(n.max(1))) {
            phys.dated(*t, &mut row)
                .map_err(|e| candle_core::Error::Msg(format!("dated terms of F: {e}")))?;
            for ((o, v), s) in out.iter_mut().zip(&row).zip(&self.scale) {
                *o = (v / s) as f32;
            }
        }
        if d.iter().all(|v| *v == 0.0) {
            return Ok(None);
        }
        Tensor::from_vec(d, (days.len(), n), &Device::Cpu).map(Some)
    }

    /// All trainable variables.
    pub fn vars(&self) -> Vec<Var> {
        let mut v = self.encoder.vars();
        if let Some(d) = &self.decoder {
            v.extend(d.vars());
        }
        v
    }

    /// Snapshot of all weights.
    pub fn snapshot(&self) -> Result<Snapshot> {
        Ok((
            self.encoder.snapshot()?,
            self.decoder.as_ref().map(|d| d.snapshot()).transpose()?,
        ))
    }

    /// Restores a snapshot.
    pub fn restore(&self, s: &Snapshot) -> Result<()> {
        self.encoder.restore(&s.0)?;
        if let (Some(d), Some(ds)) = (&self.decoder, &s.1) {
            d.restore(ds)?;
        }
        Ok(())
    }
}

/// Mean squared error over all elements.
pub fn mse(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    a.sub(b)?.sqr()?.mean_all()
}

/// The smoothness term of eq. 19: Σ over sequences and consecutive days of ‖x_F(t+1) − x_F(t)‖²,
/// for `f` laid out as `n_seq` sequences of `t` consecutive rows.
pub fn smoothness(f: &Tensor, n_seq: usize, t: usize) -> Result<Tensor> {
    let n = f.dim(D::Minus1)?;
    let s = f.reshape((n_seq, t, n))?;
    let d = s.narrow(1, 1, t - 1)?.sub(&s.narrow(1, 0, t - 1)?)?;
    d.sqr()?.sum_all()
}

/// A `(rows, 1)` f32 tensor of day numbers.
pub fn days_tensor(days: &[f64]) -> Result<Tensor> {
    Tensor::from_vec(
        days.iter().map(|d| *d as f32).collect::<Vec<f32>>(),
        (days.len(), 1),
        &Device::Cpu,
    )
}

/// A `(rows, n)` f32 tensor from rows.
pub fn to_tensor(rows: &[&[f32]], n: usize) -> Result<Tensor> {
    let flat: Vec<f32> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    Tensor::from_vec(flat, (rows.len(), n), &Device::Cpu)?.to_dtype(DType::F32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::synth;
    use crate::model::{OwnedEffect, OwnedModel};
    use crate::MogiPhysics;
    use rand::SeedableRng;

    #[test]
    fn the_trainers_correction_is_the_cores_beside_dated_terms() {
        // A random variant-C model whose F holds a drift and a step: the trainer's reconstruction
        // (C on F without them, then them added) and the exported model's, through magic-core.
        let s = synth::generate(synth::Scenario::Clean, 4);
        let (d, network) = (&s.problem.data, &s.problem.network);
        let rows = d.test.rows(0, 64);
        let days = rows.days();
        let effects = vec![
            OwnedEffect::Drift {
                t0_day: 14_000.0,
                rate: (0..36).map(|c| (c % 7) as f32 - 3.0).collect(),
            },
            OwnedEffect::Step {
                station: 2,
                // Mid-way through the rows: half of them before it, half after.
                epoch_day: days[32] as f32,
                offset_mm: [4.0, -3.0, 9.0],
            },
        ];
        let phys: Arc<dyn Physics> =
            Arc::new(MogiPhysics::new(network.stations.clone(), effects.clone()));
        let mut rng = StdRng::seed_from_u64(4);
        let bounds = magic_core::mogi::PAPER_BOUNDS.to_vec();
        let net = Net::new(Variant::C, d, Some(phys), bounds, 4, &mut rng).unwrap();
        let model = OwnedModel::from_net(&net, network.spec().unwrap(), effects).unwrap();
        let bytes = model.encode().unwrap();
        let core = magic_core::Model::decode(&bytes).unwrap();

        let x: Vec<f32> = rows.x.iter().flatten().copied().collect();
        let xt = Tensor::from_vec(x, (rows.len(), 36), &Device::Cpu).unwrap();
        let dt = Tensor::from_vec(days.clone(), (rows.len(), 1), &Device::Cpu).unwrap();
        let recon = net
            .forward(&xt, &dt)
            .unwrap()
            .recon
            .to_vec2::<f32>()
            .unwrap();
        let mut ws = magic_core::Workspace::default();
        let (mut worst, mut worst_input) = (0f64, 0f64);
        let (mut input, mut y, mut dated) = ([0f32; 36], [0f32; 36], [0f64; 36]);
        for ((row, t), r) in rows.x.iter().zip(&days).zip(&recon) {
            let obs: Vec<f32> = (0..36)
                .map(|c| row[c] * core.obs_scale.get(c) + core.obs_mean.get(c))
                .collect();
            let inv = magic_core::invert_at::<f64>(&core, &obs, *t, &mut ws).unwrap();
            // C run on `correction_input_of` (as the int8 calibration and the standard
            // deviations do), its dated terms added back: the inversion's reconstruction.
            let physics = inv.physics;
            magic_core::invert::correction_input_of(&core, &physics[..36], *t, &mut input).unwrap();
            magic_core::invert::model_decoder(&core, &input, &mut y, &mut ws).unwrap();
            magic_core::invert::dated_part(&core, *t, &mut dated).unwrap();
            for c in 0..36 {
                let (m, sc) = (core.obs_mean.get(c) as f64, core.obs_scale.get(c) as f64);
                worst = worst.max(((inv.recon[c] - m) / sc - r[c] as f64).abs());
                let again = y[c] as f64 * sc + m + dated[c];
                worst_input = worst_input.max((again - inv.recon[c]).abs() / sc);
            }
        }
        // f32 networks on both sides (candle's kernels and the core's): rounding only.
        assert!(worst < 1e-4, "trainer and core differ by {worst}");
        assert!(
            worst_input < 1e-5,
            "C on correction_input_of differs by {worst_input}"
        );
    }
}
