//! The plain-text record format shared by the firmware and the host: one observation vector per
//! line in, one result per line out, so that `magic invert` and the board print the same rows.
//!
//! Input: comma-separated numbers (whitespace around them ignored); an empty field or `nan` marks a
//! missing channel. Output: `x_km,y_km,depth_km,dv_1e6m3,residual_rms,flags,stations_used` (the
//! variables of the model, then the residual in physical units, the flag bits and the bit mask of
//! stations used), or `error,<message>` for a line that could not be inverted.

use crate::error::FmtSink;
use crate::{Error, Inversion, MessageSink, Real};
use core::fmt::{self, Write};

/// Why an input line could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineError {
    /// The line has a different number of fields.
    FieldCount {
        /// Fields expected.
        expected: usize,
        /// Fields found (counting stops one past the expected number).
        found: usize,
    },
    /// A field is not a number (1-based field index).
    NotANumber {
        /// 1-based field.
        field: usize,
    },
    /// A field is infinite or absurdly large (1-based field index).
    OutOfRange {
        /// 1-based field.
        field: usize,
    },
    /// The leading date field is not `YYYY-MM-DD` or `YYYY.MM.DD`.
    BadDate,
    /// The inversion failed.
    Invert(Error),
}

impl LineError {
    /// Writes the message `Display` prints, piece by piece (see [`Error::describe`]).
    pub fn describe<S: MessageSink + ?Sized>(&self, s: &mut S) {
        let n32 = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        match *self {
            LineError::FieldCount { expected, found } => {
                s.text("expected ");
                s.number(n32(expected));
                s.text(" fields, found ");
                s.number(n32(found));
            }
            LineError::NotANumber { field } => {
                s.text("field ");
                s.number(n32(field));
                s.text(": not a number");
            }
            LineError::OutOfRange { field } => {
                s.text("field ");
                s.number(n32(field));
                s.text(": infinite or beyond 10 m");
            }
            LineError::BadDate => s.text("field 1: expected a date YYYY-MM-DD"),
            LineError::Invert(e) => e.describe(s),
        }
    }
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        FmtSink::display(f, |s| self.describe(s))
    }
}

/// Parses one line of comma-separated numbers into `out` (all of it), NaN for missing fields.
///
/// ```
/// let mut v = [0f32; 3];
/// magic_core::line::parse_obs(" 1.5, ,nan", &mut v).unwrap();
/// assert_eq!(v[0], 1.5);
/// assert!(v[1].is_nan() && v[2].is_nan());
/// assert!(magic_core::line::parse_obs("1,2", &mut v).is_err());
/// ```
pub fn parse_obs(line: &str, out: &mut [f32]) -> Result<(), LineError> {
    let line = line.trim_end_matches(['\r', '\n']);
    let mut n = 0usize;
    for (i, field) in line.split(',').enumerate() {
        if i >= out.len() {
            return Err(LineError::FieldCount {
                expected: out.len(),
                found: i + 1,
            });
        }
        let t = field.trim();
        out[i] = if t.is_empty() || t.eq_ignore_ascii_case("nan") {
            f32::NAN
        } else {
            let v: f32 = t
                .parse()
                .map_err(|_| LineError::NotANumber { field: i + 1 })?;
            if !v.is_finite() || (v as f64).abs() > crate::invert::MAX_ABS_OBS {
                return Err(LineError::OutOfRange { field: i + 1 });
            }
            v
        };
        n = i + 1;
    }
    if n != out.len() {
        return Err(LineError::FieldCount {
            expected: out.len(),
            found: n,
        });
    }
    Ok(())
}

/// Parses a record for a model: when `with_date`, the first field is the observation's date
/// (`YYYY-MM-DD` or `YYYY.MM.DD`) and the observations follow. Returns the day number (NaN without
/// a date).
///
/// ```
/// let mut v = [0f32; 2];
/// let t = magic_core::line::parse_record("2006-01-02,1,2", true, &mut v).unwrap();
/// assert_eq!((t, v), (13150.0, [1.0, 2.0]));
/// ```
pub fn parse_record(line: &str, with_date: bool, out: &mut [f32]) -> Result<f64, LineError> {
    if !with_date {
        return parse_obs(line, out).map(|_| f64::NAN);
    }
    let line = line.trim_end_matches(['\r', '\n']);
    let (date, rest) = line.split_once(',').ok_or(LineError::FieldCount {
        expected: out.len() + 1,
        found: 1,
    })?;
    let day = crate::time::parse_date(date).ok_or(LineError::BadDate)?;
    parse_obs(rest, out).map_err(|e| match e {
        LineError::FieldCount { expected, found } => LineError::FieldCount {
            expected: expected + 1,
            found: found + 1,
        },
        LineError::NotANumber { field } => LineError::NotANumber { field: field + 1 },
        LineError::OutOfRange { field } => LineError::OutOfRange { field: field + 1 },
        other => other,
    })?;
    Ok(day as f64)
}

/// Writes the result row of an inversion (no newline).
pub fn write_result<R: Real, W: Write>(w: &mut W, inv: &Inversion<R>) -> fmt::Result {
    for p in &inv.params[..inv.n_params] {
        write!(w, "{:.6},", p.value())?;
    }
    write!(w, "{:.6},{},{}", inv.residual_rms, inv.flags.0, inv.used)
}

/// Writes an error row (no newline).
pub fn write_error<W: Write>(w: &mut W, e: &LineError) -> fmt::Result {
    write!(w, "error,{e}")
}
