//! Data in and out, the same for every problem: where the data lives, the dataset type, numeric
//! CSV tables with located errors, and observation/result rows of `magic invert`.

pub mod dataset;
mod interleave;
pub mod records;
pub mod table;

pub use dataset::{day_number, Dataset, Split, SplitName};
pub use interleave::{onset_folds, window_folds};

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Finds a data folder: the explicit `--data-dir`, else `$MAGIC_DATA/<sub>`, else
/// `../shared/data/<sub>` relative to the working directory, when present.
pub fn locate(explicit: Option<&Path>, sub: &str) -> Option<PathBuf> {
    if let Some(p) = explicit {
        return Some(p.to_path_buf());
    }
    if let Ok(root) = std::env::var("MAGIC_DATA") {
        let p = Path::new(&root).join(sub);
        if p.is_dir() {
            return Some(p);
        }
    }
    let p = Path::new("..").join("shared").join("data").join(sub);
    p.is_dir().then_some(p)
}

/// [`locate`], or an error saying how to point at the folder (`what`: "GNSS data", "S2 data",
/// "RTM tables"; `flag`: the option that names it).
pub fn require(explicit: Option<&Path>, sub: &str, what: &str, flag: &str) -> Result<PathBuf> {
    locate(explicit, sub).with_context(|| {
        format!("no {what}: pass {flag}, set MAGIC_DATA (a folder holding {sub}/), or run next to ../shared/data")
    })
}
