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
    /// The projected fit's offset per band (reflectance), named `offset_<band>`.
    fn key_params(&self, res: &SpectraResiduals, fit: &OffsetFit) -> Vec<(&'static str, f64)> {
        let Some(off) = &fit.offset else {
            return vec![];
        };
        off.iter()
            .zip(&res.ctx.bands)
            .zip(&res.ctx.scale)
            .filter_map(|((v, band), sc)| offset_key(band).map(|k| (k, v * sc)))
            .collect()
    }
    /// Bootstrap over the fitting spectra ([`SpectraResiduals::resample_fit`]).
    fn resample(
        &self,
        res: &SpectraResiduals,
        _: &OffsetFit,
        rng: &mut StdRng,
    ) -> Option<Result<SpectraResiduals>> {
        Some(Ok(res.resample_fit(rng)))
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

/// The key of the offset of the band of column `band` (`B05` or `B05_RE1`: `offset_B05`), for
/// the Sentinel-2 bands.
fn offset_key(band: &str) -> Option<&'static str> {
    let band = band.split('_').next().unwrap_or(band);
    const KEYS: [&str; 13] = [
        "offset_B01",
        "offset_B02",
        "offset_B03",
        "offset_B04",
        "offset_B05",
        "offset_B06",
        "offset_B07",
        "offset_B08",
        "offset_B8A",
        "offset_B09",
        "offset_B10",
        "offset_B11",
        "offset_B12",
    ];
    magic_core::rtm::S2_BANDS
        .iter()
        .position(|b| *b == band)
        .map(|i| KEYS[i])
}

#[cfg(test)]
mod tests {
    #[test]
    fn offset_keys_name_the_band() {
        assert_eq!(super::offset_key("B05_RE1"), Some("offset_B05"));
        assert_eq!(super::offset_key("B8A"), Some("offset_B8A"));
        assert_eq!(super::offset_key("NDVI"), None);
    }
}
