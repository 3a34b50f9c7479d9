//! `magic map`: the forest variables of a Sentinel-2 image, GeoTIFF in, GeoTIFF out
//! ([`crate::raster::map`]).

use crate::raster::map::{self, MapOptions};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `magic map`.
#[derive(Args, Clone, Debug)]
pub struct MapCmd {
    /// RTM model file (variant B or C).
    #[arg(long)]
    model: PathBuf,
    /// Multi-band GeoTIFF with the model's bands (integer digital numbers or float
    /// reflectance), or a folder of single-band files named by band (`…_B05.tif`).
    #[arg(long)]
    input: PathBuf,
    /// Output GeoTIFF.
    #[arg(long)]
    output: PathBuf,
    /// Added to digital numbers before dividing by 10 000 (−1000 from processing baseline
    /// 04.00 on).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    offset: f64,
    /// Scene classification raster on the same grid: cloud, cloud shadow, cirrus, snow,
    /// water, saturated and no-data pixels are masked.
    #[arg(long)]
    scl: Option<PathBuf>,
    /// Run INFORM and the correction for every pixel: the residual and every flag of `magic
    /// invert` (about 30 times the cost of the encoder alone).
    #[arg(long)]
    residual: bool,
    /// Also a standard deviation per variable, from INFORM's exact Jacobian at the solution
    /// (implies --residual; about 3 times the cost of --residual alone).
    #[arg(long)]
    sd: bool,
    /// Acquisition date YYYY-MM-DD (needed by models with the illumination effect).
    #[arg(long)]
    date: Option<String>,
    /// Map only the window x0,y0,width,height (pixels).
    #[arg(long)]
    window: Option<String>,
    /// The input file's bands in order, comma-separated (e.g. B01,B02,…), when not the
    /// model's.
    #[arg(long, value_delimiter = ',')]
    bands: Option<Vec<String>>,
    /// Write the raw standard deviations (without the calibration factors).
    #[arg(long)]
    raw_sd: bool,
    /// Also write a PNG of one band here.
    #[arg(long)]
    preview: Option<PathBuf>,
    /// The band of the PNG.
    #[arg(long, default_value = "LAI")]
    preview_band: String,
}

/// Runs `magic map`.
pub fn run(a: &MapCmd) -> Result<()> {
    let o = MapOptions {
        model: a.model.clone(),
        input: a.input.clone(),
        output: a.output.clone(),
        offset: a.offset,
        scl: a.scl.clone(),
        residual: a.residual,
        sd: a.sd,
        date: a.date.clone(),
        window: a.window.as_deref().map(map::parse_window).transpose()?,
        bands: a.bands.clone(),
        raw_sd: a.raw_sd,
        preview: a.preview.clone(),
        preview_band: a.preview_band.clone(),
        progress: true,
        window_rows: map::WINDOW_ROWS,
    };
    let s = map::run(&o)?;
    let sd = if a.sd {
        format!(", {} without sd", s.sd_failed)
    } else {
        String::new()
    };
    eprintln!(
        "mapped {} pixels ({} no data, {} masked, {} failed{sd}) in {:.1} s ({:.0} pixels/s inverting) -> {}",
        s.pixels,
        s.no_data,
        s.masked,
        s.failed,
        s.seconds,
        s.pixels as f64 / s.compute_seconds.max(1e-9),
        o.output.display()
    );
    Ok(())
}
