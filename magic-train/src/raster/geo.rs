//! GeoTIFF georeferencing: the tags read from an input and written, unchanged, to the map.
//!
//! A GeoTIFF places its pixel grid with either a tie point (`ModelTiepointTag`, 33922) and a
//! pixel size (`ModelPixelScaleTag`, 33550), or an affine matrix (`ModelTransformationTag`,
//! 34264), and names the coordinate reference system in the key directory
//! (`GeoKeyDirectoryTag`, 34735, with its `GeoDoubleParamsTag` 34736 and `GeoAsciiParamsTag`
//! 34737). The map copies these tags as they are; only a `--window` shifts the tie point (or the
//! matrix's translation) to the window's first pixel. A file with none of them, or with a grid but
//! no CRS (or a CRS but no grid), is mapped on its pixel grid with a warning.

use super::writer::TagValue;
use tiff::decoder::ifd::Value;
use tiff::tags::Tag;

/// Tag numbers.
pub const MODEL_PIXEL_SCALE: u16 = 33550;
/// Tie points (raster i, j, k → model x, y, z).
pub const MODEL_TIEPOINT: u16 = 33922;
/// Affine raster → model matrix (4 × 4, row-major).
pub const MODEL_TRANSFORMATION: u16 = 34264;
/// GeoKey directory.
pub const GEO_KEY_DIRECTORY: u16 = 34735;
/// Double-valued GeoKeys.
pub const GEO_DOUBLE_PARAMS: u16 = 34736;
/// ASCII GeoKeys.
pub const GEO_ASCII_PARAMS: u16 = 34737;
/// GDAL's XML metadata (band descriptions).
pub const GDAL_METADATA: u16 = 42112;
/// GDAL's no-data value (ASCII).
pub const GDAL_NODATA: u16 = 42113;

/// The georeferencing tags of one file, as read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeoRef {
    /// Pixel size (x, y, z).
    pub pixel_scale: Option<Vec<f64>>,
    /// Tie points, six values each.
    pub tiepoints: Option<Vec<f64>>,
    /// 16 values.
    pub transformation: Option<Vec<f64>>,
    /// The key directory (header + keys).
    pub key_directory: Option<Vec<u16>>,
    /// Double parameters.
    pub double_params: Option<Vec<f64>>,
    /// ASCII parameters.
    pub ascii_params: Option<String>,
    /// Tags present with a type or length that cannot be right (dropped, reported).
    pub malformed: Vec<&'static str>,
}

fn doubles(v: Value) -> Option<Vec<f64>> {
    let one = |v: &Value| match *v {
        Value::Double(x) => Some(x),
        Value::Float(x) => Some(x as f64),
        _ => None,
    };
    match v {
        Value::List(l) => l.iter().map(one).collect(),
        v => one(&v).map(|x| vec![x]),
    }
}

fn shorts(v: Value) -> Option<Vec<u16>> {
    let one = |v: &Value| match *v {
        Value::Short(x) => Some(x),
        _ => None,
    };
    match v {
        Value::List(l) => l.iter().map(one).collect(),
        v => one(&v).map(|x| vec![x]),
    }
}

impl GeoRef {
    /// Reads the georeferencing tags of the decoder's current image. Tags that are present but
    /// malformed are dropped and listed in [`GeoRef::malformed`]; I/O errors are errors.
    pub fn read<R: std::io::Read + std::io::Seek>(
        d: &mut tiff::decoder::Decoder<R>,
    ) -> tiff::TiffResult<GeoRef> {
        let mut g = GeoRef::default();
        let mut get = |tag: Tag| d.find_tag(tag);
        if let Some(v) = get(Tag::ModelPixelScaleTag)? {
            g.pixel_scale = doubles(v).filter(|v| v.len() == 3 && v.iter().all(|x| x.is_finite()));
            if g.pixel_scale.is_none() {
                g.malformed.push("ModelPixelScale");
            }
        }
        if let Some(v) = get(Tag::ModelTiepointTag)? {
            g.tiepoints = doubles(v)
                .filter(|v| !v.is_empty() && v.len() % 6 == 0 && v.iter().all(|x| x.is_finite()));
            if g.tiepoints.is_none() {
                g.malformed.push("ModelTiepoint");
            }
        }
        if let Some(v) = get(Tag::ModelTransformationTag)? {
            g.transformation =
                doubles(v).filter(|v| v.len() == 16 && v.iter().all(|x| x.is_finite()));
            if g.transformation.is_none() {
                g.malformed.push("ModelTransformation");
            }
        }
        if let Some(v) = get(Tag::GeoKeyDirectoryTag)? {
            g.key_directory = shorts(v)
                .filter(|k| k.len() >= 4 && k.len() % 4 == 0 && k[3] as usize == k.len() / 4 - 1);
            if g.key_directory.is_none() {
                g.malformed.push("GeoKeyDirectory");
            }
        }
        if let Some(v) = get(Tag::GeoDoubleParamsTag)? {
            g.double_params = doubles(v);
            if g.double_params.is_none() {
                g.malformed.push("GeoDoubleParams");
            }
        }
        if let Some(v) = get(Tag::GeoAsciiParamsTag)? {
            match v {
                Value::Ascii(s) => g.ascii_params = Some(s),
                _ => g.malformed.push("GeoAsciiParams"),
            }
        }
        Ok(g)
    }

    /// Whether the grid is placed (a transformation, or a tie point with a pixel size).
    pub fn has_grid(&self) -> bool {
        self.transformation.is_some() || (self.tiepoints.is_some() && self.pixel_scale.is_some())
    }

    /// Whether the file has a CRS (a key directory).
    pub fn has_crs(&self) -> bool {
        self.key_directory.is_some()
    }

    /// What is missing or wrong, for the warning; `None` when the georeference is complete.
    pub fn problem(&self) -> Option<String> {
        let mut p = Vec::new();
        if !self.malformed.is_empty() {
            p.push(format!(
                "malformed tags dropped: {}",
                self.malformed.join(", ")
            ));
        }
        match (self.has_grid(), self.has_crs()) {
            (true, true) => {}
            (false, false) => p.push("no georeference (no GeoTIFF tags)".into()),
            (true, false) => p.push("a pixel grid but no CRS (no GeoKeyDirectory)".into()),
            (false, true) => p.push(
                "a CRS but no pixel grid (neither ModelTransformation nor tie point + pixel scale)"
                    .into(),
            ),
        }
        (!p.is_empty()).then(|| p.join("; "))
    }

    /// The same georeference for the window whose first pixel is (`x0`, `y0`) of this grid: the
    /// first tie point (raster point I, J → model X, Y) or the matrix's translation moved by
    /// (`x0`, `y0`) pixels. Tie points without a pixel size (ground control points) cannot be
    /// moved: they are dropped (returned as the second value, for a warning).
    pub fn window(&self, x0: u32, y0: u32) -> (GeoRef, bool) {
        let mut g = self.clone();
        if x0 == 0 && y0 == 0 {
            return (g, false);
        }
        let (dx, dy) = (x0 as f64, y0 as f64);
        let mut dropped = false;
        if let Some(m) = g.transformation.as_mut() {
            // X = a·i + b·j + d, Y = e·i + f·j + h (row-major 4×4).
            m[3] += m[0] * dx + m[1] * dy;
            m[7] += m[4] * dx + m[5] * dy;
        }
        match (&mut g.tiepoints, &g.pixel_scale) {
            (Some(t), Some(s)) if t.len() == 6 => {
                // The raster point (I, J) is at (X, Y); pixel (x0, y0) is at
                // X + (x0 − I)·sx, Y − (y0 − J)·sy: write it as the tie point of (0, 0).
                let (i, j) = (t[0], t[1]);
                t[3] += (dx - i) * s[0];
                t[4] -= (dy - j) * s[1];
                t[0] = 0.0;
                t[1] = 0.0;
            }
            (Some(_), _) => {
                g.tiepoints = None;
                dropped = true;
            }
            _ => {}
        }
        (g, dropped)
    }

    /// The tags to write (absent ones left out).
    pub fn tags(&self) -> Vec<(u16, TagValue)> {
        let mut t = Vec::new();
        if let Some(v) = &self.pixel_scale {
            t.push((MODEL_PIXEL_SCALE, TagValue::Double(v.clone())));
        }
        if let Some(v) = &self.tiepoints {
            t.push((MODEL_TIEPOINT, TagValue::Double(v.clone())));
        }
        if let Some(v) = &self.transformation {
            t.push((MODEL_TRANSFORMATION, TagValue::Double(v.clone())));
        }
        if let Some(v) = &self.key_directory {
            t.push((GEO_KEY_DIRECTORY, TagValue::Short(v.clone())));
        }
        if let Some(v) = &self.double_params {
            t.push((GEO_DOUBLE_PARAMS, TagValue::Double(v.clone())));
        }
        if let Some(v) = &self.ascii_params {
            // The reader returns the text without its final NUL; the writer adds it back.
            t.push((GEO_ASCII_PARAMS, TagValue::Ascii(v.clone())));
        }
        t
    }

    /// A UTM georeference (WGS 84, EPSG 326zz north): upper-left corner (`x`, `y`) in metres,
    /// square pixels of `size` metres — what a Sentinel-2 L2A tile carries.
    pub fn utm_north(zone: u16, x: f64, y: f64, size: f64) -> GeoRef {
        GeoRef {
            pixel_scale: Some(vec![size, size, 0.0]),
            tiepoints: Some(vec![0.0, 0.0, 0.0, x, y, 0.0]),
            // Version 1.1.0, 3 keys: GTModelType = projected, GTRasterType = PixelIsArea,
            // ProjectedCSType = EPSG 32600 + zone.
            key_directory: Some(vec![
                1,
                1,
                0,
                3,
                1024,
                0,
                1,
                1,
                1025,
                0,
                1,
                1,
                3072,
                0,
                1,
                32600 + zone,
            ]),
            ..GeoRef::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_moves_the_tie_point_and_the_matrix() {
        let g = GeoRef::utm_north(33, 500_000.0, 5_300_000.0, 10.0);
        assert!(g.problem().is_none());
        let (w, dropped) = g.window(3, 5);
        assert!(!dropped);
        assert_eq!(
            w.tiepoints.unwrap(),
            vec![0.0, 0.0, 0.0, 500_030.0, 5_299_950.0, 0.0]
        );
        let m = GeoRef {
            transformation: Some(vec![
                10.0, 0.0, 0.0, 100.0, 0.0, -10.0, 0.0, 200.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                1.0,
            ]),
            ..GeoRef::default()
        };
        let (w, _) = m.window(2, 1);
        let t = w.transformation.unwrap();
        assert_eq!((t[3], t[7]), (120.0, 190.0));
        assert!(m.problem().unwrap().contains("no CRS"));
        let gcp = GeoRef {
            tiepoints: Some(vec![0.0; 12]),
            ..GeoRef::default()
        };
        assert!(gcp.window(1, 1).1, "ground control points are dropped");
        assert!(GeoRef::default()
            .problem()
            .unwrap()
            .contains("no georeference"));
    }
}
