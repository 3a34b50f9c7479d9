//! Splitting days into training, validation and test periods by date, as in the paper's
//! release: by default the first [`DEFAULT_TEST_SHARE`] of the days are the test period (the
//! release's test period is its earliest, holding the 2008 inflation), the last
//! [`DEFAULT_VALID_SHARE`] the validation period, and the days between the training period.

use crate::data::SplitName;
use crate::gnss::tenv3::{format_date, parse_ymd};
use anyhow::{bail, Context, Result};
use std::str::FromStr;

/// Share of the days in the default test period (the first ones).
pub const DEFAULT_TEST_SHARE: f64 = 0.20;

/// Share of the days in the default validation period (the last ones).
pub const DEFAULT_VALID_SHARE: f64 = 0.15;

/// Days `from..to`, both included (day numbers).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct DateRange {
    /// First day.
    pub from: i64,
    /// Last day (included).
    pub to: i64,
}

impl DateRange {
    /// Whether `day` is in the range.
    pub fn contains(&self, day: i64) -> bool {
        self.from <= day && day <= self.to
    }

    /// `YYYY-MM-DD..YYYY-MM-DD`.
    pub fn text(&self) -> String {
        format!(
            "{}..{}",
            format_date(self.from, '-'),
            format_date(self.to, '-')
        )
    }
}

impl FromStr for DateRange {
    type Err = anyhow::Error;
    /// `FROM..TO` with `YYYY-MM-DD` (or `YYYY.MM.DD`) dates, both included.
    fn from_str(s: &str) -> Result<DateRange> {
        let (a, b) = s
            .split_once("..")
            .with_context(|| format!("`{s}`: expected FROM..TO (e.g. 2008-01-01..2009-06-30)"))?;
        let day = |d: &str| {
            parse_ymd(d.trim()).with_context(|| format!("`{d}` in `{s}`: expected YYYY-MM-DD"))
        };
        let r = DateRange {
            from: day(a)?,
            to: day(b)?,
        };
        if r.from > r.to {
            bail!("`{s}`: the range ends before it starts");
        }
        Ok(r)
    }
}

/// The split of every day in `days` (increasing day numbers), with the test and validation
/// periods as given or by default, and the periods used.
///
/// ```
/// use magic_train::gnss::prepare::splits::assign;
/// use magic_train::data::SplitName;
/// let days: Vec<i64> = (0..100).collect();
/// let (s, test, valid) = assign(&days, None, None).unwrap();
/// assert_eq!(s.iter().filter(|x| **x == SplitName::Test).count(), 20);
/// assert_eq!(s.iter().filter(|x| **x == SplitName::Valid).count(), 15);
/// assert_eq!((test.to, valid.from), (19, 85));
/// ```
pub fn assign(
    days: &[i64],
    test: Option<DateRange>,
    valid: Option<DateRange>,
) -> Result<(Vec<SplitName>, DateRange, DateRange)> {
    let n = days.len();
    if n < 3 {
        bail!("{n} days are too few to split into training, validation and test periods");
    }
    let n_test = ((n as f64 * DEFAULT_TEST_SHARE).round() as usize).max(1);
    let n_valid = ((n as f64 * DEFAULT_VALID_SHARE).round() as usize).max(1);
    let test = test.unwrap_or(DateRange {
        from: days[0],
        to: days[n_test - 1],
    });
    let valid = valid.unwrap_or(DateRange {
        from: days[n - n_valid],
        to: days[n - 1],
    });
    if test.from <= valid.to && valid.from <= test.to {
        bail!(
            "the test period {} and the validation period {} overlap",
            test.text(),
            valid.text()
        );
    }
    let split: Vec<SplitName> = days
        .iter()
        .map(|&d| {
            if test.contains(d) {
                SplitName::Test
            } else if valid.contains(d) {
                SplitName::Valid
            } else {
                SplitName::Train
            }
        })
        .collect();
    for name in SplitName::ALL {
        if !split.contains(&name) {
            bail!(
                "no day falls in the {name} period (test {}, validation {}, data {}..{})",
                test.text(),
                valid.text(),
                format_date(days[0], '-'),
                format_date(days[n - 1], '-')
            );
        }
    }
    Ok((split, test, valid))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_and_periods_are_checked() {
        let r: DateRange = "2008-01-01..2008.12.31".parse().unwrap();
        assert_eq!(r.text(), "2008-01-01..2008-12-31");
        assert!("2008-01-01".parse::<DateRange>().is_err());
        assert!("2009-01-01..2008-01-01".parse::<DateRange>().is_err());
        assert!("2008-13-01..2009-01-01".parse::<DateRange>().is_err());
        let days: Vec<i64> = (r.from..r.from + 400).collect();
        let test: DateRange = "2008-03-01..2008-03-31".parse().unwrap();
        let (s, _, v) = assign(&days, Some(test), None).unwrap();
        assert_eq!(s.iter().filter(|x| **x == SplitName::Test).count(), 31);
        assert_eq!(v.to, days[399]);
        let overlapping: DateRange = "2008-12-01..2009-01-31".parse().unwrap();
        assert!(assign(&days, Some(overlapping), None).is_err());
        let outside: DateRange = "2001-01-01..2001-12-31".parse().unwrap();
        assert!(assign(&days, Some(outside), None).is_err());
    }
}
