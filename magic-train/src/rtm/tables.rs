//! The INFORM tables (`shared/data/rtm` layout) in f64, the rows a set of observed bands needs,
//! and the RTM problem description a model file carries.
//!
//! Files, all comma-separated with a header (1 nm, 400–2500 nm):
//! `prospect_d_coefficients.csv`, `soil_spectra.csv`, `solar_spectra.csv`, `lidf_tables.csv`,
//! `sentinel2_full_resampling_matrix.csv`. Columns are looked up by name; every wavelength
//! column must list the same grid.

use crate::data::table::Table;
use anyhow::{bail, Context, Result};
use magic_core::model_file::Problem;
use magic_core::quant::LeF32;
use magic_core::rtm::bands::{Packed, ROW_WIDTH};
use magic_core::rtm::prospect::Coefficients;
use magic_core::rtm::{Fixed, Geometry, Inform, Tables, N_BANDS, S2_BANDS};
use std::path::{Path, PathBuf};

/// The 11 bands of the S2 dataset (no B01, no B10), as indices into [`S2_BANDS`].
pub const S2_DATA_BANDS: [usize; 11] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12];

/// The PROSPECT-D columns, in [`Coefficients`] order.
const PROSPECT_COLS: [&str; 9] = [
    "nr", "k_cab", "k_car", "k_anth", "k_brown", "k_cw", "k_cm", "t12", "tav90n",
];

/// The tables in f64, owned.
#[derive(Clone, Debug)]
pub struct RtmTables {
    /// Folder read from.
    pub dir: PathBuf,
    /// Wavelengths (nm).
    pub wl: Vec<f64>,
    /// PROSPECT-D columns (see `PROSPECT_COLS`).
    pub prospect: [Vec<f64>; 9],
    /// Dry soil.
    pub soil_dry: Vec<f64>,
    /// Wet soil.
    pub soil_wet: Vec<f64>,
    /// Direct irradiance.
    pub es: Vec<f64>,
    /// Diffuse irradiance.
    pub ed: Vec<f64>,
    /// Beta leaf-angle table, 13 angles × 6 rows, angle-major.
    pub lidf_beta: Vec<f64>,
    /// Resampling matrix, wavelengths × 13 bands, row-major.
    pub resampling: Vec<f64>,
}

/// Finds the tables folder: `--tables`, else `$MAGIC_DATA/rtm`, else `../shared/data/rtm`.
pub fn locate(explicit: Option<&Path>) -> Result<PathBuf> {
    crate::data::locate(explicit, "rtm")
        .context("no RTM tables: pass --tables, set MAGIC_DATA, or run next to shared/data")
}

fn column(t: &Table, name: &str) -> Result<Vec<f64>> {
    let c = t.col(name)?;
    (0..t.rows.len()).map(|r| t.num(r, c, false)).collect()
}

fn same_grid(t: &Table, wl: &[f64]) -> Result<()> {
    let w = column(t, "wl")?;
    if w.len() != wl.len() {
        bail!(
            "{}: {} wavelengths, the PROSPECT-D table has {}",
            t.path,
            w.len(),
            wl.len()
        );
    }
    if let Some(r) = w.iter().zip(wl).position(|(a, b)| a != b) {
        bail!(
            "{}:{}: wavelength {} differs from the PROSPECT-D table's {}",
            t.path,
            t.line(r),
            w[r],
            wl[r]
        );
    }
    Ok(())
}

impl RtmTables {
    /// Reads the tables from `dir`.
    pub fn read(dir: &Path) -> Result<RtmTables> {
        let p = Table::read(&dir.join("prospect_d_coefficients.csv"), b',')?;
        let wl = column(&p, "wl")?;
        let [nr, cab, car, anth, brown, cw, cm, t12, t90] = PROSPECT_COLS.map(|c| column(&p, c));
        let prospect = [nr?, cab?, car?, anth?, brown?, cw?, cm?, t12?, t90?];
        let soil = Table::read(&dir.join("soil_spectra.csv"), b',')?;
        same_grid(&soil, &wl)?;
        let sun = Table::read(&dir.join("solar_spectra.csv"), b',')?;
        same_grid(&sun, &wl)?;
        let m = Table::read(&dir.join("sentinel2_full_resampling_matrix.csv"), b',')?;
        same_grid(&m, &wl)?;
        let cols = S2_BANDS
            .iter()
            .map(|b| column(&m, b))
            .collect::<Result<Vec<_>>>()?;
        let resampling = (0..wl.len())
            .flat_map(|i| cols.iter().map(move |c| c[i]))
            .collect();
        let lidf = Table::read(&dir.join("lidf_tables.csv"), b',')?;
        if lidf.rows.len() != 13 {
            bail!(
                "{}: expected 13 leaf-angle rows, found {}",
                lidf.path,
                lidf.rows.len()
            );
        }
        let beta_cols: Vec<Vec<f64>> = (0..6)
            .map(|k| column(&lidf, &format!("beta_{k}")))
            .collect::<Result<_>>()?;
        let lidf_beta = (0..13)
            .flat_map(|a| beta_cols.iter().map(move |c| c[a]))
            .collect();
        let t = RtmTables {
            dir: dir.to_path_buf(),
            wl,
            prospect,
            soil_dry: column(&soil, "Rsoil1_dry")?,
            soil_wet: column(&soil, "Rsoil2_wet")?,
            es: column(&sun, "Es_direct")?,
            ed: column(&sun, "Ed_diffuse")?,
            lidf_beta,
            resampling,
        };
        t.inform()
            .map_err(|e| anyhow::anyhow!("{}: inconsistent tables: {e}", dir.display()))?;
        Ok(t)
    }

    /// The core's view of the tables.
    pub fn tables(&self) -> Tables<'_> {
        let c = &self.prospect;
        Tables {
            prospect: Coefficients::from_columns(c),
            soil_dry: &self.soil_dry,
            soil_wet: &self.soil_wet,
            es: &self.es,
            ed: &self.ed,
            lidf_beta: &self.lidf_beta,
            resampling: &self.resampling,
        }
    }

    /// The full 13-band model over the f64 tables.
    pub fn inform(&self) -> Result<Inform<'_>, magic_core::Error> {
        Inform::new(self.tables())
    }

    /// The rows the bands `bands` (indices into [`S2_BANDS`], ascending) need.
    pub fn pack(&self, bands: &[usize]) -> Result<PackedRows> {
        if bands.is_empty()
            || bands.windows(2).any(|w| w[0] >= w[1])
            || bands.iter().any(|&b| b >= N_BANDS)
        {
            bail!("observed bands must be distinct band indices below {N_BANDS}, ascending");
        }
        let mut spectral = Vec::new();
        let mut weights = Vec::new();
        for i in 0..self.wl.len() {
            let w: Vec<f64> = bands
                .iter()
                .map(|&b| self.resampling[i * N_BANDS + b])
                .collect();
            if w.iter().all(|&x| x == 0.0) {
                continue;
            }
            spectral.extend(self.prospect.iter().map(|c| c[i]));
            spectral.extend([self.soil_dry[i], self.soil_wet[i], self.es[i], self.ed[i]]);
            weights.extend(w);
        }
        debug_assert_eq!(spectral.len() % ROW_WIDTH, 0);
        Ok(PackedRows {
            bands: bands.to_vec(),
            spectral,
            weights,
            lidf_beta: self.lidf_beta.clone(),
        })
    }
}

/// The rows of a set of observed bands in f64 (what the trainer differentiates through; the
/// model file carries the same rows in f32).
#[derive(Clone, Debug)]
pub struct PackedRows {
    /// Observed bands (indices into [`S2_BANDS`]).
    pub bands: Vec<usize>,
    /// Spectral rows.
    pub spectral: Vec<f64>,
    /// Band weights.
    pub weights: Vec<f64>,
    /// Beta leaf-angle table.
    pub lidf_beta: Vec<f64>,
}

impl PackedRows {
    /// The core's model over these rows.
    pub fn model(&self) -> Result<Packed<&[f64]>, magic_core::Error> {
        Packed::new(
            &self.spectral[..],
            &self.weights[..],
            &self.lidf_beta[..],
            self.bands.len(),
        )
    }

    /// Band mask of the model file.
    pub fn mask(&self) -> u16 {
        self.bands.iter().fold(0, |m, b| m | 1 << b)
    }

    /// The model-file problem: these rows rounded to f32 (interned: see [`intern`](crate::model::intern)).
    pub fn problem(&self, fixed: Fixed, geometry: Geometry) -> Problem<'static> {
        Problem::Rtm {
            geometry,
            fixed,
            bands: self.mask(),
            spectral: LeF32(crate::model::intern(f32_bytes(&self.spectral))),
            weights: LeF32(crate::model::intern(f32_bytes(&self.weights))),
            lidf_beta: LeF32(crate::model::intern(f32_bytes(&self.lidf_beta))),
        }
    }
}

fn f32_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| (*x as f32).to_le_bytes()).collect()
}
