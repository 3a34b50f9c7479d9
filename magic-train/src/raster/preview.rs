//! A PNG of one band of a map (`magic map --preview`), for reports and the README.
//!
//! The band is read back from the written map row by row (every k-th pixel of every k-th row
//! when the map is wider or taller than [`MAX_SIDE`] pixels), coloured with the viridis colour
//! map between its 2nd and 98th percentiles (no data in grey), and drawn with a colour bar by
//! `plotters` on its bitmap backend (fonts compiled in, as in [`crate::report::plots`]).

use super::pixel::band_names;
use super::reader::Raster;
use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// Longest side of the picture's raster part, in map pixels after subsampling.
pub const MAX_SIDE: u32 = 1024;

/// Viridis at 9 evenly spaced points (matplotlib's table, rounded).
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 44, 122),
    (59, 81, 139),
    (44, 113, 142),
    (33, 144, 141),
    (39, 173, 129),
    (92, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
];

fn viridis(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0) * (VIRIDIS.len() - 1) as f64;
    let i = (t.floor() as usize).min(VIRIDIS.len() - 2);
    let f = t - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let mix = |x: u8, y: u8| (x as f64 + (y as f64 - x as f64) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

static FONTS: Once = Once::new();

/// Renders band `band` (a name of [`band_names`]) of the map `map` to `png`.
pub fn render(map: &Path, band: &str, png: &Path) -> Result<()> {
    let names = band_names();
    let Some(b) = names.iter().position(|n| n == band) else {
        bail!(
            "--preview-band {band}: not a band of the map ({})",
            names.join(", ")
        );
    };
    let mut r = Raster::open(map)?;
    if r.bands as usize != names.len() {
        bail!(
            "{}: {} bands, not a map of this version",
            map.display(),
            r.bands
        );
    }
    let step = r.width.max(r.height).div_ceil(MAX_SIDE).max(1);
    let (w, h) = (r.width.div_ceil(step), r.height.div_ceil(step));
    let mut values = Vec::with_capacity((w * h) as usize);
    let mut row = vec![0.0; r.width as usize];
    for y in (0..r.height).step_by(step as usize) {
        r.read_band(b as u16, 0, y, 1, &mut row)?;
        values.extend(row.iter().step_by(step as usize).copied());
    }
    let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        bail!(
            "{}: band {band} holds no value (all no data)",
            map.display()
        );
    }
    finite.sort_by(f64::total_cmp);
    let q = |p: f64| finite[((finite.len() - 1) as f64 * p).round() as usize];
    let (lo, hi) = (q(0.02), q(0.98));
    let span = if hi > lo { hi - lo } else { 1.0 };

    // Small maps are drawn enlarged (each axis to about 600 × 300 screen pixels at least).
    let (zx, zy) = ((600 / w).max(1), (300 / h).max(1));
    let (iw, ih) = (w * zx, h * zy);
    let (margin, bar_w, label_w) = (16u32, 24u32, 90u32);
    let size = (iw + 2 * margin + bar_w + label_w, ih + 2 * margin + 30);
    FONTS.call_once(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            let _ = plotters::style::register_font("sans-serif", style, dejavu::sans::regular());
        }
    });
    let root = BitMapBackend::new(png, size).into_drawing_area();
    let e = |e: &dyn std::fmt::Display| anyhow!("{}: cannot draw: {e}", png.display());
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let top = margin as i32 + 24;
    root.draw(&Text::new(
        format!(
            "{band} ({}×{} px{}{})",
            r.width,
            r.height,
            if step > 1 {
                format!(", every {step}th shown")
            } else {
                String::new()
            },
            if (zx, zy) != (1, 1) {
                format!(", each drawn {zx}×{zy}")
            } else {
                String::new()
            }
        ),
        (margin as i32, 6),
        ("sans-serif", 16).into_font(),
    ))
    .map_err(|x| e(&x))?;
    for (i, v) in values.iter().enumerate() {
        let (x, y) = ((i as u32 % w) * zx, (i as u32 / w) * zy);
        let c = if v.is_finite() {
            viridis((v - lo) / span)
        } else {
            RGBColor(200, 200, 200)
        };
        let (x0, y0) = (margin as i32 + x as i32, top + y as i32);
        root.draw(&Rectangle::new(
            [(x0, y0), (x0 + zx as i32, y0 + zy as i32)],
            c.filled(),
        ))
        .map_err(|x| e(&x))?;
    }
    // Colour bar with its ends and middle labelled.
    let bx = (margin + iw + margin) as i32;
    for k in 0..ih {
        let t = 1.0 - k as f64 / (ih.max(2) - 1) as f64;
        root.draw(&Rectangle::new(
            [
                (bx, top + k as i32),
                (bx + bar_w as i32, top + k as i32 + 1),
            ],
            viridis(t).filled(),
        ))
        .map_err(|x| e(&x))?;
    }
    for (t, y) in [(1.0, 0), (0.5, ih as i32 / 2), (0.0, ih as i32 - 12)] {
        root.draw(&Text::new(
            format!("{:.3}", lo + span * t),
            (bx + bar_w as i32 + 4, top + y),
            ("sans-serif", 13).into_font(),
        ))
        .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
