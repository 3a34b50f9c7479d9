//! `species`: one constant per band and species — structure the forest model does not have per
//! species (leaf angles, crown shape, understory). Chance: species labels permuted among the
//! fitting spectra (what is left is the band offset shared by all species). Reported, not added:
//! the species is not an input of the inversion.

use super::offsets::{held_share, offset};
use crate::analysis::Family;
use crate::model::OwnedEffect;
use crate::rtm::residuals::{SpectraResiduals, Spectrum};
use anyhow::Result;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use serde_json::json;
use std::collections::BTreeMap;

/// The species family.
pub struct Species;

/// Per-species offsets (standardised units) and their held-out score.
pub struct SpeciesFit {
    /// Offset per species (none for a species with too few spectra).
    pub offsets: Vec<Option<Vec<f64>>>,
    /// Share of the held-out projected residual variance explained.
    pub score: f64,
}

impl Family<SpectraResiduals> for Species {
    type Fit = SpeciesFit;

    fn name(&self) -> &'static str {
        "species"
    }
    fn fit(&self, res: &SpectraResiduals) -> Result<SpeciesFit> {
        let (ctx, nb) = (&res.ctx, res.nb());
        let offsets: Vec<Option<Vec<f64>>> = (0..ctx.species.len())
            .map(|k| {
                let (ss, ws): (Vec<&Spectrum>, Vec<f64>) = ctx
                    .fit
                    .iter()
                    .zip(&res.fit_species)
                    .zip(&res.fit_signs)
                    .filter(|((_, &l), _)| l == k)
                    .map(|((s, _), &w)| (s, w))
                    .unzip();
                // Too few spectra for 11 constants: no offset for that species.
                if ss.len() < 4 * nb {
                    None
                } else {
                    offset(&ss, &ws, nb)
                }
            })
            .collect();
        let score = held_share(&ctx.held, nb, &|i| {
            offsets.get(ctx.held[i].species).and_then(|o| o.as_deref())
        });
        Ok(SpeciesFit { offsets, score })
    }
    fn score(&self, fit: &SpeciesFit) -> f64 {
        fit.score
    }
    fn surrogate(
        &self,
        res: &SpectraResiduals,
        _: &SpeciesFit,
        rng: &mut StdRng,
    ) -> Result<SpectraResiduals> {
        let mut s = res.clone();
        s.fit_species.shuffle(rng);
        Ok(s)
    }
    /// The RMS offset per species (standardised units).
    fn params(&self, res: &SpectraResiduals, fit: &SpeciesFit) -> serde_json::Value {
        let nb = res.nb();
        let norms: BTreeMap<String, f64> = res
            .ctx
            .species
            .iter()
            .zip(&fit.offsets)
            .filter_map(|(n, g)| {
                g.as_ref().map(|b| {
                    let rms = (b.iter().map(|v| v * v).sum::<f64>() / nb as f64).sqrt();
                    (n.clone(), (rms * 1e4).round() / 1e4)
                })
            })
            .collect();
        json!({ "rms_offset_std_units": norms })
    }
    fn declare(&self, _: &SpectraResiduals, _: &SpeciesFit) -> Option<OwnedEffect> {
        None
    }
}
