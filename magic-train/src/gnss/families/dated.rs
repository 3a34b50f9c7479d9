//! What the dated families (per-channel functions of the date with fitted constants: seasonal
//! terms, a step, a drift) share: cross-validation over [`FOLDS`] contiguous blocks of the
//! analysed record (fitted without a block, scored on it: an effect confined to any period is
//! judged on the days it holds), and phase-randomised surrogates of the residuals with the fit
//! removed (one random phase per frequency shared by all channels, so spectra and cross-spectra
//! are kept).

use crate::analysis::score::weighted_gain;
use crate::analysis::surrogate::PhaseSurrogates;
use crate::gnss::residuals::Block;
use crate::gnss::GnssResiduals;
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;

/// Number of contiguous folds of the analysed split in the cross-validation.
pub const FOLDS: usize = 5;

/// A fitted dated family: its prediction of channel c on a day, as a deviation from the
/// channel's mean over the rows it was fitted on (0 for channels it leaves alone).
pub trait TimeFit: Sync {
    /// The prediction.
    fn predict(&self, c: usize, day: f64) -> f64;
    /// Whether the family predicts channel c.
    fn active(&self, _c: usize) -> bool {
        true
    }
}

/// A dated fit with its cross-validated score.
pub struct Scored<F> {
    /// The fit on the whole analysed split.
    pub fit: F,
    /// Its cross-validated share of the residual variance.
    pub score: f64,
}

/// Least squares of every channel on a basis shared by all channels (`basis(day)` values, a
/// constant included by the caller): coefficients per channel (zeros where singular).
pub fn fit_basis(
    r: &[f64],
    days: &[f64],
    nc: usize,
    nb: usize,
    basis: &dyn Fn(f64, &mut [f64]),
) -> Vec<Vec<f64>> {
    let mut ata = DMatrix::<f64>::zeros(nb, nb);
    let mut atr = DMatrix::<f64>::zeros(nb, nc);
    let mut b = vec![0.0; nb];
    for (t, &d) in days.iter().enumerate() {
        basis(d, &mut b);
        for i in 0..nb {
            for j in 0..nb {
                ata[(i, j)] += b[i] * b[j];
            }
            for c in 0..nc {
                atr[(i, c)] += b[i] * r[t * nc + c];
            }
        }
    }
    let lu = ata.lu();
    (0..nc)
        .map(|c| {
            let rhs = DVector::from_iterator(nb, (0..nb).map(|i| atr[(i, c)]));
            match lu.solve(&rhs) {
                Some(x) if x.iter().all(|v| v.is_finite()) => x.iter().copied().collect(),
                _ => vec![0.0; nb],
            }
        })
        .collect()
}

/// `(Σ r·p, Σ p², Σ r²)` of a fit's prediction over `block`, the residuals taken relative to
/// `level` (the channel means of the rows the family was fitted on); only the channels the
/// family predicts count in the first two sums.
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

/// Cross-validated score of a dated family: fitted on the record without each of [`FOLDS`]
/// contiguous blocks and scored on the block left out. Returns the share of the variance of the
/// scored days explained by the predictions, scaled by one least-squares weight.
pub fn cv_score<F: TimeFit>(fit: &Block, nc: usize, refit: &dyn Fn(&Block) -> F) -> f64 {
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
        let (da, db, dv) = ab_on(&test, nc, &f, &level);
        a += da;
        b += db;
        v += dv;
    }
    weighted_gain((a, b)) / v
}

/// Fits on the whole analysed split and scores by [`cv_score`].
pub fn fit_scored<F: TimeFit>(res: &GnssResiduals, refit: &dyn Fn(&Block) -> F) -> Scored<F> {
    Scored {
        fit: refit(&res.fit),
        score: cv_score(&res.fit, res.nc(), refit),
    }
}

/// A dated family's bootstrap draw: its fit kept, the rest phase-randomised as for the
/// surrogates and added back.
pub fn resample(res: &GnssResiduals, f: &dyn TimeFit, rng: &mut StdRng) -> GnssResiduals {
    let nc = res.nc();
    let mut noise = res.fit.r.clone();
    let mut effect = vec![0.0; noise.len()];
    for (t, &d) in res.fit.days.iter().enumerate() {
        for c in 0..nc {
            let p = f.predict(c, d);
            noise[t * nc + c] -= p;
            effect[t * nc + c] = p;
        }
    }
    let noise = PhaseSurrogates::new(&noise, nc).draw(rng);
    res.with_fit(noise.iter().zip(&effect).map(|(n, e)| n + e).collect())
}

/// A dated family's surrogate: its fit removed, the rest phase-randomised.
pub fn surrogate(res: &GnssResiduals, f: &dyn TimeFit, rng: &mut StdRng) -> GnssResiduals {
    let nc = res.nc();
    let mut r = res.fit.r.clone();
    for (t, &d) in res.fit.days.iter().enumerate() {
        for c in 0..nc {
            r[t * nc + c] -= f.predict(c, d);
        }
    }
    res.with_fit(PhaseSurrogates::new(&r, nc).draw(rng))
}
