//! Fuzzing the GeoTIFF reader of `magic map` on stable Rust: no panic, no hang, on mutated files.
//!
//! Seeds are small valid images of every layout the map reads (band- and pixel-interleaved,
//! striped and tiled, uncompressed, deflate, LZW, classic and BigTIFF, 16-bit integers and 32-bit
//! floats, with GeoTIFF and GDAL tags), written by the crate's own writer and by the `tiff`
//! crate's encoder. Each case mutates one (bit flips, byte sets, extreme 16/32/64-bit words,
//! truncations, insertions, deletions, splices), writes it to a file, opens it with
//! `Raster::open` and, when that succeeds, reads every band in windows of rows as the map does;
//! the band-set reader (`Input`) and the SCL mask are run on the same file. An error is fine; a
//! panic or a case slower than `MAGIC_MAP_FUZZ_CASE_SECS` (default 10 s) fails the test with the
//! input saved and printed.
//!
//! `MAGIC_MAP_FUZZ_CASES` cases (default 20 000), `MAGIC_MAP_FUZZ_SEED`, `MAGIC_MAP_FUZZ_ONLY=<case>`.
//! The long run: `MAGIC_MAP_FUZZ_CASES=200000 cargo test --release -p magic-tests --test map_fuzz
//! -- --nocapture`.

use magic_train::raster::geo::GeoRef;
use magic_train::raster::input::Input;
use magic_train::raster::reader::Raster;
use magic_train::raster::scl::Scl;
use magic_train::raster::writer::{Sample, StripWriter, TagValue, TiffSpec};
use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, OnceLock};
use std::time::{Duration, Instant};

/// SplitMix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        magic_tests::splitmix64(&mut self.0)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .map(|v| {
            v.trim()
                .parse()
                .unwrap_or_else(|_| panic!("{name}={v}: an integer"))
        })
        .unwrap_or(default)
}

/// Valid seed files.
fn seeds() -> &'static Vec<Vec<u8>> {
    static S: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    S.get_or_init(|| {
        let (w, h) = (9u32, 7u32);
        let mut v = Vec::new();
        let geo = GeoRef::utm_north(33, 500_000.0, 5_300_000.0, 10.0);
        for (bands, sample, planar, deflate, big, rps) in [
            (11u16, Sample::U16, true, true, false, 3u32),
            (11, Sample::U16, false, false, true, 7),
            (11, Sample::F32, true, false, false, 2),
            (1, Sample::U8, false, true, true, 4),
        ] {
            let n = (w * h) as usize * bands as usize;
            let data: Vec<u8> = (0..n)
                .flat_map(|i| match sample {
                    Sample::U16 => ((1000 + i * 37) as u16).to_le_bytes().to_vec(),
                    Sample::F32 => (0.01 * (i % 50) as f32).to_le_bytes().to_vec(),
                    Sample::U8 => vec![(i % 12) as u8],
                })
                .collect();
            let mut tags = geo.tags();
            tags.push((42113, TagValue::Ascii("0".into())));
            let mut wr = StripWriter::new(
                Cursor::new(Vec::new()),
                TiffSpec {
                    width: w,
                    height: h,
                    bands,
                    sample,
                    planar,
                    rows_per_strip: rps,
                    deflate,
                    big: Some(big),
                    tags,
                },
            )
            .unwrap();
            wr.write_rows(h, &data).unwrap();
            v.push(wr.finish().unwrap().into_inner());
        }
        // The `tiff` crate's encoder: LZW, deflate (whole-image `write_data`).
        use magic_train::raster::tiff::encoder::{colortype, Compression, TiffEncoder};
        for c in [Compression::Lzw, Compression::Deflate(Default::default())] {
            let mut cur = Cursor::new(Vec::new());
            let mut t = TiffEncoder::new(&mut cur).unwrap().with_compression(c);
            t.write_image::<colortype::Gray16>(w, h, &vec![1500u16; (w * h) as usize])
                .unwrap();
            v.push(cur.into_inner());
        }
        v
    })
}

fn mutate(r: &mut Rng) -> Vec<u8> {
    let s = seeds();
    let mut b = s[r.below(s.len())].clone();
    for _ in 0..1 + r.below(4) {
        let n = b.len();
        match r.below(9) {
            0 | 1 => {
                let i = r.below(n);
                b[i] ^= 1 << r.below(8);
            }
            2 => {
                let i = r.below(n);
                b[i] = [0, 1, 0x7F, 0x80, 0xFF, 0xFE, 2, 3][r.below(8)];
            }
            3 | 4 => {
                // An extreme little-endian word: a count, an offset, a size, a type.
                let words: [u64; 10] = [
                    0,
                    1,
                    2,
                    0xFF,
                    0xFFFF,
                    0x7FFF_FFFF,
                    0xFFFF_FFFF,
                    u64::MAX,
                    n as u64,
                    r.next(),
                ];
                let w = words[r.below(words.len())];
                let width = [2usize, 4, 8][r.below(3)];
                let at = r.below(n.saturating_sub(width) + 1);
                for (k, x) in w.to_le_bytes().into_iter().take(width).enumerate() {
                    if let Some(y) = b.get_mut(at + k) {
                        *y = x;
                    }
                }
            }
            5 => b.truncate(r.below(n + 1)),
            6 => {
                let at = r.below(n + 1);
                let ins: Vec<u8> = (0..1 + r.below(16)).map(|_| r.next() as u8).collect();
                b.splice(at..at, ins);
            }
            7 => {
                let at = r.below(n + 1);
                let end = (at + 1 + r.below(16)).min(n);
                b.drain(at..end);
            }
            _ => {
                let o = &s[r.below(s.len())];
                let a = r.below(o.len());
                let len = r.below(64.min(o.len() - a) + 1);
                let at = r.below(n + 1);
                for (k, c) in o[a..a + len].iter().enumerate() {
                    if let Some(x) = b.get_mut(at + k) {
                        *x = *c;
                    }
                }
            }
        }
        if b.is_empty() {
            break;
        }
    }
    b
}

/// Largest image read in full (samples), so that a mutated size cannot make a case slow.
const MAX_READ_SAMPLES: u64 = 4 << 20;

/// Opens and reads the file as the map does; any error is fine.
fn exercise(path: &Path) {
    if let Ok(mut r) = Raster::open(path) {
        let (w, h, nb) = (r.width, r.height, r.bands);
        if w as u64 * h as u64 * nb as u64 <= MAX_READ_SAMPLES {
            let mut buf = vec![0.0; (3 * w) as usize];
            'bands: for b in 0..nb {
                let mut y = 0;
                while y < h {
                    let rows = 3.min(h - y);
                    if r.read_band(b, 0, y, rows, &mut buf[..(rows * w) as usize])
                        .is_err()
                    {
                        continue 'bands;
                    }
                    y += rows;
                }
            }
            let _ = r.read_band(nb, 0, 0, 1, &mut buf[..w as usize]);
            // Re-open: a band-interleaved or multi-file read restarts the cache.
            if nb == 11 {
                let names: Vec<String> = [
                    "B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B11", "B12",
                ]
                .iter()
                .map(|s| s.to_string())
                .collect();
                if let Ok(mut i) = Input::open(path, &names, None, -1000.0) {
                    let mut out = Vec::new();
                    let _ = i.read(0, 0, w, h.min(5), &mut out);
                }
            }
            if nb == 1 {
                if let Ok(mut s) = Scl::open(path, w, h) {
                    let mut obs = vec![0f32; (w * h) as usize * 2];
                    let _ = s.apply(0, 0, w, h, 2, &mut obs);
                }
            }
        }
    }
}

#[test]
fn fuzz_geotiff_reader() {
    let cases = env_u64("MAGIC_MAP_FUZZ_CASES", 20_000);
    let seed = env_u64("MAGIC_MAP_FUZZ_SEED", 0x7469_6666);
    let only = std::env::var("MAGIC_MAP_FUZZ_ONLY")
        .ok()
        .map(|v| v.parse::<u64>().unwrap());
    let case_limit = Duration::from_secs(env_u64("MAGIC_MAP_FUZZ_CASE_SECS", 10));
    // Every seed reads cleanly.
    let dir = std::env::temp_dir().join(format!("magic-map-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (k, s) in seeds().iter().enumerate() {
        let p = dir.join(format!("seed{k}.tif"));
        std::fs::write(&p, s).unwrap();
        let mut r = Raster::open(&p).unwrap_or_else(|e| panic!("seed {k}: {e:#}"));
        let mut buf = vec![0.0; (r.width * r.height) as usize];
        for b in 0..r.bands {
            r.read_band(b, 0, 0, r.height, &mut buf).unwrap();
        }
    }
    let progress = Arc::new(AtomicU64::new(0));
    let opened = Arc::new(AtomicU64::new(0));
    let (tx, rx) = mpsc::channel::<Result<f64, (u64, Vec<u8>)>>();
    let (p, o, d) = (progress.clone(), opened.clone(), dir.clone());
    let case_input = move |i: u64| mutate(&mut Rng(seed ^ i.wrapping_mul(0xE703_7ED1_A0B4_28DB)));
    let gen = case_input;
    let start = Instant::now();
    std::thread::spawn(move || {
        let path = d.join("case.tif");
        let range = match only {
            Some(i) => i..i + 1,
            None => 0..cases,
        };
        let mut slowest = 0f64;
        for i in range {
            p.store(i, Ordering::Relaxed);
            let input = gen(i);
            std::fs::write(&path, &input).unwrap();
            let t = Instant::now();
            if catch_unwind(AssertUnwindSafe(|| exercise(&path))).is_err() {
                let _ = tx.send(Err((i, input)));
                return;
            }
            if Raster::open(&path).is_ok() {
                o.fetch_add(1, Ordering::Relaxed);
            }
            slowest = slowest.max(t.elapsed().as_secs_f64());
        }
        let _ = tx.send(Ok(slowest));
    });
    let mut last = (u64::MAX, Instant::now());
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(Ok(slowest)) => {
                eprintln!(
                    "fuzz geotiff: {cases} cases in {:.1} s ({} opened, slowest {:.1} ms), MAGIC_MAP_FUZZ_SEED={seed}: no panic, no hang",
                    start.elapsed().as_secs_f64(),
                    opened.load(Ordering::Relaxed),
                    slowest * 1e3
                );
                let _ = std::fs::remove_dir_all(&dir);
                return;
            }
            Ok(Err((i, input))) => {
                let at = dir.join(format!("panic-case{i}.tif"));
                std::fs::write(&at, &input).unwrap();
                panic!(
                    "fuzz geotiff: case {i} panicked (MAGIC_MAP_FUZZ_SEED={seed} MAGIC_MAP_FUZZ_ONLY={i}); input saved to {}",
                    at.display()
                );
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                let i = progress.load(Ordering::Relaxed);
                if i != last.0 {
                    last = (i, Instant::now());
                } else if last.1.elapsed() > case_limit {
                    let at = dir.join(format!("hang-case{i}.tif"));
                    std::fs::write(&at, case_input(i)).unwrap();
                    panic!(
                        "fuzz geotiff: case {i} still running after {case_limit:?} (MAGIC_MAP_FUZZ_ONLY={i}); input saved to {}",
                        at.display()
                    );
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                panic!("fuzz worker ended without a result")
            }
        }
    }
}
