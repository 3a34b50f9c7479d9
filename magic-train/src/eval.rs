//! Evaluation through the same path the board runs: every day is inverted with magic-core's
//! `invert` (physics in f64) and compared in standardised units, the paper's metric.

use crate::data::gnss::Split;
use anyhow::{anyhow, Result};
use magic_core::{invert_at, Model, Variant, Workspace};
use serde::Serialize;

/// The paper's MSE and its parts on one split.
#[derive(Clone, Debug, Serialize)]
pub struct EvalResult {
    /// Split name.
    pub split: String,
    /// Days.
    pub n: usize,
    /// Mean over days and channels of the squared error (standardised units).
    pub mse: f64,
    /// The same per channel.
    pub mse_per_channel: Vec<f64>,
    /// MSE of F(E(x)) alone, without the correction (B and C).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physics_mse: Option<f64>,
}

/// Inverts every row of `split` (standardised) and measures the reconstruction error.
pub fn evaluate(model: &Model<'_>, split: &Split, name: &str) -> Result<EvalResult> {
    let n_obs = model.n_obs();
    let mut ws = Workspace::default();
    let mut per = vec![0f64; n_obs];
    let mut phys = 0f64;
    let mut obs = vec![0f32; n_obs];
    for (row, t) in split.x.iter().zip(split.days()) {
        for c in 0..n_obs {
            obs[c] = row[c] * model.obs_scale.get(c) + model.obs_mean.get(c);
        }
        let inv = invert_at::<f64>(model, &obs, t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        for c in 0..n_obs {
            let s = model.obs_scale.get(c) as f64;
            let m = model.obs_mean.get(c) as f64;
            let r = (inv.recon[c] - m) / s - row[c] as f64;
            per[c] += r * r;
            if model.variant != Variant::A {
                let p = (inv.physics[c] - m) / s - row[c] as f64;
                phys += p * p;
            }
        }
    }
    let n = split.len().max(1) as f64;
    for v in per.iter_mut() {
        *v /= n;
    }
    let mse = per.iter().sum::<f64>() / n_obs as f64;
    Ok(EvalResult {
        split: name.to_string(),
        n: split.len(),
        mse,
        mse_per_channel: per,
        physics_mse: (model.variant != Variant::A).then(|| phys / (n * n_obs as f64)),
    })
}
