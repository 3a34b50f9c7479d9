//! The lasting families' search by the matched filter (`--lasting matched`): the filter's |z|
//! table over the grid and onsets, the best onsets refined off the grid, and the fit at a given
//! position; the numerics are [`matched`](super::matched)'s.

use super::super::matched;
use super::{
    argmax, held_by, lasting_gain, lasting_grid, nearest, on_bound, pattern, pulse, refine,
    resolvable, translations, unresolvable, LastingFit, LastingSource, Prefix, CANDIDATES,
    MIN_RESOLVABLE, SCAN_DAYS,
};
use crate::gnss::residuals::SourceGrid;
use crate::gnss::GnssResiduals;

/// Standard deviations above the surrogates' mean (square-root scale: |z|) the matched
/// filter's statistic must reach to detect (`--lasting matched`), beside being above every
/// surrogate's.
pub const MATCHED_SD_MARGIN: f64 = 2.0;

/// The first row on or after `day` (the last row when none is).
fn row_at(days: &[f64], day: f64) -> usize {
    days.partition_point(|d| *d < day)
        .min(days.len().saturating_sub(1))
}

/// The search by the matched filter ([`matched`]) on the held view beside the pulse, as
/// [`search`](super::search): per onset the grid point of largest |z|, the
/// [`CANDIDATES`] onsets where it is largest at least [`SCAN_DAYS`] apart (the main source's
/// episodes would take every place), each refined off the grid by |z| at its onset (again from
/// the nearest admissible grid point where a move of the main source mimics it); the largest
/// |z| of those off the grid's bound and resolvable kept (of all of them where none is). Its
/// onset is the ramp's middle; its score the held-out gain of a change there.
pub(super) fn search_matched(res: &GnssResiduals, family: LastingSource) -> LastingFit {
    let ns = res.ns();
    let loc = res.locating();
    let r = pulse::taken_off(loc, pulse::beside(res));
    let days = &loc.fit.days;
    let SourceGrid {
        points: pts,
        patterns,
        ..
    } = lasting_grid(loc);
    let Some(mf) = family
        .matched(&r, loc.nc(), days)
        .filter(|_| !pts.is_empty())
    else {
        return LastingFit::default();
    };
    let table = mf.table(patterns);
    let mut by_onset: Vec<(f64, usize, usize)> = (0..mf.onsets())
        .map(|k| {
            let (v, pi) = argmax(table.iter().map(|row| row[k]).zip(0..));
            (v, pi, k)
        })
        .collect();
    by_onset.sort_by(|a, b| b.0.total_cmp(&a.0));
    let apart = (SCAN_DAYS as f64 / matched::ONSET_SPACING_DAYS).round() as usize;
    let mut chosen: Vec<(f64, usize, usize)> = Vec::new();
    for c in by_onset {
        if chosen.len() >= CANDIDATES {
            break;
        }
        if chosen.iter().all(|d| d.2.abs_diff(c.2) >= apart) {
            chosen.push(c);
        }
    }
    let admissible = |p: [f64; 3]| resolvable(loc, p) >= MIN_RESOLVABLE && held_by(loc, p);
    let (ts, pre) = (translations(loc), Prefix::new(&r, loc.nc()));
    let mut best: Option<(bool, LastingFit)> = None;
    for (v, pi, k) in chosen {
        let z_at = |g: &[f64]| mf.z(g, k).abs();
        let (mut pos, mut z) = refine(loc, pts, pts[pi], v, &z_at, &|_| true);
        if !admissible(pos) {
            if let Some(q) = nearest(pts, pos, &admissible) {
                (pos, z) = refine(loc, pts, q, z_at(&pattern(loc, q)), &z_at, &admissible);
            }
        }
        let kept = on_bound(pts, pos).is_none() && unresolvable(loc, pos).is_none();
        let onset = row_at(days, mf.onset_days[k] + 0.5 * matched::RAMP_DAYS);
        let fit = LastingFit {
            pos,
            onset,
            score: lasting_gain(&pattern(loc, pos), &ts, &pre, ns, onset),
            stat: z * z,
        };
        if best.is_none_or(|(bk, b)| (kept && !bk) || (kept == bk && fit.stat > b.stat)) {
            best = Some((kept, fit));
        }
    }
    let mut best = best.map(|b| b.1).unwrap_or_default();
    best.score /= loc.ctx.total_fit.max(1e-300);
    best
}

/// [`fit_at`] by the matched filter: the onset whose ramp's middle lies between `from` and
/// `to` (the nearest to their middle when none does, unless kept to the last year) where |z|
/// at `pos` is largest.
pub(super) fn fit_at_matched(
    family: LastingSource,
    res: &GnssResiduals,
    pos: [f64; 3],
    (from, to): (f64, f64),
) -> Option<LastingFit> {
    let (ns, loc) = (res.ns(), res.locating());
    let r = pulse::taken_off(loc, pulse::beside(res));
    let days = &loc.fit.days;
    let mf = family.matched(&r, loc.nc(), days)?;
    let middle = |k: usize| mf.onset_days[k] + 0.5 * matched::RAMP_DAYS;
    let mut inside: Vec<usize> = (0..mf.onsets())
        .filter(|&k| (from..=to).contains(&middle(k)))
        .collect();
    if inside.is_empty() && family.within_days.is_none() {
        let mid = 0.5 * (from + to);
        inside.extend(
            (0..mf.onsets())
                .min_by(|&a, &b| (middle(a) - mid).abs().total_cmp(&(middle(b) - mid).abs())),
        );
    }
    let g = pattern(loc, pos);
    let k = inside
        .into_iter()
        .max_by(|&a, &b| mf.z(&g, a).abs().total_cmp(&mf.z(&g, b).abs()))?;
    let onset = row_at(days, middle(k));
    let ts = translations(loc);
    let score = lasting_gain(&g, &ts, &Prefix::new(&r, loc.nc()), ns, onset);
    Some(LastingFit {
        pos,
        onset,
        score: score / loc.ctx.total_fit.max(1e-300),
        stat: mf.z(&g, k).powi(2),
    })
}
