//! Data readers: where the data lives, the GNSS splits, the S2 spectra, the INFORM tables, and
//! numeric CSV tables.

pub mod gnss;
pub mod rtm_tables;
pub mod s2;
pub mod table;
pub mod tenv3;

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
