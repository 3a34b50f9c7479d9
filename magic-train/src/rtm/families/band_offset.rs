//! `band_offset`: one constant reflectance per band — a bias of the band model, the sensor or
//! the atmospheric correction. Scored in the projected space; chance: a random sign per fitting
//! spectrum. Declarable as `magic_core::effects::Effect::BandOffset` with the mean residual per
//! band of the fitting spectra (reflectance): the projected fit scores the family, but as an
//! offset it has components along F's Jacobian that the encoder would have to undo.

use super::offsets::{held_share, offset};
use crate::analysis::Family;
use crate::model::OwnedEffect;
use crate::rtm::residuals::{SpectraResiduals, Spectrum};
use anyhow::Result;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;
use std::collections::BTreeMap;

/// The band-offset family.
pub struct BandOffset;

/// The fitted offsets (standardised units) and their held-out score.
pub struct OffsetFit {
    /// Offset per band, if any could be fitted.
    pub offset: Option<Vec<f64>>,
    /// Share of the held-out projected residual variance explained.
    pub score: f64,
}

impl Family<SpectraResiduals> for BandOffset {
    type Fit = OffsetFit;

    fn name(&self) -> &'static str {
        "band_offset"
    }
    fn fit(&self, res: &SpectraResiduals) -> Result<OffsetFit> {
        let nb = res.nb();
        let fit: Vec<&Spectrum> = res.ctx.fit.iter().collect();
        let offset = offset(&fit, &res.fit_signs, nb);
        let score = held_share(&res.ctx.held, nb, &|_| offset.as_deref());
        Ok(OffsetFit { offset, score })
    }
    fn score(&self, fit: &OffsetFit) -> f64 {
        fit.score
    }
    fn surrogate(
        &self,
        res: &SpectraResiduals,
        _: &OffsetFit,
        rng: &mut StdRng,
    ) -> Result<SpectraResiduals> {
        let mut s = res.clone();
        for w in s.fit_signs.iter_mut() {
            *w = if rng.random::<bool>() { 1.0 } else { -1.0 };
        }
        Ok(s)
    }
    /// The projected fit's offset per band (reflectance).
    fn params(&self, res: &SpectraResiduals, fit: &OffsetFit) -> serde_json::Value {
        let refl: BTreeMap<String, f64> = fit
            .offset
            .iter()
            .flat_map(|b| {
                b.iter().enumerate().map(|(c, v)| {
                    (
                        res.ctx.bands.get(c).cloned().unwrap_or_default(),
                        (v * res.ctx.scale[c] * 1e5).round() / 1e5,
                    )
                })
            })
            .collect();
        json!({ "offset_reflectance": refl, "declared": res.declares(self.name()) })
    }
    fn declare(&self, res: &SpectraResiduals, _: &OffsetFit) -> Option<OwnedEffect> {
        let fit = &res.ctx.fit;
        (!res.declares(self.name()) && !fit.is_empty()).then(|| OwnedEffect::BandOffset {
            offset: (0..res.nb())
                .map(|c| {
                    let m = fit.iter().map(|s| s.raw[c]).sum::<f64>() / fit.len() as f64;
                    (m * res.ctx.scale[c]) as f32
                })
                .collect(),
        })
    }
}
