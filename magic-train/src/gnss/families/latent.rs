//! What the latent families (whose variables the encoder would infer every day: a network
//! translation, an elevation term, a second source) share: each is a pattern over the channels
//! with a daily amplitude, scored by predicting each station from the other stations (leave one
//! station out) on the neighbouring days (±[`NEIGHBOUR_WINDOWS`] days, the day itself excluded,
//! best window taken), on the residuals less their running mean over ±[`LATENT_HIGHPASS_DAYS`]
//! days. A day-to-day white network jitter is noise, not an effect: only a term that persists
//! from day to day and is shared by the network scores.
//!
//! **Chance.** The family's daily fit is removed, each channel scaled back to the variance the
//! projection took from it ([`unshrunk`]), and each station's series is given a random sign and
//! direction of time ([`flip_reverse`]: network coherence destroyed, every station's own series
//! kept whole), then projected again like the residuals themselves.

use crate::analysis::projection::{leverage, orthonormal};
use crate::analysis::score::weighted_gain;
use crate::analysis::surrogate::{flip_reverse, PhaseSurrogates};
use crate::gnss::GnssResiduals;
use nalgebra::DMatrix;
use rand::rngs::StdRng;

/// Days on each side of a day whose residuals predict it (the best of these windows is taken:
/// from weather-like terms to slow transients).
pub const NEIGHBOUR_WINDOWS: [usize; 3] = [3, 10, 30];
/// Half-width (days) of the running mean removed from the residuals before the latent families
/// are scored (see [`highpass`]): they are judged on variations faster than about two years.
/// Slower ones are dominated by each station's own red noise (monument and reference-frame
/// wander), of which a split of a few years holds only a few independent cycles: chance coherence
/// between stations is then large, and the sign/time-reversal surrogates, which can only rearrange
/// those few cycles, understate how large it gets. Weather-like terms, seasons (a whole number of
/// cycles in the window) and transients of up to a year or two are kept.
pub const LATENT_HIGHPASS_DAYS: usize = 365;
/// Squared norm (standardised units per unit of the effect's variable) below which a projected
/// pattern counts as already produced by F (the effect is declared).
pub const DECLARED_NORM2: f64 = 1e-12;

/// A latent family's fit: its held-out score (share of the residual variance) and the
/// neighbour window that gave it.
#[derive(Clone, Copy, Debug, Default)]
pub struct LatentFit {
    /// Share of the analysed split's residual variance explained.
    pub score: f64,
    /// Neighbour window (days).
    pub window: usize,
}

/// Running sums of every channel over the rows (`sum[t * nc + c]`: rows before t), for window
/// means in constant time.
pub(super) struct Prefix {
    nc: usize,
    t_n: usize,
    sum: Vec<f64>,
}

impl Prefix {
    /// The running sums of the rows `r` (`nc` channels).
    pub(super) fn new(r: &[f64], nc: usize) -> Prefix {
        let t_n = r.len() / nc;
        let mut sum = vec![0.0; (t_n + 1) * nc];
        for t in 0..t_n {
            for c in 0..nc {
                sum[(t + 1) * nc + c] = sum[t * nc + c] + r[t * nc + c];
            }
        }
        Prefix { nc, t_n, sum }
    }

    /// Number of rows.
    pub(super) fn rows(&self) -> usize {
        self.t_n
    }

    /// Number of channels.
    pub(super) fn channels(&self) -> usize {
        self.nc
    }

    /// Sum of channel c over rows `lo..hi`.
    pub(super) fn sum(&self, c: usize, lo: usize, hi: usize) -> f64 {
        self.sum[hi * self.nc + c] - self.sum[lo * self.nc + c]
    }

    /// `m`: the mean of the rows within ±w of row t (whose values are `row`), t excluded.
    fn neighbour_mean(&self, row: &[f64], t: usize, w: usize, m: &mut [f64]) {
        let (lo, hi) = (t.saturating_sub(w), (t + w + 1).min(self.t_n));
        let k = (hi - lo - 1) as f64;
        for (c, mc) in m.iter_mut().enumerate() {
            *mc = (self.sum(c, lo, hi) - row[c]) / k;
        }
    }
}

/// Every channel less its running mean over ±h days (the mean of the days available at the ends):
/// variations slower than about 2h days removed, faster ones kept.
pub fn highpass(r: &[f64], nc: usize, h: usize) -> Vec<f64> {
    let t_n = r.len() / nc;
    let pre = Prefix::new(r, nc);
    let mut out = r.to_vec();
    for t in 0..t_n {
        let (lo, hi) = (t.saturating_sub(h), (t + h + 1).min(t_n));
        let k = (hi - lo) as f64;
        for c in 0..nc {
            out[t * nc + c] -= pre.sum(c, lo, hi) / k;
        }
    }
    out
}

/// Cross products of the residuals with their neighbour means: `c = Σₜ rₜ mₜᵀ`, `m = Σₜ mₜ mₜᵀ`,
/// where `mₜ` is the mean of the rows within ±w of t, t excluded.
pub struct Cross {
    nc: usize,
    c: Vec<f64>,
    m: Vec<f64>,
}

/// [`Cross`] of `r` for window `w`.
pub fn cross(r: &[f64], nc: usize, w: usize) -> Cross {
    let t_n = r.len() / nc;
    let pre = Prefix::new(r, nc);
    let (mut cm, mut mm) = (vec![0.0; nc * nc], vec![0.0; nc * nc]);
    let mut m = vec![0.0; nc];
    for t in 0..t_n {
        let row = &r[t * nc..(t + 1) * nc];
        pre.neighbour_mean(row, t, w, &mut m);
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
pub fn loso_ab(g: &[f64], x: &Cross, ns: usize) -> (f64, f64) {
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

/// `gᵀ C g / gᵀ g`: the residuals' variance along `g` that persists to the neighbouring days
/// (the cross products with the neighbour means), fitted on every station at once.
pub fn persistent_along(g: &[f64], x: &Cross) -> f64 {
    let nc = x.nc;
    let gg: f64 = g.iter().map(|v| v * v).sum();
    if gg < DECLARED_NORM2 {
        return 0.0;
    }
    let gcg: f64 = (0..nc)
        .map(|a| g[a] * (0..nc).map(|b| x.c[a * nc + b] * g[b]).sum::<f64>())
        .sum();
    gcg / gg
}

/// [`loso_ab`] day by day, with nuisance patterns: `(Σ r·p, Σ p²)` of every row of `r`
/// (window `w`), so that the gain can be taken over any interval of days. Each station's
/// channels are predicted by `g · â`, where â is `g`'s amplitude in a least-squares fit of `g`
/// and the `nuisance` patterns together to the other stations' neighbour means: what the
/// nuisance explains (a network translation, say) is neither credited to `g` nor held against
/// it. Without nuisance, summed over all days it is [`loso_ab`] of [`cross`]`(r, nc, w)`.
pub fn loso_daily(
    g: &[f64],
    nuisance: &[Vec<f64>],
    r: &[f64],
    nc: usize,
    ns: usize,
    w: usize,
) -> Vec<(f64, f64)> {
    let t_n = r.len() / nc.max(1);
    let gg: f64 = g.iter().map(|v| v * v).sum();
    if gg < DECLARED_NORM2 || t_n < 2 {
        return vec![(0.0, 0.0); t_n];
    }
    let nk = nc / ns;
    let mut cols: Vec<&[f64]> = vec![g];
    cols.extend(nuisance.iter().map(|v| v.as_slice()));
    let k = cols.len();
    let gm = DMatrix::<f64>::from_fn(nc, k, |c, j| cols[j][c]);
    let gtg = gm.transpose() * &gm;
    let largest = gtg.diagonal().max();
    // Per station: the first row of the inverse Gram matrix of the other stations' channels
    // (g's amplitude as a combination of the projections), or None where it is singular.
    let rows: Vec<Option<Vec<f64>>> = (0..ns)
        .map(|i| {
            let ci: Vec<usize> = (0..nk).map(|q| q * ns + i).collect();
            let gi = gm.select_rows(&ci);
            let own = gi.transpose() * &gi;
            if own[(0, 0)] == 0.0 {
                return None;
            }
            let ch = (&gtg - &own).cholesky()?;
            if ch.l().diagonal().iter().any(|d| d * d <= 1e-12 * largest) {
                return None;
            }
            Some(ch.inverse().row(0).iter().copied().collect())
        })
        .collect();
    let pre = Prefix::new(r, nc);
    let mut m = vec![0.0; nc];
    (0..t_n)
        .map(|t| {
            let row = &r[t * nc..(t + 1) * nc];
            pre.neighbour_mean(row, t, w, &mut m);
            let v: Vec<f64> = cols
                .iter()
                .map(|col| col.iter().zip(&m).map(|(a, b)| a * b).sum())
                .collect();
            let (mut rp, mut pp) = (0.0, 0.0);
            for (i, a0) in rows.iter().enumerate() {
                let Some(a0) = a0 else { continue };
                let a: f64 = (0..k)
                    .map(|j| {
                        let vi: f64 = (0..nk).map(|q| cols[j][q * ns + i] * m[q * ns + i]).sum();
                        a0[j] * (v[j] - vi)
                    })
                    .sum();
                for q in 0..nk {
                    let c = q * ns + i;
                    let p = g[c] * a;
                    rp += row[c] * p;
                    pp += p * p;
                }
            }
            (rp, pp)
        })
        .collect()
}

/// The largest [`weighted_gain`] over intervals of whole blocks of `block` days (at least
/// `min_blocks` of them, up to the whole record) of day-by-day `(Σ r·p, Σ p²)`: the gain of a
/// transient judged where it happens rather than diluted over the whole record.
pub fn best_interval_gain(daily: &[(f64, f64)], block: usize, min_blocks: usize) -> f64 {
    best_interval(daily, block, min_blocks).0
}

/// [`best_interval_gain`] and the rows of its interval (the first of equal gains; the whole
/// record when nothing gains).
///
/// ```
/// use magic_train::gnss::families::latent::best_interval;
/// let mut daily = vec![(-1.0, 1.0); 6];
/// daily[2] = (3.0, 1.0);
/// daily[3] = (3.0, 1.0);
/// let (gain, rows) = best_interval(&daily, 2, 1);
/// assert_eq!(rows, 2..4);
/// assert!((gain - 18.0).abs() < 1e-12);
/// ```
pub fn best_interval(
    daily: &[(f64, f64)],
    block: usize,
    min_blocks: usize,
) -> (f64, std::ops::Range<usize>) {
    let block = block.max(1);
    let mut pre = vec![(0.0, 0.0)];
    for ch in daily.chunks(block) {
        let last = *pre.last().unwrap_or(&(0.0, 0.0));
        let (a, b) = ch.iter().fold((0.0, 0.0), |s, d| (s.0 + d.0, s.1 + d.1));
        pre.push((last.0 + a, last.1 + b));
    }
    let nb = pre.len() - 1;
    let mut best = (0.0f64, 0..daily.len());
    for a in 0..nb {
        for b in a + min_blocks.clamp(1, nb.max(1))..=nb {
            let g = weighted_gain((pre[b].0 - pre[a].0, pre[b].1 - pre[a].1));
            if g > best.0 {
                best = (g, a * block..(b * block).min(daily.len()));
            }
        }
    }
    best
}

/// The [`weighted_gain`] of day-by-day `(Σ r·p, Σ p²)` over the rows `rows` (those the record
/// holds).
pub fn interval_gain(daily: &[(f64, f64)], rows: std::ops::Range<usize>) -> f64 {
    let rows = rows.start.min(daily.len())..rows.end.min(daily.len());
    weighted_gain(
        daily[rows]
            .iter()
            .fold((0.0, 0.0), |s, d| (s.0 + d.0, s.1 + d.1)),
    )
}

/// The leave-one-station-out gain of pattern `g`.
pub fn loso_gain(g: &[f64], x: &Cross, ns: usize) -> f64 {
    weighted_gain(loso_ab(g, x, ns))
}

/// The cross products of the analysed block, high-passed, for every neighbour window.
pub fn windows(res: &GnssResiduals) -> Vec<(usize, Cross)> {
    let nc = res.nc();
    let r = highpass(&res.fit.r, nc, LATENT_HIGHPASS_DAYS);
    NEIGHBOUR_WINDOWS
        .iter()
        .map(|&w| (w, cross(&r, nc, w)))
        .collect()
}

/// The best window's summed gain of `patterns` (a family with several patterns, like a
/// three-component translation, predicts with all of them), as a share of the residual variance.
pub fn best_window(res: &GnssResiduals, patterns: &[Vec<f64>]) -> LatentFit {
    let ns = res.ns();
    let mut best = (0.0, 0usize);
    for (w, x) in windows(res) {
        let g: f64 = patterns.iter().map(|p| loso_gain(p, &x, ns)).sum();
        if g > best.0 || best.1 == 0 {
            best = (g, w);
        }
    }
    LatentFit {
        score: best.0 / res.ctx.total_fit.max(1e-300),
        window: best.1,
    }
}

/// Daily least-squares amplitude of a pattern (standardised units) on every row.
///
/// A pattern already inside F's tangent space (an effect the model declares) projects to
/// (numerically) nothing: its amplitude is then 0.
pub fn daily_amplitude(r: &[f64], nc: usize, g: &[f64]) -> Vec<f64> {
    let gg: f64 = g.iter().map(|v| v * v).sum();
    if gg < DECLARED_NORM2 {
        return vec![0.0; r.len() / nc];
    }
    r.chunks(nc)
        .map(|row| row.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() / gg)
        .collect()
}

/// Lag-one autocovariance of a series (the variance of its day-to-day persistent part).
pub fn persistent_var(a: &[f64]) -> f64 {
    if a.len() < 2 {
        return 0.0;
    }
    a.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (a.len() - 1) as f64
}

/// The part of [`persistent_var`] of a pattern's daily amplitude `a` (from [`daily_amplitude`])
/// that the channels' own persistent noise puts there: each channel's lag-one autocovariance about
/// the daily fit, weighted by the pattern's square, the channels taken independent.
///
/// Slow per-station noise (monument wander) is persistent from day to day: its network average is
/// part of `persistent_var(a)` though no station shares it. Subtracting this leaves the part the
/// stations share.
pub fn persistent_noise(r: &[f64], nc: usize, g: &[f64], a: &[f64]) -> f64 {
    let gg: f64 = g.iter().map(|v| v * v).sum();
    let t_n = a.len();
    if gg < DECLARED_NORM2 || t_n < 2 || r.len() != t_n * nc {
        return 0.0;
    }
    let mut lag1 = vec![0.0; nc];
    for t in 1..t_n {
        let (prev, row) = (&r[(t - 1) * nc..t * nc], &r[t * nc..(t + 1) * nc]);
        for c in 0..nc {
            lag1[c] += (prev[c] - a[t - 1] * g[c]) * (row[c] - a[t] * g[c]);
        }
    }
    g.iter().zip(&lag1).map(|(x, l)| x * x * l).sum::<f64>() / ((t_n - 1) as f64 * gg * gg)
}

/// The largest leverage [`unshrunk`] scales back from: a channel almost inside the removed span
/// keeps too little of its noise to be scaled back up.
pub const MAX_LEVERAGE: f64 = 0.9;

/// A latent family's surrogate: the daily fits of `patterns` removed, each channel's noise scaled
/// back to the variance the data's hold ([`unshrunk`]), every station's series given a random
/// sign and direction of time, projected again. The data's rows were projected once, off F's
/// tangent and the translations; a surrogate's are projected twice, the flipped rows again, so
/// unscaled, along every pattern beyond that span they would hold less noise than the data (on
/// `paper`-noise clean data, about two-thirds of its variance), and the chance level would come
/// out low.
pub fn surrogate(res: &GnssResiduals, patterns: &[Vec<f64>], rng: &mut StdRng) -> GnssResiduals {
    let nc = res.nc();
    let (_, r) = split_effect(&res.fit.r, nc, patterns);
    let mut cols: Vec<(Vec<f64>, f64)> = res.ctx.tangent.iter().map(|q| (q.clone(), 1.0)).collect();
    cols.extend(patterns.iter().map(|q| (q.clone(), 1.0)));
    let r = unshrunk(&r, nc, &orthonormal(&cols, 1e-9, 2));
    let r = flip_reverse(&r, nc, res.ns(), rng);
    res.with_fit(res.project_rows(&r))
}

/// Rows `r` (`nc` channels; already projected off the orthonormal `removed`) with each channel
/// divided by `√(1 − h)`, `h` its [`leverage`] under `removed` (at most [`MAX_LEVERAGE`]): noise of
/// equal variance on every channel keeps `1 − h` of it on a channel once projected, which this
/// gives back — the modified residuals of the regression bootstrap (Davison & Hinkley 1997,
/// §6.2.3), the projection being each day's least-squares fit of the removed span.
pub fn unshrunk(r: &[f64], nc: usize, removed: &[Vec<f64>]) -> Vec<f64> {
    let k: Vec<f64> = leverage(removed, nc)
        .iter()
        .map(|h| (1.0 - h.min(MAX_LEVERAGE)).sqrt().recip())
        .collect();
    r.chunks(nc.max(1))
        .flat_map(|row| row.iter().zip(&k).map(|(v, s)| v * s))
        .collect()
}

/// `r` split into the daily fits of `patterns` (the effect) and the rest (the noise).
pub fn split_effect(r: &[f64], nc: usize, patterns: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let mut noise = r.to_vec();
    let mut effect = vec![0.0; noise.len()];
    for g in patterns {
        let a = daily_amplitude(&noise, nc, g);
        for ((row, e), at) in noise.chunks_mut(nc).zip(effect.chunks_mut(nc)).zip(&a) {
            for c in 0..nc {
                row[c] -= at * g[c];
                e[c] += at * g[c];
            }
        }
    }
    (effect, noise)
}

/// A latent family's bootstrap draw: the daily fits of `patterns` kept, the rest randomised as
/// for the surrogates (flipped and projected as in [`surrogate`], not scaled back) and added back.
pub fn resample(res: &GnssResiduals, patterns: &[Vec<f64>], rng: &mut StdRng) -> GnssResiduals {
    let nc = res.nc();
    let (effect, noise) = split_effect(&res.fit.r, nc, patterns);
    let noise = res.project_rows(&flip_reverse(&noise, nc, res.ns(), rng));
    res.with_fit(noise.iter().zip(&effect).map(|(n, e)| n + e).collect())
}

/// A bootstrap draw that keeps the noise's network coherence: the daily fits of `patterns` kept,
/// the rest phase-randomised with one random phase per frequency shared by every channel (each
/// channel's spectrum and every cross-spectrum kept, [`PhaseSurrogates`]) and added back. For a
/// parameter that moves the pattern (a source's position) the error comes from the noise along
/// the pattern's derivatives, whose correlation between stations the per-station flips of
/// [`resample`] would destroy. Noise with no part along the patterns keeps none, so this draw
/// says nothing of an amplitude's error: it is for positions.
pub fn resample_coherent(
    res: &GnssResiduals,
    patterns: &[Vec<f64>],
    rng: &mut StdRng,
) -> GnssResiduals {
    res.with_fit(coherent_draw(&res.fit.r, res.nc(), patterns, rng))
}

/// The rows of [`resample_coherent`]'s draw from the rows `r`.
fn coherent_draw(r: &[f64], nc: usize, patterns: &[Vec<f64>], rng: &mut StdRng) -> Vec<f64> {
    let (effect, noise) = split_effect(r, nc, patterns);
    kept_plus_drawn(&effect, &noise, nc, rng)
}

/// A draw of the rows `r` that keeps the rows `kept` (an effect as modelled) and phase-randomises
/// the rest as [`resample_coherent`] does: `kept + draw(r − kept)`.
pub fn coherent_draw_keeping(r: &[f64], nc: usize, kept: &[f64], rng: &mut StdRng) -> Vec<f64> {
    let noise: Vec<f64> = r.iter().zip(kept).map(|(a, k)| a - k).collect();
    kept_plus_drawn(kept, &noise, nc, rng)
}

/// `kept` plus a phase surrogate of `noise` with one phase per frequency shared by every channel.
fn kept_plus_drawn(kept: &[f64], noise: &[f64], nc: usize, rng: &mut StdRng) -> Vec<f64> {
    let noise = PhaseSurrogates::new(noise, nc).draw(rng);
    noise.iter().zip(kept).map(|(n, k)| n + k).collect()
}

/// Whether every pattern projects to (numerically) nothing: F already produces it.
pub fn declared(patterns: &[Vec<f64>]) -> bool {
    patterns
        .iter()
        .all(|g| g.iter().map(|v| v * v).sum::<f64>() < DECLARED_NORM2)
}

/// `v` rounded to three decimals.
pub fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Mean of the rows within ±w of row t, t excluded (directly).
    fn neighbour_mean(r: &[f64], nc: usize, t: usize, w: usize) -> Vec<f64> {
        let t_n = r.len() / nc;
        let (lo, hi) = (t.saturating_sub(w), (t + w + 1).min(t_n));
        (0..nc)
            .map(|c| {
                (lo..hi)
                    .filter(|&u| u != t)
                    .map(|u| r[u * nc + c])
                    .sum::<f64>()
                    / (hi - lo - 1) as f64
            })
            .collect()
    }

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    /// Noise projected off a span (the data), flipped station by station and projected again (a
    /// surrogate) holds less along a pattern beyond the span than the data; scaled back by each
    /// channel's leverage first ([`unshrunk`]), as much, within the estimate's spread (about 2 %).
    /// One channel per station: the flips then leave no two channels' noise correlated on
    /// average over draws (a station's channels keep what the projection coupled between them,
    /// which the scaling does not undo).
    #[test]
    fn unshrunk_surrogates_hold_the_data_variance_beyond_the_span() {
        use crate::analysis::projection::project;
        let (ns, t_n) = (30, 3000);
        let nc = ns;
        let mut rng = StdRng::seed_from_u64(11);
        let mut random = || -> Vec<f64> { (0..nc).map(|_| rng.random_range(-1.0..1.0)).collect() };
        let cols: Vec<(Vec<f64>, f64)> = (0..8).map(|_| (random(), 1.0)).collect();
        let span = orthonormal(&cols, 1e-9, 2);
        let u = project(&span, &random());
        let norm = u.iter().map(|v| v * v).sum::<f64>().sqrt();
        let u: Vec<f64> = u.iter().map(|v| v / norm).collect();
        let projected =
            |r: &[f64]| -> Vec<f64> { r.chunks(nc).flat_map(|row| project(&span, row)).collect() };
        let data = projected(&noise(t_n * nc, 3));
        let along = |r: &[f64]| {
            r.chunks(nc)
                .map(|row| row.iter().zip(&u).map(|(a, b)| a * b).sum::<f64>().powi(2))
                .sum::<f64>()
                / t_n as f64
        };
        // Averaged over draws: one draw's signs leave chance covariances between stations.
        let draws = 40;
        let surrogates = |r: &[f64]| {
            (0..draws)
                .map(|k| {
                    along(&projected(&flip_reverse(
                        r,
                        nc,
                        ns,
                        &mut StdRng::seed_from_u64(k),
                    )))
                })
                .sum::<f64>()
                / draws as f64
        };
        let (d, plain, fixed) = (
            along(&data),
            surrogates(&data),
            surrogates(&unshrunk(&data, nc, &span)),
        );
        assert!(plain < 0.85 * d, "{plain} vs {d}");
        assert!((fixed / d - 1.0).abs() < 0.06, "{fixed} vs {d}");
    }

    /// Slow noise of each channel's own (AR(1), φ = 0.99) is persistent, so it puts a share into
    /// the daily amplitude's lag-one autocovariance; [`persistent_noise`] takes that share off and
    /// leaves the shared term's variance.
    #[test]
    fn persistent_noise_leaves_what_the_channels_share() {
        let (nc, t_n, phi) = (12, 4000, 0.99);
        let mut rng = StdRng::seed_from_u64(5);
        let mut step = |x: &mut f64, sd: f64| {
            *x = phi * *x + sd * (1.0 - phi * phi).sqrt() * rng.random_range(-1.7..1.7f64);
        };
        let (mut own, mut shared) = (vec![0.0; nc], 0.0);
        let mut r = vec![0.0; t_n * nc];
        let mut truth = vec![0.0; t_n];
        for t in 0..t_n {
            step(&mut shared, 0.5);
            truth[t] = shared;
            for c in 0..nc {
                step(&mut own[c], 2.0);
                r[t * nc + c] = own[c] + shared;
            }
        }
        let g = vec![1.0; nc];
        let a = daily_amplitude(&r, nc, &g);
        let (all, floor) = (persistent_var(&a), persistent_noise(&r, nc, &g, &a));
        let want = persistent_var(&truth);
        // Own noise's share of the network mean: about 2² / 12 ≈ 0.33 against 0.25 shared.
        assert!(all - want > 0.15, "{all} {want}");
        assert!(
            (all - floor - want).abs() < 0.25 * want,
            "{all} {floor} {want}"
        );
    }

    /// Zero-lag cross products of the channels (`nc × nc`).
    fn cross_products(r: &[f64], nc: usize) -> Vec<f64> {
        let mut m = vec![0.0; nc * nc];
        for row in r.chunks(nc) {
            for a in 0..nc {
                for b in 0..nc {
                    m[a * nc + b] += row[a] * row[b];
                }
            }
        }
        m
    }

    #[test]
    fn coherent_draw_keeps_the_effect_day_by_day_and_the_noise_cross_products() {
        // Four channels over 400 days: a pattern with a slow amplitude, plus noise correlated
        // between channels (a shared series and each channel's own).
        let (nc, n) = (4usize, 400usize);
        let g = vec![1.0, -0.5, 0.25, 2.0];
        let (shared, own) = (noise(n, 1), noise(n * nc, 2));
        let r: Vec<f64> = (0..n)
            .flat_map(|t| {
                let a = (t as f64 / 50.0).sin();
                let (g, own, s) = (&g, &own, shared[t]);
                (0..nc).map(move |c| a * g[c] + s + 0.5 * own[t * nc + c])
            })
            .collect();
        let mut rng = StdRng::seed_from_u64(7);
        let gs = [g];
        let out = coherent_draw(&r, nc, &gs, &mut rng);
        assert_ne!(out, r);
        for (x, y) in daily_amplitude(&out, nc, &gs[0])
            .iter()
            .zip(daily_amplitude(&r, nc, &gs[0]))
        {
            assert!((x - y).abs() < 1e-9, "daily amplitude {x} vs {y}");
        }
        let (noise_in, noise_out) = (split_effect(&r, nc, &gs).1, split_effect(&out, nc, &gs).1);
        let (a, b) = (
            cross_products(&noise_in, nc),
            cross_products(&noise_out, nc),
        );
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-9 * a[0], "cross product {x} vs {y}");
        }
    }

    #[test]
    fn a_draw_keeping_the_rows_gives_them_back_and_one_keeping_nothing_randomises_them() {
        let (nc, n) = (3usize, 256usize);
        let r = noise(n * nc, 7);
        let mut rng = StdRng::seed_from_u64(1);
        let same = coherent_draw_keeping(&r, nc, &r, &mut rng);
        assert!(same.iter().zip(&r).all(|(a, b)| (a - b).abs() < 1e-12));
        // Keeping nothing: a phase surrogate of the rows (cross products kept, the rows not).
        let drawn = coherent_draw_keeping(&r, nc, &vec![0.0; r.len()], &mut rng);
        let (a, b) = (cross_products(&r, nc), cross_products(&drawn, nc));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-9 * a[0], "cross product {x} vs {y}");
        }
        assert!(drawn.iter().zip(&r).any(|(a, b)| (a - b).abs() > 0.1));
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
        for t in h..n - h {
            assert!(out[2 * t].abs() < 1e-9, "day {t}: {}", out[2 * t]);
        }
        let var = |c: usize, v: &[f64]| (0..n).map(|t| v[2 * t + c].powi(2)).sum::<f64>();
        let kept = var(1, &out) / var(1, &r);
        assert!((kept - 1.0).abs() < 0.05, "fast variance kept: {kept}");
        let m = (0..n).map(|t| r[2 * t]).sum::<f64>() / n as f64;
        let slow = (0..n).map(|t| (r[2 * t] - m).powi(2)).sum::<f64>();
        assert!(var(0, &out) < 0.05 * slow, "slow variance kept");
    }

    #[test]
    fn day_by_day_sums_to_the_whole_record() {
        let (ns, nc, w) = (5usize, 15usize, 4usize);
        let r = noise(80 * nc, 41);
        let g = noise(nc, 42);
        let (a, b) = loso_ab(&g, &cross(&r, nc, w), ns);
        let daily = loso_daily(&g, &[], &r, nc, ns, w);
        let (da, db) = daily.iter().fold((0.0, 0.0), |s, d| (s.0 + d.0, s.1 + d.1));
        assert!((a - da).abs() < 1e-9 * (1.0 + a.abs()), "{a} {da}");
        assert!((b - db).abs() < 1e-9 * (1.0 + b.abs()), "{b} {db}");
        let whole = weighted_gain((da, db));
        assert!(best_interval_gain(&daily, 10, 1) >= whole);
        assert!((best_interval_gain(&daily, 10, 8) - whole).abs() < 1e-12 * (1.0 + whole));
    }

    #[test]
    fn day_by_day_with_nuisance_matches_a_direct_computation() {
        let (ns, nc, t_n, w) = (4usize, 12usize, 50usize, 3usize);
        let r = noise(t_n * nc, 51);
        let g = noise(nc, 52);
        let nu = vec![noise(nc, 53)];
        let daily = loso_daily(&g, &nu, &r, nc, ns, w);
        for t in [0usize, 17, 49] {
            let m = neighbour_mean(&r, nc, t, w);
            let (mut da, mut db) = (0.0, 0.0);
            for i in 0..ns {
                let others: Vec<usize> = (0..nc).filter(|c| c % ns != i).collect();
                let go = DMatrix::from_fn(others.len(), 2, |p, j| [&g, &nu[0]][j][others[p]]);
                let mo = nalgebra::DVector::from_fn(others.len(), |p, _| m[others[p]]);
                let amp =
                    (go.transpose() * &go).try_inverse().expect("invertible") * go.transpose() * mo;
                for c in (0..nc).filter(|c| c % ns == i) {
                    let p = g[c] * amp[0];
                    da += r[t * nc + c] * p;
                    db += p * p;
                }
            }
            let (a, b) = daily[t];
            assert!(
                (a - da).abs() < 1e-9 * (1.0 + da.abs()),
                "day {t}: {a} {da}"
            );
            assert!(
                (b - db).abs() < 1e-9 * (1.0 + db.abs()),
                "day {t}: {b} {db}"
            );
        }
    }

    #[test]
    fn leave_one_station_out_matches_a_direct_computation() {
        let (ns, nc, t_n, w) = (3usize, 9usize, 40usize, 2usize);
        let r = noise(t_n * nc, 11);
        let g = noise(nc, 12);
        let (a, b) = loso_ab(&g, &cross(&r, nc, w), ns);
        let (mut da, mut db) = (0.0, 0.0);
        for t in 0..t_n {
            let m = neighbour_mean(&r, nc, t, w);
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
}
