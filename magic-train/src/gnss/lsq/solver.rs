//! The projected Levenberg–Marquardt iteration from one start point: its options, its result and
//! [`fit`].

use super::normal::{linearise, solve};
use super::problem::{check, project, sum_sq};
use super::{Problem, MAX_UNKNOWNS};
use magic_core::Error;

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

pub(super) fn levenberg_marquardt(
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
