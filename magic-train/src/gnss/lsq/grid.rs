//! The multi-start fit: a coarse grid over (x, y, depth) with the linear unknowns solved exactly,
//! the best points refined by Levenberg–Marquardt.

use super::normal::{linearise, solve};
use super::problem::{check, project, sum_sq};
use super::solver::levenberg_marquardt;
use super::{Fit, Options, Problem, MAX_KEEP, MAX_UNKNOWNS};
use magic_core::mogi;
use magic_core::Error;

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

/// Multi-start fit: screens a grid over (x, y, depth) with the linear unknowns (ΔV and the
/// effects' latent variables) solved exactly at every point, refines the `grid.keep` best points
/// by Levenberg–Marquardt and returns the fit with the lowest cost.
///
/// ```
/// use magic_train::gnss::lsq::{fit_grid, Grid, Options, Problem};
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
