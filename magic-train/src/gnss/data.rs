//! The GNSS splits laid out like the paper's release: `train.csv`, `valid.csv`, `test.csv`
//! (standardised displacements `ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S, `date`, `sin_date`,
//! `cos_date`), `train_x_mean.csv`, `train_x_scale.csv` (mm), `stations.json` (km) and, when the
//! source's bounds are not the paper's, `bounds.json`. Read and written here. An empty or `NaN`
//! cell is a missing channel (a station down that day).

use super::{GnssProblem, Network, SourceBounds};
use crate::data::table::{read_vector, Table};
use crate::data::{Dataset, Split};
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::Path;

/// `ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S.
pub fn channel_names(names: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    for comp in ["ux", "uy", "uz"] {
        for n in names {
            out.push(format!("{comp}_{n}"));
        }
    }
    out
}

/// Station names in the order of the `ux_` columns of a header.
pub fn station_names_from_header(header: &[String], path: &str) -> Result<Vec<String>> {
    let names: Vec<String> = header
        .iter()
        .filter_map(|h| h.strip_prefix("ux_").map(str::to_string))
        .collect();
    if names.is_empty() {
        bail!("{path}:1: no `ux_<STATION>` columns in the header");
    }
    for comp in ["uy", "uz"] {
        for n in &names {
            if !header.iter().any(|h| *h == format!("{comp}_{n}")) {
                bail!("{path}:1: column `{comp}_{n}` missing (every station needs ux, uy, uz)");
            }
        }
    }
    Ok(names)
}

fn read_split(t: &Table, names: &[String]) -> Result<Split> {
    let cols: Vec<usize> = channel_names(names)
        .iter()
        .map(|c| t.col(c))
        .collect::<Result<_>>()?;
    let date_col = t.col("date").ok();
    let mut split = Split::default();
    for r in 0..t.rows.len() {
        let mut row = Vec::with_capacity(cols.len());
        for &c in &cols {
            row.push(t.num(r, c, true)? as f32);
        }
        split.x.push(row);
        split
            .dates
            .push(date_col.map_or_else(String::new, |c| t.text(r, c).to_string()));
    }
    Ok(split)
}

/// Reads a folder laid out like the paper's `gnss/`.
pub fn read_dir(dir: &Path) -> Result<GnssProblem> {
    let train_t = Table::read(&dir.join("train.csv"), b',')?;
    let names = station_names_from_header(&train_t.header, &train_t.path)?;
    let network = Network::read_json(&dir.join("stations.json"), Some(&names))?;
    let mean = read_vector(&dir.join("train_x_mean.csv"))?;
    let scale = read_vector(&dir.join("train_x_scale.csv"))?;
    let n = 3 * names.len();
    if mean.len() != n || scale.len() != n {
        bail!(
            "{}: mean/scale files must hold {n} values (found {} and {})",
            dir.display(),
            mean.len(),
            scale.len()
        );
    }
    if let Some(i) = scale.iter().position(|s| *s <= 0.0) {
        bail!(
            "{}:{}:1: scale must be positive",
            dir.join("train_x_scale.csv").display(),
            i + 1
        );
    }
    let data = Dataset {
        columns: channel_names(&names),
        mean,
        scale,
        train: read_split(&train_t, &names)?,
        valid: read_split(&Table::read(&dir.join("valid.csv"), b',')?, &names)?,
        test: read_split(&Table::read(&dir.join("test.csv"), b',')?, &names)?,
        source: dir.display().to_string(),
    };
    let source_bounds = SourceBounds::read_dir(dir)?.unwrap_or_default();
    Ok(GnssProblem {
        network,
        data,
        source_bounds,
    })
}

/// Day of year (1-based) of a `YYYY.MM.DD` date; 0 when it does not parse.
pub fn day_of_year(date: &str) -> f64 {
    match magic_core::time::parse_date(date) {
        Some(d) => {
            let (y, _, _) = magic_core::time::civil_from_days(d);
            let jan1 = magic_core::time::days_from_civil(y, 1, 1);
            (d - jan1 + 1) as f64
        }
        None => 0.0,
    }
}

/// Writes a dataset in the release layout (`train.csv`, `valid.csv`, `test.csv`,
/// `train_x_mean.csv`, `train_x_scale.csv`, `stations.json`) and its source bounds
/// (`bounds.json`) when they are not the paper's.
pub fn write_dir(p: &GnssProblem, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let cols = p.network.channel_names();
    for (name, split) in [
        ("train", &p.data.train),
        ("valid", &p.data.valid),
        ("test", &p.data.test),
    ] {
        let path = dir.join(format!("{name}.csv"));
        let mut w = csv::Writer::from_path(&path)
            .with_context(|| format!("{}: cannot write", path.display()))?;
        let mut header = cols.clone();
        header.extend([
            "date".to_string(),
            "sin_date".to_string(),
            "cos_date".to_string(),
        ]);
        w.write_record(&header)?;
        for (row, date) in split.x.iter().zip(&split.dates) {
            let ang = std::f64::consts::TAU * day_of_year(date) / 365.25;
            let mut rec: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            rec.extend([date.clone(), ang.sin().to_string(), ang.cos().to_string()]);
            w.write_record(&rec)?;
        }
        w.flush()?;
    }
    let vec_file = |name: &str, v: &[f64]| -> Result<()> {
        let text: String = v.iter().map(|x| format!("{x}\n")).collect();
        std::fs::write(dir.join(name), text).with_context(|| format!("{name}: cannot write"))
    };
    vec_file("train_x_mean.csv", &p.data.mean)?;
    vec_file("train_x_scale.csv", &p.data.scale)?;
    let mut st = serde_json::Map::new();
    for (n, s) in p.network.names.iter().zip(&p.network.stations) {
        st.insert(n.clone(), json!({"xE": s.x_km, "yN": s.y_km, "zV": s.z_km}));
    }
    std::fs::write(
        dir.join("stations.json"),
        serde_json::to_string_pretty(&st)?,
    )?;
    if p.source_bounds == SourceBounds::paper() {
        // No stale bounds from an earlier dataset in the same folder.
        let stale = dir.join(super::bounds::BOUNDS_FILE);
        if stale.exists() {
            std::fs::remove_file(&stale)
                .with_context(|| format!("{}: cannot remove", stale.display()))?;
        }
        Ok(())
    } else {
        p.source_bounds.write_dir(dir)
    }
}
