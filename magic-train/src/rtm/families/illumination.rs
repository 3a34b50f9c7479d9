//! `illumination`: the acquisition's true sun (zenith and relative azimuth from the date at the
//! site and overpass time) instead of the model's fixed one. Its pattern for a spectrum is F with
//! that date's sun less F with the model's sun, at the spectrum's variables, scaled by one weight
//! fitted on the fitting split; chance: dates permuted among the spectra of each split (any sun
//! but the right one; the part of the pattern shared by all dates stays in the chance level).
//! Declarable: it becomes `magic_core::effects::Effect::Illumination`; when the model declares
//! it already, the pattern is zero.

use super::super::residuals::{SpectraResiduals, Spectrum};
use crate::analysis::score::share;
use crate::analysis::Family;
use crate::model::OwnedEffect;
use anyhow::Result;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use serde_json::json;
use std::collections::BTreeMap;

/// The illumination family.
pub struct Illumination;

/// The fitted weight and its held-out score.
pub struct IlluminationFit {
    /// Weight of the pattern (1: the sun's effect as F computes it).
    pub weight: f64,
    /// Share of the held-out projected residual variance explained.
    pub score: f64,
}

fn weight(spectra: &[Spectrum], dates: &[usize]) -> Option<f64> {
    let (mut rg, mut gg) = (0.0, 0.0);
    for (s, &d) in spectra.iter().zip(dates) {
        for (a, b) in s.r.iter().zip(&s.g[d]) {
            rg += a * b;
            gg += b * b;
        }
    }
    (gg > 1e-18).then(|| rg / gg)
}

impl Family<SpectraResiduals> for Illumination {
    type Fit = IlluminationFit;

    fn name(&self) -> &'static str {
        "illumination"
    }
    fn fit(&self, res: &SpectraResiduals) -> Result<IlluminationFit> {
        let ctx = &res.ctx;
        let Some(alpha) = weight(&ctx.fit, &res.fit_dates) else {
            return Ok(IlluminationFit {
                weight: 0.0,
                score: 0.0,
            });
        };
        let r: Vec<&[f64]> = ctx.held.iter().map(|s| s.r.as_slice()).collect();
        let p: Vec<Vec<f64>> = ctx
            .held
            .iter()
            .zip(&res.held_dates)
            .map(|(s, &d)| s.g[d].iter().map(|v| alpha * v).collect())
            .collect();
        Ok(IlluminationFit {
            weight: alpha,
            score: share(&r, &p),
        })
    }
    fn score(&self, fit: &IlluminationFit) -> f64 {
        fit.score
    }
    fn surrogate(
        &self,
        res: &SpectraResiduals,
        _: &IlluminationFit,
        rng: &mut StdRng,
    ) -> Result<SpectraResiduals> {
        let mut s = res.clone();
        s.fit_dates.shuffle(rng);
        s.held_dates.shuffle(rng);
        Ok(s)
    }
    /// The site, the overpass time, the fitted weight and the sun zenith per date.
    fn params(&self, res: &SpectraResiduals, fit: &IlluminationFit) -> serde_json::Value {
        let ctx = &res.ctx;
        let zenith: BTreeMap<String, f64> = ctx
            .dates
            .iter()
            .filter_map(|(d, day)| {
                let sun = ctx.sun.borrow(&[]);
                magic_core::effects::rtm_fixed_at(&[sun], &Default::default(), *day)
                    .ok()
                    .map(|f| (d.clone(), (f.tts * 100.0).round() / 100.0))
            })
            .collect();
        let (lat, lon, utc) = match ctx.sun {
            OwnedEffect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                ..
            } => (lat_deg, lon_deg, utc_hours),
            _ => (f32::NAN, f32::NAN, f32::NAN),
        };
        json!({
            "site_lat_deg": lat, "site_lon_deg": lon, "utc_hours": utc,
            "weight": fit.weight,
            "sun_zenith_deg": zenith,
            "declared": res.declares(self.name()),
        })
    }
    /// The pattern's weight (1: the sun's effect as F computes it).
    fn key_params(&self, _: &SpectraResiduals, fit: &IlluminationFit) -> Vec<(&'static str, f64)> {
        vec![("weight", fit.weight)]
    }
    /// Bootstrap over the fitting spectra ([`SpectraResiduals::resample_fit`]).
    fn resample(
        &self,
        res: &SpectraResiduals,
        _: &IlluminationFit,
        rng: &mut StdRng,
    ) -> Option<Result<SpectraResiduals>> {
        Some(Ok(res.resample_fit(rng)))
    }
    fn declare(&self, res: &SpectraResiduals, _: &IlluminationFit) -> Option<OwnedEffect> {
        (!res.declares(self.name())).then(|| res.ctx.sun.clone())
    }
}
