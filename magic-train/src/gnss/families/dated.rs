//! What the dated families (per-channel functions of the date with fitted constants: seasonal
//! terms, a step, a drift) share: cross-validation over [`FOLDS`] folds of interleaved blocks of
//! [`CV_BLOCK_DAYS`] rows (fold j holds blocks j, j + FOLDS, …: fitted without a fold, scored
//! on it), so that every fold's fit sees days on both sides of any epoch — an effect confined to
//! any period, even the record's first or last months, is judged on the days it holds with a
//! fit that has seen it —, and phase-randomised surrogates of the residuals with the fit removed
//! (one random phase per frequency shared by all channels, so spectra and cross-spectra are
//! kept), which carry the same autocorrelation and so the same leakage between neighbouring
//! blocks.

use crate::analysis::score::weighted_gain;
use crate::analysis::surrogate::PhaseSurrogates;
use crate::gnss::residuals::Block;
use crate::gnss::GnssResiduals;
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;

/// Number of folds of the analysed split in the cross-validation.
pub const FOLDS: usize = 5;

/// Rows (days) per block of the cross-validation's folds: twice the step scan's margin
/// ([`super::step::STEP_SCAN_DAYS`]), so that a held-out block can hold an epoch with the
/// margin's days on both sides.
pub const CV_BLOCK_DAYS: usize = 2 * super::step::STEP_SCAN_DAYS;

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

/// The rows of `b` whose fold (block of [`CV_BLOCK_DAYS`] rows, round robin over [`FOLDS`]) is
/// (`held_out`) or is not fold `j`.
fn fold_rows(b: &Block, nc: usize, j: usize, held_out: bool) -> Block {
    let keep = |t: usize| ((t / CV_BLOCK_DAYS) % FOLDS == j) == held_out;
    let rows: Vec<usize> = (0..b.days.len()).filter(|&t| keep(t)).collect();
    Block {
        days: rows.iter().map(|&t| b.days[t]).collect(),
        r: rows
            .iter()
            .flat_map(|&t| b.r[t * nc..(t + 1) * nc].iter().copied())
            .collect(),
    }
}

/// Cross-validated score of a dated family: fitted on the record without each of [`FOLDS`]
/// folds of interleaved blocks and scored on the fold left out. Returns the share of the
/// variance of the scored days explained by the predictions, scaled by one least-squares weight.
pub fn cv_score<F: TimeFit>(fit: &Block, nc: usize, refit: &dyn Fn(&Block) -> F) -> f64 {
    let (mut a, mut b, mut v) = (0.0, 0.0, 0.0);
    for j in 0..FOLDS {
        let train = fold_rows(fit, nc, j, false);
        let test = fold_rows(fit, nc, j, true);
        if train.days.is_empty() || test.days.is_empty() {
            continue;
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::families::step::fit_block;
    use rand::{Rng, SeedableRng};

    /// `n` days of uniform noise on `nc` channels, with a step (`offset` on the channels of
    /// station 1 of 4) from day `epoch` on.
    fn record(n: usize, epoch: usize, offset: [f64; 3]) -> Block {
        let (ns, nc) = (4usize, 12usize);
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut r: Vec<f64> = (0..n * nc).map(|_| rng.random_range(-1.0..1.0)).collect();
        for t in epoch..n {
            for (k, o) in offset.iter().enumerate() {
                r[t * nc + k * ns + 1] += o;
            }
        }
        Block {
            days: (0..n).map(|t| 15_000.0 + t as f64).collect(),
            r,
        }
    }

    #[test]
    fn folds_partition_the_rows_and_span_the_record() {
        let b = record(1000, 0, [0.0; 3]);
        let mut seen = vec![0usize; 1000];
        for j in 0..FOLDS {
            let held = fold_rows(&b, 12, j, true);
            let kept = fold_rows(&b, 12, j, false);
            assert_eq!(held.days.len() + kept.days.len(), 1000);
            assert_eq!(held.r.len(), 12 * held.days.len());
            // The rows kept reach both ends of the record.
            assert!(kept.days[0] < 15_000.0 + CV_BLOCK_DAYS as f64 * FOLDS as f64);
            assert!(*kept.days.last().unwrap() > 15_999.0 - (CV_BLOCK_DAYS * FOLDS) as f64);
            for d in &held.days {
                seen[(*d - 15_000.0) as usize] += 1;
            }
        }
        assert!(
            seen.iter().all(|&s| s == 1),
            "every row held out exactly once"
        );
    }

    /// A step in the record's first tenth is scored (every fold's fit sees both of its sides):
    /// the cross-validated share is most of the share the step holds.
    #[test]
    fn a_step_near_the_start_is_scored() {
        let (nc, ns) = (12, 4);
        let offset = [1.5, -1.0, 2.0];
        let b = record(1000, 100, offset);
        // The step's share of the variance (means removed): p(1 − p)·Σ offset² over the total.
        let held: f64 = 0.9 * 0.1 * offset.iter().map(|o| o * o).sum::<f64>();
        let share = held / (held + nc as f64 / 3.0);
        let s = cv_score(&b, nc, &|b| fit_block(b, nc, ns, &[]));
        assert!(
            s > 0.8 * share,
            "cv score {s:.4} vs the step's share {share:.4}"
        );
    }
}
