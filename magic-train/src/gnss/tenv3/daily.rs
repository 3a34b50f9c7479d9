//! Station series combined into daily rows: one row per calendar day from the first to the last
//! date of any station, displacements (mm) from each station's reference epoch, NaN where a
//! station has no good line.

use super::dates::format_date;
use super::line::Epoch;
use super::station::StationSeries;
use super::{Tenv3Error, COMPONENTS, MAX_DISPLACEMENT_M};
use anyhow::{Context, Result};
use std::path::Path;

/// Which epoch displacements are measured from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Reference {
    /// The first day on which every station with data has a good line; if there is none, each
    /// station's own first epoch.
    #[default]
    Auto,
    /// A given day (days since 1970-01-01). A station without a line on that day is referenced to
    /// its nearest epoch (the earlier one on a tie), with a note.
    Day(i64),
}

/// Daily displacement rows for a list of stations.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Daily {
    /// Station names in column order.
    pub stations: Vec<String>,
    /// Day number of the first row (days since 1970-01-01); row `i` is day `first_day + i`.
    pub first_day: i64,
    /// One row per calendar day: east ×S, north ×S, up ×S in mm, NaN where missing.
    pub rows: Vec<Vec<f64>>,
    /// Reference day per station (`None` for a station without data).
    pub reference: Vec<Option<i64>>,
}

impl Daily {
    /// Number of days (rows).
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Date of row `i` as `YYYY.MM.DD`.
    pub fn date(&self, i: usize) -> String {
        format_date(self.first_day + i as i64, '.')
    }

    /// Row `i` as the f32 observation vector `magic_core::invert` takes (NaN = missing).
    pub fn obs(&self, i: usize) -> Vec<f32> {
        self.rows[i].iter().map(|v| *v as f32).collect()
    }

    /// Column names: `ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S, `date`.
    pub fn header(&self) -> Vec<String> {
        let mut h = crate::gnss::data::channel_names(&self.stations);
        h.push("date".to_string());
        h
    }

    /// The rows as CSV text (header first; missing channels written as `NaN`; 0.1 µm resolution).
    pub fn to_csv(&self) -> String {
        let mut s = self.header().join(",");
        s.push('\n');
        for (i, row) in self.rows.iter().enumerate() {
            for v in row {
                if v.is_nan() {
                    s.push_str("NaN,");
                } else {
                    s.push_str(&format!("{v:.4},"));
                }
            }
            s.push_str(&self.date(i));
            s.push('\n');
        }
        s
    }

    /// Writes [`Daily::to_csv`] to `path`.
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_csv())
            .with_context(|| format!("{}: cannot write", path.display()))
    }
}

/// Combines station series (in output column order; a station without data has no epochs) into
/// daily rows relative to `reference`. Returns the rows, the problems (epochs more than 10 m from
/// the reference epoch, skipped) and notes.
pub fn combine(
    series: &[StationSeries],
    reference: Reference,
) -> (Daily, Vec<Tenv3Error>, Vec<String>) {
    let mut errors = Vec::new();
    let mut notes = Vec::new();
    let s = series.len();
    let stations: Vec<String> = series.iter().map(|x| x.name.clone()).collect();
    let first = series
        .iter()
        .filter_map(|x| x.epochs.first())
        .map(|e| e.day)
        .min();
    let last = series
        .iter()
        .filter_map(|x| x.epochs.last())
        .map(|e| e.day)
        .max();
    let (Some(first), Some(last)) = (first, last) else {
        let daily = Daily {
            stations,
            first_day: 0,
            rows: Vec::new(),
            reference: vec![None; s],
        };
        return (daily, errors, notes);
    };
    let n_days = (last - first + 1) as usize;
    let refs = reference_epochs(series, reference, first, n_days, &mut notes);

    let mut rows = vec![vec![f64::NAN; 3 * s]; n_days];
    for (si, x) in series.iter().enumerate() {
        let Some(r) = refs[si].map(|i| &x.epochs[i]) else {
            continue;
        };
        for e in &x.epochs {
            match displacement(x, e, r) {
                Ok(d) => {
                    let row = &mut rows[(e.day - first) as usize];
                    for k in 0..3 {
                        row[k * s + si] = d[k] * 1000.0;
                    }
                }
                Err(err) => errors.push(err),
            }
        }
    }
    let reference = refs
        .iter()
        .zip(series)
        .map(|(r, x)| r.map(|i| x.epochs[i].day))
        .collect();
    (
        Daily {
            stations,
            first_day: first,
            rows,
            reference,
        },
        errors,
        notes,
    )
}

/// The displacement (m) of epoch `e` of station `x` from its reference epoch `r`, or the error
/// when a component exceeds [`MAX_DISPLACEMENT_M`].
fn displacement(
    x: &StationSeries,
    e: &Epoch,
    r: &Epoch,
) -> std::result::Result<[f64; 3], Tenv3Error> {
    let d: [f64; 3] = std::array::from_fn(|k| e.minus(r, k));
    match (0..3).find(|&k| d[k].abs() > MAX_DISPLACEMENT_M) {
        Some(k) => Err(Tenv3Error {
            path: x.path.clone(),
            line: e.line,
            column: e.frac_col[k],
            message: format!(
                "{} displacement {:.4} m from the reference epoch {} (line {}): expected at most {MAX_DISPLACEMENT_M} m",
                COMPONENTS[k],
                d[k],
                format_date(r.day, '-'),
                r.line
            ),
        }),
        None => Ok(d),
    }
}

/// The reference epoch of every station (an index into its epochs; `None` without data) for
/// days `first .. first + n_days`, with notes where the choice falls back.
fn reference_epochs(
    series: &[StationSeries],
    reference: Reference,
    first: i64,
    n_days: usize,
    notes: &mut Vec<String>,
) -> Vec<Option<usize>> {
    let find = |x: &StationSeries, day: i64| x.epochs.binary_search_by_key(&day, |e| e.day).ok();
    match reference {
        Reference::Auto => {
            let with_data: Vec<&StationSeries> =
                series.iter().filter(|x| !x.epochs.is_empty()).collect();
            let mut count = vec![0usize; n_days];
            for x in &with_data {
                for e in &x.epochs {
                    count[(e.day - first) as usize] += 1;
                }
            }
            match count.iter().position(|&c| c == with_data.len()) {
                Some(i) => series.iter().map(|x| find(x, first + i as i64)).collect(),
                None => {
                    notes.push(
                        "no day on which every station has data: each station is referenced to its own first epoch".into(),
                    );
                    series
                        .iter()
                        .map(|x| (!x.epochs.is_empty()).then_some(0))
                        .collect()
                }
            }
        }
        Reference::Day(day) => series
            .iter()
            .map(|x| {
                if x.epochs.is_empty() {
                    return None;
                }
                if let Some(i) = find(x, day) {
                    return Some(i);
                }
                let i = (0..x.epochs.len())
                    .min_by_key(|&i| ((x.epochs[i].day - day).abs(), x.epochs[i].day))
                    .unwrap_or(0);
                notes.push(format!(
                    "station {} has no data on {}: referenced to its nearest epoch {}",
                    x.name,
                    format_date(day, '-'),
                    format_date(x.epochs[i].day, '-')
                ));
                Some(i)
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::tenv3::parse_station;
    use crate::gnss::tenv3::test_lines::{line, D0, HEAD};

    #[test]
    fn integer_reset_keeps_the_position_continuous() {
        // The east fraction grows past 10 m, then NGL moves 10 m into the integer part.
        let mut text = format!("{HEAD}\n");
        text += &line("AKLV", D0, [-100, 0, 0], [9.99, 0.0, 0.0], [0.001; 3]);
        text += "\n";
        text += &line("AKLV", D0 + 1, [-100, 0, 0], [10.01, 0.0, 0.0], [0.001; 3]);
        text += "\n";
        text += &line("AKLV", D0 + 2, [-90, 0, 0], [0.03, 0.0, 0.0], [0.001; 3]);
        text += "\n";
        let (s, e) = parse_station("AKLV", "x", &text);
        assert!(e.is_empty(), "{e:?}");
        let (d, _, _) = combine(&[s], Reference::Auto);
        let east: Vec<f64> = d.rows.iter().map(|r| r[0]).collect();
        for (got, want) in east.iter().zip([0.0, 20.0, 40.0]) {
            assert!((got - want).abs() < 1e-6, "{east:?}");
        }
    }

    #[test]
    fn daily_rows_gaps_and_reference() {
        let mk = |name: &str, days: &[i64], up: f64| {
            let mut text = format!("{HEAD}\n");
            for &d in days {
                text += &line(
                    name,
                    D0 + d,
                    [0, 0, 100],
                    [0.0, 0.0, up * d as f64],
                    [0.001; 3],
                );
                text += "\n";
            }
            parse_station(name, name, &text).0
        };
        let a = mk("AAAA", &[0, 1, 2, 5], 0.001);
        let b = mk("BBBB", &[2, 3, 5, 6], 0.002);
        let none = StationSeries {
            name: "CCCC".into(),
            ..Default::default()
        };
        let (d, e, n) = combine(&[a.clone(), b.clone(), none.clone()], Reference::Auto);
        assert!(e.is_empty() && n.is_empty());
        assert_eq!(d.len(), 7, "2010-07-28 … 2010-08-03, gaps included");
        assert_eq!(d.date(0), "2010.07.28");
        assert_eq!(d.date(6), "2010.08.03");
        assert_eq!(d.reference, [Some(D0 + 2), Some(D0 + 2), None]);
        let up = |r: usize, s: usize| d.rows[r][6 + s];
        assert!((up(0, 0) + 2.0).abs() < 1e-9 && (up(5, 0) - 3.0).abs() < 1e-9);
        assert!((up(3, 1) - 2.0).abs() < 1e-9);
        assert!(up(3, 0).is_nan() && up(4, 0).is_nan() && up(4, 1).is_nan() && up(0, 2).is_nan());
        let csv = d.to_csv();
        let mut lines = csv.lines();
        assert_eq!(
            lines.next().unwrap(),
            "ux_AAAA,ux_BBBB,ux_CCCC,uy_AAAA,uy_BBBB,uy_CCCC,uz_AAAA,uz_BBBB,uz_CCCC,date"
        );
        assert_eq!(
            lines.nth(4).unwrap(),
            "NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,2010.08.01"
        );

        // A given reference day; a station without data that day takes its nearest epoch.
        let (d, _, n) = combine(&[a.clone(), b.clone()], Reference::Day(D0 + 1));
        assert_eq!(d.reference, [Some(D0 + 1), Some(D0 + 2)]);
        assert_eq!(n.len(), 1);
        assert!(
            n[0].contains("BBBB") && n[0].contains("2010-07-30"),
            "{n:?}"
        );

        // No common day: per-station first epoch.
        let c = mk("CCCC", &[7], 0.0);
        let (d, _, n) = combine(&[a, c], Reference::Auto);
        assert_eq!(d.reference, [Some(D0), Some(D0 + 7)]);
        assert_eq!(d.len(), 8);
        assert_eq!(n.len(), 1);
    }

    #[test]
    fn displacement_beyond_ten_metres_from_the_reference_is_an_error() {
        // Within 10 m of the median but 12 m from the reference epoch.
        let mut text = format!("{HEAD}\n");
        for (d, e) in [(0, -6.0), (1, 0.0), (2, 0.0), (3, 6.0)] {
            text += &line("AV15", D0 + d, [0, 0, 0], [e, 0.0, 0.0], [0.001; 3]);
            text += "\n";
        }
        let (s, e) = parse_station("AV15", "x", &text);
        assert!(e.is_empty());
        let (d, e, _) = combine(&[s], Reference::Auto);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].line, 5);
        assert!(e[0].message.contains("12.0000 m"), "{}", e[0]);
        assert!(d.rows[3][0].is_nan());
        assert_eq!(d.len(), 4);
    }
}
