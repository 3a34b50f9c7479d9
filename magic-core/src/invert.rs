//! Inversion: observations → physical variables, reconstruction, residual and quality flags.
//!
//! One path for every target: standardise the observations, run the encoder E, map its sigmoid
//! outputs into the variables' bounds, run the forward model F (generic over [`Real`]: `f32` on the
//! board, `f64` on the host), standardise F's output, run the correction C, and compare with the
//! observations. Missing channels (NaN) are allowed: they first enter the encoder as the training
//! mean (standardised 0), then [`IMPUTE_PASSES`] more passes refill them with the model's own
//! reconstruction; they are left out of the residual and reported in the flags and the station
//! mask.

use crate::effects::mogi_with_effects;
use crate::model_file::{Model, Problem, Variant, MAX_OBS, MAX_PARAMS};
use crate::nn::{run, Scratch};
use crate::rtm::inform::crown_from_cover;
use crate::rtm::N_LEARNED;
use crate::{Error, Real};

/// Derived variables an RTM inversion reports after the 7 learned ones: crown diameter `cd` (m)
/// and tree height `h` (m), paper eqs. 7–8.
pub const N_DERIVED_RTM: usize = 2;

/// Largest absolute observation accepted, in the model's physical unit (mm for GNSS: 10 m).
pub const MAX_ABS_OBS: f64 = 1.0e4;

/// Quality flags of one inversion (bit set).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Flags(pub u8);

impl Flags {
    /// A variable sits within 0.1 % of its bound (the encoder saturated).
    pub const AT_BOUND: u8 = 1;
    /// Some channels were missing.
    pub const MISSING: u8 = 2;
    /// The residual exceeds the model's threshold (the model does not explain this observation).
    pub const HIGH_RESIDUAL: u8 = 4;

    /// Whether `bit` is set.
    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

/// The result of one inversion.
#[derive(Clone, Debug)]
pub struct Inversion<R> {
    /// Number of valid entries in `params`: the encoder's variables, then derived ones (RTM
    /// variants B and C: crown diameter `cd` and tree height `h`, from `fc`; see
    /// [`N_DERIVED_RTM`]).
    pub n_params: usize,
    /// Physical variables (for variant A: the latent code), then derived variables.
    pub params: [R; MAX_PARAMS],
    /// The encoder's normalised outputs in [0, 1] (variants B, C).
    pub unit: [f32; MAX_PARAMS],
    /// Number of valid entries in the observation-sized arrays.
    pub n_obs: usize,
    /// F(Z) in physical units (zeros for variant A).
    pub physics: [R; MAX_OBS],
    /// The final reconstruction in physical units (C(F(Z)) for C, F(Z) for B, decoder for A).
    pub recon: [R; MAX_OBS],
    /// RMS of observation − reconstruction over observed channels, physical units.
    pub residual_rms: f64,
    /// The same in standardised units.
    pub residual_rms_std: f64,
    /// Quality flags.
    pub flags: Flags,
    /// Bit i set when station (or channel group) i had at least one observed channel.
    pub used: u32,
}

/// Working memory for [`invert`] (about 2.5 KiB), reusable between calls.
#[derive(Clone, Debug, Default)]
pub struct Workspace {
    nn: Scratch,
}

/// Inverts one observation vector (physical units; NaN marks a missing channel).
///
/// ```no_run
/// # use magic_core::{model_file::Model, invert::{invert, Workspace}};
/// # let bytes: &[u8] = &[];
/// let model = Model::decode(bytes)?;
/// let obs = [0.0f32; 36];
/// let out = invert::<f64>(&model, &obs, &mut Workspace::default())?;
/// println!("depth {} km", out.params[2]);
/// # Ok::<(), magic_core::Error>(())
/// ```
pub fn invert<R: Real>(
    model: &Model<'_>,
    obs: &[f32],
    ws: &mut Workspace,
) -> Result<Inversion<R>, Error> {
    invert_at(model, obs, f64::NAN, ws)
}

/// [`invert`] for an observation made on day `t_day` (days since 1970-01-01; NaN when unknown,
/// which is an error only for models with time-dependent effects).
pub fn invert_at<R: Real>(
    model: &Model<'_>,
    obs: &[f32],
    t_day: f64,
    ws: &mut Workspace,
) -> Result<Inversion<R>, Error> {
    let n_obs = model.n_obs();
    if obs.len() != n_obs {
        return Err(Error::SizeMismatch {
            what: "observations",
            expected: n_obs,
            found: obs.len(),
        });
    }
    let mut z = [0f32; MAX_OBS];
    let mut observed = 0usize;
    for (i, &x) in obs.iter().enumerate() {
        if x.is_nan() {
            continue;
        }
        if x.is_infinite() {
            return Err(Error::NonFinite {
                what: "observation",
                index: i,
            });
        }
        if (x as f64).abs() > MAX_ABS_OBS {
            return Err(Error::OutOfRange {
                what: "observation magnitude",
            });
        }
        z[i] = (x - model.obs_mean.get(i)) / model.obs_scale.get(i);
        observed += 1;
    }
    let n_params = model.n_params();
    if observed < n_params.max(1) {
        return Err(Error::TooFewObservations {
            observed,
            needed: n_params.max(1),
        });
    }
    let mut flags = Flags::default();
    if observed < n_obs {
        flags.0 |= Flags::MISSING;
    }
    let groups = match &model.problem {
        Problem::Mogi { stations, .. } => stations.len(),
        Problem::Rtm { .. } => n_obs,
    };
    let per_group = n_obs / groups.max(1);
    let mut used = 0u32;
    for (i, x) in obs.iter().enumerate() {
        if !x.is_nan() && groups <= 32 {
            let g = if per_group == 3 { i % groups } else { i };
            used |= 1 << g;
        }
    }

    let mut pass = Pass::<R>::run(model, &z[..n_obs], t_day, ws)?;
    if observed < n_obs {
        // Missing channels: refill them with the model's own reconstruction and invert again.
        for _ in 0..IMPUTE_PASSES {
            for i in 0..n_obs {
                if obs[i].is_nan() {
                    z[i] = ((pass.recon[i].value() as f32) - model.obs_mean.get(i))
                        / model.obs_scale.get(i);
                }
            }
            pass = Pass::run(model, &z[..n_obs], t_day, ws)?;
        }
    }
    let Pass {
        mut params,
        unit,
        physics,
        recon,
        at_bound,
    } = pass;
    let mut n_params = n_params;
    if let (Problem::Rtm { fixed, .. }, Variant::B | Variant::C) = (&model.problem, model.variant) {
        let (cd, h) = crown_from_cover(params[6], R::c(fixed.sd));
        params[n_params] = cd;
        params[n_params + 1] = h;
        n_params += N_DERIVED_RTM;
    }
    if at_bound {
        flags.0 |= Flags::AT_BOUND;
    }

    let (mut ss, mut ss_std) = (0.0f64, 0.0f64);
    for i in 0..n_obs {
        if obs[i].is_nan() {
            continue;
        }
        let r = obs[i] as f64 - recon[i].value();
        ss += r * r;
        let rs = r / model.obs_scale.get(i) as f64;
        ss_std += rs * rs;
    }
    let residual_rms = libm::sqrt(ss / observed as f64);
    let residual_rms_std = libm::sqrt(ss_std / observed as f64);
    if model.residual_threshold > 0.0 && residual_rms_std > model.residual_threshold as f64 {
        flags.0 |= Flags::HIGH_RESIDUAL;
    }
    Ok(Inversion {
        n_params,
        params,
        unit,
        n_obs,
        physics,
        recon,
        residual_rms,
        residual_rms_std,
        flags,
        used,
    })
}

/// Extra passes for a day with missing channels: each refills the missing channels with the
/// previous pass's reconstruction (an EM-style imputation by the model itself, so one model file
/// serves every pattern of missing stations).
pub const IMPUTE_PASSES: usize = 3;

/// One encoder → F → C pass on standardised observations.
struct Pass<R> {
    params: [R; MAX_PARAMS],
    unit: [f32; MAX_PARAMS],
    physics: [R; MAX_OBS],
    recon: [R; MAX_OBS],
    at_bound: bool,
}

impl<R: Real> Pass<R> {
    fn run(model: &Model<'_>, z: &[f32], t_day: f64, ws: &mut Workspace) -> Result<Self, Error> {
        let n_obs = z.len();
        let n_params = model.n_params();
        let mut unit = [0f32; MAX_PARAMS];
        model_encoder(model, z, &mut unit[..n_params], ws)?;
        let mut params = [R::zero(); MAX_PARAMS];
        let mut physics = [R::zero(); MAX_OBS];
        let mut recon = [R::zero(); MAX_OBS];
        let mut at_bound = false;
        match model.variant {
            Variant::A => {
                for (p, u) in params.iter_mut().zip(&unit[..n_params]) {
                    *p = R::c(*u as f64);
                }
                let mut y = [0f32; MAX_OBS];
                run(
                    &model.decoder,
                    &unit[..n_params],
                    &mut y[..n_obs],
                    &mut ws.nn,
                )?;
                destandardise(model, &y[..n_obs], &mut recon[..n_obs]);
            }
            Variant::B | Variant::C => {
                for (i, u) in unit[..n_params].iter().enumerate() {
                    let [lo, hi] = model.bounds[i];
                    params[i] = R::c(lo as f64) + R::c((hi - lo) as f64) * R::c(*u as f64);
                    at_bound |= *u < 1e-3 || *u > 1.0 - 1e-3;
                }
                forward(model, &params[..n_params], t_day, &mut physics[..n_obs])?;
                if model.variant == Variant::C {
                    let mut fz = [0f32; MAX_OBS];
                    for i in 0..n_obs {
                        fz[i] = ((physics[i].value() as f32) - model.obs_mean.get(i))
                            / model.obs_scale.get(i);
                    }
                    let mut y = [0f32; MAX_OBS];
                    run(&model.decoder, &fz[..n_obs], &mut y[..n_obs], &mut ws.nn)?;
                    destandardise(model, &y[..n_obs], &mut recon[..n_obs]);
                } else {
                    recon[..n_obs].copy_from_slice(&physics[..n_obs]);
                }
            }
        }
        Ok(Pass {
            params,
            unit,
            physics,
            recon,
            at_bound,
        })
    }
}

/// Runs the encoder on standardised observations, writing its outputs (sigmoid units for B/C).
pub fn model_encoder(
    model: &Model<'_>,
    z: &[f32],
    out: &mut [f32],
    ws: &mut Workspace,
) -> Result<(), Error> {
    run(&model.encoder, z, out, &mut ws.nn)
}

/// The model's forward model F with its declared effects: physical variables → observations in
/// physical units, for an observation on day `t_day` (NaN if unknown).
pub fn forward<R: Real>(
    model: &Model<'_>,
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    match &model.problem {
        Problem::Mogi { stations, .. } => {
            mogi_with_effects(stations, &model.effects, params, t_day, out)
        }
        Problem::Rtm {
            fixed, geometry, ..
        } => {
            if model.variant == Variant::A {
                return Err(Error::InvalidModel("variant A has no forward model"));
            }
            let z: [R; N_LEARNED] = params.try_into().map_err(|_| Error::SizeMismatch {
                what: "RTM variables",
                expected: N_LEARNED,
                found: params.len(),
            })?;
            model
                .problem
                .packed()?
                .forward_learned(&z, fixed, *geometry, out)
        }
    }
}

fn destandardise<R: Real>(model: &Model<'_>, y: &[f32], out: &mut [R]) {
    for (i, (o, v)) in out.iter_mut().zip(y).enumerate() {
        *o = R::c((v * model.obs_scale.get(i) + model.obs_mean.get(i)) as f64);
    }
}
