//! Calibrating the standard deviations on synthetic spectra with known variables.
//!
//! The local curvature ([`magic_core::uncertainty`]) sees the noise the residual shows, not the
//! bias of the amortised encoder. To give standard deviations that mean what they say, the map
//! scales them by one factor per variable, measured on synthetic spectra: variables drawn
//! uniformly within the model's bounds, spectra from the model's own reconstruction (F, then the
//! correction C for variant C, with the model's declared effects), plus Gaussian noise
//! ([`Noise`]); each spectrum is inverted and its raw standard deviations computed; the factor of
//! a variable is the 68.27 % quantile of |estimate − truth| / sd, so that about 68 % of the true
//! values fall within ±1 calibrated sd on such spectra. [`coverage`] measures the shares within
//! ±1 and ±2 sd on other spectra (another seed).
//!
//! What this cannot see: spectra unlike the model's reconstructions (real forest spectra are
//! fitted by INFORM with a residual far above sensor noise), variables distributed otherwise than
//! uniformly in the bounds.

use super::pixel::N_VARIABLES;
use crate::numerics::{quantile, ONE_SIGMA};
use anyhow::{bail, Result};
use magic_core::invert::{forward, model_correction, Workspace};
use magic_core::invert_at;
use magic_core::model_file::{Model, Problem, Variant};
use magic_core::rtm::inform::crown_from_cover;
use magic_core::uncertainty::{standard_deviations, SdWorkspace};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Sensor noise added to synthetic spectra: σ = √((relative·ρ)² + absolute²) per band.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// Relative part (of the reflectance).
    pub relative: f64,
    /// Absolute part (reflectance).
    pub absolute: f64,
}

/// The noise assumed for Sentinel-2 L2A surface reflectance: 3 % of the value (the mission's
/// radiometric uncertainty requirement is 5 %, measured in flight at about 2–3 %) and 0.003
/// absolute (atmospheric correction over dark vegetation).
pub const S2_NOISE: Noise = Noise {
    relative: 0.03,
    absolute: 0.003,
};

/// Spectra the map calibrates on.
pub const CALIBRATION_SPECTRA: usize = 2000;

/// Seed of the map's calibration spectra (the figures of the README use other seeds).
pub const CALIBRATION_SEED: u64 = 0x5D_CA11B;

/// A synthetic spectrum with its true variables (learned, then derived).
pub struct Synthetic {
    /// True variables (7 learned, then crown diameter and height).
    pub truth: [f64; N_VARIABLES],
    /// Noisy spectrum (reflectance).
    pub obs: Vec<f32>,
}

/// The model's reconstruction at physical variables `z` (F, then C for variant C), physical
/// units.
pub fn reconstruct(
    model: &Model<'_>,
    z: &[f64],
    t_day: f64,
    ws: &mut Workspace,
) -> Result<Vec<f64>> {
    let n = model.n_obs();
    let mut y = vec![0.0; n];
    forward(model, z, t_day, &mut y).map_err(|e| anyhow::anyhow!("forward model: {e}"))?;
    if model.variant == Variant::C {
        let mut recon = vec![0.0; n];
        model_correction(model, &y, t_day, &mut recon, ws)
            .map_err(|e| anyhow::anyhow!("correction: {e}"))?;
        return Ok(recon);
    }
    Ok(y)
}

/// `n` synthetic spectra from `seed` (see the module documentation).
pub fn simulate(
    model: &Model<'_>,
    n: usize,
    seed: u64,
    noise: Noise,
    t_day: f64,
) -> Result<Vec<Synthetic>> {
    let Problem::Rtm { fixed, .. } = &model.problem else {
        bail!("synthetic spectra need an RTM model");
    };
    let p = model.n_params();
    if p + 2 != N_VARIABLES || model.bounds.len() < p {
        bail!("synthetic spectra need the 7 variables of an RTM model of variant B or C");
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut ws = Workspace::default();
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let mut truth = [0.0; N_VARIABLES];
        for (t, [lo, hi]) in truth.iter_mut().zip(&model.bounds[..p]) {
            *t = *lo as f64 + (hi - lo) as f64 * rng.random::<f64>();
        }
        let (cd, h) = crown_from_cover(truth[p - 1], fixed.sd);
        truth[p] = cd;
        truth[p + 1] = h;
        let y = reconstruct(model, &truth[..p], t_day, &mut ws)?;
        let obs = y
            .iter()
            .map(|&r| {
                let sigma = ((noise.relative * r).powi(2) + noise.absolute.powi(2)).sqrt();
                (r + sigma * gaussian(&mut rng)) as f32
            })
            .collect();
        out.push(Synthetic { truth, obs });
    }
    Ok(out)
}

/// A standard normal deviate (Box–Muller).
fn gaussian(rng: &mut StdRng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Normalised errors (estimate − truth) / raw sd per variable, for the spectra that invert
/// with finite standard deviations.
pub fn normalised_errors(
    model: &Model<'_>,
    spectra: &[Synthetic],
    t_day: f64,
) -> Vec<[f64; N_VARIABLES]> {
    spectra
        .par_iter()
        .map_init(
            || {
                (
                    Workspace::default(),
                    SdWorkspace::with_precision(super::pixel::SD_PRECISION),
                )
            },
            |(ws, sw), s| {
                let inv = invert_at::<f64>(model, &s.obs, t_day, ws).ok()?;
                let u = standard_deviations(model, &s.obs, &inv, t_day, sw).ok()?;
                let mut e = [0.0; N_VARIABLES];
                for (k, ek) in e.iter_mut().enumerate() {
                    *ek = (inv.params[k] - s.truth[k]) / u.sd[k];
                }
                e.iter().all(|v| v.is_finite()).then_some(e)
            },
        )
        .flatten()
        .collect()
}

/// Share of true values within ±1 sd and ±2 sd, per variable, after scaling the sd by
/// `factors`.
pub fn coverage(errors: &[[f64; N_VARIABLES]], factors: &[f64]) -> Vec<(f64, f64)> {
    (0..N_VARIABLES)
        .map(|k| {
            let f = factors.get(k).copied().unwrap_or(1.0);
            let n = errors.len().max(1) as f64;
            let within = |m: f64| errors.iter().filter(|e| e[k].abs() <= m * f).count() as f64 / n;
            (within(1.0), within(2.0))
        })
        .collect()
}

/// The calibration factors: per variable, the [`ONE_SIGMA`] quantile of |normalised error|.
pub fn factors(errors: &[[f64; N_VARIABLES]]) -> Result<Vec<f64>> {
    if errors.len() < 100 {
        bail!(
            "only {} synthetic spectra inverted with finite standard deviations (at least 100 needed to calibrate)",
            errors.len()
        );
    }
    Ok((0..N_VARIABLES)
        .map(|k| {
            let a: Vec<f64> = errors.iter().map(|e| e[k].abs()).collect();
            quantile(&a, ONE_SIGMA)
        })
        .collect())
}

/// Factors for `model` from [`CALIBRATION_SPECTRA`] spectra of [`CALIBRATION_SEED`] with
/// [`S2_NOISE`].
pub fn calibrate(model: &Model<'_>, t_day: f64) -> Result<Vec<f64>> {
    let s = simulate(
        model,
        CALIBRATION_SPECTRA,
        CALIBRATION_SEED,
        S2_NOISE,
        t_day,
    )?;
    factors(&normalised_errors(model, &s, t_day))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_are_the_one_sigma_quantile_of_the_absolute_errors() {
        // |errors| 1..=100 (half of them negative) in every variable: the 68.27 % quantile,
        // interpolated between order statistics, is 1 + 0.682689492 · 99.
        let errors: Vec<[f64; N_VARIABLES]> = (1..=100)
            .map(|i| [if i % 2 == 0 { i as f64 } else { -(i as f64) }; N_VARIABLES])
            .collect();
        let f = factors(&errors).unwrap();
        assert_eq!(f.len(), N_VARIABLES);
        for v in f {
            assert!((v - (1.0 + ONE_SIGMA * 99.0)).abs() < 1e-12, "{v}");
        }
    }

    #[test]
    fn factors_refuse_fewer_than_a_hundred_spectra() {
        let err = factors(&[[1.0; N_VARIABLES]; 99]).unwrap_err().to_string();
        assert!(err.contains("only 99 synthetic spectra"), "{err}");
    }
}
