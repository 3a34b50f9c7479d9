//! One data line of a station file: its fields checked against the file's layout (count,
//! station, finite numbers, a date that agrees with the MJD, non-negative sigmas) into an
//! [`Epoch`], or the column and message of the first thing wrong with it.

use super::dates::{format_date, parse_yymmmdd, MJD_1970};
use super::layout::{fields, Layout};
use super::UNKNOWN_SIGMA;

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
    /// Latitude (°), longitude (° as written: NGL does not wrap it into ±180°) and ellipsoidal
    /// height (m) of the day's position, when the file has those fields.
    pub geo: Option<[f64; 3]>,
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

/// Parses one data line; on failure returns (column, message).
pub(crate) fn parse_line(
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
    if let Some([lat, _, _]) = layout.geo {
        if num[lat].abs() > 90.0 {
            return Err((
                f[lat].0,
                format!(
                    "{}: expected a latitude within ±90°, found `{}`",
                    what(lat),
                    f[lat].1
                ),
            ));
        }
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
        geo: layout.geo.map(|g| g.map(|i| num[i])),
    })
}
