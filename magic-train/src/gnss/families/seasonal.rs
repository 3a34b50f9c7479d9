//! `seasonal`: per-station annual and semiannual terms (loading, monument thermal expansion,
//! multipath). Fitted: declared, its constants (4 per channel, mm) enter F as a function of the
//! date. Scored (and its surrogates drawn) on the projected residuals, what F cannot produce;
//! its amplitudes declared from the rows with the projection's part given back
//! ([`GnssResiduals::given_back`]), F's daily variables taken not to follow the calendar, and
//! reported whole, with the network's share a declared common mode holds
//! ([`GnssResiduals::given_back_whole`]).

use super::dated::{self, Scored, TimeFit};
use super::latent::round3;
use crate::analysis::Family;
use crate::gnss::residuals::Block;
use crate::gnss::GnssResiduals;
use crate::model::OwnedEffect;
use anyhow::Result;
use rand::rngs::StdRng;
use serde_json::json;

/// The seasonal family.
pub struct Seasonal;

const W_YEAR: f64 = std::f64::consts::TAU / 365.25;

fn basis(d: f64, b: &mut [f64]) {
    let w = W_YEAR * d;
    b[0] = 1.0;
    b[1] = w.sin();
    b[2] = w.cos();
    b[3] = (2.0 * w).sin();
    b[4] = (2.0 * w).cos();
}

/// Annual and semiannual coefficients per channel (standardised units).
pub struct SeasonalFit {
    coef: Vec<Vec<f64>>,
    /// Mean of each basis function over the fitted rows.
    mean_basis: [f64; 5],
}

impl TimeFit for SeasonalFit {
    fn predict(&self, c: usize, d: f64) -> f64 {
        let mut b = [0.0; 5];
        basis(d, &mut b);
        (1..5)
            .map(|j| self.coef[c][j] * (b[j] - self.mean_basis[j]))
            .sum()
    }
}

fn fit_block(b: &Block, nc: usize) -> SeasonalFit {
    let mut mean_basis = [0.0; 5];
    let mut v = [0.0; 5];
    for &d in &b.days {
        basis(d, &mut v);
        for j in 0..5 {
            mean_basis[j] += v[j] / b.days.len() as f64;
        }
    }
    SeasonalFit {
        coef: dated::fit_basis(&b.r, &b.days, nc, 5, &basis),
        mean_basis,
    }
}

/// The coefficients declared: fitted to the rows with the projection's part given back where
/// they are the data's own ([`GnssResiduals::given_back`]), else the fit's.
fn coefficients(res: &GnssResiduals, fit: &Scored<SeasonalFit>) -> Vec<Vec<f64>> {
    res.given_back()
        .map_or_else(|| fit.fit.coef.clone(), |b| fit_block(&b, res.nc()).coef)
}

/// The coefficients reported: each station's whole term, the network's share that a declared
/// common mode holds included ([`GnssResiduals::given_back_whole`]); else those declared.
fn reported(res: &GnssResiduals, fit: &Scored<SeasonalFit>) -> Vec<Vec<f64>> {
    res.given_back_whole()
        .map_or_else(|| coefficients(res, fit), |b| fit_block(&b, res.nc()).coef)
}

impl Family<GnssResiduals> for Seasonal {
    type Fit = Scored<SeasonalFit>;

    fn name(&self) -> &'static str {
        "seasonal"
    }
    fn fit(&self, res: &GnssResiduals) -> Result<Self::Fit> {
        let nc = res.nc();
        Ok(dated::fit_scored(res, &|b| fit_block(b, nc)))
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
    /// Annual and semiannual amplitudes per station and component (mm): each station's whole
    /// term ([`GnssResiduals::given_back_whole`]), of which F's term holds the part beside the
    /// network's share when F has a common mode.
    fn params(&self, res: &GnssResiduals, fit: &Self::Fit) -> serde_json::Value {
        let ns = res.ns();
        let coef = &reported(res, fit);
        let amp = |c: usize, j: usize| coef[c][j].hypot(coef[c][j + 1]) * res.ctx.scale[c];
        let per_station = |j: usize| {
            let mut m = serde_json::Map::new();
            for (i, n) in res.ctx.network.names.iter().enumerate() {
                let v: [f64; 3] = core::array::from_fn(|k| round3(amp(k * ns + i, j)));
                m.insert(n.clone(), json!(v));
            }
            serde_json::Value::Object(m)
        };
        json!({"annual_mm": per_station(1), "semiannual_mm": per_station(3)})
    }
    fn declare(&self, res: &GnssResiduals, fit: &Self::Fit) -> Option<OwnedEffect> {
        let coef = &coefficients(res, fit);
        Some(OwnedEffect::Seasonal {
            coef: (0..res.nc())
                .flat_map(|c| (1..5).map(move |j| (coef[c][j] * res.ctx.scale[c]) as f32))
                .collect(),
        })
    }
}
