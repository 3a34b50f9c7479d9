//! The matched filter for a change that stays ([`Matched`]): the residuals whitened by a noise
//! model fitted to them (white plus AR(1), one shape for every channel, each its own level), a
//! ramp of [`RAMP_DAYS`] at onsets every [`ONSET_SPACING_DAYS`], and the generalised least
//! squares z of a source's pattern along each ramp, every station at its own weight — the
//! lasting source's; and, under the same noise, for a change that comes back ([`pulse`]), the
//! second source's.
//!
//! Why: whitened by slow noise, a change is seen while it happens, and a ramp about as long as
//! it matches it nearly whole; the persistence needs long lags (1–512 days) to be told from a
//! random walk (docs/matched-filter.md: on the same residuals this finds the lasting deflations
//! at the record's ends that the held-out-station gain loses).

use rayon::prelude::*;

/// Length (days) of the ramp a change builds along: the middle of the two to four months the
/// scenarios a lasting change is tried on build over.
pub const RAMP_DAYS: f64 = 90.0;
/// Days between the onsets searched.
pub const ONSET_SPACING_DAYS: f64 = 10.0;
/// Days from either end of the record to the first and last onsets.
pub const ONSET_EDGE_DAYS: f64 = 60.0;
/// Lags (days) of the structure functions the noise's shape is fitted to.
pub const LAGS: [usize; 10] = [1, 2, 4, 8, 16, 32, 64, 128, 256, 512];
/// Share of a lag's squared differences kept (the smallest): a few large ones (a step, an
/// episode) would read as noise.
const KEPT: f64 = 0.95;
/// The mean of the smallest [`KEPT`] of χ²₁ values over the mean of all of them: scales the
/// kept mean back to a Gaussian's.
const KEPT_MEAN: f64 = 0.7588;
/// Least pairs a lag needs to enter the fit.
const MIN_PAIRS: usize = 50;

/// The noise's shape, shared by every channel: white of unit variance plus an AR(1) of
/// persistence `phi` and stationary variance `rho` (in units of the white's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    /// The AR(1)'s persistence per day.
    pub phi: f64,
    /// The AR(1)'s stationary variance over the white's.
    pub rho: f64,
}

impl Shape {
    /// The structure function at `lag` days over its value at one day.
    fn ratio(&self, lag: f64) -> f64 {
        (1.0 + self.rho * (1.0 - self.phi.powf(lag))) / (1.0 + self.rho * (1.0 - self.phi))
    }
}

/// Robust half mean squared difference of channel `c` of `r` (`nc` channels, rows on `days`)
/// between days `lag` apart: the mean of the smallest [`KEPT`] scaled by [`KEPT_MEAN`]; `None`
/// with fewer than [`MIN_PAIRS`] pairs.
fn structure(r: &[f64], nc: usize, days: &[f64], c: usize, lag: usize) -> Option<f64> {
    let mut d: Vec<f64> = (0..days.len().saturating_sub(lag))
        .filter(|&t| (days[t + lag] - days[t] - lag as f64).abs() < 0.5)
        .map(|t| (r[(t + lag) * nc + c] - r[t * nc + c]).powi(2))
        .filter(|v| v.is_finite())
        .collect();
    if d.len() < MIN_PAIRS {
        return None;
    }
    let keep = ((KEPT * d.len() as f64) as usize).max(1);
    d.select_nth_unstable_by(keep - 1, f64::total_cmp);
    Some(d[..keep].iter().sum::<f64>() / keep as f64 / KEPT_MEAN / 2.0)
}

/// The noise fitted to `r` (rows on `days`, `nc` channels): the [`Shape`] whose structure
/// function over its one-day value fits, on a log scale, the median over channels of theirs at
/// the [`LAGS`] within a quarter of the record (persistences `1 − 10^(−4…−0.5)`, variance
/// ratios `10^(−2…3)`); and each channel's white variance from its one-day value. `None` when
/// the record is too short for two lags, a channel has no one-day differences, or `r` does not
/// hold `nc` channels on `days`.
pub fn fit_noise(r: &[f64], nc: usize, days: &[f64]) -> Option<(Shape, Vec<f64>)> {
    if nc == 0 || r.len() != days.len() * nc {
        return None;
    }
    let span = days.last()? - days.first()?;
    let lags: Vec<usize> = LAGS
        .iter()
        .copied()
        .filter(|&l| (l as f64) < span / 4.0)
        .collect();
    // Per lag, every channel's structure over its one-day value.
    let one: Vec<f64> = (0..nc)
        .map(|c| structure(r, nc, days, c, 1).filter(|v| *v > 0.0))
        .collect::<Option<_>>()?;
    let shape: Vec<(f64, f64)> = lags
        .iter()
        .filter_map(|&l| {
            let mut v: Vec<f64> = (0..nc)
                .filter_map(|c| structure(r, nc, days, c, l).map(|s| s / one[c]))
                .collect();
            (v.len() * 2 > nc).then(|| (l as f64, crate::numerics::median(&mut v)))
        })
        .collect();
    if shape.len() < 2 {
        return None;
    }
    let mut best = (f64::INFINITY, Shape { phi: 0.0, rho: 0.0 });
    for i in 0..120 {
        let phi = 1.0 - 10f64.powf(-4.0 + 3.5 * i as f64 / 119.0);
        for j in 0..200 {
            let s = Shape {
                phi,
                rho: 10f64.powf(-2.0 + 5.0 * j as f64 / 199.0),
            };
            let err: f64 = shape
                .iter()
                .map(|&(l, v)| (s.ratio(l).ln() - v.max(1e-300).ln()).powi(2))
                .sum();
            if err < best.0 {
                best = (err, s);
            }
        }
    }
    let s = best.1;
    let levels = one
        .iter()
        .map(|v| (v / (1.0 + s.rho * (1.0 - s.phi))).max(1e-300))
        .collect();
    Some((s, levels))
}

/// Ramps at onsets and the whitened residuals' products with them: enough to give the z of any
/// pattern at any onset in `O(channels)` ([`Matched::z`]).
#[derive(Clone, Debug)]
pub struct Matched {
    /// The onsets' days.
    pub onset_days: Vec<f64>,
    /// The fitted noise's shape.
    pub shape: Shape,
    /// Per onset and channel, ⟨ĥ_k, ŷ_c⟩ / level_c: the whitened ramp and residuals (each
    /// channel's whitened under the unit level), each off the whitened constant, weighted so a
    /// pattern's numerator is a plain dot product.
    cross: Vec<f64>,
    /// Per onset, 1 / |ĥ_k| (0 where the ramp is not identified).
    inv_ramp_norm: Vec<f64>,
    /// Per channel, 1 / level_c.
    inv_level: Vec<f64>,
}

/// The whitening filter of the noise on given days: the Kalman filter of a stationary AR(1)
/// seen through white noise, started from the AR(1)'s stationary variance, so that the
/// innovations it gives are exactly independent (a gap of L days decays the state by φᴸ). Its
/// gains depend on the days alone: computed once, applied to every series.
#[derive(Clone, Debug)]
struct Kalman {
    /// Per row: the state's decay since the previous row, the gain, 1 / the innovation's sd.
    rows: Vec<(f64, f64, f64)>,
}

impl Kalman {
    /// The filter of `shape` (unit white variance) on `days`.
    fn new(shape: Shape, days: &[f64]) -> Kalman {
        let mut p = shape.rho;
        let rows = days
            .iter()
            .enumerate()
            .map(|(t, d)| {
                let a = if t == 0 {
                    1.0
                } else {
                    shape.phi.powf((d - days[t - 1]).max(0.0))
                };
                if t > 0 {
                    p = a * a * p + shape.rho * (1.0 - a * a);
                }
                let f = p + 1.0;
                let k = p / f;
                p *= 1.0 - k;
                (a, k, 1.0 / f.sqrt())
            })
            .collect();
        Kalman { rows }
    }

    /// The standardised innovations of `x` (one value per row).
    fn whiten(&self, x: &[f64]) -> Vec<f64> {
        let mut s = 0.0;
        x.iter()
            .zip(&self.rows)
            .map(|(v, (a, k, isf))| {
                s *= a;
                let inn = v - s;
                s += k * inn;
                inn * isf
            })
            .collect()
    }

    /// The whitened constant, of unit norm (`None` where it has none).
    fn unit_constant(&self) -> Option<Vec<f64>> {
        let mut level = self.whiten(&vec![1.0; self.rows.len()]);
        let norm = dot(&level, &level).sqrt();
        if !(norm > 0.0 && norm.is_finite()) {
            return None;
        }
        level.iter_mut().for_each(|v| *v /= norm);
        Some(level)
    }

    /// `x` whitened and projected off the unit vector `level` (the whitened constant).
    fn whiten_off(&self, x: &[f64], level: &[f64]) -> Vec<f64> {
        let mut e = self.whiten(x);
        let p = dot(level, &e);
        e.iter_mut().zip(level).for_each(|(v, q)| *v -= p * q);
        e
    }
}

/// 1 / √x, or 0 where x is not a positive finite number (a pattern or ramp not identified).
fn inv_sqrt(x: f64) -> f64 {
    if x > 0.0 && x.is_finite() {
        1.0 / x.sqrt()
    } else {
        0.0
    }
}

/// Σ aᵢbᵢ over four running sums (which the compiler can keep in one vector register).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            acc[i] += x[i] * y[i];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// The ramp from day `onset` rising to 1 over [`RAMP_DAYS`], on `days`.
pub fn ramp(days: &[f64], onset: f64) -> Vec<f64> {
    days.iter()
        .map(|d| ((d - onset) / RAMP_DAYS).clamp(0.0, 1.0))
        .collect()
}

impl Matched {
    /// The filter on residuals `r` (rows on `days`, `nc` channels, row-major), with the noise
    /// fitted to them ([`fit_noise`]), at onsets every [`ONSET_SPACING_DAYS`] from
    /// [`ONSET_EDGE_DAYS`] after the first day to as many before the last, those `keep` admits.
    /// `None` when the noise cannot be fitted or no onset is kept.
    pub fn new(r: &[f64], nc: usize, days: &[f64], keep: impl Fn(f64) -> bool) -> Option<Matched> {
        let (shape, levels) = fit_noise(r, nc, days)?;
        Matched::with_noise(r, nc, days, shape, &levels, keep)
    }

    /// [`Matched::new`] with a given noise (`levels`: each channel's white variance).
    pub fn with_noise(
        r: &[f64],
        nc: usize,
        days: &[f64],
        shape: Shape,
        levels: &[f64],
        keep: impl Fn(f64) -> bool,
    ) -> Option<Matched> {
        let n = days.len();
        let (first, last) = (*days.first()?, *days.last()?);
        let onset_days: Vec<f64> = (0..)
            .map(|i| first + ONSET_EDGE_DAYS + ONSET_SPACING_DAYS * i as f64)
            .take_while(|d| *d <= last - ONSET_EDGE_DAYS)
            .filter(|d| keep(*d))
            .collect();
        if onset_days.is_empty() || levels.len() != nc || r.len() != n * nc {
            return None;
        }
        let kalman = Kalman::new(shape, days);
        let level = kalman.unit_constant()?;
        let ys: Vec<Vec<f64>> = (0..nc)
            .into_par_iter()
            .map(|c| {
                let x: Vec<f64> = (0..n).map(|t| r[t * nc + c]).collect();
                kalman.whiten_off(&x, &level)
            })
            .collect();
        let per_onset: Vec<(Vec<f64>, f64)> = onset_days
            .par_iter()
            .map(|&o| {
                let h = kalman.whiten_off(&ramp(days, o), &level);
                let cross = ys.iter().zip(levels).map(|(y, l)| dot(&h, y) / l).collect();
                (cross, inv_sqrt(dot(&h, &h)))
            })
            .collect();
        Some(Matched {
            onset_days,
            shape,
            cross: per_onset.iter().flat_map(|p| p.0.iter().copied()).collect(),
            inv_ramp_norm: per_onset.iter().map(|p| p.1).collect(),
            inv_level: levels.iter().map(|l| 1.0 / l).collect(),
        })
    }

    /// The z of pattern `g` (one value per channel) changing along the ramp at onset `k`, its
    /// amplitude free: standard normal where the residuals are the fitted noise; 0 where the
    /// pattern or the ramp is not identified.
    pub fn z(&self, g: &[f64], k: usize) -> f64 {
        self.z_scaled(g, inv_sqrt(self.weighted_norm2(g)), k)
    }

    /// Σ g_c² / level_c: the pattern's part of [`Matched::z`]'s denominator, the same at every
    /// onset.
    fn weighted_norm2(&self, g: &[f64]) -> f64 {
        g.iter()
            .zip(&self.inv_level)
            .map(|(v, il)| v * v * il)
            .sum()
    }

    /// [`Matched::z`] given 1 / √[`weighted_norm2`](Matched::weighted_norm2) `inv_g`: the
    /// inner loop of [`Matched::table`], a dot product of `channels` terms.
    fn z_scaled(&self, g: &[f64], inv_g: f64, k: usize) -> f64 {
        let nc = self.inv_level.len();
        let (Some(cross), Some(inv_h)) = (
            self.cross.get(k * nc..(k + 1) * nc),
            self.inv_ramp_norm.get(k),
        ) else {
            return 0.0;
        };
        dot(g, cross) * inv_g * inv_h
    }

    /// |z| of every pattern (rows) at every onset (columns).
    pub fn table(&self, patterns: &[Vec<f64>]) -> Vec<Vec<f64>> {
        patterns
            .par_iter()
            .map(|g| {
                let inv_g = inv_sqrt(self.weighted_norm2(g));
                (0..self.onsets())
                    .map(|k| self.z_scaled(g, inv_g, k).abs())
                    .collect()
            })
            .collect()
    }

    /// The number of onsets.
    pub fn onsets(&self) -> usize {
        self.onset_days.len()
    }
}

pub mod pulse;
#[cfg(test)]
mod tests;
