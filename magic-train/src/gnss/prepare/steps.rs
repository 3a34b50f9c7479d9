//! NGL's list of potential steps (`steps.txt`, described in NGL's `steps_readme.txt`): one
//! whitespace-separated line per step,
//!
//! ```text
//! STA  YYMMMDD  1  equipment_change                        (code 1: antenna, receiver, firmware)
//! STA  YYMMMDD  2  threshold_km  distance_km  mag  event   (code 2: a possible earthquake step)
//! ```
//!
//! Code 2 marks a station within r₀ = 10^(mag/2 − 0.8) km of an epicentre. Both shapes are read;
//! a bad line (too few fields, an unknown code, a date or number that does not parse) is reported
//! with its line and column and skipped. Empty lines and lines starting with `#` are ignored.

use crate::gnss::tenv3::{format_date, parse_yymmmdd, Tenv3Error};
use std::collections::BTreeMap;

/// What caused a step.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum StepKind {
    /// Code 1: an equipment change (its description, e.g. `Antenna_Code_Changed`).
    Equipment {
        /// The change, as written.
        change: String,
    },
    /// Code 2: an earthquake near the station.
    Earthquake {
        /// Distance threshold for the magnitude, km.
        threshold_km: f64,
        /// Station–epicentre distance, km.
        distance_km: f64,
        /// Magnitude.
        magnitude: f64,
        /// USGS event id.
        event: String,
    },
}

/// One line of a steps file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepEntry {
    /// Station.
    pub station: String,
    /// Day number of the step (days since 1970-01-01); observations on that day and later are
    /// after it.
    pub day: i64,
    /// What caused it.
    pub kind: StepKind,
    /// 1-based line in the file.
    pub line: usize,
}

impl StepEntry {
    /// `YYYY-MM-DD` of the step.
    pub fn date(&self) -> String {
        format_date(self.day, '-')
    }
}

/// Whitespace-separated fields of a line with their 1-based character columns.
fn fields(line: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start = None;
    for (col, (b, ch)) in line.char_indices().enumerate() {
        match (ch.is_whitespace(), start) {
            (true, Some((sb, sc))) => {
                out.push((sc, &line[sb..b]));
                start = None;
            }
            (false, None) => start = Some((b, col + 1)),
            _ => {}
        }
    }
    if let Some((sb, sc)) = start {
        out.push((sc, &line[sb..]));
    }
    out
}

/// Parses one line (not empty, not a comment); on failure the column and message.
fn parse_line(
    f: &[(usize, &str)],
    line_len: usize,
) -> Result<(String, i64, StepKind), (usize, String)> {
    if f.len() < 3 {
        return Err((
            line_len + 1,
            format!(
                "expected `STA YYMMMDD CODE …` (at least 3 fields), found {}",
                f.len()
            ),
        ));
    }
    let day = parse_yymmmdd(f[1].1).ok_or_else(|| {
        (
            f[1].0,
            format!("expected a date like `10JUL28`, found `{}`", f[1].1),
        )
    })?;
    let kind = match f[2].1 {
        "1" => StepKind::Equipment {
            change: f[3..].iter().map(|x| x.1).collect::<Vec<_>>().join(" "),
        },
        "2" => {
            if f.len() < 6 {
                return Err((
                    line_len + 1,
                    format!(
                        "code 2 (earthquake): expected `STA YYMMMDD 2 threshold_km distance_km magnitude [event]`, found {} fields",
                        f.len()
                    ),
                ));
            }
            let num = |k: usize, what: &str| -> Result<f64, (usize, String)> {
                f[k].1
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| (f[k].0, format!("expected the {what}, found `{}`", f[k].1)))
            };
            StepKind::Earthquake {
                threshold_km: num(3, "threshold distance (km)")?,
                distance_km: num(4, "distance to the epicentre (km)")?,
                magnitude: num(5, "magnitude")?,
                event: f.get(6).map_or(String::new(), |x| x.1.to_string()),
            }
        }
        other => {
            return Err((
                f[2].0,
                format!("expected the step code 1 (equipment) or 2 (earthquake), found `{other}`"),
            ))
        }
    };
    Ok((f[0].1.to_string(), day, kind))
}

/// Parses the text of a steps file (`path` for messages): the entries in file order, and the
/// bad lines.
///
/// ```
/// use magic_train::gnss::prepare::steps::{parse_steps, StepKind};
/// let text = "AV06  10JUL28  1  Antenna_Code_Changed\n\
///             AV06  11MAR11  2  158.49  102.3  6.0  us2011abcd\n";
/// let (steps, errors) = parse_steps("steps.txt", text);
/// assert!(errors.is_empty());
/// assert_eq!(steps[1].date(), "2011-03-11");
/// assert!(matches!(steps[1].kind, StepKind::Earthquake { magnitude, .. } if magnitude == 6.0));
/// ```
pub fn parse_steps(path: &str, text: &str) -> (Vec<StepEntry>, Vec<Tenv3Error>) {
    let mut out = Vec::new();
    let mut errors = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim_end_matches('\r');
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            continue;
        }
        match parse_line(&fields(line), line.chars().count()) {
            Ok((station, day, kind)) => out.push(StepEntry {
                station,
                day,
                kind,
                line: i + 1,
            }),
            Err((column, message)) => errors.push(Tenv3Error {
                path: path.to_string(),
                line: i + 1,
                column,
                message,
            }),
        }
    }
    (out, errors)
}

/// The step days of each station (sorted, each day once), for the stations in `names`; entries
/// of other stations are counted in the second value.
pub fn by_station(entries: &[StepEntry], names: &[String]) -> (BTreeMap<String, Vec<i64>>, usize) {
    let mut map: BTreeMap<String, Vec<i64>> = BTreeMap::new();
    let mut other = 0;
    for e in entries {
        match names.iter().find(|n| n.eq_ignore_ascii_case(&e.station)) {
            Some(n) => map.entry(n.clone()).or_default().push(e.day),
            None => other += 1,
        }
    }
    for v in map.values_mut() {
        v.sort_unstable();
        v.dedup();
    }
    (map, other)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_row_shapes_bad_lines_and_other_stations() {
        let text = "\
# a comment\n\
AV06  10JUL28  1  Antenna_Code_Changed\n\
\n\
AV06  10JUL28  2  158.49  102.3  6.0  us2010xyz\r\n\
AV13  09JAN05  1\n\
AKGG  09JAN05\n\
AKGG  09JAX05  1  Receiver\n\
AKGG  09JAN05  3  what\n\
AKGG  09JAN05  2  158.49  far  6.0  id\n\
P123  12DEC01  2  50.1  20.0  5.0  ci123\n";
        let (s, e) = parse_steps("steps.txt", text);
        assert_eq!(s.len(), 4);
        assert_eq!(
            s[0].kind,
            StepKind::Equipment {
                change: "Antenna_Code_Changed".into()
            }
        );
        assert_eq!(s[1].line, 4);
        assert!(
            matches!(&s[1].kind, StepKind::Earthquake { event, distance_km, .. }
            if event == "us2010xyz" && *distance_km == 102.3)
        );
        assert_eq!(
            s[2].kind,
            StepKind::Equipment {
                change: String::new()
            }
        );
        let at: Vec<(usize, usize)> = e.iter().map(|e| (e.line, e.column)).collect();
        assert_eq!(at, [(6, 14), (7, 7), (8, 16), (9, 27)], "{e:?}");
        assert!(e[2].message.contains("`3`") && e[3].message.contains("`far`"));
        let names = vec!["AV06".to_string(), "AV13".to_string(), "AKGG".to_string()];
        let (m, other) = by_station(&s, &names);
        assert_eq!(m["AV06"], vec![s[0].day], "one step per day");
        assert_eq!(m["AV13"].len(), 1);
        assert!(!m.contains_key("AKGG"));
        assert_eq!(other, 1, "P123 is not in the network");
    }
}
