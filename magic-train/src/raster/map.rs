//! `magic map`: a Sentinel-2 image in, a map of the forest variables out, window by window.
//!
//! The image is read [`WINDOW_ROWS`] rows at a time (the decoded chunks of the current row of
//! tiles are kept, no more), the window's pixels are inverted in parallel (rayon), and the
//! window's rows of every output band are deflated (in parallel) and appended to the output by
//! the streaming [`StripWriter`]. Memory is thus bounded by a window of rows (and by one row of
//! input tiles), whatever the height of the image. The output is written under a temporary name
//! and renamed when complete.

use super::calibrate;
use super::geo::{GeoRef, GDAL_METADATA, GDAL_NODATA};
use super::input::Input;
use super::pixel::{
    band_names, check_model, pixel, Outcome, PixelConfig, Scratch, N_OUT, N_VARIABLES,
};
use super::scl::Scl;
use super::writer::{Sample, StripWriter, TagValue, TiffSpec};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use magic_core::Model;
use rayon::prelude::*;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Rows inverted per window.
pub const WINDOW_ROWS: u32 = 64;

/// Rows per output strip (a divisor of [`WINDOW_ROWS`]).
pub const STRIP_ROWS: u32 = 16;

/// Options of `magic map`.
#[derive(Clone, Debug)]
pub struct MapOptions {
    /// Model file (RTM, variant B or C).
    pub model: PathBuf,
    /// Image (multi-band GeoTIFF) or folder of one file per band.
    pub input: PathBuf,
    /// Output GeoTIFF.
    pub output: PathBuf,
    /// Added to digital numbers before dividing by 10 000 (−1000 from processing baseline 04.00).
    pub offset: f64,
    /// Scene classification raster.
    pub scl: Option<PathBuf>,
    /// Run INFORM and C: the residual and every flag of `magic invert`.
    pub residual: bool,
    /// Also the standard deviations (INFORM's Jacobian; implies `residual`).
    pub sd: bool,
    /// Acquisition date `YYYY-MM-DD`.
    pub date: Option<String>,
    /// Window `x0, y0, width, height` of the image to map.
    pub window: Option<[u32; 4]>,
    /// The file's band order, when not the model's.
    pub bands: Option<Vec<String>>,
    /// Write the raw (uncalibrated) standard deviations.
    pub raw_sd: bool,
    /// Write a PNG of one band here.
    pub preview: Option<PathBuf>,
    /// The band the PNG shows.
    pub preview_band: String,
    /// Show a progress bar.
    pub progress: bool,
    /// Rows per window (memory grows with it; [`WINDOW_ROWS`] by default).
    pub window_rows: u32,
}

impl MapOptions {
    /// Whether INFORM and C run for every pixel (`--residual` or `--sd`).
    pub fn physics(&self) -> bool {
        self.residual || self.sd
    }
}

/// What a map run did.
#[derive(Clone, Debug, Default)]
pub struct MapSummary {
    /// Pixels mapped.
    pub pixels: u64,
    /// Pixels with no observed band.
    pub no_data: u64,
    /// Pixels masked by the SCL.
    pub masked: u64,
    /// Pixels whose inversion failed.
    pub failed: u64,
    /// Inverted pixels without standard deviations.
    pub sd_failed: u64,
    /// Calibration factors of the standard deviations (empty when not computed).
    pub sd_factors: Vec<f64>,
    /// Seconds spent inverting (compute only).
    pub compute_seconds: f64,
    /// Seconds in all.
    pub seconds: f64,
    /// Warnings (georeference).
    pub warnings: Vec<String>,
    /// Whether the output is a BigTIFF.
    pub big: bool,
}

/// Parses `x0,y0,w,h`.
pub fn parse_window(s: &str) -> Result<[u32; 4]> {
    let v: Vec<u32> = s
        .split(',')
        .map(|p| p.trim().parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("--window {s}: expected x0,y0,width,height (whole numbers)"))?;
    match v.as_slice() {
        [x, y, w, h] if *w > 0 && *h > 0 => Ok([*x, *y, *w, *h]),
        _ => bail!("--window {s}: expected x0,y0,width,height with width and height above 0"),
    }
}

/// Parses `YYYY-MM-DD` into days since 1970-01-01.
pub fn parse_date(s: &str) -> Result<f64> {
    let p: Vec<&str> = s.trim().split('-').collect();
    let bad = || anyhow::anyhow!("--date {s}: expected YYYY-MM-DD");
    let [y, m, d] = p.as_slice() else {
        return Err(bad());
    };
    let (y, m, d): (i32, u32, u32) = (
        y.parse().map_err(|_| bad())?,
        m.parse().map_err(|_| bad())?,
        d.parse().map_err(|_| bad())?,
    );
    if !(1..=12).contains(&m) || !(1..=31).contains(&d) || !(1900..=2200).contains(&y) {
        return Err(bad());
    }
    let days = magic_core::time::days_from_civil(y, m, d);
    let (y2, m2, d2) = magic_core::time::civil_from_days(days);
    if (y2, m2, d2) != (y, m, d) {
        return Err(bad());
    }
    Ok(days as f64)
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// GDAL's metadata XML: each band's description (its column name) and notes.
fn gdal_metadata(names: &[String], notes: &[(Option<usize>, String, String)]) -> String {
    let mut x = String::from("<GDALMetadata>\n");
    for (k, v) in notes.iter().filter(|n| n.0.is_none()).map(|n| (&n.1, &n.2)) {
        x.push_str(&format!(
            "  <Item name=\"{}\">{}</Item>\n",
            xml_escape(k),
            xml_escape(v)
        ));
    }
    for (i, n) in names.iter().enumerate() {
        x.push_str(&format!(
            "  <Item name=\"DESCRIPTION\" sample=\"{i}\" role=\"description\">{}</Item>\n",
            xml_escape(n)
        ));
        for (k, v) in notes
            .iter()
            .filter(|n| n.0 == Some(i))
            .map(|n| (&n.1, &n.2))
        {
            x.push_str(&format!(
                "  <Item name=\"{}\" sample=\"{i}\">{}</Item>\n",
                xml_escape(k),
                xml_escape(v)
            ));
        }
    }
    x.push_str("</GDALMetadata>");
    x
}

/// Makes the map; see the module documentation.
pub fn run(o: &MapOptions) -> Result<MapSummary> {
    let start = Instant::now();
    let bytes = std::fs::read(&o.model)
        .with_context(|| format!("{}: cannot read model file", o.model.display()))?;
    let model = Model::decode(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", o.model.display()))?;
    check_model(&model).with_context(|| o.model.display().to_string())?;
    let bands = crate::data::records::model_channels(&model)?;
    let mut input = Input::open(&o.input, &bands, o.bands.as_deref(), o.offset)?;
    let [x0, y0, w, h] = checked_window(o, &input)?;
    let mut scl = match &o.scl {
        Some(p) => Some(Scl::open(p, input.width, input.height)?),
        None => None,
    };
    let t_day = match &o.date {
        Some(d) => parse_date(d)?,
        None => f64::NAN,
    };
    if o.physics() && model.needs_time() && t_day.is_nan() {
        bail!(
            "{}: the model's forward model depends on the date (illumination): pass --date YYYY-MM-DD",
            o.model.display()
        );
    }
    let mut summary = MapSummary::default();
    let geo = window_georef(&input, x0, y0, &mut summary.warnings);
    for wmsg in &summary.warnings {
        eprintln!("warning: {wmsg}");
    }
    let sd_factors = sd_factors(o, &model, t_day)?;
    let window_rows = o.window_rows.max(1);
    let strip_rows = STRIP_ROWS.min(window_rows);
    if !window_rows.is_multiple_of(strip_rows) {
        bail!("{window_rows} rows per window: a multiple of {STRIP_ROWS} (or fewer) is needed");
    }
    let mut tags = geo.tags();
    tags.push((
        GDAL_METADATA,
        TagValue::Ascii(gdal_metadata(&band_names(), &notes(o, &sd_factors))),
    ));
    tags.push((GDAL_NODATA, TagValue::Ascii("nan".into())));
    let spec = TiffSpec {
        width: w,
        height: h,
        bands: N_OUT as u16,
        sample: Sample::F32,
        planar: true,
        rows_per_strip: strip_rows,
        deflate: true,
        big: None,
        tags,
    };
    let partial = partial_path(&o.output);
    let file = std::fs::File::create(&partial)
        .with_context(|| format!("{}: cannot create", partial.display()))?;
    let mut writer = StripWriter::new(BufWriter::with_capacity(1 << 20, file), spec)?;
    summary.big = writer.is_big();

    let cfg = PixelConfig {
        residual: o.physics(),
        sd: o.sd,
        t_day,
        sd_factors: sd_factors.clone(),
    };
    let nb = bands.len();
    let bar = progress_bar(o.progress, w as u64 * h as u64);
    let mut obs = Vec::new();
    let mut pix = Vec::new();
    let mut planes: Vec<u8> = Vec::new();
    let mut r = 0;
    while r < h {
        let rows = window_rows.min(h - r);
        let n = (rows * w) as usize;
        input.read(x0, y0 + r, w, rows, &mut obs)?;
        if let Some(s) = scl.as_mut() {
            summary.masked += s.apply(x0, y0 + r, w, rows, nb, &mut obs)? as u64;
        }
        invert_window(&model, &cfg, (n, nb), &obs, &mut pix, &mut summary);
        band_planes(&pix, n, &mut planes);
        writer.write_rows(rows, &planes)?;
        bar.inc(n as u64);
        r += rows;
    }
    bar.finish_and_clear();
    let out = writer.finish()?;
    out.into_inner()
        .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", partial.display()))?
        .sync_all()
        .ok();
    std::fs::rename(&partial, &o.output).with_context(|| {
        format!(
            "cannot rename {} to {}",
            partial.display(),
            o.output.display()
        )
    })?;
    summary.pixels = w as u64 * h as u64;
    summary.sd_factors = if o.sd { sd_factors } else { vec![] };
    if let Some(png) = &o.preview {
        super::preview::render(&o.output, &o.preview_band, png)?;
    }
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

/// The window `x0, y0, width, height` to map (`--window`, or the whole image), checked to lie
/// inside the image.
fn checked_window(o: &MapOptions, input: &Input) -> Result<[u32; 4]> {
    let [x0, y0, w, h] = o.window.unwrap_or([0, 0, input.width, input.height]);
    if x0.checked_add(w).is_none_or(|e| e > input.width)
        || y0.checked_add(h).is_none_or(|e| e > input.height)
    {
        bail!(
            "--window {x0},{y0},{w},{h} is not inside the {}×{} image {}",
            input.width,
            input.height,
            o.input.display()
        );
    }
    Ok([x0, y0, w, h])
}

/// The map's georeference: the input's, moved to the window's origin; what cannot be kept is
/// added to `warnings`.
fn window_georef(input: &Input, x0: u32, y0: u32, warnings: &mut Vec<String>) -> GeoRef {
    let src_geo = &input.first().geo;
    if let Some(p) = src_geo.problem() {
        warnings.push(format!(
            "{}: {p}; the map keeps the pixel grid",
            input.first().path().display()
        ));
    }
    let (geo, dropped): (GeoRef, bool) = src_geo.window(x0, y0);
    if dropped {
        warnings.push(format!(
            "{}: tie points without a pixel size cannot be moved to the window: dropped",
            input.first().path().display()
        ));
    }
    geo
}

/// The calibration factors of the standard deviations (1 when they are not computed or
/// `--raw-sd` asks for the raw ones); the factors found are reported on stderr.
fn sd_factors(o: &MapOptions, model: &Model<'_>, t_day: f64) -> Result<Vec<f64>> {
    if !o.sd || o.raw_sd {
        return Ok(vec![1.0; N_VARIABLES]);
    }
    let f = calibrate::calibrate(model, t_day)?;
    eprintln!(
        "sd calibration ({} synthetic spectra, seed {:#x}): {}",
        calibrate::CALIBRATION_SPECTRA,
        calibrate::CALIBRATION_SEED,
        band_names()[..N_VARIABLES]
            .iter()
            .zip(&f)
            .map(|(n, k)| format!("{n} ×{k:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(f)
}

/// The notes of the GDAL metadata: the model, whether the residual was computed, the date, and
/// each standard deviation's calibration factor (band, key, value; no band = the dataset's).
fn notes(o: &MapOptions, sd_factors: &[f64]) -> Vec<(Option<usize>, String, String)> {
    let mut notes: Vec<(Option<usize>, String, String)> = vec![
        (
            None,
            "MAGIC_MODEL".into(),
            o.model
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
        ),
        (
            None,
            "MAGIC_RESIDUAL".into(),
            if o.physics() {
                "computed"
            } else {
                "not computed (encoder only): residual_rms is NaN"
            }
            .into(),
        ),
        (
            None,
            "MAGIC_SD".into(),
            if o.sd {
                "computed"
            } else {
                "not computed (no --sd): *_sd are NaN"
            }
            .into(),
        ),
    ];
    if let Some(d) = &o.date {
        notes.push((None, "ACQUISITION_DATE".into(), d.clone()));
    }
    if o.sd {
        for (k, f) in sd_factors.iter().enumerate() {
            notes.push((
                Some(N_VARIABLES + 2 + k),
                "SD_CALIBRATION_FACTOR".into(),
                format!("{f}"),
            ));
        }
    }
    notes
}

/// A progress bar over `pixels` (hidden unless `show`).
fn progress_bar(show: bool, pixels: u64) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(pixels);
    b.set_style(
        ProgressStyle::with_template(
            "{bar:40} {percent:>3}% {human_pos}/{human_len} px, {per_sec}, ETA {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b
}

/// Inverts a window's `n` pixels (`obs`, `nb` bands each) in parallel into `pix` (pixel-major,
/// [`N_OUT`] values each) and counts the outcomes and the compute time in `summary`.
fn invert_window(
    model: &Model<'_>,
    cfg: &PixelConfig,
    (n, nb): (usize, usize),
    obs: &[f32],
    pix: &mut Vec<f32>,
    summary: &mut MapSummary,
) {
    let t = Instant::now();
    pix.resize(n * N_OUT, f32::NAN);
    let outcomes: Vec<Outcome> = obs
        .par_chunks(nb)
        .zip(pix.par_chunks_mut(N_OUT))
        .map_init(Scratch::default, |s, (o, out)| pixel(model, o, cfg, s, out))
        .collect();
    summary.compute_seconds += t.elapsed().as_secs_f64();
    for oc in &outcomes {
        match oc {
            Outcome::NoData => summary.no_data += 1,
            Outcome::Failed => summary.failed += 1,
            Outcome::Inverted { sd: false } if cfg.sd => summary.sd_failed += 1,
            Outcome::Inverted { .. } => {}
        }
    }
}

/// Pixel-major values of `n` pixels → band planes of little-endian f32.
fn band_planes(pix: &[f32], n: usize, planes: &mut Vec<u8>) {
    planes.resize(n * N_OUT * 4, 0);
    planes
        .par_chunks_mut(n * 4)
        .enumerate()
        .for_each(|(b, plane)| {
            for (i, dst) in plane.chunks_exact_mut(4).enumerate() {
                dst.copy_from_slice(&pix[i * N_OUT + b].to_le_bytes());
            }
        });
}

/// Where the output is written until it is complete.
fn partial_path(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_are_parsed_or_refused() {
        assert_eq!(parse_window("1, 2,3,4").unwrap(), [1, 2, 3, 4]);
        assert!(parse_window("1,2,0,4").is_err());
        assert!(parse_window("1,2,3").is_err());
        assert!(parse_window("a,2,3,4").is_err());
        assert_eq!(parse_date("1970-01-02").unwrap(), 1.0);
        assert!(parse_date("2018-02-30").is_err());
        assert!(parse_date("2018-6-1x").is_err());
        let x = gdal_metadata(&["a<b".into()], &[(Some(0), "K".into(), "v".into())]);
        assert!(x.contains("role=\"description\">a&lt;b</Item>") && x.contains("sample=\"0\">v"));
    }
}
