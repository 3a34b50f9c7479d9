//! Is the inferred source plausible? The share of days with a shallow, moderate source (depth
//! < 10 km, |ΔV| < 5·10⁶ m³; published estimates for Akutan's 2008 inflation: depth ~6–9 km,
//! ΔV ~5·10⁶ m³) and the largest inflation of a split with its depth — the figures the volcano's
//! reports show beside the MSE.

use crate::data::{Dataset, SplitName};
use crate::problem::Metric;
use anyhow::{anyhow, Result};
use magic_core::{invert_at, Model, Workspace};

/// A source is called plausible when it is shallower than this (km) …
pub const PLAUSIBLE_DEPTH_KM: f64 = 10.0;
/// … and its volume change is smaller in magnitude than this (10⁶ m³).
pub const PLAUSIBLE_DV: f64 = 5.0;

/// Whether a source (x, y, depth, ΔV) is plausible.
pub fn plausible(p: &[f64]) -> bool {
    p[2] < PLAUSIBLE_DEPTH_KM && p[3].abs() < PLAUSIBLE_DV
}

/// Peak ΔV (10⁶ m³) over the days of `split`, the depth (km) then, and the share of days with a
/// plausible source.
pub fn plausibility(
    model: &Model<'_>,
    data: &Dataset,
    split: SplitName,
) -> Result<(f64, f64, f64)> {
    let s = data.split(split);
    let mut ws = Workspace::default();
    let (mut peak, mut depth, mut ok) = (f64::NEG_INFINITY, 0.0, 0usize);
    for (row, t) in s.x.iter().zip(s.days()) {
        let inv = invert_at::<f64>(model, &data.physical_row(row), t, &mut ws)
            .map_err(|e| anyhow!("{e}"))?;
        let (d, dv) = (inv.params[2], inv.params[3]);
        if dv > peak {
            peak = dv;
            depth = d;
        }
        ok += usize::from(plausible(&inv.params[..4]));
    }
    Ok((peak, depth, ok as f64 / s.len().max(1) as f64))
}

/// [`plausibility`] as report metrics.
pub fn metrics(model: &Model<'_>, data: &Dataset, split: SplitName) -> Result<Vec<Metric>> {
    let (peak, depth, share) = plausibility(model, data, split)?;
    Ok(vec![
        Metric::new(
            "plausible_share",
            "plausible",
            share,
            format!("{:.0} %", 100.0 * share),
        ),
        Metric::new("peak_dv", "peak ΔV (10⁶ m³)", peak, format!("{peak:.2}")),
        Metric::new(
            "peak_depth",
            "depth at peak (km)",
            depth,
            format!("{depth:.1}"),
        ),
    ])
}
