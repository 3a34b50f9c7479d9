//! Residual analysis for the forest spectra: which effect does INFORM lack?
//!
//! **The residual.** Every spectrum of the fitting split (`train`) and of the held-out split
//! (`valid` by default) is inverted with the core's `invert_at` (the model as it will be used);
//! the residual is the observation less F(E(x)) (for a C model too: the question is what F
//! lacks), in the data's standardised units (the paper's metric). As for the GNSS analysis, the
//! families are fitted to what F cannot produce whatever its variables: each spectrum's residual
//! and each candidate pattern are projected off the span of F's exact Jacobian (7 learned
//! variables, 11 bands) at that spectrum's variables, so that a pattern the encoder could mimic by
//! moving LAI or chlorophyll does not count as a discovery, and what is left is what no choice of
//! the variables can fit.
//!
//! **Families.**
//! * `illumination`: F with the true sun of the acquisition (zenith and relative azimuth from the
//!   date at the site and overpass time, [`crate::rtm_pipeline::s2_illumination`]) less F with the
//!   model's sun (the paper's 30°), at the spectrum's variables: one pattern per spectrum, scaled
//!   by one weight fitted on the fitting split. Declarable: it becomes
//!   `magic_core::effects::Effect::Illumination`. When the model already declares it the pattern
//!   is zero and the family scores 0.
//! * `band_offset`: one constant per band (a bias of the band model, the sensor or the atmospheric
//!   correction), scored in the projected space (`(Σ Pᵢ)⁻¹ Σ Pᵢ rᵢ`). Declarable as
//!   `magic_core::effects::Effect::BandOffset` with the mean residual per band of the fitting
//!   spectra (reflectance).
//! * `species`: one constant per band and species (structure the forest model does not have per
//!   species: leaf angles, crown shape, understory). Reported, not added (the species is not an
//!   input of the inversion).
//!
//! **Scores** are shares of the projected residual variance of the held-out split explained by a
//! family's prediction scaled by one least-squares weight λ ≥ 0 (so a family never scores below
//! zero): `max(0, Σ⟨r, p⟩)² / (Σ‖p‖² Σ‖r‖²)`.
//!
//! **Chance.** The same fit and score on surrogates that keep everything but the family's
//! information: dates permuted among the spectra of each split (`illumination`: any sun but the
//! right one; the part of the pattern shared by all dates stays in the chance level), a random
//! sign per fitting spectrum (`band_offset`), species labels permuted among the fitting spectra
//! (`species`: what is left is the band offset shared by all species). Significance as in
//! [`crate::residuals`] ([`Candidate::from_scores`]).

use crate::data::s2::{S2Data, S2Split};
use crate::export::OwnedEffect;
use crate::residuals::{effects_chart, Candidate};
use crate::rtm_pipeline::s2_illumination;
use anyhow::{anyhow, bail, Result};
use magic_core::effects::rtm_fixed_at;
use magic_core::rtm::N_LEARNED;
use magic_core::{invert_at, Model, Problem, Workspace};
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde_json::json;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The families of the forest-spectra analysis.
pub const RTM_FAMILIES: [&str; 3] = ["illumination", "band_offset", "species"];

/// Options of [`analyse_rtm`].
#[derive(Clone, Debug)]
pub struct RtmAnalysisOptions {
    /// Split the families are fitted on.
    pub fit_split: String,
    /// Held-out split they are scored on.
    pub split: String,
    /// Surrogates per family.
    pub surrogates: usize,
    /// Quantile of the surrogate scores taken as the chance level.
    pub quantile: f64,
    /// Seed of the surrogates.
    pub seed: u64,
    /// Project residuals and patterns off F's Jacobian (what no choice of the variables can fit).
    pub project: bool,
}

impl Default for RtmAnalysisOptions {
    fn default() -> Self {
        RtmAnalysisOptions {
            fit_split: "train".into(),
            split: "valid".into(),
            surrogates: 20,
            quantile: 0.95,
            seed: 0,
            project: true,
        }
    }
}

/// One spectrum's projected residual and patterns.
struct Spectrum {
    /// Residual (standardised), projected off F's Jacobian.
    r: Vec<f64>,
    /// Orthonormal basis of F's Jacobian columns (standardised), column-major: `nb` values each.
    q: Vec<Vec<f64>>,
    /// Index of the spectrum's date in [`RtmAnalysis::dates`].
    date: usize,
    /// Index of its species.
    species: usize,
    /// Per date: the projected pattern F(z; that date's sun) − F(z; the model's sun).
    g: Vec<Vec<f64>>,
    /// Squared norm of the unprojected residual.
    raw2: f64,
    /// The unprojected residual (standardised).
    raw: Vec<f64>,
}

impl Spectrum {
    /// `v − Q Qᵀ v`.
    fn project(&self, v: &[f64]) -> Vec<f64> {
        let mut out = v.to_vec();
        for c in &self.q {
            let d: f64 = c.iter().zip(v).map(|(a, b)| a * b).sum();
            for (o, a) in out.iter_mut().zip(c) {
                *o -= d * a;
            }
        }
        out
    }
}

/// The result of [`analyse_rtm`].
#[derive(Clone, Debug)]
pub struct RtmAnalysis {
    /// Candidates ranked by excess over chance, descending.
    pub effects: Vec<Candidate>,
    /// Fitting and held-out split names.
    pub splits: [String; 2],
    /// Spectra in each.
    pub n: [usize; 2],
    /// Physics-only MSE (standardised) of each split.
    pub physics_mse: [f64; 2],
    /// Share of the held-out physics-only MSE left after projecting off F's Jacobian.
    pub projected_share: f64,
    /// Dates of the data (`YYYY.MM.DD`) and the sun zenith at the site then (degrees).
    pub dates: Vec<(String, f64)>,
    /// Mean held-out residual per date and band (standardised, projected off F's Jacobian).
    pub date_band_mean: Vec<Vec<f64>>,
    /// Band names.
    pub bands: Vec<String>,
    /// Seconds the analysis took.
    pub seconds: f64,
}

impl RtmAnalysis {
    /// The most significant candidate that can be declared as physics (has an effect; a family
    /// the model already declares has none).
    pub fn top_declarable(&self) -> Option<&Candidate> {
        self.effects
            .iter()
            .find(|c| c.significant && c.effect.is_some())
    }

    /// The JSON report (`{"effects": [{"family", "variance_explained", "chance_level",
    /// "significant", "params"}, …], …}`).
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "effects": self.effects.iter().map(Candidate::to_json).collect::<Vec<_>>(),
            "fit_split": self.splits[0],
            "split": self.splits[1],
            "n": self.n,
            "physics_mse": self.physics_mse,
            "projected_share": self.projected_share,
            "dates": self.dates.iter().map(|(d, z)| json!({"date": d, "sun_zenith_deg": z})).collect::<Vec<_>>(),
        })
    }

    /// A text table of the candidates.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "residuals fitted on {} ({} spectra), scored on {} ({} spectra): physics-only MSE {:.4} / {:.4}, {:.0} % of it beyond what F's variables can fit",
            self.splits[0],
            self.n[0],
            self.splits[1],
            self.n[1],
            self.physics_mse[0],
            self.physics_mse[1],
            100.0 * self.projected_share
        );
        let _ = writeln!(
            s,
            "{:<14} {:>10} {:>10} {:>10} {:>8}  params",
            "family", "explained", "chance", "excess", "signif."
        );
        for c in &self.effects {
            let p = c.params.to_string();
            let p: String = p.chars().take(150).collect();
            let _ = writeln!(
                s,
                "{:<14} {:>9.2}% {:>9.2}% {:>9.2}% {:>8}  {}",
                c.family,
                100.0 * c.variance_explained,
                100.0 * c.chance_level,
                100.0 * c.excess(),
                if c.significant { "yes" } else { "no" },
                p
            );
        }
        s
    }
}

/// `max(0, Σ⟨r, p⟩)² / (Σ‖p‖² Σ‖r‖²)` over spectra.
fn share(r: &[&[f64]], p: &[Vec<f64>]) -> f64 {
    let (mut rp, mut pp, mut rr) = (0.0, 0.0, 0.0);
    for (ri, pi) in r.iter().zip(p) {
        for (a, b) in ri.iter().zip(pi) {
            rp += a * b;
            pp += b * b;
            rr += a * a;
        }
    }
    if rp <= 0.0 || pp <= 0.0 || rr <= 0.0 {
        return 0.0;
    }
    rp * rp / (pp * rr)
}

/// Constant offset per band, least squares in the projected space: `(Σ Pᵢ)⁻¹ Σ Pᵢ rᵢ` over
/// `spectra` with weights `w` (±1 for the sign surrogates). `None` when singular.
fn offset(spectra: &[&Spectrum], w: &[f64], nb: usize) -> Option<Vec<f64>> {
    if spectra.is_empty() {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(nb, nb);
    let mut b = DVector::<f64>::zeros(nb);
    for (s, &wi) in spectra.iter().zip(w) {
        for i in 0..nb {
            a[(i, i)] += 1.0;
            b[i] += wi * s.r[i];
        }
        for c in &s.q {
            for i in 0..nb {
                for j in 0..nb {
                    a[(i, j)] -= c[i] * c[j];
                }
            }
        }
    }
    // Pseudo-inverse: directions (nearly) every spectrum's F can fit have no offset to find.
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    let x = svd.solve(&b, 1e-3 * smax).ok()?;
    Some(x.iter().copied().collect())
}

/// Illumination weight fitted on `fit` with date index map `dates` (identity or a surrogate's
/// permutation), prediction on `held` with `held_dates`.
fn illumination_score(
    fit: &[&Spectrum],
    fit_dates: &[usize],
    held: &[&Spectrum],
    held_dates: &[usize],
) -> (f64, f64) {
    let (mut rg, mut gg) = (0.0, 0.0);
    for (s, &d) in fit.iter().zip(fit_dates) {
        for (a, b) in s.r.iter().zip(&s.g[d]) {
            rg += a * b;
            gg += b * b;
        }
    }
    if gg <= 1e-18 {
        return (0.0, 0.0);
    }
    let alpha = rg / gg;
    let r: Vec<&[f64]> = held.iter().map(|s| s.r.as_slice()).collect();
    let p: Vec<Vec<f64>> = held
        .iter()
        .zip(held_dates)
        .map(|(s, &d)| s.g[d].iter().map(|v| alpha * v).collect())
        .collect();
    (share(&r, &p), alpha)
}

/// Per-band offsets (`band_offset`) or per-species offsets (`species`) fitted on `fit` and
/// scored on `held`.
fn offset_score(
    fit: &[&Spectrum],
    fit_species: Option<&[usize]>,
    w: &[f64],
    held: &[&Spectrum],
    nb: usize,
    n_species: usize,
) -> (f64, Vec<Option<Vec<f64>>>) {
    let groups: Vec<Option<Vec<f64>>> = match fit_species {
        None => vec![offset(fit, w, nb)],
        Some(lab) => (0..n_species)
            .map(|k| {
                let (ss, ws): (Vec<&Spectrum>, Vec<f64>) = fit
                    .iter()
                    .zip(lab)
                    .zip(w)
                    .filter(|((_, &l), _)| l == k)
                    .map(|((s, _), &wi)| (*s, wi))
                    .unzip();
                // Too few spectra for 11 constants: no offset for that species.
                if ss.len() < 4 * nb {
                    None
                } else {
                    offset(&ss, &ws, nb)
                }
            })
            .collect(),
    };
    let r: Vec<&[f64]> = held.iter().map(|s| s.r.as_slice()).collect();
    let p: Vec<Vec<f64>> = held
        .iter()
        .map(|s| {
            let k = if fit_species.is_some() { s.species } else { 0 };
            match groups.get(k).and_then(|g| g.as_ref()) {
                Some(b) => s.project(b),
                None => vec![0.0; nb],
            }
        })
        .collect();
    (share(&r, &p), groups)
}

/// The sun zenith at the S2 site and overpass on a date (day number).
fn zenith_at(day: f64) -> Result<f64> {
    let sun = s2_illumination().borrow(&[]);
    let f = rtm_fixed_at(&[sun], &Default::default(), day).map_err(|e| anyhow!("{e}"))?;
    Ok(f.tts)
}

/// Inverts a split and builds its projected residuals and patterns.
fn spectra(
    model: &Model<'_>,
    split: &S2Split,
    date_of: &BTreeMap<String, usize>,
    date_days: &[f64],
    species_of: &BTreeMap<String, usize>,
    project: bool,
) -> Result<Vec<Spectrum>> {
    let Problem::Rtm {
        fixed, geometry, ..
    } = model.problem
    else {
        bail!("not an RTM model");
    };
    let packed = model.problem.packed().map_err(|e| anyhow!("{e}"))?;
    let nb = model.n_obs();
    let sun = s2_illumination().borrow(&[]);
    let days = split.rows.days();
    let obs_mean: Vec<f32> = model.obs_mean.iter().collect();
    let obs_scale: Vec<f32> = model.obs_scale.iter().collect();
    (0..split.len())
        .into_par_iter()
        .map_init(Workspace::default, |ws, i| {
            let x = &split.rows.x[i];
            let day = days[i];
            let obs: Vec<f32> = x
                .iter()
                .enumerate()
                .map(|(c, v)| v * obs_scale[c] + obs_mean[c])
                .collect();
            let inv = invert_at::<f64>(model, &obs, day, ws)
                .map_err(|e| anyhow!("spectrum {} of {}: {e}", i + 1, split.rows.x.len()))?;
            let z: [f64; N_LEARNED] = inv.params[..N_LEARNED]
                .try_into()
                .map_err(|_| anyhow!("RTM model with {} variables", inv.n_params))?;
            let scale = |c: usize| obs_scale[c] as f64;
            let raw: Vec<f64> = (0..nb)
                .map(|c| (obs[c] as f64 - inv.physics[c]) / scale(c))
                .collect();
            // F's Jacobian in standardised units at the model's own sun for this date.
            let cur = rtm_fixed_at(&model.effects, &fixed, day).map_err(|e| anyhow!("{e}"))?;
            let mut y = vec![0.0; nb];
            let mut jac = vec![[0.0; N_LEARNED]; nb];
            packed
                .jacobian(&z, &cur, geometry, &mut y, &mut jac)
                .map_err(|e| anyhow!("{e}"))?;
            // Orthonormal basis of the columns (modified Gram–Schmidt, rank-revealing).
            let mut q: Vec<Vec<f64>> = Vec::new();
            for k in 0..N_LEARNED {
                let mut v: Vec<f64> = jac
                    .iter()
                    .enumerate()
                    .map(|(c, row)| row[k] / scale(c))
                    .collect();
                let n0 = v.iter().map(|a| a * a).sum::<f64>().sqrt();
                for _ in 0..2 {
                    for c in &q {
                        let d: f64 = c.iter().zip(&v).map(|(a, b)| a * b).sum();
                        v.iter_mut().zip(c).for_each(|(o, a)| *o -= d * a);
                    }
                }
                let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
                if project && n > 1e-8 * n0.max(1e-300) && n > 0.0 {
                    q.push(v.iter().map(|a| a / n).collect());
                }
            }
            let mut s = Spectrum {
                r: vec![],
                q,
                date: *date_of.get(&split.rows.dates[i]).unwrap_or(&0),
                species: *species_of.get(&split.class[i]).unwrap_or(&0),
                g: vec![],
                raw2: raw.iter().map(|v| v * v).sum(),
                raw: raw.clone(),
            };
            s.r = s.project(&raw);
            // The model's own F at its sun (y, from the Jacobian call) against each date's sun.
            s.g = date_days
                .iter()
                .map(|&d| -> Result<Vec<f64>> {
                    let f = rtm_fixed_at(&[sun], &fixed, d).map_err(|e| anyhow!("{e}"))?;
                    let mut yd = vec![0.0; nb];
                    packed
                        .forward_learned(&z, &f, geometry, &mut yd)
                        .map_err(|e| anyhow!("{e}"))?;
                    let g: Vec<f64> = (0..nb).map(|c| (yd[c] - y[c]) / scale(c)).collect();
                    Ok(s.project(&g))
                })
                .collect::<Result<_>>()?;
            Ok(s)
        })
        .collect()
}

/// Analyses the residuals of an RTM model (B or C) on the S2 data.
pub fn analyse_rtm(
    model: &Model<'_>,
    data: &S2Data,
    opts: &RtmAnalysisOptions,
) -> Result<RtmAnalysis> {
    let start = std::time::Instant::now();
    if !matches!(model.problem, Problem::Rtm { .. }) {
        bail!("residual analysis of the forest spectra needs an RTM model");
    }
    if model.variant == magic_core::Variant::A {
        bail!("variant A has no forward model: analyse a B or C model");
    }
    if model.n_obs() != data.n_obs() {
        bail!(
            "the model has {} bands, the data {}",
            model.n_obs(),
            data.n_obs()
        );
    }
    let fit_split = data.split(&opts.fit_split)?;
    let held_split = data.split(&opts.split)?;
    if opts.fit_split == opts.split {
        bail!("fit and held-out splits must differ ({})", opts.split);
    }
    // Dates and species over both splits.
    let mut date_of = BTreeMap::new();
    let mut species_of = BTreeMap::new();
    for s in [fit_split, held_split] {
        for d in &s.rows.dates {
            date_of.entry(d.clone()).or_insert(0);
        }
        for c in &s.class {
            species_of.entry(c.clone()).or_insert(0);
        }
    }
    for (k, v) in date_of.values_mut().enumerate() {
        *v = k;
    }
    for (k, v) in species_of.values_mut().enumerate() {
        *v = k;
    }
    let date_names: Vec<String> = date_of.keys().cloned().collect();
    let date_days: Vec<f64> = date_names
        .iter()
        .map(|d| crate::data::gnss::day_number(d))
        .collect();
    if let Some(d) = date_names
        .iter()
        .zip(&date_days)
        .find(|(_, v)| !v.is_finite())
    {
        bail!("date `{}` is not YYYY.MM.DD", d.0);
    }
    let species_names: Vec<String> = species_of.keys().cloned().collect();
    let fit_s = spectra(
        model,
        fit_split,
        &date_of,
        &date_days,
        &species_of,
        opts.project,
    )?;
    let held_s = spectra(
        model,
        held_split,
        &date_of,
        &date_days,
        &species_of,
        opts.project,
    )?;
    let nb = model.n_obs();
    let fit: Vec<&Spectrum> = fit_s.iter().collect();
    let held: Vec<&Spectrum> = held_s.iter().collect();
    let n_sur = opts.surrogates.max(2);
    let mut rng = StdRng::seed_from_u64(opts.seed);

    // Illumination.
    let fit_dates: Vec<usize> = fit.iter().map(|s| s.date).collect();
    let held_dates: Vec<usize> = held.iter().map(|s| s.date).collect();
    let declared = model
        .effects
        .iter()
        .any(|e| matches!(e, magic_core::effects::Effect::Illumination { .. }));
    let (ill, alpha) = illumination_score(&fit, &fit_dates, &held, &held_dates);
    let ill_chance: Vec<f64> = (0..n_sur)
        .map(|_| {
            let mut fd = fit_dates.clone();
            let mut hd = held_dates.clone();
            fd.shuffle(&mut rng);
            hd.shuffle(&mut rng);
            illumination_score(&fit, &fd, &held, &hd).0
        })
        .collect();
    let zeniths: Vec<f64> = date_days
        .iter()
        .map(|&d| zenith_at(d))
        .collect::<Result<_>>()?;
    let ill_params = json!({
        "site_lat_deg": crate::rtm_pipeline::S2_SITE[0],
        "site_lon_deg": crate::rtm_pipeline::S2_SITE[1],
        "utc_hours": crate::rtm_pipeline::S2_OVERPASS_UTC,
        "weight": alpha,
        "sun_zenith_deg": date_names.iter().zip(&zeniths).map(|(d, z)| (d.clone(), (z * 100.0).round() / 100.0)).collect::<BTreeMap<_, _>>(),
        "declared": declared,
    });
    let mut effects = vec![Candidate::from_scores(
        "illumination",
        ill,
        ill_chance,
        opts.quantile,
        ill_params,
        (!declared).then(s2_illumination),
    )];

    // Band offsets.
    let ones = vec![1.0; fit.len()];
    let (band, groups) = offset_score(&fit, None, &ones, &held, nb, 0);
    let band_chance: Vec<f64> = (0..n_sur)
        .map(|_| {
            let w: Vec<f64> = (0..fit.len())
                .map(|_| if rng.random::<bool>() { 1.0 } else { -1.0 })
                .collect();
            offset_score(&fit, None, &w, &held, nb, 0).0
        })
        .collect();
    let obs_scale: Vec<f32> = model.obs_scale.iter().collect();
    let offsets_refl: BTreeMap<String, f64> = groups
        .first()
        .and_then(|g| g.as_ref())
        .map(|b| {
            b.iter()
                .enumerate()
                .map(|(c, v)| {
                    (
                        data.columns.get(c).cloned().unwrap_or_default(),
                        (v * obs_scale[c] as f64 * 1e5).round() / 1e5,
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    let offset_declared = model
        .effects
        .iter()
        .any(|e| matches!(e, magic_core::effects::Effect::BandOffset { .. }));
    // The declared offset: the mean residual per band over the fitting spectra, in reflectance
    // (the projected fit above scores the family; its offset has components along F's Jacobian
    // that the encoder would have to undo).
    let offset_effect = (!offset_declared && !fit.is_empty()).then(|| OwnedEffect::BandOffset {
        offset: (0..nb)
            .map(|c| {
                let m = fit.iter().map(|s| s.raw[c]).sum::<f64>() / fit.len() as f64;
                (m * obs_scale[c] as f64) as f32
            })
            .collect(),
    });
    effects.push(Candidate::from_scores(
        "band_offset",
        band,
        band_chance,
        opts.quantile,
        json!({ "offset_reflectance": offsets_refl, "declared": offset_declared }),
        offset_effect,
    ));

    // Species.
    let labels: Vec<usize> = fit.iter().map(|s| s.species).collect();
    let ns = species_names.len();
    let (spec, sgroups) = offset_score(&fit, Some(&labels), &ones, &held, nb, ns);
    let spec_chance: Vec<f64> = (0..n_sur)
        .map(|_| {
            let mut l = labels.clone();
            l.shuffle(&mut rng);
            offset_score(&fit, Some(&l), &ones, &held, nb, ns).0
        })
        .collect();
    let norms: BTreeMap<String, f64> = species_names
        .iter()
        .zip(&sgroups)
        .filter_map(|(n, g)| {
            g.as_ref().map(|b| {
                let rms = (b.iter().map(|v| v * v).sum::<f64>() / nb as f64).sqrt();
                (n.clone(), (rms * 1e4).round() / 1e4)
            })
        })
        .collect();
    effects.push(Candidate::from_scores(
        "species",
        spec,
        spec_chance,
        opts.quantile,
        json!({ "rms_offset_std_units": norms }),
        None,
    ));
    effects.sort_by(|a, b| b.excess().total_cmp(&a.excess()));

    // Context: physics-only MSE, projected share, per-date mean residual.
    let mse = |s: &[Spectrum]| s.iter().map(|x| x.raw2).sum::<f64>() / (s.len() * nb).max(1) as f64;
    let proj2: f64 = held_s
        .iter()
        .map(|s| s.r.iter().map(|v| v * v).sum::<f64>())
        .sum();
    let raw2: f64 = held_s.iter().map(|s| s.raw2).sum();
    let mut date_band_mean = vec![vec![0.0; nb]; date_names.len()];
    let mut counts = vec![0usize; date_names.len()];
    for s in &held_s {
        counts[s.date] += 1;
        for (c, v) in s.r.iter().enumerate() {
            date_band_mean[s.date][c] += v;
        }
    }
    for (m, &n) in date_band_mean.iter_mut().zip(&counts) {
        m.iter_mut().for_each(|v| *v /= n.max(1) as f64);
    }
    Ok(RtmAnalysis {
        effects,
        splits: [opts.fit_split.clone(), opts.split.clone()],
        n: [fit_s.len(), held_s.len()],
        physics_mse: [mse(&fit_s), mse(&held_s)],
        projected_share: if raw2 > 0.0 { proj2 / raw2 } else { 0.0 },
        dates: date_names.into_iter().zip(zeniths).collect(),
        date_band_mean,
        bands: data.columns.clone(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// `effects.png` (explained vs chance per family) and `residual_by_date.png` (held-out residual
/// per acquisition date: RMS over bands of the date's mean projected residual, with the sun
/// zenith at the overpass).
pub fn write_plots(a: &RtmAnalysis, dir: &std::path::Path) -> Result<()> {
    use anyhow::Context as _;
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    effects_chart(
        &dir.join("effects.png"),
        &format!(
            "Projected residual explained on {}, % (tick: chance, *: significant)",
            a.splits[1]
        ),
        &a.effects,
    )?;
    let days: Vec<f64> = a
        .dates
        .iter()
        .map(|(d, _)| crate::data::gnss::day_number(d))
        .collect();
    let rms: Vec<f64> = a
        .date_band_mean
        .iter()
        .map(|m| (m.iter().map(|v| v * v).sum::<f64>() / m.len().max(1) as f64).sqrt())
        .collect();
    let zen: Vec<f64> = a.dates.iter().map(|(_, z)| z / 100.0).collect();
    crate::plots::time_series(
        &dir.join("residual_by_date.png"),
        "Mean residual per acquisition date (RMS over bands, standardised) and sun zenith / 100°",
        &days,
        &[("residual", &rms), ("sun zenith / 100°", &zen)],
    )?;
    Ok(())
}
