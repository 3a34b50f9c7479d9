//! The classical baseline: per-observation nonlinear least squares for the Mogi source and the
//! latent variables of declared effects.
//!
//! For one day's observations y (mm; NaN = missing channel, left out) the fit minimises
//!
//! ```text
//! cost(p) = 1/m · Σ_c ((F(p)_c − y_c) / s_c)²      over the m observed channels c
//! ```
//!
//! where F is [`mogi_with_effects`] and s the per-channel standardisation scale, so `cost` is the
//! paper's MSE of that day in standardised units. The unknowns are `p = [x, y, depth, ΔV]` followed
//! by the latent variables of the effects, inside box bounds.
//!
//! The solver is a projected Levenberg–Marquardt method:
//!
//! * the Jacobian is exact, from forward-mode [`Dual`] numbers through the same F the encoder
//!   models use (no finite differences);
//! * each step solves the damped normal equations `(JᵀJ + λ·D) δ = −Jᵀr` (D the diagonal of JᵀJ,
//!   Marquardt's scaling) with a fixed-size Cholesky factorisation ([`nalgebra::SMatrix`], at most
//!   [`MAX_UNKNOWNS`] unknowns, no allocation); a factorisation that fails raises λ instead;
//! * bounds: the trial point is projected onto the box, and unknowns sitting on a bound with the
//!   gradient pushing outwards are held fixed for that step (a simple active set), so a solution
//!   on a bound is reached and recognised as converged.
//!
//! F is linear in ΔV and in every latent variable of the effects; only x, y and depth are
//! nonlinear. [`fit_grid`] uses that for its start points: on a coarse grid over (x, y, depth) the
//! linear unknowns are solved exactly (one Gauss–Newton step), the best grid points are kept and
//! refined by Levenberg–Marquardt, and the best refinement wins.
//!
//! No function here panics on input: wrong sizes, non-finite values, empty or inverted bounds and
//! too few observed channels are [`Error`]s; singular normal equations are damped.

use magic_core::effects::{mogi_with_effects, Effect};
use magic_core::model_file::MAX_OBS;
use magic_core::mogi::{self, Station};
use magic_core::{Dual, Error};
use nalgebra::{SMatrix, SVector};

/// Largest number of unknowns (4 source parameters plus the effects' latent variables).
pub const MAX_UNKNOWNS: usize = 8;

/// Largest number of grid points [`fit_grid`] refines.
pub const MAX_KEEP: usize = 8;

type Mat = SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>;
type Vector = SVector<f64, MAX_UNKNOWNS>;
type D = Dual<MAX_UNKNOWNS>;

/// What is fitted: the network, the declared effects, the bounds and the channel weights.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a> {
    /// Stations in channel order; observations are uₑ ×S, uₙ ×S, uᵥ ×S (mm).
    pub stations: &'a [Station],
    /// Declared effects; their latent variables follow the 4 source parameters, in this order.
    pub effects: &'a [Effect<'a>],
    /// `[min, max]` of every unknown (4 + the effects' latent variables), e.g.
    /// [`mogi::PAPER_BOUNDS`] for the source. The depth's minimum must be positive.
    pub bounds: &'a [[f64; 2]],
    /// Per-channel scale (mm): residuals are divided by it, so the cost is in standardised units.
    pub scale: &'a [f64],
}

impl Problem<'_> {
    /// Number of unknowns: 4 plus the effects' latent variables.
    pub fn n_unknowns(&self) -> usize {
        mogi::N_PARAMS + self.effects.iter().map(Effect::n_latent).sum::<usize>()
    }

    /// Checks sizes, bounds, scales and effects; returns the number of unknowns.
    pub fn validate(&self) -> Result<usize, Error> {
        let s = self.stations.len();
        if s == 0 || 3 * s > MAX_OBS {
            return Err(Error::SizeMismatch {
                what: "stations",
                expected: MAX_OBS / 3,
                found: s,
            });
        }
        let n = self.n_unknowns();
        if n > MAX_UNKNOWNS {
            return Err(Error::SizeMismatch {
                what: "least-squares unknowns",
                expected: MAX_UNKNOWNS,
                found: n,
            });
        }
        if self.bounds.len() != n {
            return Err(Error::SizeMismatch {
                what: "bounds",
                expected: n,
                found: self.bounds.len(),
            });
        }
        if self.scale.len() != 3 * s {
            return Err(Error::SizeMismatch {
                what: "channel scales",
                expected: 3 * s,
                found: self.scale.len(),
            });
        }
        for (i, st) in self.stations.iter().enumerate() {
            if !(st.x_km.is_finite() && st.y_km.is_finite() && st.z_km.is_finite()) {
                return Err(Error::NonFinite {
                    what: "station position",
                    index: i,
                });
            }
        }
        for (i, &[lo, hi]) in self.bounds.iter().enumerate() {
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(Error::NonFinite {
                    what: "bounds",
                    index: i,
                });
            }
            if lo > hi {
                return Err(Error::OutOfRange {
                    what: "bounds (minimum above maximum)",
                });
            }
        }
        if self.bounds[2][0] <= 0.0 {
            return Err(Error::OutOfRange {
                what: "depth bound (the minimum must be positive)",
            });
        }
        for (i, &sc) in self.scale.iter().enumerate() {
            if !sc.is_finite() {
                return Err(Error::NonFinite {
                    what: "channel scale",
                    index: i,
                });
            }
            if sc <= 0.0 {
                return Err(Error::OutOfRange {
                    what: "channel scale (must be positive)",
                });
            }
        }
        for e in self.effects {
            e.validate(s)?;
        }
        Ok(n)
    }
}

/// Stopping rules and damping of the Levenberg–Marquardt iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// Largest number of accepted or rejected steps.
    pub max_iter: u32,
    /// Converged when an accepted step lowers the cost by less than `ftol` relative.
    pub ftol: f64,
    /// Converged when an accepted step moves every unknown by less than `xtol` relative.
    pub xtol: f64,
    /// Converged when every free gradient component, as the cosine between the residual and the
    /// Jacobian column, is below `gtol`.
    pub gtol: f64,
    /// Initial damping λ.
    pub lambda0: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            max_iter: 200,
            ftol: 1e-12,
            xtol: 1e-12,
            gtol: 1e-10,
            lambda0: 1e-3,
        }
    }
}

/// A coarse start grid for [`fit_grid`]: points per axis over the bounds of x, y and depth (cell
/// centres), and how many of the best points are refined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grid {
    /// Points along x.
    pub nx: u8,
    /// Points along y.
    pub ny: u8,
    /// Points along depth.
    pub nd: u8,
    /// Best grid points refined by Levenberg–Marquardt (1 ..= [`MAX_KEEP`]).
    pub keep: u8,
}

impl Default for Grid {
    fn default() -> Self {
        Grid {
            nx: 5,
            ny: 5,
            nd: 4,
            keep: 3,
        }
    }
}

/// The result of a fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    /// Number of valid entries in `params`.
    pub n_params: usize,
    /// The unknowns: x (km), y (km), depth (km), ΔV (10⁶ m³), then the effects' latent variables.
    pub params: [f64; MAX_UNKNOWNS],
    /// Mean over the observed channels of the squared standardised residual (the day's MSE).
    pub cost: f64,
    /// Levenberg–Marquardt iterations (accepted steps) of the winning refinement.
    pub iterations: u32,
    /// Whether a stopping rule on cost, step or gradient was met (not the iteration limit).
    pub converged: bool,
    /// Observed channels used.
    pub n_used: usize,
}

impl Fit {
    /// The valid unknowns.
    pub fn params(&self) -> &[f64] {
        &self.params[..self.n_params]
    }
}

/// Fits one day's observations `obs` (mm; NaN = missing) made on day `t_day` (NaN if unknown,
/// which is an error only with time-dependent effects) from `start` (one value per unknown; it is
/// projected onto the bounds first).
pub fn fit(
    pb: &Problem<'_>,
    obs: &[f64],
    t_day: f64,
    start: &[f64],
    opts: &Options,
) -> Result<Fit, Error> {
    let (n, m) = check(pb, obs)?;
    if start.len() != n {
        return Err(Error::SizeMismatch {
            what: "start point",
            expected: n,
            found: start.len(),
        });
    }
    let mut p = [0.0; MAX_UNKNOWNS];
    for (j, &v) in start.iter().enumerate() {
        if !v.is_finite() {
            return Err(Error::NonFinite {
                what: "start point",
                index: j,
            });
        }
        p[j] = v;
    }
    project(pb.bounds, &mut p);
    levenberg_marquardt(pb, obs, t_day, p, n, m, opts)
}

/// Multi-start fit: screens a grid over (x, y, depth) with the linear unknowns (ΔV and the
/// effects' latent variables) solved exactly at every point, refines the `grid.keep` best points
/// by Levenberg–Marquardt and returns the fit with the lowest cost.
///
/// ```
/// use magic_train::lsq::{fit_grid, Grid, Options, Problem};
/// use magic_core::mogi::{field, Station, PAPER_BOUNDS};
/// let stations: [Station; 4] = core::array::from_fn(|i| Station {
///     x_km: [-5.0, 6.0, 1.0, 9.0][i], y_km: [3.0, -2.0, 6.0, 1.0][i], z_km: 0.0,
/// });
/// let mut obs = [0.0; 12];
/// field(&stations, &[1.0, 0.5, 6.0, 2.0], &mut obs)?;
/// let pb = Problem { stations: &stations, effects: &[], bounds: &PAPER_BOUNDS, scale: &[1.0; 12] };
/// let fit = fit_grid(&pb, &obs, f64::NAN, &Grid::default(), &Options::default())?;
/// assert!((fit.params[2] - 6.0).abs() < 1e-6 && fit.converged);
/// # Ok::<(), magic_core::Error>(())
/// ```
pub fn fit_grid(
    pb: &Problem<'_>,
    obs: &[f64],
    t_day: f64,
    grid: &Grid,
    opts: &Options,
) -> Result<Fit, Error> {
    let (n, m) = check(pb, obs)?;
    let axes = [grid.nx, grid.ny, grid.nd];
    if axes.contains(&0) {
        return Err(Error::OutOfRange {
            what: "grid size (every axis needs a point)",
        });
    }
    let keep = grid.keep as usize;
    if keep == 0 || keep > MAX_KEEP {
        return Err(Error::OutOfRange {
            what: "grid keep (1 to 8)",
        });
    }
    // The best `keep` screened points, sorted by cost.
    let mut best = [(f64::INFINITY, [0.0; MAX_UNKNOWNS]); MAX_KEEP];
    let mut held = 0usize;
    let mut linear = [false; MAX_UNKNOWNS];
    for l in linear.iter_mut().take(n).skip(mogi::N_PARAMS - 1) {
        *l = true;
    }
    for ix in 0..grid.nx {
        for iy in 0..grid.ny {
            for id in 0..grid.nd {
                let mut p = [0.0; MAX_UNKNOWNS];
                for (j, (k, nk)) in [(ix, grid.nx), (iy, grid.ny), (id, grid.nd)]
                    .into_iter()
                    .enumerate()
                {
                    let [lo, hi] = pb.bounds[j];
                    p[j] = lo + (hi - lo) * (k as f64 + 0.5) / nk as f64;
                }
                project(pb.bounds, &mut p);
                let lin = linearise(pb, obs, t_day, &p, n)?;
                let mut q = p;
                if let Some(d) = solve(&lin, &linear, n, 1e-12) {
                    for j in 0..n {
                        q[j] += d[j];
                    }
                    project(pb.bounds, &mut q);
                }
                let cq = sum_sq(pb, obs, t_day, &q, n);
                let (c, q) = if cq <= lin.cost {
                    (cq, q)
                } else {
                    (lin.cost, p)
                };
                if !c.is_finite() {
                    continue;
                }
                // Insert into the sorted list of the best points.
                let mut at = held.min(keep);
                while at > 0 && best[at - 1].0 > c {
                    at -= 1;
                }
                if at < keep {
                    let mut k = keep - 1;
                    while k > at {
                        best[k] = best[k - 1];
                        k -= 1;
                    }
                    best[at] = (c, q);
                    held = (held + 1).min(keep);
                }
            }
        }
    }
    if held == 0 {
        return Err(Error::NonFinite {
            what: "model output on every grid point",
            index: 0,
        });
    }
    let mut winner: Option<Fit> = None;
    let mut last_err = None;
    for (_, p) in best.iter().take(held) {
        match levenberg_marquardt(pb, obs, t_day, *p, n, m, opts) {
            Ok(f) => {
                if winner.is_none_or(|w| f.cost < w.cost) {
                    winner = Some(f);
                }
            }
            Err(e) => last_err = Some(e),
        }
    }
    match (winner, last_err) {
        (Some(f), _) => Ok(f),
        (None, Some(e)) => Err(e),
        (None, None) => Err(Error::NonFinite {
            what: "model output",
            index: 0,
        }),
    }
}

/// The day's cost (mean squared standardised residual over observed channels) at `params`.
pub fn cost(pb: &Problem<'_>, obs: &[f64], t_day: f64, params: &[f64]) -> Result<f64, Error> {
    let (n, m) = check(pb, obs)?;
    if params.len() != n {
        return Err(Error::SizeMismatch {
            what: "parameters",
            expected: n,
            found: params.len(),
        });
    }
    let mut p = [0.0; MAX_UNKNOWNS];
    p[..n].copy_from_slice(params);
    let mut out = [0.0; MAX_OBS];
    let k = 3 * pb.stations.len();
    mogi_with_effects(pb.stations, pb.effects, &p[..n], t_day, &mut out[..k])?;
    Ok(weighted_ss(pb, obs, &out[..k]) / m as f64)
}

/// Validates the problem and the observations; returns (unknowns, observed channels).
fn check(pb: &Problem<'_>, obs: &[f64]) -> Result<(usize, usize), Error> {
    let n = pb.validate()?;
    let k = 3 * pb.stations.len();
    if obs.len() != k {
        return Err(Error::SizeMismatch {
            what: "observations",
            expected: k,
            found: obs.len(),
        });
    }
    let mut m = 0;
    for (i, &y) in obs.iter().enumerate() {
        if y.is_nan() {
            continue;
        }
        if y.is_infinite() {
            return Err(Error::NonFinite {
                what: "observation",
                index: i,
            });
        }
        m += 1;
    }
    if m < n {
        return Err(Error::TooFewObservations {
            observed: m,
            needed: n,
        });
    }
    Ok((n, m))
}

fn project(bounds: &[[f64; 2]], p: &mut [f64; MAX_UNKNOWNS]) {
    for (v, &[lo, hi]) in p.iter_mut().zip(bounds) {
        *v = v.clamp(lo, hi);
    }
}

/// Σ ((F − y) / s)² over observed channels; +∞ if F is not finite there.
fn weighted_ss(pb: &Problem<'_>, obs: &[f64], f: &[f64]) -> f64 {
    let mut ss = 0.0;
    for ((&y, &fc), &s) in obs.iter().zip(f).zip(pb.scale) {
        if y.is_nan() {
            continue;
        }
        let r = (fc - y) / s;
        if !r.is_finite() {
            return f64::INFINITY;
        }
        ss += r * r;
    }
    ss
}

/// Σ r² at `p`, +∞ when F fails or is not finite (a rejected step, not an error).
fn sum_sq(pb: &Problem<'_>, obs: &[f64], t_day: f64, p: &[f64; MAX_UNKNOWNS], n: usize) -> f64 {
    let mut out = [0.0; MAX_OBS];
    let k = 3 * pb.stations.len();
    match mogi_with_effects(pb.stations, pb.effects, &p[..n], t_day, &mut out[..k]) {
        Ok(()) => weighted_ss(pb, obs, &out[..k]),
        Err(_) => f64::INFINITY,
    }
}

/// Σ r², JᵀJ and Jᵀr at a point.
struct Lin {
    cost: f64,
    jtj: Mat,
    g: Vector,
}

fn linearise(
    pb: &Problem<'_>,
    obs: &[f64],
    t_day: f64,
    p: &[f64; MAX_UNKNOWNS],
    n: usize,
) -> Result<Lin, Error> {
    let pd: [D; MAX_UNKNOWNS] = core::array::from_fn(|j| {
        if j < n {
            D::var(p[j], j)
        } else {
            D::constant(0.0)
        }
    });
    let mut out = [D::constant(0.0); MAX_OBS];
    let k = 3 * pb.stations.len();
    mogi_with_effects(pb.stations, pb.effects, &pd[..n], t_day, &mut out[..k])?;
    let mut lin = Lin {
        cost: 0.0,
        jtj: Mat::zeros(),
        g: Vector::zeros(),
    };
    for (c, ((&y, f), &s)) in obs.iter().zip(&out[..k]).zip(pb.scale).enumerate() {
        if y.is_nan() {
            continue;
        }
        let r = (f.v - y) / s;
        let row = Vector::from_fn(|j, _| f.d[j] / s);
        if !r.is_finite() || row.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "model output or derivative",
                index: c,
            });
        }
        lin.cost += r * r;
        lin.g += row * r;
        lin.jtj += row * row.transpose();
    }
    Ok(lin)
}

/// Solves `(JᵀJ + λ·D) δ = −Jᵀr` over the unknowns marked `free` (the others stay put).
fn solve(lin: &Lin, free: &[bool; MAX_UNKNOWNS], n: usize, lambda: f64) -> Option<Vector> {
    let max_diag = (0..n).map(|j| lin.jtj[(j, j)]).fold(0.0, f64::max);
    let floor = (max_diag * 1e-12).max(f64::MIN_POSITIVE);
    let mut a = Mat::identity();
    let mut rhs = Vector::zeros();
    for i in 0..n {
        if !free[i] {
            continue;
        }
        rhs[i] = -lin.g[i];
        for j in 0..n {
            if free[j] {
                a[(i, j)] = lin.jtj[(i, j)];
            }
        }
        a[(i, i)] += lambda * lin.jtj[(i, i)].max(floor);
    }
    let d = a.cholesky()?.solve(&rhs);
    d.iter().all(|v| v.is_finite()).then_some(d)
}

fn levenberg_marquardt(
    pb: &Problem<'_>,
    obs: &[f64],
    t_day: f64,
    mut p: [f64; MAX_UNKNOWNS],
    n: usize,
    m: usize,
    opts: &Options,
) -> Result<Fit, Error> {
    let mut lin = linearise(pb, obs, t_day, &p, n)?;
    let mut lambda = if opts.lambda0.is_finite() && opts.lambda0 > 0.0 {
        opts.lambda0
    } else {
        1e-3
    };
    let mut iterations = 0u32;
    let mut converged = false;
    let mut steps = 0u32;
    'outer: while steps < opts.max_iter {
        // Active set: unknowns on a bound whose descent direction points outwards stay fixed.
        let mut free = [false; MAX_UNKNOWNS];
        let mut gmax = 0.0f64;
        for j in 0..n {
            let [lo, hi] = pb.bounds[j];
            let blocked =
                (p[j] <= lo && lin.g[j] > 0.0) || (p[j] >= hi && lin.g[j] < 0.0) || lo == hi;
            free[j] = !blocked;
            if free[j] {
                let denom = (lin.jtj[(j, j)] * lin.cost).sqrt();
                if denom > 0.0 {
                    gmax = gmax.max(lin.g[j].abs() / denom);
                }
            }
        }
        if lin.cost <= f64::MIN_POSITIVE || gmax <= opts.gtol {
            converged = true;
            break;
        }
        loop {
            steps += 1;
            let trial = solve(&lin, &free, n, lambda).map(|d| {
                let mut q = p;
                for j in 0..n {
                    q[j] += d[j];
                }
                project(pb.bounds, &mut q);
                q
            });
            if let Some(q) = trial {
                let c = sum_sq(pb, obs, t_day, &q, n);
                if c < lin.cost {
                    let small_step =
                        (0..n).all(|j| (q[j] - p[j]).abs() <= opts.xtol * (p[j].abs() + opts.xtol));
                    let small_gain = lin.cost - c <= opts.ftol * lin.cost;
                    p = q;
                    lin = linearise(pb, obs, t_day, &p, n)?;
                    iterations += 1;
                    lambda = (lambda * 0.1).max(1e-15);
                    if small_step || small_gain {
                        converged = true;
                        break 'outer;
                    }
                    break;
                }
            }
            lambda *= 10.0;
            if lambda > 1e15 {
                // No damped step lowers the cost: a minimum to working precision.
                converged = true;
                break 'outer;
            }
            if steps >= opts.max_iter {
                break 'outer;
            }
        }
    }
    Ok(Fit {
        n_params: n,
        params: p,
        cost: lin.cost / m as f64,
        iterations,
        converged,
        n_used: m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use magic_core::mogi::PAPER_BOUNDS;

    /// The Akutan network (km), rounded from the data's `stations.json`.
    const NET: [Station; 12] = [
        Station {
            x_km: -4.245,
            y_km: 6.222,
            z_km: 0.350,
        },
        Station {
            x_km: -1.768,
            y_km: 2.273,
            z_km: 0.543,
        },
        Station {
            x_km: -5.478,
            y_km: -5.790,
            z_km: 0.298,
        },
        Station {
            x_km: -9.329,
            y_km: -1.453,
            z_km: 0.364,
        },
        Station {
            x_km: 10.695,
            y_km: 0.545,
            z_km: 0.463,
        },
        Station {
            x_km: -7.188,
            y_km: 2.299,
            z_km: 0.521,
        },
        Station {
            x_km: -6.520,
            y_km: -0.666,
            z_km: 0.598,
        },
        Station {
            x_km: -0.323,
            y_km: -4.972,
            z_km: 0.330,
        },
        Station {
            x_km: 2.049,
            y_km: 7.627,
            z_km: 0.405,
        },
        Station {
            x_km: 2.034,
            y_km: 1.202,
            z_km: 0.495,
        },
        Station {
            x_km: 5.726,
            y_km: -2.603,
            z_km: 0.396,
        },
        Station {
            x_km: 14.357,
            y_km: -4.685,
            z_km: 0.457,
        },
    ];

    /// Every fitted unknown within 1e-6 of the truth.
    fn assert_recovered(f: &Fit, truth: &[f64]) {
        assert_eq!(f.params().len(), truth.len());
        for (j, (p, t)) in f.params().iter().zip(truth).enumerate() {
            assert!((p - t).abs() < 1e-6, "p{j}: {p} vs {t}");
        }
    }

    fn scales() -> [f64; 36] {
        core::array::from_fn(|c| 1.0 + 0.25 * (c % 5) as f64)
    }

    fn synth(effects: &[Effect<'_>], truth: &[f64]) -> [f64; 36] {
        let mut y = [0.0; 36];
        mogi_with_effects(&NET, effects, truth, f64::NAN, &mut y).unwrap();
        y
    }

    fn bounds_with(extra: &[[f64; 2]]) -> ([[f64; 2]; MAX_UNKNOWNS], usize) {
        let mut b = [[0.0; 2]; MAX_UNKNOWNS];
        b[..4].copy_from_slice(&PAPER_BOUNDS);
        b[4..4 + extra.len()].copy_from_slice(extra);
        (b, 4 + extra.len())
    }

    #[test]
    fn recovers_a_known_source_from_noiseless_data() {
        let truth = [1.3, 0.4, 7.2, 3.1];
        let y = synth(&[], &truth);
        let sc = scales();
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let f = fit(
            &pb,
            &y,
            f64::NAN,
            &[5.0, 3.0, 12.0, 0.5],
            &Options::default(),
        )
        .unwrap();
        assert!(f.converged);
        assert_recovered(&f, &truth);
        assert!(f.cost < 1e-20, "cost {}", f.cost);
        let g = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert_recovered(&g, &truth);
        assert_eq!(g.n_used, 36);
        assert!((cost(&pb, &y, f64::NAN, g.params()).unwrap() - g.cost).abs() < 1e-15);
    }

    #[test]
    fn deflation_and_missing_channels() {
        let truth = [-2.0, 2.5, 4.0, -1.5];
        let mut y = synth(&[], &truth);
        for c in [0, 7, 13, 20, 35] {
            y[c] = f64::NAN;
        }
        let sc = scales();
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert_eq!(f.n_used, 31);
        assert_recovered(&f, &truth);
    }

    #[test]
    fn recovers_the_translation_with_common_mode() {
        let effects = [Effect::CommonMode];
        let truth = [2.0, 1.0, 6.0, 2.5, 4.0, -3.0, 7.5];
        let y = synth(&effects, &truth);
        let sc = scales();
        let (b, n) = bounds_with(&[[-30.0, 30.0]; 3]);
        let pb = Problem {
            stations: &NET,
            effects: &effects,
            bounds: &b[..n],
            scale: &sc,
        };
        assert_eq!(pb.n_unknowns(), 7);
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert!(f.converged);
        assert_eq!(f.params().len(), 7);
        assert_recovered(&f, &truth);
    }

    #[test]
    fn recovers_elevation_and_second_source_terms() {
        let effects = [
            Effect::CommonMode,
            Effect::Elevation { z_ref_km: 0.34 },
            Effect::SecondSource {
                x_km: 9.0,
                y_km: -3.0,
                depth_km: 3.0,
            },
        ];
        let truth = [0.5, 1.5, 8.0, 4.0, -1.0, 2.0, 0.5, 12.0, -0.8];
        // 9 unknowns exceed the solver's size: an error, not a panic.
        let sc = scales();
        let (b, _) = bounds_with(&[[-30.0, 30.0]; 4]);
        let mut b9 = [[0.0; 2]; 9];
        b9[..8].copy_from_slice(&b);
        b9[8] = [-10.0, 10.0];
        let pb = Problem {
            stations: &NET,
            effects: &effects,
            bounds: &b9,
            scale: &sc,
        };
        assert!(matches!(
            fit_grid(
                &pb,
                &[0.0; 36],
                f64::NAN,
                &Grid::default(),
                &Options::default()
            ),
            Err(Error::SizeMismatch { .. })
        ));
        // Elevation and second source without the common mode: 6 unknowns.
        let effects = [effects[1], effects[2]];
        let truth = [truth[0], truth[1], truth[2], truth[3], truth[7], truth[8]];
        let y = synth(&effects, &truth);
        let (b, n) = bounds_with(&[[-200.0, 200.0], [-10.0, 10.0]]);
        let pb = Problem {
            stations: &NET,
            effects: &effects,
            bounds: &b[..n],
            scale: &sc,
        };
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert_recovered(&f, &truth);
    }

    #[test]
    fn stops_on_a_bound() {
        // A source shallower than the bounds allow: the depth ends on its minimum, converged.
        let y = synth(&[], &[1.0, 1.0, 1.0, 0.3]);
        let sc = [1.0; 36];
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert_eq!(f.params[2], PAPER_BOUNDS[2][0]);
        assert!(f.converged && f.cost.is_finite());
        for (v, [lo, hi]) in f.params().iter().zip(PAPER_BOUNDS) {
            assert!((lo..=hi).contains(v));
        }
    }

    #[test]
    fn noisy_data_fit_is_no_worse_than_the_truth() {
        let truth = [3.0, -1.0, 9.0, 5.0];
        let mut y = synth(&[], &truth);
        let mut s = 12345u32;
        for v in y.iter_mut() {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *v += ((s >> 8) as f64 / (1u32 << 24) as f64 - 0.5) * 2.0;
        }
        let sc = scales();
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert!(f.cost <= cost(&pb, &y, f64::NAN, &truth).unwrap());
        assert!(f.converged);
    }

    #[test]
    fn wrong_sizes_and_non_finite_inputs_are_errors() {
        let sc = [1.0; 36];
        let y = synth(&[], &[1.0, 1.0, 6.0, 1.0]);
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let o = Options::default();
        let start = [0.0, 0.0, 5.0, 0.0];
        // Wrong sizes.
        assert!(matches!(
            fit(&pb, &y[..35], f64::NAN, &start, &o),
            Err(Error::SizeMismatch { .. })
        ));
        assert!(matches!(
            fit(&pb, &y, f64::NAN, &start[..3], &o),
            Err(Error::SizeMismatch { .. })
        ));
        let short = Problem {
            scale: &sc[..30],
            ..pb
        };
        assert!(matches!(
            fit(&short, &y, f64::NAN, &start, &o),
            Err(Error::SizeMismatch { .. })
        ));
        let nob = Problem {
            bounds: &PAPER_BOUNDS[..3],
            ..pb
        };
        assert!(matches!(
            fit(&nob, &y, f64::NAN, &start, &o),
            Err(Error::SizeMismatch { .. })
        ));
        let none = Problem {
            stations: &[],
            scale: &[],
            ..pb
        };
        assert!(fit(&none, &[], f64::NAN, &start, &o).is_err());
        // Non-finite inputs.
        let mut bad = y;
        bad[3] = f64::INFINITY;
        assert!(matches!(
            fit(&pb, &bad, f64::NAN, &start, &o),
            Err(Error::NonFinite { index: 3, .. })
        ));
        assert!(matches!(
            fit(&pb, &y, f64::NAN, &[f64::NAN, 0.0, 5.0, 0.0], &o),
            Err(Error::NonFinite { .. })
        ));
        let mut nsc = sc;
        nsc[5] = f64::NAN;
        assert!(fit(&Problem { scale: &nsc, ..pb }, &y, f64::NAN, &start, &o).is_err());
        nsc[5] = 0.0;
        assert!(fit(&Problem { scale: &nsc, ..pb }, &y, f64::NAN, &start, &o).is_err());
    }

    #[test]
    fn bad_bounds_sparse_data_bad_grids_and_undated_effects_are_errors() {
        let sc = [1.0; 36];
        let y = synth(&[], &[1.0, 1.0, 6.0, 1.0]);
        let pb = Problem {
            stations: &NET,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let o = Options::default();
        let start = [0.0, 0.0, 5.0, 0.0];
        // Bounds: inverted, non-finite, depth not positive.
        let mut b = PAPER_BOUNDS;
        b[0] = [1.0, -1.0];
        assert!(matches!(
            fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o),
            Err(Error::OutOfRange { .. })
        ));
        b[0] = [f64::NEG_INFINITY, 1.0];
        assert!(fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o).is_err());
        let mut b = PAPER_BOUNDS;
        b[2] = [0.0, 20.0];
        assert!(fit(&Problem { bounds: &b, ..pb }, &y, f64::NAN, &start, &o).is_err());
        // Too few observed channels.
        let mut sparse = [f64::NAN; 36];
        sparse[..3].copy_from_slice(&y[..3]);
        assert!(matches!(
            fit(&pb, &sparse, f64::NAN, &start, &o),
            Err(Error::TooFewObservations {
                observed: 3,
                needed: 4
            })
        ));
        assert!(fit_grid(&pb, &[f64::NAN; 36], f64::NAN, &Grid::default(), &o).is_err());
        // Grid without points or with too many kept.
        assert!(fit_grid(
            &pb,
            &y,
            f64::NAN,
            &Grid {
                nx: 0,
                ..Grid::default()
            },
            &o
        )
        .is_err());
        assert!(fit_grid(
            &pb,
            &y,
            f64::NAN,
            &Grid {
                keep: 9,
                ..Grid::default()
            },
            &o
        )
        .is_err());
        // Time-dependent effect without a date.
        let rate = [0u8; 4 * 36];
        let eff = [Effect::Drift {
            t0_day: 0.0,
            rate: magic_core::quant::LeF32(&rate),
        }];
        assert!(fit(
            &Problem {
                effects: &eff,
                ..pb
            },
            &y,
            f64::NAN,
            &start,
            &o
        )
        .is_err());
        assert!(fit(
            &Problem {
                effects: &eff,
                ..pb
            },
            &y,
            100.0,
            &start,
            &o
        )
        .is_ok());
    }

    #[test]
    fn singular_systems_are_damped_not_fatal() {
        // Every station at one point: x, y and depth are not separable; no panic, finite result.
        let st = [Station {
            x_km: 1.0,
            y_km: 1.0,
            z_km: 0.0,
        }; 4];
        let mut y = [0.0; 12];
        mogi::field(&st, &[0.0, 0.0, 5.0, 1.0], &mut y).unwrap();
        let sc = [1.0; 12];
        let pb = Problem {
            stations: &st,
            effects: &[],
            bounds: &PAPER_BOUNDS,
            scale: &sc,
        };
        let f = fit_grid(&pb, &y, f64::NAN, &Grid::default(), &Options::default()).unwrap();
        assert!(f.cost.is_finite() && f.cost < 1e-12);
        // Zero volume change: the Jacobian columns of x, y, depth vanish.
        let f = fit(
            &pb,
            &[0.0; 12],
            f64::NAN,
            &[0.0, 0.0, 5.0, 0.0],
            &Options::default(),
        )
        .unwrap();
        assert!(f.converged && f.cost == 0.0);
        // A flat (zero-width) bound holds its unknown.
        let mut b = PAPER_BOUNDS;
        b[2] = [5.0, 5.0];
        let f = fit(
            &Problem { bounds: &b, ..pb },
            &y,
            f64::NAN,
            &[3.0, 3.0, 9.0, 0.0],
            &Options::default(),
        )
        .unwrap();
        assert_eq!(f.params[2], 5.0);
    }
}
