//! Python exceptions for the ways a call can fail, each carrying the core's message and where.
//!
//! * input of the wrong kind (not numbers, integer arrays where floats are required) → `TypeError`;
//! * wrong shapes, values the model cannot take (NaN where not allowed, out of range), corrupt or
//!   truncated model bytes, inconsistent tables → `ValueError`;
//! * files that cannot be read → `OSError` (the subclass Python picks for the errno, e.g.
//!   `FileNotFoundError`, with the file name).

use pyo3::exceptions::{PyOSError, PyTypeError, PyValueError};
use pyo3::PyErr;
use std::fmt::Display;
use std::path::Path;

/// `ValueError: {what}: {error}`.
pub fn value(what: impl Display, e: impl Display) -> PyErr {
    PyValueError::new_err(format!("{what}: {e}"))
}

/// `TypeError` with a message.
pub fn type_error(msg: impl Into<String>) -> PyErr {
    PyTypeError::new_err(msg.into())
}

/// An `OSError` for `path` (errno, message and file name, as `open()` raises it).
pub fn io(path: &Path, e: &std::io::Error) -> PyErr {
    let name = path.display().to_string();
    match e.raw_os_error() {
        Some(code) => PyOSError::new_err((code, e.to_string(), name)),
        None => PyOSError::new_err(format!("{name}: {e}")),
    }
}

/// The index of flat row `row` in an array whose leading (row) axes are `shape`, as Python
/// writes it: `[3, 17]` (`[]` for a single row of a 1-D input).
pub fn row_index(shape: &[usize], mut row: usize) -> String {
    let mut idx = vec![0usize; shape.len()];
    for (i, &n) in shape.iter().enumerate().rev() {
        if n > 0 {
            idx[i] = row % n;
            row /= n;
        }
    }
    let parts: Vec<String> = idx.iter().map(|i| i.to_string()).collect();
    format!("[{}]", parts.join(", "))
}
