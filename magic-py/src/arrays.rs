//! NumPy arrays of shape `(..., n)` in and out: float32 or float64 rows of `n` values, read in
//! place when C-contiguous, and result arrays shaped like the input's leading axes.

use crate::errors;
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use std::borrow::Cow;

/// The values of a float array, in C order.
pub enum Values<'a> {
    /// float32 input.
    F32(Cow<'a, [f32]>),
    /// float64 input.
    F64(Cow<'a, [f64]>),
}

/// A float array read as rows of its last axis.
pub struct Rows<'a> {
    /// The leading axes (the output shape of per-row results).
    pub shape: Vec<usize>,
    /// Values per row (the last axis).
    pub width: usize,
    /// The values.
    pub values: Values<'a>,
}

impl Rows<'_> {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    /// Row `i` converted into `out` (`width` values) as `f32` (float64 values rounded as the
    /// CLI rounds the numbers it reads).
    pub fn row_f32(&self, i: usize, out: &mut [f32]) {
        let (a, w) = (i * self.width, self.width);
        match &self.values {
            Values::F32(v) => out.copy_from_slice(&v[a..a + w]),
            Values::F64(v) => {
                for (o, x) in out.iter_mut().zip(&v[a..a + w]) {
                    *o = *x as f32;
                }
            }
        }
    }

    /// Row `i` converted into `out` (`width` values) as `f64`.
    pub fn row_f64(&self, i: usize, out: &mut [f64]) {
        let (a, w) = (i * self.width, self.width);
        match &self.values {
            Values::F32(v) => {
                for (o, x) in out.iter_mut().zip(&v[a..a + w]) {
                    *o = *x as f64;
                }
            }
            Values::F64(v) => out.copy_from_slice(&v[a..a + w]),
        }
    }
}

/// A float32 or float64 array borrowed from Python (kept alive while its rows are read).
pub enum FloatArray<'py> {
    /// float32.
    F32(PyReadonlyArrayDyn<'py, f32>),
    /// float64.
    F64(PyReadonlyArrayDyn<'py, f64>),
}

/// `obj` as a float32/float64 array: NumPy arrays as they are, other sequences through
/// `numpy.asarray`. Any other dtype (integers, bool, objects, strings) is a `TypeError` naming
/// `what`.
pub fn float_array<'py>(what: &str, obj: &Bound<'py, PyAny>) -> PyResult<FloatArray<'py>> {
    let py = obj.py();
    let arr = if obj.cast::<PyUntypedArray>().is_ok() {
        obj.clone()
    } else {
        let np = py.import("numpy")?;
        np.call_method1("asarray", (obj,)).map_err(|e| {
            errors::type_error(format!(
                "{what} must be an array of float32 or float64 numbers: {e}"
            ))
        })?
    };
    let borrow = |e: numpy::BorrowError| errors::value(what, e);
    if let Ok(a) = arr.cast::<PyArrayDyn<f32>>() {
        return Ok(FloatArray::F32(a.try_readonly().map_err(borrow)?));
    }
    if let Ok(a) = arr.cast::<PyArrayDyn<f64>>() {
        return Ok(FloatArray::F64(a.try_readonly().map_err(borrow)?));
    }
    let dtype = match arr.cast::<PyUntypedArray>() {
        Ok(a) => a.dtype().to_string(),
        Err(_) => arr.get_type().name()?.to_string(),
    };
    Err(errors::type_error(format!(
        "{what} must be float32 or float64 (physical units; NaN for a missing value), not {dtype}"
    )))
}

impl<'py> FloatArray<'py> {
    /// The array's shape.
    pub fn shape(&self) -> &[usize] {
        match self {
            FloatArray::F32(a) => a.shape(),
            FloatArray::F64(a) => a.shape(),
        }
    }

    /// The rows of the last axis, which must hold `width` values (`ValueError` naming `what`
    /// and `names` otherwise).
    pub fn rows(&self, what: &str, width: usize, names: &[String]) -> PyResult<Rows<'_>> {
        let shape = self.shape();
        let Some((&last, lead)) = shape.split_last() else {
            return Err(errors::value(
                what,
                format!("a 0-d array; expected shape (..., {width})"),
            ));
        };
        if last != width {
            let list = if names.is_empty() {
                String::new()
            } else {
                format!(" ({})", names.join(", "))
            };
            return Err(errors::value(
                what,
                format!("shape {shape:?}: the last axis must hold {width} values{list}"),
            ));
        }
        let values = match self {
            FloatArray::F32(a) => Values::F32(match a.as_slice() {
                Ok(s) => Cow::Borrowed(s),
                Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
            }),
            FloatArray::F64(a) => Values::F64(match a.as_slice() {
                Ok(s) => Cow::Borrowed(s),
                Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
            }),
        };
        Ok(Rows {
            shape: lead.to_vec(),
            width,
            values,
        })
    }
}

/// An array of shape `lead + tail` from C-ordered values.
pub fn shaped<'py, T: numpy::Element>(
    py: Python<'py>,
    lead: &[usize],
    tail: &[usize],
    values: Vec<T>,
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let shape: Vec<usize> = lead.iter().chain(tail).copied().collect();
    let a = ArrayD::from_shape_vec(IxDyn(&shape), values)
        .map_err(|e| errors::value("result shape", e))?;
    Ok(a.into_pyarray(py))
}
