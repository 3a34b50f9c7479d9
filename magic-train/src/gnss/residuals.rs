//! The residuals of a GNSS model, as its effect families see them.
//!
//! Every day of the data is inverted with the core's `invert_at` (the model as it will be used)
//! and the physics-only error F(E(x)) is reported. The main source's typical position is the
//! median, over the days of largest volume change by the encoder, of each day's least-squares
//! source (the source and the network's translations, started from the encoder's). The families
//! are then fitted to what F, linearised around that typical state, cannot produce: each day's
//! observation less F's time-dependent declared effects, in the data's standardised units (the
//! paper's metric), projected off the declared latent effects and off the main source, each
//! channel's mean over the analysed split removed (a channel missing on a day takes the model's
//! reconstruction, as the core fills it at inversion). For a C model the same holds: the
//! correction absorbs bias, the question is what F lacks. Working off the linearisation rather
//! than off `x − F(E(x))` keeps the analysis independent of how the encoder distorts its
//! variables to mimic a missing effect (an encoder readily moves the main source towards a
//! second one, or tilts it to follow a step at an edge station); candidate patterns are
//! projected the same way.
//!
//! The main source is either free to move ([`MainSource::Free`], the default: the whole span of
//! its Jacobian — position, depth, volume — is projected off) or held in place
//! ([`MainSource::Held`]: only the one direction of that span along which the days vary most, a
//! source whose volume changes where it is). Free, a second source 2–4 km from the main one is
//! mostly a move of it: what is left of its field looks like a shallower source, so free
//! residuals carry a held view too ([`GnssResiduals::held`]), where the point-source families
//! locate a source (and `second_source` scores its episode). Held, a second source stays in
//! the residuals whole, and so does a main source that really moves between its episodes.

use super::{lsq, GnssProblem, Network};
use crate::analysis::projection::{orthonormal, project, scaled, share_beyond};
use crate::analysis::MainSource;
use crate::data::SplitName;
use crate::gnss::families::second_source::MIN_RESOLVABLE_DECLARED;
use crate::model::OwnedEffect;
use crate::numerics::median;
use crate::problem::Problem as _;
use anyhow::{anyhow, bail, Result};
use magic_core::{invert_at, mogi, Model, Workspace};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde_json::json;
use std::sync::{Arc, OnceLock};

/// The second-source search's grid, computed once per set of residuals (surrogates share it).
#[derive(Debug)]
pub struct SourceGrid {
    /// Orthonormal basis of F's tangent space and the network's translations: the directions
    /// a point source is not judged on.
    pub basis: Vec<Vec<f64>>,
    /// Grid points (x, y, depth km).
    pub points: Vec<[f64; 3]>,
    /// The pattern of a unit source at each point, projected off `basis`.
    pub patterns: Vec<Vec<f64>>,
}

/// The main source's variables (x, y, depth, volume change): the first of every GNSS model.
const SOURCE_VARIABLES: usize = 4;

/// Least share (squared norm) of each direction of the main source's span that must lie off the
/// nuisances (translations, declared latent effects) for the source to be held in place (see
/// [`held_source`]).
const MIN_OFF_NUISANCE: f64 = 1e-6;

/// Fewest days of a split the analysis accepts.
pub const MIN_DAYS: usize = 360;

/// A block of residual rows: `r[t * nc + c]` in standardised units.
#[derive(Clone, Debug, Default)]
pub struct Block {
    /// Day numbers.
    pub days: Vec<f64>,
    /// Residuals, row-major (days × channels).
    pub r: Vec<f64>,
}

impl Block {
    /// Number of rows for `nc` channels.
    pub fn len(&self, nc: usize) -> usize {
        self.r.len() / nc.max(1)
    }

    /// Channel `c`'s series (one value per row) for `nc` channels.
    pub fn channel(&self, c: usize, nc: usize) -> Vec<f64> {
        self.r.iter().skip(c).step_by(nc.max(1)).copied().collect()
    }
}

/// What every family shares about the residuals of one model: the network, the units, F's
/// tangent space and the real residuals' scale.
#[derive(Debug)]
pub struct Context {
    /// The network.
    pub network: Network,
    /// mm per standardised unit, per channel.
    pub scale: Vec<f64>,
    /// Channel means removed from the residuals (standardised units).
    pub mean: Vec<f64>,
    /// Mean squared residual of the analysed split before removing the means (the physics-only
    /// MSE of the split).
    pub mse: f64,
    /// The main source's typical position (x, y, depth): the median of the least-squares
    /// sources of the days of largest volume change by the encoder.
    pub main_source: [f64; 3],
    /// Orthonormal basis (standardised units) of the directions F already produces around its
    /// typical state: the main source's (free or held, [`MainSource`]) and the declared latent
    /// effects'.
    pub tangent: Vec<Vec<f64>>,
    /// Orthonormal basis (standardised units) of the main source's own span around its typical
    /// state — its position, depth and volume, whether the analysis holds it or not: what a
    /// second source's field must not be mostly made of to be told from a move of it.
    pub source_span: Vec<Vec<f64>>,
    /// Orthonormal basis of [`Context::source_span`] and the fields of the extra sources F
    /// declares: what a new source's field must not be mostly made of to be told from a move
    /// of the main source and a change of the declared ones (a declared source found again
    /// lies entirely in it).
    pub sources_span: Vec<Vec<f64>>,
    /// The declared extra sources with less than [`MIN_RESOLVABLE_DECLARED`] of their field (in
    /// norm) beyond [`Context::source_span`]: the main source trades with them, and a source
    /// across it from one of them is not told from the trade.
    pub trading: Vec<Trade>,
    /// Sum of squares of the analysed days' (real) residuals: the denominator of the latent
    /// families' shares, for the data and its surrogates alike.
    pub total_fit: f64,
    /// The analysed splits.
    pub splits: Vec<SplitName>,
    /// Cached second-source search grid and its projected patterns.
    pub(crate) source_grid: OnceLock<SourceGrid>,
    /// Cached lasting-source search grid (the second source's, reaching shallower).
    pub(crate) lasting_grid: OnceLock<SourceGrid>,
    /// Cached best fit of the second source on the data's own residuals.
    pub(crate) second_source: OnceLock<crate::gnss::families::second_source::SourceFit>,
    /// Cached pulse the lasting source is searched beside, if any (found on the
    /// data's own residuals; their draws share it).
    pub(crate) pulse: OnceLock<Option<crate::gnss::families::lasting_source::pulse::Pulse>>,
}

/// Residuals of a model on a dataset: the analysed days in time order (which surrogates
/// replace) and the shared [`Context`].
#[derive(Clone, Debug)]
pub struct GnssResiduals {
    /// What every family shares.
    pub ctx: Arc<Context>,
    /// The analysed days in time order, with each channel's mean over them removed.
    pub fit: Block,
    /// With the main source free ([`MainSource::Free`]): the same days with it held in place
    /// (its own context), where a point source is located — projected off the whole span, a
    /// source near the main one keeps too little of its field to fix its depth by. `fit` is this
    /// block projected off the rest of the span. `None` when held and free coincide.
    pub held: Option<Arc<GnssResiduals>>,
    /// What the projection off [`Context::tangent`] took off each analysed row (rows like
    /// `fit.r`): kept for the data's own residuals, `None` for a draw. A term that follows the
    /// calendar is fitted with it given back ([`GnssResiduals::given_back`]).
    pub taken: Option<Arc<Vec<f64>>>,
    /// A draw that keeps this station's rows as the data hold them (the null of a source that
    /// station holds most of): its sources are searched among those the station holds most of
    /// ([`held_station::held_by`](crate::gnss::families::held_station::held_by)). `None` for
    /// the data and every other draw.
    pub kept: Option<usize>,
}

impl GnssResiduals {
    /// Number of channels.
    pub fn nc(&self) -> usize {
        self.ctx.scale.len()
    }

    /// Number of stations.
    pub fn ns(&self) -> usize {
        self.ctx.network.len()
    }

    /// `g` without its part along [`Context::tangent`]: what remains of an effect of pattern `g`
    /// once F has absorbed what it already produces.
    pub fn project(&self, g: &[f64]) -> Vec<f64> {
        project(&self.ctx.tangent, g)
    }

    /// Every row of `r` projected with [`GnssResiduals::project`].
    pub fn project_rows(&self, r: &[f64]) -> Vec<f64> {
        r.par_chunks(self.nc())
            .flat_map_iter(|row| self.project(row))
            .collect()
    }

    /// The same residuals with another analysed block (a surrogate), without a held view.
    pub fn with_fit(&self, r: Vec<f64>) -> GnssResiduals {
        GnssResiduals {
            ctx: self.ctx.clone(),
            fit: Block {
                days: self.fit.days.clone(),
                r,
            },
            held: None,
            taken: None,
            kept: None,
        }
    }

    /// The analysed rows with what the projection took given back, less its part along the
    /// network's translations (the data's own residuals only: `None` for a draw). F's daily
    /// variables — the main source's volume and moves, the declared latent effects — are free
    /// from day to day, so the projection takes off every day whatever of a term lies in their
    /// span; a term that follows the calendar (a seasonal one) is told from them only by
    /// assuming they do not, and then its part in the span is in these rows. A translation's
    /// part stays taken: a common mode wandering over months has a share at every period, which
    /// would pass for a network-wide seasonal term (trial seeds 101–110, `seasonal` and
    /// `common_mode+seasonal` under both generators: the seasonal amplitudes' median error
    /// within 30 % in 36 of 40 fitted to the projected rows, 11–37 %; in 40 fitted to these,
    /// 11–27 %; in 38 with the translations given back too, 6–31 %).
    pub fn given_back(&self) -> Option<Block> {
        self.give_back(&translation_basis(&self.ctx.scale, self.ns()))
    }

    /// The rows [`GnssResiduals::given_back`] with the translations' part given back too, when
    /// F declares them (the common mode, by the rule its family declares it by:
    /// [`latent::declared`](crate::gnss::families::latent::declared); else `None`, as for a
    /// draw). The declared common mode's daily translation then holds the network's share of
    /// every station's annual term: what a station's annual amplitude is, whichever of the two
    /// effects was declared first. It is not what F's seasonal term should hold beside it: the
    /// encoder, which does not see the date, puts the network's share in its translation
    /// (declared there too, trial seeds 101–105 under `red`, `common_mode+seasonal`: B's test
    /// MSE after the loop 0.01–0.04 higher).
    pub fn given_back_whole(&self) -> Option<Block> {
        let projected: Vec<Vec<f64>> = translation_basis(&self.ctx.scale, self.ns())
            .iter()
            .map(|t| self.project(t))
            .collect();
        crate::gnss::families::latent::declared(&projected)
            .then(|| self.give_back(&[]))
            .flatten()
    }

    /// The analysed rows plus what the projection took, less its part along the orthonormal
    /// `kept`.
    fn give_back(&self, kept: &[Vec<f64>]) -> Option<Block> {
        let taken = self.taken.as_deref()?;
        let r = self
            .fit
            .r
            .chunks(self.nc())
            .zip(taken.chunks(self.nc()))
            .flat_map(|(r, t)| r.iter().zip(project(kept, t)).map(|(a, b)| a + b))
            .collect();
        Some(Block {
            days: self.fit.days.clone(),
            r,
        })
    }

    /// `drawn` (a draw of these residuals) with a held view: `drawn` plus the part of `held_rows`
    /// (rows of the held view) beyond these residuals, what the projection takes off them. The
    /// analysed block stays `drawn`'s. Without a held view, `drawn` itself.
    pub fn beside_moves(&self, drawn: GnssResiduals, held_rows: &[f64]) -> GnssResiduals {
        let Some(held) = self.held.as_deref() else {
            return drawn;
        };
        let projected = self.project_rows(held_rows);
        let rows = drawn
            .fit
            .r
            .iter()
            .zip(held_rows.iter().zip(&projected))
            .map(|(d, (h, p))| d + (h - p))
            .collect();
        let mut out = drawn;
        out.held = Some(Arc::new(held.with_fit(rows)));
        out
    }

    /// The residuals whose held view is `held` (a draw of [`GnssResiduals::held`] that keeps the
    /// main source's moves coherent): the analysed block is `held`'s projected off this context's
    /// tangent, as the data's is the held view's.
    pub fn with_held(&self, held: GnssResiduals) -> GnssResiduals {
        let mut out = self.with_fit(self.project_rows(&held.fit.r));
        out.held = Some(Arc::new(held));
        out
    }

    /// Where a point source is located: the held view if there is one, else these residuals.
    pub fn locating(&self) -> &GnssResiduals {
        self.held.as_deref().unwrap_or(self)
    }

    /// The report's view of the residuals (JSON) and its summary line.
    pub fn describe(&self) -> (serde_json::Value, String) {
        let (nc, ns) = (self.nc(), self.ns());
        let t_n = self.fit.len(nc);
        let (pc, share) = dominant_pattern(&self.fit.r, nc);
        let amp = (share * self.ctx.total_fit / t_n.max(1) as f64).sqrt();
        let pattern_mm: Vec<[f64; 3]> = (0..ns)
            .map(|i| core::array::from_fn(|k| pc[k * ns + i] * amp * self.ctx.scale[k * ns + i]))
            .collect();
        let station_rms_mm: Vec<[f64; 3]> = (0..ns)
            .map(|i| {
                core::array::from_fn(|k| {
                    let c = k * ns + i;
                    let s: f64 = (0..t_n).map(|t| self.fit.r[t * nc + c].powi(2)).sum();
                    (s / t_n.max(1) as f64).sqrt() * self.ctx.scale[c]
                })
            })
            .collect();
        let variance = self.ctx.total_fit / self.fit.r.len().max(1) as f64;
        let m = self.ctx.main_source;
        let splits: Vec<&str> = self.ctx.splits.iter().map(|s| s.as_str()).collect();
        let summary = format!(
            "residuals on {} ({t_n} days): variance {variance:.4} (standardised, means removed), physics-only MSE {:.4}",
            splits.join(" + "),
            self.ctx.mse
        );
        let json = json!({
            "residual_variance": variance,
            "residual_mse": self.ctx.mse,
            "n_days": t_n,
            "splits": self.ctx.splits,
            "main_source": {"x_km": m[0], "y_km": m[1], "depth_km": m[2]},
            "station_rms_mm": station_rms_mm,
            "pattern_mm": pattern_mm,
            "pattern_share": share,
        });
        (json, summary)
    }
}

/// An inverted day: observation (mm), F(E(x)) (mm) and the encoder's variables.
struct Day {
    obs: Vec<f64>,
    physics: Vec<f64>,
    params: Vec<f64>,
}

fn invert_split(
    p: &GnssProblem,
    model: &Model<'_>,
    name: SplitName,
) -> Result<(Vec<f64>, Vec<Day>)> {
    let (nc, np) = (p.data.n_obs(), model.n_params());
    let s = p.data.split(name);
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
                let obs = p.data.physical_row(row);
                let inv = invert_at::<f64>(model, &obs, t, ws)
                    .map_err(|e| anyhow!("{name} day {t}: {e}"))?;
                // A missing channel takes the model's own reconstruction (as the core fills it):
                // it then adds nothing that F could not produce.
                Ok(Day {
                    obs: obs
                        .iter()
                        .zip(&inv.recon)
                        .map(|(v, r)| if v.is_nan() { *r } else { *v as f64 })
                        .collect(),
                    physics: inv.physics[..nc].to_vec(),
                    params: inv.params[..np].to_vec(),
                })
            })
            .collect::<Result<_>>()?;
    Ok((days, rows))
}

/// Residuals (observation − F(E(x)), standardised) of every day of `splits`, in time order, with
/// the tangent space of F at the main source's typical position. `extra_sources`: the most
/// extra sources F may hold; while it holds fewer, a new source must be told from the declared
/// ones ([`Context::sources_span`], [`Context::trading`]).
pub fn residuals(
    p: &GnssProblem,
    model: &Model<'_>,
    splits: &[SplitName],
    mode: MainSource,
    extra_sources: usize,
) -> Result<GnssResiduals> {
    let nc = p.data.n_obs();
    if model.n_obs() != nc {
        bail!("the model has {} channels, the data {}", model.n_obs(), nc);
    }
    if nc != 3 * p.network.len() {
        bail!("expected 3 channels per station");
    }
    let np = model.n_params();
    let (mut days, mut rows) = (Vec::new(), Vec::new());
    for &s in splits {
        let (d, r) = invert_split(p, model, s)?;
        days.extend(d);
        rows.extend(r);
    }
    if days.len() < MIN_DAYS {
        bail!(
            "{} days are too few for the analysis (at least {MIN_DAYS})",
            days.len()
        );
    }
    let mut order: Vec<usize> = (0..days.len()).collect();
    order.sort_by(|&a, &b| days[a].total_cmp(&days[b]));
    let days: Vec<f64> = order.iter().map(|&i| days[i]).collect();
    let mut slots: Vec<Option<Day>> = rows.into_iter().map(Some).collect();
    let rows: Vec<Day> = order.iter().filter_map(|&i| slots[i].take()).collect();
    let main = main_source(p, &rows, &days)?;
    let scale = &p.data.scale;
    let columns = jacobian_columns(model, scale, main, days[days.len() / 2])?;
    let mse = rows
        .iter()
        .flat_map(|d| (0..nc).map(move |c| ((d.obs[c] - d.physics[c]) / scale[c]).powi(2)))
        .sum::<f64>()
        / (rows.len() * nc) as f64;
    // Observations less F's time-dependent effects (F with the source's volume and the latent
    // effects at zero), standardised; then projected off F's tangent (free or held).
    let mut p0 = vec![0.0; np];
    p0[..3].copy_from_slice(&main);
    let rows: Vec<Vec<f64>> = rows
        .par_iter()
        .zip(days.par_iter())
        .map(|(d, t)| {
            let mut f = vec![0.0; nc];
            magic_core::invert::forward(model, &p0, *t, &mut f)
                .map_err(|e| anyhow!("day {t}: {e}"))?;
            Ok((0..nc).map(|c| (d.obs[c] - f[c]) / scale[c]).collect())
        })
        .collect::<Result<_>>()?;
    let k = SOURCE_VARIABLES.min(columns.len());
    let mut declared = Vec::new();
    let mut j = mogi::N_PARAMS;
    for e in &model.effects {
        if let magic_core::effects::Effect::SecondSource {
            x_km,
            y_km,
            depth_km,
        } = *e
        {
            declared.push((j, [x_km, y_km, depth_km].map(f64::from)));
        }
        j += e.n_latent();
    }
    // With F holding as many extra sources as it may, no new one need be told from them.
    if declared.len() >= extra_sources {
        declared.clear();
    }
    let declared: Vec<_> = declared
        .iter()
        .filter_map(|&(j, at)| Some((columns.get(j)?, at)))
        .collect();
    let source_span = orthonormal(&columns[..k], 1e-9, 1);
    let trading = declared
        .iter()
        .map(|((c, _), at)| Trade {
            share: share_beyond(&source_span, c),
            at: *at,
        })
        .filter(|t| t.share < MIN_RESOLVABLE_DECLARED)
        .collect();
    let mut sources = columns[..k].to_vec();
    sources.extend(declared.into_iter().map(|(c, _)| c.clone()));
    let shared = Shared {
        network: &p.network,
        scale,
        mse,
        main,
        sources_span: orthonormal(&sources, 1e-9, 1),
        source_span,
        trading,
        splits,
        days: &days,
    };
    let held = held_tangent(
        &shared.source_span,
        &columns[k..],
        scale,
        p.network.len(),
        &rows,
    );
    Ok(match mode {
        MainSource::Held => view(
            &shared,
            &rows,
            held.unwrap_or_else(|| orthonormal(&columns, 1e-9, 1)),
        ),
        MainSource::Free => {
            let mut free = view(&shared, &rows, orthonormal(&columns, 1e-9, 1));
            free.held = held.map(|t| Arc::new(view(&shared, &rows, t)));
            free
        }
    })
}

/// A declared extra source the main source trades with ([`Context::trading`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trade {
    /// Its share of its field (in norm) beyond the main source's span.
    pub share: f64,
    /// Its position: x, y, depth (km).
    pub at: [f64; 3],
}

/// What the views of one set of residuals share ([`view`]).
struct Shared<'a> {
    network: &'a Network,
    scale: &'a [f64],
    mse: f64,
    main: [f64; 3],
    source_span: Vec<Vec<f64>>,
    sources_span: Vec<Vec<f64>>,
    trading: Vec<Trade>,
    splits: &'a [SplitName],
    days: &'a [f64],
}

/// The rows (one per day, standardised) projected off `tangent`, each channel's mean over the
/// days removed, in a context of their own.
fn view(shared: &Shared<'_>, rows: &[Vec<f64>], tangent: Vec<Vec<f64>>) -> GnssResiduals {
    let nc = shared.scale.len();
    let r: Vec<Vec<f64>> = rows.par_iter().map(|row| project(&tangent, row)).collect();
    let taken = rows
        .iter()
        .zip(&r)
        .flat_map(|(row, p)| row.iter().zip(p).map(|(a, b)| a - b))
        .collect();
    let mut fit = Block {
        days: shared.days.to_vec(),
        r: r.concat(),
    };
    let t_n = fit.len(nc);
    let mut mean = vec![0.0; nc];
    for row in fit.r.chunks(nc) {
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v / t_n as f64;
        }
    }
    for row in fit.r.chunks_mut(nc) {
        for (v, m) in row.iter_mut().zip(&mean) {
            *v -= m;
        }
    }
    let total_fit = fit.r.iter().map(|v| v * v).sum();
    GnssResiduals {
        ctx: Arc::new(Context {
            network: shared.network.clone(),
            scale: shared.scale.to_vec(),
            mean,
            mse: shared.mse,
            main_source: shared.main,
            tangent,
            source_span: shared.source_span.clone(),
            sources_span: shared.sources_span.clone(),
            trading: shared.trading.clone(),
            total_fit,
            splits: shared.splits.to_vec(),
            source_grid: OnceLock::new(),
            lasting_grid: OnceLock::new(),
            second_source: OnceLock::new(),
            pulse: OnceLock::new(),
        }),
        fit,
        held: None,
        taken: Some(Arc::new(taken)),
        kept: None,
    }
}

/// The columns of F's Jacobian (standardised units, each with its largest entry) at the main
/// source's typical position with a unit volume change (the span does not depend on the volume)
/// and the latent effects at zero (they enter linearly): the main source's position, depth and
/// volume, then the declared latent effects'.
fn jacobian_columns(
    model: &Model<'_>,
    scale: &[f64],
    main: [f64; 3],
    day: f64,
) -> Result<Vec<(Vec<f64>, f64)>> {
    const N: usize = magic_core::model_file::MAX_PARAMS;
    let np = model.n_params();
    let nc = scale.len();
    let mut p = [magic_core::Dual::<N>::constant(0.0); N];
    for (j, v) in p.iter_mut().enumerate().take(np) {
        let x = match j {
            0..=2 => main[j],
            3 => 1.0,
            _ => 0.0,
        };
        *v = magic_core::Dual::var(x, j);
    }
    let mut out = vec![magic_core::Dual::<N>::constant(0.0); nc];
    magic_core::invert::forward(model, &p[..np], day, &mut out)
        .map_err(|e| anyhow!("F's Jacobian: {e}"))?;
    Ok((0..np)
        .map(|j| scaled((0..nc).map(|c| out[c].d[j] / scale[c]).collect()))
        .collect())
}

/// The tangent basis with the main source held in place ([`MainSource::Held`]): its field's
/// direction ([`held_source`], fitted with the declared latent effects, free every day, and the
/// network's translations as nuisances) and the declared latent effects' directions. (A span
/// that holds a translation cannot tell the source from a common mode: then the source is left
/// free to move, its whole span projected off: `None`.)
///
/// `source` is the main source's span (orthonormal), `latent` the declared latent effects'
/// columns.
fn held_tangent(
    source: &[Vec<f64>],
    latent: &[(Vec<f64>, f64)],
    scale: &[f64],
    ns: usize,
    rows: &[Vec<f64>],
) -> Option<Vec<Vec<f64>>> {
    let latent = orthonormal(latent, 1e-9, 1);
    let unit =
        |v: &[Vec<f64>]| -> Vec<(Vec<f64>, f64)> { v.iter().map(|q| (q.clone(), 1.0)).collect() };
    let mut nuisance = translation_basis(scale, ns);
    nuisance.extend(latent.iter().cloned());
    let nuisance = orthonormal(&unit(&nuisance), 1e-9, 2);
    let mut tangent = vec![held_source(source, &nuisance, rows)?];
    tangent.extend(latent);
    Some(orthonormal(&unit(&tangent), 1e-9, 2))
}

/// The main source held in place: the one direction, within the span of its own Jacobian
/// (`source`, orthonormal), along which the rows vary most — the field of a source at a fixed
/// position whose volume changes (to first order around the typical position). What the rows
/// hold along the span's other directions (the source moving over time) is left in the
/// residuals: a second source near the main one, which the encoder mimics by moving the main
/// one, stays visible there. Each row's coordinates in the span are fitted with `nuisance`
/// (orthonormal: the network's translations, the declared latent effects) beside them, so that a
/// common mode, which the span partly holds, does not tilt the direction away from the source's
/// field.
fn held_source(source: &[Vec<f64>], nuisance: &[Vec<f64>], rows: &[Vec<f64>]) -> Option<Vec<f64>> {
    let k = source.len();
    let nc = source.first()?.len();
    // B = the span's directions off the nuisances; a row's coordinates: (BᵀB)⁻¹ Bᵀ row.
    let b: Vec<Vec<f64>> = source.iter().map(|q| project(nuisance, q)).collect();
    let btb = DMatrix::from_fn(k, k, |i, j| dot(&b[i], &b[j]));
    // Its eigenvalues lie in [0, 1]: near 0, a direction of the span is a nuisance's.
    if btb.clone().symmetric_eigen().eigenvalues.min() < MIN_OFF_NUISANCE {
        return None;
    }
    let inv = btb.try_inverse()?;
    let coords: Vec<DVector<f64>> = rows
        .iter()
        .map(|row| &inv * DVector::from_iterator(k, b.iter().map(|q| dot(q, row))))
        .collect();
    let n = coords.len().max(1) as f64;
    let mean = coords.iter().fold(DVector::zeros(k), |m, c| m + c) / n;
    let cov = coords.iter().fold(DMatrix::zeros(k, k), |m, c| {
        let d = c - &mean;
        m + &d * d.transpose()
    });
    let eig = cov.symmetric_eigen();
    let u = eig.eigenvectors.column(eig.eigenvalues.imax());
    let w: Vec<f64> = (0..nc)
        .map(|c| source.iter().zip(u.iter()).map(|(q, x)| q[c] * x).sum())
        .collect();
    let norm = dot(&w, &w).sqrt();
    (norm > 0.0).then(|| w.iter().map(|x| x / norm).collect())
}

/// The network's translation by 1 mm along component `k` (E, N, U) in standardised units, for
/// channels ordered component by component over `ns` stations.
pub fn translation(scale: &[f64], ns: usize, k: usize) -> Vec<f64> {
    (0..scale.len())
        .map(|c| {
            if c / ns.max(1) == k {
                1.0 / scale[c]
            } else {
                0.0
            }
        })
        .collect()
}

/// Orthonormal basis of the network's translations ([`translation`], every component).
fn translation_basis(scale: &[f64], ns: usize) -> Vec<Vec<f64>> {
    let columns: Vec<(Vec<f64>, f64)> = (0..scale.len() / ns.max(1))
        .map(|k| scaled(translation(scale, ns, k)))
        .collect();
    orthonormal(&columns, 1e-9, 2)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The main source's typical position: over the days of largest |ΔV| by the encoder (the top
/// quarter), the median of each day's least-squares source ([`refit`]). The encoder's own
/// positions are not used: briefly trained, with the network's common mode not yet in F, it puts
/// the source several km too deep on those days (trial seeds 111–114 under `red`: 10–12 km, the
/// refits 7.1–8.2 km, truth 7), and linearised there F leaves the main source's own episode in
/// the residuals.
fn main_source(p: &GnssProblem, rows: &[Day], days: &[f64]) -> Result<[f64; 3]> {
    let mut by_dv: Vec<usize> = (0..rows.len()).collect();
    by_dv.sort_by(|&a, &b| rows[b].params[3].abs().total_cmp(&rows[a].params[3].abs()));
    let top = &by_dv[..(by_dv.len() / 4).max(1)];
    let common = [OwnedEffect::CommonMode];
    let bytes = common[0].bytes();
    let effects = [common[0].borrow(&bytes)];
    let bounds = p.bounds(&common);
    let pb = lsq::Problem {
        stations: &p.network.stations,
        effects: &effects,
        bounds: &bounds,
        scale: &p.data.scale,
    };
    let pos: Vec<[f64; 3]> = top
        .par_iter()
        .map(|&i| refit(&pb, &rows[i], days[i]))
        .collect::<Result<_>>()?;
    Ok(core::array::from_fn(|k| {
        median(&mut pos.iter().map(|q| q[k]).collect::<Vec<_>>())
    }))
}

/// One day's main source (x, y, depth) refitted by least squares (`pb`: the source and the
/// network's translations, the Levenberg–Marquardt fit of `magic classical`) to the day's
/// observation less F's other terms as the encoder put them, started from the encoder's source.
fn refit(pb: &lsq::Problem<'_>, d: &Day, t: f64) -> Result<[f64; 3]> {
    let enc = [d.params[0], d.params[1], d.params[2], d.params[3]];
    let mut own = vec![0.0; d.obs.len()];
    mogi::field(pb.stations, &enc, &mut own).map_err(|e| anyhow!("day {t}: {e}"))?;
    let y: Vec<f64> = (0..own.len())
        .map(|c| d.obs[c] - (d.physics[c] - own[c]))
        .collect();
    let start = [enc[0], enc[1], enc[2], enc[3], 0.0, 0.0, 0.0];
    let f = lsq::fit(pb, &y, t, &start, &lsq::Options::default())
        .map_err(|e| anyhow!("day {t}: the main source's refit: {e}"))?;
    Ok(core::array::from_fn(|k| f.params()[k]))
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

pub mod series;
#[cfg(test)]
mod tests;
