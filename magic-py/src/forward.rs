//! The forward models on arrays of parameter rows: Mogi (a GNSS network's displacements),
//! INFORM and PROSAIL (Sentinel-2 bands), in f64, in parallel, GIL released.

use crate::arrays::{float_array, shaped, Rows};
use crate::errors;
use crate::parallel::{install, map_rows, OnError};
use crate::tables::Tables;
use magic_core::mogi::{self, Station};
use magic_core::rtm::prosail::{self, Prosail};
use magic_core::rtm::{Geometry, Inform, INPUT_NAMES, N_BANDS, N_INPUTS};
use magic_core::Error;
use numpy::{PyArrayDyn, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// Runs `f` over the rows of `params` (the last axis `width` values named `names`) without the
/// GIL: an array shaped `params.shape[:-1] + tail`.
fn run<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    names: &[String],
    tail: &[usize],
    errors: &str,
    threads: Option<usize>,
    f: impl Fn(&[f64], &mut [f64]) -> Result<(), Error> + Sync + Send,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let on_error = OnError::parse(errors)?;
    let arr = float_array("params", params)?;
    let rows: Rows<'_> = arr.rows("params", names.len(), names)?;
    let out_width = tail.iter().product();
    let out = py.detach(|| install(threads, || map_rows(&rows, out_width, on_error, &f)))?;
    let out = out.map_err(|(row, e)| {
        errors::value(format!("params{}", errors::row_index(&rows.shape, row)), e)
    })?;
    shaped(py, &rows.shape, tail, out)
}

fn names(n: &[&str]) -> Vec<String> {
    n.iter().map(|s| s.to_string()).collect()
}

/// Mogi displacements: `params` `(..., 4)` (x_km, y_km, depth_km, dv_1e6m3), `stations`
/// `(S, 3)` (east, north, elevation in km) → `(..., 3 S)` mm (east ×S, north ×S, up ×S).
#[pyfunction]
#[pyo3(signature = (params, stations, errors="raise", threads=None))]
pub fn mogi_forward<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    stations: PyReadonlyArray2<'py, f64>,
    errors: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let s = stations.shape();
    if s[1] != 3 || s[0] == 0 {
        return Err(errors::value(
            "stations",
            format!("shape {s:?}; expected (n_stations, 3): east, north, elevation (km)"),
        ));
    }
    let net: Vec<Station> = stations
        .as_array()
        .rows()
        .into_iter()
        .map(|r| Station {
            x_km: r[0],
            y_km: r[1],
            z_km: r[2],
        })
        .collect();
    if let Some(i) = net
        .iter()
        .position(|st| !(st.x_km.is_finite() && st.y_km.is_finite() && st.z_km.is_finite()))
    {
        return Err(errors::value(
            format!("stations[{i}]"),
            "not a finite position",
        ));
    }
    let n_out = 3 * net.len();
    run(
        py,
        params,
        &names(&mogi::PARAM_NAMES),
        &[n_out],
        errors,
        threads,
        move |x, y| {
            let p: [f64; mogi::N_PARAMS] = [x[0], x[1], x[2], x[3]];
            if let Some(index) = p.iter().position(|v| !v.is_finite()) {
                return Err(Error::NonFinite {
                    what: "mogi parameter",
                    index,
                });
            }
            mogi::field(&net, &p, y)
        },
    )
}

/// INFORM in the 13 Sentinel-2 bands: `params` `(..., 21)` (`INFORM_INPUTS`) → `(..., 13)`.
#[pyfunction]
#[pyo3(signature = (params, tables, geometry="physical", errors="raise", threads=None))]
pub fn inform_forward<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    tables: &Tables,
    geometry: &str,
    errors: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let geometry = match geometry {
        "physical" => Geometry::Physical,
        "reference" => Geometry::Reference,
        other => {
            return Err(errors::value(
                "geometry",
                format!("`{other}`: expected \"physical\" or \"reference\""),
            ))
        }
    };
    let data = tables.shared();
    let model = Inform::new(data.tables()).map_err(|e| errors::value("tables", e))?;
    run(
        py,
        params,
        &names(&INPUT_NAMES),
        &[N_BANDS],
        errors,
        threads,
        move |x, y| {
            let x: [f64; N_INPUTS] = core::array::from_fn(|i| x[i]);
            y.copy_from_slice(&model.forward(&x, geometry)?);
            Ok(())
        },
    )
}

/// PROSAIL (PROSPECT-D + 4SAIL): `params` `(..., 14)` (`PROSAIL_INPUTS`) → `(..., 4, 13)`, the
/// reflectance factors rsot, rdot, rsdt, rddt in the 13 Sentinel-2 bands.
#[pyfunction]
#[pyo3(signature = (params, tables, errors="raise", threads=None))]
pub fn prosail_forward<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    tables: &Tables,
    errors: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let data = tables.shared();
    let core = data.tables();
    let model = Prosail::new(&core).map_err(|e| errors::value("tables", e))?;
    run(
        py,
        params,
        &names(&prosail::INPUT_NAMES),
        &[prosail::N_FACTORS, N_BANDS],
        errors,
        threads,
        move |x, y| {
            let x: [f64; prosail::N_INPUTS] = core::array::from_fn(|i| x[i]);
            for (o, f) in y.chunks_mut(N_BANDS).zip(model.forward(&x)?) {
                o.copy_from_slice(&f);
            }
            Ok(())
        },
    )
}
