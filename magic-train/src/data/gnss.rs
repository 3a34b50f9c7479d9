//! The GNSS splits laid out like the paper's release: `train.csv`, `valid.csv`, `test.csv`
//! (standardised displacements, `date`, `sin_date`, `cos_date`), `train_x_mean.csv`,
//! `train_x_scale.csv` (mm) and `stations.json` (km).

use super::table::{read_vector, Table};
use anyhow::{bail, Context, Result};
use magic_core::mogi::Station;
use std::path::Path;

/// One split: standardised observations and their dates.
#[derive(Clone, Debug, Default)]
pub struct Split {
    /// Rows of 3 × stations standardised values.
    pub x: Vec<Vec<f32>>,
    /// Dates as written in the file (`YYYY.MM.DD`).
    pub dates: Vec<String>,
}

/// Day number (days since 1970-01-01) of a date as written in the data files; NaN if malformed.
pub fn day_number(date: &str) -> f64 {
    magic_core::time::parse_date(date).map_or(f64::NAN, |d| d as f64)
}

impl Split {
    /// Number of days.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// Day numbers of the rows (NaN where the date is missing or malformed).
    pub fn days(&self) -> Vec<f64> {
        self.dates.iter().map(|d| day_number(d)).collect()
    }
}

/// A GNSS dataset: network, standardisation and the three splits.
#[derive(Clone, Debug)]
pub struct GnssData {
    /// Station names in channel order.
    pub names: Vec<String>,
    /// Station positions in channel order.
    pub stations: Vec<Station>,
    /// Channel mean (mm).
    pub mean: Vec<f64>,
    /// Channel scale (mm).
    pub scale: Vec<f64>,
    /// Training split.
    pub train: Split,
    /// Validation split.
    pub valid: Split,
    /// Test split.
    pub test: Split,
    /// Where it came from (a folder, or "synthetic").
    pub source: String,
}

impl GnssData {
    /// Channel names: `ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S.
    pub fn channel_names(&self) -> Vec<String> {
        channel_names(&self.names)
    }

    /// Number of channels.
    pub fn n_obs(&self) -> usize {
        3 * self.names.len()
    }

    /// A split by name.
    pub fn split(&self, name: &str) -> Result<&Split> {
        match name {
            "train" => Ok(&self.train),
            "valid" => Ok(&self.valid),
            "test" => Ok(&self.test),
            _ => bail!("unknown split `{name}` (expected train, valid or test)"),
        }
    }

    /// Physical (mm) value of standardised channel `c`.
    pub fn to_mm(&self, c: usize, v: f64) -> f64 {
        v * self.scale[c] + self.mean[c]
    }

    /// Reads a folder laid out like the paper's `gnss/`.
    pub fn read(dir: &Path) -> Result<GnssData> {
        let st_path = dir.join("stations.json");
        let text = std::fs::read_to_string(&st_path)
            .with_context(|| format!("{}: cannot read", st_path.display()))?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not valid JSON", st_path.display()))?;
        let obj = json
            .as_object()
            .with_context(|| format!("{}: expected an object of stations", st_path.display()))?;

        let train_t = Table::read(&dir.join("train.csv"), b',')?;
        let names = station_names_from_header(&train_t.header, &train_t.path)?;
        let mut stations = Vec::new();
        for n in &names {
            let s = obj.get(n).with_context(|| {
                format!(
                    "{}: station {n} (from the CSV header) is missing",
                    st_path.display()
                )
            })?;
            let get = |k: &str| {
                s.get(k).and_then(|v| v.as_f64()).with_context(|| {
                    format!(
                        "{}: station {n}: `{k}` missing or not a number",
                        st_path.display()
                    )
                })
            };
            stations.push(Station {
                x_km: get("xE")?,
                y_km: get("yN")?,
                z_km: get("zV")?,
            });
        }
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
        let train = read_split(&train_t, &names)?;
        let valid = read_split(&Table::read(&dir.join("valid.csv"), b',')?, &names)?;
        let test = read_split(&Table::read(&dir.join("test.csv"), b',')?, &names)?;
        Ok(GnssData {
            names,
            stations,
            mean,
            scale,
            train,
            valid,
            test,
            source: dir.display().to_string(),
        })
    }
}

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
            row.push(t.num(r, c, false)? as f32);
        }
        split.x.push(row);
        split
            .dates
            .push(date_col.map_or_else(String::new, |c| t.text(r, c).to_string()));
    }
    Ok(split)
}
