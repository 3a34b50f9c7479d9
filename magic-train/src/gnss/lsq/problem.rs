//! What is fitted and how well: the network, effects, bounds and channel scales, their
//! validation, and the day's weighted residual sum.

use super::MAX_UNKNOWNS;
use magic_core::effects::{mogi_with_effects, Effect};
use magic_core::model_file::MAX_OBS;
use magic_core::mogi::{self, Station};
use magic_core::Error;

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
pub(super) fn check(pb: &Problem<'_>, obs: &[f64]) -> Result<(usize, usize), Error> {
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

pub(super) fn project(bounds: &[[f64; 2]], p: &mut [f64; MAX_UNKNOWNS]) {
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
pub(super) fn sum_sq(
    pb: &Problem<'_>,
    obs: &[f64],
    t_day: f64,
    p: &[f64; MAX_UNKNOWNS],
    n: usize,
) -> f64 {
    let mut out = [0.0; MAX_OBS];
    let k = 3 * pb.stations.len();
    match mogi_with_effects(pb.stations, pb.effects, &p[..n], t_day, &mut out[..k]) {
        Ok(()) => weighted_ss(pb, obs, &out[..k]),
        Err(_) => f64::INFINITY,
    }
}
