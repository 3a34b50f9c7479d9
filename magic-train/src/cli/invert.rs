//! `magic invert` (on the host, physics in f64) and `magic qemu` (the same rows on the firmware
//! under QEMU): observation rows in, one result row out per input row.

use super::args::{decode, read_model};
use crate::data::records::{self, ObsRow};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

/// The rows to invert and where the results go.
#[derive(Args, Clone, Debug)]
pub struct RowsArgs {
    /// Model file.
    #[arg(long)]
    model: PathBuf,
    /// Observation CSV: columns `ux_<STA>` … in mm (volcano) or the bands `B02` … as reflectance
    /// (forest), optionally a `date`; other columns are ignored.
    #[arg(long)]
    input: PathBuf,
    /// Result CSV.
    #[arg(long)]
    output: PathBuf,
    /// The input holds standardised values (the data files as they are).
    #[arg(long)]
    standardized: bool,
    /// Append each variable's standard deviation (`<name>_sd`) from the exact Jacobian at the
    /// solution (variants B and C; with `magic qemu` on a firmware built with the feature `sd`).
    #[arg(long)]
    sd: bool,
}

fn report_row_errors(rows: &[ObsRow]) {
    for r in rows {
        if let Err(e) = &r.obs {
            eprintln!("error: {e}");
        }
    }
}

/// Runs `magic invert`.
pub fn invert(a: &RowsArgs) -> Result<()> {
    let bytes = read_model(&a.model)?;
    let m = decode(&a.model, &bytes)?;
    let rows = records::read_obs(&a.input, &m, a.standardized)?;
    let (lines, extra) = if a.sd {
        let lines = records::invert_rows_sd(&m, &rows)
            .map_err(|e| anyhow::anyhow!("{}: {e}", a.model.display()))?;
        (lines, records::sd_columns(&m))
    } else {
        (records::invert_rows(&m, &rows), vec![])
    };
    report_row_errors(&rows);
    records::write_results_with(&a.output, &m, &rows, &lines, &extra)?;
    let bad = lines.iter().filter(|l| l.starts_with("error,")).count();
    eprintln!(
        "inverted {} rows ({} errors) -> {}",
        lines.len(),
        bad,
        a.output.display()
    );
    if bad > 0 {
        bail!(
            "{bad} of {} rows could not be inverted (error rows written)",
            lines.len()
        );
    }
    Ok(())
}

/// Runs `magic qemu` (with `--sd`: on a firmware that also computes the standard deviations).
pub fn qemu(a: &RowsArgs) -> Result<()> {
    let bytes = read_model(&a.model)?;
    let m = decode(&a.model, &bytes)?;
    if a.sd && m.variant == magic_core::Variant::A {
        bail!(
            "{}: standard deviations need a forward model: this is a variant A model (use B or C)",
            a.model.display()
        );
    }
    let rows = records::read_obs(&a.input, &m, a.standardized)?;
    report_row_errors(&rows);
    let features: &[&str] = if a.sd { &["sd"] } else { &[] };
    let run = crate::firmware::run_rows_with(&a.model, &m, &rows, features)?;
    let extra = if a.sd {
        records::sd_columns(&m)
    } else {
        vec![]
    };
    records::write_results_with(&a.output, &m, &rows, &run.results, &extra)?;
    for (k, v) in &run.costs {
        eprintln!("# {k} = {v}");
    }
    let host = if a.sd {
        records::invert_rows_sd(&m, &rows)?
    } else {
        records::invert_rows(&m, &rows)
    };
    let (worst, mismatched) = crate::firmware::agreement(&m, &run.results, &host);
    let sd = if a.sd {
        let w = crate::firmware::sd_agreement(&run.results, &host, extra.len());
        format!("; standard deviations within {w:.1e} (relative) of the host's")
    } else {
        String::new()
    };
    eprintln!(
        "{} rows -> {}; largest difference from the host: {:.1e} of a variable's range{sd}; {} rows failed on one side only",
        rows.len(),
        a.output.display(),
        worst.iter().copied().fold(0.0, f64::max),
        mismatched
    );
    Ok(())
}
