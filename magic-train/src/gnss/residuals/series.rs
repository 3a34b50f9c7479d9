//! The residual series a point source is searched on, written out: `residuals.csv` (one row per
//! analysed day, `date` then one column per channel, mm) and `grid.csv` (one row per point of the
//! lasting source's search grid, `x_km,y_km,depth_km` then the field of a 10⁶ m³ volume change
//! there, mm, projected as the residuals are). With both, an analysis of one's own — another
//! statistic, another noise model — runs on exactly what `magic residuals` searched
//! (`scripts/lasting_matched_filter.py` is one).

use super::GnssResiduals;
use crate::gnss::data::channel_names;
use crate::gnss::families::iso_date;
use crate::gnss::families::lasting_source;
use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// `date,<channels>` then one row per day: `rows` (row-major, standardised units) times each
/// channel's `scale` (mm per unit).
pub fn series_csv(names: &[String], days: &[f64], rows: &[f64], scale: &[f64]) -> Result<String> {
    let nc = scale.len();
    if names.len() != nc || nc == 0 || rows.len() != days.len() * nc {
        bail!(
            "residual series: {} channel names, {} scales, {} values for {} days",
            names.len(),
            nc,
            rows.len(),
            days.len()
        );
    }
    let mut out = format!("date,{}\n", names.join(","));
    for (day, row) in days.iter().zip(rows.chunks(nc)) {
        out.push_str(&iso_date(*day));
        for (v, s) in row.iter().zip(scale) {
            let _ = write!(out, ",{}", v * s);
        }
        out.push('\n');
    }
    Ok(out)
}

/// `x_km,y_km,depth_km,<channels>` then one row per grid point: its pattern (standardised
/// units) times each channel's `scale`.
pub fn grid_csv(
    names: &[String],
    points: &[[f64; 3]],
    patterns: &[Vec<f64>],
    scale: &[f64],
) -> Result<String> {
    if points.len() != patterns.len() || patterns.iter().any(|p| p.len() != scale.len()) {
        bail!(
            "search grid: {} points, {} patterns, {} channels",
            points.len(),
            patterns.len(),
            scale.len()
        );
    }
    let mut out = format!("x_km,y_km,depth_km,{}\n", names.join(","));
    for (p, g) in points.iter().zip(patterns) {
        let _ = write!(out, "{},{},{}", p[0], p[1], p[2]);
        for (v, s) in g.iter().zip(scale) {
            let _ = write!(out, ",{}", v * s);
        }
        out.push('\n');
    }
    Ok(out)
}

/// Writes `residuals.csv` and `grid.csv` of `res` into `dir` (created if missing): the view a
/// point source is located on (the held view when the main source is free), as analysed — a
/// pulse the lasting source is searched beside is still in it.
pub fn write(res: &GnssResiduals, dir: &Path) -> Result<()> {
    let loc = res.locating();
    let names = channel_names(&loc.ctx.network.names);
    let grid = lasting_source::lasting_grid(loc);
    let files = [
        (
            "residuals.csv",
            series_csv(&names, &loc.fit.days, &loc.fit.r, &loc.ctx.scale)?,
        ),
        (
            "grid.csv",
            grid_csv(&names, &grid.points, &grid.patterns, &loc.ctx.scale)?,
        ),
    ];
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in files {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        channel_names(&["A".to_string()])
    }

    #[test]
    fn a_series_row_is_its_day_and_each_channel_in_mm() {
        let days = [16071.0, 16072.0];
        let rows = [1.0, -2.0, 0.5, 0.0, 4.0, -1.0];
        let scale = [2.0, 3.0, 10.0];
        let text = series_csv(&names(), &days, &rows, &scale).unwrap();
        assert_eq!(
            text,
            "date,ux_A,uy_A,uz_A\n2014-01-01,2,-6,5\n2014-01-02,0,12,-10\n"
        );
    }

    #[test]
    fn a_grid_row_is_its_point_and_its_pattern_in_mm() {
        let text = grid_csv(
            &names(),
            &[[1.0, -2.0, 3.5]],
            &[vec![0.5, 0.25, -1.0]],
            &[2.0, 4.0, 3.0],
        )
        .unwrap();
        assert_eq!(text, "x_km,y_km,depth_km,ux_A,uy_A,uz_A\n1,-2,3.5,1,1,-3\n");
    }

    #[test]
    fn mismatched_shapes_are_an_error_that_says_them() {
        let e = series_csv(&names(), &[1.0], &[1.0, 2.0], &[1.0, 1.0, 1.0]).unwrap_err();
        assert!(e.to_string().contains("2 values for 1 days"), "{e}");
        let e = grid_csv(&names(), &[[0.0; 3]], &[vec![1.0]], &[1.0, 1.0, 1.0]).unwrap_err();
        assert!(
            e.to_string().contains("1 points, 1 patterns, 3 channels"),
            "{e}"
        );
    }
}
