//! The bands of an image, in the model's order, as reflectance.
//!
//! An input is one multi-band GeoTIFF whose bands are the model's (in its order, or named with
//! `--bands` in the file's order), or a folder holding one single-band file per band (a file
//! belongs to band `B05` when `B05` is a word of its name: `T33UWP_20180601_B05.tif`). Integer
//! samples are Sentinel-2 L2A digital numbers: reflectance = (DN + offset) / 10 000, DN 0 (and
//! the file's GDAL_NODATA value) = no data. Float samples are reflectance already (NaN and the
//! no-data value = no data).

use super::reader::Raster;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Digital numbers per unit of reflectance in Sentinel-2 L2A products.
pub const QUANTIFICATION: f64 = 10_000.0;

/// Where each of the model's bands is read.
pub struct Input {
    /// Open files.
    files: Vec<Raster>,
    /// Per model band: (file, sample).
    map: Vec<(usize, u16)>,
    /// Added to digital numbers before dividing by [`QUANTIFICATION`].
    pub offset: f64,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Scratch for one band of a window.
    scratch: Vec<f64>,
}

/// Whether `word` is a word of `name` (bounded by non-alphanumerics or the ends).
fn has_word(name: &str, word: &str) -> bool {
    let n = name.to_ascii_uppercase();
    let w = word.to_ascii_uppercase();
    n.match_indices(&w).any(|(i, _)| {
        let before = n[..i].chars().last();
        let after = n[i + w.len()..].chars().next();
        !before.is_some_and(|c| c.is_ascii_alphanumeric())
            && !after.is_some_and(|c| c.is_ascii_alphanumeric())
    })
}

impl Input {
    /// Opens `path` (a file or a folder) for a model observing `bands` (names as in
    /// [`magic_core::rtm::S2_BANDS`]). `names` is the file's band order (`--bands`), if given.
    pub fn open(
        path: &Path,
        bands: &[String],
        names: Option<&[String]>,
        offset: f64,
    ) -> Result<Input> {
        let (files, map) = if path.is_dir() {
            if names.is_some() {
                bail!("--bands names the bands of one multi-band file; {} is a folder (its files are matched to bands by name)", path.display());
            }
            let mut entries: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("{}: cannot list the folder", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                        e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff")
                    })
                })
                .collect();
            entries.sort();
            let mut files = Vec::new();
            let mut map = Vec::new();
            for b in bands {
                let hits: Vec<&PathBuf> = entries
                    .iter()
                    .filter(|p| {
                        p.file_stem()
                            .and_then(|s| s.to_str())
                            .is_some_and(|s| has_word(s, b))
                    })
                    .collect();
                match hits.as_slice() {
                    [one] => {
                        let r = Raster::open(one)?;
                        if r.bands != 1 {
                            bail!("{}: {} bands; a band folder holds one single-band file per band", one.display(), r.bands);
                        }
                        files.push(r);
                        map.push((files.len() - 1, 0));
                    }
                    [] => bail!("{}: no .tif file for band {b} (expected a file with `{b}` as a word of its name, e.g. `…_{b}.tif`)", path.display()),
                    many => bail!(
                        "{}: several files for band {b}: {}",
                        path.display(),
                        many.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
                    ),
                }
            }
            (files, map)
        } else {
            let r = Raster::open(path)?;
            let map = match names {
                None => {
                    if r.bands as usize != bands.len() {
                        bail!(
                            "{}: {} bands, the model expects {} ({}); name the file's bands in order with --bands",
                            path.display(),
                            r.bands,
                            bands.len(),
                            bands.join(" ")
                        );
                    }
                    (0..bands.len() as u16).map(|s| (0, s)).collect()
                }
                Some(names) => {
                    if names.len() != r.bands as usize {
                        bail!(
                            "{}: {} bands, --bands names {}",
                            path.display(),
                            r.bands,
                            names.len()
                        );
                    }
                    bands
                        .iter()
                        .map(
                            |b| match names.iter().position(|n| n.eq_ignore_ascii_case(b)) {
                                Some(s) => Ok((0, s as u16)),
                                None => bail!(
                                    "--bands {}: the model's band {b} is not among them",
                                    names.join(",")
                                ),
                            },
                        )
                        .collect::<Result<_>>()?
                }
            };
            (vec![r], map)
        };
        let (width, height) = (files[0].width, files[0].height);
        for f in &files {
            if (f.width, f.height) != (width, height) {
                bail!(
                    "{}: {}×{} pixels, {} has {width}×{height}: resample the bands to one grid first",
                    f.path().display(),
                    f.width,
                    f.height,
                    files[0].path().display()
                );
            }
        }
        Ok(Input {
            files,
            map,
            offset,
            width,
            height,
            scratch: Vec::new(),
        })
    }

    /// The first file (its georeference is the map's).
    pub fn first(&self) -> &Raster {
        &self.files[0]
    }

    /// Reflectance of the window (`x0`, `y0`, `cols`, `rows`), pixel after pixel, the model's bands
    /// in order for each (`rows × cols × bands` values; NaN = no data).
    pub fn read(
        &mut self,
        x0: u32,
        y0: u32,
        cols: u32,
        rows: u32,
        out: &mut Vec<f32>,
    ) -> Result<()> {
        let n = (rows * cols) as usize;
        let nb = self.map.len();
        out.clear();
        out.resize(n * nb, f32::NAN);
        self.scratch.resize(n, 0.0);
        for (k, &(f, s)) in self.map.iter().enumerate() {
            let file = &mut self.files[f];
            file.read_band(s, x0, y0, rows, &mut self.scratch)?;
            let (integer, nodata) = (file.kind.is_integer(), file.nodata);
            for (i, &v) in self.scratch.iter().enumerate() {
                out[i * nb + k] = to_reflectance(v, integer, nodata, self.offset);
            }
        }
        Ok(())
    }
}

/// A raw sample as reflectance (f32, as the inversion takes it; NaN = no data).
///
/// ```
/// use magic_train::raster::input::to_reflectance;
/// assert_eq!(to_reflectance(1234.0, true, None, -1000.0), 0.0234);
/// assert!(to_reflectance(0.0, true, None, -1000.0).is_nan());
/// assert_eq!(to_reflectance(0.25, false, None, -1000.0), 0.25);
/// ```
pub fn to_reflectance(v: f64, integer: bool, nodata: Option<f64>, offset: f64) -> f32 {
    if v.is_nan() || nodata.is_some_and(|nd| v == nd) {
        return f32::NAN;
    }
    if integer {
        if v == 0.0 {
            f32::NAN
        } else {
            ((v + offset) / QUANTIFICATION) as f32
        }
    } else {
        v as f32
    }
}

#[cfg(test)]
mod tests {
    use super::has_word;

    #[test]
    fn band_names_are_words() {
        assert!(has_word("T33UWP_20180601_B05_20m", "B05"));
        assert!(has_word("b8a", "B8A"));
        assert!(!has_word("T33UWP_B8A", "B08"));
        assert!(!has_word("B051", "B05"));
        assert!(has_word("B05", "B05"));
    }
}
