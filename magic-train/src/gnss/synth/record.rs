//! The record a synthetic dataset covers — its first day and its three periods — and the dataset
//! cut from it: test, training and validation splits in time order (as in the release, the test
//! period comes first and holds the large early event), standardised with the training split's
//! mean and standard deviation.

use crate::data::{Dataset, Split, SplitName};
use crate::gnss::Network;

/// A record: first day and the lengths of its test, training and validation periods, in that
/// order in time, one row per day.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Day number of the first row (days since 1970-01-01).
    pub day0: i64,
    /// Days in the test, training and validation periods.
    pub periods: [usize; 3],
}

impl Layout {
    /// The `paper` generator's record: 2006-01-01, 900 test, 1900 training and 500 validation
    /// days (to 2015-01-14).
    pub const PAPER: Layout = Layout {
        day0: 13_149,
        periods: [900, 1900, 500],
    };
    /// The release's calendar (2006-01-01 … 2024-03-29), one row per day: test to 2009-07-29
    /// (1306 days), training to 2021-09-22 (4438), validation to 2024-03-29 (919). (The
    /// release itself has gaps and repeated dates: 1305, 4437 and 783 rows.)
    pub const RELEASE: Layout = Layout {
        day0: 13_149,
        periods: [1306, 4438, 919],
    };

    /// Days in the record.
    pub fn n_days(&self) -> usize {
        self.periods.iter().sum()
    }

    /// Row indices `[start, end)` of a split's period.
    pub fn range(&self, split: SplitName) -> (usize, usize) {
        let [n_test, n_train, _] = self.periods;
        match split {
            SplitName::Test => (0, n_test),
            SplitName::Train => (n_test, n_test + n_train),
            SplitName::Valid => (n_test + n_train, self.n_days()),
        }
    }

    /// Day number of row `t`.
    pub fn day(&self, t: usize) -> i64 {
        self.day0 + t as i64
    }

    /// Row of a day number (`None` outside the record).
    pub fn row(&self, day: i64) -> Option<usize> {
        let t = usize::try_from(day - self.day0).ok()?;
        (t < self.n_days()).then_some(t)
    }
}

/// `YYYY-MM-DD` of a day number.
pub fn iso_date(days: i64) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(days);
    format!("{y:04}-{m:02}-{d:02}")
}

/// The dataset of the rows `mm` (one per day of `layout`, channels in `network`'s order), cut
/// into its three splits and standardised with the training split's mean and standard
/// deviation.
pub fn dataset(layout: &Layout, network: &Network, mm: &[Vec<f64>], source: String) -> Dataset {
    let (a, b) = layout.range(SplitName::Train);
    let train_rows = &mm[a..b];
    let n = 3 * network.len();
    let mean: Vec<f64> = (0..n)
        .map(|c| train_rows.iter().map(|r| r[c]).sum::<f64>() / train_rows.len() as f64)
        .collect();
    let scale: Vec<f64> = (0..n)
        .map(|c| {
            (train_rows
                .iter()
                .map(|r| (r[c] - mean[c]).powi(2))
                .sum::<f64>()
                / train_rows.len() as f64)
                .sqrt()
        })
        .collect();
    let split = |name: SplitName| {
        let (a, b) = layout.range(name);
        Split {
            x: mm[a..b]
                .iter()
                .map(|r| {
                    r.iter()
                        .enumerate()
                        .map(|(c, v)| ((v - mean[c]) / scale[c]) as f32)
                        .collect()
                })
                .collect(),
            dates: (a..b)
                .map(|t| {
                    let (y, m, d) = magic_core::time::civil_from_days(layout.day(t));
                    format!("{y:04}.{m:02}.{d:02}")
                })
                .collect(),
            ..Split::default()
        }
    };
    let (train, valid, test) = (
        split(SplitName::Train),
        split(SplitName::Valid),
        split(SplitName::Test),
    );
    Dataset {
        columns: network.channel_names(),
        mean,
        scale,
        train,
        valid,
        test,
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_release_layout_matches_the_release_dates() {
        let l = Layout::RELEASE;
        assert_eq!(iso_date(l.day(0)), "2006-01-01");
        assert_eq!(iso_date(l.day(l.range(SplitName::Train).0)), "2009-07-30");
        assert_eq!(iso_date(l.day(l.range(SplitName::Valid).0)), "2021-09-23");
        assert_eq!(iso_date(l.day(l.n_days() - 1)), "2024-03-29");
        assert_eq!(l.row(l.day(17)), Some(17));
        assert_eq!(l.row(l.day0 - 1), None);
        assert_eq!(l.row(l.day(l.n_days())), None);
    }
}
