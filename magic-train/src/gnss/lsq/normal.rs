//! The linearised problem: the normal equations `JᵀJ`, `Jᵀr` from the exact Jacobian (forward-mode
//! dual numbers) and their damped solution over the free unknowns.

use super::Problem;
use super::{Mat, Vector, D, MAX_UNKNOWNS};
use magic_core::effects::mogi_with_effects;
use magic_core::model_file::MAX_OBS;
use magic_core::Error;

/// Σ r², JᵀJ and Jᵀr at a point.
pub(super) struct Lin {
    pub(super) cost: f64,
    pub(super) jtj: Mat,
    pub(super) g: Vector,
}

pub(super) fn linearise(
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
pub(super) fn solve(
    lin: &Lin,
    free: &[bool; MAX_UNKNOWNS],
    n: usize,
    lambda: f64,
) -> Option<Vector> {
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
