//! One station file: its layout (from the header, or the standard one), its data lines, the
//! longest run of strictly increasing dates, and positions within 10 m of the station's median —
//! the good epochs and every problem found, each naming its line and column.

use super::dates::format_date;
use super::layout::{fields, Layout, HEADER, OLD_FIELDS};
use super::line::{parse_line, Epoch};
use super::{Tenv3Error, COMPONENTS, MAX_DISPLACEMENT_M};
use std::collections::HashMap;

/// The good lines of one station file, in strictly increasing date order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StationSeries {
    /// Station name.
    pub name: String,
    /// File the series was read from (empty when the station has no file).
    pub path: String,
    /// Good epochs, strictly increasing in day.
    pub epochs: Vec<Epoch>,
}

impl StationSeries {
    /// The station's geodetic position: the median latitude (°), longitude (° east, wrapped into
    /// (−180°, 180°]) and ellipsoidal height (m) over its good epochs; `None` when its file has no
    /// such fields (the older 20-field layout) or no good epoch. Longitudes are unwrapped about
    /// the first epoch's before the median, so a station on the antimeridian stays there.
    pub fn geodetic(&self) -> Option<[f64; 3]> {
        let geo: Vec<[f64; 3]> = self.epochs.iter().filter_map(|e| e.geo).collect();
        let lon0 = crate::gnss::geodesy::wrap_longitude(geo.first()?[1]);
        let median = |mut v: Vec<f64>| crate::numerics::median(&mut v);
        let lat = median(geo.iter().map(|g| g[0]).collect());
        let lon = median(
            geo.iter()
                .map(|g| lon0 + crate::gnss::geodesy::wrap_longitude(g[1] - lon0))
                .collect(),
        );
        let h = median(geo.iter().map(|g| g[2]).collect());
        Some([lat, crate::gnss::geodesy::wrap_longitude(lon), h])
    }
}

/// Builds the errors of one file.
struct Errors<'a> {
    path: &'a str,
    list: Vec<Tenv3Error>,
}

impl Errors<'_> {
    fn push(&mut self, line: usize, column: usize, message: String) {
        self.list.push(Tenv3Error {
            path: self.path.to_string(),
            line,
            column,
            message,
        });
    }
}

/// Parses the text of one station file. `name` is the station (from the file name), `path` is
/// used in messages. Returns the good epochs (strictly increasing in date) and the problems.
///
/// ```
/// use magic_train::gnss::tenv3::parse_station;
/// let text = "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)\n\
/// AV08 10JUL28 2010.5708 55405 1594 3 -166 -7612 0.241339 6001536 0.822711 410 0.318840 0.0 0.000912 0.001002 0.004217 0.0123 -0.0204 0.0071 54.1271930 -165.9743172 410.3188\n";
/// let (s, errors) = parse_station("AV08", "AV08.tenv3", text);
/// assert!(errors.is_empty());
/// assert_eq!(s.epochs.len(), 1);
/// assert!((s.epochs[0].pos(2) - 410.31884).abs() < 1e-9);
/// ```
pub fn parse_station(name: &str, path: &str, text: &str) -> (StationSeries, Vec<Tenv3Error>) {
    let mut errors = Errors {
        path,
        list: Vec::new(),
    };
    let mut series = StationSeries {
        name: name.to_string(),
        path: path.to_string(),
        epochs: Vec::new(),
    };
    let lines: Vec<&str> = text.split('\n').map(|l| l.trim_end_matches('\r')).collect();
    let Some((layout, data_from)) = layout_of(&lines, &mut errors) else {
        return (series, errors.list);
    };
    let mut epochs = Vec::new();
    for (i, line) in lines.iter().enumerate().skip(data_from) {
        if line.trim().is_empty() {
            continue;
        }
        match parse_line(&layout, name, line, i + 1) {
            Ok(e) => epochs.push(e),
            Err((column, message)) => errors.push(i + 1, column, message),
        }
    }
    let epochs = keep_increasing(epochs, &lines, &layout, &mut errors);
    series.epochs = near_median(epochs, &mut errors);
    errors.list.sort_by_key(|e| (e.line, e.column));
    (series, errors.list)
}

/// The file's layout and the index of its first data line, from its first non-empty line (a
/// header, or a data line of a standard layout); `None` (with the error) when there is none.
fn layout_of(lines: &[&str], errors: &mut Errors<'_>) -> Option<(Layout, usize)> {
    let Some(first) = lines.iter().position(|l| !l.trim().is_empty()) else {
        errors.push(
            0,
            0,
            "file is empty: expected a header line and one line per day".into(),
        );
        return None;
    };
    let head = fields(lines[first]);
    if head[0].1.eq_ignore_ascii_case("site") {
        match Layout::from_names(head.iter().map(|f| f.1.to_string()).collect()) {
            Ok(l) => Some((l, first + 1)),
            Err(m) => {
                errors.push(
                    first + 1,
                    1,
                    format!(
                        "{m}: expected the NGL tenv3 header (`{}`)",
                        HEADER.join(" ")
                    ),
                );
                None
            }
        }
    } else {
        match Layout::standard(head.len()) {
            Some(l) => Some((l, first)),
            None => {
                errors.push(
                    first + 1,
                    1,
                    format!(
                        "no header line, and {} fields match neither the {}-field nor the {OLD_FIELDS}-field layout",
                        head.len(),
                        HEADER.len()
                    ),
                );
                None
            }
        }
    }
}

/// The longest strictly increasing run of dates (the first of equal dates preferred); every other
/// epoch is reported as a duplicate or out of order, at its date field.
fn keep_increasing(
    epochs: Vec<Epoch>,
    lines: &[&str],
    layout: &Layout,
    errors: &mut Errors<'_>,
) -> Vec<Epoch> {
    let days: Vec<i64> = epochs.iter().map(|e: &Epoch| e.day).collect();
    let keep = increasing_subsequence(&days);
    let kept: Vec<usize> = (0..epochs.len()).filter(|&i| keep[i]).collect();
    let by_day: HashMap<i64, usize> = kept
        .iter()
        .map(|&i| (epochs[i].day, epochs[i].line))
        .collect();
    let date_col = |e: &Epoch| -> usize {
        fields(lines[e.line - 1])
            .get(layout.date)
            .map_or(1, |f| f.0)
    };
    for (i, e) in epochs.iter().enumerate() {
        if keep[i] {
            continue;
        }
        let date = format_date(e.day, '-');
        let message = if let Some(l) = by_day.get(&e.day) {
            format!("duplicate date {date}: expected each date once (kept line {l})")
        } else {
            let prev = kept.iter().rev().find(|&&k| k < i).map(|&k| &epochs[k]);
            let next = kept.iter().find(|&&k| k > i).map(|&k| &epochs[k]);
            match (prev, next) {
                (Some(p), _) if p.day > e.day => format!(
                    "date {date} out of order: expected a date after {} (line {})",
                    format_date(p.day, '-'),
                    p.line
                ),
                (_, Some(n)) => format!(
                    "date {date} out of order: expected a date before {} (line {})",
                    format_date(n.day, '-'),
                    n.line
                ),
                _ => format!("date {date} out of order"),
            }
        };
        errors.push(e.line, date_col(e), message);
    }
    epochs
        .into_iter()
        .zip(keep)
        .filter_map(|(e, k)| k.then_some(e))
        .collect()
}

/// The epochs within [`MAX_DISPLACEMENT_M`] of the station's median position: farther is not a
/// displacement but a corrupt line (reported at the offending fraction field).
fn near_median(epochs: Vec<Epoch>, errors: &mut Errors<'_>) -> Vec<Epoch> {
    let median: [f64; 3] = std::array::from_fn(|k| {
        let mut v: Vec<f64> = epochs.iter().map(|e| e.pos(k)).collect();
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            0.0
        } else {
            v[v.len() / 2]
        }
    });
    let mut out = Vec::with_capacity(epochs.len());
    for e in epochs {
        let off = (0..3).find(|&k| (e.pos(k) - median[k]).abs() > MAX_DISPLACEMENT_M);
        match off {
            Some(k) => errors.push(
                e.line,
                e.frac_col[k],
                format!(
                    "{} position {:.4} m is {:.3} m from the station's median position {:.4} m: expected a displacement within {MAX_DISPLACEMENT_M} m",
                    COMPONENTS[k],
                    e.pos(k),
                    e.pos(k) - median[k],
                    median[k]
                ),
            ),
            None => out.push(e),
        }
    }
    out
}

/// Marks a longest strictly increasing subsequence of `days`, preferring earlier entries among
/// equal values (so the first of two lines with the same date is kept).
fn increasing_subsequence(days: &[i64]) -> Vec<bool> {
    let n = days.len();
    if days.windows(2).all(|w| w[0] < w[1]) {
        return vec![true; n];
    }
    // A longest strictly decreasing subsequence of the reversed sequence; replacing on ties makes
    // the backtracking end on the entries that come first in the file.
    let b: Vec<i64> = (0..n).map(|j| -days[n - 1 - j]).collect();
    let mut tails: Vec<usize> = Vec::new();
    let mut pred = vec![usize::MAX; n];
    for j in 0..n {
        let pos = tails.partition_point(|&t| b[t] < b[j]);
        if pos > 0 {
            pred[j] = tails[pos - 1];
        }
        if pos == tails.len() {
            tails.push(j);
        } else {
            tails[pos] = j;
        }
    }
    let mut keep = vec![false; n];
    let mut j = tails.last().copied().unwrap_or(usize::MAX);
    while j != usize::MAX {
        keep[n - 1 - j] = true;
        j = pred[j];
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::tenv3::dates::MJD_1970;
    use crate::gnss::tenv3::test_lines::{line, old_line, D0, HEAD};

    #[test]
    fn reads_header_fields_by_name_and_sums_parts() {
        let text = format!(
            "{HEAD}\n{}\n",
            line(
                "AV08",
                D0,
                [-7612, 6001536, 410],
                [0.241339, 0.822711, 0.31884],
                [0.0009, 0.001, 0.004]
            )
        );
        let (s, e) = parse_station("AV08", "AV08.tenv3", &text);
        assert!(e.is_empty(), "{e:?}");
        let ep = &s.epochs[0];
        assert_eq!(ep.day, D0);
        assert!((ep.pos(0) - (-7611.758661)).abs() < 1e-9);
        assert!((ep.pos(1) - 6001536.822711).abs() < 1e-9);
        assert!(
            (ep.pos(2) - 410.31884).abs() < 1e-9,
            "the vertical is field 13"
        );
        assert_eq!(ep.sigma, [0.0009, 0.001, 0.004]);

        // Columns in another order are still found by name.
        let mut names: Vec<&str> = HEAD.split_whitespace().collect();
        let mut vals: Vec<String> = line("AV08", D0, [1, 2, 3], [0.5, 0.25, 0.125], [0.001; 3])
            .split_whitespace()
            .map(String::from)
            .collect();
        names.swap(8, 12);
        vals.swap(8, 12);
        let text = format!("{}\n{}\n", names.join(" "), vals.join(" "));
        let (s, e) = parse_station("AV08", "x", &text);
        assert!(e.is_empty(), "{e:?}");
        assert_eq!([s.epochs[0].pos(0), s.epochs[0].pos(2)], [1.5, 3.125]);
    }

    #[test]
    fn unknown_sigma_old_layout_and_headerless() {
        let text = format!(
            "{HEAD}\n{}\n",
            line(
                "AKGG",
                D0,
                [0, 0, 0],
                [0.1, 0.2, 0.3],
                [9.99999, 0.002, 9.99999]
            )
        );
        let (s, e) = parse_station("AKGG", "x", &text);
        assert!(e.is_empty());
        assert!(s.epochs[0].sigma[0].is_nan() && s.epochs[0].sigma[2].is_nan());
        assert_eq!(s.epochs[0].sigma[1], 0.002);

        let old_head: Vec<&str> = HEAD.split_whitespace().take(OLD_FIELDS).collect();
        let text = format!(
            "{}\n{}\n{}\n",
            old_head.join(" "),
            old_line("AKGG", D0, [5, 6, 7], [0.1, 0.2, 0.3]),
            old_line("AKGG", D0 + 1, [5, 6, 7], [0.1, 0.2, 0.4])
        );
        let (s, e) = parse_station("AKGG", "x", &text);
        assert!(e.is_empty(), "{e:?}");
        assert_eq!(s.epochs.len(), 2);
        assert!((s.epochs[1].pos(2) - 7.4).abs() < 1e-12);

        // No header: the standard layouts by field count; line numbers still count from 1.
        let text = format!(
            "{}\n{}\n",
            old_line("AKGG", D0, [5, 6, 7], [0.1, 0.2, 0.3]),
            line("AKGG", D0 + 1, [5, 6, 7], [0.1, 0.2, 0.3], [0.001; 3])
        );
        let (s, e) = parse_station("AKGG", "x", &text);
        assert_eq!(s.epochs.len(), 1);
        assert_eq!((e.len(), e[0].line), (1, 2));
        assert!(e[0].message.contains("expected 20"), "{}", e[0]);
    }

    #[test]
    fn bad_lines_are_reported_with_line_and_column_and_skipped() {
        let good = |d: i64| line("AV13", D0 + d, [10, 20, 30], [0.1, 0.2, 0.3], [0.001; 3]);
        let mut lines = vec![HEAD.to_string(), good(0), good(1)];
        // 4: too few fields.
        lines.push(
            good(2)
                .split_whitespace()
                .take(22)
                .collect::<Vec<_>>()
                .join(" "),
        );
        // 5: text in the up fraction (field 13).
        lines.push(good(3).replacen(" 0.300000 ", " abc ", 1));
        // 6: infinity in sig_n (field 16).
        let mut f: Vec<String> = good(4).split_whitespace().map(String::from).collect();
        f[15] = "inf".into();
        lines.push(f.join(" "));
        // 7: MJD disagrees with the date.
        let mut f: Vec<String> = good(5).split_whitespace().map(String::from).collect();
        f[3] = (D0 + 5 + MJD_1970 + 1).to_string();
        lines.push(f.join(" "));
        // 8: duplicated date, 9: a date going back, 10: absurd position (corrupt integer part).
        lines.push(good(1));
        lines.push(good(-3));
        lines.push(line(
            "AV13",
            D0 + 6,
            [10, 20, 3000],
            [0.1, 0.2, 0.3],
            [0.001; 3],
        ));
        // 11: wrong station, 12: not a date, 13: good.
        lines.push(good(7).replacen("AV13", "AV14", 1));
        let g8 = good(8);
        let date8 = g8.split_whitespace().nth(1).unwrap().to_string();
        lines.push(g8.replacen(&date8, "10JUL3X", 1));
        lines.push(good(9));
        let text = lines.join("\n");
        let (s, e) = parse_station("AV13", "AV13.tenv3", &text);
        let col = |l: usize, field: usize| fields(&lines[l - 1])[field - 1].0;
        let got: Vec<(usize, usize)> = e.iter().map(|e| (e.line, e.column)).collect();
        let end4 = lines[3].chars().count() + 1;
        assert_eq!(
            got,
            vec![
                (4, end4),
                (5, col(5, 13)),
                (6, col(6, 16)),
                (7, col(7, 4)),
                (8, col(8, 2)),
                (9, col(9, 2)),
                (10, col(10, 13)),
                (11, 1),
                (12, col(12, 2))
            ],
            "{}",
            e.iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("\n")
        );
        assert!(e[0].message.contains("expected 23") && e[0].message.contains("found 22"));
        assert!(e[1].message.contains("`____up(m)`") && e[1].message.contains("`abc`"));
        assert!(e[2].message.contains("finite") && e[2].message.contains("`sig_n(m)`"));
        assert!(e[3].message.contains("MJD"));
        assert!(e[4].message.contains("duplicate") && e[4].message.contains("line 3"));
        assert!(
            e[5].message.contains("out of order") && e[5].message.contains("after 2010-07-29"),
            "{}",
            e[5]
        );
        assert!(e[6].message.contains("up position"));
        assert!(e[7].message.contains("`AV13`"));
        assert!(e[8].message.contains("10JUL28"));
        assert_eq!(
            e[0].to_string().split(':').take(3).collect::<Vec<_>>(),
            ["AV13.tenv3", "4", &end4.to_string()]
        );
        let days: Vec<i64> = s.epochs.iter().map(|e| e.day - D0).collect();
        assert_eq!(days, [0, 1, 9]);
        assert_eq!(s.epochs[1].line, 3, "the first of two equal dates is kept");
    }

    #[test]
    fn one_wrong_date_does_not_discard_the_lines_after_it() {
        let mut text = format!("{HEAD}\n");
        for d in [0, 1, 2, 400, 3, 4, 5] {
            text += &line("AV06", D0 + d, [0, 0, 0], [0.0; 3], [0.001; 3]);
            text += "\n";
        }
        let (s, e) = parse_station("AV06", "x", &text);
        assert_eq!(s.epochs.len(), 6);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].line, 5);
        assert!(e[0].message.contains("before 2010-07-31"), "{}", e[0]);
    }

    #[test]
    fn subsequence_prefers_earlier_lines() {
        assert_eq!(
            increasing_subsequence(&[1, 2, 2, 3]),
            [true, true, false, true]
        );
        assert_eq!(
            increasing_subsequence(&[1, 2, 4, 3, 5]),
            [true, true, true, false, true]
        );
        assert_eq!(increasing_subsequence(&[5, 5, 5]), [true, false, false]);
        assert_eq!(increasing_subsequence(&[]), Vec::<bool>::new());
    }
}
