//! The firmware leg of `magic demo` and `magic qemu`: build the board image with a model, stream
//! observation rows through it under QEMU, and compare every result with the host.

use super::qemu::{build_firmware_with, ensure_toolchain, run_firmware, FirmwareRun};
use crate::data::records::{firmware_lines, ObsRow};
use anyhow::{bail, Result};
use magic_core::Model;
use serde_json::json;
use std::path::Path;

/// Seconds QEMU may take for a run (a full test split takes well under one).
pub const TIMEOUT_S: u64 = 120;

/// Builds the firmware with `model_path` and runs `rows` through it; checks one result per row.
pub fn run_rows(model_path: &Path, model: &Model<'_>, rows: &[ObsRow]) -> Result<FirmwareRun> {
    run_rows_with(model_path, model, rows, &[])
}

/// [`run_rows`] on a firmware built with `extra_features` (`sd`: the standard deviations).
pub fn run_rows_with(
    model_path: &Path,
    model: &Model<'_>,
    rows: &[ObsRow],
    extra_features: &[&str],
) -> Result<FirmwareRun> {
    ensure_toolchain()?;
    let elf = build_firmware_with(model_path, extra_features)?;
    let run = run_firmware(&elf, &firmware_lines(rows, model.needs_time()), TIMEOUT_S)?;
    if !run.success {
        bail!(
            "the firmware failed (exit {:?}): {}",
            run.exit_code,
            run.results.last().map_or("", |s| s.as_str())
        );
    }
    if run.results.len() != rows.len() {
        bail!(
            "the firmware wrote {} result lines for {} input rows",
            run.results.len(),
            rows.len()
        );
    }
    Ok(run)
}

/// Largest difference between firmware and host per variable, as a fraction of its range, over
/// the rows both inverted; and the number of rows where one failed and the other did not.
pub fn agreement(model: &Model<'_>, fw: &[String], host: &[String]) -> (Vec<f64>, usize) {
    let n = model.n_params();
    let mut worst = vec![0f64; n];
    let mut mismatched = 0;
    for (a, b) in fw.iter().zip(host) {
        let pa: Vec<f64> = a
            .split(',')
            .take(n)
            .filter_map(|v| v.parse().ok())
            .collect();
        let pb: Vec<f64> = b
            .split(',')
            .take(n)
            .filter_map(|v| v.parse().ok())
            .collect();
        if pa.len() != n || pb.len() != n {
            mismatched += usize::from(a.starts_with("error") != b.starts_with("error"));
            continue;
        }
        for j in 0..n {
            let range = model.bounds.get(j).map_or(1.0, |b| (b[1] - b[0]) as f64);
            worst[j] = worst[j].max((pa[j] - pb[j]).abs() / range);
        }
    }
    (worst, mismatched)
}

/// Largest relative difference between the firmware's and the host's standard deviations (the
/// `n_sd` last fields of each result line, both sides finite), over the rows both inverted.
pub fn sd_agreement(fw: &[String], host: &[String], n_sd: usize) -> f64 {
    let tail = |line: &str| -> Vec<f64> {
        let v: Vec<&str> = line.split(',').collect();
        v[v.len().saturating_sub(n_sd)..]
            .iter()
            .filter_map(|x| x.parse().ok())
            .collect()
    };
    let mut worst = 0f64;
    for (a, b) in fw.iter().zip(host) {
        if a.starts_with("error") || b.starts_with("error") {
            continue;
        }
        for (x, y) in tail(a).iter().zip(&tail(b)) {
            if x.is_finite() && y.is_finite() {
                worst = worst.max((x - y).abs() / y.abs().max(1e-12));
            }
        }
    }
    worst
}

/// Runs the test days on the firmware, prints the comparison and the board's cost figures, and
/// returns them as JSON.
pub fn run_test_days(
    model_path: &Path,
    model: &Model<'_>,
    rows: &[ObsRow],
    host: &[String],
) -> Result<serde_json::Value> {
    let run = run_rows(model_path, model, rows)?;
    let (worst, mismatched) = agreement(model, &run.results, host);
    let max = worst.iter().copied().fold(0.0, f64::max);
    println!(
        "firmware (QEMU mps2-an386, Cortex-M4F): {} days, largest difference from the host {:.1e} of a variable's range{}",
        rows.len(),
        max,
        if mismatched > 0 { format!(", {mismatched} rows failed on one side only") } else { String::new() }
    );
    let fig = |k: Option<u64>| k.map_or("?".to_string(), |v| v.to_string());
    println!(
        "firmware cost: {} instructions per inversion (encoder {}, Mogi {}, correction {}), stack {} bytes, flash {} bytes",
        fig(run.instructions_per_inversion),
        fig(run.instructions_encoder),
        fig(run.instructions_mogi),
        fig(run.instructions_correction),
        fig(run.stack_bytes),
        fig(run.flash_bytes)
    );
    Ok(json!({
        "days": rows.len(),
        "max_diff_fraction_of_range": worst,
        "rows_failed_on_one_side": mismatched,
        "costs": run.costs,
    }))
}
