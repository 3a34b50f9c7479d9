//! Inversion: observations → physical variables, reconstruction, residual and quality flags.
//!
//! One path for every target: standardise the observations, run the encoder E, map its sigmoid
//! outputs into the variables' bounds, run the forward model F (generic over [`Real`]: `f32` on the
//! board, `f64` on the host), standardise F's output, run the correction C (on F without its dated
//! terms, which are added after it: [`model_correction`]), and compare with the observations.
//! Missing channels (NaN) are allowed: they first enter the encoder as the training mean
//! (standardised 0), then [`IMPUTE_PASSES`] more passes refill them with the model's own
//! reconstruction; they are left out of the residual and reported in the flags and the station
//! mask.

use crate::effects::mogi_terms_of;
use crate::model_file::{AnyProblem, Model, Problem, Problems, Variant, MAX_OBS, MAX_PARAMS};
use crate::nn::{run, run_scratch, Scratch};
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
    /// The final reconstruction in physical units (for C, C(F₀(Z)) + D(t): F₀ is F without its
    /// dated terms D(t), see [`model_correction`]; F(Z) for B; the decoder's output for A).
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

impl Workspace {
    /// Zeroed working memory (`const`, as [`Scratch::new`]).
    pub const fn new() -> Self {
        Workspace { nn: Scratch::new() }
    }
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
    invert_at_for::<R, AnyProblem>(model, obs, t_day, ws)
}

/// [`invert_at`] in a build that links only the forward models of `P` (see
/// [`crate::model_file::Problems`]; the firmware uses [`crate::model_file::MogiOnly`]).
pub fn invert_at_for<R: Real, P: Problems>(
    model: &Model<'_>,
    obs: &[f32],
    t_day: f64,
    ws: &mut Workspace,
) -> Result<Inversion<R>, Error> {
    let mut out = Inversion::empty();
    invert_into::<R, P>(model, obs, t_day, ws, &mut out)?;
    Ok(out)
}

impl<R: Real> Inversion<R> {
    /// An inversion with no variables and every array zero (to be filled by [`invert_into`]).
    pub fn empty() -> Self {
        Inversion {
            n_params: 0,
            params: [R::zero(); MAX_PARAMS],
            unit: [0f32; MAX_PARAMS],
            n_obs: 0,
            physics: [R::zero(); MAX_OBS],
            recon: [R::zero(); MAX_OBS],
            residual_rms: 0.0,
            residual_rms_std: 0.0,
            flags: Flags::default(),
            used: 0,
        }
    }
}

/// The three parts of an inversion pass, for cost measurement ([`Probe`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The encoder E (inputs copied in and quantised, layers, outputs).
    Encoder,
    /// The forward model F with its effects.
    Forward,
    /// The correction C (variant C) or the decoder (variant A), after its inputs are standardised.
    Correction,
}

/// Observes the parts of an inversion as [`invert_probed`] runs them: `begin` just before and
/// `end` just after each part of each pass (a day with missing channels makes several passes).
/// The firmware times the parts with it; `()` observes nothing and costs nothing.
pub trait Probe {
    /// A part starts.
    fn begin(&mut self, part: Part);
    /// The part ends.
    fn end(&mut self, part: Part);
}

impl Probe for () {
    #[inline(always)]
    fn begin(&mut self, _: Part) {}
    #[inline(always)]
    fn end(&mut self, _: Part) {}
}

/// [`invert_at_for`] writing into `out` in place (the firmware's path: no ~1 KB result to copy).
/// On success the first `n_params` / `n_obs` entries of `out`'s arrays are this inversion's; the
/// entries after them keep what they held. On error `out` holds no valid inversion.
///
/// Everything after the networks is computed in `R` (f32 on the board, no soft-float f64): the
/// bounds mapping, the forward model, the destandardisation and the residual, which is
/// converted to `f64` once at the end.
pub fn invert_into<R: Real, P: Problems>(
    model: &Model<'_>,
    obs: &[f32],
    t_day: f64,
    ws: &mut Workspace,
    out: &mut Inversion<R>,
) -> Result<(), Error> {
    invert_probed::<R, P, ()>(model, obs, t_day, ws, out, &mut ())
}

/// [`invert_into`] reporting the start and end of each part to `probe`.
pub fn invert_probed<R: Real, P: Problems, Q: Probe>(
    model: &Model<'_>,
    obs: &[f32],
    t_day: f64,
    ws: &mut Workspace,
    out: &mut Inversion<R>,
    probe: &mut Q,
) -> Result<(), Error> {
    let n_obs = model.n_obs();
    if obs.len() != n_obs || n_obs > MAX_OBS {
        return Err(Error::SizeMismatch {
            what: "observations",
            expected: n_obs,
            found: obs.len(),
        });
    }
    // Channel i belongs to station i mod S (components E, N, U of S stations), or is its own
    // group (RTM bands): bit g of `used` is set when group g has an observed channel.
    let groups = match &model.problem {
        Problem::Mogi { stations, .. } => stations.len(),
        Problem::Rtm { .. } => n_obs,
    };
    let per_group = n_obs / groups.max(1);
    let track = groups <= 32 && (per_group == 3 || groups == n_obs);
    let mut z = [0f32; MAX_OBS];
    let (observed, used) = standardise(model, obs, groups, &mut z)?;
    let used = if track { used } else { 0 };
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

    out.n_obs = n_obs;
    let mut at_bound = pass::<R, P, Q>(model, &z[..n_obs], t_day, ws, out, probe)?;
    if observed < n_obs {
        // Missing channels: refill them with the model's own reconstruction and invert again.
        for _ in 0..IMPUTE_PASSES {
            let (mut means, mut scales) = (model.obs_mean.iter(), model.obs_scale.iter());
            for ((zi, x), r) in z.iter_mut().zip(obs).zip(&out.recon) {
                let (mean, scale) = (means.next().unwrap_or(0.0), scales.next().unwrap_or(0.0));
                if x.is_nan() {
                    *zi = (R::value(*r) as f32 - mean) / scale;
                }
            }
            at_bound = pass::<R, P, Q>(model, &z[..n_obs], t_day, ws, out, probe)?;
        }
    }
    out.n_params = n_params;
    if let (Problem::Rtm { fixed, .. }, Variant::B | Variant::C) = (&model.problem, model.variant) {
        if !P::RTM {
            return Err(Error::WrongProblem);
        }
        if let (Some(&fc), true) = (out.params.get(6), n_params + N_DERIVED_RTM <= MAX_PARAMS) {
            let (cd, h) = crown_from_cover(fc, R::c(fixed.sd));
            out.params[n_params] = cd;
            out.params[n_params + 1] = h;
            out.n_params += N_DERIVED_RTM;
        }
    }
    if at_bound {
        flags.0 |= Flags::AT_BOUND;
    }

    // The residual over the observed channels, in R.
    let (mut ss, mut ss_std) = (R::zero(), R::zero());
    let mut scales = model.obs_scale.iter();
    for (&x, &rec) in obs.iter().zip(&out.recon) {
        let scale = scales.next().unwrap_or(0.0);
        if x.is_nan() {
            continue;
        }
        let r = R::c(x as f64) - rec;
        ss += r * r;
        let rs = r / R::c(scale as f64);
        ss_std += rs * rs;
    }
    // (`observed` ≤ MAX_OBS: exact in f32.)
    let n = R::c(observed as f32 as f64);
    let rms = crate::mogi::sqrt(ss / n);
    let rms_std = crate::mogi::sqrt(ss_std / n);
    if model.residual_threshold > 0.0 && rms_std > R::c(model.residual_threshold as f64) {
        flags.0 |= Flags::HIGH_RESIDUAL;
    }
    out.residual_rms = rms.value();
    out.residual_rms_std = rms_std.value();
    out.flags = flags;
    out.used = used;
    Ok(())
}

/// Standardises the observations `obs` into `z` (`(x − mean) / scale`; a missing channel, NaN,
/// stays as `z` holds it), checking their magnitude; returns the number of observed channels and
/// the set of groups (channel i in group i mod `groups`, bit g for group g, modulo 32) that
/// have one. (The means, scales and observations are read in order, by iterators: no bounds
/// checks in the loop; one comparison passes every ordinary value, NaN and the too large fail
/// it.)
fn standardise(
    model: &Model<'_>,
    obs: &[f32],
    groups: usize,
    z: &mut [f32],
) -> Result<(usize, u32), Error> {
    let (mut observed, mut used) = (0usize, 0u32);
    let (mut g, mut bit) = (0usize, 1u32);
    let mut scales = model.obs_scale.iter();
    let channels = obs.iter().zip(z.iter_mut()).zip(model.obs_mean.iter());
    for (i, ((&x, zi), mean)) in channels.enumerate() {
        let scale = scales.next().unwrap_or(0.0);
        // (1e4 is exact in f32: the same test as in f64.)
        if x.abs() <= MAX_ABS_OBS as f32 {
            *zi = (x - mean) / scale;
            observed += 1;
            used |= bit;
        } else if !x.is_nan() {
            return Err(observation_error(x, i));
        }
        g += 1;
        bit = bit.rotate_left(1);
        if g >= groups {
            (g, bit) = (0, 1);
        }
    }
    Ok((observed, used))
}

/// The error for observation `index`, `x`, beyond [`MAX_ABS_OBS`] (not NaN).
#[cold]
fn observation_error(x: f32, index: usize) -> Error {
    if x.is_infinite() {
        Error::NonFinite {
            what: "observation",
            index,
        }
    } else {
        Error::OutOfRange {
            what: "observation magnitude",
        }
    }
}

/// Extra passes for a day with missing channels: each refills the missing channels with the
/// previous pass's reconstruction (an EM-style imputation by the model itself, so one model file
/// serves every pattern of missing stations).
pub const IMPUTE_PASSES: usize = 3;

/// One encoder → F → C pass on standardised observations, writing `params`, `unit`, `physics`
/// and `recon` of `out` in place; returns whether a variable sits at its bound. The networks
/// read their inputs from and leave their outputs in the working memory (no copies).
fn pass<R: Real, P: Problems, Q: Probe>(
    model: &Model<'_>,
    z: &[f32],
    t_day: f64,
    ws: &mut Workspace,
    out: &mut Inversion<R>,
    probe: &mut Q,
) -> Result<bool, Error> {
    let n_obs = z.len().min(MAX_OBS);
    let n_params = model.n_params().min(MAX_PARAMS);
    let unit = &mut out.unit[..n_params];
    probe.begin(Part::Encoder);
    model_encoder(model, z, unit, ws)?;
    probe.end(Part::Encoder);
    let mut at_bound = false;
    // The variables: the encoder's outputs mapped into their bounds (B, C), or the latent code
    // itself (A). (One loop for both: a plain copy loop is turned into a call of `memmove`,
    // 1.5 KB of flash on the board.)
    let scaled = model.variant != Variant::A;
    for (i, (p, &u)) in out.params.iter_mut().zip(unit.iter()).enumerate() {
        *p = match (scaled, model.bounds.get(i)) {
            (true, Some(&[lo, hi])) => {
                // (Not `!(a..=b).contains(&u)`: a NaN output must not count as at a bound.)
                #[allow(clippy::manual_range_contains)]
                let edge = u < 1e-3 || u > 1.0 - 1e-3;
                at_bound |= edge;
                R::c(lo as f64) + R::c((hi - lo) as f64) * R::c(u as f64)
            }
            _ => R::c(u as f64),
        };
    }
    match model.variant {
        Variant::A => {
            out.physics[..n_obs].fill(R::zero());
            let input = ws.nn.input();
            input[..n_params].copy_from_slice(unit);
            probe.begin(Part::Correction);
            let y = run_scratch(&model.decoder, n_params, &mut ws.nn)?;
            probe.end(Part::Correction);
            destandardise(model, y, &mut out.recon[..n_obs], false)?;
        }
        Variant::B | Variant::C => {
            // C sees F₀, F without its dated terms D(t), which are added after it
            // ([`model_correction`]): where a C model has dated terms, F₀ and D(t) are evaluated
            // apart (D into `recon`, which C's output is then added onto), and F = F₀ + D(t) is
            // reported.
            let c = model.variant == Variant::C;
            let dated = model.dated_after_correction();
            let (physics, recon) = (&mut out.physics[..n_obs], &mut out.recon[..n_obs]);
            probe.begin(Part::Forward);
            forward_terms_for::<R, P>(model, &out.params[..n_params], t_day, physics, !dated)?;
            if dated {
                dated_part(model, t_day, recon)?;
            }
            probe.end(Part::Forward);
            if c {
                probe.begin(Part::Correction);
                correction_input(model, physics.iter().copied(), ws);
                if dated {
                    for (f, d) in physics.iter_mut().zip(recon.iter()) {
                        *f += *d;
                    }
                }
                let y = run_scratch(&model.decoder, n_obs, &mut ws.nn)?;
                destandardise(model, y, recon, dated)?;
                probe.end(Part::Correction);
            } else {
                recon.copy_from_slice(physics);
            }
        }
    }
    Ok(at_bound)
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

/// Runs the correction C (variant C) or the decoder (variant A) on standardised values.
pub fn model_decoder(
    model: &Model<'_>,
    z: &[f32],
    out: &mut [f32],
    ws: &mut Workspace,
) -> Result<(), Error> {
    run(&model.decoder, z, out, &mut ws.nn)
}

/// The correction C of a variant-C model: F's values `physics` (physical units) of an observation
/// on day `t_day` → the reconstruction `recon`. C sees F without its dated terms
/// ([`Effect::is_dated`](crate::effects::Effect::is_dated): steps and drifts),
/// standardised, and those terms are added to its output: C, fitted over the training years,
/// corrects the physics of the source and its latent effects, and a term that grows with the
/// date cannot take C's input where it was never fitted.
pub fn model_correction<R: Real>(
    model: &Model<'_>,
    physics: &[R],
    t_day: f64,
    recon: &mut [R],
    ws: &mut Workspace,
) -> Result<(), Error> {
    // (`recon` shorter than `physics` is an error below, from the network's output size.)
    let n_obs = physics.len();
    // The dated terms first, into `recon`, which C's output is then added onto.
    dated_part(model, t_day, recon)?;
    let undated = physics.iter().zip(recon.iter()).map(|(p, d)| *p - *d);
    correction_input(model, undated, ws);
    let y = run_scratch(&model.decoder, n_obs, &mut ws.nn)?;
    destandardise(model, y, recon, true)
}

/// C's input: F₀ (F without its dated terms, physical units) standardised into the network's
/// input.
fn correction_input<R: Real>(model: &Model<'_>, f0: impl Iterator<Item = R>, ws: &mut Workspace) {
    standardise_values(model, f0, ws.nn.input());
}

/// C's input for F's values `physics` (physical units, dated terms included) on day `t_day`,
/// written over `out[..physics.len()]`: F without its dated terms, standardised — what
/// [`model_correction`] feeds C, for callers that run C themselves (finite differences through
/// it, the int8 export's calibration).
pub fn correction_input_of<R: Real>(
    model: &Model<'_>,
    physics: &[R],
    t_day: f64,
    out: &mut [f32],
) -> Result<(), Error> {
    let (n, found) = (physics.len(), out.len());
    let out = out.get_mut(..n).ok_or(Error::SizeMismatch {
        what: "correction input",
        expected: n,
        found,
    })?;
    let mut dated = [R::zero(); MAX_OBS];
    let dated = dated.get_mut(..n).ok_or(Error::SizeMismatch {
        what: "observations",
        expected: MAX_OBS,
        found: n,
    })?;
    dated_part(model, t_day, dated)?;
    standardise_values(
        model,
        physics.iter().zip(dated.iter()).map(|(p, d)| *p - *d),
        out,
    );
    Ok(())
}

/// `values` (physical units) standardised by the model's observation means and scales into `out`.
fn standardise_values<R: Real>(
    model: &Model<'_>,
    values: impl Iterator<Item = R>,
    out: &mut [f32],
) {
    let (mut means, mut scales) = (model.obs_mean.iter(), model.obs_scale.iter());
    for (f, p) in out.iter_mut().zip(values) {
        let (mean, scale) = (means.next().unwrap_or(0.0), scales.next().unwrap_or(0.0));
        *f = (R::value(p) as f32 - mean) / scale;
    }
}

/// The model's dated terms ([`Effect::is_dated`](crate::effects::Effect::is_dated): steps and
/// drifts) on day `t_day` (physical units), written over `out`: zero for a model without them
/// (and for the forest-spectra problem).
pub fn dated_part<R: Real>(model: &Model<'_>, t_day: f64, out: &mut [R]) -> Result<(), Error> {
    match &model.problem {
        Problem::Mogi { stations, .. } => {
            crate::effects::dated_part_of(stations, &model.effects, t_day, out)
        }
        Problem::Rtm { .. } => {
            out.fill(R::zero());
            Ok(())
        }
    }
}

/// The model's forward model F with its declared effects: physical variables → observations in
/// physical units, for an observation on day `t_day` (NaN if unknown).
pub fn forward<R: Real>(
    model: &Model<'_>,
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    forward_for::<R, AnyProblem>(model, params, t_day, out)
}

/// [`forward`] in a build that links only the forward models of `P` (an RTM model is
/// [`Error::WrongProblem`] for [`crate::model_file::MogiOnly`]).
pub fn forward_for<R: Real, P: Problems>(
    model: &Model<'_>,
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    forward_terms_for::<R, P>(model, params, t_day, out, true)
}

/// [`forward_for`], without the dated terms unless `dated` (F₀; the forest problem has none).
fn forward_terms_for<R: Real, P: Problems>(
    model: &Model<'_>,
    params: &[R],
    t_day: f64,
    out: &mut [R],
    dated: bool,
) -> Result<(), Error> {
    match &model.problem {
        Problem::Mogi { stations, .. } => {
            mogi_terms_of(stations, &model.effects, params, t_day, out, dated)
        }
        Problem::Rtm { .. } if !P::RTM => Err(Error::WrongProblem),
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
            let fixed = crate::effects::rtm_fixed_at(&model.effects, fixed, t_day)?;
            model
                .problem
                .packed()?
                .forward_learned(&z, &fixed, *geometry, out)?;
            crate::effects::rtm_add_offsets(&model.effects, out)
        }
    }
}

/// Destandardises network outputs into R (`x = y · scale + mean`, computed in f32 as the
/// network's outputs are), written over `out` or, if `onto`, added to what it holds.
fn destandardise<R: Real>(
    model: &Model<'_>,
    y: &[f32],
    out: &mut [R],
    onto: bool,
) -> Result<(), Error> {
    if y.len() != out.len() {
        return Err(Error::SizeMismatch {
            what: "network output",
            expected: out.len(),
            found: y.len(),
        });
    }
    let (mut means, mut scales) = (model.obs_mean.iter(), model.obs_scale.iter());
    for (o, v) in out.iter_mut().zip(y) {
        let (mean, scale) = (means.next().unwrap_or(0.0), scales.next().unwrap_or(0.0));
        let x = R::c((v * scale + mean) as f64);
        *o = if onto { *o + x } else { x };
    }
    Ok(())
}
