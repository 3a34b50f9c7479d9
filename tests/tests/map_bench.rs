//! Throughput and memory of `magic map` (a benchmark, not a timed test: it asserts nothing about
//! time and is ignored in the normal suite).
//!
//! For each size N in `MAGIC_MAP_BENCH_SIZES` (default `1024,4096,10980`) it writes an N × N
//! image of 11 bands of L2A digital numbers (the test split's spectra repeated in a shuffled
//! order; deflate, 16-row strips, band-interleaved; kept in `MAGIC_MAP_BENCH_DIR`, default the
//! temporary folder, and reused), then runs the `magic` binary under `/usr/bin/time -v`:
//!
//! * the encoder alone on the first `MAGIC_MAP_BENCH_ROWS` rows (default 1024; all rows of a
//!   1 024² image) at full width;
//! * with `--residual` (INFORM, C, residual and flags), then with `--sd` (also the standard
//!   deviations) on the first `MAGIC_MAP_BENCH_RESIDUAL_ROWS` rows (default 32) at full width;
//!
//! and prints pixels per second (inversion only, and end to end), peak resident memory and the
//! time a full 10 980² tile would take at that rate.
//!
//! `cargo test --release -p magic-tests --test map_bench -- --ignored --nocapture`

mod map_common;

use magic_train::raster::writer::{Sample, StripWriter, TiffSpec};
use map_common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

fn env_list(name: &str, default: &str) -> Vec<u32> {
    std::env::var(name)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .map(|s| s.trim().parse().unwrap())
        .collect()
}

/// Writes the N × N benchmark image (rows generated as written: bounded memory).
fn bench_image(dir: &Path, n: u32, scene: &Scene) -> PathBuf {
    let p = dir.join(format!("bench_{n}.tif"));
    if p.is_file() {
        return p;
    }
    let spectra: Vec<(u32, u32)> = (0..scene.height)
        .flat_map(|y| (0..scene.width).map(move |x| (x, y)))
        .collect();
    let nb = scene.bands();
    let plane = (scene.width * scene.height) as usize;
    let tmp = dir.join(format!("bench_{n}.tif.partial"));
    let mut w = StripWriter::new(
        std::io::BufWriter::new(std::fs::File::create(&tmp).unwrap()),
        TiffSpec {
            width: n,
            height: n,
            bands: nb as u16,
            sample: Sample::U16,
            planar: true,
            rows_per_strip: 16,
            deflate: true,
            big: None,
            tags: test_geo().tags(),
        },
    )
    .unwrap();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut r = 0;
    while r < n {
        let rows = 256.min(n - r);
        let mut buf = vec![0u8; nb * (rows * n) as usize * 2];
        for i in 0..(rows * n) as usize {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let (x, y) = spectra[(state % spectra.len() as u64) as usize];
            let src = (y * scene.width + x) as usize;
            for b in 0..nb {
                let v = scene.dn[b * plane + src];
                let at = (b * (rows * n) as usize + i) * 2;
                buf[at..at + 2].copy_from_slice(&v.to_le_bytes());
            }
        }
        w.write_rows(rows, &buf).unwrap();
        r += rows;
    }
    w.finish().unwrap();
    std::fs::rename(&tmp, &p).unwrap();
    p
}

struct Run {
    pixels: f64,
    compute_px_s: f64,
    wall_s: f64,
    rss_mib: f64,
}

fn run(model: &Path, image: &Path, out: &Path, window: [u32; 4], flag: Option<&str>) -> Run {
    let mut c = Command::new("/usr/bin/time");
    c.arg("-v")
        .arg(magic_bin())
        .args(["map", "--offset", "-1000", "--model"]);
    c.arg(model)
        .arg("--input")
        .arg(image)
        .arg("--output")
        .arg(out);
    c.arg("--window").arg(format!(
        "{},{},{},{}",
        window[0], window[1], window[2], window[3]
    ));
    c.args(flag);
    let o = c.output().expect("/usr/bin/time (Debian package `time`)");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "magic map failed: {err}");
    let field = |key: &str| -> &str {
        err.lines()
            .find_map(|l| l.trim().strip_prefix(key))
            .unwrap_or_else(|| panic!("no `{key}` in: {err}"))
            .trim()
    };
    let rss_kib: f64 = field("Maximum resident set size (kbytes):")
        .parse()
        .unwrap();
    let wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss):");
    let wall_s = wall
        .split(':')
        .fold(0.0, |acc, p| acc * 60.0 + p.parse::<f64>().unwrap());
    let mapped = err.lines().find(|l| l.starts_with("mapped ")).unwrap();
    // "… in 3.7 s (1655 pixels/s inverting) -> …"
    let px_s: f64 = mapped
        .split(" pixels/s inverting")
        .next()
        .and_then(|h| h.rsplit('(').next())
        .unwrap()
        .parse()
        .unwrap();
    Run {
        pixels: window[2] as f64 * window[3] as f64,
        compute_px_s: px_s,
        wall_s,
        rss_mib: rss_kib / 1024.0,
    }
}

#[test]
#[ignore = "benchmark: minutes to hours; run with --ignored"]
fn bench_map() {
    let sizes = env_list("MAGIC_MAP_BENCH_SIZES", "1024,4096,10980");
    let rows = env_list("MAGIC_MAP_BENCH_ROWS", "1024")[0];
    let res_rows = env_list("MAGIC_MAP_BENCH_RESIDUAL_ROWS", "32")[0];
    let dir = std::env::var_os("MAGIC_MAP_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("magic-map-bench"));
    std::fs::create_dir_all(&dir).unwrap();
    let model = dir.join("model.magic");
    std::fs::write(&model, figures_model()).unwrap();
    let scene = Scene::test_split();
    let tile = 10_980f64 * 10_980.0;
    println!("| image | mode | pixels mapped | inversion px/s | end-to-end px/s | peak RSS (MiB) | full 10 980² tile at this rate |");
    println!("|---|---|---|---|---|---|---|");
    for n in sizes {
        let img = bench_image(&dir, n, &scene);
        let out = dir.join(format!("bench_{n}_map.tif"));
        for (flag, r) in [
            (None, rows.min(n)),
            (Some("--residual"), res_rows.min(n)),
            (Some("--sd"), res_rows.min(n)),
        ] {
            let m = run(&model, &img, &out, [0, 0, n, r], flag);
            let e2e = m.pixels / m.wall_s.max(1e-9);
            println!(
                "| {n}² | {} | {n} × {r} | {:.0} | {:.0} | {:.0} | {:.1} min |",
                flag.unwrap_or("encoder"),
                m.compute_px_s,
                e2e,
                m.rss_mib,
                tile / e2e / 60.0
            );
        }
        let _ = std::fs::remove_file(&out);
    }
}

/// Where the time of a `--residual` pixel goes, on one thread: the encoder alone, the whole
/// inversion (encoder, INFORM, C, residual) and the standard deviations (INFORM's Jacobian and
/// the correction's slopes), per test-split spectrum.
#[test]
#[ignore = "benchmark; run with --ignored"]
fn bench_pixel_parts() {
    use magic_core::uncertainty::{standard_deviations, Precision, SdWorkspace};
    use magic_core::{invert_at, Model, Workspace};
    use magic_train::raster::pixel::{pixel, PixelConfig, Scratch, N_OUT};
    use std::time::Instant;
    let bytes = figures_model();
    let model = Model::decode(&bytes).unwrap();
    let scene = Scene::test_split();
    let spectra: Vec<Vec<f32>> = (0..scene.height)
        .flat_map(|y| (0..scene.width).map(move |x| (x, y)))
        .filter_map(|(x, y)| scene.reflectance(x, y))
        .collect();
    let n = spectra.len() as f64;
    let mut out = vec![0f32; N_OUT];
    let mut s = Scratch::default();
    let enc = PixelConfig {
        residual: false,
        sd: false,
        t_day: f64::NAN,
        sd_factors: vec![1.0; 9],
    };
    let t = Instant::now();
    for o in &spectra {
        pixel(&model, o, &enc, &mut s, &mut out);
    }
    let t_enc = t.elapsed().as_secs_f64() / n * 1e6;
    let mut ws = Workspace::default();
    let t = Instant::now();
    let invs: Vec<_> = spectra
        .iter()
        .map(|o| invert_at::<f64>(&model, o, f64::NAN, &mut ws).unwrap())
        .collect();
    let t_inv = t.elapsed().as_secs_f64() / n * 1e6;
    let mut t_sd = [0.0; 2];
    let mut sds = [vec![], vec![]];
    for (k, precision) in [Precision::F64, Precision::F32].into_iter().enumerate() {
        let mut sw = SdWorkspace::with_precision(precision);
        let t = Instant::now();
        for (o, inv) in spectra.iter().zip(&invs) {
            sds[k].push(standard_deviations(&model, o, inv, f64::NAN, &mut sw).ok());
        }
        t_sd[k] = t.elapsed().as_secs_f64() / n * 1e6;
    }
    // How far the f32 Jacobian moves the standard deviations (relative).
    let mut worst = 0.0f64;
    for (a, b) in sds[0].iter().zip(&sds[1]) {
        if let (Some(a), Some(b)) = (a, b) {
            for (x, y) in a.sd[..a.n_params].iter().zip(&b.sd[..b.n_params]) {
                worst = worst.max((x - y).abs() / x.abs());
            }
        }
    }
    println!(
        "one thread, µs per spectrum ({} spectra): encoder alone {t_enc:.1}; invert (encoder + INFORM + C + residual) {t_inv:.1}; standard deviations with INFORM's Jacobian in f64 {:.1}, in f32 {:.1} (largest relative change of a standard deviation {worst:.1e}); --residual pixel {t_inv:.1}, --sd pixel {:.1}",
        spectra.len(),
        t_sd[0],
        t_sd[1],
        t_inv + t_sd[1]
    );
}
