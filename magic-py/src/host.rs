//! What the bindings take from the host crate (`magic-train`), in one place: the names of a
//! model's input channels and result columns (exactly those `magic invert` reads and writes),
//! and the reader of the spectral tables.

use magic_core::Model;
use magic_train::data::records;
use magic_train::RtmTables;

use std::path::{Path, PathBuf};

/// The spectral tables, owned, in f64 (the `rtm/` folder of the data).
pub type TableData = RtmTables;

/// The input channels of `model` in order: `ux_<STA>`, …, `uz_<STA>` for a GNSS network, band
/// names (`B02`, …) for a forest model.
pub fn input_names(model: &Model<'_>) -> Result<Vec<String>, String> {
    records::model_channels(model).map_err(|e| e.to_string())
}

/// The result columns `magic invert` writes for `model` (no `date`).
pub fn output_names(model: &Model<'_>) -> Vec<String> {
    records::result_columns(model)
}

/// Why tables could not be read.
pub enum TablesError {
    /// A file could not be opened.
    Io(PathBuf, std::io::Error),
    /// A file could be read but is not a valid table (message names file, line, column).
    Invalid(String),
}

/// The file names of the tables in their folder.
pub const TABLE_FILES: [&str; 5] = [
    "prospect_d_coefficients.csv",
    "soil_spectra.csv",
    "solar_spectra.csv",
    "lidf_tables.csv",
    "sentinel2_full_resampling_matrix.csv",
];

/// Reads the tables from `dir`.
pub fn read_tables(dir: &Path) -> Result<TableData, TablesError> {
    for f in TABLE_FILES {
        let p = dir.join(f);
        if let Err(e) = std::fs::File::open(&p) {
            return Err(TablesError::Io(p, e));
        }
    }
    RtmTables::read(dir).map_err(|e| TablesError::Invalid(format!("{e:#}")))
}

/// Tables from their parts (as [`TableData`]'s fields), checked as [`read_tables`] checks them.
#[allow(clippy::too_many_arguments)]
pub fn tables_from_parts(
    dir: PathBuf,
    wl: Vec<f64>,
    prospect: Vec<Vec<f64>>,
    soil_dry: Vec<f64>,
    soil_wet: Vec<f64>,
    es: Vec<f64>,
    ed: Vec<f64>,
    lidf_beta: Vec<f64>,
    resampling: Vec<f64>,
) -> Result<TableData, String> {
    let n = prospect.len();
    let prospect: [Vec<f64>; 9] = prospect
        .try_into()
        .map_err(|_| format!("expected 9 PROSPECT columns, found {n}"))?;
    let t = RtmTables {
        dir,
        wl,
        prospect,
        soil_dry,
        soil_wet,
        es,
        ed,
        lidf_beta,
        resampling,
    };
    if t.prospect.len() != 9 {
        return Err(format!(
            "{} PROSPECT-D columns, expected 9",
            t.prospect.len()
        ));
    }
    t.inform().map_err(|e| e.to_string())?;
    Ok(t)
}

/// The parts of `t` in the order [`tables_from_parts`] takes them (the wavelengths, the 9
/// PROSPECT-D columns, the soils, the irradiances, the beta table, the resampling matrix).
pub fn table_parts(t: &TableData) -> (&Path, Vec<&[f64]>) {
    let mut parts: Vec<&[f64]> = vec![&t.wl];
    parts.extend(t.prospect.iter().map(|c| c.as_slice()));
    parts.extend([
        t.soil_dry.as_slice(),
        &t.soil_wet,
        &t.es,
        &t.ed,
        &t.lidf_beta,
        &t.resampling,
    ]);
    (&t.dir, parts)
}
