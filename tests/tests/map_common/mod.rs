//! Shared by the `map_*` tests: the `magic` binary, a small trained RTM model, the test split of
//! `s2/` written as a Sentinel-2-like GeoTIFF, and GDAL's command-line tools.
#![allow(dead_code)]

use magic_core::rtm::Geometry;
use magic_train::raster::geo::GeoRef;
use magic_train::raster::writer::{Sample, StripWriter, TiffSpec};
use magic_train::{train_model, ModelKind, RtmProblem, TrainConfig};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The shared data folder (`MAGIC_DATA` or `../shared/data`); a missing `s2/` or `rtm/` is a
/// failure.
pub fn data() -> PathBuf {
    let d = magic_tests::shared_data();
    assert!(
        d.join("s2/test.csv").is_file() && d.join("rtm/prospect_d_coefficients.csv").is_file(),
        "s2/ or rtm/ missing in {} (set MAGIC_DATA)",
        d.display()
    );
    d
}

/// The `magic` executable of this build (cargo builds it on first use).
pub fn magic_bin() -> PathBuf {
    magic_tests::magic_bin()
}

/// Runs `magic` with `args`; returns (success, stderr).
pub fn magic(args: &[&str]) -> (bool, String) {
    let out = Command::new(magic_bin())
        .args(args)
        .env("MAGIC_DATA", data())
        .output()
        .expect("running magic");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A small RTM model of `variant` (physical geometry, 300 training spectra, 2 epochs), encoded.
pub fn small_model(variant: ModelKind, seed: u64) -> Vec<u8> {
    let d = data();
    let mut s = RtmProblem::read(&d.join("s2"), &d.join("rtm"), Geometry::Physical).unwrap();
    s.data.train = s.data.train.head(300);
    s.data.valid = s.data.valid.head(200);
    let cfg = TrainConfig {
        epochs: 2,
        progress: false,
        ..TrainConfig::s2()
    };
    let (m, _) = train_model(&s, variant, &[], &cfg, seed).unwrap();
    m.encode().unwrap()
}

/// The map's CRS and grid in the tests: UTM zone 33 N (EPSG:32633), 10 m pixels.
pub fn test_geo() -> GeoRef {
    GeoRef::utm_north(33, 499_980.0, 5_300_040.0, 10.0)
}

/// DN offset of processing baseline 04.00 on.
pub const OFFSET: f64 = -1000.0;

/// The test split of `s2/` as an image: one column per site (sites ordered by species, then
/// id), one row per acquisition date, the 11 bands as L2A digital numbers with the −1000 offset
/// (DN = round(reflectance · 10 000) + 1000; 0 = no data where a site has no spectrum that day).
pub struct Scene {
    /// Columns (sites), rows (dates).
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Band after band, row after row.
    pub dn: Vec<u16>,
    /// Site ids of the columns.
    pub sites: Vec<u64>,
    /// Dates of the rows.
    pub dates: Vec<String>,
}

impl Scene {
    /// Builds it from the data.
    pub fn test_split() -> Scene {
        let d = magic_train::rtm::data::read_dir(&data().join("s2")).unwrap();
        let t = &d.test;
        let mut sites: Vec<(String, u64)> = t
            .labels
            .iter()
            .cloned()
            .zip(t.ids.iter().copied())
            .collect();
        sites.sort();
        sites.dedup();
        let mut dates = t.dates.clone();
        dates.sort();
        dates.dedup();
        let (w, h) = (sites.len() as u32, dates.len() as u32);
        let nb = d.n_obs();
        let mut dn = vec![0u16; nb * (w * h) as usize];
        for i in 0..t.len() {
            let x = sites
                .iter()
                .position(|s| s.1 == t.ids[i] && s.0 == t.labels[i])
                .unwrap();
            let y = dates.iter().position(|s| *s == t.dates[i]).unwrap();
            for b in 0..nb {
                let refl = t.x[i][b] as f64 * d.scale[b] + d.mean[b];
                let v = ((refl * 10_000.0).round() - OFFSET).clamp(1.0, 65_535.0);
                dn[(b * h as usize + y) * w as usize + x] = v as u16;
            }
        }
        Scene {
            width: w,
            height: h,
            dn,
            sites: sites.into_iter().map(|s| s.1).collect(),
            dates,
        }
    }

    /// Number of bands.
    pub fn bands(&self) -> usize {
        self.dn.len() / (self.width * self.height) as usize
    }

    /// The reflectances of pixel (x, y) as the map reads them, or `None` for no data.
    pub fn reflectance(&self, x: u32, y: u32) -> Option<Vec<f32>> {
        let n = (self.width * self.height) as usize;
        let i = (y * self.width + x) as usize;
        let v: Vec<u16> = (0..self.bands()).map(|b| self.dn[b * n + i]).collect();
        if v.iter().all(|&d| d == 0) {
            return None;
        }
        Some(
            v.iter()
                .map(|&d| magic_train::raster::input::to_reflectance(d as f64, true, None, OFFSET))
                .collect(),
        )
    }

    /// Writes it as a GeoTIFF (band-interleaved, deflate, 4-row strips) with `geo`'s tags.
    pub fn write(&self, path: &Path, geo: &GeoRef) {
        let n = (self.width * self.height) as usize;
        let spec = TiffSpec {
            width: self.width,
            height: self.height,
            bands: self.bands() as u16,
            sample: Sample::U16,
            planar: true,
            rows_per_strip: 4,
            deflate: true,
            big: Some(false),
            tags: geo.tags(),
        };
        let mut w = StripWriter::new(std::fs::File::create(path).unwrap(), spec).unwrap();
        let mut r = 0;
        while r < self.height {
            let rows = 4.min(self.height - r);
            let mut buf = Vec::new();
            for b in 0..self.bands() {
                let plane = &self.dn[b * n..(b + 1) * n];
                for v in &plane[(r * self.width) as usize..((r + rows) * self.width) as usize] {
                    buf.extend(v.to_le_bytes());
                }
            }
            w.write_rows(rows, &buf).unwrap();
            r += rows;
        }
        w.finish().unwrap();
    }

    /// The spectra as a CSV for `magic invert` (columns B02 … B12 of the model; one row per
    /// pixel with data, in raster order), with the reflectances exactly as the map reads them.
    pub fn write_csv(&self, path: &Path, bands: &[String]) -> Vec<(u32, u32)> {
        let mut text = bands.join(",");
        text.push('\n');
        let mut pixels = Vec::new();
        for y in 0..self.height {
            for x in 0..self.width {
                if let Some(r) = self.reflectance(x, y) {
                    // f64 printed exactly, read back by `magic invert` as this f64, then as f32.
                    let n = (self.width * self.height) as usize;
                    let i = (y * self.width + x) as usize;
                    let f: Vec<String> = (0..self.bands())
                        .map(|b| format!("{}", (self.dn[b * n + i] as f64 + OFFSET) / 10_000.0))
                        .collect();
                    assert_eq!(r.len(), f.len());
                    text.push_str(&f.join(","));
                    text.push('\n');
                    pixels.push((x, y));
                }
            }
        }
        std::fs::write(path, text).unwrap();
        pixels
    }
}

/// `gdalinfo -json` of a file. GDAL is part of the test environment (`scripts/test-all.sh`
/// installs Debian's `gdal-bin`): a missing `gdalinfo` fails the test.
pub fn gdalinfo(path: &Path) -> serde_json::Value {
    let out = Command::new("gdalinfo")
        .args(["-json", "-mdd", "all"])
        .arg(path)
        .output()
        .unwrap_or_else(|e| {
            panic!("gdalinfo not found ({e}): install Debian's gdal-bin (scripts/test-all.sh does)")
        });
    assert!(
        out.status.success(),
        "gdalinfo {} failed: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Runs `gdal_translate` with `args` (fails the test when GDAL is missing).
pub fn gdal_translate(src: &Path, dst: &Path, args: &[&str]) {
    let out = Command::new("gdal_translate")
        .args(["-q"])
        .args(args)
        .arg(src)
        .arg(dst)
        .output()
        .unwrap_or_else(|e| {
            panic!("gdal_translate not found ({e}): install Debian's gdal-bin (scripts/test-all.sh does)")
        });
    assert!(
        out.status.success(),
        "gdal_translate {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Reads every band of a map (band-major f32) through the crate's own reader.
pub fn read_map(path: &Path) -> (u32, u32, Vec<Vec<f32>>) {
    let mut r = magic_train::raster::reader::Raster::open(path).unwrap();
    let (w, h) = (r.width, r.height);
    let bands = (0..r.bands)
        .map(|b| {
            let mut v = vec![0.0; (w * h) as usize];
            r.read_band(b, 0, 0, h, &mut v).unwrap();
            v.into_iter().map(|x| x as f32).collect()
        })
        .collect();
    (w, h, bands)
}

/// The model the figures use: `MAGIC_MAP_MODEL` if set, else a C trained here as `magic train rtm
/// --variant C --geometry physical --limit 2000 --epochs 3 --seed 1` would.
pub fn figures_model() -> Vec<u8> {
    if let Some(p) = std::env::var_os("MAGIC_MAP_MODEL") {
        return std::fs::read(p).unwrap();
    }
    let d = data();
    let mut s = RtmProblem::read(&d.join("s2"), &d.join("rtm"), Geometry::Physical).unwrap();
    s.data.train = s.data.train.head(2000);
    let cfg = TrainConfig {
        epochs: 3,
        progress: false,
        ..TrainConfig::s2()
    };
    let (m, _) = train_model(&s, ModelKind::C, &[], &cfg, 1).unwrap();
    m.encode().unwrap()
}
