//! Figures for reports: bar charts, time series and station maps, written as PNG files.
//!
//! # Backend and fonts
//!
//! The figures are drawn with `plotters` on its bitmap backend and saved as PNG. Its default text
//! support (`ttf`) goes through `font-kit`, which finds fonts through the system's fontconfig and
//! FreeType: a build and run-time dependency on system libraries that a fresh machine or CI may
//! lack. Here `plotters` is built without default features and with `ab_glyph`, a pure-Rust font
//! rasteriser that reads no system fonts; the one font it uses, DejaVu Sans, is compiled into the
//! binary from the `dejavu` crate (crate MIT/Apache-2.0; the font under the Bitstream Vera licence
//! with public-domain DejaVu changes, free to use, embed and redistribute). So the figures look the
//! same on every machine and the build needs nothing but crates.
//!
//! PNG rather than SVG: an SVG needs no font to *write*, but its text is laid out by whatever
//! fonts the *viewer* has, and PNG is what a report, an issue comment or an image viewer shows as
//! is.

use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;
use std::sync::Once;

const FONT: &str = "sans-serif";
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

static FONT_ONCE: Once = Once::new();

/// Registers the embedded DejaVu Sans for every style plotters asks for (once per process).
fn register_fonts() {
    FONT_ONCE.call_once(|| {
        for style in [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ] {
            // The bytes are a valid TrueType font shipped by the crate; a failure would only leave
            // text undrawn, and the first draw call reports it.
            let _ = plotters::style::register_font(FONT, style, dejavu::sans::regular());
        }
    });
}

fn check_path(path: &Path) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("png") => Ok(()),
        _ => bail!(
            "{}: figures are written as PNG (use a .png file name)",
            path.display()
        ),
    }
}

fn area(path: &Path, size: (u32, u32)) -> Result<DrawingArea<BitMapBackend<'_>, Shift>> {
    check_path(path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    }
    register_fonts();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(root)
}

fn finish(root: DrawingArea<BitMapBackend<'_>, Shift>, path: &Path) -> Result<()> {
    root.present()
        .map_err(|e| anyhow!("{}: cannot write the figure: {e}", path.display()))
}

/// `[min, max]` of the finite values, widened by `pad` of the span (or ±1 when flat); `None` if
/// there is no finite value.
fn range(values: impl Iterator<Item = f64>, pad: f64) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        return None;
    }
    let span = hi - lo;
    if span <= f64::EPSILON * (1.0 + lo.abs().max(hi.abs())) {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        return Some((lo - d, hi + d));
    }
    Some((lo - pad * span, hi + pad * span))
}

/// A bar per label (`values`, e.g. the variance a declared effect explains) with a black tick at
/// its `reference` (e.g. the variance explained by chance). `reference` may be empty (no ticks).
pub fn bar_chart(
    path: &Path,
    title: &str,
    labels: &[String],
    values: &[f64],
    reference: &[f64],
) -> Result<()> {
    let n = labels.len();
    if n == 0 {
        bail!("bar chart `{title}`: no bars");
    }
    if values.len() != n || !(reference.is_empty() || reference.len() == n) {
        bail!(
            "bar chart `{title}`: {n} labels, {} values, {} reference values",
            values.len(),
            reference.len()
        );
    }
    if !values.iter().any(|v| v.is_finite()) {
        bail!("bar chart `{title}`: no finite value");
    }
    let (lo, hi) = range(values.iter().chain(reference).copied().chain([0.0]), 0.08)
        .with_context(|| format!("bar chart `{title}`: no finite value"))?;
    // Bars start at zero: the axis always includes it.
    let (lo, hi) = (lo.min(0.0), hi.max(0.0));
    let width = (160 + 110 * n as u32).clamp(480, 1800);
    let root = area(path, (width, 480))?;
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..n as f64 - 0.5, lo..hi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_label_formatter(&|v| tick(*v, hi - lo))
        .y_label_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| err(&e))?;
    if lo < 0.0 {
        chart
            .draw_series([PathElement::new(
                vec![(-0.5, 0.0), (n as f64 - 0.5, 0.0)],
                BLACK,
            )])
            .map_err(|e| err(&e))?;
    }
    let bars = values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .map(|(i, &v)| {
            Rectangle::new(
                [(i as f64 - 0.35, 0.0), (i as f64 + 0.35, v)],
                PALETTE[0].filled(),
            )
        });
    chart
        .draw_series(bars)
        .map_err(|e| err(&e))?
        .label("value")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], PALETTE[0].filled()));
    if !reference.is_empty() {
        let ticks = reference
            .iter()
            .enumerate()
            .filter(|(_, r)| r.is_finite())
            .map(|(i, &r)| {
                PathElement::new(
                    vec![(i as f64 - 0.45, r), (i as f64 + 0.45, r)],
                    BLACK.stroke_width(3),
                )
            });
        chart
            .draw_series(ticks)
            .map_err(|e| err(&e))?
            .label("reference")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 14))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(&e))?;
    // Category labels under the axis, centred on their bars.
    let style = (FONT, 14)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    for (i, label) in labels.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(i as f64, lo));
        root.draw(&Text::new(label.as_str(), (x, y + 8), style.clone()))
            .map_err(|e| err(&e))?;
    }
    finish(root, path)
}

/// An axis tick label with as many decimals as the axis span needs, and `0` never printed as
/// `-0.0`.
fn tick(v: f64, span: f64) -> String {
    let digits = if span > 0.0 && span.is_finite() {
        (-(span / 10.0).log10().floor()).clamp(0.0, 8.0) as usize
    } else {
        2
    };
    let s = format!("{v:.digits$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// A date label of a day number: `YYYY-MM` on an axis spanning years, `YYYY-MM-DD` on a shorter
/// one (ticks fall on round day numbers, not on month starts).
fn date_label(day: f64, span_days: f64) -> String {
    if !day.is_finite() {
        return String::new();
    }
    let (y, m, d) = magic_core::time::civil_from_days(day.round() as i64);
    if span_days > 730.0 {
        format!("{y}-{m:02}")
    } else {
        format!("{y}-{m:02}-{d:02}")
    }
}

/// Lines over time: `dates` are day numbers (days since 1970-01-01), each series one value per
/// date (NaN leaves a gap). E.g. a station's observed and reconstructed displacement.
pub fn time_series(
    path: &Path,
    title: &str,
    dates: &[f64],
    series: &[(&str, &[f64])],
) -> Result<()> {
    if dates.is_empty() || series.is_empty() {
        bail!(
            "time series `{title}`: nothing to draw ({} dates, {} series)",
            dates.len(),
            series.len()
        );
    }
    for (name, v) in series {
        if v.len() != dates.len() {
            bail!(
                "time series `{title}`: series `{name}` has {} values for {} dates",
                v.len(),
                dates.len()
            );
        }
    }
    let (x0, x1) = range(dates.iter().copied(), 0.01)
        .with_context(|| format!("time series `{title}`: no finite date"))?;
    let (y0, y1) = range(series.iter().flat_map(|(_, v)| v.iter().copied()), 0.05)
        .with_context(|| format!("time series `{title}`: no finite value"))?;
    let root = area(path, (1000, 450))?;
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 22))
        .margin(12)
        .margin_right(36)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_labels(8)
        .x_label_formatter(&|d| date_label(*d, x1 - x0))
        .y_label_formatter(&|v| tick(*v, y1 - y0))
        .x_label_style((FONT, 14))
        .y_label_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| err(&e))?;
    for (k, (name, values)) in series.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        // One path per run of finite points, so gaps stay gaps.
        let mut runs: Vec<Vec<(f64, f64)>> = vec![vec![]];
        for (&d, &v) in dates.iter().zip(values.iter()) {
            if d.is_finite() && v.is_finite() {
                if let Some(r) = runs.last_mut() {
                    r.push((d, v));
                }
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(vec![]);
            }
        }
        let style = color.stroke_width(2);
        let drawn = chart
            .draw_series(
                runs.into_iter()
                    .filter(|r| !r.is_empty())
                    .map(|r| PathElement::new(r, style)),
            )
            .map_err(|e| err(&e))?;
        drawn.label(*name).legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
        });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 14))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| err(&e))?;
    finish(root, path)
}

/// A diverging colour for `v` in `[-m, m]`: blue (negative), white (zero), red (positive).
fn diverging(v: f64, m: f64) -> RGBColor {
    if !v.is_finite() {
        return RGBColor(160, 160, 160);
    }
    let t = if m > 0.0 {
        (v / m).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let mix = |a: u8, b: u8, s: f64| (a as f64 + (b as f64 - a as f64) * s).round() as u8;
    if t >= 0.0 {
        RGBColor(mix(255, 202, t), mix(255, 0, t), mix(255, 32, t))
    } else {
        RGBColor(mix(255, 5, -t), mix(255, 113, -t), mix(255, 176, -t))
    }
}

/// Stations on a map (km east, km north) with an arrow per station (`vectors`: east, north, e.g.
/// residual or displacement in mm, scaled so the longest is a seventh of the map) and a colour per
/// station (`values`, e.g. the vertical residual, on a blue–white–red scale symmetric about 0).
/// `vectors` or `values` may be empty.
pub fn station_map(
    path: &Path,
    title: &str,
    stations: &[(String, f64, f64)],
    vectors: &[(f64, f64)],
    values: &[f64],
) -> Result<()> {
    let n = stations.len();
    if n == 0 {
        bail!("station map `{title}`: no stations");
    }
    if !(vectors.is_empty() || vectors.len() == n) || !(values.is_empty() || values.len() == n) {
        bail!(
            "station map `{title}`: {n} stations, {} vectors, {} values",
            vectors.len(),
            values.len()
        );
    }
    let [x0, x1, y0, y1] = map_extent(title, stations)?;
    let root = area(path, (900, 720))?;
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let (map, legend) = root.split_horizontally(800);
    let mut chart = ChartBuilder::on(&map)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("km east")
        .y_desc("km north")
        .axis_desc_style((FONT, 14))
        .x_label_style((FONT, 13))
        .y_label_style((FONT, 13))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| err(&e))?;

    let vmax = values
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let lmax = vectors
        .iter()
        .map(|(e, n)| e.hypot(*n))
        .filter(|l| l.is_finite())
        .fold(0.0f64, f64::max);
    let arrow_scale = if lmax > 0.0 {
        (x1 - x0).min(y1 - y0) / 7.0 / lmax
    } else {
        0.0
    };
    // Arrows first, stations on top.
    draw_arrows(
        &mut chart,
        path,
        stations,
        vectors,
        arrow_scale,
        (x1 - x0) / 60.0,
    )?;
    draw_stations(&mut chart, path, stations, values, vmax)?;

    // Legend column: the colour scale and the arrow scale.
    if !values.is_empty() {
        colour_scale(&legend, path, vmax)?;
    }
    if lmax > 0.0 {
        // An arrow of a round length, drawn at the map's scale.
        let nice = nice_length(lmax / 2.0);
        let px_per_km = 780.0 / (x1 - x0);
        let len_px = (nice * arrow_scale * px_per_km).round() as i32;
        arrow_legend(&legend, path, nice, len_px)?;
    }
    finish(root, path)
}

/// A station map's chart: km east and north on the plotting area of a bitmap.
type MapChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The map's extent `[x0, x1, y0, y1]` (km): the stations with a margin, the shorter span widened
/// so both axes have the same scale on the plotting area.
fn map_extent(title: &str, stations: &[(String, f64, f64)]) -> Result<[f64; 4]> {
    let (mut x0, mut x1) = range(stations.iter().map(|s| s.1), 0.15)
        .with_context(|| format!("station map `{title}`: no finite position"))?;
    let (mut y0, mut y1) = range(stations.iter().map(|s| s.2), 0.15)
        .with_context(|| format!("station map `{title}`: no finite position"))?;
    // Equal scales on both axes: widen the shorter span.
    let (w, h) = (x1 - x0, y1 - y0);
    let (plot_w, plot_h) = (780.0, 600.0);
    if w / plot_w > h / plot_h {
        let extra = (w * plot_h / plot_w - h) / 2.0;
        y0 -= extra;
        y1 += extra;
    } else {
        let extra = (h * plot_w / plot_h - w) / 2.0;
        x0 -= extra;
        x1 += extra;
    }
    Ok([x0, x1, y0, y1])
}

/// One arrow per station from its position along its vector times `scale` (`head`: length of
/// the arrow heads, km); vectors of zero or non-finite length are left out.
fn draw_arrows(
    chart: &mut MapChart<'_, '_>,
    path: &Path,
    stations: &[(String, f64, f64)],
    vectors: &[(f64, f64)],
    scale: f64,
    head: f64,
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    for (k, &(ve, vn)) in vectors.iter().enumerate() {
        let (_, sx, sy) = &stations[k];
        let (dx, dy) = (ve * scale, vn * scale);
        if !(dx.is_finite() && dy.is_finite() && sx.is_finite() && sy.is_finite())
            || dx.hypot(dy) == 0.0
        {
            continue;
        }
        chart
            .draw_series(arrow((*sx, *sy), (sx + dx, sy + dy), head))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// A marker per station, coloured by its value on the scale ±`vmax` (grey without values), and
/// its label: the name and the value.
fn draw_stations(
    chart: &mut MapChart<'_, '_>,
    path: &Path,
    stations: &[(String, f64, f64)],
    values: &[f64],
    vmax: f64,
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    for (k, (name, sx, sy)) in stations.iter().enumerate() {
        if !(sx.is_finite() && sy.is_finite()) {
            continue;
        }
        let fill = values
            .get(k)
            .map_or(RGBColor(200, 200, 200), |v| diverging(*v, vmax));
        chart
            .draw_series([
                Circle::new((*sx, *sy), 9, fill.filled()),
                Circle::new((*sx, *sy), 9, BLACK.stroke_width(1)),
            ])
            .map_err(|e| err(&e))?;
        let label = match values.get(k) {
            Some(v) => format!("{name} {v:.2}"),
            None => name.clone(),
        };
        // The label sits up and to the right of the marker, clear of it.
        let text = Text::new(
            label,
            (11, -4),
            (FONT, 14)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Bottom)),
        );
        chart
            .draw_series([EmptyElement::at((*sx, *sy)) + text])
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// The legend's colour scale from `vmax` (top) through 0 to −`vmax` (bottom).
fn colour_scale(
    legend: &DrawingArea<BitMapBackend<'_>, Shift>,
    path: &Path,
    vmax: f64,
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let style = |s: u32| (FONT, s).into_font().color(&BLACK);
    legend
        .draw(&Text::new("value", (8, 60), style(14)))
        .map_err(|e| err(&e))?;
    let (top, bottom) = (90, 330);
    for py in top..bottom {
        let v = vmax * (1.0 - 2.0 * (py - top) as f64 / (bottom - top) as f64);
        legend
            .draw(&Rectangle::new(
                [(10, py), (34, py + 1)],
                diverging(v, vmax).filled(),
            ))
            .map_err(|e| err(&e))?;
    }
    legend
        .draw(&Rectangle::new(
            [(10, top), (34, bottom)],
            BLACK.stroke_width(1),
        ))
        .map_err(|e| err(&e))?;
    for (py, v) in [(top, vmax), ((top + bottom) / 2, 0.0), (bottom, -vmax)] {
        legend
            .draw(&Text::new(format!("{v:.2}"), (40, py - 7), style(13)))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// The legend's arrow scale: an arrow `len_px` pixels long, labelled with its length `nice`.
fn arrow_legend(
    legend: &DrawingArea<BitMapBackend<'_>, Shift>,
    path: &Path,
    nice: f64,
    len_px: i32,
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let style = |s: u32| (FONT, s).into_font().color(&BLACK);
    let y = 400;
    legend
        .draw(&Text::new("arrow", (8, y - 30), style(14)))
        .map_err(|e| err(&e))?;
    legend
        .draw(&PathElement::new(
            vec![(10, y), (10 + len_px, y)],
            BLACK.stroke_width(2),
        ))
        .map_err(|e| err(&e))?;
    legend
        .draw(&PathElement::new(
            vec![
                (10 + len_px - 6, y - 4),
                (10 + len_px, y),
                (10 + len_px - 6, y + 4),
            ],
            BLACK.stroke_width(2),
        ))
        .map_err(|e| err(&e))?;
    legend
        .draw(&Text::new(format!("{nice}"), (10, y + 10), style(13)))
        .map_err(|e| err(&e))?;
    Ok(())
}

/// 1, 2 or 5 times a power of ten, at most `v`.
fn nice_length(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|k| k * p)
        .find(|&c| c <= v)
        .unwrap_or(p)
}

/// An arrow from `a` to `b` (data coordinates) with a head of length `head`.
fn arrow(a: (f64, f64), b: (f64, f64), head: f64) -> Vec<PathElement<(f64, f64)>> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let l = dx.hypot(dy);
    let (ux, uy) = (dx / l, dy / l);
    let h = head.min(0.5 * l);
    let side = |s: f64| {
        (
            b.0 - h * ux + s * 0.5 * h * uy,
            b.1 - h * uy - s * 0.5 * h * ux,
        )
    };
    let style = RGBColor(40, 40, 40).stroke_width(2);
    vec![
        PathElement::new(vec![a, b], style),
        PathElement::new(vec![side(1.0), b, side(-1.0)], style),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file in a scratch folder: `$MAGIC_PLOTS_DIR` when set (the figures stay there to be looked
    /// at), else a temporary folder the tests remove.
    fn tmp(name: &str) -> std::path::PathBuf {
        let d = match std::env::var_os("MAGIC_PLOTS_DIR") {
            Some(d) => std::path::PathBuf::from(d),
            // One folder per test (tests run in parallel threads named after them), so that one
            // test's clean-up never removes a folder another is writing into.
            None => std::env::temp_dir().join(format!(
                "magic-plots-{}-{}",
                std::process::id(),
                std::thread::current()
                    .name()
                    .unwrap_or("main")
                    .replace(|c: char| !c.is_ascii_alphanumeric(), "_")
            )),
        };
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    fn clean(names: &[&str]) {
        if std::env::var_os("MAGIC_PLOTS_DIR").is_none() {
            for n in names {
                std::fs::remove_file(tmp(n)).ok();
            }
            std::fs::remove_dir(tmp("x").parent().unwrap()).ok();
        }
    }

    fn assert_png(p: &Path) {
        let b = std::fs::read(p).unwrap();
        assert!(b.len() > 1000, "{}: {} bytes", p.display(), b.len());
        assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{}", p.display());
    }

    #[test]
    fn plots_bar_chart_writes_a_png() {
        let p = tmp("bars.png");
        let labels: Vec<String> = ["common_mode", "elevation", "seasonal", "step", "drift"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        bar_chart(
            &p,
            "Variance explained by declared effects",
            &labels,
            &[0.31, 0.05, 0.12, 0.02, f64::NAN],
            &[0.04; 5],
        )
        .unwrap();
        assert_png(&p);
        bar_chart(
            &tmp("bars2.png"),
            "no reference",
            &labels[..2],
            &[-0.1, 0.2],
            &[],
        )
        .unwrap();
        assert!(bar_chart(&p, "t", &labels, &[0.1], &[]).is_err());
        assert!(bar_chart(&p, "t", &[], &[], &[]).is_err());
        assert!(bar_chart(&p, "t", &labels[..1], &[f64::NAN], &[]).is_err());
        assert!(bar_chart(&tmp("bars.svg"), "t", &labels[..1], &[1.0], &[]).is_err());
        clean(&["bars.png", "bars2.png"]);
    }

    #[test]
    fn plots_time_series_writes_a_png() {
        let p = tmp("series.png");
        let dates: Vec<f64> = (0..400).map(|i| 13_879.0 + i as f64).collect();
        let obs: Vec<f64> = dates
            .iter()
            .map(|d| {
                ((d - 13_879.0) / 40.0).sin() * 5.0
                    + if *d as i64 % 97 == 0 { f64::NAN } else { 0.0 }
            })
            .collect();
        let rec: Vec<f64> = dates
            .iter()
            .map(|d| ((d - 13_879.0) / 40.0).sin() * 4.0)
            .collect();
        time_series(
            &p,
            "AV08 up (mm): observed vs reconstructed",
            &dates,
            &[("observed", &obs), ("before", &rec)],
        )
        .unwrap();
        assert_png(&p);
        assert!(time_series(&p, "t", &dates, &[("x", &rec[..10])]).is_err());
        assert!(time_series(&p, "t", &[], &[]).is_err());
        assert!(time_series(&p, "t", &[1.0], &[("x", &[f64::NAN])]).is_err());
        // A flat series still draws.
        time_series(&tmp("flat.png"), "flat", &[1.0, 2.0], &[("x", &[3.0, 3.0])]).unwrap();
        assert_png(&tmp("flat.png"));
        let years: Vec<f64> = (0..3000).map(|i| 13_000.0 + i as f64).collect();
        let wave: Vec<f64> = years.iter().map(|d| (d / 100.0).sin()).collect();
        time_series(&tmp("years.png"), "years", &years, &[("x", &wave)]).unwrap();
        assert_png(&tmp("years.png"));
        assert_eq!(date_label(13_938.0, 100.0), "2008-02-29");
        assert_eq!(date_label(13_938.0, 1000.0), "2008-02");
        assert_eq!(tick(-1e-17, 2.0), "0.0");
        assert_eq!(tick(0.25, 0.4), "0.25");
        assert_eq!(tick(120.0, 500.0), "120");
        clean(&["series.png", "flat.png", "years.png"]);
    }

    #[test]
    fn plots_station_map_writes_a_png() {
        let p = tmp("map.png");
        let st: Vec<(String, f64, f64)> = crate::gnss::synth::AKUTAN
            .iter()
            .map(|s| (s.0.to_string(), s.1, s.2))
            .collect();
        let vec: Vec<(f64, f64)> = st.iter().map(|(_, x, y)| (0.3 * x, 0.3 * y)).collect();
        let val: Vec<f64> = st.iter().map(|(_, x, _)| 0.2 * x).collect();
        station_map(&p, "Residual (mm)", &st, &vec, &val).unwrap();
        assert_png(&p);
        station_map(&tmp("map2.png"), "stations only", &st, &[], &[]).unwrap();
        assert!(station_map(&p, "t", &st, &vec[..3], &[]).is_err());
        assert!(station_map(&p, "t", &[], &[], &[]).is_err());
        assert_eq!(nice_length(7.3), 5.0);
        assert_eq!(nice_length(0.31), 0.2);
        clean(&["map.png", "map2.png"]);
    }
}
