//! Observation CSVs in, result CSVs out, for `magic invert`, `magic qemu` and the demo.
//!
//! Input columns are matched to the model's network by name (`ux_<STA>`, `uy_<STA>`, `uz_<STA>`;
//! other columns such as `date` are carried or ignored). An empty or `NaN` cell is a missing
//! channel; any other cell that is not a finite number, or beyond 10 m, makes that row an error
//! row — named by file, line and column — and the next row is still processed.

use crate::data::table::Table;
use crate::gnss::data::channel_names;
use anyhow::{anyhow, Result};
use magic_core::line::{write_error, write_result, LineError};
use magic_core::model_file::Problem;
use magic_core::{invert_at, Model, Workspace};
use std::fmt::Write as _;
use std::path::Path;

/// One input row: its date (if the file has one) and observations in physical units, or why not.
pub struct ObsRow {
    /// `date` column, if any.
    pub date: Option<String>,
    /// Observations (NaN = missing), or the error message naming file:line:column.
    pub obs: std::result::Result<Vec<f32>, String>,
}

impl ObsRow {
    /// Day number of the row's date (NaN without a date).
    pub fn day(&self) -> f64 {
        self.date
            .as_deref()
            .map_or(f64::NAN, crate::data::day_number)
    }
}

/// Channel names of a model (`ux_<STA>` …).
pub fn model_channels(model: &Model<'_>) -> Result<Vec<String>> {
    match &model.problem {
        Problem::Mogi { names, .. } => Ok(channel_names(
            &names.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
        )),
        Problem::Rtm { .. } => {
            let (idx, n) = model.problem.band_indices();
            Ok(idx[..n]
                .iter()
                .map(|&b| magic_core::rtm::S2_BANDS[b].to_string())
                .collect())
        }
    }
}

/// Reads observation rows for `model` from a CSV; `standardized` converts with the model's
/// mean and scale (for the data files as they are).
pub fn read_obs(path: &Path, model: &Model<'_>, standardized: bool) -> Result<Vec<ObsRow>> {
    let t = Table::read_lenient(path, b',')?;
    let chans = model_channels(model)?;
    let cols: Vec<usize> = match model.problem {
        // Band `B02` is the column `B02` or `B02_<name>` (as in the S2 data files).
        Problem::Rtm { .. } => chans
            .iter()
            .map(|c| crate::rtm::data::band_column(&t, c))
            .collect::<Result<_>>()?,
        _ => chans.iter().map(|c| t.col(c)).collect::<Result<_>>()?,
    };
    let date = t.col("date").ok();
    let mut rows = Vec::with_capacity(t.rows.len());
    for r in 0..t.rows.len() {
        let mut obs = Vec::with_capacity(cols.len());
        let mut err = t.malformed[r].clone();
        for (i, &c) in cols.iter().enumerate() {
            if err.is_some() {
                break;
            }
            match t.num(r, c, true) {
                Ok(v) => {
                    let v = if standardized {
                        v * model.obs_scale.get(i) as f64 + model.obs_mean.get(i) as f64
                    } else {
                        v
                    };
                    if v.abs() > magic_core::invert::MAX_ABS_OBS {
                        err = Some(format!(
                            "{}: column `{}`: {v} mm is beyond 10 m",
                            t.at(r, c),
                            t.header[c]
                        ));
                        break;
                    }
                    obs.push(v as f32);
                }
                Err(e) => {
                    err = Some(e.to_string());
                    break;
                }
            }
        }
        rows.push(ObsRow {
            date: date.map(|c| t.text(r, c).to_string()),
            obs: err.map_or(Ok(obs), Err),
        });
    }
    Ok(rows)
}

/// The header of a result CSV for `model` (with a leading `date` column when `with_date`).
pub fn result_header(model: &Model<'_>, with_date: bool) -> String {
    let mut h = String::new();
    if with_date {
        h.push_str("date,");
    }
    h.push_str(&result_columns(model).join(","));
    h
}

/// The result columns of `model` (no `date`): its variables — for a GNSS network the source's,
/// then the latent variables of each declared effect — then `residual_rms`, `flags`,
/// `stations_used`.
pub fn result_columns(model: &Model<'_>) -> Vec<String> {
    let mut names: Vec<String> = match (&model.problem, model.variant) {
        (Problem::Mogi { .. }, _) => magic_core::mogi::PARAM_NAMES.map(String::from).to_vec(),
        (Problem::Rtm { .. }, magic_core::Variant::A) => (0..7).map(|i| format!("z{i}")).collect(),
        (Problem::Rtm { .. }, _) => RTM_RESULT_NAMES.map(String::from).to_vec(),
    };
    if let Problem::Mogi { .. } = model.problem {
        names.extend(latent_columns(model.effects.iter().map(|e| e.family())));
    }
    names.extend(["residual_rms", "flags", "stations_used"].map(String::from));
    names
}

/// The columns of the latent variables of GNSS effects of `families`, in order: a common
/// mode's `cm_e_mm`, `cm_n_mm`, `cm_u_mm`, an elevation term's `elev_mm_per_km`, and each
/// extra source's volume change, `dv2_1e6m3` for the first (the main source's is `dv_1e6m3`),
/// `dv3_1e6m3` for the next, and so on. Effects without latent variables have no column.
///
/// ```
/// use magic_train::data::records::latent_columns;
/// let cols = latent_columns(["second_source", "common_mode", "step", "second_source"]);
/// assert_eq!(cols, ["dv2_1e6m3", "cm_e_mm", "cm_n_mm", "cm_u_mm", "dv3_1e6m3"]);
/// ```
pub fn latent_columns<'a>(families: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut sources = 0;
    let mut out = Vec::new();
    for f in families {
        match f {
            "common_mode" => out.extend(["cm_e_mm", "cm_n_mm", "cm_u_mm"].map(String::from)),
            "elevation" => out.push("elev_mm_per_km".into()),
            "second_source" => {
                sources += 1;
                out.push(format!("dv{}_1e6m3", sources + 1));
            }
            _ => {}
        }
    }
    out
}

/// The standard-deviation columns `magic invert --sd` appends: `<variable>_sd` for each of the
/// model's variables (the source's, the effects' latents, the RTM's derived ones).
pub fn sd_columns(model: &Model<'_>) -> Vec<String> {
    let names = result_columns(model);
    names[..names.len() - 3]
        .iter()
        .map(|n| format!("{n}_sd"))
        .collect()
}

/// Inverts rows on the host like [`invert_rows`] and appends to each result line the standard
/// deviations of its variables ([`magic_core::uncertainty::standard_deviations`]: the Laplace
/// approximation at the solution with the exact Jacobian, raw — not calibrated), `NaN` where
/// they cannot be computed (e.g. fewer observed channels than variables plus one). Error rows
/// stay error rows. Fails for a model without a forward model (variant A).
pub fn invert_rows_sd(model: &Model<'_>, rows: &[ObsRow]) -> Result<Vec<String>> {
    if model.variant == magic_core::Variant::A {
        return Err(anyhow!(
            "standard deviations need a forward model: this is a variant A model (use B or C)"
        ));
    }
    Ok(invert_lines(model, rows, Some(sd_columns(model).len())))
}

/// Result columns of an RTM inversion: the 7 learned variables, then the derived crown diameter
/// and tree height.
pub const RTM_RESULT_NAMES: [&str; 9] = ["N", "cab", "cw", "cm", "LAI", "LAIu", "fc", "cd", "h"];

/// Inverts rows on the host (physics in f64), returning one result line per row.
pub fn invert_rows(model: &Model<'_>, rows: &[ObsRow]) -> Vec<String> {
    invert_lines(model, rows, None)
}

/// The result line of every row, with the standard deviations of the first `n_sd` variables
/// appended when `n_sd` is given.
fn invert_lines(model: &Model<'_>, rows: &[ObsRow], n_sd: Option<usize>) -> Vec<String> {
    use magic_core::uncertainty::{standard_deviations, SdWorkspace};
    let (mut ws, mut sw) = (Workspace::default(), SdWorkspace::default());
    rows.iter()
        .map(|row| {
            let mut s = String::new();
            match &row.obs {
                Ok(obs) => match invert_at::<f64>(model, obs, row.day(), &mut ws) {
                    Ok(inv) => {
                        let _ = write_result(&mut s, &inv);
                        if let Some(n) = n_sd {
                            let u = standard_deviations(model, obs, &inv, row.day(), &mut sw).ok();
                            for k in 0..n {
                                let sd = u.as_ref().and_then(|u| u.sd.get(k));
                                let _ = write!(s, ",{}", sd.map_or(f32::NAN, |v| *v as f32));
                            }
                        }
                    }
                    Err(e) => {
                        let _ = write_error(&mut s, &LineError::Invert(e));
                    }
                },
                Err(msg) => {
                    let _ = write!(s, "error,{}", msg.replace(',', ";"));
                }
            }
            s
        })
        .collect()
}

/// Observation rows as the plain lines the firmware reads (empty fields for missing channels;
/// rows that already failed on the host are sent as a line the firmware rejects too). With
/// `with_date` (models with time-dependent effects) each line starts with the date `YYYY-MM-DD`.
pub fn firmware_lines(rows: &[ObsRow], with_date: bool) -> String {
    let mut out = String::new();
    for row in rows {
        match &row.obs {
            Ok(obs) => {
                if with_date {
                    let d = row.day();
                    if d.is_finite() {
                        let (y, m, dd) = magic_core::time::civil_from_days(d as i64);
                        out.push_str(&format!("{y:04}-{m:02}-{dd:02},"));
                    } else {
                        out.push_str("no-date,");
                    }
                }
                let fields: Vec<String> = obs
                    .iter()
                    .map(|v| {
                        if v.is_nan() {
                            String::new()
                        } else {
                            format!("{v}")
                        }
                    })
                    .collect();
                out.push_str(&fields.join(","));
            }
            Err(_) => out.push_str("invalid"),
        }
        out.push('\n');
    }
    out
}

/// Writes a result CSV: header, then one line per row (date first when present).
pub fn write_results(
    path: &Path,
    model: &Model<'_>,
    rows: &[ObsRow],
    lines: &[String],
) -> Result<()> {
    write_results_with(path, model, rows, lines, &[])
}

/// [`write_results`] with `extra` columns after the model's (e.g. [`sd_columns`]).
pub fn write_results_with(
    path: &Path,
    model: &Model<'_>,
    rows: &[ObsRow],
    lines: &[String],
    extra: &[String],
) -> Result<()> {
    if rows.len() != lines.len() {
        return Err(anyhow!(
            "{} result lines for {} input rows",
            lines.len(),
            rows.len()
        ));
    }
    let with_date = rows.iter().any(|r| r.date.is_some());
    let mut text = result_header(model, with_date);
    for c in extra {
        text.push(',');
        text.push_str(c);
    }
    text.push('\n');
    for (row, line) in rows.iter().zip(lines) {
        if with_date {
            text.push_str(row.date.as_deref().unwrap_or(""));
            text.push(',');
        }
        text.push_str(line);
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|e| anyhow!("{}: cannot write: {e}", path.display()))
}

/// The rows of a split in physical units, with their dates (as `magic invert` would read them
/// from the data files).
pub fn split_rows(data: &crate::data::Dataset, split: crate::data::SplitName) -> Vec<ObsRow> {
    let s = data.split(split);
    s.x.iter()
        .enumerate()
        .map(|(i, x)| ObsRow {
            date: s.dates.get(i).cloned(),
            obs: Ok(data.physical_row(x)),
        })
        .collect()
}
