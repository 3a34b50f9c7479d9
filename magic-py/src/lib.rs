//! # magic-py
//!
//! The native part of the Python package `magic` (module `magic._magic`): model files and their
//! inversion, the forward models (Mogi, INFORM, PROSAIL) and the spectral tables, on NumPy arrays
//! of any leading shape, computed by `magic-core` in f64 on every core with the GIL released.
//! The Python layer (`python/magic`) adds argument handling (dates, station files), the
//! `magic.xarray` helper, type stubs and documentation.

#![deny(missing_docs)]

mod arrays;
mod errors;
mod forward;
mod host;
mod model;
mod parallel;
mod tables;

use pyo3::prelude::*;

/// The native module.
#[pymodule]
fn _magic(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<model::Model>()?;
    m.add_class::<tables::Tables>()?;
    m.add_function(wrap_pyfunction!(forward::mogi_forward, m)?)?;
    m.add_function(wrap_pyfunction!(forward::inform_forward, m)?)?;
    m.add_function(wrap_pyfunction!(forward::prosail_forward, m)?)?;
    m.add("S2_BANDS", magic_core::rtm::S2_BANDS.to_vec())?;
    m.add("INFORM_INPUTS", magic_core::rtm::INPUT_NAMES.to_vec())?;
    m.add(
        "PROSAIL_INPUTS",
        magic_core::rtm::prosail::INPUT_NAMES.to_vec(),
    )?;
    m.add(
        "PROSAIL_FACTORS",
        magic_core::rtm::prosail::FACTOR_NAMES.to_vec(),
    )?;
    m.add("MOGI_PARAMS", magic_core::mogi::PARAM_NAMES.to_vec())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
