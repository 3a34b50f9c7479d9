//! One pixel of a map: the columns of `magic invert` and the standard deviations.
//!
//! With the residual (`--residual`) a pixel is exactly `magic invert`'s row: [`invert_at`] (the
//! encoder, INFORM, the correction C, the residual and the flags); `--sd` adds the standard
//! deviations of [`magic_core::uncertainty`] (INFORM's Jacobian in [`SD_PRECISION`]), scaled by
//! the calibration factors. Without either only the encoder runs: the variables and the flags
//! `AT_BOUND` and `MISSING`; the residual and the standard deviations are NaN. A pixel with
//! missing bands then gets one encoder pass with the missing bands at their training mean, where
//! `invert` refines them with three more passes through INFORM. Costs per pixel on one thread
//! (`map_bench`): encoder 1.3 µs, `--residual` 42 µs, `--sd` 127 µs.

use crate::data::records::RTM_RESULT_NAMES;
use magic_core::invert::{model_encoder, Flags, Workspace};
use magic_core::model_file::{Model, Problem, Variant, MAX_OBS, MAX_PARAMS};
use magic_core::rtm::inform::crown_from_cover;
use magic_core::uncertainty::{standard_deviations, Precision, SdWorkspace};
use magic_core::{invert_at, Error};

/// Names of the map's bands for an RTM model of variant B or C: the variables, `residual_rms`,
/// `flags`, then `<variable>_sd` per variable.
pub fn band_names() -> Vec<String> {
    let mut v: Vec<String> = RTM_RESULT_NAMES.iter().map(|s| s.to_string()).collect();
    v.push("residual_rms".into());
    v.push("flags".into());
    v.extend(RTM_RESULT_NAMES.iter().map(|s| format!("{s}_sd")));
    v
}

/// Number of variables (learned and derived) of a map.
pub const N_VARIABLES: usize = RTM_RESULT_NAMES.len();

/// Number of bands of a map.
pub const N_OUT: usize = 2 * N_VARIABLES + 2;

/// What happened to a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// No band observed (or masked): every output NaN.
    NoData,
    /// The inversion failed (every output NaN), e.g. a value beyond the accepted range.
    Failed,
    /// Inverted; the standard deviations failed (NaN) when `false`.
    Inverted {
        /// Whether the standard deviations were computed.
        sd: bool,
    },
}

/// The precision of INFORM's Jacobian for a map's standard deviations (and their calibration):
/// `f32`, half the time of `f64`, standard deviations within 1e-4 of `f64`'s (relative;
/// measured 6.9e-5 on the test split by `map_bench`'s `bench_pixel_parts`).
pub const SD_PRECISION: Precision = Precision::F32;

/// Per-thread working memory.
pub struct Scratch {
    ws: Workspace,
    sw: SdWorkspace,
}

impl Default for Scratch {
    /// INFORM's Jacobian in [`SD_PRECISION`].
    fn default() -> Self {
        Scratch {
            ws: Workspace::default(),
            sw: SdWorkspace::with_precision(SD_PRECISION),
        }
    }
}

/// How pixels are computed.
#[derive(Clone, Debug)]
pub struct PixelConfig {
    /// Run INFORM and C: residual and flags.
    pub residual: bool,
    /// Also the standard deviations (needs `residual`).
    pub sd: bool,
    /// Acquisition day (days since 1970-01-01; NaN when unknown).
    pub t_day: f64,
    /// Calibration factor per variable for the standard deviations (1 = raw).
    pub sd_factors: Vec<f64>,
}

/// Computes one pixel: `obs` the model's bands (reflectance, NaN = missing), `out` the
/// [`N_OUT`] bands of the map.
pub fn pixel(
    model: &Model<'_>,
    obs: &[f32],
    cfg: &PixelConfig,
    s: &mut Scratch,
    out: &mut [f32],
) -> Outcome {
    out.fill(f32::NAN);
    if obs.iter().all(|x| x.is_nan()) {
        return Outcome::NoData;
    }
    if cfg.residual {
        let Ok(inv) = invert_at::<f64>(model, obs, cfg.t_day, &mut s.ws) else {
            return Outcome::Failed;
        };
        let n = inv.n_params.min(N_VARIABLES);
        for (o, p) in out.iter_mut().zip(&inv.params[..n]) {
            *o = *p as f32;
        }
        out[N_VARIABLES] = inv.residual_rms as f32;
        out[N_VARIABLES + 1] = inv.flags.0 as f32;
        if !cfg.sd {
            return Outcome::Inverted { sd: false };
        }
        match standard_deviations(model, obs, &inv, cfg.t_day, &mut s.sw) {
            Ok(u) => {
                let u = u.scaled(&cfg.sd_factors);
                for (o, sd) in out[N_VARIABLES + 2..].iter_mut().zip(&u.sd[..n]) {
                    *o = *sd as f32;
                }
                Outcome::Inverted { sd: true }
            }
            Err(_) => Outcome::Inverted { sd: false },
        }
    } else {
        match encode(model, obs, &mut s.ws, out) {
            Ok(()) => Outcome::Inverted { sd: false },
            Err(_) => {
                out.fill(f32::NAN);
                Outcome::Failed
            }
        }
    }
}

/// The encoder alone: variables and the flags `AT_BOUND` and `MISSING` into `out`, with the
/// checks of [`invert_at`] on the observations.
fn encode(
    model: &Model<'_>,
    obs: &[f32],
    ws: &mut Workspace,
    out: &mut [f32],
) -> Result<(), Error> {
    let n_obs = model.n_obs();
    let p = model.n_params();
    if obs.len() != n_obs || n_obs > MAX_OBS || p > MAX_PARAMS || model.bounds.len() < p {
        return Err(Error::SizeMismatch {
            what: "observations",
            expected: n_obs,
            found: obs.len(),
        });
    }
    let mut z = [0f32; MAX_OBS];
    let mut observed = 0;
    for (i, (&x, zi)) in obs.iter().zip(z.iter_mut()).enumerate() {
        if x.is_nan() {
            continue;
        }
        if x.abs() > magic_core::invert::MAX_ABS_OBS as f32 {
            return Err(Error::OutOfRange {
                what: "observation magnitude",
            });
        }
        *zi = (x - model.obs_mean.get(i)) / model.obs_scale.get(i);
        observed += 1;
    }
    if observed < p.max(1) {
        return Err(Error::TooFewObservations {
            observed,
            needed: p.max(1),
        });
    }
    let mut unit = [0f32; MAX_PARAMS];
    model_encoder(model, &z[..n_obs], &mut unit[..p], ws)?;
    let mut flags = 0u8;
    if observed < n_obs {
        flags |= Flags::MISSING;
    }
    let mut params = [0f64; MAX_PARAMS];
    for (k, (v, &u)) in params.iter_mut().zip(&unit[..p]).enumerate() {
        let [lo, hi] = model.bounds[k];
        #[allow(clippy::manual_range_contains)]
        if u < 1e-3 || u > 1.0 - 1e-3 {
            flags |= Flags::AT_BOUND;
        }
        *v = lo as f64 + (hi - lo) as f64 * u as f64;
    }
    if let Problem::Rtm { fixed, .. } = &model.problem {
        if p + 2 <= MAX_PARAMS && p >= 1 {
            let (cd, h) = crown_from_cover(params[p - 1], fixed.sd);
            params[p] = cd;
            params[p + 1] = h;
        }
    }
    for (o, v) in out.iter_mut().zip(&params[..(p + 2).min(N_VARIABLES)]) {
        *o = *v as f32;
    }
    out[N_VARIABLES + 1] = flags as f32;
    Ok(())
}

/// Checks that `model` can make a map: an RTM model of variant B or C with the 7 learned
/// variables.
pub fn check_model(model: &Model<'_>) -> anyhow::Result<()> {
    match (&model.problem, model.variant) {
        (Problem::Rtm { .. }, Variant::B | Variant::C) if model.n_params() + 2 == N_VARIABLES => {
            Ok(())
        }
        (Problem::Rtm { .. }, v) => anyhow::bail!(
            "a map needs an RTM model of variant B or C (7 variables); this one is variant {v:?} with {} outputs",
            model.n_params()
        ),
        (p, _) => anyhow::bail!(
            "a map needs a forest (RTM) model; this one is a {} model",
            p.name()
        ),
    }
}
