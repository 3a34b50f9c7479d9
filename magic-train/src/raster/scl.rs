//! The Sentinel-2 L2A scene classification (SCL) as a mask.
//!
//! Classes of the L2A product definition (ESA, Sentinel-2 Level-2A Product Format
//! Specification): 0 no data, 1 saturated or defective, 2 dark area pixels (topographic or cast
//! shadows), 3 cloud shadows, 4 vegetation, 5 not vegetated, 6 water, 7 unclassified, 8 cloud
//! (medium probability), 9 cloud (high probability), 10 thin cirrus, 11 snow or ice. A pixel is
//! masked when its class is one of [`MASKED`]: no data, saturated, cloud shadow, water, the
//! clouds, cirrus and snow. Dark-area pixels, vegetation, bare ground and unclassified pixels
//! are inverted. Values above 11 are not classes: an error.

use super::reader::Raster;
use anyhow::{bail, Result};
use std::path::Path;

/// The masked classes.
pub const MASKED: [u8; 8] = [0, 1, 3, 6, 8, 9, 10, 11];

/// Whether SCL class `c` is masked.
///
/// ```
/// use magic_train::raster::scl::masked;
/// assert!(masked(9) && masked(3) && masked(0));
/// assert!(!masked(4) && !masked(5) && !masked(7));
/// ```
pub fn masked(c: u8) -> bool {
    MASKED.contains(&c)
}

/// An SCL raster on the input's grid.
pub struct Scl {
    raster: Raster,
    scratch: Vec<f64>,
}

impl Scl {
    /// Opens `path` and checks it is one integer band of `width` × `height` pixels.
    pub fn open(path: &Path, width: u32, height: u32) -> Result<Scl> {
        let raster = Raster::open(path)?;
        if (raster.width, raster.height) != (width, height) {
            bail!(
                "{}: scene classification of {}×{} pixels, the image has {width}×{height} (resample the 20 m SCL to the bands' grid first, nearest neighbour)",
                path.display(),
                raster.width,
                raster.height
            );
        }
        if raster.bands != 1 || !raster.kind.is_integer() {
            bail!(
                "{}: {} bands of {}; an SCL raster is one band of integer classes",
                path.display(),
                raster.bands,
                raster.kind
            );
        }
        Ok(Scl {
            raster,
            scratch: Vec::new(),
        })
    }

    /// Masks the window: sets every band of each masked pixel of `obs` (pixel after pixel,
    /// `bands` values each) to NaN; returns how many pixels were masked.
    pub fn apply(
        &mut self,
        x0: u32,
        y0: u32,
        cols: u32,
        rows: u32,
        bands: usize,
        obs: &mut [f32],
    ) -> Result<usize> {
        let n = (rows * cols) as usize;
        self.scratch.resize(n, 0.0);
        self.raster.read_band(0, x0, y0, rows, &mut self.scratch)?;
        let mut count = 0;
        for (i, &c) in self.scratch.iter().enumerate() {
            if !(0.0..=11.0).contains(&c) || c.fract() != 0.0 {
                bail!(
                    "{}: value {c} at column {}, row {} is not an SCL class (0 to 11)",
                    self.raster.path().display(),
                    x0 as usize + i % cols as usize,
                    y0 as usize + i / cols as usize
                );
            }
            if masked(c as u8) {
                obs[i * bands..(i + 1) * bands].fill(f32::NAN);
                count += 1;
            }
        }
        Ok(count)
    }
}
