//! `magic missing`: how the inversion degrades when stations are down.
//!
//! For every day of a split, the complete-data inversion is the reference; then stations are
//! removed (their three channels set to NaN) — 1, 2 or 4 chosen at random per day, or the two
//! stations nearest the source — and the day is inverted again with the same model file. Reported:
//! the MSE on the observed channels (standardised units) and the deviation of each source
//! parameter from the complete-data inversion (mean absolute and 95th percentile).

use super::GnssProblem;
use crate::data::SplitName;
use anyhow::{anyhow, Result};
use magic_core::{invert_at, Model, Workspace};
use rand::rngs::StdRng;
use rand::seq::index::sample;
use rand::SeedableRng;
use serde::Serialize;

/// One removal pattern's figures.
#[derive(Clone, Debug, Serialize)]
pub struct MissingRow {
    /// Pattern name.
    pub pattern: String,
    /// Days inverted.
    pub n: usize,
    /// MSE over the observed channels (standardised units).
    pub mse_observed: f64,
    /// Mean absolute deviation of each parameter from the complete-data inversion.
    pub mean_abs_dev: Vec<f64>,
    /// 95th percentile of the absolute deviation.
    pub p95_abs_dev: Vec<f64>,
}

/// A removal pattern.
#[derive(Clone, Debug)]
pub enum Pattern {
    /// No station removed.
    Complete,
    /// `k` stations chosen at random for every day.
    Random(usize),
    /// Fixed stations (indices).
    Fixed(Vec<usize>, String),
}

impl Pattern {
    fn name(&self) -> String {
        match self {
            Pattern::Complete => "complete".into(),
            Pattern::Random(k) => format!(
                "{k} random station{} removed",
                if *k == 1 { "" } else { "s" }
            ),
            Pattern::Fixed(_, n) => n.clone(),
        }
    }
}

/// The two stations nearest a point.
pub fn nearest_two(p: &GnssProblem, x: f64, y: f64) -> (Vec<usize>, String) {
    let mut d: Vec<(f64, usize)> = p
        .network
        .stations
        .iter()
        .enumerate()
        .map(|(i, s)| ((s.x_km - x).hypot(s.y_km - y), i))
        .collect();
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    let idx = vec![d[0].1, d[1].1];
    let name = format!(
        "nearest two removed ({}, {})",
        p.network.names[idx[0]], p.network.names[idx[1]]
    );
    (idx, name)
}

/// Runs the patterns on a split. Returns the rows and the complete-data result lines' params.
pub fn evaluate_missing(
    model: &Model<'_>,
    p: &GnssProblem,
    split: SplitName,
    seed: u64,
) -> Result<Vec<MissingRow>> {
    let s = p.data.split(split);
    let days = s.days();
    let n_obs = model.n_obs();
    let ns = n_obs / 3;
    let mut ws = Workspace::default();
    let mm = |row: &[f32]| -> Vec<f32> {
        row.iter()
            .enumerate()
            .map(|(c, v)| p.data.to_physical(c, *v as f64) as f32)
            .collect()
    };
    // Complete-data reference.
    let mut reference = Vec::with_capacity(s.len());
    for (row, t) in s.x.iter().zip(&days) {
        let inv = invert_at::<f64>(model, &mm(row), *t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        reference.push(inv.params[..4].to_vec());
    }
    let med = |j: usize| {
        let mut v: Vec<f64> = reference.iter().map(|p| p[j]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (near, near_name) = nearest_two(p, med(0), med(1));
    let patterns = [
        Pattern::Complete,
        Pattern::Random(1),
        Pattern::Random(2),
        Pattern::Random(4),
        Pattern::Fixed(near, near_name),
    ];
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = Vec::new();
    for pat in patterns {
        let (mut se, mut cnt) = (0f64, 0usize);
        let mut dev: Vec<Vec<f64>> = vec![Vec::new(); 4];
        for (i, (row, t)) in s.x.iter().zip(&days).enumerate() {
            let removed: Vec<usize> = match &pat {
                Pattern::Complete => vec![],
                Pattern::Random(k) => sample(&mut rng, ns, *k).into_vec(),
                Pattern::Fixed(v, _) => v.clone(),
            };
            let mut obs = mm(row);
            for &st in &removed {
                for k in 0..3 {
                    obs[k * ns + st] = f32::NAN;
                }
            }
            let inv = invert_at::<f64>(model, &obs, *t, &mut ws).map_err(|e| anyhow!("{e}"))?;
            for c in 0..n_obs {
                if obs[c].is_nan() {
                    continue;
                }
                let r = (inv.recon[c] - model.obs_mean.get(c) as f64)
                    / model.obs_scale.get(c) as f64
                    - row[c] as f64;
                se += r * r;
                cnt += 1;
            }
            for j in 0..4 {
                dev[j].push((inv.params[j] - reference[i][j]).abs());
            }
        }
        let mean_abs_dev = dev
            .iter()
            .map(|d| d.iter().sum::<f64>() / d.len().max(1) as f64)
            .collect();
        let p95_abs_dev = dev
            .iter_mut()
            .map(|d| {
                d.sort_by(f64::total_cmp);
                d.get(((d.len().max(1) - 1) as f64 * 0.95) as usize)
                    .copied()
                    .unwrap_or(0.0)
            })
            .collect();
        out.push(MissingRow {
            pattern: pat.name(),
            n: s.len(),
            mse_observed: se / cnt.max(1) as f64,
            mean_abs_dev,
            p95_abs_dev,
        });
    }
    Ok(out)
}

/// Prints the rows as a Markdown table.
pub fn print_table(rows: &[MissingRow]) {
    println!("| stations | MSE (observed channels) | mean abs deviation x, y, depth (km), ΔV (10⁶ m³) | 95th percentile |");
    println!("|---|---|---|---|");
    for r in rows {
        let f = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        println!(
            "| {} | {:.4} | {} | {} |",
            r.pattern,
            r.mse_observed,
            f(&r.mean_abs_dev),
            f(&r.p95_abs_dev)
        );
    }
}
