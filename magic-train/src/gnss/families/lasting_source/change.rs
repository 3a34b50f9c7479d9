//! The change a lasting source makes, as its daily amplitude shows it: the means before and
//! after its onset and a straight ramp between where it begins and where it ends. The family
//! reports the start and end, and its bootstrap keeps the change as modelled.

/// A change that stays, as a daily amplitude shows it: its mean before the onset and after,
/// and the rows where it begins and ends (the day after the last one before the onset on which
/// the 30-day running mean had gone at most 10 % of the way from the mean before to the mean
/// after; the first on which it has gone 90 %).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Change {
    pub(super) before: f64,
    pub(super) after: f64,
    pub(super) begun: usize,
    pub(super) done: usize,
}

impl Change {
    /// The change in the daily amplitude `a` at row `onset`.
    pub(super) fn of(a: &[f64], onset: usize) -> Change {
        let (n, e) = (a.len(), onset.min(a.len()));
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len().max(1) as f64;
        let (before, after) = (mean(&a[..e]), mean(&a[e..]));
        let smooth = |t: usize| mean(&a[t.saturating_sub(15)..(t + 16).min(n)]);
        let gone = |t: usize| (smooth(t) - before) / (after - before);
        let begun = (0..e).rev().find(|&t| gone(t) <= 0.1).map_or(e, |t| t + 1);
        let done = (e..n).find(|&t| gone(t) >= 0.9).unwrap_or(e);
        Change {
            before,
            after,
            begun,
            done,
        }
    }

    /// The modelled amplitude at row `t`: the mean before, a straight ramp from where the change
    /// begins to where it ends, the mean after.
    pub(super) fn at(&self, t: usize) -> f64 {
        if t < self.begun {
            self.before
        } else if t >= self.done {
            self.after
        } else {
            let f = (t - self.begun) as f64 / (self.done - self.begun) as f64;
            self.before + f * (self.after - self.before)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_change_is_modelled_as_its_means_and_a_ramp_between() {
        // 600 days: 1 until day 200, a straight ramp to −3 by day 300, −3 after; onset at 250.
        let a: Vec<f64> = (0..600)
            .map(|t| match t {
                0..200 => 1.0,
                200..300 => 1.0 - 4.0 * (t - 200) as f64 / 100.0,
                _ => -3.0,
            })
            .collect();
        let c = Change::of(&a, 250);
        // Means about the onset: 250 days before (200 at 1, 50 on the ramp's first half), 350
        // after.
        let before = (200.0 + (0..50).map(|u| 1.0 - 0.04 * u as f64).sum::<f64>()) / 250.0;
        let after = ((50..100).map(|u| 1.0 - 0.04 * u as f64).sum::<f64>() - 900.0) / 350.0;
        assert!((c.before - before).abs() < 1e-12 && (c.after - after).abs() < 1e-12);
        // Begun and done where the 30-day mean crosses 10 % and 90 % of the way.
        assert!(
            c.begun > 150 && c.begun < 250 && c.done > 250 && c.done < 320,
            "{c:?}"
        );
        assert_eq!((c.at(0), c.at(c.begun - 1)), (c.before, c.before));
        assert_eq!((c.at(c.done), c.at(599)), (c.after, c.after));
        let mid = c.at((c.begun + c.done) / 2);
        assert!(mid < c.before && mid > c.after);
        // No change at all: a step of nothing at the onset.
        let flat = Change::of(&[2.0; 100], 40);
        assert_eq!(
            (flat.begun, flat.done, flat.at(0), flat.at(99)),
            (40, 40, 2.0, 2.0)
        );
    }
}
