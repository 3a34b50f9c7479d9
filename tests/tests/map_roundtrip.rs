//! `magic map` on real spectra: the test split of `s2/` written as a Sentinel-2-like GeoTIFF (L2A
//! digital numbers with the −1000 offset, UTM 33 N, 10 m pixels) gives, pixel by pixel, what
//! `magic invert` gives on the same spectra as CSV; the map opens in GDAL with the input's CRS and
//! grid; every input layout (tiled, striped, pixel- or band-interleaved, deflate/LZW/zstd,
//! BigTIFF, float reflectance, a folder of band files, another band order) gives the same map; a
//! window is the same block of the full map on a moved grid; the SCL masks its classes.
//!
//! Needs the shared data (`MAGIC_DATA`) and GDAL's `gdalinfo`/`gdal_translate` (Debian's
//! `gdal-bin`, installed by `scripts/test-all.sh`). The model is a small C trained here, or the
//! file `MAGIC_MAP_MODEL` names; `MAGIC_MAP_PNG=FILE` keeps the LAI picture of the first test (the
//! README's).

mod map_common;

use magic_core::{invert_at, Model, Workspace};
use magic_tests::TempDir;
use magic_train::data::records::model_channels;
use magic_train::raster::map::{self, MapOptions};
use magic_train::raster::pixel::{band_names, N_OUT, N_VARIABLES};
use magic_train::raster::writer::{Sample, StripWriter, TiffSpec};
use magic_train::ModelKind;
use map_common::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Map (f32) against the library's f64 inversion: relative, f32 rounding is ~6e-8.
const LIBRARY_REL: f64 = 1e-5;
/// Map against `magic invert`'s CSV: 1e-5 relative plus half a unit of the CSV's sixth decimal.
const CSV_REL: f64 = 1e-5;
const CSV_ABS: f64 = 5e-7;

/// A test's own folder (removed when the test ends) with the model and the scene's image, and
/// the scene.
struct Fixture {
    dir: TempDir,
    model: PathBuf,
    scene: &'static Scene,
    image: PathBuf,
}

/// The model (`MAGIC_MAP_MODEL` or a small C trained here) and the scene, made once for all the
/// tests; each test writes them into a folder of its own.
fn fixture() -> Fixture {
    static F: OnceLock<(Vec<u8>, Scene)> = OnceLock::new();
    let (bytes, scene) = F.get_or_init(|| {
        let bytes = match std::env::var_os("MAGIC_MAP_MODEL") {
            Some(m) => std::fs::read(m).unwrap(),
            None => small_model(ModelKind::C, 3),
        };
        (bytes, Scene::test_split())
    });
    let dir = TempDir::new("map-roundtrip");
    let model = dir.join("C.magic");
    std::fs::write(&model, bytes).unwrap();
    let image = dir.join("test_split.tif");
    scene.write(&image, &test_geo());
    Fixture {
        dir,
        model,
        scene,
        image,
    }
}

/// The map of `input` to `output` with `f`'s model.
fn options(f: &Fixture, input: &Path, output: &Path, residual: bool) -> MapOptions {
    MapOptions {
        model: f.model.clone(),
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        offset: OFFSET,
        scl: None,
        residual,
        sd: residual,
        date: None,
        window: None,
        bands: None,
        raw_sd: false,
        preview: None,
        preview_band: "LAI".into(),
        progress: false,
        window_rows: 4,
    }
}

/// The encoder-only map of the fixture image (the reference the layouts are compared with),
/// made once, in `f`'s folder.
fn base_map(f: &Fixture) -> &'static (u32, u32, Vec<Vec<f32>>) {
    static M: OnceLock<(u32, u32, Vec<Vec<f32>>)> = OnceLock::new();
    M.get_or_init(|| {
        let out = f.dir.join("base.tif");
        map::run(&options(f, &f.image, &out, false)).unwrap();
        read_map(&out)
    })
}

fn same_bits(a: &[Vec<f32>], b: &[Vec<f32>], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: band count");
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.len(), y.len(), "{what}: band {k} size");
        for (i, (p, q)) in x.iter().zip(y).enumerate() {
            assert!(
                p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()),
                "{what}: band {k} pixel {i}: {p} vs {q}"
            );
        }
    }
}

/// `magic map --sd --preview` (the residual and the standard deviations) on the fixture image: the map's path (the preview must be
/// written; `MAGIC_MAP_PNG` keeps it).
fn map_through_the_cli(f: &Fixture) -> PathBuf {
    let out = f.dir.join("map.tif");
    let png = f.dir.join("lai.png");
    let m = f.model.to_str().unwrap();
    let (ok, err) = magic(&[
        "map",
        "--model",
        m,
        "--input",
        f.image.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "--offset",
        "-1000",
        "--sd",
        "--preview",
        png.to_str().unwrap(),
    ]);
    assert!(ok, "magic map failed: {err}");
    eprintln!("{}", err.trim());
    assert!(png.is_file(), "no preview written");
    if let Some(keep) = std::env::var_os("MAGIC_MAP_PNG") {
        std::fs::copy(&png, &keep).unwrap();
    }
    out
}

/// The map at `out` against the same spectra through `magic invert` (its CSV) and `invert_at`
/// (f64), pixel by pixel; pixels without a spectrum are no data in every band, and nearly every
/// pixel has all standard deviations.
fn check_against_invert(f: &Fixture, out: &Path) {
    let m = f.model.to_str().unwrap();
    let bytes = std::fs::read(&f.model).unwrap();
    let model = Model::decode(&bytes).unwrap();
    let bands = model_channels(&model).unwrap();
    let csv = f.dir.join("spectra.csv");
    let pixels = f.scene.write_csv(&csv, &bands);
    let res = f.dir.join("invert.csv");
    let (ok, err) = magic(&[
        "invert",
        "--model",
        m,
        "--input",
        csv.to_str().unwrap(),
        "--output",
        res.to_str().unwrap(),
    ]);
    assert!(ok, "magic invert failed: {err}");
    let text = std::fs::read_to_string(&res).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let names = band_names();
    assert_eq!(&header[..N_VARIABLES + 2], &names[..N_VARIABLES + 2]);

    let (w, h, map) = read_map(out);
    assert_eq!((w, h), (f.scene.width, f.scene.height));
    assert_eq!(map.len(), N_OUT);
    let mut ws = Workspace::default();
    let (mut worst_csv, mut worst_lib, mut with_sd) = (0f64, 0f64, 0usize);
    for ((x, y), line) in pixels.iter().zip(lines) {
        let i = (y * w + x) as usize;
        let row: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let obs = f.scene.reflectance(*x, *y).unwrap();
        let inv = invert_at::<f64>(&model, &obs, f64::NAN, &mut ws).unwrap();
        let mut lib: Vec<f64> = inv.params[..inv.n_params].to_vec();
        lib.push(inv.residual_rms);
        lib.push(inv.flags.0 as f64);
        for k in 0..N_VARIABLES + 2 {
            let v = map[k][i] as f64;
            let (c, l) = (row[k], lib[k]);
            assert!(
                (v - c).abs() <= CSV_REL * c.abs() + CSV_ABS,
                "pixel ({x}, {y}) {}: map {v} vs magic invert {c}",
                names[k]
            );
            assert!(
                (v - l).abs() <= LIBRARY_REL * l.abs(),
                "pixel ({x}, {y}) {}: map {v} vs invert_at {l}",
                names[k]
            );
            worst_csv = worst_csv.max((v - c).abs() / c.abs().max(1e-30));
            worst_lib = worst_lib.max((v - l).abs() / l.abs().max(1e-30));
        }
        let sd = &map[N_VARIABLES + 2..];
        if sd.iter().all(|b| b[i].is_finite() && b[i] > 0.0) {
            with_sd += 1;
        }
    }
    // Pixels without a spectrum are no data in every band.
    let empty = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| f.scene.reflectance(x, y).is_none())
        .collect::<Vec<_>>();
    for (x, y) in &empty {
        assert!(map.iter().all(|b| b[(y * w + x) as usize].is_nan()));
    }
    eprintln!(
        "{} spectra mapped ({}×{} pixels, {} without a spectrum): largest relative difference {worst_lib:.1e} from invert_at (f64), {worst_csv:.1e} from magic invert's CSV (6 decimals); {with_sd} with all standard deviations",
        pixels.len(),
        w,
        h,
        empty.len()
    );
    assert!(
        with_sd * 100 >= pixels.len() * 99,
        "standard deviations for only {with_sd} of {} pixels",
        pixels.len()
    );
}

/// GDAL reads the map at `out` with the input's CRS and grid, the band names and the no-data
/// value.
fn check_in_gdal(f: &Fixture, out: &Path) {
    let names = band_names();
    let info = gdalinfo(out);
    let src = gdalinfo(&f.image);
    assert_eq!(info["geoTransform"], src["geoTransform"], "grid");
    let gt: Vec<f64> = serde_json::from_value(info["geoTransform"].clone()).unwrap();
    assert_eq!(gt, vec![499_980.0, 10.0, 0.0, 5_300_040.0, 0.0, -10.0]);
    let wkt = info["coordinateSystem"]["wkt"].as_str().unwrap();
    assert_eq!(wkt, src["coordinateSystem"]["wkt"].as_str().unwrap(), "CRS");
    assert!(
        wkt.contains("UTM zone 33N") && wkt.contains("ID[\"EPSG\",32633]"),
        "CRS: {wkt}"
    );
    let gbands = info["bands"].as_array().unwrap();
    assert_eq!(gbands.len(), N_OUT);
    for (b, n) in gbands.iter().zip(&names) {
        assert_eq!(b["description"].as_str(), Some(n.as_str()));
        assert_eq!(b["type"].as_str(), Some("Float32"));
        assert_eq!(b["noDataValue"].as_str(), Some("NaN"), "{b}");
    }
    eprintln!(
        "gdalinfo: {} bands, geoTransform {gt:?}, EPSG:32633",
        gbands.len()
    );
}

#[test]
fn map_equals_invert_on_the_test_split_and_opens_in_gdal() {
    let f = fixture();
    let out = map_through_the_cli(&f);
    // The same spectra through `magic invert`.
    check_against_invert(&f, &out);
    // GDAL: CRS, grid, band names, no-data value.
    check_in_gdal(&f, &out);
}

/// The layouts GDAL writes the fixture image in (name, `gdal_translate` options).
const LAYOUTS: [(&str, &[&str]); 4] = [
    (
        "tiled_zstd_pixel_bigtiff",
        &[
            "-co",
            "TILED=YES",
            "-co",
            "BLOCKXSIZE=64",
            "-co",
            "BLOCKYSIZE=16",
            "-co",
            "COMPRESS=ZSTD",
            "-co",
            "INTERLEAVE=PIXEL",
            "-co",
            "BIGTIFF=YES",
        ],
    ),
    (
        "striped_lzw_band",
        &[
            "-co",
            "COMPRESS=LZW",
            "-co",
            "PREDICTOR=2",
            "-co",
            "INTERLEAVE=BAND",
            "-co",
            "BLOCKYSIZE=3",
        ],
    ),
    (
        "tiled_deflate_band",
        &[
            "-co",
            "TILED=YES",
            "-co",
            "BLOCKXSIZE=32",
            "-co",
            "BLOCKYSIZE=32",
            "-co",
            "COMPRESS=DEFLATE",
            "-co",
            "INTERLEAVE=BAND",
        ],
    ),
    ("striped_none_pixel", &["-co", "INTERLEAVE=PIXEL"]),
];

/// The fixture's spectra as float reflectance (NaN = no data), band-interleaved, written by the
/// crate's writer to `img`.
fn write_float_reflectance(f: &Fixture, img: &Path) {
    let (w, h) = (f.scene.width, f.scene.height);
    let nb = f.scene.bands();
    let mut planes = vec![f32::NAN; nb * (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if let Some(r) = f.scene.reflectance(x, y) {
                for (b, v) in r.iter().enumerate() {
                    planes[(b * h as usize + y as usize) * w as usize + x as usize] = *v;
                }
            }
        }
    }
    let mut wr = StripWriter::new(
        std::fs::File::create(img).unwrap(),
        TiffSpec {
            width: w,
            height: h,
            bands: nb as u16,
            sample: Sample::F32,
            planar: true,
            rows_per_strip: h,
            deflate: false,
            big: None,
            tags: test_geo().tags(),
        },
    )
    .unwrap();
    wr.write_rows(
        h,
        &planes
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    wr.finish().unwrap();
}

/// A folder of one file per band, and a file with the bands in another order (`--bands`), give
/// the map `base`.
fn check_band_files(f: &Fixture, base: &[Vec<f32>]) {
    let folder = f.dir.join("bands");
    std::fs::create_dir_all(&folder).unwrap();
    let bytes = std::fs::read(&f.model).unwrap();
    let names = model_channels(&Model::decode(&bytes).unwrap()).unwrap();
    for (k, b) in names.iter().enumerate() {
        let p = folder.join(format!("T33UWP_20180601T100031_{b}_10m.tif"));
        gdal_translate(&f.image, &p, &["-b", &(k + 1).to_string()]);
    }
    let out = f.dir.join("folder_map.tif");
    map::run(&options(f, &folder, &out, false)).unwrap();
    same_bits(&read_map(&out).2, base, "folder of bands");
    let reversed = f.dir.join("reversed.tif");
    let mut args = Vec::new();
    for k in (1..=names.len()).rev() {
        args.push("-b".to_string());
        args.push(k.to_string());
    }
    gdal_translate(
        &f.image,
        &reversed,
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
    );
    let out = f.dir.join("reversed_map.tif");
    let mut o = options(f, &reversed, &out, false);
    o.bands = Some(names.iter().rev().cloned().collect());
    map::run(&o).unwrap();
    same_bits(&read_map(&out).2, base, "--bands in reverse order");
}

#[test]
fn every_layout_gives_the_same_map() {
    let f = fixture();
    let base = base_map(&f);
    for (name, args) in LAYOUTS {
        let img = f.dir.join(&format!("{name}.tif"));
        gdal_translate(&f.image, &img, args);
        let out = f.dir.join(&format!("{name}_map.tif"));
        map::run(&options(&f, &img, &out, false)).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        same_bits(&read_map(&out).2, &base.2, name);
        eprintln!("{name}: same map");
    }

    // Float reflectance (NaN = no data), written by the crate's writer.
    let img = f.dir.join("float.tif");
    write_float_reflectance(&f, &img);
    let out = f.dir.join("float_map.tif");
    map::run(&options(&f, &img, &out, false)).unwrap();
    same_bits(&read_map(&out).2, &base.2, "float reflectance");

    // A folder of one file per band, and a file with the bands in another order.
    check_band_files(&f, &base.2);
}

#[test]
fn a_window_is_the_same_block_on_a_moved_grid() {
    let f = fixture();
    let base = base_map(&f);
    let out = f.dir.join("window.tif");
    let mut o = options(&f, &f.image, &out, false);
    o.window = Some([10, 3, 50, 9]);
    map::run(&o).unwrap();
    let (w, h, m) = read_map(&out);
    assert_eq!((w, h), (50, 9));
    for (k, band) in m.iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                let a = band[(y * w + x) as usize];
                let b = base.2[k][((y + 3) * base.0 + x + 10) as usize];
                assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
            }
        }
    }
    let gt: Vec<f64> = serde_json::from_value(gdalinfo(&out)["geoTransform"].clone()).unwrap();
    assert_eq!(
        gt,
        vec![499_980.0 + 100.0, 10.0, 0.0, 5_300_040.0 - 30.0, 0.0, -10.0]
    );
    o.window = Some([250, 0, 50, 9]);
    let e = map::run(&o).unwrap_err().to_string();
    assert!(e.contains("not inside"), "{e}");
}

#[test]
fn the_scl_masks_its_classes() {
    let f = fixture();
    let base = base_map(&f);
    let (w, h) = (f.scene.width, f.scene.height);
    let classes: Vec<u8> = (0..w * h).map(|i| (i % 12) as u8).collect();
    let scl = f.dir.join("scl.tif");
    let mut wr = StripWriter::new(
        std::fs::File::create(&scl).unwrap(),
        TiffSpec {
            width: w,
            height: h,
            bands: 1,
            sample: Sample::U8,
            planar: false,
            rows_per_strip: 5,
            deflate: true,
            big: None,
            tags: vec![],
        },
    )
    .unwrap();
    wr.write_rows(h, &classes).unwrap();
    wr.finish().unwrap();
    let out = f.dir.join("scl_map.tif");
    let mut o = options(&f, &f.image, &out, false);
    o.scl = Some(scl);
    let s = map::run(&o).unwrap();
    let (_, _, m) = read_map(&out);
    let masked = [0u8, 1, 3, 6, 8, 9, 10, 11];
    assert!(m.len() >= N_OUT && base.2.len() >= N_OUT, "band count");
    for i in 0..(w * h) as usize {
        let c = classes[i];
        for (band, base_band) in m.iter().zip(&base.2).take(N_OUT) {
            if masked.contains(&c) {
                assert!(band[i].is_nan(), "class {c} not masked");
            } else {
                let (a, b) = (band[i], base_band[i]);
                assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
            }
        }
    }
    assert_eq!(
        s.masked as usize,
        classes.iter().filter(|c| masked.contains(c)).count()
    );
}
