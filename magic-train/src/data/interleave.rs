//! Training and validation rows dealt out again in interleaved blocks of consecutive rows.
//!
//! The loop's keep rule retrains B and asks whether its validation MSE fell. An effect that only
//! starts after the training years (a step in the validation years) is zero on every training row:
//! the encoder never learns that F carries it, so the comparison cannot judge it. Dealing the
//! training and validation rows out again in blocks puts rows after its onset on both sides; two
//! folds hold out every row after it once, so the judgement rests on all of them. An effect that
//! acts within the training years only (a pulse that comes back) is the mirror case: the
//! validation years do not hold it, so folds over its window judge it instead; a pulse within
//! the test years, before them, the same way, with the test rows dealt out too.

use super::{Dataset, Split};

/// The training rows followed by the validation rows, cut into blocks of `block` rows and dealt
/// out twice, for judging an effect that begins on day `onset` (days since 1970-01-01): the
/// blocks from the one holding the onset on are held out in turn, the even ones in the first
/// dataset and the odd ones in the second, so that every row from the onset on is held out once
/// and each dataset trains on the other half; before the onset, the validation share of the
/// blocks (as in `data`) is held out, spread evenly. The test split and the standardisation are
/// kept. `None` without dates on every row or with fewer than two blocks from the onset on.
///
/// ```
/// use magic_train::data::{onset_folds, Dataset, Split};
/// let days = |from: i64, n: i64| Split {
///     x: (from..from + n).map(|d| vec![d as f32]).collect(),
///     dates: (from..from + n)
///         .map(|d| {
///             let (y, m, dd) = magic_core::time::civil_from_days(d);
///             format!("{y:04}-{m:02}-{dd:02}")
///         })
///         .collect(),
///     ..Split::default()
/// };
/// let data = Dataset {
///     columns: vec!["day".into()],
///     mean: vec![0.0],
///     scale: vec![1.0],
///     train: days(0, 8),
///     valid: days(8, 4),
///     test: Split::default(),
///     source: "twelve days".into(),
/// };
/// // blocks of two days; the onset (day 7) in the fourth block: three blocks from it on
/// let [a, b] = onset_folds(&data, 2, 7.0).unwrap();
/// let held = |d: &Dataset| d.valid.x.iter().map(|r| r[0] as i64).collect::<Vec<_>>();
/// // before it, one block in three (as in `data`): the third
/// assert_eq!(held(&a), vec![4, 5, 6, 7, 10, 11]);
/// assert_eq!(held(&b), vec![4, 5, 8, 9]);
/// assert_eq!(a.train.len() + a.valid.len(), 12);
/// ```
pub fn onset_folds(data: &Dataset, block: usize, onset: f64) -> Option<[Dataset; 2]> {
    window_folds(data, block, onset, f64::INFINITY)
}

/// The training rows followed by the validation rows, cut into blocks of `block` rows and dealt
/// out twice, for judging an effect that acts from day `first` to day `last` only (a source's
/// pulse within the training years, which the validation years do not hold): the blocks holding
/// a row of that window are held out in turn, the even ones in the first dataset and the odd
/// ones in the second, so that every row of the window is held out once; the other blocks hold
/// out the validation share (as in `data`), spread evenly. A window holding no training or
/// validation row (a pulse within the test years, which precede the training years in the
/// volcano's layouts) deals the test rows out with them, so that its own days judge it; the
/// dealt-out datasets keep the test split as it is all the same. [`onset_folds`] is the window
/// that never ends. `None` without dates on every row or with fewer than two blocks in the
/// window.
///
/// ```
/// use magic_train::data::{window_folds, Dataset, Split};
/// let days = |from: i64, n: i64| Split {
///     x: (from..from + n).map(|d| vec![d as f32]).collect(),
///     dates: (from..from + n)
///         .map(|d| {
///             let (y, m, dd) = magic_core::time::civil_from_days(d);
///             format!("{y:04}-{m:02}-{dd:02}")
///         })
///         .collect(),
///     ..Split::default()
/// };
/// let data = Dataset {
///     columns: vec!["day".into()],
///     mean: vec![0.0],
///     scale: vec![1.0],
///     train: days(0, 12),
///     valid: days(12, 4),
///     test: Split::default(),
///     source: "sixteen days".into(),
/// };
/// // blocks of two days; days 5 to 8 lie in the third to fifth blocks
/// let [a, b] = window_folds(&data, 2, 5.0, 8.0).unwrap();
/// let held = |d: &Dataset| d.valid.x.iter().map(|r| r[0] as i64).collect::<Vec<_>>();
/// // outside it, one block in four (as in `data`): the last of the five
/// assert_eq!(held(&a), vec![4, 5, 8, 9, 14, 15]);
/// assert_eq!(held(&b), vec![6, 7, 14, 15]);
/// assert_eq!(a.train.len() + a.valid.len(), 16);
/// ```
pub fn window_folds(data: &Dataset, block: usize, first: f64, last: f64) -> Option<[Dataset; 2]> {
    let all = dealt_rows(data, first, last)?;
    let block = block.max(1);
    let total = all.len();
    let days = all.days();
    let blocks = total.div_ceil(block);
    // The window's blocks: from the one holding its first row to the one holding its last.
    let from = days.iter().position(|&d| d >= first)? / block;
    let to = days.iter().rposition(|&d| d <= last)? / block;
    if to < from + 1 {
        return None;
    }
    let dealt = if total > data.train.len() + data.valid.len() {
        "test, training and validation"
    } else {
        "training and validation"
    };
    let inside = |k: usize| (from..=to).contains(&k);
    let outside = blocks - (to - from + 1);
    let share = data.valid.len() as f64 / total as f64;
    let held_out = ((outside as f64 * share).round() as usize).min(outside.saturating_sub(1));
    let fold = |f: usize| {
        let (mut train, mut valid) = (Split::default(), Split::default());
        let mut j = 0; // index among the blocks outside the window
        for k in 0..blocks {
            let held = if inside(k) {
                (k - from) % 2 == f
            } else {
                j += 1;
                j * held_out / outside > (j - 1) * held_out / outside
            };
            let rows = all.rows(k * block, (k + 1) * block);
            if held {
                valid.append(&rows);
            } else {
                train.append(&rows);
            }
        }
        Dataset {
            train,
            valid,
            source: format!(
                "{} ({dealt} rows in blocks of {block}, fold {} of 2 over the effect's days)",
                data.source,
                f + 1
            ),
            ..data.clone()
        }
    };
    Some([fold(0), fold(1)])
}

/// The rows [`window_folds`] deals out, in date order: the training rows followed by the
/// validation rows; when none of them lies in the window from `first` to `last` (an episode
/// within the test years), the test rows too, before or after them as their dates fall, so that
/// the effect's own days can be held out. `None` without dates on every row, or with test rows
/// that do not all precede or all follow the others.
fn dealt_rows(data: &Dataset, first: f64, last: f64) -> Option<Split> {
    let dated = |s: &Split| {
        let days = s.days();
        (days.len() == s.len() && days.iter().all(|d| d.is_finite())).then_some(days)
    };
    let mut all = data.train.clone();
    all.append(&data.valid);
    let days = dated(&all)?;
    if data.test.is_empty() || days.iter().any(|&d| d >= first && d <= last) {
        return Some(all);
    }
    let test = dated(&data.test)?;
    if !test.iter().any(|&d| d >= first && d <= last) {
        return Some(all);
    }
    let lo_hi = |d: &[f64]| {
        d.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            })
    };
    let ((t0, t1), (a0, a1)) = (lo_hi(&test), lo_hi(&days));
    if t1 < a0 {
        let mut rows = data.test.clone();
        rows.append(&all);
        Some(rows)
    } else if t0 > a1 {
        all.append(&data.test);
        Some(all)
    } else {
        None
    }
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
    fn every_row_from_the_onset_on_is_held_out_once() {
        let d = data(1900, 500);
        let onset = d.valid.days()[100];
        let folds = onset_folds(&d, 60, onset).unwrap();
        let mut held_after = 0;
        for f in &folds {
            assert_eq!(f.train.len() + f.valid.len(), 2400);
            assert_eq!(f.train.dates.len(), f.train.len(), "dates stay aligned");
            assert_eq!(f.test.len(), 3);
            assert!(
                f.train.days().iter().any(|&t| t >= onset),
                "rows after it train"
            );
            held_after += f.valid.since(onset).len();
        }
        assert_eq!(held_after, 400);
        // Before the onset's block (block 33 of 40) the validation share: 7 of 33 blocks.
        let before = folds[0].valid.len() - folds[0].valid.since(d.valid.days()[80]).len();
        assert_eq!(before, 7 * 60);
        assert_eq!(
            folds[0].valid.dates[0], d.train.dates[240],
            "the fifth block"
        );
    }

    #[test]
    fn every_row_of_a_window_is_held_out_once() {
        let d = data(1900, 500);
        let (first, last) = (d.train.days()[700], d.train.days()[1000]);
        let folds = window_folds(&d, 60, first, last).unwrap();
        let mut held_inside = 0;
        for f in &folds {
            assert_eq!(f.train.len() + f.valid.len(), 2400);
            assert_eq!(f.test.len(), 3);
            assert!(
                !f.train.within(first, last).is_empty(),
                "rows of the window train"
            );
            held_inside += f.valid.within(first, last).len();
        }
        assert_eq!(held_inside, 301);
        // Blocks 11 to 16 hold the window; of the other 34, the validation share: 7.
        let inside = 6 * 60;
        for f in &folds {
            let window_blocks = f.valid.within(d.train.days()[660], d.train.days()[1019]);
            assert_eq!(window_blocks.len(), inside / 2);
            assert_eq!(f.valid.len() - window_blocks.len(), 7 * 60);
        }
        // Without an end it is the onset's folds.
        let onset = d.valid.days()[100];
        let (a, b) = (
            window_folds(&d, 60, onset, f64::INFINITY).unwrap(),
            onset_folds(&d, 60, onset).unwrap(),
        );
        assert_eq!(a[0].valid.dates, b[0].valid.dates);
        assert_eq!(a[1].valid.dates, b[1].valid.dates);
        // A window within one block, or outside the rows, gives none.
        assert!(window_folds(&d, 60, first, first + 10.0).is_none());
        assert!(window_folds(&d, 60, 0.0, 100.0).is_none());
    }

    #[test]
    fn a_window_within_the_test_years_deals_their_rows_out_too() {
        // 600 test days before 1900 training and 500 validation days.
        let mut d = data(1900, 500);
        d.test = days(600, 14_000 - 600);
        let (first, last) = (d.test.days()[200], d.test.days()[450]);
        let folds = window_folds(&d, 60, first, last).unwrap();
        let mut held_inside = 0;
        for f in &folds {
            assert_eq!(f.train.len() + f.valid.len(), 3000);
            assert_eq!(f.test.len(), 600, "the test split kept as it is");
            assert!(!f.train.within(first, last).is_empty());
            held_inside += f.valid.within(first, last).len();
            assert!(f.source.contains("test, training and validation rows"));
        }
        assert_eq!(held_inside, 251);
        // In date order: the first block is the test years' first.
        assert_eq!(folds[0].train.dates[0], d.test.dates[0]);
        // Test rows after the others are dealt out after them.
        let mut later = data(1900, 500);
        later.test = days(600, 14_000 + 2400);
        let (first, last) = (later.test.days()[100], later.test.days()[300]);
        let [a, b] = window_folds(&later, 60, first, last).unwrap();
        assert_eq!(
            a.valid.within(first, last).len() + b.valid.within(first, last).len(),
            201
        );
        // A window reaching into the training years deals out those years only.
        let (first, last) = (d.test.days()[500], d.train.days()[300]);
        let [a, _] = window_folds(&d, 60, first, last).unwrap();
        assert_eq!(a.train.len() + a.valid.len(), 2400);
        // Test rows among the others cannot be dealt out in date order.
        let mut among = data(1900, 500);
        among.test = days(600, 14_000 + 1000);
        let (first, last) = (among.test.days()[100], among.test.days()[400]);
        assert!(
            window_folds(&among, 60, first, last).is_some(),
            "training rows there"
        );
        among.train = days(900, 14_000);
        among.valid = days(500, 14_000 + 1800);
        let (first, last) = (14_000.0 + 950.0, 14_000.0 + 1_500.0);
        assert!(window_folds(&among, 60, first, last).is_none());
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
    fn too_few_blocks_from_the_onset_on() {
        let d = data(30, 20);
        assert!(
            onset_folds(&d, 60, d.train.days()[0]).is_none(),
            "one block"
        );
        let last = d.valid.days()[19];
        assert!(
            onset_folds(&d, 10, last).is_none(),
            "the onset in the last block"
        );
        let [a, b] = onset_folds(&d, 10, last - 10.0).unwrap();
        assert_eq!(
            (a.valid.len(), b.valid.len()),
            (20, 20),
            "a block before it and one after"
        );
    }

    #[test]
    fn rows_without_a_date_give_no_folds() {
        let mut d = data(20, 10);
        d.valid.dates.clear();
        assert!(onset_folds(&d, 5, 0.0).is_none());
    }
}
