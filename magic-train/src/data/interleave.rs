//! Training and validation rows dealt out again in interleaved blocks of consecutive rows.
//!
//! The loop's keep rule retrains B and asks whether its validation MSE fell. An effect that only
//! starts after the training years (a step in the validation years) is zero on every training row:
//! the encoder never learns that F carries it, so the comparison cannot judge it. Dealing the
//! training and validation rows out again in blocks puts rows after its onset on both sides.

use super::{Dataset, Split};

impl Split {
    /// Appends `other`'s rows (dates, labels and ids kept only where both splits have them).
    fn append(&mut self, other: &Split) {
        let both = |a: &mut Vec<String>, b: &[String], n: usize| {
            if a.len() == n && b.len() == other.len() {
                a.extend_from_slice(b);
            } else {
                a.clear();
            }
        };
        let n = self.len();
        both(&mut self.dates, &other.dates, n);
        both(&mut self.labels, &other.labels, n);
        if self.ids.len() == n && other.ids.len() == other.len() {
            self.ids.extend_from_slice(&other.ids);
        } else {
            self.ids.clear();
        }
        self.x.extend(other.x.iter().cloned());
    }

    /// The rows dated on or after `day` (days since 1970-01-01), in order; none without dates.
    pub fn since(&self, day: f64) -> Split {
        let mut out = Split::default();
        let days = self.days();
        for (i, _) in days.iter().enumerate().filter(|(_, d)| **d >= day) {
            out.append(&self.rows(i, i + 1));
        }
        out
    }
}

/// The training rows followed by the validation rows, cut into blocks of `block` rows, with the
/// validation share of the blocks (as in `data`, at least one block) spread evenly among them;
/// the test split and the standardisation are kept. `None` when there are fewer than two blocks.
///
/// ```
/// use magic_train::data::{interleaved, Dataset, Split};
/// let split = |n: usize, from: f32| Split {
///     x: (0..n).map(|i| vec![from + i as f32]).collect(),
///     ..Split::default()
/// };
/// let data = Dataset {
///     columns: vec!["u".into()],
///     mean: vec![0.0],
///     scale: vec![1.0],
///     train: split(8, 0.0),
///     valid: split(2, 8.0),
///     test: Split::default(),
///     source: "ten rows".into(),
/// };
/// let d = interleaved(&data, 2).unwrap();
/// // five blocks of two rows, one in five for validation: the last of them
/// assert_eq!(d.valid.x, vec![vec![8.0], vec![9.0]]);
/// let d = interleaved(&data, 1).unwrap();
/// // ten blocks of one row: every fifth
/// assert_eq!(d.valid.x, vec![vec![4.0], vec![9.0]]);
/// assert_eq!(d.train.len(), 8);
/// ```
pub fn interleaved(data: &Dataset, block: usize) -> Option<Dataset> {
    let mut all = data.train.clone();
    all.append(&data.valid);
    let block = block.max(1);
    let blocks = all.len().div_ceil(block);
    let total = data.train.len() + data.valid.len();
    if blocks < 2 || total == 0 {
        return None;
    }
    let share = data.valid.len() as f64 / total as f64;
    let to_valid = ((blocks as f64 * share).round() as usize).clamp(1, blocks - 1);
    let (mut train, mut valid) = (Split::default(), Split::default());
    for k in 0..blocks {
        let rows = all.rows(k * block, (k + 1) * block);
        if (k + 1) * to_valid / blocks > k * to_valid / blocks {
            valid.append(&rows);
        } else {
            train.append(&rows);
        }
    }
    Some(Dataset {
        train,
        valid,
        source: format!(
            "{} (training and validation rows in blocks of {block})",
            data.source
        ),
        ..data.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` daily rows from day number `from`.
    fn days(n: usize, from: i64) -> Split {
        let date = |d: i64| {
            let (y, m, dd) = magic_core::time::civil_from_days(d);
            format!("{y:04}.{m:02}.{dd:02}")
        };
        Split {
            x: (0..n).map(|i| vec![i as f32]).collect(),
            dates: (0..n as i64).map(|i| date(from + i)).collect(),
            labels: vec![],
            ids: vec![],
        }
    }

    fn data(nt: usize, nv: usize) -> Dataset {
        Dataset {
            columns: vec!["u".into()],
            mean: vec![0.0],
            scale: vec![1.0],
            test: days(3, 13_000),
            train: days(nt, 14_000),
            valid: days(nv, 14_000 + nt as i64),
            source: "test".into(),
        }
    }

    #[test]
    fn every_row_lands_once_and_the_share_is_kept() {
        let d = data(1900, 500);
        let i = interleaved(&d, 60).unwrap();
        assert_eq!(i.train.len() + i.valid.len(), 2400);
        assert_eq!(i.valid.len(), 480, "8 of 40 blocks");
        assert_eq!(i.train.dates.len(), i.train.len(), "dates stay aligned");
        assert_eq!(i.test.len(), 3);
        let first_valid = &i.valid.dates[0];
        assert_eq!(first_valid, &d.train.dates[240], "the fifth block");
    }

    #[test]
    fn rows_after_the_training_years_reach_training() {
        let d = data(1900, 500);
        let i = interleaved(&d, 60).unwrap();
        let last_train = d.train.days().into_iter().fold(f64::MIN, f64::max);
        assert!(i.train.days().iter().any(|&t| t > last_train));
        assert!(i.valid.days().iter().any(|&t| t <= last_train));
    }

    #[test]
    fn rows_since_a_day_keep_their_dates() {
        let d = data(20, 10);
        let onset = d.valid.days()[4];
        let s = d.valid.since(onset);
        assert_eq!(s.len(), 6);
        assert_eq!(s.dates, d.valid.dates[4..]);
        assert!(d.valid.since(f64::INFINITY).is_empty());
        let mut undated = d.valid.clone();
        undated.dates.clear();
        assert!(undated.since(0.0).is_empty(), "no dates, no rows");
    }

    #[test]
    fn too_few_rows_for_two_blocks() {
        assert!(interleaved(&data(30, 20), 60).is_none());
        let i = interleaved(&data(30, 20), 10).unwrap();
        assert_eq!(i.valid.len(), 20, "two of five blocks");
    }

    #[test]
    fn missing_dates_are_dropped_not_misaligned() {
        let mut d = data(20, 10);
        d.valid.dates.clear();
        let i = interleaved(&d, 5).unwrap();
        assert!(i.train.dates.is_empty() && i.valid.dates.is_empty());
        assert_eq!(i.train.len() + i.valid.len(), 30);
    }
}
