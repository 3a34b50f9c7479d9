//! `magic prepare`: a folder of NGL `<STA>.tenv3` files to a training set in the release layout
//! (standardised splits by date, station coordinates in local km, the source's bounds).

use crate::gnss::prepare::{self, splits::DateRange, PrepareOptions};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};

/// How the files become a training set.
#[derive(Args, Clone, Debug, Default)]
pub struct PrepareArgs {
    /// NGL steps file (`steps.txt`: equipment changes and earthquakes); the offsets at the
    /// network's stations are estimated and removed.
    #[arg(long)]
    pub steps: Option<PathBuf>,
    /// Remove each station's trend (NGL's MIDAS estimator; pairs across a listed step skipped).
    #[arg(long)]
    pub detrend: bool,
    /// Test period `FROM..TO` (YYYY-MM-DD, both included; default: the first 20 % of the days).
    #[arg(long, value_parser = date_range)]
    pub test: Option<DateRange>,
    /// Validation period `FROM..TO` (default: the last 15 % of the days).
    #[arg(long, value_parser = date_range)]
    pub valid: Option<DateRange>,
    /// Depth range of the source `MIN..MAX`, km.
    #[arg(long, default_value = "2..20")]
    pub depth: String,
    /// Margin around the stations' box for the source's x and y, km.
    #[arg(long, default_value_t = prepare::DEFAULT_MARGIN_KM)]
    pub margin: f64,
    /// Origin of the local frame `LAT,LON` in degrees (default: the network's centre).
    #[arg(long, allow_hyphen_values = true)]
    pub origin: Option<String>,
    /// Half-width of the window either side of a listed step, days.
    #[arg(long, default_value_t = prepare::offsets::STEP_WINDOW_DAYS)]
    pub step_window: f64,
}

/// `FROM..TO` for clap.
fn date_range(s: &str) -> std::result::Result<DateRange, String> {
    s.parse().map_err(|e: anyhow::Error| e.to_string())
}

impl PrepareArgs {
    /// The options these arguments give.
    pub fn options(&self) -> Result<PrepareOptions> {
        let (lo, hi) = self
            .depth
            .split_once("..")
            .with_context(|| format!("--depth {}: expected MIN..MAX in km", self.depth))?;
        let num = |s: &str, what: &str| -> Result<f64> {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{what}: expected a number, found `{s}`"))
        };
        let depth_km = [num(lo, "--depth")?, num(hi, "--depth")?];
        if !(depth_km[0] > 0.0 && depth_km[0] < depth_km[1]) {
            bail!("--depth {}: expected 0 < MIN < MAX", self.depth);
        }
        let origin = match &self.origin {
            None => None,
            Some(o) => {
                let (a, b) = o
                    .split_once(',')
                    .with_context(|| format!("--origin {o}: expected LAT,LON in degrees"))?;
                let lat = num(a, "--origin latitude")?;
                if lat.abs() > 90.0 {
                    bail!("--origin {o}: the latitude must be within ±90°");
                }
                Some([lat, num(b, "--origin longitude")?])
            }
        };
        if !(self.step_window.is_finite() && self.step_window > 0.0) {
            bail!("--step-window: expected a positive number of days");
        }
        Ok(PrepareOptions {
            steps: self.steps.clone(),
            detrend: self.detrend,
            test: self.test,
            valid: self.valid,
            depth_km,
            margin_km: self.margin,
            origin,
            step_window_days: self.step_window,
        })
    }
}

/// `magic prepare`.
#[derive(Args, Clone, Debug)]
pub struct PrepareCmd {
    /// Folder holding `<STA>.tenv3` files (one per station).
    #[arg(long)]
    pub tenv3: PathBuf,
    /// Output folder (`train.csv`, `valid.csv`, `test.csv`, `train_x_mean.csv`,
    /// `train_x_scale.csv`, `stations.json`, `bounds.json`, `prepare.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// How.
    #[command(flatten)]
    pub how: PrepareArgs,
}

/// Prepares `tenv3` into `out`, printing what was done; fails after writing when input lines
/// were bad (they are skipped and listed).
pub fn prepare_into(tenv3: &Path, out: &Path, how: &PrepareArgs) -> Result<()> {
    let p = prepare::prepare(tenv3, &how.options()?)?;
    prepare::write(&p, out)?;
    for e in &p.errors {
        eprintln!("{e}");
    }
    for n in &p.notes {
        eprintln!("note: {n}");
    }
    let r = &p.report;
    eprintln!(
        "{} stations, {} days {} ({} without data left out, {:.1} % of channels missing); origin {:.5}°, {:.5}°; train/valid/test {}/{}/{} rows (test {}, valid {}) -> {}",
        r.stations.len(),
        r.days,
        r.span,
        r.empty_days,
        100.0 * r.missing_share,
        r.origin[0],
        r.origin[1],
        r.rows[0],
        r.rows[1],
        r.rows[2],
        r.test,
        r.valid,
        out.display()
    );
    for s in &r.stations {
        let v: Vec<String> = s
            .velocity_mm_yr
            .iter()
            .map(|v| v.map_or("–".into(), |[v, e]| format!("{v:.2}±{e:.2}")))
            .collect();
        let steps: Vec<String> = s
            .steps
            .iter()
            .map(|st| {
                let o: Vec<String> = st
                    .offset_mm
                    .iter()
                    .map(|o| o.map_or("–".into(), |o| format!("{o:.1}")))
                    .collect();
                format!("{} ({} mm)", st.date, o.join(", "))
            })
            .collect();
        eprintln!(
            "  {} x {:.3} y {:.3} z {:.3} km; velocity E, N, U {} mm/yr; steps: {}",
            s.name,
            s.enu_km[0],
            s.enu_km[1],
            s.enu_km[2],
            v.join(", "),
            if steps.is_empty() {
                "none".into()
            } else {
                steps.join("; ")
            }
        );
    }
    if !p.errors.is_empty() {
        bail!(
            "{} bad lines or files (skipped; everything else was written)",
            p.errors.len()
        );
    }
    Ok(())
}

/// Runs `magic prepare`.
pub fn run(a: &PrepareCmd) -> Result<()> {
    prepare_into(&a.tenv3, &a.out, &a.how)
}
