//! `step`: an offset at one station from one epoch on (an antenna change, an earthquake, a
//! disturbed monument). Fitted: declared, the offset (mm, E N U) enters F from its epoch on.

use super::dated::{self, Scored, TimeFit};
use super::latent::round3;
use crate::analysis::projection::{deproject, projected_response};
use crate::analysis::Family;
use crate::gnss::residuals::Block;
use crate::gnss::GnssResiduals;
use crate::model::OwnedEffect;
use crate::numerics::Ar1White;
use anyhow::Result;
use rand::rngs::StdRng;
use rayon::prelude::*;
use serde_json::json;

/// The step scan's margin: no epoch within this many rows of either end of the analysed record
/// (a step is told from the noise by days on both of its sides).
pub const STEP_SCAN_DAYS: usize = 30;

/// The step family.
pub struct Step;

/// A step at one station.
pub struct StepFit {
    /// Station index.
    pub station: usize,
    /// First day with the offset.
    pub epoch: f64,
    /// Offsets (standardised units) of the station's channels, E N U, de-projected.
    pub offset: Vec<f64>,
    /// Projected response of the step on every channel.
    response: Vec<f64>,
    /// Share of the fitted rows on or after the epoch (the step has zero mean over them).
    frac_after: f64,
    /// The scan statistic of the chosen station and epoch.
    pub stat: f64,
}

impl TimeFit for StepFit {
    fn predict(&self, c: usize, d: f64) -> f64 {
        self.response[c] * (if d >= self.epoch { 1.0 } else { 0.0 } - self.frac_after)
    }
    fn active(&self, c: usize) -> bool {
        self.response[c] != 0.0
    }
}

/// The step scan: for every station and epoch, the sum over the station's channels of the
/// squared GLS z statistic of a step in white + AR(1) noise, each channel's noise fitted to its
/// own series ([`Ar1White`]); the largest wins (epochs at least [`STEP_SCAN_DAYS`] rows from
/// either end). The offset is the GLS jump at that epoch in each channel, fitted with its
/// noise ([`Ar1White::step_jump`]): the difference of the means after and before it would add
/// the slow noise's levels, which held-out blocks share with their neighbours, to real and
/// surrogate steps alike.
pub fn fit_block(b: &Block, nc: usize, ns: usize, tangent: &[Vec<f64>]) -> StepFit {
    let t_n = b.days.len();
    let w = STEP_SCAN_DAYS.min(t_n / 4).max(1);
    let nk = nc / ns;
    let best = (0..ns)
        .into_par_iter()
        .map(|i| {
            let mut s = vec![0.0; t_n];
            for k in 0..nk {
                let x = b.channel(k * ns + i, nc);
                let z = Ar1White::fit(&x, &b.days).step_z(&x, &b.days);
                for (s, z) in s.iter_mut().zip(z) {
                    *s += z * z;
                }
            }
            let mut bi = (t_n / 2, f64::MIN);
            for (e, &v) in s.iter().enumerate().take(t_n.saturating_sub(w) + 1).skip(w) {
                if v > bi.1 {
                    bi = (e, v);
                }
            }
            (i, bi.0, bi.1)
        })
        .max_by(|a, b| a.2.total_cmp(&b.2))
        .unwrap_or((0, t_n / 2, 0.0));
    let (station, e, stat) = best;
    let chans: Vec<usize> = (0..nk).map(|k| k * ns + station).collect();
    let d: Vec<f64> = chans
        .iter()
        .map(|&c| {
            let x = b.channel(c, nc);
            Ar1White::step_jump(&x, &b.days, e)
        })
        .collect();
    let offset = deproject(tangent, &chans, &d);
    let response = projected_response(tangent, nc, &chans, &offset);
    let frac_after = (t_n - e) as f64 / t_n.max(1) as f64;
    StepFit {
        station,
        epoch: b.days.get(e).copied().unwrap_or(f64::NAN),
        offset,
        response,
        frac_after,
        stat,
    }
}

impl Family<GnssResiduals> for Step {
    type Fit = Scored<StepFit>;

    fn name(&self) -> &'static str {
        "step"
    }
    fn fit(&self, res: &GnssResiduals) -> Result<Self::Fit> {
        let (nc, ns, tangent) = (res.nc(), res.ns(), &res.ctx.tangent);
        Ok(dated::fit_scored(res, &|b| fit_block(b, nc, ns, tangent)))
    }
    fn score(&self, fit: &Self::Fit) -> f64 {
        fit.score
    }
    fn surrogate(
        &self,
        res: &GnssResiduals,
        fit: &Self::Fit,
        rng: &mut StdRng,
    ) -> Result<GnssResiduals> {
        Ok(dated::surrogate(res, &fit.fit, rng))
    }
    /// Station, epoch, offset (mm, E N U) and the scan statistic.
    /// The scan statistic: a step's jump, weighed as the noise says, must stand out of the
    /// noise's.
    fn statistic(&self, fit: &Self::Fit) -> Option<f64> {
        Some(fit.fit.stat)
    }
    fn params(&self, res: &GnssResiduals, fit: &Self::Fit) -> serde_json::Value {
        let (ns, f) = (res.ns(), &fit.fit);
        json!({
            "station": res.ctx.network.names[f.station],
            "epoch": super::iso_date(f.epoch),
            "offset_mm": (0..3).map(|k| round3(f.offset[k] * res.ctx.scale[k * ns + f.station])).collect::<Vec<_>>(),
            "scan_statistic": round3(f.stat),
        })
    }
    fn key_params(&self, res: &GnssResiduals, fit: &Self::Fit) -> Vec<(&'static str, f64)> {
        let (ns, f) = (res.ns(), &fit.fit);
        let mm = |k: usize| f.offset[k] * res.ctx.scale[k * ns + f.station];
        vec![
            ("epoch_day", f.epoch),
            ("offset_e_mm", mm(0)),
            ("offset_n_mm", mm(1)),
            ("offset_u_mm", mm(2)),
        ]
    }
    fn resample(
        &self,
        res: &GnssResiduals,
        fit: &Self::Fit,
        rng: &mut StdRng,
    ) -> Option<Result<GnssResiduals>> {
        Some(Ok(dated::resample(res, &fit.fit, rng)))
    }
    fn declare(&self, res: &GnssResiduals, fit: &Self::Fit) -> Option<OwnedEffect> {
        let (ns, f) = (res.ns(), &fit.fit);
        f.epoch.is_finite().then(|| OwnedEffect::Step {
            station: f.station as u16,
            epoch_day: f.epoch as f32,
            offset_mm: core::array::from_fn(|k| {
                (f.offset[k] * res.ctx.scale[k * ns + f.station]) as f32
            }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn step_scan_finds_a_step_in_noise() {
        let (ns, nc, t_n) = (4usize, 12usize, 600usize);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut r: Vec<f64> = (0..t_n * nc).map(|_| rng.random_range(-1.0..1.0)).collect();
        for t in 250..t_n {
            for k in 0..3 {
                r[t * nc + k * ns + 2] += [1.5, -1.0, 2.0][k];
            }
        }
        let b = Block {
            days: (0..t_n).map(|t| 14_000.0 + t as f64).collect(),
            r,
        };
        let f = fit_block(&b, nc, ns, &[]);
        assert_eq!(f.station, 2);
        assert_eq!(f.epoch, 14_250.0);
        for (o, want) in f.offset.iter().zip([1.5, -1.0, 2.0]) {
            assert!((o - want).abs() < 0.15, "{o} vs {want}");
        }
    }
}
