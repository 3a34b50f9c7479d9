//! INFORM per spectrum on one core, f64 (and f32 for the model file's rows): the 13-band model
//! over the full tables and the 11 observed bands over the packed rows a model file carries;
//! forward alone and forward + exact Jacobian of the 7 learned variables.
//!
//! It first prints thread CPU time per spectrum (on a shared machine criterion's wall clock also
//! counts time spent waiting for a core), then runs criterion. Measured on the development
//! machine (2-core x86-64 with AVX2, AVX-512 and FMA; 13 bands, 884 wavelengths; median of
//! three runs): forward 77 µs, forward + Jacobian 253 µs, with the workspace's x86-64-v3 code
//! generation (`.cargo/config.toml`). For the baseline x86-64 target (SSE2 only) they are about
//! 107 and 620 µs: the SIMD lanes INFORM runs on ([`magic_core::real::F64x8`], and
//! `Dual<4, F64x4>` for the Jacobian) need AVX2 to pay off in full. Before the lanes (one
//! wavelength per dual, four per `f64` call without SIMD exponentials) they were 182 and 800 µs.
//!
//! Needs the published tables (`MAGIC_DATA` or `../shared/data`); prints a notice and does nothing
//! without them.

use criterion::{criterion_group, criterion_main, Criterion};
use magic_core::quant::LeF32;
use magic_core::rtm::bands::Packed;
use magic_core::rtm::prospect::Coefficients;
use magic_core::rtm::{Fixed, Geometry, Inform, Tables, N_BANDS, N_LEARNED};
use std::hint::black_box;
use std::path::PathBuf;

/// The 11 bands of the S2 dataset (no B01, no B10).
const BANDS: [usize; 11] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12];

fn data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("MAGIC_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")),
    };
    dir.join("rtm/prospect_d_coefficients.csv")
        .exists()
        .then_some(dir.join("rtm"))
}

/// Columns of a comma-separated file with a header, by name.
fn columns(path: PathBuf, names: &[&str]) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::trim)
        .collect();
    let idx: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .unwrap_or_else(|| panic!("{}: no column {n}", path.display()))
        })
        .collect();
    let rows: Vec<Vec<f64>> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|f| f.trim().parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    idx.iter()
        .map(|&c| rows.iter().map(|r| r[c]).collect())
        .collect()
}

struct Owned {
    cols: Vec<Vec<f64>>,
    beta: Vec<f64>,
    resampling: Vec<f64>,
}

impl Owned {
    fn load(dir: PathBuf) -> Owned {
        let mut cols = columns(
            dir.join("prospect_d_coefficients.csv"),
            &[
                "nr", "k_cab", "k_car", "k_anth", "k_brown", "k_cw", "k_cm", "t12", "tav90n",
            ],
        );
        cols.extend(columns(
            dir.join("soil_spectra.csv"),
            &["Rsoil1_dry", "Rsoil2_wet"],
        ));
        cols.extend(columns(
            dir.join("solar_spectra.csv"),
            &["Es_direct", "Ed_diffuse"],
        ));
        let b = columns(
            dir.join("lidf_tables.csv"),
            &["beta_0", "beta_1", "beta_2", "beta_3", "beta_4", "beta_5"],
        );
        let beta = (0..13).flat_map(|a| b.iter().map(move |c| c[a])).collect();
        let names = magic_core::rtm::S2_BANDS;
        let m = columns(dir.join("sentinel2_full_resampling_matrix.csv"), &names);
        let resampling = (0..m[0].len())
            .flat_map(|i| m.iter().map(move |c| c[i]))
            .collect();
        Owned {
            cols,
            beta,
            resampling,
        }
    }

    fn tables(&self) -> Tables<'_> {
        let c = &self.cols;
        Tables {
            prospect: Coefficients {
                nr: &c[0],
                k_cab: &c[1],
                k_car: &c[2],
                k_anth: &c[3],
                k_brown: &c[4],
                k_cw: &c[5],
                k_cm: &c[6],
                t12: &c[7],
                tav90n: &c[8],
            },
            soil_dry: &c[9],
            soil_wet: &c[10],
            es: &c[11],
            ed: &c[12],
            lidf_beta: &self.beta,
            resampling: &self.resampling,
        }
    }

    /// The packed rows of [`BANDS`] (as a model file carries them).
    fn pack(&self) -> (Vec<f64>, Vec<f64>) {
        let (mut s, mut w) = (Vec::new(), Vec::new());
        for i in 0..self.cols[0].len() {
            let wi: Vec<f64> = BANDS
                .iter()
                .map(|&b| self.resampling[i * N_BANDS + b])
                .collect();
            if wi.iter().any(|&x| x != 0.0) {
                s.extend(self.cols.iter().map(|c| c[i]));
                w.extend(wi);
            }
        }
        (s, w)
    }
}

/// Seconds of CPU time this thread has run (Linux `schedstat`), else wall time.
fn thread_seconds() -> f64 {
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    let start = START.get_or_init(std::time::Instant::now);
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map(|ns| ns * 1e-9)
        .unwrap_or_else(|| start.elapsed().as_secs_f64())
}

fn f32_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| (*x as f32).to_le_bytes()).collect()
}

fn bench(c: &mut Criterion) {
    let Some(dir) = data_dir() else {
        eprintln!("notice: RTM tables not found (set MAGIC_DATA); nothing to measure");
        return;
    };
    let t = Owned::load(dir);
    let full = Inform::new(t.tables()).unwrap();
    let (s, w) = t.pack();
    let packed = Packed::new(&s[..], &w[..], &t.beta[..], BANDS.len()).unwrap();
    let (sb, wb, bb) = (f32_bytes(&s), f32_bytes(&w), f32_bytes(&t.beta));
    let packed32 = Packed::new(LeF32(&sb), LeF32(&wb), LeF32(&bb), BANDS.len()).unwrap();
    eprintln!(
        "rows evaluated: 13 bands {} wavelengths, 11 bands {} rows ({} KiB in f32)",
        full.sensor().n_active(),
        packed.n_rows(),
        (sb.len() + wb.len() + bb.len()) / 1024
    );
    let fixed = Fixed::default();
    let z = [1.8, 45.0, 0.01, 0.02, 3.0, 0.5, 0.6];
    let g = Geometry::Reference;

    // Thread CPU time per spectrum first: on a shared machine criterion's wall clock also counts
    // the time spent waiting for a core.
    let per = |n: usize, f: &mut dyn FnMut(usize) -> f64| {
        let t0 = thread_seconds();
        let mut acc = 0.0;
        for k in 0..n {
            acc += f(k);
        }
        black_box(acc);
        (thread_seconds() - t0) / n as f64 * 1e6
    };
    let zk = |k: usize| {
        let mut zz = z;
        zz[1] += (k % 100) as f64 * 0.1;
        zz
    };
    let (mut y, mut j) = ([0.0; 11], [[0.0; N_LEARNED]; 11]);
    let mut y32 = [0f32; 11];
    let f13 = per(10_000, &mut |k| {
        full.forward_learned(&zk(k), &fixed, g).unwrap()[3]
    });
    let f11 = per(10_000, &mut |k| {
        packed.forward_learned(&zk(k), &fixed, g, &mut y).unwrap();
        y[3]
    });
    let f32_11 = per(10_000, &mut |k| {
        packed32
            .forward_learned(&zk(k).map(|v| v as f32), &fixed, g, &mut y32)
            .unwrap();
        y32[3] as f64
    });
    let j13 = per(3000, &mut |k| {
        full.jacobian(&zk(k), &fixed, g).unwrap().1[3][1]
    });
    let j11 = per(3000, &mut |k| {
        packed.jacobian(&zk(k), &fixed, g, &mut y, &mut j).unwrap();
        j[3][1]
    });
    eprintln!(
        "thread CPU time per spectrum: forward f64 13 bands {f13:.1} us, 11 bands {f11:.1} us, \
         f32 11 bands {f32_11:.1} us; forward + Jacobian f64 13 bands {j13:.1} us, 11 bands {j11:.1} us"
    );

    let mut grp = c.benchmark_group("inform per spectrum");
    grp.bench_function("forward f64, 13 bands, full tables", |b| {
        b.iter(|| full.forward_learned(black_box(&z), &fixed, g).unwrap())
    });
    grp.bench_function("forward f64, 11 bands, packed rows", |b| {
        let mut y = [0.0; 11];
        b.iter(|| {
            packed
                .forward_learned(black_box(&z), &fixed, g, &mut y)
                .unwrap()
        })
    });
    grp.bench_function("forward f32, 11 bands, model-file rows", |b| {
        let z32 = z.map(|v| v as f32);
        let mut y = [0f32; 11];
        b.iter(|| {
            packed32
                .forward_learned(black_box(&z32), &fixed, g, &mut y)
                .unwrap()
        })
    });
    grp.bench_function("forward + jacobian f64, 13 bands, full tables", |b| {
        b.iter(|| full.jacobian(black_box(&z), &fixed, g).unwrap())
    });
    grp.bench_function("forward + jacobian f64, 11 bands, packed rows", |b| {
        let (mut y, mut j) = ([0.0; 11], [[0.0; N_LEARNED]; 11]);
        b.iter(|| {
            packed
                .jacobian(black_box(&z), &fixed, g, &mut y, &mut j)
                .unwrap()
        })
    });
    grp.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
