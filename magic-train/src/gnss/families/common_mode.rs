//! `common_mode`: a daily translation of the whole network (E, N, U), the same at every station —
//! reference-frame and atmospheric-loading errors shared by a small network. Latent: declared, it
//! adds three variables the encoder infers every day.

use super::latent::{self, round3, LatentFit};
use crate::analysis::Family;
use crate::gnss::residuals::translation;
use crate::gnss::GnssResiduals;
use crate::model::OwnedEffect;
use anyhow::Result;
use rand::rngs::StdRng;
use serde_json::json;

/// The network translation family.
pub struct CommonMode;

/// Common-mode patterns: one per component, 1 mm on every station of it (standardised units,
/// projected off F's Jacobian like every latent pattern).
pub fn patterns(res: &GnssResiduals) -> Vec<Vec<f64>> {
    let (ns, nc) = (res.ns(), res.nc());
    (0..nc / ns)
        .map(|k| res.project(&translation(&res.ctx.scale, ns, k)))
        .collect()
}

/// The RMS (mm) of the persistent part of each component's daily network mean that the stations
/// share: less what each station's own persistent noise puts into the mean
/// ([`latent::persistent_noise`]).
fn rms_mm(res: &GnssResiduals) -> Vec<f64> {
    let (r, nc) = (&res.fit.r, res.nc());
    patterns(res)
        .iter()
        .map(|g| {
            // g is 1/scale on the component: the amplitude is the weighted network mean in mm.
            let a = latent::daily_amplitude(r, nc, g);
            let shared = latent::persistent_var(&a) - latent::persistent_noise(r, nc, g, &a);
            shared.max(0.0).sqrt()
        })
        .collect()
}

impl Family<GnssResiduals> for CommonMode {
    type Fit = LatentFit;

    fn name(&self) -> &'static str {
        "common_mode"
    }
    fn fit(&self, res: &GnssResiduals) -> Result<LatentFit> {
        Ok(latent::best_window(res, &patterns(res)))
    }
    fn score(&self, fit: &LatentFit) -> f64 {
        fit.score
    }
    fn surrogate(
        &self,
        res: &GnssResiduals,
        _: &LatentFit,
        rng: &mut StdRng,
    ) -> Result<GnssResiduals> {
        Ok(latent::surrogate(res, &patterns(res), rng))
    }
    /// The RMS (mm) of the persistent part of each component's daily network mean that the
    /// stations share.
    fn params(&self, res: &GnssResiduals, fit: &LatentFit) -> serde_json::Value {
        let rms: Vec<f64> = rms_mm(res).iter().map(|v| round3(*v)).collect();
        json!({"rms_mm": rms, "neighbour_days": fit.window})
    }
    fn declare(&self, res: &GnssResiduals, _: &LatentFit) -> Option<OwnedEffect> {
        (!latent::declared(&patterns(res))).then_some(OwnedEffect::CommonMode)
    }
    fn key_params(&self, res: &GnssResiduals, _: &LatentFit) -> Vec<(&'static str, f64)> {
        let rms = rms_mm(res);
        vec![
            ("rms_e_mm", rms[0]),
            ("rms_n_mm", rms[1]),
            ("rms_u_mm", rms[2]),
        ]
    }
    fn resample(
        &self,
        res: &GnssResiduals,
        _: &LatentFit,
        rng: &mut StdRng,
    ) -> Option<Result<GnssResiduals>> {
        Some(Ok(latent::resample(res, &patterns(res), rng)))
    }
}
