//! `magic.Model`: a model file (GNSS volcano source or forest spectra), and its inversion of
//! observation arrays on every core with the GIL released.
//!
//! Each row goes through `magic_core::invert_at::<f64>` exactly as `magic invert` runs it (the
//! same decoded model, the observations rounded to f32 as the CLI reads them, the date as a day
//! number), so the numbers are the CLI's.

use crate::arrays::{float_array, shaped};
use crate::errors;
use crate::host;
use crate::parallel::{install, FirstError, OnError, BLOCK};
use magic_core::model_file::{Problem, MAX_OBS};
use magic_core::uncertainty::{standard_deviations, SdWorkspace};
use magic_core::{invert_at, Model as CoreModel, Variant, Workspace};
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// A trained model file (`magic train` / `magic export`): observations to physical variables.
///
/// Load with `Model.load(path)` or `Model.from_bytes(data)`; corrupt, truncated or foreign
/// bytes raise `ValueError` with the core's reason. Properties: `problem` (`"mogi"` or `"rtm"`),
/// `variant` (`"A"`, `"B"`, `"C"`), `inputs` (channel or band names: the last axis of `obs`),
/// `outputs` (the result columns of `magic invert`), `bounds` (`{name: (min, max)}`),
/// `needs_time`. A model is immutable and pickles as its bytes, so it travels to Dask workers.
#[pyclass(module = "magic", frozen)]
pub struct Model {
    bytes: Arc<[u8]>,
    problem: &'static str,
    variant: Variant,
    inputs: Vec<String>,
    outputs: Vec<String>,
    bounds: Vec<(String, f64, f64)>,
    needs_time: bool,
}

impl Model {
    fn new(bytes: Arc<[u8]>, origin: &str) -> PyResult<Self> {
        let m = CoreModel::decode(&bytes).map_err(|e| errors::value(origin, e))?;
        let inputs = host::input_names(&m).map_err(|e| errors::value(origin, e))?;
        let outputs = host::output_names(&m);
        let n_vars = outputs.len() - 3;
        if inputs.len() != m.n_obs() || n_vars < m.n_params() {
            return Err(errors::value(
                origin,
                "the model's channels or variables do not match its description",
            ));
        }
        let bounds = match m.variant {
            Variant::A => Vec::new(),
            _ => outputs
                .iter()
                .zip(&m.bounds)
                .map(|(n, b)| (n.clone(), b[0] as f64, b[1] as f64))
                .collect(),
        };
        let problem = match m.problem {
            Problem::Mogi { .. } => "mogi",
            Problem::Rtm { .. } => "rtm",
        };
        Ok(Model {
            problem,
            variant: m.variant,
            inputs,
            outputs,
            bounds,
            needs_time: m.needs_time(),
            bytes: bytes.clone(),
        })
    }
}

/// Results of a batch: the variables and residual (row after row), flags and station masks.
struct Batch {
    floats: Vec<f64>,
    flags: Vec<u8>,
    used: Vec<u32>,
}

/// Inverts `n` rows read by `row(i, buf)` with day numbers `days` (NaN: unknown). Each row's
/// floats are its `n_floats` variables and residual, then, with `n_sd > 0`, the standard
/// deviations of its first `n_sd` variables (NaN where they cannot be computed).
fn invert_batch(
    model: &CoreModel<'_>,
    n: usize,
    (n_floats, n_sd): (usize, usize),
    row: impl Fn(usize, &mut [f32]) + Sync,
    days: Option<&[f64]>,
    on_error: OnError,
) -> Result<Batch, (usize, magic_core::Error)> {
    let width = n_floats + n_sd;
    let n_obs = model.n_obs();
    let mut b = Batch {
        floats: vec![0.0; n * width],
        flags: vec![0; n],
        used: vec![0; n],
    };
    if n == 0 {
        return Ok(b);
    }
    let first = FirstError::default();
    b.floats
        .par_chunks_mut(BLOCK * width)
        .zip(b.flags.par_chunks_mut(BLOCK))
        .zip(b.used.par_chunks_mut(BLOCK))
        .enumerate()
        .for_each_init(
            || (Workspace::default(), SdWorkspace::default()),
            |(ws, sw), (k, ((fl, fg), us))| {
                let mut obs = [0f32; MAX_OBS];
                let obs = &mut obs[..n_obs.min(MAX_OBS)];
                for (j, ((y, f), u)) in fl
                    .chunks_mut(width)
                    .zip(fg.iter_mut())
                    .zip(us.iter_mut())
                    .enumerate()
                {
                    let i = k * BLOCK + j;
                    if on_error == OnError::Raise && first.before(i) {
                        return;
                    }
                    row(i, obs);
                    let day = days.map_or(f64::NAN, |d| d[i]);
                    match invert_at::<f64>(model, obs, day, ws) {
                        Ok(inv) => {
                            let (y, s) = y.split_at_mut(n_floats);
                            let np = inv.n_params.min(n_floats - 1);
                            y[..np].copy_from_slice(&inv.params[..np]);
                            y[np..].fill(f64::NAN);
                            y[n_floats - 1] = inv.residual_rms;
                            *f = inv.flags.0;
                            *u = inv.used;
                            s.fill(f64::NAN);
                            if n_sd > 0 {
                                if let Ok(sd) = standard_deviations(model, obs, &inv, day, sw) {
                                    let m = sd.n_params.min(n_sd);
                                    s[..m].copy_from_slice(&sd.sd[..m]);
                                }
                            }
                        }
                        Err(e) => match on_error {
                            OnError::Raise => {
                                first.record(i, e);
                                return;
                            }
                            OnError::Nan => {
                                y.fill(f64::NAN);
                                (*f, *u) = (0, 0);
                            }
                        },
                    }
                }
            },
        );
    match first.take() {
        Some(e) => Err(e),
        None => Ok(b),
    }
}

#[pymethods]
impl Model {
    /// Decodes and validates model bytes (as `Model.from_bytes`).
    #[new]
    fn py_new(data: &[u8]) -> PyResult<Self> {
        Model::new(Arc::from(data), "model bytes")
    }

    /// Reads a model file. `OSError` if it cannot be read, `ValueError` if it is not a valid
    /// model (the message names the file and the reason).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let bytes = std::fs::read(&path).map_err(|e| errors::io(&path, &e))?;
        Model::new(Arc::from(bytes), &path.display().to_string())
    }

    /// Decodes and validates model bytes; `ValueError` for corrupt, truncated or foreign bytes.
    #[staticmethod]
    fn from_bytes(data: &[u8]) -> PyResult<Self> {
        Model::new(Arc::from(data), "model bytes")
    }

    /// The model file's bytes.
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.bytes)
    }

    /// `"mogi"` (a volcano source under a GNSS network) or `"rtm"` (forest spectra, INFORM).
    #[getter]
    fn problem(&self) -> &'static str {
        self.problem
    }

    /// The paper's variant: `"A"` (autoencoder), `"B"` (encoder + physics) or `"C"` (+ correction).
    #[getter]
    fn variant(&self) -> &'static str {
        match self.variant {
            Variant::A => "A",
            Variant::B => "B",
            Variant::C => "C",
        }
    }

    /// The input channels in order (the last axis of `obs`): `ux_<STA>`…`uz_<STA>` in mm, or
    /// band names (`B02`…) in reflectance.
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.inputs.clone()
    }

    /// The result columns, as `magic invert` writes them: the variables, then `residual_rms`,
    /// `flags`, `stations_used`.
    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.outputs.clone()
    }

    /// The variables' bounds: `{name: (min, max)}` (empty for variant A).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (n, lo, hi) in &self.bounds {
            d.set_item(n, (*lo, *hi))?;
        }
        Ok(d)
    }

    /// Whether inversions need the observations' dates (a time-dependent effect is declared).
    #[getter]
    fn needs_time(&self) -> bool {
        self.needs_time
    }

    /// Inverts observations into the model's variables, exactly as `magic invert` does.
    ///
    /// Parameters
    /// ----------
    /// obs
    ///     float32 or float64 array of shape `(..., len(model.inputs))` in the units
    ///     `magic invert` reads: mm for a GNSS network (`ux_<STA>`, `uy_<STA>`, `uz_<STA>`),
    ///     reflectance (0-1, not scaled integers) for Sentinel-2 bands. NaN marks a missing
    ///     channel. Other dtypes raise `TypeError`, another last axis `ValueError`.
    /// dates
    ///     The observations' dates, broadcastable to `obs.shape[:-1]`: `numpy.datetime64`
    ///     values, strings `YYYY-MM-DD` / `YYYY.MM.DD`, or day numbers since 1970-01-01.
    ///     Needed by models with time-dependent effects (`model.needs_time`), else optional;
    ///     NaT/NaN is an unknown date.
    /// errors
    ///     `"raise"` (default): a row that cannot be inverted (too few observed channels, a
    ///     value beyond 10 m or infinite, an unknown date where one is needed) raises
    ///     `ValueError` naming the first such row, e.g. `obs[3, 17]: too few observations`.
    ///     `"nan"`: such rows get NaN in every float column and 0 in `flags` and
    ///     `stations_used`.
    /// threads
    ///     Threads to use (default: all cores, or `RAYON_NUM_THREADS`).
    /// sd
    ///     Also return `<variable>_sd` per variable, as `magic invert --sd` writes them: the
    ///     Laplace approximation at the solution with the exact Jacobian (raw, not calibrated);
    ///     NaN where a row has too few observed channels. Variants B and C only.
    ///
    /// Returns
    /// -------
    /// dict[str, numpy.ndarray]
    ///     One array per column of `model.outputs`, shaped `obs.shape[:-1]`: the variables
    ///     (float64; `x_km, y_km, depth_km, dv_1e6m3` for a volcano, `N, cab, cw, cm, LAI,
    ///     LAIu, fc, cd, h` for a forest), `residual_rms` (float64, physical units), `flags`
    ///     (uint8: 1 a variable at its bound, 2 missing channels, 4 residual above the model's
    ///     threshold) and `stations_used` (uint32 bit mask of the stations or bands observed).
    #[pyo3(signature = (obs, dates=None, *, errors="raise", threads=None, sd=false))]
    fn invert<'py>(
        &self,
        py: Python<'py>,
        obs: &Bound<'py, PyAny>,
        dates: Option<&Bound<'py, PyAny>>,
        errors: &str,
        threads: Option<usize>,
        sd: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let on_error = OnError::parse(errors)?;
        if sd && self.variant == Variant::A {
            return Err(errors::value(
                "sd",
                "standard deviations need a forward model: this is a variant A model (use B or C)",
            ));
        }
        let arr = float_array("obs", obs)?;
        let rows = arr.rows("obs", self.inputs.len(), &self.inputs)?;
        let n = rows.len();
        let days = match dates {
            Some(d) if !d.is_none() => {
                let shape = PyTuple::new(py, &rows.shape)?;
                let f = py.import("magic._dates")?.getattr("day_numbers")?;
                let a = f.call1((d, shape))?;
                let a = a
                    .cast::<PyArrayDyn<f64>>()
                    .map_err(|e| errors::value("dates", e))?
                    .try_readonly()
                    .map_err(|e| errors::value("dates", e))?;
                let v = a.as_array().iter().copied().collect::<Vec<f64>>();
                if v.len() != n {
                    return Err(errors::value(
                        "dates",
                        format!("{} dates for {n} rows of obs", v.len()),
                    ));
                }
                Some(v)
            }
            _ => None,
        };
        let n_floats = self.outputs.len() - 2;
        let n_sd = if sd { n_floats - 1 } else { 0 };
        let width = n_floats + n_sd;
        let bytes = self.bytes.clone();
        let result = py.detach(|| {
            install(threads, || {
                let model = CoreModel::decode(&bytes).map_err(|e| (usize::MAX, e))?;
                invert_batch(
                    &model,
                    n,
                    (n_floats, n_sd),
                    |i, buf| rows.row_f32(i, buf),
                    days.as_deref(),
                    on_error,
                )
            })
        })?;
        let b = result.map_err(|(row, e)| {
            if row == usize::MAX {
                errors::value("model bytes", e)
            } else {
                errors::value(format!("obs{}", errors::row_index(&rows.shape, row)), e)
            }
        })?;
        let out = PyDict::new(py);
        for (k, name) in self.outputs[..n_floats].iter().enumerate() {
            let col: Vec<f64> = b.floats.iter().skip(k).step_by(width).copied().collect();
            out.set_item(name, shaped(py, &rows.shape, &[], col)?)?;
        }
        out.set_item(
            &self.outputs[n_floats],
            shaped(py, &rows.shape, &[], b.flags)?,
        )?;
        out.set_item(
            &self.outputs[n_floats + 1],
            shaped(py, &rows.shape, &[], b.used)?,
        )?;
        for (k, name) in self.outputs[..n_sd].iter().enumerate() {
            let col: Vec<f64> = b
                .floats
                .iter()
                .skip(n_floats + k)
                .step_by(width)
                .copied()
                .collect();
            out.set_item(format!("{name}_sd"), shaped(py, &rows.shape, &[], col)?)?;
        }
        Ok(out)
    }

    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let cls = py.get_type::<Model>();
        let args = PyTuple::new(py, [PyBytes::new(py, &self.bytes)])?;
        PyTuple::new(py, [cls.into_any(), args.into_any()])
    }

    fn __repr__(&self) -> String {
        format!(
            "<magic.Model {} variant {}: {} inputs -> {}>",
            self.problem,
            self.variant(),
            self.inputs.len(),
            self.outputs.join(", ")
        )
    }
}
