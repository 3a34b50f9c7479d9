//! `drift`: a linear drift at one or a few stations (a monument settling, an unmodelled local
//! deformation) — stations whose rates are outliers among the network's. Fitted: declared, the
//! rates (mm/yr) enter F as a function of the date.

use super::dated::{self, Scored, TimeFit};
use super::latent::round3;
use crate::analysis::projection::{deproject, projected_response};
use crate::analysis::{Family, Rejection};
use crate::gnss::residuals::Block;
use crate::gnss::GnssResiduals;
use crate::model::OwnedEffect;
use crate::numerics::median;
use anyhow::Result;
use rand::rngs::StdRng;
use serde_json::json;

/// Sum over a station's components of its trends' squared robust z-scores needed to enter the
/// drift family (χ² with 3 degrees of freedom exceeds 20 with probability 2·10⁻⁴).
pub const DRIFT_Z2: f64 = 20.0;

/// The drift family.
pub struct Drift;

/// Drifting channels and their rates.
pub struct DriftFit {
    t0: f64,
    /// Selected channels and their rates (standardised units per year, de-projected).
    chans: Vec<usize>,
    rates: Vec<f64>,
    /// Projected response per year on every channel (what the residuals show).
    response: Vec<f64>,
}

impl TimeFit for DriftFit {
    fn predict(&self, c: usize, d: f64) -> f64 {
        self.response[c] * (d - self.t0) / 365.25
    }
    fn active(&self, c: usize) -> bool {
        self.response[c] != 0.0
    }
}

fn fit_block(b: &Block, scale: &[f64], ns: usize, tangent: &[Vec<f64>]) -> DriftFit {
    let nc = scale.len();
    let t0 = b.days.iter().sum::<f64>() / b.days.len().max(1) as f64;
    let coef: Vec<[f64; 2]> = dated::fit_basis(&b.r, &b.days, nc, 2, &|d, v: &mut [f64]| {
        v[0] = 1.0;
        v[1] = (d - t0) / 365.25;
    })
    .into_iter()
    .map(|x| [x[0], x[1]])
    .collect();
    // Stations whose rates (mm/yr) are outliers among the network's (robust z per component from
    // the median absolute deviation over stations, summed in squares over the components).
    let nk = nc / ns;
    let mut z2 = vec![0.0; ns];
    for k in 0..nk {
        let rates: Vec<f64> = (0..ns)
            .map(|i| coef[k * ns + i][1] * scale[k * ns + i])
            .collect();
        let med = median(&mut rates.clone());
        let mad = (1.4826 * median(&mut rates.iter().map(|v| (v - med).abs()).collect::<Vec<_>>()))
            .max(1e-12);
        for i in 0..ns {
            z2[i] += (rates[i] / mad).powi(2);
        }
    }
    let chans: Vec<usize> = (0..ns)
        .filter(|&i| z2[i] > DRIFT_Z2 && ramp_beats_step(b, nc, ns, i))
        .flat_map(|i| (0..nk).map(move |k| k * ns + i))
        .collect();
    let d: Vec<f64> = chans.iter().map(|&c| coef[c][1]).collect();
    let rates = deproject(tangent, &chans, &d);
    let response = if chans.is_empty() {
        vec![0.0; nc]
    } else {
        projected_response(tangent, nc, &chans, &rates)
    };
    DriftFit {
        t0,
        chans,
        rates,
        response,
    }
}

/// Whether station `i`'s channels are fitted better (least squares) by a straight line than by
/// the best single step: a step inside a record also has an outlying rate, and is the step
/// family's to explain, not the drift's.
fn ramp_beats_step(b: &Block, nc: usize, ns: usize, i: usize) -> bool {
    let t_n = b.days.len();
    if t_n < 4 {
        return false;
    }
    let chans: Vec<usize> = (0..nc / ns).map(|k| k * ns + i).collect();
    let x: Vec<Vec<f64>> = chans.iter().map(|&c| b.channel(c, nc)).collect();
    // Straight line per channel (least squares in the day number).
    let tm = b.days.iter().sum::<f64>() / t_n as f64;
    let stt: f64 = b.days.iter().map(|d| (d - tm).powi(2)).sum();
    let ss_ramp: f64 = x
        .iter()
        .map(|v| {
            let m = v.iter().sum::<f64>() / t_n as f64;
            let sxt: f64 = v.iter().zip(&b.days).map(|(a, d)| (a - m) * (d - tm)).sum();
            let sxx: f64 = v.iter().map(|a| (a - m).powi(2)).sum();
            sxx - if stt > 0.0 { sxt * sxt / stt } else { 0.0 }
        })
        .sum();
    // Best single step shared by the channels: two levels, before and after the epoch.
    let pre: Vec<Vec<f64>> = x
        .iter()
        .map(|v| {
            std::iter::once(0.0)
                .chain(v.iter().scan(0.0, |s, a| {
                    *s += a;
                    Some(*s)
                }))
                .collect()
        })
        .collect();
    let total: f64 = x.iter().flatten().map(|a| a * a).sum();
    let ss_step = (1..t_n)
        .map(|e| {
            let explained: f64 = pre
                .iter()
                .map(|p| p[e] * p[e] / e as f64 + (p[t_n] - p[e]).powi(2) / (t_n - e) as f64)
                .sum();
            total - explained
        })
        .fold(f64::INFINITY, f64::min);
    ss_ramp < ss_step
}

/// Drift rates (mm/yr) per channel, zero where no drift was selected.
fn mm_per_yr(res: &GnssResiduals, f: &DriftFit) -> Vec<f64> {
    let mut out = vec![0.0; res.nc()];
    for (c, r) in f.chans.iter().zip(&f.rates) {
        out[*c] = r * res.ctx.scale[*c];
    }
    out
}

impl Family<GnssResiduals> for Drift {
    type Fit = Scored<DriftFit>;

    fn name(&self) -> &'static str {
        "drift"
    }
    fn fit(&self, res: &GnssResiduals) -> Result<Self::Fit> {
        let (ns, ctx) = (res.ns(), &res.ctx);
        Ok(dated::fit_scored(res, &|b| {
            fit_block(b, &ctx.scale, ns, &ctx.tangent)
        }))
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
    /// Rates (mm/yr, E N U) of the drifting stations and the reference date.
    fn params(&self, res: &GnssResiduals, fit: &Self::Fit) -> serde_json::Value {
        let ns = res.ns();
        let f = &fit.fit;
        let rates = mm_per_yr(res, f);
        let mut m = serde_json::Map::new();
        for i in 0..ns {
            if f.chans.iter().any(|c| c % ns == i) {
                let r: [f64; 3] = core::array::from_fn(|k| round3(rates[k * ns + i]));
                m.insert(res.ctx.network.names[i].clone(), json!(r));
            }
        }
        json!({"rate_mm_per_yr": m, "t0": super::iso_date(f.t0)})
    }
    /// A fit that explains held-out days though its whole-record rates select no station: the
    /// held-out fits' drifts were local to their periods, and the effect F would take is zero.
    fn reject(&self, _res: &GnssResiduals, fit: &Self::Fit) -> Option<Rejection> {
        (fit.fit.chans.is_empty() && fit.score > 0.0).then_some(Rejection::NothingToAdd(
            "no station's rate stands out over the whole record",
        ))
    }
    fn declare(&self, res: &GnssResiduals, fit: &Self::Fit) -> Option<OwnedEffect> {
        Some(OwnedEffect::Drift {
            t0_day: fit.fit.t0 as f32,
            rate: mm_per_yr(res, &fit.fit).iter().map(|v| *v as f32).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Two stations × 3 components over 1 200 days of noise, with `f(t)` added to station 0.
    fn block(f: &dyn Fn(usize) -> f64) -> Block {
        stations(2, f)
    }

    /// `ns` stations × 3 components over 1 200 days of noise, with `f(t)` added to station 0.
    fn stations(ns: usize, f: &dyn Fn(usize) -> f64) -> Block {
        let (nc, t_n) = (3 * ns, 1200usize);
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut r: Vec<f64> = (0..t_n * nc).map(|_| rng.random_range(-0.5..0.5)).collect();
        for t in 0..t_n {
            for k in 0..3 {
                r[t * nc + k * ns] += f(t);
            }
        }
        Block {
            days: (0..t_n).map(|t| 14_000.0 + t as f64).collect(),
            r,
        }
    }

    #[test]
    fn a_step_is_not_a_drift_and_a_ramp_is() {
        let step = block(&|t| if t >= 500 { 2.0 } else { 0.0 });
        assert!(!ramp_beats_step(&step, 6, 2, 0));
        let ramp = block(&|t| 3.0 * t as f64 / 1200.0);
        assert!(ramp_beats_step(&ramp, 6, 2, 0));
    }

    #[test]
    fn a_record_without_an_outlying_rate_selects_no_station_and_adds_nothing() {
        let ns = 8;
        let fit = |b: &Block| fit_block(b, &vec![1.0; 3 * ns], ns, &[]);
        assert!(fit(&stations(ns, &|_| 0.0)).chans.is_empty());
        let ramp = fit(&stations(ns, &|t| 3.0 * t as f64 / 1200.0));
        assert_eq!(ramp.chans, [0, ns, 2 * ns]);
        assert!(
            ramp.rates.iter().all(|r| (r - 0.91).abs() < 0.1),
            "{:?}",
            ramp.rates
        );
    }
}
