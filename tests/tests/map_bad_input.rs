//! `magic map` on bad input: a clear error naming the file and what was expected, never a
//! panic; a missing or partial georeference is a warning and the map keeps the pixel grid. Also
//! checks the `tiff` crate's behaviour the map relies on (or works around).

mod map_common;

use magic_tests::TempDir;
use magic_train::raster::geo::GeoRef;
use magic_train::raster::map::{self, MapOptions};
use magic_train::raster::writer::{Sample, StripWriter, TiffSpec};
use magic_train::ModelKind;
use map_common::*;
use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A test's own folder (removed when the test ends) and what it holds at the start.
struct Fixture {
    dir: TempDir,
    model: PathBuf,
    image: PathBuf,
}

/// A small C model (trained once for all the tests) and an 11-band image (a 16 × 12 block of
/// the test split), in a folder of the test's own.
fn fixture() -> Fixture {
    static MODEL: OnceLock<Vec<u8>> = OnceLock::new();
    let dir = TempDir::new("map-bad");
    let model = dir.join("C.magic");
    std::fs::write(&model, MODEL.get_or_init(|| small_model(ModelKind::C, 2))).unwrap();
    let image = dir.join("image.tif");
    write_block(&image, 11, &test_geo());
    Fixture { dir, model, image }
}

/// `bands` bands of the test split's first 16 × 12 pixels (band k repeats band k mod 11).
fn write_block(path: &Path, bands: usize, geo: &GeoRef) {
    let s = Scene::test_split();
    let (w, h) = (16u32, 12u32);
    let n = (s.width * s.height) as usize;
    let mut buf = Vec::new();
    for b in 0..bands {
        for y in 0..h {
            for x in 0..w {
                let v = s.dn[(b % 11) * n + (y * s.width + x) as usize];
                buf.extend(v.to_le_bytes());
            }
        }
    }
    let mut wr = StripWriter::new(
        std::fs::File::create(path).unwrap(),
        TiffSpec {
            width: w,
            height: h,
            bands: bands as u16,
            sample: Sample::U16,
            planar: true,
            rows_per_strip: 4,
            deflate: true,
            big: None,
            tags: geo.tags(),
        },
    )
    .unwrap();
    wr.write_rows(h, &buf).unwrap();
    wr.finish().unwrap();
}

/// The map of `input` with `f`'s model, to `out` in `f`'s folder.
fn options(f: &Fixture, input: &Path, out: &str) -> MapOptions {
    MapOptions {
        model: f.model.clone(),
        input: input.to_path_buf(),
        output: f.dir.join(out),
        offset: OFFSET,
        scl: None,
        residual: true,
        sd: true,
        date: None,
        window: None,
        bands: None,
        raw_sd: true,
        preview: None,
        preview_band: "LAI".into(),
        progress: false,
        window_rows: 4,
    }
}

/// Runs the map, which must fail without panicking; returns the message.
fn fails(o: &MapOptions) -> String {
    let r = catch_unwind(AssertUnwindSafe(|| map::run(o))).expect("panicked");
    format!("{:#}", r.expect_err("accepted bad input"))
}

#[test]
fn a_band_count_that_does_not_match_is_an_error() {
    let f = fixture();
    let p = f.dir.join("three_bands.tif");
    write_block(&p, 3, &test_geo());
    let e = fails(&options(&f, &p, "x.tif"));
    assert!(
        e.contains("three_bands.tif") && e.contains("3 bands, the model expects 11"),
        "{e}"
    );
    let mut o = options(&f, &f.image, "x.tif");
    o.bands = Some(vec!["B02".into(), "B03".into()]);
    let e = fails(&o);
    assert!(e.contains("11 bands, --bands names 2"), "{e}");
    let mut names: Vec<String> = (1..=11).map(|k| format!("X{k}")).collect();
    o.bands = Some(names.clone());
    assert!(fails(&o).contains("the model's band B02 is not among them"));
    names[0] = "B02".into();
    o.bands = Some(names);
    assert!(fails(&o).contains("band B03 is not among them"));
    // The binary says the same, naming the file.
    let (ok, err) = magic(&[
        "map",
        "--model",
        f.model.to_str().unwrap(),
        "--input",
        p.to_str().unwrap(),
        "--output",
        f.dir.join("y.tif").to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("three_bands.tif: 3 bands, the model expects 11"),
        "{err}"
    );
    assert!(!f.dir.join("y.tif").exists(), "no output on error");
}

#[test]
fn an_unsupported_sample_type_is_an_error() {
    let f = fixture();
    let p = f.dir.join("u64.tif");
    let mut tif =
        magic_train::raster::tiff::encoder::TiffEncoder::new(std::fs::File::create(&p).unwrap())
            .unwrap();
    tif.write_image::<magic_train::raster::tiff::encoder::colortype::Gray64>(4, 4, &[7u64; 16])
        .unwrap();
    drop(tif);
    let e = fails(&options(&f, &p, "x.tif"));
    assert!(
        e.contains("u64.tif") && e.contains("unsupported sample type"),
        "{e}"
    );
    let p = f.dir.join("rgb8.tif");
    let mut tif =
        magic_train::raster::tiff::encoder::TiffEncoder::new(std::fs::File::create(&p).unwrap())
            .unwrap();
    tif.write_image::<magic_train::raster::tiff::encoder::colortype::RGB8>(4, 4, &[7u8; 48])
        .unwrap();
    drop(tif);
    let e = fails(&options(&f, &p, "x.tif"));
    assert!(e.contains("rgb8.tif: 3 bands, the model expects 11"), "{e}");
}

#[test]
fn truncated_or_corrupt_files_are_errors() {
    let f = fixture();
    let bytes = std::fs::read(&f.image).unwrap();
    let p = f.dir.join("cut.tif");
    let mut errors = 0;
    for k in 0..40 {
        let len = bytes.len() * k / 40;
        std::fs::write(&p, &bytes[..len]).unwrap();
        let e = fails(&options(&f, &p, "cut_map.tif"));
        assert!(e.contains("cut.tif"), "cut at {len}: {e}");
        errors += 1;
    }
    // Corrupt strip data (the deflate streams), header intact.
    let mut bad = bytes.clone();
    for b in bad[16..400].iter_mut() {
        *b ^= 0x5A;
    }
    std::fs::write(&p, &bad).unwrap();
    let e = fails(&options(&f, &p, "cut_map.tif"));
    assert!(
        e.contains("cut.tif") && e.contains("cannot decode strip"),
        "{e}"
    );
    let e = fails(&options(&f, &f.dir.join("absent.tif"), "x.tif"));
    assert!(e.contains("absent.tif: cannot open"), "{e}");
    std::fs::write(&p, b"not a tiff at all").unwrap();
    assert!(fails(&options(&f, &p, "x.tif")).contains("cut.tif: not a readable TIFF"));
    eprintln!("{errors} truncations, corrupt strips, a missing file and a non-TIFF: all errors naming the file");
}

#[test]
fn a_missing_or_partial_georeference_is_a_warning() {
    let f = fixture();
    for (name, geo, want) in [
        ("nogeo.tif", GeoRef::default(), "no georeference"),
        (
            "crs_only.tif",
            GeoRef {
                pixel_scale: None,
                tiepoints: None,
                ..test_geo()
            },
            "a CRS but no pixel grid",
        ),
        (
            "grid_only.tif",
            GeoRef {
                key_directory: None,
                ..test_geo()
            },
            "a pixel grid but no CRS",
        ),
    ] {
        let p = f.dir.join(name);
        write_block(&p, 11, &geo);
        let mut o = options(&f, &p, &format!("{name}.map.tif"));
        o.residual = false;
        let s = map::run(&o).unwrap();
        assert!(
            s.warnings
                .iter()
                .any(|w| w.contains(want) && w.contains(name)),
            "{name}: {:?}",
            s.warnings
        );
        let (w, h, _) = read_map(&o.output);
        assert_eq!((w, h), (16, 12));
        // The map carries what the input had, no more.
        let r = magic_train::raster::reader::Raster::open(&o.output).unwrap();
        assert_eq!(r.geo.tags(), geo.tags(), "{name}");
    }
}

#[test]
fn an_scl_of_another_size_is_an_error() {
    let f = fixture();
    let p = f.dir.join("scl_small.tif");
    let mut wr = StripWriter::new(
        std::fs::File::create(&p).unwrap(),
        TiffSpec {
            width: 8,
            height: 6,
            bands: 1,
            sample: Sample::U8,
            planar: false,
            rows_per_strip: 6,
            deflate: false,
            big: None,
            tags: vec![],
        },
    )
    .unwrap();
    wr.write_rows(6, &[4u8; 48]).unwrap();
    wr.finish().unwrap();
    let mut o = options(&f, &f.image, "x.tif");
    o.scl = Some(p);
    let e = fails(&o);
    assert!(
        e.contains("scl_small.tif: scene classification of 8×6 pixels, the image has 16×12"),
        "{e}"
    );
    // Values that are no SCL class.
    let p = f.dir.join("scl_bad.tif");
    let mut wr = StripWriter::new(
        std::fs::File::create(&p).unwrap(),
        TiffSpec {
            width: 16,
            height: 12,
            bands: 1,
            sample: Sample::U8,
            planar: false,
            rows_per_strip: 12,
            deflate: false,
            big: None,
            tags: vec![],
        },
    )
    .unwrap();
    wr.write_rows(12, &[200u8; 192]).unwrap();
    wr.finish().unwrap();
    o.scl = Some(p);
    assert!(fails(&o).contains("scl_bad.tif: value 200 at column 0, row 0 is not an SCL class"));
}

#[test]
fn other_models_and_options_are_errors() {
    let f = fixture();
    let mogi = f.dir.join("mogi.magic");
    std::fs::write(
        &mogi,
        magic_tests::random_mogi_model(magic_core::Variant::C, 1)
            .encode()
            .unwrap(),
    )
    .unwrap();
    let mut o = options(&f, &f.image, "x.tif");
    o.model = mogi;
    assert!(fails(&o).contains("a map needs a forest (RTM) model; this one is a mogi model"));
    let mut o = options(&f, &f.image, "x.tif");
    o.window = Some([10, 10, 10, 10]);
    assert!(fails(&o).contains("is not inside the 16×12 image"));
    o.window = None;
    o.date = Some("2018-13-01".into());
    assert!(fails(&o).contains("expected YYYY-MM-DD"));
}

/// The `tiff` crate's behaviour, as the issue describes it and as the map relies on it.
#[test]
fn the_tiff_crate_behaves_as_described() {
    use magic_train::raster::tiff::decoder::{Decoder, DecodingResult};
    use magic_train::raster::tiff::encoder::{colortype, Compression, TiffEncoder};
    // 1. `ImageEncoder::write_data` checks the length against the pixel count, not the sample
    //    count: three samples per pixel given one per pixel passes the check and panics while
    //    slicing. The map never calls it (its own writer streams strips).
    let r = catch_unwind(|| {
        let mut c = Cursor::new(Vec::new());
        let mut t = TiffEncoder::new(&mut c).unwrap();
        let img = t.new_image::<colortype::RGB8>(4, 4).unwrap();
        let _ = img.write_data(&[0u8; 16]);
    });
    assert!(
        r.is_err(),
        "write_data with too little data no longer panics"
    );
    // 2. `write_strip` writes strips one at a time but does not compress them: the strips of an
    //    image declared deflate are raw, so the file does not decode as written.
    let mut c = Cursor::new(Vec::new());
    {
        let mut t = TiffEncoder::new(&mut c)
            .unwrap()
            .with_compression(Compression::Deflate(Default::default()));
        let mut img = t.new_image::<colortype::Gray16>(4, 4).unwrap();
        img.rows_per_strip(4).unwrap();
        img.write_strip(&[1234u16; 16]).unwrap();
        img.finish().unwrap();
    }
    let mut d = Decoder::new(Cursor::new(c.into_inner())).unwrap();
    let back = d.read_chunk(0);
    assert!(
        !matches!(back, Ok(DecodingResult::U16(ref v)) if v == &vec![1234u16; 16]),
        "write_strip now compresses"
    );
    // 3. `read_image` of a band-interleaved file returns only the first plane.
    let f = fixture();
    let mut d = Decoder::new(std::fs::File::open(&f.image).unwrap()).unwrap();
    #[allow(deprecated)]
    let DecodingResult::U16(v) = d.read_image().unwrap() else {
        panic!("not u16")
    };
    assert_eq!(v.len(), 16 * 12, "read_image returned more than one plane");
}
