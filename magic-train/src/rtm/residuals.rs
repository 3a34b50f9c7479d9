//! The residuals of a forest-spectra model, as its effect families see them.
//!
//! Every spectrum of the fitting split (`train`) and of the held-out split (`valid` by default)
//! is inverted with the core's `invert_at` (the model as it will be used); the residual is the
//! observation less F(E(x)) (for a C model too: the question is what F lacks), in the data's
//! standardised units (the paper's metric). As for the GNSS analysis, the families are fitted to
//! what F cannot produce whatever its variables: each spectrum's residual and each candidate
//! pattern are projected off the span of F's exact Jacobian (7 learned variables, 11 bands) at
//! that spectrum's variables, so that a pattern the encoder could mimic by moving LAI or
//! chlorophyll does not count as a discovery, and what is left is what no choice of the variables
//! can fit.
//!
//! Surrogates keep the spectra and change only their labels: [`SpectraResiduals`] holds the
//! spectra once (shared) and, per spectrum, the date and species index and a sign the families'
//! surrogates permute or flip.

use super::RtmProblem;
use crate::analysis::projection::{orthonormal, project};
use crate::data::{day_number, Split, SplitName};
use crate::model::OwnedEffect;
use anyhow::{anyhow, bail, Result};
use magic_core::effects::rtm_fixed_at;
use magic_core::rtm::N_LEARNED;
use magic_core::{invert_at, Model, Problem, Workspace};
use rayon::prelude::*;
use serde_json::json;
use std::collections::BTreeMap;
use std::sync::Arc;

/// One spectrum's projected residual and patterns.
#[derive(Clone, Debug)]
pub struct Spectrum {
    /// Residual (standardised), projected off F's Jacobian.
    pub r: Vec<f64>,
    /// Orthonormal basis of F's Jacobian columns (standardised).
    pub q: Vec<Vec<f64>>,
    /// Index of the spectrum's date in [`Context::dates`].
    pub date: usize,
    /// Index of its species in [`Context::species`].
    pub species: usize,
    /// Per date: the projected pattern F(z; that date's sun) − F(z; the model's sun).
    pub g: Vec<Vec<f64>>,
    /// The unprojected residual (standardised).
    pub raw: Vec<f64>,
}

impl Spectrum {
    /// `v − Q Qᵀ v`.
    pub fn project(&self, v: &[f64]) -> Vec<f64> {
        project(&self.q, v)
    }
}

/// What every family shares about one model's residuals.
#[derive(Debug)]
pub struct Context {
    /// Fitting spectra.
    pub fit: Vec<Spectrum>,
    /// Held-out spectra.
    pub held: Vec<Spectrum>,
    /// Fitting and held-out split.
    pub splits: [SplitName; 2],
    /// The dates of both splits (`YYYY.MM.DD`) and their day numbers.
    pub dates: Vec<(String, f64)>,
    /// The species of both splits.
    pub species: Vec<String>,
    /// Band column names.
    pub bands: Vec<String>,
    /// The model's observation scale (reflectance per standardised unit).
    pub scale: Vec<f64>,
    /// Effects the model declares.
    pub declared: Vec<OwnedEffect>,
    /// The illumination effect the families test (the data's site and overpass).
    pub sun: OwnedEffect,
}

/// The residuals with the labels the surrogates permute.
#[derive(Clone, Debug)]
pub struct SpectraResiduals {
    /// The spectra (shared by surrogates).
    pub ctx: Arc<Context>,
    /// Date index of every fitting spectrum.
    pub fit_dates: Vec<usize>,
    /// Date index of every held-out spectrum.
    pub held_dates: Vec<usize>,
    /// Species index of every fitting spectrum.
    pub fit_species: Vec<usize>,
    /// Sign of every fitting spectrum's residual (±1).
    pub fit_signs: Vec<f64>,
}

impl SpectraResiduals {
    /// Number of bands.
    pub fn nb(&self) -> usize {
        self.ctx.bands.len()
    }

    /// A bootstrap draw for the families' uncertainties: as many fitting spectra drawn with
    /// replacement (with their dates, species and signs), no held-out spectra (a draw is refitted,
    /// not scored).
    pub fn resample_fit(&self, rng: &mut impl rand::Rng) -> SpectraResiduals {
        let n = self.ctx.fit.len();
        let idx: Vec<usize> = (0..n).map(|_| rng.random_range(0..n.max(1))).collect();
        let c = &self.ctx;
        SpectraResiduals {
            fit_dates: idx.iter().map(|&i| self.fit_dates[i]).collect(),
            held_dates: vec![],
            fit_species: idx.iter().map(|&i| self.fit_species[i]).collect(),
            fit_signs: idx.iter().map(|&i| self.fit_signs[i]).collect(),
            ctx: Arc::new(Context {
                fit: idx.iter().map(|&i| c.fit[i].clone()).collect(),
                held: vec![],
                splits: c.splits,
                dates: c.dates.clone(),
                species: c.species.clone(),
                bands: c.bands.clone(),
                scale: c.scale.clone(),
                declared: c.declared.clone(),
                sun: c.sun.clone(),
            }),
        }
    }

    /// Whether the model declares an effect of `family`.
    pub fn declares(&self, family: &str) -> bool {
        self.ctx.declared.iter().any(|e| e.family() == family)
    }

    /// The report's view of the residuals (JSON) and its summary line.
    pub fn describe(&self) -> (serde_json::Value, String) {
        let (ctx, nb) = (&self.ctx, self.nb());
        let mse = |s: &[Spectrum]| {
            s.iter()
                .map(|x| x.raw.iter().map(|v| v * v).sum::<f64>())
                .sum::<f64>()
                / (s.len() * nb).max(1) as f64
        };
        let proj2: f64 = ctx
            .held
            .iter()
            .map(|s| s.r.iter().map(|v| v * v).sum::<f64>())
            .sum();
        let raw2: f64 = ctx
            .held
            .iter()
            .map(|s| s.raw.iter().map(|v| v * v).sum::<f64>())
            .sum();
        let share = if raw2 > 0.0 { proj2 / raw2 } else { 0.0 };
        let (m0, m1) = (mse(&ctx.fit), mse(&ctx.held));
        let mut date_band_mean = vec![vec![0.0; nb]; ctx.dates.len()];
        let mut counts = vec![0usize; ctx.dates.len()];
        for (s, &d) in ctx.held.iter().zip(&self.held_dates) {
            counts[d] += 1;
            for (c, v) in s.r.iter().enumerate() {
                date_band_mean[d][c] += v;
            }
        }
        for (m, &n) in date_band_mean.iter_mut().zip(&counts) {
            m.iter_mut().for_each(|v| *v /= n.max(1) as f64);
        }
        let summary = format!(
            "residuals fitted on {} ({} spectra), scored on {} ({} spectra): physics-only MSE {m0:.4} / {m1:.4}, {:.0} % of it beyond what F's variables can fit",
            ctx.splits[0],
            ctx.fit.len(),
            ctx.splits[1],
            ctx.held.len(),
            100.0 * share
        );
        let json = json!({
            "n": [ctx.fit.len(), ctx.held.len()],
            "physics_mse": [m0, m1],
            "projected_share": share,
            "dates": ctx.dates.iter().map(|(d, _)| d).collect::<Vec<_>>(),
            "date_band_mean": date_band_mean,
            "bands": ctx.bands,
        });
        (json, summary)
    }
}

/// Orthonormal basis of F's Jacobian columns (standardised) at `z` under `fixed` (modified
/// Gram–Schmidt twice, rank-revealing); also F's values there.
fn tangent(
    model: &Model<'_>,
    z: &[f64; N_LEARNED],
    fixed: &magic_core::rtm::Fixed,
    scale: &[f64],
) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
    let Problem::Rtm { geometry, .. } = model.problem else {
        bail!("not an RTM model");
    };
    let nb = scale.len();
    let mut y = vec![0.0; nb];
    let mut jac = vec![[0.0; N_LEARNED]; nb];
    model
        .problem
        .packed()?
        .jacobian(z, fixed, geometry, &mut y, &mut jac)?;
    let columns: Vec<(Vec<f64>, f64)> = (0..N_LEARNED)
        .map(|k| {
            let v: Vec<f64> = jac
                .iter()
                .enumerate()
                .map(|(c, row)| row[k] / scale[c])
                .collect();
            let n0 = v.iter().map(|a| a * a).sum::<f64>().sqrt();
            (v, n0)
        })
        .collect();
    Ok((y, orthonormal(&columns, 1e-8, 2)))
}

/// Inverts a split and builds its projected residuals and patterns.
fn spectra(
    p: &RtmProblem,
    model: &Model<'_>,
    split: &Split,
    dates: &BTreeMap<String, usize>,
    date_days: &[f64],
    species: &BTreeMap<String, usize>,
) -> Result<Vec<Spectrum>> {
    let Problem::Rtm {
        fixed, geometry, ..
    } = model.problem
    else {
        bail!("not an RTM model");
    };
    let packed = model.problem.packed()?;
    let nb = model.n_obs();
    let sun_owned = p.illumination();
    let sun = sun_owned.borrow(&[]);
    let days = split.days();
    let scale: Vec<f64> = model.obs_scale.iter().map(|v| v as f64).collect();
    (0..split.len())
        .into_par_iter()
        .map_init(Workspace::default, |ws, i| {
            let obs: Vec<f32> = split.x[i]
                .iter()
                .enumerate()
                .map(|(c, v)| v * model.obs_scale.get(c) + model.obs_mean.get(c))
                .collect();
            let inv = invert_at::<f64>(model, &obs, days[i], ws)
                .map_err(|e| anyhow!("spectrum {} of {}: {e}", i + 1, split.len()))?;
            let z: [f64; N_LEARNED] = inv.params[..N_LEARNED]
                .try_into()
                .map_err(|_| anyhow!("RTM model with {} variables", inv.n_params))?;
            let raw: Vec<f64> = (0..nb)
                .map(|c| (obs[c] as f64 - inv.physics[c]) / scale[c])
                .collect();
            // F's Jacobian in standardised units at the model's own sun for this date.
            let cur = rtm_fixed_at(&model.effects, &fixed, days[i])?;
            let (y, q) = tangent(model, &z, &cur, &scale)?;
            let mut s = Spectrum {
                r: project(&q, &raw),
                q,
                date: *dates.get(&split.dates[i]).unwrap_or(&0),
                species: split
                    .labels
                    .get(i)
                    .and_then(|l| species.get(l))
                    .copied()
                    .unwrap_or(0),
                g: vec![],
                raw,
            };
            // The model's own F at its sun (y) against each date's sun.
            s.g = date_days
                .iter()
                .map(|&d| -> Result<Vec<f64>> {
                    let f = rtm_fixed_at(&[sun], &fixed, d)?;
                    let mut yd = vec![0.0; nb];
                    packed.forward_learned(&z, &f, geometry, &mut yd)?;
                    let g: Vec<f64> = (0..nb).map(|c| (yd[c] - y[c]) / scale[c]).collect();
                    Ok(s.project(&g))
                })
                .collect::<Result<_>>()?;
            Ok(s)
        })
        .collect()
}

/// The residuals of an RTM model (B or C) fitted on `split`, scored on `held`.
pub fn residuals(
    p: &RtmProblem,
    model: &Model<'_>,
    split: SplitName,
    held: SplitName,
) -> Result<SpectraResiduals> {
    if !matches!(model.problem, Problem::Rtm { .. }) {
        bail!("residual analysis of the forest spectra needs an RTM model");
    }
    if model.n_obs() != p.data.n_obs() {
        bail!(
            "the model has {} bands, the data {}",
            model.n_obs(),
            p.data.n_obs()
        );
    }
    if split == held {
        bail!("fit and held-out splits must differ ({split})");
    }
    let (fs, hs) = (p.data.split(split), p.data.split(held));
    // Dates and species over both splits.
    let mut date_of = BTreeMap::new();
    let mut species_of = BTreeMap::new();
    for s in [fs, hs] {
        for d in &s.dates {
            date_of.entry(d.clone()).or_insert(0);
        }
        for c in &s.labels {
            species_of.entry(c.clone()).or_insert(0);
        }
    }
    for (k, v) in date_of.values_mut().enumerate() {
        *v = k;
    }
    for (k, v) in species_of.values_mut().enumerate() {
        *v = k;
    }
    let dates: Vec<(String, f64)> = date_of.keys().map(|d| (d.clone(), day_number(d))).collect();
    if let Some(d) = dates.iter().find(|(_, v)| !v.is_finite()) {
        bail!("date `{}` is not YYYY.MM.DD", d.0);
    }
    let days: Vec<f64> = dates.iter().map(|d| d.1).collect();
    let fit = spectra(p, model, fs, &date_of, &days, &species_of)?;
    let held_s = spectra(p, model, hs, &date_of, &days, &species_of)?;
    Ok(SpectraResiduals {
        fit_dates: fit.iter().map(|s| s.date).collect(),
        held_dates: held_s.iter().map(|s| s.date).collect(),
        fit_species: fit.iter().map(|s| s.species).collect(),
        fit_signs: vec![1.0; fit.len()],
        ctx: Arc::new(Context {
            fit,
            held: held_s,
            splits: [split, held],
            dates,
            species: species_of.keys().cloned().collect(),
            bands: p.data.columns.clone(),
            scale: model.obs_scale.iter().map(|v| v as f64).collect(),
            declared: model.effects.iter().map(OwnedEffect::from_core).collect(),
            sun: p.illumination(),
        }),
    })
}
