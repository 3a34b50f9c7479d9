//! Residual analysis: which declared effect does F lack?
//!
//! **The residual.** Every day of the data is inverted with the core's `invert_at` (the model as
//! it will be used): the encoder's variables give the main source's typical position (the median
//! over the days of largest volume change) and the physics-only error F(E(x)) is reported. The
//! families are then fitted to what F, linearised around that typical state, cannot produce
//! whatever its variables: each day's observation less F's time-dependent declared effects, in
//! the data's standardised units (the paper's metric), projected off the span of F's Jacobian
//! (the main source's position, depth and volume, and the declared latent effects), each
//! channel's mean over the analysed split removed. For a C model the same holds: the correction
//! absorbs bias, the question is what F lacks. Working off the linearisation rather than off
//! `x − F(E(x))` keeps the analysis independent of how the encoder distorts its variables to
//! mimic a missing effect (an encoder readily moves the main source towards a second one, or
//! tilts it to follow a step at an edge station); candidate patterns are projected the same way,
//! and the constants of fitted effects are de-projected so that adding the effect to F reproduces
//! the fit (in mm).
//!
//! **Scores on held-out data.** Each effect family is fitted to the residuals in its own form and
//! scored by the share of residual variance it explains on data not used in the fit, its
//! prediction scaled by one least-squares weight (λ ≥ 0, so a family never scores below zero):
//!
//! * latent families, whose variables the encoder would infer every day (`common_mode`,
//!   `elevation`, `second_source`), predict each station from the other stations (leave one
//!   station out) on the neighbouring days (±[`NEIGHBOUR_WINDOWS`] days, the day itself excluded,
//!   best window taken), on the residuals less their running mean over ±[`LATENT_HIGHPASS_DAYS`]
//!   days (the few multi-year cycles of each station's red noise make chance coherence large and
//!   poorly represented by the surrogates). A day-to-day white network jitter is noise, not an
//!   effect: only a term that persists from day to day and is shared by the network scores;
//! * fitted families, constants applied as a function of the date (`seasonal`, `step`, `drift`),
//!   are cross-validated over [`FOLDS`] contiguous blocks of the analysed split (fitted without a
//!   block, scored on it) and fitted on the whole split and scored on the other splits.
//!
//! **Chance.** The same procedure (fit, selections, scoring) runs on surrogate residuals that keep
//! the noise's structure but not the family's: for latent families the family's daily fit is
//! removed and each station's series is given a random sign and direction of time (network
//! coherence destroyed, every station's own series kept whole); for fitted families the family's fit is removed
//! and the rest phase-randomised (one random phase per frequency shared by all channels, so
//! spectra and cross-spectra are kept). The **chance level** is the
//! [`AnalysisOptions::quantile`] of the surrogate scores, floored at zero.
//!
//! **Significance.** A family is significant when its score exceeds the chance level by more
//! than its margin: the score must pass the surrogates' mean plus [`SD_MARGIN`] standard
//! deviations on the square-root scale (where noise scores are close to Gaussian; the raw scores
//! are χ²-like with a heavy tail), and exceed the chance level by at least [`MIN_EXCESS`] of the
//! residual variance (negligible effects are not worth a model term).

use crate::data::gnss::GnssData;
use crate::export::OwnedEffect;
use anyhow::{anyhow, bail, Context, Result};
use magic_core::mogi::{self, Station};
use magic_core::{invert_at, Model, Workspace};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// Days on each side of a day whose residuals predict it in the latent families' score (the
/// best of these windows is taken: from weather-like terms to slow transients).
pub const NEIGHBOUR_WINDOWS: [usize; 3] = [3, 10, 30];
/// Half-width (days) of the running mean removed from the residuals before the latent families
/// are scored (see [`highpass`]): they are judged on variations faster than about two years.
/// Slower ones are dominated by each station's own red noise (monument and reference-frame
/// wander), of which a split of a few years holds only a few independent cycles: chance coherence
/// between stations is then large, and the sign/time-reversal surrogates, which can only rearrange
/// those few cycles, understate how large it gets. Weather-like terms, seasons (a whole number of
/// cycles in the window) and transients of up to a year or two are kept.
pub const LATENT_HIGHPASS_DAYS: usize = 365;
/// Smallest excess over chance (share of residual variance) that counts as a discovery.
pub const MIN_EXCESS: f64 = 0.005;
/// Standard deviations above the surrogates' mean (square-root scale) a significant score must
/// reach. Red noise makes chance coherence between a dozen stations heavy-tailed: on clean
/// synthetic data scores of 3–4 such deviations occur in a few percent of the families.
pub const SD_MARGIN: f64 = 4.0;
/// Half-width (days) of the windows compared by the step scan.
pub const STEP_SCAN_DAYS: usize = 30;
/// Fewest days of a split the analysis accepts.
pub const MIN_DAYS: usize = 360;
/// Sum over a station's components of its trends' squared robust z-scores needed to enter the
/// drift family (χ² with 3 degrees of freedom exceeds 20 with probability 2·10⁻⁴).
pub const DRIFT_Z2: f64 = 20.0;
/// Second-source candidates closer than this (km, horizontally) to the main source's median
/// position are not considered: there the residual is the main source's misfit.
pub const MAIN_SOURCE_EXCLUSION_KM: f64 = 3.0;

/// Squared norm (standardised units per unit of the effect's variable) below which a projected
/// pattern counts as already produced by F.
const DECLARED_NORM2: f64 = 1e-12;

/// The families, in report order.
pub const FAMILIES: [&str; 6] = [
    "common_mode",
    "seasonal",
    "elevation",
    "step",
    "second_source",
    "drift",
];

/// Options of [`analyse`].
#[derive(Clone, Debug)]
pub struct AnalysisOptions {
    /// The split the families are fitted on (`train`, `valid` or `test`).
    pub split: String,
    /// Surrogates per family for the chance level.
    pub surrogates: usize,
    /// Quantile of the surrogate scores taken as the chance level.
    pub quantile: f64,
    /// Seed of the surrogates.
    pub seed: u64,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        AnalysisOptions {
            split: "train".into(),
            surrogates: 20,
            quantile: 0.95,
            seed: 0,
        }
    }
}

/// One effect family fitted to the residuals.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Family name (`common_mode`, `seasonal`, `elevation`, `step`, `second_source`, `drift`).
    pub family: String,
    /// Share of the residual variance explained on held-out data.
    pub variance_explained: f64,
    /// Share explained by chance (quantile over surrogates, floored at 0).
    pub chance_level: f64,
    /// Whether the excess over chance is beyond the margin.
    pub significant: bool,
    /// Fitted parameters (the names of `truth.json` of `magic synth`).
    pub params: serde_json::Value,
    /// The effect that adds this family to F, with its fitted constants in mm.
    pub effect: Option<OwnedEffect>,
    /// Standard deviation of the surrogate scores.
    pub chance_sd: f64,
    /// The margin the excess had to exceed.
    pub margin: f64,
    /// The surrogate scores the chance level comes from.
    pub surrogate_scores: Vec<f64>,
}

impl Candidate {
    /// A family's candidate from its held-out score and its surrogates' scores: the chance level
    /// is their `quantile`, floored at zero; significant when the score exceeds it by more than
    /// the margin — the surrogates' mean plus [`SD_MARGIN`] standard deviations on the
    /// square-root scale (where the scores of noise are close to Gaussian), and at least
    /// [`MIN_EXCESS`].
    pub fn from_scores(
        family: &str,
        score: f64,
        chance: Vec<f64>,
        quantile_level: f64,
        params: serde_json::Value,
        effect: Option<OwnedEffect>,
    ) -> Candidate {
        let chance_level = quantile(&chance, quantile_level).max(0.0);
        let chance_sd = sd(&chance);
        let roots: Vec<f64> = chance.iter().map(|v| v.max(0.0).sqrt()).collect();
        let t = roots.iter().sum::<f64>() / roots.len().max(1) as f64 + SD_MARGIN * sd(&roots);
        let margin = MIN_EXCESS.max(t * t - chance_level);
        Candidate {
            family: family.into(),
            variance_explained: score,
            chance_level,
            significant: score - chance_level > margin,
            params,
            effect,
            chance_sd,
            margin,
            surrogate_scores: chance,
        }
    }

    /// The candidate as reported (`family`, `variance_explained`, `chance_level`, `significant`,
    /// `params`, and `excess`, `margin`, `declarable` — whether it can be added to F — and the
    /// surrogate scores).
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "family": self.family,
            "variance_explained": self.variance_explained,
            "chance_level": self.chance_level,
            "significant": self.significant,
            "params": self.params,
            "excess": self.excess(),
            "margin": self.margin,
            "declarable": self.effect.is_some(),
            "surrogate_scores": self.surrogate_scores,
        })
    }

    /// Score minus chance level (the ranking key).
    pub fn excess(&self) -> f64 {
        self.variance_explained - self.chance_level
    }
}

/// The result of [`analyse`].
#[derive(Clone, Debug)]
pub struct Analysis {
    /// Candidates ranked by excess over chance, descending.
    pub effects: Vec<Candidate>,
    /// Residual variance the shares refer to: mean over days and channels of the squared
    /// residual (standardised units) after removing each channel's mean, on the analysed split.
    pub residual_variance: f64,
    /// Mean squared residual without removing the means (the physics-only MSE of the split).
    pub residual_mse: f64,
    /// Analysed split.
    pub split: String,
    /// Days analysed.
    pub n_days: usize,
    /// Held-out days of the other splits (scoring of the fitted families).
    pub n_heldout_days: usize,
    /// Station names.
    pub names: Vec<String>,
    /// Station positions.
    pub stations: Vec<Station>,
    /// RMS residual per station and component (E, N, U), mm, on the analysed split.
    pub station_rms_mm: Vec<[f64; 3]>,
    /// The main source's typical position (x, y, depth km): the F linearised around it.
    pub main_source: [f64; 3],
    /// The dominant residual pattern (first principal component) per station, E N U, as the
    /// RMS of its daily amplitude in mm.
    pub pattern_mm: Vec<[f64; 3]>,
    /// Its share of the residual variance.
    pub pattern_share: f64,
    /// Seconds the analysis took.
    pub seconds: f64,
}

impl Analysis {
    /// The top candidate if it is significant.
    pub fn top_significant(&self) -> Option<&Candidate> {
        self.effects.first().filter(|c| c.significant)
    }

    /// The JSON report (`{"effects": [{"family", "variance_explained", "chance_level",
    /// "significant", "params"}, …], …}`).
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "effects": self.effects.iter().map(Candidate::to_json).collect::<Vec<_>>(),
            "residual_variance": self.residual_variance,
            "residual_mse": self.residual_mse,
            "split": self.split,
            "n_days": self.n_days,
            "n_heldout_days": self.n_heldout_days,
            "main_source": {"x_km": self.main_source[0], "y_km": self.main_source[1], "depth_km": self.main_source[2]},
        })
    }

    /// A text table of the candidates.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "residuals on {} ({} days, {} held-out days): variance {:.4} (standardised, means removed), physics-only MSE {:.4}",
            self.split, self.n_days, self.n_heldout_days, self.residual_variance, self.residual_mse
        );
        let _ = writeln!(
            s,
            "{:<14} {:>10} {:>10} {:>10} {:>8}  params",
            "family", "explained", "chance", "excess", "signif."
        );
        for c in &self.effects {
            let _ = writeln!(
                s,
                "{:<14} {:>9.2}% {:>9.2}% {:>9.2}% {:>8}  {}",
                c.family,
                100.0 * c.variance_explained,
                100.0 * c.chance_level,
                100.0 * c.excess(),
                if c.significant { "yes" } else { "no" },
                compact(&c.params)
            );
        }
        s
    }
}

fn compact(v: &serde_json::Value) -> String {
    let s = v.to_string();
    if s.len() > 160 {
        format!(
            "{}…",
            &s[..s
                .char_indices()
                .take_while(|(i, _)| *i < 157)
                .last()
                .map_or(0, |(i, c)| i + c.len_utf8())]
        )
    } else {
        s
    }
}

/// A block of residual rows: `r[t * nc + c]` in standardised units.
#[derive(Clone, Debug, Default)]
pub struct Block {
    /// Day numbers.
    pub days: Vec<f64>,
    /// Residuals, row-major (days × channels).
    pub r: Vec<f64>,
}

impl Block {
    fn len(&self, nc: usize) -> usize {
        self.r.len() / nc.max(1)
    }
}

/// Residuals of a model on a dataset.
#[derive(Clone, Debug)]
pub struct Residuals {
    /// Station names.
    pub names: Vec<String>,
    /// Station positions.
    pub stations: Vec<Station>,
    /// mm per standardised unit, per channel.
    pub scale: Vec<f64>,
    /// The analysed split, with each channel's mean over it removed.
    pub fit: Block,
    /// The other splits, with the analysed split's channel means removed.
    pub held: Block,
    /// Channel means removed (standardised units).
    pub mean: Vec<f64>,
    /// Mean squared residual of the analysed split before removing the means.
    pub mse: f64,
    /// The main source's typical position (x, y, depth): the encoder's median over the days of
    /// largest volume change.
    pub main_source: [f64; 3],
    /// Orthonormal basis (standardised units) of the directions F can already produce by
    /// adjusting its variables around their typical values: the columns of F's Jacobian (the
    /// main source's position, depth and volume, and the declared latent effects).
    pub tangent: Vec<Vec<f64>>,
}

impl Residuals {
    /// Every row of `r` projected with [`Residuals::project`].
    pub fn project_rows(&self, r: &[f64]) -> Vec<f64> {
        r.par_chunks(self.nc())
            .flat_map_iter(|row| self.project(row))
            .collect()
    }

    /// `g` without its part in the span of F's Jacobian: what remains of an effect of pattern
    /// `g` after the encoder has absorbed what F can mimic.
    pub fn project(&self, g: &[f64]) -> Vec<f64> {
        project_with(&self.tangent, g)
    }

    /// Number of channels.
    pub fn nc(&self) -> usize {
        self.scale.len()
    }
    /// Number of stations.
    pub fn ns(&self) -> usize {
        self.names.len()
    }
}

/// Residuals (observation − F(E(x)), standardised) of every day of `split` and of the other
/// splits, with the tangent space of F at the main source's typical position.
pub fn residuals(model: &Model<'_>, data: &GnssData, split: &str) -> Result<Residuals> {
    let nc = data.n_obs();
    if model.n_obs() != nc {
        bail!("the model has {} channels, the data {}", model.n_obs(), nc);
    }
    if model.variant == magic_core::Variant::A {
        bail!("residual analysis needs a model with physics (variant B or C), not A");
    }
    let fit_split = data.split(split)?;
    if fit_split.len() < MIN_DAYS {
        bail!(
            "split {split}: {} days are too few for the analysis (at least {})",
            fit_split.len(),
            MIN_DAYS
        );
    }
    let np = model.n_params();
    // Every day: observation (mm), F(E(x)) (mm) and the encoder's variables.
    struct Day {
        obs: Vec<f64>,
        physics: Vec<f64>,
        params: Vec<f64>,
    }
    let invert_split = |name: &str| -> Result<(Vec<f64>, Vec<Day>)> {
        let s = data.split(name)?;
        let days = s.days();
        if let Some(i) = days.iter().position(|d| !d.is_finite()) {
            bail!(
                "split {name}: row {} has no valid date `{}`",
                i + 1,
                s.dates[i]
            );
        }
        let rows: Vec<Day> =
            s.x.par_iter()
                .zip(days.par_iter())
                .map_init(Workspace::default, |ws, (row, &t)| {
                    let obs: Vec<f32> = row
                        .iter()
                        .enumerate()
                        .map(|(c, v)| data.to_mm(c, *v as f64) as f32)
                        .collect();
                    let inv = invert_at::<f64>(model, &obs, t, ws)
                        .map_err(|e| anyhow!("{name} day {t}: {e}"))?;
                    Ok(Day {
                        obs: obs.iter().map(|v| *v as f64).collect(),
                        physics: inv.physics[..nc].to_vec(),
                        params: inv.params[..np].to_vec(),
                    })
                })
                .collect::<Result<_>>()?;
        Ok((days, rows))
    };
    let (fit_days, fit_rows) = invert_split(split)?;
    let main = main_source(
        &fit_rows
            .iter()
            .map(|d| [d.params[0], d.params[1], d.params[2], d.params[3]])
            .collect::<Vec<_>>(),
    );
    let tangent = tangent_basis(model, data, main, fit_days[fit_days.len() / 2])?;
    let mse = fit_rows
        .iter()
        .flat_map(|d| (0..nc).map(move |c| ((d.obs[c] - d.physics[c]) / data.scale[c]).powi(2)))
        .sum::<f64>()
        / (fit_rows.len() * nc) as f64;
    // Observations less F's time-dependent effects (F with the source's volume and the latent
    // effects at zero), standardised and projected off F's Jacobian.
    let mut p0 = vec![0.0; np];
    p0[..3].copy_from_slice(&main);
    let block = |days: Vec<f64>, rows: &[Day]| -> Result<Block> {
        let r: Vec<Vec<f64>> = rows
            .par_iter()
            .zip(days.par_iter())
            .map(|(d, t)| {
                let mut f = vec![0.0; nc];
                magic_core::invert::forward(model, &p0, *t, &mut f)
                    .map_err(|e| anyhow!("day {t}: {e}"))?;
                let row: Vec<f64> = (0..nc).map(|c| (d.obs[c] - f[c]) / data.scale[c]).collect();
                Ok(project_with(&tangent, &row))
            })
            .collect::<Result<_>>()?;
        Ok(Block {
            days,
            r: r.concat(),
        })
    };
    let mut fit = block(fit_days, &fit_rows)?;
    let mut held = Block::default();
    for name in ["train", "valid", "test"] {
        if name != split {
            let (days, rows) = invert_split(name)?;
            let b = block(days, &rows)?;
            held.days.extend(b.days);
            held.r.extend(b.r);
        }
    }
    let t_n = fit.len(nc);
    let mut mean = vec![0.0; nc];
    for row in fit.r.chunks(nc) {
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v;
        }
    }
    mean.iter_mut().for_each(|m| *m /= t_n as f64);
    for b in [&mut fit, &mut held] {
        for row in b.r.chunks_mut(nc) {
            for (v, m) in row.iter_mut().zip(&mean) {
                *v -= m;
            }
        }
    }
    Ok(Residuals {
        names: data.names.clone(),
        stations: data.stations.clone(),
        scale: data.scale.clone(),
        fit,
        held,
        mean,
        mse,
        main_source: main,
        tangent,
    })
}

fn project_with(basis: &[Vec<f64>], g: &[f64]) -> Vec<f64> {
    let mut out = g.to_vec();
    for q in basis {
        let d: f64 = q.iter().zip(&out).map(|(a, b)| a * b).sum();
        for (o, v) in out.iter_mut().zip(q) {
            *o -= d * v;
        }
    }
    out
}

/// Orthonormal basis of the columns of F's Jacobian (standardised units) at the main source's
/// typical position with a unit volume change (the span does not depend on the volume) and the
/// latent effects at zero (they enter linearly).
fn tangent_basis(
    model: &Model<'_>,
    data: &GnssData,
    main: [f64; 3],
    day: f64,
) -> Result<Vec<Vec<f64>>> {
    const N: usize = magic_core::model_file::MAX_PARAMS;
    let np = model.n_params();
    let nc = data.n_obs();
    let mut p = [magic_core::Dual::<N>::var(0.0, 0); N];
    for (j, v) in p.iter_mut().enumerate().take(np) {
        let x = match j {
            0..=2 => main[j],
            3 => 1.0,
            _ => 0.0,
        };
        *v = magic_core::Dual::var(x, j);
    }
    let mut out = vec![magic_core::Dual::<N>::var(0.0, 0); nc];
    for o in out.iter_mut() {
        *o = magic_core::Dual::var(0.0, N - 1);
        o.d = [0.0; N];
    }
    magic_core::invert::forward(model, &p[..np], day, &mut out)
        .map_err(|e| anyhow!("F's Jacobian: {e}"))?;
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for j in 0..np {
        let mut v: Vec<f64> = (0..nc).map(|c| out[c].d[j] / data.scale[c]).collect();
        for q in &basis {
            let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
            for (x, y) in v.iter_mut().zip(q) {
                *x -= d * y;
            }
        }
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let scale = (0..nc)
            .map(|c| out[c].d[j].abs() / data.scale[c])
            .fold(0.0, f64::max);
        if n > 1e-9 * scale.max(1e-300) && n > 0.0 {
            v.iter_mut().for_each(|x| *x /= n);
            basis.push(v);
        }
    }
    Ok(basis)
}

/// Median position of the source over the days with the largest |ΔV| (the top quarter).
fn main_source(p: &[[f64; 4]]) -> [f64; 3] {
    let mut by_dv: Vec<&[f64; 4]> = p.iter().collect();
    by_dv.sort_by(|a, b| b[3].abs().total_cmp(&a[3].abs()));
    let top = &by_dv[..(by_dv.len() / 4).max(1)];
    core::array::from_fn(|k| median(&mut top.iter().map(|q| q[k]).collect::<Vec<_>>()))
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos - pos.floor());
    if i + 1 < s.len() {
        s[i] * (1.0 - f) + s[i + 1] * f
    } else {
        s[i]
    }
}

fn sd(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

fn date(day: f64) -> String {
    crate::synth::iso_date(day.round() as i64)
}

// ---------------------------------------------------------------------------------------------
// Latent families: leave one station out, neighbouring days.

/// Cross products of the residuals with their neighbour means: `c = Σₜ rₜ mₜᵀ`, `m = Σₜ mₜ mₜᵀ`,
/// where `mₜ` is the mean of the rows within ±w of t, t excluded.
struct Cross {
    nc: usize,
    c: Vec<f64>,
    m: Vec<f64>,
}

fn cross(r: &[f64], nc: usize, w: usize) -> Cross {
    let t_n = r.len() / nc;
    let mut pre = vec![0.0; (t_n + 1) * nc];
    for t in 0..t_n {
        for c in 0..nc {
            pre[(t + 1) * nc + c] = pre[t * nc + c] + r[t * nc + c];
        }
    }
    let (mut cm, mut mm) = (vec![0.0; nc * nc], vec![0.0; nc * nc]);
    let mut m = vec![0.0; nc];
    for t in 0..t_n {
        let (lo, hi) = (t.saturating_sub(w), (t + w + 1).min(t_n));
        let k = (hi - lo - 1) as f64;
        let row = &r[t * nc..(t + 1) * nc];
        for c in 0..nc {
            m[c] = (pre[hi * nc + c] - pre[lo * nc + c] - row[c]) / k;
        }
        for a in 0..nc {
            let (ra, ma) = (row[a], m[a]);
            let (crow, mrow) = (&mut cm[a * nc..(a + 1) * nc], &mut mm[a * nc..(a + 1) * nc]);
            for b in 0..nc {
                crow[b] += ra * m[b];
                mrow[b] += ma * m[b];
            }
        }
    }
    Cross { nc, c: cm, m: mm }
}

/// Leave-one-station-out prediction of every channel c of station i by `g_c · â`, â fitted
/// (least squares) to the neighbour means of the other stations' channels: returns
/// `(Σ r·p, Σ p²)` over days and channels.
fn loso_ab(g: &[f64], x: &Cross, ns: usize) -> (f64, f64) {
    let nc = x.nc;
    let mut mg = vec![0.0; nc];
    let mut cg = vec![0.0; nc];
    for a in 0..nc {
        let (mut s1, mut s2) = (0.0, 0.0);
        for b in 0..nc {
            s1 += x.m[a * nc + b] * g[b];
            s2 += x.c[a * nc + b] * g[b];
        }
        mg[a] = s1;
        cg[a] = s2;
    }
    let gmg: f64 = g.iter().zip(&mg).map(|(a, b)| a * b).sum();
    let gg: f64 = g.iter().map(|v| v * v).sum();
    let (mut sa, mut sb) = (0.0, 0.0);
    if gg < DECLARED_NORM2 {
        return (0.0, 0.0);
    }
    for i in 0..ns {
        let ci: Vec<usize> = (0..nc / ns).map(|k| k * ns + i).collect();
        let own: f64 = ci.iter().map(|&c| g[c] * g[c]).sum();
        if own == 0.0 {
            continue;
        }
        let n = gg - own;
        if n <= 1e-12 * gg {
            continue;
        }
        let mut umu = gmg;
        for &a in &ci {
            umu -= 2.0 * g[a] * mg[a];
            for &b in &ci {
                umu += g[a] * g[b] * x.m[a * nc + b];
            }
        }
        for &a in &ci {
            let mut cu = cg[a];
            for &b in &ci {
                cu -= x.c[a * nc + b] * g[b];
            }
            sa += g[a] * cu / n;
            sb += g[a] * g[a] * umu / (n * n);
        }
    }
    (sa, sb)
}

/// Reduction of the squared residual by a prediction scaled by its least-squares weight λ ≥ 0:
/// `max(0, Σ r·p)² / Σ p²`. One fitted scalar per prediction; the surrogates fit it too.
fn weighted_gain((a, b): (f64, f64)) -> f64 {
    if a > 0.0 && b > 0.0 {
        a * a / b
    } else {
        0.0
    }
}

fn loso_gain(g: &[f64], x: &Cross, ns: usize) -> f64 {
    weighted_gain(loso_ab(g, x, ns))
}

/// Common-mode patterns: one per component, 1 mm on every station of it (standardised units,
/// projected off F's Jacobian like every latent pattern).
fn cm_patterns(res: &Residuals) -> Vec<Vec<f64>> {
    let (ns, nc) = (res.ns(), res.nc());
    (0..nc / ns)
        .map(|k| {
            res.project(
                &(0..nc)
                    .map(|c| if c / ns == k { 1.0 / res.scale[c] } else { 0.0 })
                    .collect::<Vec<_>>(),
            )
        })
        .collect()
}

fn z_ref(res: &Residuals) -> f64 {
    res.stations.iter().map(|s| s.z_km).sum::<f64>() / res.ns() as f64
}

/// Elevation pattern: `zᵢ − z̄` mm per (mm/km) on the vertical channels (projected).
fn elev_pattern(res: &Residuals) -> Vec<f64> {
    let (ns, nc) = (res.ns(), res.nc());
    let z0 = z_ref(res);
    res.project(
        &(0..nc)
            .map(|c| {
                if c / ns == 2 {
                    (res.stations[c % ns].z_km - z0) / res.scale[c]
                } else {
                    0.0
                }
            })
            .collect::<Vec<_>>(),
    )
}

/// Mogi pattern of a unit volume change at `p = (x, y, depth)` (standardised units, projected).
fn source_pattern(res: &Residuals, p: [f64; 3]) -> Vec<f64> {
    let mut u = vec![0.0; res.nc()];
    if mogi::field(&res.stations, &[p[0], p[1], p[2], 1.0], &mut u).is_err() {
        return vec![0.0; res.nc()];
    }
    res.project(
        &u.iter()
            .zip(&res.scale)
            .map(|(v, s)| v / s)
            .collect::<Vec<_>>(),
    )
}

/// The second-source search grid (x, y over the network ± 3 km, depths 2–15 km: a shallower
/// source is seen by one station only, indistinguishable from that station's own noise), without
/// the neighbourhood of the main source.
fn source_grid(res: &Residuals) -> Vec<[f64; 3]> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in &res.stations {
        x0 = x0.min(s.x_km);
        x1 = x1.max(s.x_km);
        y0 = y0.min(s.y_km);
        y1 = y1.max(s.y_km);
    }
    let depths = [3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0, 15.0];
    let mut out = Vec::new();
    let mut x = (x0 - 1.0).floor();
    while x <= x1 + 1.0 {
        let mut y = (y0 - 1.0).floor();
        while y <= y1 + 1.0 {
            if (x - res.main_source[0]).hypot(y - res.main_source[1]) >= MAIN_SOURCE_EXCLUSION_KM {
                for d in depths {
                    out.push([x, y, d]);
                }
            }
            y += 1.0;
        }
        x += 1.0;
    }
    out
}

/// Local pattern search of a second-source position maximising `score`, from `p`.
fn refine_source(
    res: &Residuals,
    grid: &[[f64; 3]],
    mut best: [f64; 3],
    mut bg: f64,
    score: &dyn Fn(&[f64]) -> f64,
) -> ([f64; 3], f64) {
    let (lo, hi) = grid
        .iter()
        .fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), p| {
            (
                core::array::from_fn(|k| lo[k].min(p[k])),
                core::array::from_fn(|k| hi[k].max(p[k])),
            )
        });
    let allowed = |p: &[f64; 3]| {
        (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k])
            && (p[0] - res.main_source[0]).hypot(p[1] - res.main_source[1])
                >= MAIN_SOURCE_EXCLUSION_KM
    };
    let mut step = 0.5;
    while step >= 0.1 {
        let mut moved = true;
        while moved {
            moved = false;
            for k in 0..3 {
                for sgn in [-1.0, 1.0] {
                    let mut q = best;
                    q[k] += sgn * step;
                    if !allowed(&q) {
                        continue;
                    }
                    let v = score(&source_pattern(res, q));
                    if v > bg {
                        bg = v;
                        best = q;
                        moved = true;
                    }
                }
            }
        }
        step /= 2.0;
    }
    (best, bg)
}

/// Candidates refined in the second-source search.
const SOURCE_CANDIDATES: usize = 6;

/// A fitted second source: position, neighbour window and score.
#[derive(Clone, Copy, Debug, Default)]
struct SourceFit {
    pos: [f64; 3],
    w: usize,
    gain: f64,
}

/// The second-source search: every grid position scored over the whole split (cross products),
/// the best few (distinct) refined locally.
fn search_source(
    res: &Residuals,
    xs: &[(usize, Cross)],
    grid: &[[f64; 3]],
    patterns: &[Vec<f64>],
) -> SourceFit {
    let ns = res.ns();
    let mut cand: Vec<(f64, usize, usize)> = Vec::new();
    for (wi, (_, x)) in xs.iter().enumerate() {
        for (pi, g) in patterns.iter().enumerate() {
            cand.push((loso_gain(g, x, ns), wi, pi));
        }
    }
    cand.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut chosen: Vec<(f64, usize, usize)> = Vec::new();
    for c in cand {
        if chosen.len() >= SOURCE_CANDIDATES {
            break;
        }
        let p = grid[c.2];
        if chosen
            .iter()
            .all(|d| (grid[d.2][0] - p[0]).hypot(grid[d.2][1] - p[1]) >= 2.0)
        {
            chosen.push(c);
        }
    }
    let mut best = SourceFit::default();
    for (g0, wi, pi) in chosen {
        let (w, x) = &xs[wi];
        let (pos, gain) = refine_source(res, grid, grid[pi], g0, &|g| loso_gain(g, x, ns));
        if gain > best.gain {
            best = SourceFit { pos, w: *w, gain };
        }
    }
    best
}

/// Scores of the three latent families on one residual matrix: for each, the best over the
/// neighbour windows [`NEIGHBOUR_WINDOWS`] (the window is part of the fit; the surrogates choose
/// theirs too).
struct LatentScores {
    cm: (f64, usize),
    elev: (f64, usize),
    ss: SourceFit,
}

fn latent_scores(
    res: &Residuals,
    r: &[f64],
    grid: &[[f64; 3]],
    patterns: &[Vec<f64>],
    cm_p: &[Vec<f64>],
    el_p: &[f64],
) -> LatentScores {
    let ns = res.ns();
    // Scored on the variations faster than about two years (see `LATENT_HIGHPASS_DAYS`).
    let r = &highpass(r, res.nc(), LATENT_HIGHPASS_DAYS);
    let xs: Vec<(usize, Cross)> = NEIGHBOUR_WINDOWS
        .iter()
        .map(|&w| (w, cross(r, res.nc(), w)))
        .collect();
    let mut out = LatentScores {
        cm: (0.0, 0),
        elev: (0.0, 0),
        ss: SourceFit::default(),
    };
    for (w, x) in &xs {
        let cm: f64 = cm_p.iter().map(|g| loso_gain(g, x, ns)).sum();
        if cm > out.cm.0 || out.cm.1 == 0 {
            out.cm = (cm, *w);
        }
        let elev = loso_gain(el_p, x, ns);
        if elev > out.elev.0 || out.elev.1 == 0 {
            out.elev = (elev, *w);
        }
    }
    if !grid.is_empty() {
        out.ss = search_source(res, &xs, grid, patterns);
    }
    out
}

/// Every channel less its running mean over ±h days (the mean of the days available at the ends):
/// variations slower than about 2h days removed, faster ones kept.
fn highpass(r: &[f64], nc: usize, h: usize) -> Vec<f64> {
    let t_n = r.len() / nc;
    let mut pre = vec![0.0; (t_n + 1) * nc];
    for t in 0..t_n {
        for c in 0..nc {
            pre[(t + 1) * nc + c] = pre[t * nc + c] + r[t * nc + c];
        }
    }
    let mut out = r.to_vec();
    for t in 0..t_n {
        let (lo, hi) = (t.saturating_sub(h), (t + h + 1).min(t_n));
        let k = (hi - lo) as f64;
        for c in 0..nc {
            out[t * nc + c] -= (pre[hi * nc + c] - pre[lo * nc + c]) / k;
        }
    }
    out
}

/// Every station's channels multiplied by a random sign and, at random, reversed in time (not all
/// stations given the same transform, which would keep the network's coherence).
fn flip_reverse(r: &[f64], nc: usize, ns: usize, rng: &mut StdRng) -> Vec<f64> {
    let t_n = r.len() / nc;
    let mut ops: Vec<(f64, bool)> = Vec::new();
    while ops.is_empty() || ops.iter().all(|o| *o == ops[0]) {
        ops = (0..ns)
            .map(|_| {
                (
                    if rng.random::<bool>() { 1.0 } else { -1.0 },
                    rng.random::<bool>(),
                )
            })
            .collect();
    }
    let mut out = vec![0.0; r.len()];
    for t in 0..t_n {
        for c in 0..nc {
            let (sign, rev) = ops[c % ns];
            out[t * nc + c] = sign * r[(if rev { t_n - 1 - t } else { t }) * nc + c];
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Fitted families: per-channel functions of the date, fitted on the split, scored on the others.

/// Solves the symmetric positive system `a x = b` (n × n, row-major) in place; `b` becomes x.
fn solve(a: &mut [f64], b: &mut [f64], n: usize) -> bool {
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))
            .unwrap_or(k);
        if a[p * n + k].abs() < 1e-300 {
            return false;
        }
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
            b.swap(k, p);
        }
        for i in k + 1..n {
            let f = a[i * n + k] / a[k * n + k];
            for j in k..n {
                a[i * n + j] -= f * a[k * n + j];
            }
            b[i] -= f * b[k];
        }
    }
    for k in (0..n).rev() {
        let mut s = b[k];
        for j in k + 1..n {
            s -= a[k * n + j] * b[j];
        }
        b[k] = s / a[k * n + k];
    }
    true
}

/// Least squares of every channel on a basis shared by all channels (`basis(day)` values, a
/// constant included by the caller): coefficients per channel.
fn fit_basis(
    r: &[f64],
    days: &[f64],
    nc: usize,
    nb: usize,
    basis: &dyn Fn(f64, &mut [f64]),
) -> Vec<Vec<f64>> {
    let mut ata = vec![0.0; nb * nb];
    let mut atr = vec![0.0; nb * nc];
    let mut b = vec![0.0; nb];
    for (t, &d) in days.iter().enumerate() {
        basis(d, &mut b);
        for i in 0..nb {
            for j in 0..nb {
                ata[i * nb + j] += b[i] * b[j];
            }
            for c in 0..nc {
                atr[i * nc + c] += b[i] * r[t * nc + c];
            }
        }
    }
    (0..nc)
        .map(|c| {
            let mut a = ata.clone();
            let mut x: Vec<f64> = (0..nb).map(|i| atr[i * nc + c]).collect();
            if solve(&mut a, &mut x, nb) {
                x
            } else {
                vec![0.0; nb]
            }
        })
        .collect()
}

/// `(Σ r·p, Σ p², Σ r²)` of a fitted family's prediction over `block`, the residuals taken
/// relative to `level` (the channel means of the rows the family was fitted on); only the
/// channels the family predicts count in the first two sums.
fn ab_on(block: &Block, nc: usize, f: &dyn TimeFit, level: &[f64]) -> (f64, f64, f64) {
    let (mut a, mut b, mut v) = (0.0, 0.0, 0.0);
    for (t, &d) in block.days.iter().enumerate() {
        for c in 0..nc {
            let r = block.r[t * nc + c] - level[c];
            v += r * r;
            if f.active(c) {
                let p = f.predict(c, d);
                a += r * p;
                b += p * p;
            }
        }
    }
    (a, b, v)
}

/// Number of contiguous folds of the analysed split in the fitted families' cross-validation.
pub const FOLDS: usize = 5;

/// Cross-validated score of a fitted family: fitted on the split without each of [`FOLDS`]
/// contiguous blocks and scored on the block left out, and fitted on the whole split and scored
/// on the held-out days of the other splits. Returns the share of the variance of all the scored
/// days explained by the predictions, scaled by one least-squares weight.
fn cv_score(
    fit: &Block,
    held: Option<&Block>,
    nc: usize,
    refit: &dyn Fn(&Block) -> Box<dyn TimeFit>,
) -> f64 {
    let t_n = fit.days.len();
    let (mut a, mut b, mut v) = (0.0, 0.0, 0.0);
    for j in 0..FOLDS {
        let (lo, hi) = (j * t_n / FOLDS, (j + 1) * t_n / FOLDS);
        let train = Block {
            days: fit.days[..lo]
                .iter()
                .chain(&fit.days[hi..])
                .copied()
                .collect(),
            r: fit.r[..lo * nc]
                .iter()
                .chain(&fit.r[hi * nc..])
                .copied()
                .collect(),
        };
        let test = Block {
            days: fit.days[lo..hi].to_vec(),
            r: fit.r[lo * nc..hi * nc].to_vec(),
        };
        let mut level = vec![0.0; nc];
        for row in train.r.chunks(nc) {
            for (l, x) in level.iter_mut().zip(row) {
                *l += x / train.days.len() as f64;
            }
        }
        let f = refit(&train);
        let (da, db, dv) = ab_on(&test, nc, f.as_ref(), &level);
        a += da;
        b += db;
        v += dv;
    }
    if let Some(h) = held {
        let f = refit(fit);
        let (da, db, dv) = ab_on(h, nc, f.as_ref(), &vec![0.0; nc]);
        a += da;
        b += db;
        v += dv;
    }
    weighted_gain((a, b)) / v
}

const W_YEAR: f64 = std::f64::consts::TAU / 365.25;

fn seasonal_basis(d: f64, b: &mut [f64]) {
    let w = W_YEAR * d;
    b[0] = 1.0;
    b[1] = w.sin();
    b[2] = w.cos();
    b[3] = (2.0 * w).sin();
    b[4] = (2.0 * w).cos();
}

/// A fitted family: its prediction of channel c on a day, as a deviation from the channel's mean
/// over the rows it was fitted on (0 for channels it leaves alone).
trait TimeFit: Sync {
    fn predict(&self, c: usize, day: f64) -> f64;
    /// Whether the family predicts channel c.
    fn active(&self, _c: usize) -> bool {
        true
    }
}

struct SeasonalFit {
    coef: Vec<Vec<f64>>,
    /// Mean of each basis function over the fitted rows.
    mean_basis: [f64; 5],
}

impl TimeFit for SeasonalFit {
    fn predict(&self, c: usize, d: f64) -> f64 {
        let mut b = [0.0; 5];
        seasonal_basis(d, &mut b);
        (1..5)
            .map(|j| self.coef[c][j] * (b[j] - self.mean_basis[j]))
            .sum()
    }
}

fn fit_seasonal(b: &Block, nc: usize) -> SeasonalFit {
    let mut mean_basis = [0.0; 5];
    let mut v = [0.0; 5];
    for &d in &b.days {
        seasonal_basis(d, &mut v);
        for j in 0..5 {
            mean_basis[j] += v[j] / b.days.len() as f64;
        }
    }
    SeasonalFit {
        coef: fit_basis(&b.r, &b.days, nc, 5, &seasonal_basis),
        mean_basis,
    }
}

/// The values `v` (standardised) on `chans` whose projection, `P⊥ E v` with `E` the injection of
/// those channels, equals `d` on them: `(Eᵀ P⊥ E) v = d`. A family fitted channel by channel on
/// projected residuals sees only `Eᵀ P⊥ E v`; this undoes that so the effect's constants are
/// those that, added to F, reproduce the fit. Falls back to `d` when the channels are almost
/// inside F's tangent space (the effect is then mostly absorbed by the encoder anyway).
fn deproject(tangent: &[Vec<f64>], chans: &[usize], d: &[f64]) -> Vec<f64> {
    let n = chans.len();
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        m[i * n + i] = 1.0;
    }
    for q in tangent {
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] -= q[chans[i]] * q[chans[j]];
            }
        }
    }
    let mut v = d.to_vec();
    let norm = |x: &[f64]| x.iter().map(|a| a * a).sum::<f64>().sqrt();
    if solve(&mut m, &mut v, n) && norm(&v) <= 5.0 * norm(d) {
        v
    } else {
        d.to_vec()
    }
}

/// `P⊥ E v`: the projected response on all channels of values `v` on `chans`.
fn projected_response(tangent: &[Vec<f64>], nc: usize, chans: &[usize], v: &[f64]) -> Vec<f64> {
    let mut full = vec![0.0; nc];
    for (c, x) in chans.iter().zip(v) {
        full[*c] = *x;
    }
    project_with(tangent, &full)
}

struct DriftFit {
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

fn fit_drift(b: &Block, scale: &[f64], ns: usize, tangent: &[Vec<f64>]) -> DriftFit {
    let nc = scale.len();
    let t0 = b.days.iter().sum::<f64>() / b.days.len().max(1) as f64;
    let coef: Vec<[f64; 2]> = fit_basis(&b.r, &b.days, nc, 2, &|d, v: &mut [f64]| {
        v[0] = 1.0;
        v[1] = (d - t0) / 365.25;
    })
    .into_iter()
    .map(|x| [x[0], x[1]])
    .collect();
    // A drift at one or a few stations: stations whose rates (mm/yr) are outliers among the
    // network's (robust z per component from the median absolute deviation over stations, summed
    // in squares over the components).
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
        .filter(|&i| z2[i] > DRIFT_Z2)
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

struct StepFit {
    station: usize,
    epoch: f64,
    /// Offsets (standardised units) of the station's channels, E N U, de-projected.
    offset: Vec<f64>,
    /// Projected response of the step on every channel.
    response: Vec<f64>,
    /// Share of the fitted rows on or after the epoch (the step has zero mean over them).
    frac_after: f64,
    stat: f64,
}

impl TimeFit for StepFit {
    fn predict(&self, c: usize, d: f64) -> f64 {
        self.response[c] * (if d >= self.epoch { 1.0 } else { 0.0 } - self.frac_after)
    }
    fn active(&self, c: usize) -> bool {
        self.response[c] != 0.0
    }
}

/// The step scan: for every station and epoch, the difference of the means of the
/// [`STEP_SCAN_DAYS`] rows after and before, normalised per channel by its typical (median)
/// value over epochs; the largest sum over the station's channels wins. The offset is then
/// the least-squares one of a two-level fit (mean after the epoch minus mean before).
fn fit_step(b: &Block, nc: usize, ns: usize, tangent: &[Vec<f64>]) -> StepFit {
    let t_n = b.days.len();
    let w = STEP_SCAN_DAYS.min(t_n / 4).max(1);
    let nk = nc / ns;
    let mut pre = vec![0.0; (t_n + 1) * nc];
    for t in 0..t_n {
        for c in 0..nc {
            pre[(t + 1) * nc + c] = pre[t * nc + c] + b.r[t * nc + c];
        }
    }
    let mean =
        |c: usize, a: usize, z: usize| (pre[z * nc + c] - pre[a * nc + c]) / (z - a).max(1) as f64;
    let best = (0..ns)
        .into_par_iter()
        .map(|i| {
            let chans: Vec<usize> = (0..nk).map(|k| k * ns + i).collect();
            let d: Vec<Vec<f64>> = chans
                .iter()
                .map(|&c| {
                    (w..=t_n - w)
                        .map(|e| mean(c, e, e + w) - mean(c, e - w, e))
                        .collect()
                })
                .collect();
            let norm: Vec<f64> = d
                .iter()
                .map(|v| {
                    (median(&mut v.iter().map(|x| x * x).collect::<Vec<_>>()) / 0.4549).max(1e-30)
                })
                .collect();
            let mut bi = (0usize, f64::MIN);
            for j in 0..d[0].len() {
                let s: f64 = (0..nk).map(|k| d[k][j] * d[k][j] / norm[k]).sum();
                if s > bi.1 {
                    bi = (j + w, s);
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
        .map(|&c| mean(c, e, t_n) - mean(c, 0, e))
        .collect();
    let offset = deproject(tangent, &chans, &d);
    let response = projected_response(tangent, nc, &chans, &offset);
    let frac_after = (t_n - e) as f64 / t_n as f64;
    StepFit {
        station,
        epoch: b.days[e],
        offset,
        response,
        frac_after,
        stat,
    }
}

/// Complex numbers and FFTs of any length (radix 2, Bluestein for the others).
mod fft {
    #[derive(Clone, Copy, Debug, Default)]
    pub struct Cx {
        pub re: f64,
        pub im: f64,
    }

    impl Cx {
        pub fn new(re: f64, im: f64) -> Cx {
            Cx { re, im }
        }
        pub fn mul(self, o: Cx) -> Cx {
            Cx::new(
                self.re * o.re - self.im * o.im,
                self.re * o.im + self.im * o.re,
            )
        }
        pub fn conj(self) -> Cx {
            Cx::new(self.re, -self.im)
        }
    }

    /// In-place radix-2 FFT (length a power of two), forward sign −.
    pub fn pow2(a: &mut [Cx]) {
        let n = a.len();
        let mut j = 0;
        for i in 1..n {
            let mut bit = n >> 1;
            while j & bit != 0 {
                j ^= bit;
                bit >>= 1;
            }
            j |= bit;
            if i < j {
                a.swap(i, j);
            }
        }
        let mut len = 2;
        while len <= n {
            let ang = -std::f64::consts::TAU / len as f64;
            let wl = Cx::new(ang.cos(), ang.sin());
            for s in (0..n).step_by(len) {
                let mut w = Cx::new(1.0, 0.0);
                for k in 0..len / 2 {
                    let u = a[s + k];
                    let v = a[s + k + len / 2].mul(w);
                    a[s + k] = Cx::new(u.re + v.re, u.im + v.im);
                    a[s + k + len / 2] = Cx::new(u.re - v.re, u.im - v.im);
                    w = w.mul(wl);
                }
            }
            len <<= 1;
        }
    }

    /// A forward DFT of a fixed length n (Bluestein's chirp-z transform).
    pub struct Plan {
        n: usize,
        m: usize,
        chirp: Vec<Cx>,
        kernel: Vec<Cx>,
    }

    impl Plan {
        pub fn new(n: usize) -> Plan {
            let m = (2 * n - 1).next_power_of_two();
            // w_k = exp(iπ k² / n), k² taken modulo 2n for precision.
            let chirp: Vec<Cx> = (0..n)
                .map(|k| {
                    let k2 = (k as u128 * k as u128 % (2 * n as u128)) as f64;
                    let a = std::f64::consts::PI * k2 / n as f64;
                    Cx::new(a.cos(), a.sin())
                })
                .collect();
            let mut kernel = vec![Cx::default(); m];
            for k in 0..n {
                kernel[k] = chirp[k];
                if k > 0 {
                    kernel[m - k] = chirp[k];
                }
            }
            pow2(&mut kernel);
            Plan {
                n,
                m,
                chirp,
                kernel,
            }
        }

        /// Forward DFT: X_k = Σ x_j exp(−2πi jk/n).
        pub fn forward(&self, x: &[Cx]) -> Vec<Cx> {
            let mut a = vec![Cx::default(); self.m];
            for k in 0..self.n {
                a[k] = x[k].mul(self.chirp[k].conj());
            }
            pow2(&mut a);
            for (v, k) in a.iter_mut().zip(&self.kernel) {
                *v = v.mul(*k);
            }
            // Inverse FFT of length m through conjugation.
            for v in a.iter_mut() {
                *v = v.conj();
            }
            pow2(&mut a);
            let s = 1.0 / self.m as f64;
            (0..self.n)
                .map(|k| Cx::new(a[k].re * s, -a[k].im * s).mul(self.chirp[k].conj()))
                .collect()
        }

        /// Inverse DFT: x_j = (1/n) Σ X_k exp(2πi jk/n).
        pub fn inverse(&self, x: &[Cx]) -> Vec<Cx> {
            let c: Vec<Cx> = x.iter().map(|v| v.conj()).collect();
            let s = 1.0 / self.n as f64;
            self.forward(&c)
                .into_iter()
                .map(|v| Cx::new(v.re * s, -v.im * s))
                .collect()
        }
    }
}

/// Phase-randomised surrogates of a block's rows (one random phase per frequency, shared by
/// all channels: each channel's spectrum and every cross-spectrum are kept).
struct PhaseSurrogates {
    nc: usize,
    n: usize,
    plan: fft::Plan,
    spectra: Vec<Vec<fft::Cx>>,
}

impl PhaseSurrogates {
    fn new(r: &[f64], nc: usize) -> PhaseSurrogates {
        let n = r.len() / nc;
        let plan = fft::Plan::new(n);
        let spectra = (0..nc)
            .into_par_iter()
            .map(|c| {
                plan.forward(
                    &(0..n)
                        .map(|t| fft::Cx::new(r[t * nc + c], 0.0))
                        .collect::<Vec<_>>(),
                )
            })
            .collect();
        PhaseSurrogates {
            nc,
            n,
            plan,
            spectra,
        }
    }

    /// One surrogate: a random phase per frequency shared by all channels.
    fn draw(&self, rng: &mut StdRng) -> Vec<f64> {
        self.draw_grouped(rng, 1, &|_| 0)
    }

    /// One surrogate with independent random phases for each of `groups` groups of channels
    /// (`group(c)`): spectra and cross-spectra within a group are kept, groups become independent.
    fn draw_grouped(
        &self,
        rng: &mut StdRng,
        groups: usize,
        group: &dyn Fn(usize) -> usize,
    ) -> Vec<f64> {
        let n = self.n;
        let rots: Vec<Vec<fft::Cx>> = (0..groups)
            .map(|_| {
                let rot: Vec<fft::Cx> = (0..n)
                    .map(|k| {
                        if k == 0 || 2 * k == n {
                            fft::Cx::new(1.0, 0.0)
                        } else {
                            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                            fft::Cx::new(a.cos(), a.sin())
                        }
                    })
                    .collect();
                (0..n)
                    .map(|k| if 2 * k > n { rot[n - k].conj() } else { rot[k] })
                    .collect()
            })
            .collect();
        let mut out = vec![0.0; n * self.nc];
        // Two real channels per complex inverse transform.
        for c0 in (0..self.nc).step_by(2) {
            let c1 = (c0 + 1 < self.nc).then_some(c0 + 1);
            let (r0, r1) = (&rots[group(c0)], c1.map(|c| &rots[group(c)]));
            let spec: Vec<fft::Cx> = (0..n)
                .map(|k| {
                    let a = self.spectra[c0][k].mul(r0[k]);
                    let b = match (c1, r1) {
                        (Some(c), Some(r)) => self.spectra[c][k].mul(r[k]),
                        _ => fft::Cx::default(),
                    };
                    fft::Cx::new(a.re - b.im, a.im + b.re)
                })
                .collect();
            let y = self.plan.inverse(&spec);
            for t in 0..n {
                out[t * self.nc + c0] = y[t].re;
                if let Some(c) = c1 {
                    out[t * self.nc + c] = y[t].im;
                }
            }
        }
        out
    }
}

fn remove(b: &Block, nc: usize, f: &dyn TimeFit) -> Vec<f64> {
    let mut r = b.r.clone();
    for (t, &d) in b.days.iter().enumerate() {
        for c in 0..nc {
            r[t * nc + c] -= f.predict(c, d);
        }
    }
    r
}

// ---------------------------------------------------------------------------------------------

/// Fits every family to the residuals of `model` on `data` and ranks them by their excess over
/// chance.
pub fn analyse(model: &Model<'_>, data: &GnssData, opts: &AnalysisOptions) -> Result<Analysis> {
    let start = std::time::Instant::now();
    let res = residuals(model, data, &opts.split)?;
    let mut a = analyse_residuals(&res, opts)?;
    a.split = opts.split.clone();
    a.seconds = start.elapsed().as_secs_f64();
    Ok(a)
}

/// [`analyse`] on residuals already computed.
pub fn analyse_residuals(res: &Residuals, opts: &AnalysisOptions) -> Result<Analysis> {
    let start = std::time::Instant::now();
    let (ns, nc) = (res.ns(), res.nc());
    if nc != 3 * ns {
        bail!("expected 3 channels per station");
    }
    let fit = &res.fit;
    let t_n = fit.len(nc);
    let total_fit: f64 = fit.r.iter().map(|v| v * v).sum();
    // Fitted families are scored on the other splits, or in-sample without them.
    let held = if res.held.days.len() >= 30 {
        &res.held
    } else {
        fit
    };
    let n_sur = opts.surrogates.max(2);
    let seeds: Vec<u64> = {
        let mut rng = StdRng::seed_from_u64(opts.seed ^ 0xA11A_0517);
        (0..4 * n_sur).map(|_| rng.random()).collect()
    };

    // Latent families.
    let grid = source_grid(res);
    let patterns: Vec<Vec<f64>> = grid.par_iter().map(|p| source_pattern(res, *p)).collect();
    let cm_p = cm_patterns(res);
    let el_p = elev_pattern(res);
    // The latent families compare projected patterns with projected residuals: the part of the
    // residual F could produce by adjusting its variables is the encoder's business.
    let fit_perp = fit.r.clone();
    let real = latent_scores(res, &fit_perp, &grid, &patterns, &cm_p, &el_p);
    // Surrogates: the family's daily fit removed, then every station's series (its three
    // components together) multiplied by a random sign and run forwards or backwards in time,
    // then projected again like the residuals themselves. For noise that is Gaussian, stationary
    // and independent between stations each such transform is as likely as the data, so the
    // chance level is exact without any model of the noise's spectrum (randomising phases or
    // shifting series circularly both break the long-range structure of red noise and make
    // chance coherence look rarer than it is).
    let removed = |gs: &[Vec<f64>]| -> Vec<f64> {
        let mut r = fit_perp.clone();
        for g in gs {
            let a = daily_amplitude(&r, nc, g);
            for (row, at) in r.chunks_mut(nc).zip(&a) {
                row.iter_mut().zip(g).for_each(|(x, gc)| *x -= at * gc);
            }
        }
        r
    };
    let latent_chance =
        |base: Vec<f64>, seeds: &[u64], score: &(dyn Fn(&[f64]) -> f64 + Sync)| -> Vec<f64> {
            seeds
                .par_iter()
                .map(|s| {
                    let mut rng = StdRng::seed_from_u64(*s);
                    let r = flip_reverse(&base, nc, ns, &mut rng);
                    score(&res.project_rows(&r)) / total_fit
                })
                .collect()
        };
    let seeds_l: Vec<u64> = seeds[..n_sur].iter().map(|s| s ^ 0x5151).collect();
    let cm_ch = latent_chance(removed(&cm_p), &seeds_l, &|r| {
        latent_scores(res, r, &[], &[], &cm_p, &el_p).cm.0
    });
    let el_ch = latent_chance(removed(std::slice::from_ref(&el_p)), &seeds_l, &|r| {
        latent_scores(res, r, &[], &[], &[], &el_p).elev.0
    });
    let ss_ch = latent_chance(
        removed(&[source_pattern(res, real.ss.pos)]),
        &seeds[..n_sur],
        &|r| latent_scores(res, r, &grid, &patterns, &[], &el_p).ss.gain,
    );

    // Fitted families.
    let seas = fit_seasonal(fit, nc);
    let sc = &seas.coef;
    let drift = fit_drift(fit, &res.scale, ns, &res.tangent);
    let step = fit_step(fit, nc, ns, &res.tangent);
    let held_opt = (!std::ptr::eq(held, fit)).then_some(held);
    let time_chance = |f: &dyn TimeFit,
                       refit: &(dyn Fn(&Block) -> Box<dyn TimeFit> + Sync),
                       seeds: &[u64]|
     -> Vec<f64> {
        let ps = PhaseSurrogates::new(&remove(fit, nc, f), nc);
        seeds
            .par_iter()
            .map(|s| {
                let mut rng = StdRng::seed_from_u64(*s);
                let b = Block {
                    days: fit.days.clone(),
                    r: ps.draw(&mut rng),
                };
                cv_score(&b, held_opt, nc, refit)
            })
            .collect()
    };
    let refit_seas = |b: &Block| -> Box<dyn TimeFit> { Box::new(fit_seasonal(b, nc)) };
    let refit_drift =
        |b: &Block| -> Box<dyn TimeFit> { Box::new(fit_drift(b, &res.scale, ns, &res.tangent)) };
    let refit_step =
        |b: &Block| -> Box<dyn TimeFit> { Box::new(fit_step(b, nc, ns, &res.tangent)) };
    let seas_ch = time_chance(&seas, &refit_seas, &seeds[n_sur..2 * n_sur]);
    let drift_ch = time_chance(&drift, &refit_drift, &seeds[2 * n_sur..3 * n_sur]);
    let step_ch = time_chance(&step, &refit_step, &seeds[3 * n_sur..4 * n_sur]);

    let mk = |family: &str,
              score: f64,
              chance: Vec<f64>,
              params: serde_json::Value,
              effect: Option<OwnedEffect>| {
        Candidate::from_scores(family, score, chance, opts.quantile, params, effect)
    };
    let mut effects = vec![
        mk(
            "common_mode",
            real.cm.0 / total_fit,
            cm_ch,
            with_window(cm_params(res, &fit_perp), real.cm.1),
            Some(OwnedEffect::CommonMode),
        ),
        mk(
            "elevation",
            real.elev.0 / total_fit,
            el_ch,
            with_window(elev_params(res, &fit_perp), real.elev.1),
            Some(OwnedEffect::Elevation {
                z_ref_km: z_ref(res) as f32,
            }),
        ),
        mk(
            "second_source",
            real.ss.gain / total_fit,
            ss_ch,
            with_window(source_params(res, &fit_perp, &real.ss), real.ss.w),
            Some(OwnedEffect::SecondSource {
                x_km: real.ss.pos[0] as f32,
                y_km: real.ss.pos[1] as f32,
                depth_km: real.ss.pos[2] as f32,
            }),
        ),
        mk(
            "seasonal",
            cv_score(fit, held_opt, nc, &refit_seas),
            seas_ch,
            seasonal_params(res, &seas),
            Some(OwnedEffect::Seasonal {
                coef: (0..nc)
                    .flat_map(|c| (1..5).map(move |j| (sc[c][j] * res.scale[c]) as f32))
                    .collect(),
            }),
        ),
        mk(
            "drift",
            cv_score(fit, held_opt, nc, &refit_drift),
            drift_ch,
            drift_params(res, &drift),
            Some(OwnedEffect::Drift {
                t0_day: drift.t0 as f32,
                rate: drift_mm_per_yr(res, &drift)
                    .iter()
                    .map(|v| *v as f32)
                    .collect(),
            }),
        ),
        mk(
            "step",
            cv_score(fit, held_opt, nc, &refit_step),
            step_ch,
            step_params(res, &step),
            Some(OwnedEffect::Step {
                station: step.station as u16,
                epoch_day: step.epoch as f32,
                offset_mm: core::array::from_fn(|k| {
                    (step.offset[k] * res.scale[k * ns + step.station]) as f32
                }),
            }),
        ),
    ];
    effects.sort_by(|a, b| b.excess().total_cmp(&a.excess()));
    let (pc, pattern_share) = dominant_pattern(&fit.r, nc);
    let pc_amp = (pattern_share * total_fit / t_n as f64).sqrt();
    let pattern_mm: Vec<[f64; 3]> = (0..ns)
        .map(|i| core::array::from_fn(|k| pc[k * ns + i] * pc_amp * res.scale[k * ns + i]))
        .collect();
    let station_rms_mm = (0..ns)
        .map(|i| {
            core::array::from_fn(|k| {
                let c = k * ns + i;
                let s: f64 = (0..t_n).map(|t| fit.r[t * nc + c].powi(2)).sum();
                (s / t_n as f64).sqrt() * res.scale[c]
            })
        })
        .collect();
    Ok(Analysis {
        effects,
        residual_variance: total_fit / fit.r.len() as f64,
        residual_mse: res.mse,
        split: opts.split.clone(),
        n_days: t_n,
        n_heldout_days: if std::ptr::eq(held, fit) {
            0
        } else {
            held.days.len()
        },
        names: res.names.clone(),
        stations: res.stations.clone(),
        station_rms_mm,
        main_source: res.main_source,
        pattern_mm,
        pattern_share,
        seconds: start.elapsed().as_secs_f64(),
    })
}

fn with_window(mut v: serde_json::Value, w: usize) -> serde_json::Value {
    if let Some(m) = v.as_object_mut() {
        m.insert("neighbour_days".into(), json!(w));
    }
    v
}

/// Daily least-squares amplitude of a pattern (standardised units) on every row.
///
/// A pattern already inside F's tangent space (an effect the model declares) projects to
/// (numerically) nothing: its amplitude is then 0.
fn daily_amplitude(r: &[f64], nc: usize, g: &[f64]) -> Vec<f64> {
    let gg: f64 = g.iter().map(|v| v * v).sum();
    if gg < DECLARED_NORM2 {
        return vec![0.0; r.len() / nc];
    }
    r.chunks(nc)
        .map(|row| row.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() / gg)
        .collect()
}

/// Lag-one autocovariance of a series (the variance of its day-to-day persistent part).
fn persistent_var(a: &[f64]) -> f64 {
    if a.len() < 2 {
        return 0.0;
    }
    a.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (a.len() - 1) as f64
}

fn cm_params(res: &Residuals, r: &[f64]) -> serde_json::Value {
    let rms: Vec<f64> = cm_patterns(res)
        .iter()
        .map(|g| {
            // g is 1/scale on the component: the amplitude is the weighted network mean in mm.
            let a = daily_amplitude(r, res.nc(), g);
            persistent_var(&a).max(0.0).sqrt()
        })
        .collect();
    json!({"rms_mm": rms.iter().map(|v| round3(*v)).collect::<Vec<_>>()})
}

/// RMS of the daily elevation slope k (mm/km): the daily least-squares amplitude of the
/// (projected) elevation pattern, its variance less the part the channels' noise puts into it
/// (each channel's variance about the fit, taken independent between channels).
fn elev_params(res: &Residuals, r: &[f64]) -> serde_json::Value {
    let nc = res.nc();
    let g = elev_pattern(res);
    let gg: f64 = g.iter().map(|v| v * v).sum();
    if gg < DECLARED_NORM2 {
        return json!({"mm_per_km": 0.0, "z_ref_km": z_ref(res)});
    }
    let a = daily_amplitude(r, nc, &g);
    let t_n = a.len() as f64;
    let mut var_c = vec![0.0; nc];
    for (row, at) in r.chunks(nc).zip(&a) {
        for c in 0..nc {
            var_c[c] += (row[c] - at * g[c]).powi(2) / t_n;
        }
    }
    let noise: f64 = g.iter().zip(&var_c).map(|(x, v)| x * x * v).sum::<f64>() / (gg * gg);
    let s2 = a.iter().map(|v| v * v).sum::<f64>() / t_n;
    json!({"mm_per_km": round3((s2 - noise).max(0.0).sqrt()), "z_ref_km": z_ref(res)})
}

/// Second-source parameters: position, the activity window found by the search, and the peak
/// of the daily volume change (30-day running mean, relative to its median outside the window).
/// Second-source parameters: position, and from the daily volume change of the source (30-day
/// running mean, relative to its median) the peak and the window around it where the change
/// stays beyond twice its robust spread (and 5 % of the peak).
fn source_params(res: &Residuals, r: &[f64], f: &SourceFit) -> serde_json::Value {
    let nc = res.nc();
    let g = source_pattern(res, f.pos);
    let dv = daily_amplitude(r, nc, &g);
    let n = dv.len();
    let hw = 15.min(n / 2);
    let smooth: Vec<f64> = (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(hw), (t + hw + 1).min(n));
            dv[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect();
    let base = median(&mut smooth.clone());
    let dev: Vec<f64> = smooth.iter().map(|v| v - base).collect();
    let sigma = 1.4826 * median(&mut dev.iter().map(|v| v.abs()).collect::<Vec<_>>());
    let (ipk, peak) =
        dev.iter().enumerate().fold(
            (0, 0.0f64),
            |b, (i, v)| if v.abs() > b.1.abs() { (i, *v) } else { b },
        );
    let thr = (2.0 * sigma).max(0.05 * peak.abs());
    let active = |i: usize| dev[i] * peak.signum() > thr;
    let (mut a, mut b) = (ipk, ipk);
    while a > 0 && active(a - 1) {
        a -= 1;
    }
    while b + 1 < n && active(b + 1) {
        b += 1;
    }
    json!({
        "x_km": round3(f.pos[0]), "y_km": round3(f.pos[1]), "depth_km": round3(f.pos[2]),
        "start": date(res.fit.days[a]), "end": date(res.fit.days[b]),
        "peak_dv_1e6m3": (peak * 1e4).round() / 1e4,
    })
}

fn per_station(res: &Residuals, v: &dyn Fn(usize) -> [f64; 3]) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    for (i, n) in res.names.iter().enumerate() {
        m.insert(n.clone(), json!(v(i).map(round3)));
    }
    serde_json::Value::Object(m)
}

fn seasonal_params(res: &Residuals, f: &SeasonalFit) -> serde_json::Value {
    let ns = res.ns();
    let amp = |c: usize, j: usize| f.coef[c][j].hypot(f.coef[c][j + 1]) * res.scale[c];
    json!({
        "annual_mm": per_station(res, &|i| core::array::from_fn(|k| amp(k * ns + i, 1))),
        "semiannual_mm": per_station(res, &|i| core::array::from_fn(|k| amp(k * ns + i, 3))),
    })
}

/// Drift rates (mm/yr) per channel, zero where no drift was selected.
fn drift_mm_per_yr(res: &Residuals, f: &DriftFit) -> Vec<f64> {
    let mut out = vec![0.0; res.nc()];
    for (c, r) in f.chans.iter().zip(&f.rates) {
        out[*c] = r * res.scale[*c];
    }
    out
}

fn drift_params(res: &Residuals, f: &DriftFit) -> serde_json::Value {
    let ns = res.ns();
    let rates = drift_mm_per_yr(res, f);
    let mut m = serde_json::Map::new();
    for i in 0..ns {
        if f.chans.iter().any(|c| c % ns == i) {
            let r: [f64; 3] = core::array::from_fn(|k| round3(rates[k * ns + i]));
            m.insert(res.names[i].clone(), json!(r));
        }
    }
    json!({"rate_mm_per_yr": m, "t0": date(f.t0)})
}

fn step_params(res: &Residuals, f: &StepFit) -> serde_json::Value {
    let ns = res.ns();
    json!({
        "station": res.names[f.station],
        "epoch": date(f.epoch),
        "offset_mm": (0..3).map(|k| round3(f.offset[k] * res.scale[k * ns + f.station])).collect::<Vec<_>>(),
        "scan_statistic": round3(f.stat),
    })
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

// ---------------------------------------------------------------------------------------------
// Plots (PNG through `crate::plots`: plotters' bitmap backend with a compiled-in font, so nothing
// but crates is needed to build or to draw).

/// A bar per candidate: the share explained (%), a tick at its chance level, `*` when
/// significant.
pub fn effects_chart(path: &Path, title: &str, effects: &[Candidate]) -> Result<()> {
    let labels: Vec<String> = effects
        .iter()
        .map(|c| {
            if c.significant {
                format!("{} *", c.family)
            } else {
                c.family.clone()
            }
        })
        .collect();
    let values: Vec<f64> = effects
        .iter()
        .map(|c| 100.0 * c.variance_explained)
        .collect();
    let chance: Vec<f64> = effects.iter().map(|c| 100.0 * c.chance_level).collect();
    crate::plots::bar_chart(path, title, &labels, &values, &chance)
}

/// Writes `effects.png` (each family's held-out score as a bar, its chance level as a tick),
/// `residual_pattern.png` (the dominant residual pattern on the network: horizontal arrows, the
/// vertical as colour) and `residual_rms.png` (residual RMS per station, all components).
pub fn write_plots(a: &Analysis, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    effects_chart(
        &dir.join("effects.png"),
        &format!(
            "Residual variance explained on held-out data, % ({}; tick: chance, *: significant)",
            a.split
        ),
        &a.effects,
    )?;
    let st: Vec<(String, f64, f64)> = a
        .names
        .iter()
        .zip(&a.stations)
        .map(|(n, s)| (n.clone(), s.x_km, s.y_km))
        .collect();
    crate::plots::station_map(
        &dir.join("residual_pattern.png"),
        &format!(
            "Dominant residual pattern ({:.0} % of the residual variance; arrows E/N, colour U, mm RMS)",
            100.0 * a.pattern_share
        ),
        &st,
        &a.pattern_mm.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
        &a.pattern_mm.iter().map(|p| p[2]).collect::<Vec<_>>(),
    )?;
    crate::plots::station_map(
        &dir.join("residual_rms.png"),
        &format!("Residual RMS per station, mm ({}, all components)", a.split),
        &st,
        &[],
        &a.station_rms_mm
            .iter()
            .map(|v| (v.iter().map(|x| x * x).sum::<f64>() / 3.0).sqrt())
            .collect::<Vec<_>>(),
    )?;
    Ok(())
}

/// The first principal component of the rows (standardised): unit vector and its share of the
/// total variance (power iteration on the channel covariance).
fn dominant_pattern(r: &[f64], nc: usize) -> (Vec<f64>, f64) {
    let mut cov = vec![0.0; nc * nc];
    for row in r.chunks(nc) {
        for a in 0..nc {
            for b in 0..nc {
                cov[a * nc + b] += row[a] * row[b];
            }
        }
    }
    let total: f64 = (0..nc).map(|c| cov[c * nc + c]).sum();
    let mut v = vec![1.0 / (nc as f64).sqrt(); nc];
    let mut lambda = 0.0;
    for _ in 0..200 {
        let w: Vec<f64> = (0..nc)
            .map(|a| (0..nc).map(|b| cov[a * nc + b] * v[b]).sum())
            .collect();
        let n = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n == 0.0 {
            break;
        }
        lambda = n;
        v = w.iter().map(|x| x / n).collect();
    }
    (v, if total > 0.0 { lambda / total } else { 0.0 })
}

// ---------------------------------------------------------------------------------------------
// Recovery on synthetic data with a known injected effect.

/// How an analysis of a synthetic dataset compares with its `truth.json`.
#[derive(Clone, Debug)]
pub struct Recovery {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// Family ranked first.
    pub top: String,
    /// Its excess over chance.
    pub top_excess: f64,
    /// The injected family is ranked first.
    pub ranked_first: bool,
    /// The injected family is significant (for `clean`: nothing is).
    pub significant: bool,
    /// Significant families.
    pub n_significant: usize,
    /// The injected family's key parameters are recovered (`None` for `clean`).
    pub params_ok: Option<bool>,
    /// What was compared.
    pub detail: String,
}

impl Recovery {
    /// Detected and recovered: for `clean`, nothing significant; otherwise ranked first,
    /// significant and parameters recovered.
    pub fn ok(&self) -> bool {
        if self.scenario == "clean" {
            self.n_significant == 0
        } else {
            self.ranked_first && self.significant && self.params_ok == Some(true)
        }
    }
}

fn num(v: &serde_json::Value, k: &str) -> f64 {
    v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN)
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    core::array::from_fn(|k| v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN))
}

/// Compares an analysis with the truth of `magic synth` (its `effect` entry). Criteria: a step's
/// station and epoch within 10 days; a second source within 2 km horizontally; the elevation
/// slope within 30 %; each common-mode RMS within 30 %; the median relative error of the
/// seasonal annual amplitudes below 30 %; the drifting stations exactly.
pub fn recovery(truth: &serde_json::Value, a: &Analysis) -> Recovery {
    let scenario = truth
        .get("scenario")
        .and_then(|v| v.as_str())
        .unwrap_or("?")
        .to_string();
    let seed = truth.get("seed").and_then(|v| v.as_u64()).unwrap_or(0);
    let top = a.effects.first();
    let n_significant = a.effects.iter().filter(|c| c.significant).count();
    let mut r = Recovery {
        scenario: scenario.clone(),
        seed,
        top: top.map_or(String::new(), |c| c.family.clone()),
        top_excess: top.map_or(0.0, |c| c.excess()),
        ranked_first: false,
        significant: n_significant == 0,
        n_significant,
        params_ok: None,
        detail: String::new(),
    };
    let eff = truth.get("effect").filter(|e| !e.is_null());
    let Some(eff) = eff else {
        r.ranked_first = true;
        r.detail = format!(
            "significant: {}",
            a.effects
                .iter()
                .filter(|c| c.significant)
                .map(|c| c.family.as_str())
                .collect::<Vec<_>>()
                .join(",")
        );
        return r;
    };
    let fam = eff.get("family").and_then(|v| v.as_str()).unwrap_or("?");
    let tp = &eff["params"];
    let Some(c) = a.effects.iter().find(|c| c.family == fam) else {
        r.detail = format!("family {fam} not analysed");
        return r;
    };
    r.ranked_first = top.is_some_and(|t| t.family == fam);
    r.significant = c.significant;
    let p = &c.params;
    let (ok, detail) = match fam {
        "step" => {
            let ds = (tp["epoch"].as_str(), p["epoch"].as_str());
            let de = match ds {
                (Some(x), Some(y)) => match (
                    magic_core::time::parse_date(x),
                    magic_core::time::parse_date(y),
                ) {
                    (Some(x), Some(y)) => (y - x) as f64,
                    _ => f64::NAN,
                },
                _ => f64::NAN,
            };
            let same = tp["station"] == p["station"];
            let (to, fo) = (vec3(&tp["offset_mm"]), vec3(&p["offset_mm"]));
            (
                same && de.abs() <= 10.0,
                format!(
                    "station {} vs {}, epoch {:+} d, offset [{:.1},{:.1},{:.1}] vs [{:.1},{:.1},{:.1}] mm",
                    p["station"], tp["station"], de, fo[0], fo[1], fo[2], to[0], to[1], to[2]
                ),
            )
        }
        "second_source" => {
            let dh = (num(p, "x_km") - num(tp, "x_km")).hypot(num(p, "y_km") - num(tp, "y_km"));
            (
                dh <= 2.0,
                format!(
                    "horizontal error {dh:.2} km, depth {:.1} vs {:.1} km, window {}..{} vs {}..{}",
                    num(p, "depth_km"),
                    num(tp, "depth_km"),
                    p["start"].as_str().unwrap_or("?"),
                    p["end"].as_str().unwrap_or("?"),
                    tp["start"].as_str().unwrap_or("?"),
                    tp["end"].as_str().unwrap_or("?")
                ),
            )
        }
        "elevation" => {
            let (e, t) = (num(p, "mm_per_km"), num(tp, "mm_per_km"));
            (
                (e - t).abs() <= 0.3 * t,
                format!("{e:.1} vs {t:.1} mm/km ({:+.0} %)", 100.0 * (e / t - 1.0)),
            )
        }
        "common_mode" => {
            let (e, t) = (vec3(&p["rms_mm"]), vec3(&tp["rms_mm"]));
            let rel: Vec<f64> = (0..3).map(|k| e[k] / t[k] - 1.0).collect();
            (
                rel.iter().all(|v| v.abs() <= 0.3),
                format!(
                    "rms [{:.2},{:.2},{:.2}] vs [{:.2},{:.2},{:.2}] mm",
                    e[0], e[1], e[2], t[0], t[1], t[2]
                ),
            )
        }
        "seasonal" => {
            let mut rel = Vec::new();
            if let (Some(em), Some(tm)) = (p["annual_mm"].as_object(), tp["annual_mm"].as_object())
            {
                for (sta, tv) in tm {
                    let (t, e) = (
                        vec3(tv),
                        vec3(em.get(sta).unwrap_or(&serde_json::Value::Null)),
                    );
                    rel.extend((0..3).map(|k| (e[k] / t[k] - 1.0).abs()));
                }
            }
            let m = median(&mut rel.clone());
            (
                m <= 0.3,
                format!(
                    "annual amplitudes: median relative error {:.0} %",
                    100.0 * m
                ),
            )
        }
        "drift" => {
            let keys = |v: &serde_json::Value| {
                let mut k: Vec<String> = v["rate_mm_per_yr"]
                    .as_object()
                    .map_or(vec![], |m| m.keys().cloned().collect());
                k.sort();
                k
            };
            let (e, t) = (keys(p), keys(tp));
            (e == t, format!("stations {e:?} vs {t:?}"))
        }
        _ => (false, String::new()),
    };
    r.params_ok = Some(ok);
    r.detail = detail;
    r
}

/// Generates a scenario, trains a B model on it and analyses its residuals.
pub fn check_one(
    scenario: crate::synth::Scenario,
    seed: u64,
    cfg: &crate::TrainConfig,
    opts: &AnalysisOptions,
) -> Result<(Recovery, Analysis)> {
    let s = crate::synth::generate(scenario, seed);
    let (model, _) = crate::pipeline::train_mogi(&s.data, magic_core::Variant::B, cfg, seed)?;
    let bytes = model.encode()?;
    let m = Model::decode(&bytes).map_err(|e| anyhow!("{e}"))?;
    let a = analyse(&m, &s.data, opts)?;
    Ok((recovery(&s.truth, &a), a))
}

/// The recovery table over scenarios and seeds: per scenario, ranked first, significant and
/// parameters recovered as counts out of the seeds (for `clean`: false positives).
pub fn recovery_table(rows: &[Recovery]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
        "scenario", "seeds", "ranked 1st", "significant", "params", "all ok"
    );
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.scenario.as_str()) {
            names.push(&r.scenario);
        }
    }
    for n in names {
        let g: Vec<&Recovery> = rows.iter().filter(|r| r.scenario == n).collect();
        let k = |f: &dyn Fn(&Recovery) -> bool| g.iter().filter(|r| f(r)).count();
        if n == "clean" {
            let _ = writeln!(
                s,
                "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
                n,
                g.len(),
                "-",
                format!("FP {}", k(&|r| r.n_significant > 0)),
                "-",
                format!("{}/{}", k(&|r| r.ok()), g.len())
            );
        } else {
            let _ = writeln!(
                s,
                "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
                n,
                g.len(),
                format!("{}/{}", k(&|r| r.ranked_first), g.len()),
                format!("{}/{}", k(&|r| r.significant), g.len()),
                format!("{}/{}", k(&|r| r.params_ok == Some(true)), g.len()),
                format!("{}/{}", k(&|r| r.ok()), g.len())
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    #[test]
    fn highpass_removes_slow_variations_and_keeps_fast_ones() {
        // Two channels over 1 900 days: a constant plus a linear trend (slow), and a 60-day
        // sinusoid (fast).
        let (n, h) = (1900usize, LATENT_HIGHPASS_DAYS);
        let r: Vec<f64> = (0..n)
            .flat_map(|t| {
                let t = t as f64;
                [3.0 + 0.01 * t, (std::f64::consts::TAU * t / 60.0).sin()]
            })
            .collect();
        let out = highpass(&r, 2, h);
        // Away from the ends the running mean of a trend is the trend itself.
        for t in h..n - h {
            assert!(out[2 * t].abs() < 1e-9, "day {t}: {}", out[2 * t]);
        }
        // The fast channel keeps its variance (a running mean over about 12 cycles is small; the
        // partial cycle in each window leaves a few percent).
        let var = |c: usize, v: &[f64]| (0..n).map(|t| v[2 * t + c].powi(2)).sum::<f64>();
        let kept = var(1, &out) / var(1, &r);
        assert!((kept - 1.0).abs() < 0.05, "fast variance kept: {kept}");
        // The slow channel loses nearly all of its variance about its mean.
        let m = (0..n).map(|t| r[2 * t]).sum::<f64>() / n as f64;
        let slow = (0..n).map(|t| (r[2 * t] - m).powi(2)).sum::<f64>();
        assert!(
            var(0, &out) < 0.05 * slow,
            "slow variance kept: {}",
            var(0, &out) / slow
        );
    }

    #[test]
    fn bluestein_matches_the_naive_dft() {
        for n in [1usize, 2, 7, 12, 30, 101] {
            let x: Vec<fft::Cx> = noise(2 * n, n as u64)
                .chunks(2)
                .map(|p| fft::Cx::new(p[0], p[1]))
                .collect();
            let plan = fft::Plan::new(n);
            let y = plan.forward(&x);
            for (k, yk) in y.iter().enumerate() {
                let (mut re, mut im) = (0.0, 0.0);
                for (j, xj) in x.iter().enumerate() {
                    let a = -std::f64::consts::TAU * (j * k) as f64 / n as f64;
                    re += xj.re * a.cos() - xj.im * a.sin();
                    im += xj.re * a.sin() + xj.im * a.cos();
                }
                assert!(
                    (yk.re - re).abs() < 1e-9 && (yk.im - im).abs() < 1e-9,
                    "n {n} k {k}"
                );
            }
            let z = plan.inverse(&y);
            for (a, b) in z.iter().zip(&x) {
                assert!((a.re - b.re).abs() < 1e-9 && (a.im - b.im).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn phase_surrogates_keep_spectra_and_cross_spectra() {
        let (n, nc) = (64, 3);
        let r = noise(n * nc, 5);
        let ps = PhaseSurrogates::new(&r, nc);
        let s = ps.draw(&mut StdRng::seed_from_u64(9));
        let spec = |v: &[f64], c: usize| {
            ps.plan.forward(
                &(0..n)
                    .map(|t| fft::Cx::new(v[t * nc + c], 0.0))
                    .collect::<Vec<_>>(),
            )
        };
        for c in 0..nc {
            let (a, b) = (spec(&r, c), spec(&s, c));
            for k in 0..n {
                assert!((a[k].re.hypot(a[k].im) - b[k].re.hypot(b[k].im)).abs() < 1e-9);
            }
            assert!(s.iter().all(|v| v.is_finite()));
        }
        // Cross-spectrum of channels 0 and 1: same at every frequency.
        let (a0, a1, b0, b1) = (spec(&r, 0), spec(&r, 1), spec(&s, 0), spec(&s, 1));
        for k in 0..n {
            let x = a0[k].mul(a1[k].conj());
            let y = b0[k].mul(b1[k].conj());
            assert!((x.re - y.re).abs() < 1e-8 && (x.im - y.im).abs() < 1e-8);
        }
        // And the series itself changed.
        assert!(r.iter().zip(&s).map(|(a, b)| (a - b).abs()).sum::<f64>() > 1.0);
    }

    #[test]
    fn leave_one_station_out_matches_a_direct_computation() {
        let (ns, nc, t_n, w) = (3usize, 9usize, 40usize, 2usize);
        let r = noise(t_n * nc, 11);
        let g = noise(nc, 12);
        let (a, b) = loso_ab(&g, &cross(&r, nc, w), ns);
        let (mut da, mut db) = (0.0, 0.0);
        for t in 0..t_n {
            let (lo, hi) = (t.saturating_sub(w), (t + w + 1).min(t_n));
            let m: Vec<f64> = (0..nc)
                .map(|c| {
                    (lo..hi)
                        .filter(|&u| u != t)
                        .map(|u| r[u * nc + c])
                        .sum::<f64>()
                        / (hi - lo - 1) as f64
                })
                .collect();
            for i in 0..ns {
                let others: Vec<usize> = (0..nc).filter(|c| c % ns != i).collect();
                let amp = others.iter().map(|&c| g[c] * m[c]).sum::<f64>()
                    / others.iter().map(|&c| g[c] * g[c]).sum::<f64>();
                for c in (0..nc).filter(|c| c % ns == i) {
                    let p = g[c] * amp;
                    da += r[t * nc + c] * p;
                    db += p * p;
                }
            }
        }
        assert!(
            (a - da).abs() < 1e-9 * (1.0 + da.abs()) && (b - db).abs() < 1e-9 * (1.0 + db.abs()),
            "{a} {da} {b} {db}"
        );
    }

    #[test]
    fn deprojection_inverts_the_projection() {
        let nc = 9;
        let mut tangent: Vec<Vec<f64>> = Vec::new();
        for seed in [1, 2] {
            let mut v = noise(nc, seed);
            for q in &tangent {
                let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(q).for_each(|(x, y)| *x -= d * y);
            }
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            tangent.push(v.iter().map(|x| x / n).collect());
        }
        let chans = [0usize, 3, 6];
        let v = [0.7, -1.2, 2.0];
        let resp = projected_response(&tangent, nc, &chans, &v);
        let d: Vec<f64> = chans.iter().map(|&c| resp[c]).collect();
        let back = deproject(&tangent, &chans, &d);
        for (a, b) in back.iter().zip(&v) {
            assert!((a - b).abs() < 1e-9);
        }
    }

    #[test]
    fn step_scan_finds_a_step_in_noise() {
        let (ns, nc, t_n) = (4usize, 12usize, 600usize);
        let mut r = noise(t_n * nc, 3);
        for t in 250..t_n {
            for k in 0..3 {
                r[t * nc + k * ns + 2] += [1.5, -1.0, 2.0][k];
            }
        }
        let b = Block {
            days: (0..t_n).map(|t| 14_000.0 + t as f64).collect(),
            r,
        };
        let f = fit_step(&b, nc, ns, &[]);
        assert_eq!(f.station, 2);
        assert_eq!(f.epoch, 14_250.0);
        for (o, want) in f.offset.iter().zip([1.5, -1.0, 2.0]) {
            assert!((o - want).abs() < 0.15, "{o} vs {want}");
        }
    }
}
