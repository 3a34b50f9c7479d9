//! Standard deviations of inverted variables, from the local curvature of the model at the
//! solution.
//!
//! An inversion gives one value per variable; a map user also wants to know how well the
//! observation pins it down. The method is the Laplace (Gauss–Newton) approximation of the
//! posterior around the solution z:
//!
//! * `J` — the exact Jacobian of the reconstruction with respect to the variables: F's by dual
//!   numbers ([`forward_jacobian`]; INFORM through [`crate::rtm::bands::Packed::jacobian`], Mogi
//!   through [`crate::invert::forward`] on [`Dual`]), and for variant C the correction's slope
//!   along each column of F's Jacobian by central differences of the network
//!   ([`CORRECTION_STEP`]), in standardised observation units;
//! * `s²` — the residual variance: the squared standardised residual of the observed channels
//!   over their number less the number of variables;
//! * a Gaussian prior per variable with the variance of a uniform distribution over its bounds
//!   (`range²/12`), which keeps the matrix invertible where the observation does not constrain a
//!   variable and caps its standard deviation at `range/√12`;
//! * `Cov = (JᵀJ/s² + P₀)⁻¹` in variables scaled to their bounds, and `sd = range·√diag(Cov)`.
//!
//! Derived variables (the RTM's crown diameter and height, functions of the cover `fc`) get the
//! standard deviation of `fc` times their exact derivative. The whole computation is
//! allocation-free (fixed-size arrays, [`SdWorkspace`]) and returns an [`Error`] instead of
//! panicking.
//!
//! What it does not see: the bias of an amortised encoder (the network's answer is not the
//! least-squares optimum, and the curvature there says nothing about how far off it is) and model
//! error beyond what the residual shows. Callers that need calibrated intervals scale these
//! standard deviations by factors measured on synthetic spectra with known variables
//! ([`Uncertainty::scaled`]).

use crate::invert::{correction_input_of, forward_for, model_decoder, Inversion, Workspace};
use crate::model_file::{AnyProblem, Model, Problem, Problems, Variant, MAX_OBS, MAX_PARAMS};
use crate::rtm::inform::crown_from_cover;
use crate::rtm::N_LEARNED;
use crate::{Dual, Error};

/// Step (standardised units of F's output) of the central differences through the correction C.
/// C is a small piecewise-linear network: the difference quotient over ±0.05 is its slope
/// averaged over a small neighbourhood, which also smooths the steps of an int8 network.
pub const CORRECTION_STEP: f32 = 0.05;

/// Smallest residual variance used (standardised units²): a perfect fit gives tiny, not zero or
/// NaN, standard deviations.
pub const MIN_RESIDUAL_VARIANCE: f64 = 1e-12;

/// Variables per dual-number pass of the generic Jacobian (Mogi and its effects).
const BLOCK: usize = 4;

/// The precision INFORM's Jacobian is computed in (Mogi models always use `f64`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// `f64` throughout (the default).
    #[default]
    F64,
    /// INFORM's Jacobian in `f32` lanes: about half the time on SIMD targets, derivatives within
    /// [`crate::rtm::bands::JACOBIAN_F32_MAX_REL_ERROR`] of `f64`'s — far below what matters for
    /// a standard deviation.
    F32,
}

/// Working memory of [`standard_deviations`] (about 13 KiB), reusable between calls.
#[derive(Clone, Debug)]
pub struct SdWorkspace {
    /// The precision of INFORM's Jacobian.
    pub precision: Precision,
    /// Jacobian rows (one per observation), physical units.
    jac: [[f64; MAX_PARAMS]; MAX_OBS],
    /// F at the solution, physical units.
    y: [f64; MAX_OBS],
    /// The network's working memory (correction C).
    ws: Workspace,
}

impl SdWorkspace {
    /// A workspace whose INFORM Jacobians are computed in `precision` (`const`: a static can
    /// hold it without building it on the stack, as the firmware does).
    pub const fn with_precision(precision: Precision) -> Self {
        SdWorkspace {
            precision,
            jac: [[0.0; MAX_PARAMS]; MAX_OBS],
            y: [0.0; MAX_OBS],
            ws: Workspace::new(),
        }
    }
}

impl Default for SdWorkspace {
    fn default() -> Self {
        SdWorkspace::with_precision(Precision::F64)
    }
}

/// Standard deviations of one inversion's variables.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Uncertainty {
    /// Number of valid entries in `sd` (the inversion's `n_params`, derived variables included).
    pub n_params: usize,
    /// Standard deviation per variable, in the variable's unit.
    pub sd: [f64; MAX_PARAMS],
    /// Residual standard deviation `s` used (standardised units).
    pub residual_sd: f64,
    /// Degrees of freedom of `s`: observed channels less learned variables.
    pub dof: usize,
}

impl Uncertainty {
    /// The standard deviations multiplied by one factor per variable (`factors[i]` for variable
    /// i; variables past the end of `factors` keep theirs).
    ///
    /// ```
    /// use magic_core::uncertainty::Uncertainty;
    /// let mut sd = [0.0; 16];
    /// sd[..2].copy_from_slice(&[0.5, 2.0]);
    /// let u = Uncertainty { n_params: 2, sd, residual_sd: 0.1, dof: 4 };
    /// assert_eq!(&u.scaled(&[2.0, 0.5]).sd[..2], &[1.0, 1.0]);
    /// ```
    pub fn scaled(&self, factors: &[f64]) -> Uncertainty {
        let mut u = *self;
        for (s, f) in u.sd[..u.n_params.min(MAX_PARAMS)].iter_mut().zip(factors) {
            *s *= f;
        }
        u
    }
}

/// F and its exact Jacobian at the physical variables `params` (the model's learned variables,
/// `model.n_params()` of them), for an observation on day `t_day` (NaN if unknown): `y[i]` and
/// `jac[i][k] = ∂yᵢ/∂params_k` in physical units, for the model's `n_obs` channels.
///
/// RTM models use INFORM's split-chain-rule Jacobian; Mogi models (with their effects) run
/// [`forward`](crate::invert::forward) on [`Dual`] numbers, four variables per pass.
pub fn forward_jacobian(
    model: &Model<'_>,
    params: &[f64],
    t_day: f64,
    y: &mut [f64],
    jac: &mut [[f64; MAX_PARAMS]],
) -> Result<(), Error> {
    forward_jacobian_for::<AnyProblem>(model, params, t_day, Precision::F64, y, jac)
}

/// [`forward_jacobian`] with INFORM's Jacobian in `precision`, in a build that links only the
/// forward models of `P` (an RTM model is [`Error::WrongProblem`] for
/// [`crate::model_file::MogiOnly`]).
pub fn forward_jacobian_for<P: Problems>(
    model: &Model<'_>,
    params: &[f64],
    t_day: f64,
    precision: Precision,
    y: &mut [f64],
    jac: &mut [[f64; MAX_PARAMS]],
) -> Result<(), Error> {
    let (n_obs, n_params) = (model.n_obs(), model.n_params());
    if model.variant == Variant::A {
        return Err(Error::InvalidModel("variant A has no forward model"));
    }
    crate::error::check_len("variables", n_params, params.len())?;
    if n_params > MAX_PARAMS || n_obs > MAX_OBS || y.len() < n_obs || jac.len() < n_obs {
        return Err(Error::SizeMismatch {
            what: "Jacobian buffers",
            expected: n_obs,
            found: y.len().min(jac.len()),
        });
    }
    let (y, jac) = (&mut y[..n_obs], &mut jac[..n_obs]);
    match &model.problem {
        Problem::Rtm { .. } if !P::RTM => return Err(Error::WrongProblem),
        Problem::Rtm {
            fixed, geometry, ..
        } => {
            let z: [f64; N_LEARNED] = params.try_into().map_err(|_| Error::SizeMismatch {
                what: "RTM variables",
                expected: N_LEARNED,
                found: params.len(),
            })?;
            let fixed = crate::effects::rtm_fixed_at(&model.effects, fixed, t_day)?;
            let mut j7 = [[0.0; N_LEARNED]; MAX_OBS];
            let packed = model.problem.packed()?;
            let j = &mut j7[..n_obs];
            match precision {
                Precision::F64 => packed.jacobian(&z, &fixed, *geometry, y, j)?,
                Precision::F32 => packed.jacobian_in::<f32>(&z, &fixed, *geometry, y, j)?,
            }
            // Band offsets are constants: they move F, not its derivatives.
            crate::effects::rtm_add_offsets(&model.effects, y)?;
            for (row, r7) in jac.iter_mut().zip(&j7) {
                *row = [0.0; MAX_PARAMS];
                row[..N_LEARNED].copy_from_slice(r7);
            }
        }
        Problem::Mogi { .. } => {
            let mut out = [Dual::<BLOCK>::constant(0.0); MAX_OBS];
            let mut p = [Dual::<BLOCK>::constant(0.0); MAX_PARAMS];
            for k0 in (0..n_params).step_by(BLOCK) {
                for (k, (pk, &v)) in p.iter_mut().zip(params).enumerate() {
                    *pk = match k.checked_sub(k0) {
                        Some(slot) if slot < BLOCK => Dual::var(v, slot),
                        _ => Dual::constant(v),
                    };
                }
                forward_for::<_, P>(model, &p[..n_params], t_day, &mut out[..n_obs])?;
                for ((row, yi), o) in jac.iter_mut().zip(y.iter_mut()).zip(&out) {
                    *yi = o.v;
                    for (slot, d) in o.d.iter().enumerate() {
                        if let Some(r) = row.get_mut(k0 + slot).filter(|_| k0 + slot < n_params) {
                            *r = *d;
                        }
                    }
                }
            }
        }
    }
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "forward model output",
            index: i,
        });
    }
    for row in jac.iter() {
        if let Some(k) = row[..n_params].iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "Jacobian entry",
                index: k,
            });
        }
    }
    Ok(())
}

/// The standard deviations of the variables of `inv`, the inversion of `obs` (physical units,
/// NaN = missing) by `model` (variant B or C) on day `t_day` (NaN if unknown). See the module
/// documentation for the method.
pub fn standard_deviations(
    model: &Model<'_>,
    obs: &[f32],
    inv: &Inversion<f64>,
    t_day: f64,
    sw: &mut SdWorkspace,
) -> Result<Uncertainty, Error> {
    standard_deviations_for::<AnyProblem>(model, obs, inv, t_day, sw)
}

/// [`standard_deviations`] in a build that links only the forward models of `P` (the
/// firmware: [`crate::model_file::MogiOnly`]).
pub fn standard_deviations_for<P: Problems>(
    model: &Model<'_>,
    obs: &[f32],
    inv: &Inversion<f64>,
    t_day: f64,
    sw: &mut SdWorkspace,
) -> Result<Uncertainty, Error> {
    let (n_obs, p) = (model.n_obs(), model.n_params());
    crate::error::check_len("observations", n_obs, obs.len())?;
    if p == 0 || p > MAX_PARAMS || inv.n_params < p || inv.n_obs != n_obs || n_obs > MAX_OBS {
        return Err(Error::SizeMismatch {
            what: "inversion",
            expected: p,
            found: inv.n_params,
        });
    }
    if model.bounds.len() < p {
        return Err(Error::InvalidModel("variables without bounds"));
    }
    // (Checked above; the clamps let the compiler see it: no index below can panic.)
    let (p, obs) = (p.min(MAX_PARAMS), &obs[..n_obs.min(obs.len()).min(MAX_OBS)]);
    forward_jacobian_for::<P>(
        model,
        &inv.params[..p],
        t_day,
        sw.precision,
        &mut sw.y,
        &mut sw.jac,
    )?;
    if model.variant == Variant::C {
        correction_jacobian(model, p, t_day, sw)?;
    }

    // Residual variance over the observed channels (standardised units).
    let (mut ss, mut m) = (0.0f64, 0usize);
    for (i, &x) in obs.iter().enumerate() {
        if x.is_nan() {
            continue;
        }
        let recon = inv.recon.get(i).copied().unwrap_or(f64::NAN);
        let r = (x as f64 - recon) / scale(model, i)?;
        ss += r * r;
        m += 1;
    }
    if m <= p {
        return Err(Error::TooFewObservations {
            observed: m,
            needed: p + 1,
        });
    }
    let dof = m - p;
    let s2 = (ss / dof as f64).max(MIN_RESIDUAL_VARIANCE);
    if !s2.is_finite() {
        return Err(Error::NonFinite {
            what: "residual",
            index: 0,
        });
    }

    // A = JᵀJ/s² + 12·I in variables scaled to their bounds (u = (z − lo)/range).
    let mut range = [0.0f64; MAX_PARAMS];
    for (r, b) in range.iter_mut().zip(model.bounds.iter().take(p)) {
        *r = (b[1] - b[0]) as f64;
        if !(*r > 0.0 && r.is_finite()) {
            return Err(Error::InvalidModel("variable bounds not increasing"));
        }
    }
    let mut a = [[0.0f64; MAX_PARAMS]; MAX_PARAMS];
    for (i, &x) in obs.iter().enumerate() {
        if x.is_nan() {
            continue;
        }
        let sc = scale(model, i)?;
        let Some(row) = sw.jac.get(i) else {
            continue;
        };
        for j in 0..p {
            let gj = row[j] * range[j] / sc;
            for k in 0..=j {
                a[j][k] += gj * row[k] * range[k] / sc / s2;
            }
        }
    }
    for (j, aj) in a.iter_mut().enumerate().take(p) {
        aj[j] += 12.0;
    }
    let var = diag_inverse(&mut a, p)?;
    let mut out = Uncertainty {
        n_params: inv.n_params.min(MAX_PARAMS),
        sd: [f64::NAN; MAX_PARAMS],
        residual_sd: libm::sqrt(s2),
        dof,
    };
    for k in 0..p {
        out.sd[k] = range[k] * libm::sqrt(var[k]);
    }
    // Derived RTM variables: crown diameter and height from fc.
    if let (Problem::Rtm { fixed, .. }, true) = (&model.problem, inv.n_params >= p + 2) {
        if let (Some(&fc), Some(&fc_sd), true) = (
            inv.params.get(p.wrapping_sub(1)),
            out.sd.get(p.wrapping_sub(1)),
            p + 2 <= MAX_PARAMS,
        ) {
            let (cd, h) = crown_from_cover(Dual::<1>::var(fc, 0), Dual::constant(fixed.sd));
            if let [sd_cd, sd_h] = &mut out.sd[p..p + 2] {
                *sd_cd = (cd.d[0] * fc_sd).abs();
                *sd_h = (h.d[0] * fc_sd).abs();
            }
        }
    }
    Ok(out)
}

/// The observation scale of channel `i`, checked positive and finite.
fn scale(model: &Model<'_>, i: usize) -> Result<f64, Error> {
    let s = model.obs_scale.get(i) as f64;
    if s > 0.0 && s.is_finite() {
        Ok(s)
    } else {
        Err(Error::InvalidModel("observation scale not positive"))
    }
}

/// Replaces F's Jacobian in `sw.jac` by that of C(F): for each variable k, the directional
/// derivative of C (standardised in and out) along F's column k, by central differences.
fn correction_jacobian(
    model: &Model<'_>,
    p: usize,
    t_day: f64,
    sw: &mut SdWorkspace,
) -> Result<(), Error> {
    let (n, p) = (model.n_obs().min(MAX_OBS), p.min(MAX_PARAMS));
    let (mut plus, mut minus) = ([0f32; MAX_OBS], [0f32; MAX_OBS]);
    // C's input: F without its dated terms, which do not depend on the variables, standardised.
    let mut f = [0f32; MAX_OBS];
    correction_input_of(model, &sw.y[..n], t_day, &mut f[..n])?;
    let (mut up, mut down) = ([0f32; MAX_OBS], [0f32; MAX_OBS]);
    for k in 0..p {
        // The direction: column k in standardised units, normalised.
        let mut norm = 0.0f64;
        for i in 0..n {
            let v = sw.jac[i][k] / scale(model, i)?;
            norm += v * v;
        }
        let norm = libm::sqrt(norm);
        if norm == 0.0 {
            continue;
        }
        for i in 0..n {
            let t = (sw.jac[i][k] / scale(model, i)? / norm) as f32;
            plus[i] = f[i] + CORRECTION_STEP * t;
            minus[i] = f[i] - CORRECTION_STEP * t;
        }
        model_decoder(model, &plus[..n], &mut up[..n], &mut sw.ws)?;
        model_decoder(model, &minus[..n], &mut down[..n], &mut sw.ws)?;
        for i in 0..n {
            let slope = (up[i] - down[i]) as f64 / (2.0 * CORRECTION_STEP as f64);
            // Back to physical units of the reconstruction per unit of the variable.
            sw.jac[i][k] = slope * norm * scale(model, i)?;
        }
    }
    Ok(())
}

/// The diagonal of the inverse of the symmetric positive definite matrix whose lower triangle
/// (first `p` rows and columns) is in `a`, by Cholesky: `a` is overwritten with the factor.
fn diag_inverse(
    a: &mut [[f64; MAX_PARAMS]; MAX_PARAMS],
    p: usize,
) -> Result<[f64; MAX_PARAMS], Error> {
    let not_pd = Error::OutOfRange {
        what: "curvature matrix not positive definite",
    };
    let p = p.min(MAX_PARAMS);
    for j in 0..p {
        let d = a[j][j] - a[j][..j].iter().map(|x| x * x).sum::<f64>();
        if !(d > 0.0 && d.is_finite()) {
            return Err(not_pd);
        }
        let l = libm::sqrt(d);
        a[j][j] = l;
        for i in j + 1..p {
            let dot: f64 = a[i][..j].iter().zip(&a[j][..j]).map(|(x, y)| x * y).sum();
            a[i][j] = (a[i][j] - dot) / l;
        }
    }
    // diag(A⁻¹)_k = Σ_i (L⁻¹)_{ik}²: column k of L⁻¹ by forward substitution.
    let mut out = [0.0f64; MAX_PARAMS];
    for (k, o) in out.iter_mut().enumerate().take(p) {
        let mut col = [0.0f64; MAX_PARAMS];
        for i in k..p {
            let mut s = if i == k { 1.0 } else { 0.0 };
            for m in k..i {
                s -= a[i][m] * col[m];
            }
            col[i] = s / a[i][i];
        }
        *o = col.iter().take(p).skip(k).map(|c| c * c).sum();
        if !o.is_finite() {
            return Err(not_pd);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diag_inverse_of_a_known_matrix() {
        // A = [[4, 2], [2, 3]]: A⁻¹ = [[3, −2], [−2, 4]] / 8.
        let mut a = [[0.0; MAX_PARAMS]; MAX_PARAMS];
        a[0][0] = 4.0;
        a[1][0] = 2.0;
        a[1][1] = 3.0;
        let d = diag_inverse(&mut a, 2).unwrap();
        assert!((d[0] - 3.0 / 8.0).abs() < 1e-15 && (d[1] - 0.5).abs() < 1e-15);
        let mut bad = [[0.0; MAX_PARAMS]; MAX_PARAMS];
        bad[0][0] = -1.0;
        assert!(diag_inverse(&mut bad, 1).is_err());
        let mut nan = [[f64::NAN; MAX_PARAMS]; MAX_PARAMS];
        assert!(diag_inverse(&mut nan, 3).is_err());
    }
}
