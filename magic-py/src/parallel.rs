//! Rows in parallel: blocks of rows on rayon's threads (all cores, or a pool of a given size),
//! with the first failing row remembered so that an error names the earliest bad row whatever
//! the scheduling.

use crate::arrays::Rows;
use crate::errors;
use pyo3::PyResult;
use rayon::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Rows per block: large enough that a block's bookkeeping is nothing next to its rows, small
/// enough that a few thousand rows still spread over every core.
pub const BLOCK: usize = 64;

/// Widest input row a forward model reads (INFORM's 21 inputs, with room).
pub const MAX_WIDTH: usize = 32;

/// How rows that cannot be computed are reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnError {
    /// The call raises for the first such row.
    Raise,
    /// Such rows get NaN in every float output; the call goes on.
    Nan,
}

impl OnError {
    /// From the `errors=` argument.
    pub fn parse(s: &str) -> PyResult<Self> {
        match s {
            "raise" => Ok(OnError::Raise),
            "nan" => Ok(OnError::Nan),
            other => Err(errors::value(
                "errors",
                format!("`{other}`: expected \"raise\" or \"nan\""),
            )),
        }
    }
}

/// The earliest failing row seen so far, and its error.
pub struct FirstError<E> {
    row: AtomicUsize,
    err: Mutex<Option<(usize, E)>>,
}

impl<E> Default for FirstError<E> {
    fn default() -> Self {
        FirstError {
            row: AtomicUsize::new(usize::MAX),
            err: Mutex::new(None),
        }
    }
}

impl<E> FirstError<E> {
    /// Records that `row` failed with `e` (kept if it is the earliest so far).
    pub fn record(&self, row: usize, e: E) {
        let mut g = self.err.lock().unwrap_or_else(|p| p.into_inner());
        if g.as_ref().is_none_or(|(r, _)| row < *r) {
            *g = Some((row, e));
            self.row.store(row, Ordering::Relaxed);
        }
    }

    /// Whether a row before `row` is already known to fail (work from `row` on is moot).
    pub fn before(&self, row: usize) -> bool {
        self.row.load(Ordering::Relaxed) < row
    }

    /// The earliest failure.
    pub fn take(self) -> Option<(usize, E)> {
        self.err.into_inner().unwrap_or_else(|p| p.into_inner())
    }
}

/// Runs `f` on `threads` threads (a pool kept per size), or on rayon's global pool (all cores,
/// or `RAYON_NUM_THREADS`) when `None`.
pub fn install<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> PyResult<T> {
    match threads {
        None => Ok(f()),
        Some(0) => Err(errors::value("threads", "must be at least 1")),
        Some(n) => Ok(pool(n)?.install(f)),
    }
}

fn pool(n: usize) -> PyResult<Arc<ThreadPool>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<ThreadPool>>>> = OnceLock::new();
    let mut pools = POOLS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    if let Some(p) = pools.get(&n) {
        return Ok(p.clone());
    }
    let p = Arc::new(
        ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| errors::value("threads", e))?,
    );
    pools.insert(n, p.clone());
    Ok(p)
}

/// Evaluates `f(input row, output row)` for every row of `rows` in parallel: the outputs, row
/// after row (`out_width` values each), or the earliest failing row and its error when `on_error`
/// is [`OnError::Raise`] (with [`OnError::Nan`] a failing row's outputs are NaN).
pub fn map_rows<E: Send>(
    rows: &Rows<'_>,
    out_width: usize,
    on_error: OnError,
    f: impl Fn(&[f64], &mut [f64]) -> Result<(), E> + Sync,
) -> Result<Vec<f64>, (usize, E)> {
    let n = rows.len();
    let width = rows.width;
    let mut out = vec![0.0; n * out_width];
    if out_width == 0 || n == 0 {
        return Ok(out);
    }
    let first = FirstError::default();
    out.par_chunks_mut(BLOCK * out_width)
        .enumerate()
        .for_each(|(b, block)| {
            let mut x = [0.0f64; MAX_WIDTH];
            let x = &mut x[..width.min(MAX_WIDTH)];
            for (j, y) in block.chunks_mut(out_width).enumerate() {
                let row = b * BLOCK + j;
                if on_error == OnError::Raise && first.before(row) {
                    return;
                }
                rows.row_f64(row, x);
                if let Err(e) = f(x, y) {
                    match on_error {
                        OnError::Raise => {
                            first.record(row, e);
                            return;
                        }
                        OnError::Nan => y.fill(f64::NAN),
                    }
                }
            }
        });
    match first.take() {
        Some(e) => Err(e),
        None => Ok(out),
    }
}
