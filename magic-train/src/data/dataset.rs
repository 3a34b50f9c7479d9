//! The one dataset type every problem trains on: three splits of standardised observations with
//! their dates (and, where the data has them, a label and a site id per row), the channel names
//! and the standardisation.

use anyhow::{bail, Result};

/// Which split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SplitName {
    /// The training split.
    Train,
    /// The validation split (early stopping, thresholds).
    Valid,
    /// The test split.
    Test,
}

impl SplitName {
    /// The three splits in the order of the paper's tables.
    pub const ALL: [SplitName; 3] = [SplitName::Train, SplitName::Valid, SplitName::Test];

    /// `train`, `valid` or `test`.
    pub fn as_str(self) -> &'static str {
        match self {
            SplitName::Train => "train",
            SplitName::Valid => "valid",
            SplitName::Test => "test",
        }
    }

    /// Index in [`SplitName::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

impl std::str::FromStr for SplitName {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<SplitName> {
        match s {
            "train" => Ok(SplitName::Train),
            "valid" => Ok(SplitName::Valid),
            "test" => Ok(SplitName::Test),
            _ => bail!("unknown split `{s}` (expected train, valid or test)"),
        }
    }
}

impl std::fmt::Display for SplitName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Day number (days since 1970-01-01) of a date as written in the data files (`YYYY.MM.DD` or
/// `YYYY-MM-DD`); NaN if malformed.
pub fn day_number(date: &str) -> f64 {
    magic_core::time::parse_date(date).map_or(f64::NAN, |d| d as f64)
}

/// One split: standardised observations, their dates, and optional per-row labels and ids.
#[derive(Clone, Debug, Default)]
pub struct Split {
    /// Rows of standardised values, one per channel.
    pub x: Vec<Vec<f32>>,
    /// Dates as written in the file (empty where the file has none).
    pub dates: Vec<String>,
    /// A label per row (the species of a forest spectrum), or empty.
    pub labels: Vec<String>,
    /// An id per row (the site of a forest spectrum), or empty.
    pub ids: Vec<u64>,
}

impl Split {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Day numbers of the rows (NaN where the date is missing or malformed).
    pub fn days(&self) -> Vec<f64> {
        self.dates.iter().map(|d| day_number(d)).collect()
    }

    /// Rows `lo..hi` (clamped to the split).
    pub fn rows(&self, lo: usize, hi: usize) -> Split {
        let hi = hi.min(self.len());
        let lo = lo.min(hi);
        Split {
            x: self.x[lo..hi].to_vec(),
            dates: part(&self.dates, lo, hi),
            labels: part(&self.labels, lo, hi),
            ids: part(&self.ids, lo, hi),
        }
    }

    /// Appends `other`'s rows (dates, labels and ids kept only where both splits have them).
    pub(crate) fn append(&mut self, other: &Split) {
        let (n, m) = (self.len(), other.len());
        extend_aligned(&mut self.dates, n, &other.dates, m);
        extend_aligned(&mut self.labels, n, &other.labels, m);
        extend_aligned(&mut self.ids, n, &other.ids, m);
        self.x.extend(other.x.iter().cloned());
    }

    /// The rows dated on or after `day` (days since 1970-01-01), in order; none without dates.
    pub fn since(&self, day: f64) -> Split {
        self.within(day, f64::INFINITY)
    }

    /// The rows dated from `first` to `last` (days since 1970-01-01, both included), in order;
    /// none without dates.
    pub fn within(&self, first: f64, last: f64) -> Split {
        let days = self.days();
        let keep: Vec<usize> = (0..self.len())
            .filter(|&i| days.get(i).is_some_and(|&d| d >= first && d <= last))
            .collect();
        self.pick(&keep)
    }

    /// The rows at `keep` (indices into the split, in the order given).
    fn pick(&self, keep: &[usize]) -> Split {
        Split {
            x: keep.iter().map(|&i| self.x[i].clone()).collect(),
            dates: pick_column(&self.dates, self.len(), keep),
            labels: pick_column(&self.labels, self.len(), keep),
            ids: pick_column(&self.ids, self.len(), keep),
        }
    }

    /// The first `n` rows (all if fewer).
    pub fn head(&self, n: usize) -> Split {
        self.rows(0, n)
    }
}

/// A per-row column's rows `lo..hi`, or none when the split does not carry it.
fn part<T: Clone>(v: &[T], lo: usize, hi: usize) -> Vec<T> {
    v.get(lo..hi).map_or_else(Vec::new, <[T]>::to_vec)
}

/// A per-row column's rows at `keep`, or none when the column is not whole (`n` rows).
fn pick_column<T: Clone>(v: &[T], n: usize, keep: &[usize]) -> Vec<T> {
    if v.len() == n {
        keep.iter().map(|&i| v[i].clone()).collect()
    } else {
        Vec::new()
    }
}

/// Extends per-row column `a` (of a split with `n` rows) by `b` (of one with `m`) when both are
/// complete; otherwise clears it, so a column is kept whole or not at all.
fn extend_aligned<T: Clone>(a: &mut Vec<T>, n: usize, b: &[T], m: usize) {
    if a.len() == n && b.len() == m {
        a.extend_from_slice(b);
    } else {
        a.clear();
    }
}

/// A dataset: channel names, standardisation and the three splits.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Channel (or band) column names, in channel order.
    pub columns: Vec<String>,
    /// Channel mean (physical units: mm, reflectance).
    pub mean: Vec<f64>,
    /// Channel scale (physical units).
    pub scale: Vec<f64>,
    /// Training split.
    pub train: Split,
    /// Validation split.
    pub valid: Split,
    /// Test split.
    pub test: Split,
    /// Where it came from (a folder, or a description of a synthetic set).
    pub source: String,
}

impl Dataset {
    /// Number of channels.
    pub fn n_obs(&self) -> usize {
        self.mean.len()
    }

    /// A split by name.
    pub fn split(&self, name: SplitName) -> &Split {
        match name {
            SplitName::Train => &self.train,
            SplitName::Valid => &self.valid,
            SplitName::Test => &self.test,
        }
    }

    /// Physical value of standardised channel `c`.
    pub fn to_physical(&self, c: usize, v: f64) -> f64 {
        v * self.scale[c] + self.mean[c]
    }

    /// A standardised row in physical units (f32, as `magic invert` reads them).
    pub fn physical_row(&self, row: &[f32]) -> Vec<f32> {
        row.iter()
            .enumerate()
            .map(|(c, v)| self.to_physical(c, *v as f64) as f32)
            .collect()
    }

    /// Checks the standardisation: one mean and one positive scale per channel.
    pub fn check(&self) -> Result<()> {
        let n = self.columns.len();
        if self.mean.len() != n || self.scale.len() != n {
            bail!(
                "{}: mean/scale must hold {n} values, one per channel (found {} and {})",
                self.source,
                self.mean.len(),
                self.scale.len()
            );
        }
        if let Some(i) = self.scale.iter().position(|s| !s.is_finite() || *s <= 0.0) {
            bail!(
                "{}: the scale of channel {} (`{}`) must be positive",
                self.source,
                i + 1,
                self.columns[i]
            );
        }
        for name in SplitName::ALL {
            if let Some((i, r)) = self
                .split(name)
                .x
                .iter()
                .enumerate()
                .find(|(_, r)| r.len() != n)
            {
                bail!(
                    "{}: {name} row {} has {} values for {n} channels",
                    self.source,
                    i + 1,
                    r.len()
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_names_round_trip() {
        for s in SplitName::ALL {
            assert_eq!(s.as_str().parse::<SplitName>().unwrap(), s);
            assert_eq!(SplitName::ALL[s.index()], s);
        }
        assert!("tests".parse::<SplitName>().is_err());
    }

    #[test]
    fn rows_keep_labels_and_ids_aligned() {
        let s = Split {
            x: vec![vec![1.0], vec![2.0], vec![3.0]],
            dates: vec![
                "2018.04.01".into(),
                "2018.04.02".into(),
                "2018.04.03".into(),
            ],
            labels: vec!["a".into(), "b".into(), "c".into()],
            ids: vec![7, 8, 9],
        };
        let p = s.rows(1, 10);
        assert_eq!(p.x, vec![vec![2.0], vec![3.0]]);
        assert_eq!(p.labels, vec!["b", "c"]);
        assert_eq!(p.ids, vec![8, 9]);
        assert_eq!(p.days()[0], day_number("2018-04-02"));
        assert!(s.head(0).is_empty());
    }

    #[test]
    fn rows_since_a_day_keep_labels_and_ids_and_skip_bad_dates() {
        let s = Split {
            x: vec![vec![1.0], vec![2.0], vec![3.0], vec![4.0]],
            dates: vec![
                "2018.04.03".into(),
                "2018.04.01".into(),
                "not a date".into(),
                "2018.04.02".into(),
            ],
            labels: vec!["a".into(), "b".into(), "c".into(), "d".into()],
            ids: vec![7, 8, 9, 10],
        };
        let p = s.since(day_number("2018-04-02"));
        assert_eq!(p.x, vec![vec![1.0], vec![4.0]], "in the split's order");
        assert_eq!(p.labels, vec!["a", "d"]);
        assert_eq!(p.ids, vec![7, 10]);
        let unlabelled = Split {
            labels: vec!["a".into()],
            ..s.clone()
        };
        assert!(
            unlabelled.since(0.0).labels.is_empty(),
            "a column kept whole or not at all"
        );
        assert_eq!(unlabelled.since(0.0).ids.len(), 3);
    }
}
