//! The residuals of a GNSS model, as its effect families see them.
//!
//! Every day of the data is inverted with the core's `invert_at` (the model as it will be used):
//! the encoder's variables give the main source's typical position (the median over the days of
//! largest volume change) and the physics-only error F(E(x)) is reported. The families are then
//! fitted to what F, linearised around that typical state, cannot produce whatever its variables:
//! each day's observation less F's time-dependent declared effects, in the data's standardised
//! units (the paper's metric), projected off the span of F's Jacobian (the main source's position,
//! depth and volume, and the declared latent effects), each channel's mean over the analysed split
//! removed (a channel missing on a day takes the model's reconstruction, as the core fills it at
//! inversion). For a C model the same holds: the correction absorbs bias, the question is what F
//! lacks. Working off the linearisation rather than off `x − F(E(x))` keeps the analysis
//! independent of how the encoder distorts its variables to mimic a missing effect (an encoder
//! readily moves the main source towards a second one, or tilts it to follow a step at an edge
//! station); candidate patterns are projected the same way.

use super::{GnssProblem, Network};
use crate::analysis::projection::{orthonormal, project};
use crate::data::SplitName;
use crate::numerics::median;
use anyhow::{anyhow, bail, Result};
use magic_core::{invert_at, Model, Workspace};
use rayon::prelude::*;
use serde_json::json;
use std::sync::{Arc, OnceLock};

/// The second-source search's grid, computed once per set of residuals (surrogates share it).
#[derive(Debug)]
pub struct SourceGrid {
    /// Orthonormal basis of F's tangent space and the network's translations: the directions
    /// a point source is not judged on.
    pub basis: Vec<Vec<f64>>,
    /// Grid points (x, y, depth km).
    pub points: Vec<[f64; 3]>,
    /// The pattern of a unit source at each point, projected off `basis`.
    pub patterns: Vec<Vec<f64>>,
}

/// Fewest days of a split the analysis accepts.
pub const MIN_DAYS: usize = 360;

/// A block of residual rows: `r[t * nc + c]` in standardised units.
#[derive(Clone, Debug, Default)]
pub struct Block {
    /// Day numbers.
    pub days: Vec<f64>,
    /// Residuals, row-major (days × channels).
    pub r: Vec<f64>,
}

impl Block {
    /// Number of rows for `nc` channels.
    pub fn len(&self, nc: usize) -> usize {
        self.r.len() / nc.max(1)
    }

    /// Channel `c`'s series (one value per row) for `nc` channels.
    pub fn channel(&self, c: usize, nc: usize) -> Vec<f64> {
        self.r.iter().skip(c).step_by(nc.max(1)).copied().collect()
    }
}

/// What every family shares about the residuals of one model: the network, the units, F's
/// tangent space and the real residuals' scale.
#[derive(Debug)]
pub struct Context {
    /// The network.
    pub network: Network,
    /// mm per standardised unit, per channel.
    pub scale: Vec<f64>,
    /// Channel means removed from the residuals (standardised units).
    pub mean: Vec<f64>,
    /// Mean squared residual of the analysed split before removing the means (the physics-only
    /// MSE of the split).
    pub mse: f64,
    /// The main source's typical position (x, y, depth): the encoder's median over the days of
    /// largest volume change.
    pub main_source: [f64; 3],
    /// Orthonormal basis (standardised units) of the directions F can already produce by
    /// adjusting its variables around their typical values.
    pub tangent: Vec<Vec<f64>>,
    /// Sum of squares of the analysed days' (real) residuals: the denominator of the latent
    /// families' shares, for the data and its surrogates alike.
    pub total_fit: f64,
    /// The analysed splits.
    pub splits: Vec<SplitName>,
    /// Cached second-source search grid and its projected patterns.
    pub(crate) source_grid: OnceLock<SourceGrid>,
}

/// Residuals of a model on a dataset: the analysed days in time order (which surrogates
/// replace) and the shared [`Context`].
#[derive(Clone, Debug)]
pub struct GnssResiduals {
    /// What every family shares.
    pub ctx: Arc<Context>,
    /// The analysed days in time order, with each channel's mean over them removed.
    pub fit: Block,
}

impl GnssResiduals {
    /// Number of channels.
    pub fn nc(&self) -> usize {
        self.ctx.scale.len()
    }

    /// Number of stations.
    pub fn ns(&self) -> usize {
        self.ctx.network.len()
    }

    /// `g` without its part in the span of F's Jacobian: what remains of an effect of pattern
    /// `g` after the encoder has absorbed what F can mimic.
    pub fn project(&self, g: &[f64]) -> Vec<f64> {
        project(&self.ctx.tangent, g)
    }

    /// Every row of `r` projected with [`GnssResiduals::project`].
    pub fn project_rows(&self, r: &[f64]) -> Vec<f64> {
        r.par_chunks(self.nc())
            .flat_map_iter(|row| self.project(row))
            .collect()
    }

    /// The same residuals with another analysed block (a surrogate).
    pub fn with_fit(&self, r: Vec<f64>) -> GnssResiduals {
        GnssResiduals {
            ctx: self.ctx.clone(),
            fit: Block {
                days: self.fit.days.clone(),
                r,
            },
        }
    }

    /// The report's view of the residuals (JSON) and its summary line.
    pub fn describe(&self) -> (serde_json::Value, String) {
        let (nc, ns) = (self.nc(), self.ns());
        let t_n = self.fit.len(nc);
        let (pc, share) = dominant_pattern(&self.fit.r, nc);
        let amp = (share * self.ctx.total_fit / t_n.max(1) as f64).sqrt();
        let pattern_mm: Vec<[f64; 3]> = (0..ns)
            .map(|i| core::array::from_fn(|k| pc[k * ns + i] * amp * self.ctx.scale[k * ns + i]))
            .collect();
        let station_rms_mm: Vec<[f64; 3]> = (0..ns)
            .map(|i| {
                core::array::from_fn(|k| {
                    let c = k * ns + i;
                    let s: f64 = (0..t_n).map(|t| self.fit.r[t * nc + c].powi(2)).sum();
                    (s / t_n.max(1) as f64).sqrt() * self.ctx.scale[c]
                })
            })
            .collect();
        let variance = self.ctx.total_fit / self.fit.r.len().max(1) as f64;
        let m = self.ctx.main_source;
        let splits: Vec<&str> = self.ctx.splits.iter().map(|s| s.as_str()).collect();
        let summary = format!(
            "residuals on {} ({t_n} days): variance {variance:.4} (standardised, means removed), physics-only MSE {:.4}",
            splits.join(" + "),
            self.ctx.mse
        );
        let json = json!({
            "residual_variance": variance,
            "residual_mse": self.ctx.mse,
            "n_days": t_n,
            "splits": self.ctx.splits,
            "main_source": {"x_km": m[0], "y_km": m[1], "depth_km": m[2]},
            "station_rms_mm": station_rms_mm,
            "pattern_mm": pattern_mm,
            "pattern_share": share,
        });
        (json, summary)
    }
}

/// An inverted day: observation (mm), F(E(x)) (mm) and the encoder's variables.
struct Day {
    obs: Vec<f64>,
    physics: Vec<f64>,
    params: Vec<f64>,
}

fn invert_split(
    p: &GnssProblem,
    model: &Model<'_>,
    name: SplitName,
) -> Result<(Vec<f64>, Vec<Day>)> {
    let (nc, np) = (p.data.n_obs(), model.n_params());
    let s = p.data.split(name);
    let days = s.days();
    if let Some(i) = days.iter().position(|d| !d.is_finite()) {
        bail!(
            "split {name}: row {} has no valid date `{}`",
            i + 1,
            s.dates[i]
        );
    }
    let rows: Vec<Day> =
        s.x.par_iter()
            .zip(days.par_iter())
            .map_init(Workspace::default, |ws, (row, &t)| {
                let obs = p.data.physical_row(row);
                let inv = invert_at::<f64>(model, &obs, t, ws)
                    .map_err(|e| anyhow!("{name} day {t}: {e}"))?;
                // A missing channel takes the model's own reconstruction (as the core fills it):
                // it then adds nothing that F could not produce.
                Ok(Day {
                    obs: obs
                        .iter()
                        .zip(&inv.recon)
                        .map(|(v, r)| if v.is_nan() { *r } else { *v as f64 })
                        .collect(),
                    physics: inv.physics[..nc].to_vec(),
                    params: inv.params[..np].to_vec(),
                })
            })
            .collect::<Result<_>>()?;
    Ok((days, rows))
}

/// Residuals (observation − F(E(x)), standardised) of every day of `splits`, in time order, with
/// the tangent space of F at the main source's typical position.
pub fn residuals(
    p: &GnssProblem,
    model: &Model<'_>,
    splits: &[SplitName],
) -> Result<GnssResiduals> {
    let nc = p.data.n_obs();
    if model.n_obs() != nc {
        bail!("the model has {} channels, the data {}", model.n_obs(), nc);
    }
    if nc != 3 * p.network.len() {
        bail!("expected 3 channels per station");
    }
    let np = model.n_params();
    let (mut days, mut rows) = (Vec::new(), Vec::new());
    for &s in splits {
        let (d, r) = invert_split(p, model, s)?;
        days.extend(d);
        rows.extend(r);
    }
    if days.len() < MIN_DAYS {
        bail!(
            "{} days are too few for the analysis (at least {MIN_DAYS})",
            days.len()
        );
    }
    let mut order: Vec<usize> = (0..days.len()).collect();
    order.sort_by(|&a, &b| days[a].total_cmp(&days[b]));
    let days: Vec<f64> = order.iter().map(|&i| days[i]).collect();
    let mut slots: Vec<Option<Day>> = rows.into_iter().map(Some).collect();
    let rows: Vec<Day> = order.iter().filter_map(|&i| slots[i].take()).collect();
    let main = main_source(
        &rows
            .iter()
            .map(|d| [d.params[0], d.params[1], d.params[2], d.params[3]])
            .collect::<Vec<_>>(),
    );
    let scale = &p.data.scale;
    let tangent = tangent_basis(model, scale, main, days[days.len() / 2])?;
    let mse = rows
        .iter()
        .flat_map(|d| (0..nc).map(move |c| ((d.obs[c] - d.physics[c]) / scale[c]).powi(2)))
        .sum::<f64>()
        / (rows.len() * nc) as f64;
    // Observations less F's time-dependent effects (F with the source's volume and the latent
    // effects at zero), standardised and projected off F's Jacobian.
    let mut p0 = vec![0.0; np];
    p0[..3].copy_from_slice(&main);
    let r: Vec<Vec<f64>> = rows
        .par_iter()
        .zip(days.par_iter())
        .map(|(d, t)| {
            let mut f = vec![0.0; nc];
            magic_core::invert::forward(model, &p0, *t, &mut f)
                .map_err(|e| anyhow!("day {t}: {e}"))?;
            let row: Vec<f64> = (0..nc).map(|c| (d.obs[c] - f[c]) / scale[c]).collect();
            Ok(project(&tangent, &row))
        })
        .collect::<Result<_>>()?;
    let mut fit = Block {
        days,
        r: r.concat(),
    };
    let t_n = fit.len(nc);
    let mut mean = vec![0.0; nc];
    for row in fit.r.chunks(nc) {
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v / t_n as f64;
        }
    }
    for row in fit.r.chunks_mut(nc) {
        for (v, m) in row.iter_mut().zip(&mean) {
            *v -= m;
        }
    }
    let total_fit = fit.r.iter().map(|v| v * v).sum();
    Ok(GnssResiduals {
        ctx: Arc::new(Context {
            network: p.network.clone(),
            scale: scale.clone(),
            mean,
            mse,
            main_source: main,
            tangent,
            total_fit,
            splits: splits.to_vec(),
            source_grid: OnceLock::new(),
        }),
        fit,
    })
}

/// Orthonormal basis of the columns of F's Jacobian (standardised units) at the main source's
/// typical position with a unit volume change (the span does not depend on the volume) and the
/// latent effects at zero (they enter linearly).
fn tangent_basis(
    model: &Model<'_>,
    scale: &[f64],
    main: [f64; 3],
    day: f64,
) -> Result<Vec<Vec<f64>>> {
    const N: usize = magic_core::model_file::MAX_PARAMS;
    let np = model.n_params();
    let nc = scale.len();
    let mut p = [magic_core::Dual::<N>::constant(0.0); N];
    for (j, v) in p.iter_mut().enumerate().take(np) {
        let x = match j {
            0..=2 => main[j],
            3 => 1.0,
            _ => 0.0,
        };
        *v = magic_core::Dual::var(x, j);
    }
    let mut out = vec![magic_core::Dual::<N>::constant(0.0); nc];
    magic_core::invert::forward(model, &p[..np], day, &mut out)
        .map_err(|e| anyhow!("F's Jacobian: {e}"))?;
    let columns: Vec<(Vec<f64>, f64)> = (0..np)
        .map(|j| {
            let v: Vec<f64> = (0..nc).map(|c| out[c].d[j] / scale[c]).collect();
            let s = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            (v, s)
        })
        .collect();
    Ok(orthonormal(&columns, 1e-9, 1))
}

/// Median position of the source over the days with the largest |ΔV| (the top quarter).
fn main_source(p: &[[f64; 4]]) -> [f64; 3] {
    let mut by_dv: Vec<&[f64; 4]> = p.iter().collect();
    by_dv.sort_by(|a, b| b[3].abs().total_cmp(&a[3].abs()));
    let top = &by_dv[..(by_dv.len() / 4).max(1)];
    core::array::from_fn(|k| median(&mut top.iter().map(|q| q[k]).collect::<Vec<_>>()))
}

/// The first principal component of the rows (standardised): unit vector and its share of the
/// total variance (power iteration on the channel covariance).
fn dominant_pattern(r: &[f64], nc: usize) -> (Vec<f64>, f64) {
    let mut cov = vec![0.0; nc * nc];
    for row in r.chunks(nc) {
        for a in 0..nc {
            for b in 0..nc {
                cov[a * nc + b] += row[a] * row[b];
            }
        }
    }
    let total: f64 = (0..nc).map(|c| cov[c * nc + c]).sum();
    let mut v = vec![1.0 / (nc as f64).sqrt(); nc];
    let mut lambda = 0.0;
    for _ in 0..200 {
        let w: Vec<f64> = (0..nc)
            .map(|a| (0..nc).map(|b| cov[a * nc + b] * v[b]).sum())
            .collect();
        let n = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n == 0.0 {
            break;
        }
        lambda = n;
        v = w.iter().map(|x| x / n).collect();
    }
    (v, if total > 0.0 { lambda / total } else { 0.0 })
}
