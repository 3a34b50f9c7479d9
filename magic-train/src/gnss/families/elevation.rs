//! `elevation`: a daily vertical term linear in station elevation, `k(t)·(zᵢ − z̄)` — a
//! tropospheric delay the processing did not model. Latent: declared, it adds one variable (the
//! slope k, mm/km) the encoder infers every day.

use super::latent::{self, round3, LatentFit};
use crate::analysis::Family;
use crate::gnss::GnssResiduals;
use crate::model::OwnedEffect;
use anyhow::Result;
use rand::rngs::StdRng;
use serde_json::json;

/// The elevation family.
pub struct Elevation;

/// Elevation pattern: `zᵢ − z̄` mm per (mm/km) on the vertical channels (projected).
pub fn pattern(res: &GnssResiduals) -> Vec<f64> {
    let (ns, nc) = (res.ns(), res.nc());
    let net = &res.ctx.network;
    let z0 = net.mean_elevation();
    res.project(
        &(0..nc)
            .map(|c| {
                if c / ns == 2 {
                    (net.stations[c % ns].z_km - z0) / res.ctx.scale[c]
                } else {
                    0.0
                }
            })
            .collect::<Vec<_>>(),
    )
}

impl Family<GnssResiduals> for Elevation {
    type Fit = LatentFit;

    fn name(&self) -> &'static str {
        "elevation"
    }
    fn fit(&self, res: &GnssResiduals) -> Result<LatentFit> {
        Ok(latent::best_window(res, &[pattern(res)]))
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
        Ok(latent::surrogate(res, &[pattern(res)], rng))
    }
    /// RMS of the daily elevation slope k (mm/km): the daily least-squares amplitude of the
    /// (projected) elevation pattern, its variance less the part the channels' noise puts into
    /// it (each channel's variance about the fit, taken independent between channels).
    fn params(&self, res: &GnssResiduals, fit: &LatentFit) -> serde_json::Value {
        let nc = res.nc();
        let z_ref = res.ctx.network.mean_elevation();
        let g = pattern(res);
        let gg: f64 = g.iter().map(|v| v * v).sum();
        if gg < latent::DECLARED_NORM2 {
            return json!({"mm_per_km": 0.0, "z_ref_km": z_ref, "neighbour_days": fit.window});
        }
        let r = &res.fit.r;
        let a = latent::daily_amplitude(r, nc, &g);
        let t_n = a.len() as f64;
        let mut var_c = vec![0.0; nc];
        for (row, at) in r.chunks(nc).zip(&a) {
            for c in 0..nc {
                var_c[c] += (row[c] - at * g[c]).powi(2) / t_n;
            }
        }
        let noise: f64 = g.iter().zip(&var_c).map(|(x, v)| x * x * v).sum::<f64>() / (gg * gg);
        let s2 = a.iter().map(|v| v * v).sum::<f64>() / t_n;
        json!({"mm_per_km": round3((s2 - noise).max(0.0).sqrt()), "z_ref_km": z_ref, "neighbour_days": fit.window})
    }
    fn key_params(&self, res: &GnssResiduals, fit: &LatentFit) -> Vec<(&'static str, f64)> {
        let p = self.params(res, fit);
        vec![("mm_per_km", p["mm_per_km"].as_f64().unwrap_or(f64::NAN))]
    }
    fn resample(
        &self,
        res: &GnssResiduals,
        _: &LatentFit,
        rng: &mut StdRng,
    ) -> Option<Result<GnssResiduals>> {
        Some(Ok(latent::resample(res, &[pattern(res)], rng)))
    }
    fn declare(&self, res: &GnssResiduals, _: &LatentFit) -> Option<OwnedEffect> {
        (!latent::declared(&[pattern(res)])).then(|| OwnedEffect::Elevation {
            z_ref_km: res.ctx.network.mean_elevation() as f32,
        })
    }
}
