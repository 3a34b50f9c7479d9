//! Is the inferred source plausible? The share of days with a shallow, moderate source (depth
//! < 10 km, |ΔV| < 5·10⁶ m³; published estimates for Akutan's 2008 inflation: depth ~6–9 km,
//! ΔV ~5·10⁶ m³) and the largest inflation of a split with its depth — the figures the volcano's
//! reports show beside the MSE.

use crate::data::{Dataset, SplitName};
use crate::problem::Metric;
use anyhow::{anyhow, Result};
use magic_core::invert::Inversion;
use magic_core::uncertainty::{standard_deviations, SdWorkspace};
use magic_core::{invert_at, Model, Workspace};

/// A source is called plausible when it is shallower than this (km) …
pub const PLAUSIBLE_DEPTH_KM: f64 = 10.0;
/// … and its volume change is smaller in magnitude than this (10⁶ m³).
pub const PLAUSIBLE_DV: f64 = 5.0;

/// Whether a source (x, y, depth, ΔV) is plausible.
pub fn plausible(p: &[f64]) -> bool {
    p[2] < PLAUSIBLE_DEPTH_KM && p[3].abs() < PLAUSIBLE_DV
}

/// A split's source in the figures the volcano's reports show.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plausibility {
    /// The largest ΔV of the split (10⁶ m³).
    pub peak_dv: f64,
    /// The source's depth on that day (km).
    pub peak_depth: f64,
    /// That day (days since 1970-01-01; NaN for an empty split).
    pub peak_day: f64,
    /// The Laplace standard deviation of ΔV on that day (exact Jacobian, raw — not calibrated;
    /// NaN where it cannot be computed, e.g. for variant A).
    pub peak_dv_sd: f64,
    /// The same for the depth (km).
    pub peak_depth_sd: f64,
    /// The share of the split's days with a plausible source.
    pub share: f64,
}

/// The peak ΔV of `split`, the depth then, both with their standard deviations on that day
/// ([`magic_core::uncertainty::standard_deviations`]), and the share of days with a plausible
/// source.
pub fn plausibility(model: &Model<'_>, data: &Dataset, split: SplitName) -> Result<Plausibility> {
    let s = data.split(split);
    let mut ws = Workspace::default();
    let (mut peak, mut depth, mut ok) = (f64::NEG_INFINITY, 0.0, 0usize);
    // The peak day's observations, day and inversion, for its standard deviations.
    let mut at: Option<(Vec<f32>, f64, Inversion<f64>)> = None;
    for (row, t) in s.x.iter().zip(s.days()) {
        let obs = data.physical_row(row);
        let inv = invert_at::<f64>(model, &obs, t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        let (d, dv) = (inv.params[2], inv.params[3]);
        ok += usize::from(plausible(&inv.params[..4]));
        if dv > peak {
            peak = dv;
            depth = d;
            at = Some((obs, t, inv));
        }
    }
    let (mut dv_sd, mut depth_sd, mut day) = (f64::NAN, f64::NAN, f64::NAN);
    if let Some((obs, t, inv)) = at {
        day = t;
        if let Ok(u) = standard_deviations(model, &obs, &inv, t, &mut SdWorkspace::default()) {
            (depth_sd, dv_sd) = (u.sd[2], u.sd[3]);
        }
    }
    Ok(Plausibility {
        peak_dv: peak,
        peak_depth: depth,
        peak_day: day,
        peak_dv_sd: dv_sd,
        peak_depth_sd: depth_sd,
        share: ok as f64 / s.len().max(1) as f64,
    })
}

/// `v ± sd` with `digits` decimals, or `v` alone where the sd is not finite.
fn with_sd(v: f64, sd: f64, digits: usize) -> String {
    if sd.is_finite() {
        format!("{v:.digits$} ± {sd:.digits$}")
    } else {
        format!("{v:.digits$}")
    }
}

impl Plausibility {
    /// The peak ΔV with its standard deviation, as a report prints it.
    pub fn peak_dv_text(&self) -> String {
        with_sd(self.peak_dv, self.peak_dv_sd, 2)
    }

    /// The depth at the peak with its standard deviation.
    pub fn peak_depth_text(&self) -> String {
        with_sd(self.peak_depth, self.peak_depth_sd, 1)
    }
}

/// [`plausibility`] as report metrics (the peak's and the depth's with their standard
/// deviations, in their text and in the JSON's `sd`).
pub fn metrics(model: &Model<'_>, data: &Dataset, split: SplitName) -> Result<Vec<Metric>> {
    let p = plausibility(model, data, split)?;
    Ok(vec![
        Metric::new(
            "plausible_share",
            "plausible",
            p.share,
            format!("{:.0} %", 100.0 * p.share),
        ),
        Metric::new("peak_dv", "peak ΔV (10⁶ m³)", p.peak_dv, p.peak_dv_text())
            .with_sd(p.peak_dv_sd),
        Metric::new(
            "peak_depth",
            "depth at peak (km)",
            p.peak_depth,
            p.peak_depth_text(),
        )
        .with_sd(p.peak_depth_sd),
    ])
}
