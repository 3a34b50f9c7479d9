//! `magic.Tables`: the spectral tables INFORM and PROSAIL run on (PROSPECT-D coefficients, soil
//! and solar spectra, leaf-angle table, Sentinel-2 resampling matrix), read once and shared.

use crate::errors;
use crate::host::{self, TableData, TablesError};
use magic_core::rtm::Tables as CoreTables;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use std::path::PathBuf;
use std::sync::Arc;

/// The spectral tables (the `rtm/` folder of the data: 1 nm, 400–2500 nm).
///
/// `Tables.load(dir)` reads them; a missing file raises `OSError` (`FileNotFoundError`) naming it,
/// a malformed one `ValueError` naming file, line and column. Tables can be pickled (they travel
/// to Dask workers as their values).
#[pyclass(module = "magic", frozen)]
pub struct Tables {
    data: Arc<TableData>,
}

impl Tables {
    /// The core's view of the tables.
    pub fn core(&self) -> CoreTables<'_> {
        self.data.tables()
    }

    /// The shared tables (to hand to a thread without the GIL).
    pub fn shared(&self) -> Arc<TableData> {
        self.data.clone()
    }
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn from_bytes(what: &str, b: &[u8]) -> PyResult<Vec<f64>> {
    let values = b.chunks_exact(8);
    if !values.remainder().is_empty() {
        return Err(errors::value(what, "not a whole number of float64 values"));
    }
    Ok(values
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect())
}

#[pymethods]
impl Tables {
    /// Reads the tables from the folder `dir` (`prospect_d_coefficients.csv`, `soil_spectra.csv`,
    /// `solar_spectra.csv`, `lidf_tables.csv`, `sentinel2_full_resampling_matrix.csv`).
    #[staticmethod]
    fn load(py: Python<'_>, dir: PathBuf) -> PyResult<Self> {
        let data = py.detach(|| host::read_tables(&dir)).map_err(|e| match e {
            TablesError::Io(p, e) => errors::io(&p, &e),
            TablesError::Invalid(msg) => errors::value("tables", msg),
        })?;
        Ok(Tables {
            data: Arc::new(data),
        })
    }

    /// The folder the tables were read from.
    #[getter]
    fn dir(&self) -> PathBuf {
        self.data.dir.clone()
    }

    /// Number of wavelengths.
    fn __len__(&self) -> usize {
        self.data.wl.len()
    }

    /// Rebuilds tables from their pickled values.
    #[staticmethod]
    fn _from_parts(dir: PathBuf, parts: Vec<Vec<u8>>) -> PyResult<Self> {
        let mut cols = parts
            .iter()
            .map(|b| from_bytes("pickled tables", b))
            .collect::<PyResult<Vec<_>>>()?;
        if cols.len() != 16 {
            return Err(errors::value(
                "pickled tables",
                format!("{} parts, expected 16", cols.len()),
            ));
        }
        let mut take = || cols.remove(0);
        let wl = take();
        let prospect = (0..9).map(|_| take()).collect();
        let (soil_dry, soil_wet, es, ed) = (take(), take(), take(), take());
        let (lidf_beta, resampling) = (take(), take());
        let data = host::tables_from_parts(
            dir, wl, prospect, soil_dry, soil_wet, es, ed, lidf_beta, resampling,
        )
        .map_err(|e| errors::value("pickled tables", e))?;
        Ok(Tables {
            data: Arc::new(data),
        })
    }

    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let (dir, parts) = host::table_parts(&self.data);
        let parts: Vec<Bound<'py, PyBytes>> = parts
            .iter()
            .map(|p| PyBytes::new(py, &f64_bytes(p)))
            .collect();
        let f = py.get_type::<Tables>().getattr("_from_parts")?;
        let args = (dir.to_path_buf(), parts).into_pyobject(py)?;
        PyTuple::new(py, [f, args.into_any()])
    }

    fn __repr__(&self) -> String {
        format!(
            "<magic.Tables {} wavelengths from {}>",
            self.data.wl.len(),
            self.data.dir.display()
        )
    }
}
