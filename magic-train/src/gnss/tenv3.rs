//! NGL `tenv3` daily GNSS position files → one row of displacements (mm) per calendar day, in the
//! observation format `magic invert` reads.
//!
//! A folder holds one file per station, `<STA>.tenv3`: a header line naming the fields, then one
//! whitespace-separated line per day. Fields are looked up by their header name (the vertical is
//! the 13th field, not the 10th); headerless files are read with the standard layout when they have
//! the standard 23 or the older 20 fields. A position is the integer part (`_e0(m)`, `____n0(m)`,
//! `u0(m)`) plus the fractional part (`__east(m)`, `_north(m)`, `____up(m)`); NGL resets the
//! integer part only after a jump of more than 10 m and moves the difference into the fraction, so
//! the sum stays continuous and the reader always uses the sum. Sigmas of 9.99999 mean "unknown"
//! (kept as NaN). The date comes from `YYMMMDD` (`10JUL28`) and must agree with `__MJD`.
//!
//! Bad input never stops the reader: a line with the wrong number of fields, text where a number
//! belongs, an infinity, a date that does not parse or disagrees with the MJD, a position more
//! than 10 m from the station's median or from the reference epoch, or a date that repeats or
//! goes backwards is reported as a [`Tenv3Error`] naming file, line, column (1-based character
//! column where the offending field starts) and what was expected, and that line is skipped. Of
//! lines that repeat or go back in time, the reader keeps the longest run of strictly increasing
//! dates (preferring the earlier line among equal dates), so one wrong date does not discard the
//! lines after it.
//!
//! The output ([`Daily`]) has one row per calendar day from the first to the last date found in
//! any file — never a day twice, never a day skipped — with NaN where a station has no (good) line.
//! Displacements are relative to a reference epoch ([`Reference`]): by default the first day on
//! which every station with data has data, else each station's own first epoch.

use anyhow::{bail, Context, Result};
use magic_core::model_file::Problem;
use magic_core::Model;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// Largest displacement accepted, in metres: from the station's median position, and from its
/// reference epoch (the core's observation limit, `magic_core::invert::MAX_ABS_OBS`, is 10 m too).
pub const MAX_DISPLACEMENT_M: f64 = 10.0;

/// The sigma NGL writes when the uncertainty is unknown.
pub const UNKNOWN_SIGMA: f64 = 9.99999;

/// The header of the current 23-field layout; older files stop after the correlations (the
/// first [`OLD_FIELDS`] fields).
pub const HEADER: [&str; 23] = [
    "site",
    "YYMMMDD",
    "yyyy.yyyy",
    "__MJD",
    "week",
    "d",
    "reflon",
    "_e0(m)",
    "__east(m)",
    "____n0(m)",
    "_north(m)",
    "u0(m)",
    "____up(m)",
    "_ant(m)",
    "sig_e(m)",
    "sig_n(m)",
    "sig_u(m)",
    "__corr_en",
    "__corr_eu",
    "__corr_nu",
    "_latitude(deg)",
    "_longitude(deg)",
    "__height(m)",
];

/// Number of fields of the older layout (up to and including `__corr_nu`).
pub const OLD_FIELDS: usize = 20;

/// Modified Julian Date of 1970-01-01 (day numbers here count days from 1970-01-01).
const MJD_1970: i64 = 40_587;

/// Components in output order: east, north, up.
const COMPONENTS: [&str; 3] = ["east", "north", "up"];

/// One problem found in the input: `file:line:column: message`. `line` and `column` are 1-based;
/// 0 means the problem concerns the whole file (it could not be read, or has no usable header).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tenv3Error {
    /// The file, as given.
    pub path: String,
    /// 1-based line (0: the whole file).
    pub line: usize,
    /// 1-based character column where the offending field starts (0: the whole line or file).
    pub column: usize,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for Tenv3Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.line, self.column) {
            (0, _) => write!(f, "{}: {}", self.path, self.message),
            (l, 0) => write!(f, "{}:{l}: {}", self.path, self.message),
            (l, c) => write!(f, "{}:{l}:{c}: {}", self.path, self.message),
        }
    }
}

impl std::error::Error for Tenv3Error {}

/// One good line of a station file.
#[derive(Clone, Debug, PartialEq)]
pub struct Epoch {
    /// Day number (days since 1970-01-01).
    pub day: i64,
    /// 1-based line in the file.
    pub line: usize,
    /// Integer parts of the position (east, north, up), metres.
    pub int: [f64; 3],
    /// Fractional parts (east, north, up), metres; may exceed ±1.
    pub frac: [f64; 3],
    /// Standard deviations (east, north, up), metres; NaN when unknown (9.99999 in the file).
    pub sigma: [f64; 3],
    /// 1-based character columns of the fractional fields (for messages).
    pub frac_col: [usize; 3],
}

impl Epoch {
    /// Position component `k` (0 east, 1 north, 2 up), metres.
    pub fn pos(&self, k: usize) -> f64 {
        self.int[k] + self.frac[k]
    }

    /// Displacement of component `k` from `reference`, metres (integer and fractional parts
    /// differenced separately, so large integer parts lose no precision).
    pub fn minus(&self, reference: &Epoch, k: usize) -> f64 {
        (self.int[k] - reference.int[k]) + (self.frac[k] - reference.frac[k])
    }
}

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
        let mut h = super::data::channel_names(&self.stations);
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

/// Everything read from a folder: the rows, the problems (each line reported once and skipped),
/// and notes that do not make the input bad (stations without a file, files not asked for, a
/// reference epoch moved to the nearest available day).
#[derive(Clone, Debug, Default)]
pub struct Tenv3Read {
    /// The daily rows.
    pub daily: Daily,
    /// Bad lines and unreadable files, sorted by file, line and column.
    pub errors: Vec<Tenv3Error>,
    /// Remarks for the user.
    pub notes: Vec<String>,
}

// ---------------------------------------------------------------------------------------------
// Dates

/// `YYYY<sep>MM<sep>DD` of a day number.
pub fn format_date(day: i64, sep: char) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(day);
    format!("{y:04}{sep}{m:02}{sep}{d:02}")
}

/// Parses `YYYY-MM-DD` or `YYYY.MM.DD` into a day number (the core's date parser).
pub fn parse_ymd(s: &str) -> Option<i64> {
    magic_core::time::parse_date(s)
}

const MONTHS: [&str; 12] = [
    "JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC",
];

/// Parses NGL's `YYMMMDD` (`10JUL28` → 2010-07-28) into a day number. Two-digit years 80–99 are
/// 1980–1999, 00–79 are 2000–2079 (the MJD cross-check catches anything else).
pub fn parse_yymmmdd(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 7 || !b[..2].iter().chain(&b[5..]).all(u8::is_ascii_digit) {
        return None;
    }
    let yy = ((b[0] - b'0') * 10 + (b[1] - b'0')) as i64;
    let mon = std::str::from_utf8(&b[2..5]).ok()?.to_ascii_uppercase();
    let m = MONTHS.iter().position(|x| *x == mon)? as u32 + 1;
    let d = ((b[5] - b'0') * 10 + (b[6] - b'0')) as u32;
    let y = if yy >= 80 { 1900 + yy } else { 2000 + yy };
    magic_core::time::parse_date(&format!("{y:04}-{m:02}-{d:02}"))
}

// ---------------------------------------------------------------------------------------------
// One file

/// Where the fields of a file are.
#[derive(Clone, Debug)]
struct Layout {
    /// Field names as written in the header (or the standard names).
    names: Vec<String>,
    site: usize,
    date: usize,
    mjd: usize,
    int: [usize; 3],
    frac: [usize; 3],
    sigma: [Option<usize>; 3],
    /// Fields that must hold finite numbers.
    numeric: Vec<usize>,
}

fn norm(name: &str) -> String {
    name.trim_matches('_').to_ascii_lowercase()
}

/// Known numeric fields, by normalised name.
const NUMERIC: [&str; 21] = [
    "yyyy.yyyy",
    "mjd",
    "week",
    "d",
    "reflon",
    "e0(m)",
    "east(m)",
    "n0(m)",
    "north(m)",
    "u0(m)",
    "up(m)",
    "ant(m)",
    "sig_e(m)",
    "sig_n(m)",
    "sig_u(m)",
    "corr_en",
    "corr_eu",
    "corr_nu",
    "latitude(deg)",
    "longitude(deg)",
    "height(m)",
];

impl Layout {
    fn from_names(names: Vec<String>) -> std::result::Result<Layout, String> {
        let normed: Vec<String> = names.iter().map(|n| norm(n)).collect();
        let find = |key: &str| normed.iter().position(|n| n == key);
        let need = |key: &str, shown: &str| {
            find(key).ok_or_else(|| format!("header has no `{shown}` field"))
        };
        Ok(Layout {
            site: need("site", "site")?,
            date: need("yymmmdd", "YYMMMDD")?,
            mjd: need("mjd", "__MJD")?,
            int: [
                need("e0(m)", "_e0(m)")?,
                need("n0(m)", "____n0(m)")?,
                need("u0(m)", "u0(m)")?,
            ],
            frac: [
                need("east(m)", "__east(m)")?,
                need("north(m)", "_north(m)")?,
                need("up(m)", "____up(m)")?,
            ],
            sigma: [find("sig_e(m)"), find("sig_n(m)"), find("sig_u(m)")],
            numeric: (0..names.len())
                .filter(|&i| NUMERIC.contains(&normed[i].as_str()))
                .collect(),
            names,
        })
    }

    fn standard(n: usize) -> Option<Layout> {
        (n == HEADER.len() || n == OLD_FIELDS)
            .then(|| Layout::from_names(HEADER[..n].iter().map(|s| s.to_string()).collect()).ok())
            .flatten()
    }
}

/// Whitespace-separated fields with their 1-based character columns.
fn fields(line: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start: Option<(usize, usize)> = None; // (byte, column)
    let mut col = 0usize;
    for (b, ch) in line.char_indices() {
        col += 1;
        if ch.is_whitespace() {
            if let Some((sb, sc)) = start.take() {
                out.push((sc, &line[sb..b]));
            }
        } else if start.is_none() {
            start = Some((b, col));
        }
    }
    if let Some((sb, sc)) = start {
        out.push((sc, &line[sb..]));
    }
    out
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
    let mut errors = Vec::new();
    let mut series = StationSeries {
        name: name.to_string(),
        path: path.to_string(),
        epochs: Vec::new(),
    };
    let err = |line: usize, column: usize, message: String| Tenv3Error {
        path: path.to_string(),
        line,
        column,
        message,
    };
    let lines: Vec<&str> = text.split('\n').map(|l| l.trim_end_matches('\r')).collect();
    let Some(first) = lines.iter().position(|l| !l.trim().is_empty()) else {
        errors.push(err(
            0,
            0,
            "file is empty: expected a header line and one line per day".into(),
        ));
        return (series, errors);
    };
    let head = fields(lines[first]);
    let (layout, data_from) = if head[0].1.eq_ignore_ascii_case("site") {
        match Layout::from_names(head.iter().map(|f| f.1.to_string()).collect()) {
            Ok(l) => (l, first + 1),
            Err(m) => {
                errors.push(err(
                    first + 1,
                    1,
                    format!(
                        "{m}: expected the NGL tenv3 header (`{}`)",
                        HEADER.join(" ")
                    ),
                ));
                return (series, errors);
            }
        }
    } else {
        match Layout::standard(head.len()) {
            Some(l) => (l, first),
            None => {
                errors.push(err(
                    first + 1,
                    1,
                    format!(
                        "no header line, and {} fields match neither the {}-field nor the {OLD_FIELDS}-field layout",
                        head.len(),
                        HEADER.len()
                    ),
                ));
                return (series, errors);
            }
        }
    };

    let mut epochs = Vec::new();
    for (i, line) in lines.iter().enumerate().skip(data_from) {
        if line.trim().is_empty() {
            continue;
        }
        match parse_line(&layout, name, line, i + 1) {
            Ok(e) => epochs.push(e),
            Err((column, message)) => errors.push(err(i + 1, column, message)),
        }
    }

    // Dates: keep the longest strictly increasing run; report the rest.
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
        errors.push(err(e.line, date_col(e), message));
    }
    let epochs: Vec<Epoch> = epochs
        .into_iter()
        .zip(keep)
        .filter_map(|(e, k)| k.then_some(e))
        .collect();

    // Positions: more than 10 m from the station's median is not a displacement but a corrupt line.
    let median: [f64; 3] = std::array::from_fn(|k| {
        let mut v: Vec<f64> = epochs.iter().map(|e| e.pos(k)).collect();
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            0.0
        } else {
            v[v.len() / 2]
        }
    });
    for e in epochs {
        let off = (0..3).find(|&k| (e.pos(k) - median[k]).abs() > MAX_DISPLACEMENT_M);
        match off {
            Some(k) => errors.push(err(
                e.line,
                e.frac_col[k],
                format!(
                    "{} position {:.4} m is {:.3} m from the station's median position {:.4} m: expected a displacement within {MAX_DISPLACEMENT_M} m",
                    COMPONENTS[k],
                    e.pos(k),
                    e.pos(k) - median[k],
                    median[k]
                ),
            )),
            None => series.epochs.push(e),
        }
    }
    errors.sort_by_key(|e| (e.line, e.column));
    (series, errors)
}

/// Parses one data line; on failure returns (column, message).
fn parse_line(
    layout: &Layout,
    station: &str,
    line: &str,
    line_no: usize,
) -> std::result::Result<Epoch, (usize, String)> {
    let f = fields(line);
    let n = layout.names.len();
    if f.len() != n {
        let column = if f.len() > n {
            f[n].0
        } else {
            line.chars().count() + 1
        };
        return Err((
            column,
            format!(
                "expected {n} whitespace-separated fields (as in the header), found {}",
                f.len()
            ),
        ));
    }
    let what = |i: usize| format!("field {} `{}`", i + 1, layout.names[i]);
    let site = f[layout.site].1;
    if !site.eq_ignore_ascii_case(station) {
        return Err((
            f[layout.site].0,
            format!(
                "{}: expected station `{station}` (from the file name), found `{site}`",
                what(layout.site)
            ),
        ));
    }
    let mut num = vec![f64::NAN; n];
    for &i in &layout.numeric {
        let t = f[i].1;
        let v: f64 = t.parse().map_err(|_| {
            (
                f[i].0,
                format!("{}: expected a number, found `{t}`", what(i)),
            )
        })?;
        if !v.is_finite() {
            return Err((
                f[i].0,
                format!("{}: expected a finite number, found `{t}`", what(i)),
            ));
        }
        num[i] = v;
    }
    let dt = f[layout.date];
    let day = parse_yymmmdd(dt.1).ok_or_else(|| {
        (
            dt.0,
            format!(
                "{}: expected a date like `10JUL28`, found `{}`",
                what(layout.date),
                dt.1
            ),
        )
    })?;
    let mjd = num[layout.mjd];
    if mjd.fract() != 0.0 || mjd.abs() > 1e7 || mjd as i64 - MJD_1970 != day {
        return Err((
            f[layout.mjd].0,
            format!(
                "{}: expected MJD {} for the date `{}` ({}), found `{}`",
                what(layout.mjd),
                day + MJD_1970,
                dt.1,
                format_date(day, '-'),
                f[layout.mjd].1
            ),
        ));
    }
    let mut sigma = [f64::NAN; 3];
    for (k, s) in layout.sigma.iter().enumerate() {
        if let Some(i) = *s {
            let v = num[i];
            if (v - UNKNOWN_SIGMA).abs() < 5e-7 {
                continue;
            }
            if v < 0.0 {
                return Err((
                    f[i].0,
                    format!(
                        "{}: expected a non-negative standard deviation, found `{}`",
                        what(i),
                        f[i].1
                    ),
                ));
            }
            sigma[k] = v;
        }
    }
    Ok(Epoch {
        day,
        line: line_no,
        int: layout.int.map(|i| num[i]),
        frac: layout.frac.map(|i| num[i]),
        sigma,
        frac_col: layout.frac.map(|i| f[i].0),
    })
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

// ---------------------------------------------------------------------------------------------
// Many stations

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

    // Reference epoch per station (index into its epochs).
    let find = |x: &StationSeries, day: i64| x.epochs.binary_search_by_key(&day, |e| e.day).ok();
    let refs: Vec<Option<usize>> = match reference {
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
    };

    let mut rows = vec![vec![f64::NAN; 3 * s]; n_days];
    for (si, x) in series.iter().enumerate() {
        let Some(r) = refs[si].map(|i| &x.epochs[i]) else {
            continue;
        };
        for e in &x.epochs {
            let d: [f64; 3] = std::array::from_fn(|k| e.minus(r, k));
            if let Some(k) = (0..3).find(|&k| d[k].abs() > MAX_DISPLACEMENT_M) {
                errors.push(Tenv3Error {
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
                });
                continue;
            }
            let row = &mut rows[(e.day - first) as usize];
            for k in 0..3 {
                row[k * s + si] = d[k] * 1000.0;
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

/// The `<STA>.tenv3` files in `dir`: station name (file stem) → path, sorted by name.
pub fn list_dir(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let rd =
        std::fs::read_dir(dir).with_context(|| format!("{}: cannot read folder", dir.display()))?;
    let mut out = Vec::new();
    for entry in rd {
        let p = entry
            .with_context(|| format!("{}: cannot read folder", dir.display()))?
            .path();
        let is_tenv3 = p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("tenv3"));
        if is_tenv3 && p.is_file() {
            if let Some(stem) = p.file_stem().and_then(|s| s.to_str()) {
                out.push((stem.to_string(), p.clone()));
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Reads the station files in `dir` for `stations` (in that column order; `None`: every
/// `*.tenv3` file, sorted by name) and combines them into daily rows.
///
/// Fails only when the folder cannot be listed, when `stations` repeats a name, or when there is
/// nothing to read; every problem inside the files is collected in [`Tenv3Read::errors`].
pub fn read_dir(
    dir: &Path,
    stations: Option<&[String]>,
    reference: Reference,
) -> Result<Tenv3Read> {
    let files = list_dir(dir)?;
    let names: Vec<String> = match stations {
        Some(s) => s.to_vec(),
        None => files.iter().map(|f| f.0.clone()).collect(),
    };
    if names.is_empty() {
        bail!(
            "{}: no `<STATION>.tenv3` files and no station list",
            dir.display()
        );
    }
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            bail!("station {n} is listed twice");
        }
    }
    let mut errors = Vec::new();
    let mut notes = Vec::new();
    let mut series = Vec::with_capacity(names.len());
    let mut used = vec![false; files.len()];
    for name in &names {
        let hit = files
            .iter()
            .position(|f| f.0 == *name)
            .or_else(|| files.iter().position(|f| f.0.eq_ignore_ascii_case(name)));
        let Some(fi) = hit else {
            notes.push(format!(
                "station {name}: no file {} (its channels are missing on every day)",
                dir.join(format!("{name}.tenv3")).display()
            ));
            series.push(StationSeries {
                name: name.clone(),
                ..Default::default()
            });
            continue;
        };
        used[fi] = true;
        let path = &files[fi].1;
        let shown = path.display().to_string();
        match std::fs::read(path) {
            Ok(bytes) => {
                let (s, e) = parse_station(name, &shown, &String::from_utf8_lossy(&bytes));
                series.push(s);
                errors.extend(e);
            }
            Err(e) => {
                errors.push(Tenv3Error {
                    path: shown.clone(),
                    line: 0,
                    column: 0,
                    message: format!("cannot read: {e}"),
                });
                series.push(StationSeries {
                    name: name.clone(),
                    path: shown,
                    epochs: Vec::new(),
                });
            }
        }
    }
    for (f, u) in files.iter().zip(&used) {
        if !u {
            notes.push(format!(
                "{}: station {} is not in the station list; ignored",
                f.1.display(),
                f.0
            ));
        }
    }
    let (daily, e, n) = combine(&series, reference);
    errors.extend(e);
    notes.extend(n);
    errors.sort_by(|a, b| (&a.path, a.line, a.column).cmp(&(&b.path, b.line, b.column)));
    Ok(Tenv3Read {
        daily,
        errors,
        notes,
    })
}

/// Station names of a Mogi model, in its channel order.
pub fn model_station_names(model: &Model<'_>) -> Result<Vec<String>> {
    match &model.problem {
        Problem::Mogi { names, .. } => Ok(names.iter().map(|n| n.to_string()).collect()),
        Problem::Rtm { .. } => bail!("the model is not a GNSS (Mogi) model: it has no stations"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)";

    /// A line of the 23-field layout for `day` (days since 1970), position parts given.
    fn line(site: &str, day: i64, int: [i64; 3], frac: [f64; 3], sig: [f64; 3]) -> String {
        let (y, m, d) = magic_core::time::civil_from_days(day);
        let mjd = day + MJD_1970;
        format!(
            "{site} {:02}{}{:02} {:.4} {mjd} {} {} -166 {} {:.6} {} {:.6} {} {:.6} 0.0000 {:.6} {:.6} {:.6} 0.0123 -0.0204 0.0071 54.1271930 -165.9743172 410.3188",
            y % 100,
            MONTHS[m as usize - 1],
            d,
            y as f64 + 0.5,
            (mjd - 44_244) / 7,
            (mjd - 44_244) % 7,
            int[0],
            frac[0],
            int[1],
            frac[1],
            int[2],
            frac[2],
            sig[0],
            sig[1],
            sig[2],
        )
    }

    fn old_line(site: &str, day: i64, int: [i64; 3], frac: [f64; 3]) -> String {
        let l = line(site, day, int, frac, [0.001, 0.001, 0.004]);
        l.split_whitespace()
            .take(OLD_FIELDS)
            .collect::<Vec<_>>()
            .join(" ")
    }

    const D0: i64 = 14_818; // 2010-07-28

    #[test]
    fn dates() {
        assert_eq!(parse_yymmmdd("10JUL28"), Some(D0));
        assert_eq!(format_date(D0, '-'), "2010-07-28");
        assert_eq!(
            parse_yymmmdd("96feb29"),
            Some(magic_core::time::days_from_civil(1996, 2, 29))
        );
        assert_eq!(parse_yymmmdd("97FEB29"), None);
        assert_eq!(parse_yymmmdd("10JUX28"), None);
        assert_eq!(parse_yymmmdd("10JUL2"), None);
        assert_eq!(parse_ymd("2010-07-28"), Some(D0));
        assert_eq!(parse_ymd("2010.07.28"), Some(D0));
        assert_eq!(parse_ymd("2010-13-01"), None);
        for day in [-1000, 0, 59, 10_000, 14_818, 20_000, 40_000] {
            let (y, m, d) = magic_core::time::civil_from_days(day);
            assert_eq!(magic_core::time::days_from_civil(y, m, d), day);
        }
        // 1858-11-17 is MJD 0.
        assert_eq!(magic_core::time::days_from_civil(1858, 11, 17), -MJD_1970);
    }

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
