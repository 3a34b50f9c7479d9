//! A folder of `<STA>.tenv3` files: the files found, each asked-for station's file parsed, and
//! the stations combined into daily rows, with every problem and note collected.

use super::daily::{combine, Daily, Reference};
use super::station::{parse_station, StationSeries};
use super::Tenv3Error;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

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
    let mut read = read_series(dir, stations)?;
    let (daily, e, n) = combine(&read.series, reference);
    read.errors.extend(e);
    read.notes.extend(n);
    read.errors
        .sort_by(|a, b| (&a.path, a.line, a.column).cmp(&(&b.path, b.line, b.column)));
    Ok(Tenv3Read {
        daily,
        errors: read.errors,
        notes: read.notes,
    })
}

/// The station series of a folder, before they are combined into daily rows.
#[derive(Clone, Debug, Default)]
pub struct SeriesRead {
    /// One series per station, in column order (empty for a station without a readable file).
    pub series: Vec<StationSeries>,
    /// Bad lines and unreadable files, in file order.
    pub errors: Vec<Tenv3Error>,
    /// Remarks for the user.
    pub notes: Vec<String>,
}

/// Reads and parses the station files in `dir` for `stations` (as [`read_dir`]) without
/// combining them.
pub fn read_series(dir: &Path, stations: Option<&[String]>) -> Result<SeriesRead> {
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
    Ok(SeriesRead {
        series,
        errors,
        notes,
    })
}
