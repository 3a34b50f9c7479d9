//! Evaluation through the same path the board runs: every row is inverted with magic-core's
//! `invert_at` (physics in f64, in parallel over chunks of rows) and compared in standardised
//! units, the paper's metric.

use crate::data::{Dataset, Split, SplitName};
use anyhow::{anyhow, Result};
use magic_core::{invert_at, Model, Variant, Workspace};
use rayon::prelude::*;
use serde::Serialize;

/// The paper's MSE and its parts on one split.
#[derive(Clone, Debug, Serialize)]
pub struct EvalResult {
    /// Split name.
    pub split: String,
    /// Rows.
    pub n: usize,
    /// Mean over rows and channels of the squared error (standardised units; over the observed
    /// cells where channels are missing).
    pub mse: f64,
    /// The same per channel (over the rows where the channel is observed).
    pub mse_per_channel: Vec<f64>,
    /// MSE of F(E(x)) alone, without the correction (B and C).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physics_mse: Option<f64>,
    /// Mean squared size of the correction, C(F(E(x))) − F(E(x)) (C only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correction_ms: Option<f64>,
}

/// Sums over a chunk of rows: squared error per channel, physics-only and correction squares.
struct Sums {
    n: usize,
    per: Vec<f64>,
    /// Rows on which each channel is observed.
    count: Vec<usize>,
    phys: f64,
    corr: f64,
}

/// Rows per parallel chunk.
const CHUNK: usize = 512;

fn sums(model: &Model<'_>, x: &[Vec<f32>], days: &[f64]) -> Result<Sums> {
    let n_obs = model.n_obs();
    let mut ws = Workspace::default();
    let mut s = Sums {
        n: x.len(),
        per: vec![0.0; n_obs],
        count: vec![0; n_obs],
        phys: 0.0,
        corr: 0.0,
    };
    let mut obs = vec![0f32; n_obs];
    for (row, &t) in x.iter().zip(days) {
        for c in 0..n_obs {
            obs[c] = row[c] * model.obs_scale.get(c) + model.obs_mean.get(c);
        }
        let inv = invert_at::<f64>(model, &obs, t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        for c in 0..n_obs {
            let sc = model.obs_scale.get(c) as f64;
            let m = model.obs_mean.get(c) as f64;
            if model.variant == Variant::C {
                s.corr += ((inv.recon[c] - inv.physics[c]) / sc).powi(2);
            }
            if row[c].is_nan() {
                continue;
            }
            s.count[c] += 1;
            let r = (inv.recon[c] - m) / sc - row[c] as f64;
            s.per[c] += r * r;
            if model.variant != Variant::A {
                let p = (inv.physics[c] - m) / sc - row[c] as f64;
                s.phys += p * p;
            }
        }
    }
    Ok(s)
}

/// Inverts every row of `split` (standardised) and measures the reconstruction error.
pub fn evaluate(model: &Model<'_>, split: &Split, name: &str) -> Result<EvalResult> {
    if split.x.iter().any(|r| r.len() != model.n_obs()) {
        return Err(anyhow!(
            "{name}: rows must hold the model's {} channels",
            model.n_obs()
        ));
    }
    let days = split.days();
    let parts: Vec<Sums> = split
        .x
        .par_chunks(CHUNK)
        .zip(days.par_chunks(CHUNK))
        .map(|(x, d)| sums(model, x, d))
        .collect::<Result<_>>()?;
    let n: usize = parts.iter().map(|p| p.n).sum();
    let nf = n.max(1) as f64;
    let n_obs = model.n_obs();
    let mut per = vec![0.0; n_obs];
    let mut count = vec![0usize; n_obs];
    let (mut phys, mut corr) = (0.0, 0.0);
    for p in &parts {
        for (a, b) in per.iter_mut().zip(&p.per) {
            *a += b;
        }
        for (a, b) in count.iter_mut().zip(&p.count) {
            *a += b;
        }
        phys += p.phys;
        corr += p.corr;
    }
    let observed: usize = count.iter().sum();
    // Each channel's MSE weighted by its share of the observed cells: the mean over observed
    // cells, and exactly the plain mean over channels when nothing is missing.
    let mean_count = observed.max(1) as f64 / n_obs.max(1) as f64;
    let mut mse = 0.0;
    for (v, &k) in per.iter_mut().zip(&count) {
        *v /= k.max(1) as f64;
        mse += *v * (k as f64 / mean_count);
    }
    Ok(EvalResult {
        split: name.to_string(),
        n,
        mse: mse / n_obs as f64,
        mse_per_channel: per,
        physics_mse: (model.variant != Variant::A).then_some(phys / observed.max(1) as f64),
        correction_ms: (model.variant == Variant::C).then_some(corr / (nf * n_obs as f64)),
    })
}

/// [`evaluate`] on the three splits, in the order of [`SplitName::ALL`].
pub fn evaluate_splits(model: &Model<'_>, data: &Dataset) -> Result<[EvalResult; 3]> {
    let [a, b, c] = SplitName::ALL;
    Ok([
        evaluate(model, data.split(a), a.as_str())?,
        evaluate(model, data.split(b), b.as_str())?,
        evaluate(model, data.split(c), c.as_str())?,
    ])
}

/// The test MSE of each split's evaluation: `[train, valid, test]`.
pub fn mse3(r: &[EvalResult; 3]) -> [f64; 3] {
    [r[0].mse, r[1].mse, r[2].mse]
}
