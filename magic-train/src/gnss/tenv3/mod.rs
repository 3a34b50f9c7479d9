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
//!
//! Layout: `dates` (NGL and ISO dates) · `layout` (where the fields of a file are) · `line` (one
//! data line) · `station` (one file) · `daily` (stations combined into daily rows) · `folder`
//! (a folder of files).

mod daily;
mod dates;
mod folder;
mod layout;
mod line;
mod station;

#[cfg(test)]
pub(crate) mod test_lines;

pub use daily::{combine, Daily, Reference};
pub use dates::{format_date, parse_ymd, parse_yymmmdd, MJD_1970};
pub use folder::{list_dir, read_dir, read_series, SeriesRead, Tenv3Read};
pub use layout::{HEADER, OLD_FIELDS};
pub use line::Epoch;
pub use station::{parse_station, StationSeries};

use anyhow::{bail, Result};
use magic_core::model_file::Problem;
use magic_core::Model;
use std::fmt;

/// Largest displacement accepted, in metres: from the station's median position, and from its
/// reference epoch (the core's observation limit, `magic_core::invert::MAX_ABS_OBS`, is 10 m too).
pub const MAX_DISPLACEMENT_M: f64 = 10.0;

/// The sigma NGL writes when the uncertainty is unknown.
pub const UNKNOWN_SIGMA: f64 = 9.99999;

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

/// Station names of a Mogi model, in its channel order.
pub fn model_station_names(model: &Model<'_>) -> Result<Vec<String>> {
    match &model.problem {
        Problem::Mogi { names, .. } => Ok(names.iter().map(|n| n.to_string()).collect()),
        Problem::Rtm { .. } => bail!("the model is not a GNSS (Mogi) model: it has no stations"),
    }
}
