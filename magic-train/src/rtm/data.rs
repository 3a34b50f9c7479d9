//! The Sentinel-2 forest spectra laid out like the paper's release: `train.csv`, `valid.csv`,
//! `test.csv` (11 standardised bands `B02_BLUE … B12_SWI2`, then `class`, `sample_id`, `date`),
//! `train_x_mean.csv`, `train_x_scale.csv` (reflectance); and the site extract
//! `BPWW_extract_2018.csv` with the SNAP LAI.

use super::tables::S2_DATA_BANDS;
use crate::data::table::{read_vector, Table};
use crate::data::{Dataset, Split};
use anyhow::{bail, Context, Result};
use magic_core::rtm::S2_BANDS;
use std::collections::HashMap;
use std::path::Path;

/// Index of the column of band `band` (`B02` matches `B02` or `B02_<anything>`).
pub fn band_column(t: &Table, band: &str) -> Result<usize> {
    let prefix = format!("{band}_");
    t.header
        .iter()
        .position(|h| h == band || h.starts_with(&prefix))
        .with_context(|| {
            format!(
                "{}:1: no column for band {band} (`{band}` or `{band}_…`)",
                t.path
            )
        })
}

/// Reads a folder laid out like the paper's `s2/`: per split the 11 standardised bands, the
/// species (`labels`) and site (`ids`) of every spectrum, and its date.
pub fn read_dir(dir: &Path) -> Result<Dataset> {
    let mean = read_vector(&dir.join("train_x_mean.csv"))?;
    let scale = read_vector(&dir.join("train_x_scale.csv"))?;
    let n = S2_DATA_BANDS.len();
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
    let train_t = Table::read(&dir.join("train.csv"), b',')?;
    let cols: Vec<usize> = S2_DATA_BANDS
        .iter()
        .map(|&b| band_column(&train_t, S2_BANDS[b]))
        .collect::<Result<_>>()?;
    let columns = cols.iter().map(|&c| train_t.header[c].clone()).collect();
    let train = read_split(&train_t)?;
    let valid = read_split(&Table::read(&dir.join("valid.csv"), b',')?)?;
    let test = read_split(&Table::read(&dir.join("test.csv"), b',')?)?;
    Ok(Dataset {
        columns,
        mean,
        scale,
        train,
        valid,
        test,
        source: dir.display().to_string(),
    })
}

fn read_split(t: &Table) -> Result<Split> {
    let cols: Vec<usize> = S2_DATA_BANDS
        .iter()
        .map(|&b| band_column(t, S2_BANDS[b]))
        .collect::<Result<_>>()?;
    let (class, id, date) = (t.col("class")?, t.col("sample_id")?, t.col("date")?);
    let mut s = Split::default();
    for r in 0..t.rows.len() {
        let row = cols
            .iter()
            .map(|&c| t.num(r, c, false).map(|v| v as f32))
            .collect::<Result<Vec<_>>>()?;
        let sid = t.num(r, id, false)?;
        if sid < 0.0 || sid.fract() != 0.0 {
            bail!(
                "{}: column `sample_id`: expected a non-negative integer, found `{}`",
                t.at(r, id),
                t.text(r, id)
            );
        }
        let d = t.text(r, date);
        if magic_core::time::parse_date(d).is_none() {
            bail!(
                "{}: column `date`: expected YYYY.MM.DD, found `{d}`",
                t.at(r, date)
            );
        }
        s.x.push(row);
        s.dates.push(d.to_string());
        s.labels.push(t.text(r, class).to_string());
        s.ids.push(sid as u64);
    }
    Ok(s)
}

/// The site extract: per site (row, 0-based = `sample_id`) and date, 11 bands (reflectance ×
/// 10 000), FAPAR and LAI (× 1000) from the SNAP biophysical processor, and the species.
#[derive(Clone, Debug)]
pub struct Extract {
    /// Dates in column order (`YYYY.MM.DD`).
    pub dates: Vec<String>,
    /// Species per site.
    pub class: Vec<String>,
    /// `(site, date)` → 11 band reflectances (not scaled: × 10 000 as in the file).
    pub bands: HashMap<(u64, String), [f64; 11]>,
    /// `(site, date)` → SNAP LAI (× 1000 as in the file).
    pub lai: HashMap<(u64, String), f64>,
}

impl Extract {
    /// Reads `BPWW_extract_2018.csv` (`;`-separated; columns `<date>_<band>`, `<date>_FAPAR`,
    /// `<date>_LAI`, `class`). Empty or non-numeric cells are skipped (no entry).
    pub fn read(path: &Path) -> Result<Extract> {
        let t = Table::read(path, b';')?;
        let class_c = t.col("class")?;
        let mut dates: Vec<String> = Vec::new();
        for h in &t.header {
            if let Some(d) = h.strip_suffix("_LAI") {
                dates.push(d.to_string());
            }
        }
        let mut bands = HashMap::new();
        let mut lai = HashMap::new();
        let band_names = [
            "B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B11", "B12",
        ];
        for d in &dates {
            let bc: Vec<usize> = band_names
                .iter()
                .map(|b| {
                    let p = format!("{d}_{b}");
                    t.header
                        .iter()
                        .position(|h| h == &p || h.starts_with(&format!("{p}_")))
                        .with_context(|| format!("{}:1: no column {p}", t.path))
                })
                .collect::<Result<_>>()?;
            let lc = t.col(&format!("{d}_LAI"))?;
            for r in 0..t.rows.len() {
                let site = r as u64;
                let vals: Vec<f64> = bc
                    .iter()
                    .filter_map(|&c| t.text(r, c).parse::<f64>().ok())
                    .collect();
                if vals.len() == 11 {
                    let mut a = [0.0; 11];
                    a.copy_from_slice(&vals);
                    bands.insert((site, d.clone()), a);
                }
                if let Ok(v) = t.text(r, lc).parse::<f64>() {
                    lai.insert((site, d.clone()), v);
                }
            }
        }
        let class = (0..t.rows.len())
            .map(|r| t.text(r, class_c).to_string())
            .collect();
        Ok(Extract {
            dates,
            class,
            bands,
            lai,
        })
    }
}
