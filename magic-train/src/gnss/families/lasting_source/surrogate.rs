//! The lasting source's surrogates: its fitted change taken off, each station's part of it put
//! back at an epoch of the station's own — no larger than the largest change that station makes
//! elsewhere in the record — and every station's series given a random sign and direction of
//! time.
//!
//! Taken off whole, the change took with it the noise's own largest coincidence, the one the
//! search had found, and the chance level fell below what noise alone reaches where a source's
//! field lies on a few stations: at the end of a long network, clean `paper` data gave lasting
//! sources beyond every surrogate in 2 of 10 runs, from the generator's noise alone (README,
//! *The lasting source's surrogates keep each station's wander*). Put back apart, a station's
//! excursion stays in its series while a true change cannot reassemble; clipped to the
//! station's own reach, the jump a true change makes at its nearest station comes back only as
//! large as that station's wander.

use super::super::latent;
use super::super::second_source::{pattern, translations};
use super::change::Change;
use super::{offsets, pulse, LastingFit, SCAN_DAYS, SCAN_EDGE_DAYS};
use crate::analysis::projection::{orthonormal, scaled};
use crate::analysis::surrogate::flip_reverse;
use crate::gnss::GnssResiduals;
use rand::rngs::StdRng;
use rand::Rng;

/// A change taken off a block of rows: the source's pattern beside the translations (unit
/// norm) and the change of its daily amplitude there.
pub(super) struct TakenOff {
    /// The pattern, orthonormal to the translations.
    pub(super) q: Vec<f64>,
    /// The change as modelled.
    pub(super) change: Change,
    /// Each channel's [`reach`] in the rows it was taken off.
    pub(super) reach: Vec<f64>,
}

/// `r` (rows of `view`) less the translations' daily fits and the change a source at `pos`
/// makes at row `onset` as modelled ([`Change`] of its daily amplitude beside the translations),
/// with what was taken off (none when the pattern lies in the translations' span).
fn less_change(
    view: &GnssResiduals,
    r: &[f64],
    pos: [f64; 3],
    onset: usize,
) -> (Vec<f64>, Option<TakenOff>) {
    let nc = view.nc();
    let mut cols: Vec<(Vec<f64>, f64)> = translations(view).into_iter().map(scaled).collect();
    let n_t = cols.len();
    cols.push(scaled(pattern(view, pos)));
    let basis = orthonormal(&cols, 1e-9, 2);
    let n_t = n_t.min(basis.len());
    let (_, mut rest) = latent::split_effect(r, nc, &basis[..n_t]);
    let Some(q) = basis.get(n_t).filter(|_| basis.len() == cols.len()) else {
        return (rest, None);
    };
    let change = Change::of(&latent::daily_amplitude(&rest, nc, q), onset);
    let reach = reach(&rest, nc, &change);
    for (t, row) in rest.chunks_mut(nc).enumerate() {
        let at = change.at(t);
        row.iter_mut().zip(q).for_each(|(k, qc)| *k -= at * qc);
    }
    let q = q.clone();
    (rest, Some(TakenOff { q, change, reach }))
}

/// Each channel's reach: the largest of its offsets ([`offsets`]) at the scanned epochs whose
/// windows stay clear of the change (they end before it begins or start after it is done).
pub(super) fn reach(rows: &[f64], nc: usize, change: &Change) -> Vec<f64> {
    let clear = |e: usize| e + SCAN_DAYS <= change.begun || e >= change.done + SCAN_DAYS;
    let d = offsets(rows, nc);
    (0..nc)
        .map(|c| {
            d.iter()
                .filter(|(e, _)| clear(*e))
                .map(|(_, de)| de[c].abs())
                .fold(0.0, f64::max)
        })
        .collect()
}

/// Puts each station's part of `taken` back into `rows` (`ns` stations, channel `c` of station
/// `c % ns`), moved from `onset` to the station's own epoch (`epochs`), each channel's jump no
/// larger than its reach.
pub(super) fn put_back(
    rows: &mut [f64],
    ns: usize,
    taken: &TakenOff,
    onset: usize,
    epochs: &[usize],
) {
    let TakenOff { q, change, reach } = taken;
    let nc = q.len();
    let t_n = rows.len() / nc.max(1);
    let step = change.after - change.before;
    for (t, row) in rows.chunks_mut(nc).enumerate() {
        for (c, (k, qc)) in row.iter_mut().zip(q).enumerate() {
            let moved = (t + onset).saturating_sub(epochs[c % ns]).min(t_n - 1);
            let u = if step != 0.0 {
                (change.at(moved) - change.before) / step
            } else {
                0.0
            };
            *k += change.before * qc + u * (step * qc).clamp(-reach[c], reach[c]);
        }
    }
}

/// One surrogate of the residuals for a lasting source fitted as `fit`, given back the held
/// view's part beyond them — the main source's moves as the data hold them, less the
/// translations' daily fits and the change along the source's pattern there
/// ([`GnssResiduals::beside_moves`]): what the source is located beside, in the data as in the
/// draw. Randomised station by station, the moves would lose the coherence by which the free
/// view projects them off and swell the chance level. The pulse the family is searched beside
/// ([`pulse::beside`]) is taken off first: randomised station by station, a pulse's months make
/// changes of the mean at every station by chance.
pub(super) fn draw(res: &GnssResiduals, fit: &LastingFit, rng: &mut StdRng) -> GnssResiduals {
    let (nc, ns) = (res.nc(), res.ns());
    let without = pulse::taken_off(res, pulse::beside(res));
    let (mut rows, taken) = less_change(res, &without, fit.pos, fit.onset);
    if let Some(taken) = &taken {
        let t_n = rows.len() / nc.max(1);
        let lo = SCAN_EDGE_DAYS.min(t_n / 2);
        let hi = t_n.saturating_sub(SCAN_EDGE_DAYS).max(lo + 1);
        let epochs: Vec<usize> = (0..ns).map(|_| rng.random_range(lo..hi)).collect();
        put_back(&mut rows, ns, taken, fit.onset, &epochs);
    }
    let drawn = res.with_fit(res.project_rows(&flip_reverse(&rows, nc, ns, rng)));
    let Some(held) = res.held.as_deref() else {
        return drawn;
    };
    let (rest, _) = less_change(held, &held.fit.r, fit.pos, fit.onset);
    res.beside_moves(drawn, &rest)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A change of 10 along `q = (0.8, 0.6)` at row 400, taken off two stations (one channel
    /// each): each part comes back at its station's own epoch, the first clipped to its reach.
    #[test]
    fn each_stations_part_comes_back_at_its_epoch_no_larger_than_its_reach() {
        let change = Change {
            before: 0.0,
            after: 10.0,
            begun: 400,
            done: 400,
        };
        let taken = TakenOff {
            q: vec![0.8, 0.6],
            change,
            reach: vec![2.0, 100.0],
        };
        let mut rows = vec![0.0; 2 * 1000];
        put_back(&mut rows, 2, &taken, 400, &[200, 700]);
        let at = |t: usize, c: usize| rows[t * 2 + c];
        assert_eq!((at(199, 0), at(200, 0), at(999, 0)), (0.0, 2.0, 2.0));
        assert_eq!(at(699, 1), 0.0);
        assert!((at(700, 1) - 6.0).abs() < 1e-12 && (at(999, 1) - 6.0).abs() < 1e-12);
    }

    /// A channel's reach leaves out the epochs whose windows hold the change: the change's own
    /// channel reaches nothing, another channel's step earlier in the record counts.
    #[test]
    fn reach_leaves_out_the_windows_around_the_change() {
        let t_n = 1200;
        let mut rows = vec![0.0; 2 * t_n];
        for t in 0..t_n {
            rows[t * 2] = if t >= 600 { 5.0 } else { 0.0 };
            rows[t * 2 + 1] = if t >= 100 { 1.0 } else { 0.0 };
        }
        let change = Change {
            before: 0.0,
            after: 5.0,
            begun: 600,
            done: 600,
        };
        let r = reach(&rows, 2, &change);
        assert_eq!(r[0], 0.0, "{r:?}");
        assert!(r[1] > 0.5 && r[1] <= 1.0, "{r:?}");
    }
}
