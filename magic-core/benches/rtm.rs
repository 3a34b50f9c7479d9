//! INFORM per spectrum on one core: forward in f64 and f32, over the full 2101-wavelength tables
//! (13 bands, 884 wavelengths evaluated) and over the packed rows of the 11 observed bands a model
//! file carries (798 rows); forward + exact Jacobian of the 7 learned variables (the training
//! path); the wavelength-independent part alone (`scene-f64`); and a whole inversion of one pixel
//! (encoder, INFORM, correction) with the paper's released C model, in f64 and f32.
//!
//! The packed cases: `forward-f64-packed` runs on f64 rows checked once (as the trainer holds
//! them); `forward-f32-packed` and the inversions take the rows from the model file's f32 bytes
//! and check them on every call, as `invert` does (`Problem::packed`).
//!
//! It first prints thread CPU time per call for every case (best of three; on a shared machine
//! criterion's wall clock also counts time spent waiting for a core), then runs criterion. The
//! inputs are 64 points spread over the learned variables' box (the cost of PROSPECT's E1 depends
//! on where a spectrum's absorption lands), the inversions run on the first 64 test spectra of
//! `s2/`.
//!
//! Needs the data (`MAGIC_DATA`, else `../shared/data`): the RTM tables under `rtm/`, the test
//! split of `s2/` and `oracle/pretrained_rtm_c_weights.json`; it stops with an error naming what
//! is missing.
//!
//! For a profile, `MAGIC_BENCH_ONLY=<case>` (a case name as printed, e.g. `forward-f64-full`) runs
//! only that case `MAGIC_BENCH_N` times (default 2000) and exits, e.g.
//! `valgrind --tool=callgrind --toggle-collect='*per_call*'` on the bench binary.

use criterion::{criterion_group, criterion_main, Criterion};
use magic_core::invert::{invert, Workspace};
use magic_core::model_file::{Model, Problem, Variant};
use magic_core::nn::{Activation, Layer, Weights};
use magic_core::quant::LeF32;
use magic_core::rtm::bands::Packed;
use magic_core::rtm::prospect::Coefficients;
use magic_core::rtm::{Fixed, Geometry, Inform, Tables, LEARNED_BOUNDS, N_BANDS, N_LEARNED};
use std::hint::black_box;
use std::path::{Path, PathBuf};

/// The 11 bands of the S2 dataset (no B01, no B10).
const BANDS: [usize; 11] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12];

/// Number of input points (spectra, pixels) the cases cycle through.
const N_POINTS: usize = 64;

/// The data folder, or an error saying where it was looked for.
fn data_dir() -> Result<PathBuf, String> {
    let dir = match std::env::var_os("MAGIC_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")),
    };
    let need = [
        "rtm/prospect_d_coefficients.csv",
        "s2/test.csv",
        "oracle/pretrained_rtm_c_weights.json",
    ];
    match need.iter().find(|f| !dir.join(f).is_file()) {
        None => Ok(dir),
        Some(f) => Err(format!(
            "the RTM benchmark needs the data: {} not found (set MAGIC_DATA to the data folder)",
            dir.join(f).display()
        )),
    }
}

/// Columns of a comma-separated file with a header, by name.
fn columns(path: &Path, names: &[&str]) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
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
    let rows: Vec<Vec<&str>> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(str::trim).collect())
        .collect();
    idx.iter()
        .map(|&c| {
            rows.iter()
                .enumerate()
                .map(|(r, row)| {
                    row.get(c).and_then(|f| f.parse().ok()).unwrap_or_else(|| {
                        panic!(
                            "{}:{}: column {}: not a number",
                            path.display(),
                            r + 2,
                            c + 1
                        )
                    })
                })
                .collect()
        })
        .collect()
}

/// The published tables, owned.
struct Owned {
    cols: Vec<Vec<f64>>,
    beta: Vec<f64>,
    resampling: Vec<f64>,
}

impl Owned {
    fn load(dir: &Path) -> Owned {
        let mut cols = columns(
            &dir.join("prospect_d_coefficients.csv"),
            &[
                "nr", "k_cab", "k_car", "k_anth", "k_brown", "k_cw", "k_cm", "t12", "tav90n",
            ],
        );
        cols.extend(columns(
            &dir.join("soil_spectra.csv"),
            &["Rsoil1_dry", "Rsoil2_wet"],
        ));
        cols.extend(columns(
            &dir.join("solar_spectra.csv"),
            &["Es_direct", "Ed_diffuse"],
        ));
        let b = columns(
            &dir.join("lidf_tables.csv"),
            &["beta_0", "beta_1", "beta_2", "beta_3", "beta_4", "beta_5"],
        );
        let beta = (0..13).flat_map(|a| b.iter().map(move |c| c[a])).collect();
        let names = magic_core::rtm::S2_BANDS;
        let m = columns(&dir.join("sentinel2_full_resampling_matrix.csv"), &names);
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
            prospect: Coefficients::from_columns(
                c[..9].try_into().expect("the nine PROSPECT columns first"),
            ),
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

fn f32_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| (*x as f32).to_le_bytes()).collect()
}

/// The paper's released C model: weights, standardisation and bounds, as f32 bytes.
struct ReleasedC {
    /// (rows, cols, weights, bias) of the encoder's four and the correction's two layers.
    layers: Vec<(usize, usize, Vec<u8>, Vec<u8>)>,
    mean: Vec<u8>,
    scale: Vec<u8>,
    bounds: Vec<[f32; 2]>,
}

impl ReleasedC {
    fn load(path: &Path) -> ReleasedC {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let v: serde_json::Value = serde_json::from_str(&text)
            .unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()));
        let floats = |x: &serde_json::Value| -> Vec<f64> {
            let mut out = Vec::new();
            let mut stack = vec![x];
            while let Some(x) = stack.pop() {
                match x {
                    serde_json::Value::Array(a) => stack.extend(a.iter().rev()),
                    serde_json::Value::Number(n) => out.push(n.as_f64().unwrap_or(f64::NAN)),
                    _ => panic!("{}: expected numbers", path.display()),
                }
            }
            out
        };
        let names = [
            "encoder.0",
            "encoder.2",
            "encoder.4",
            "encoder.6",
            "correction.0",
            "correction.2",
        ];
        let layers = names
            .iter()
            .map(|n| {
                let w = &v["layers"][format!("{n}.weight")];
                let shape = floats(&w["shape"]);
                let (w, b) = (
                    floats(&w["values"]),
                    floats(&v["layers"][format!("{n}.bias")]["values"]),
                );
                let (rows, cols) = (shape[0] as usize, shape[1] as usize);
                assert_eq!((w.len(), b.len()), (rows * cols, rows), "{n}");
                (rows, cols, f32_bytes(&w), f32_bytes(&b))
            })
            .collect();
        let bounds = magic_core::rtm::LEARNED_NAMES
            .iter()
            .map(|n| {
                let r = &v["latent_ranges"][n];
                [
                    r["min"].as_f64().unwrap() as f32,
                    r["max"].as_f64().unwrap() as f32,
                ]
            })
            .collect();
        let st = &v["standardization"];
        ReleasedC {
            layers,
            mean: f32_bytes(&floats(&st["x_mean"])),
            scale: f32_bytes(&floats(&st["x_scale"])),
            bounds,
        }
    }

    /// The model over `problem` (validated as a decoded file is).
    fn model<'a>(&'a self, problem: Problem<'a>) -> Model<'a> {
        let mut m = Model::empty();
        m.variant = Variant::C;
        m.problem = problem;
        m.obs_mean = LeF32(&self.mean);
        m.obs_scale = LeF32(&self.scale);
        for b in &self.bounds {
            m.bounds.push(*b).unwrap();
        }
        let acts = [
            Activation::Relu,
            Activation::Relu,
            Activation::Relu,
            Activation::Sigmoid,
            Activation::Relu,
            Activation::Linear,
        ];
        for (k, ((rows, cols, w, b), act)) in self.layers.iter().zip(acts).enumerate() {
            let layer = Layer {
                rows: *rows as u16,
                cols: *cols as u16,
                act,
                weights: Weights::F32 {
                    w: LeF32(w),
                    bias: LeF32(b),
                },
            };
            if k < 4 {
                &mut m.encoder
            } else {
                &mut m.decoder
            }
            .push(layer)
            .unwrap();
        }
        m.validate().expect("released C model");
        m
    }
}

/// The first [`N_POINTS`] test spectra of `s2/` in reflectance (the split is standardised with
/// the model's mean and scale).
fn test_spectra(dir: &Path, c: &ReleasedC) -> Vec<[f32; 11]> {
    let names = [
        "B02_BLUE",
        "B03_GREEN",
        "B04_RED",
        "B05_RE1",
        "B06_RE2",
        "B07_RE3",
        "B08_NIR1",
        "B8A_NIR2",
        "B09_WV",
        "B11_SWI1",
        "B12_SWI2",
    ];
    let x = columns(&dir.join("test.csv"), &names);
    let (mean, scale) = (LeF32(&c.mean), LeF32(&c.scale));
    (0..N_POINTS)
        .map(|r| core::array::from_fn(|b| x[b][r] as f32 * scale.get(b) + mean.get(b)))
        .collect()
}

/// [`N_POINTS`] learned-variable vectors spread over the paper's box, 2 % in from its faces (a
/// Kronecker sequence with the generalised golden ratio of dimension 7: g = (1 + g)^(1/8)).
fn box_points() -> Vec<[f64; N_LEARNED]> {
    let mut g = 1.1f64;
    for _ in 0..60 {
        g = (1.0 + g).powf(1.0 / 8.0);
    }
    let alpha: [f64; N_LEARNED] = core::array::from_fn(|i| (1.0 / g.powi(i as i32 + 1)).fract());
    (0..N_POINTS)
        .map(|k| {
            core::array::from_fn(|i| {
                let u = (0.5 + alpha[i] * (k + 1) as f64).fract();
                let [lo, hi] = LEARNED_BOUNDS[i];
                lo + (0.02 + 0.96 * u) * (hi - lo)
            })
        })
        .collect()
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

/// Everything the cases run on.
struct Setup {
    tables: Owned,
    spectral: Vec<f64>,
    weights: Vec<f64>,
    spectral32: Vec<u8>,
    weights32: Vec<u8>,
    beta32: Vec<u8>,
    released: ReleasedC,
    pixels: Vec<[f32; 11]>,
    z: Vec<[f64; N_LEARNED]>,
}

impl Setup {
    fn load() -> Setup {
        let dir = data_dir().unwrap_or_else(|e| {
            eprintln!("error: {e}");
            std::process::exit(2)
        });
        let tables = Owned::load(&dir.join("rtm"));
        let (spectral, weights) = tables.pack();
        let released = ReleasedC::load(&dir.join("oracle/pretrained_rtm_c_weights.json"));
        Setup {
            spectral32: f32_bytes(&spectral),
            weights32: f32_bytes(&weights),
            beta32: f32_bytes(&tables.beta),
            tables,
            spectral,
            weights,
            pixels: test_spectra(&dir.join("s2"), &released),
            released,
            z: box_points(),
        }
    }

    fn problem(&self) -> Problem<'_> {
        Problem::Rtm {
            geometry: Geometry::Reference,
            fixed: Fixed::default(),
            bands: BANDS.iter().fold(0u16, |m, b| m | 1 << b),
            spectral: LeF32(&self.spectral32),
            weights: LeF32(&self.weights32),
            lidf_beta: LeF32(&self.beta32),
        }
    }
}

/// One case: its name and one evaluation at input point `k` (returning a value to keep).
type Case<'a> = (&'static str, Box<dyn FnMut(usize) -> f64 + 'a>);

fn cases<'a>(s: &'a Setup, model: &'a Model<'a>) -> Vec<Case<'a>> {
    let full = Inform::new(s.tables.tables()).unwrap();
    let packed = Packed::new(
        &s.spectral[..],
        &s.weights[..],
        &s.tables.beta[..],
        BANDS.len(),
    )
    .unwrap();
    let fixed = Fixed::default();
    let g = Geometry::Reference;
    let z = &s.z;
    let z32: Vec<[f32; N_LEARNED]> = z.iter().map(|v| v.map(|x| x as f32)).collect();
    let z32b = z32.clone();
    let at = |k: usize| k % N_POINTS;
    let mut ws = Workspace::default();
    let mut ws32 = Workspace::default();
    let pixels = &s.pixels;
    vec![
        (
            "forward-f64-full",
            Box::new(move |k| full.forward_learned(&z[at(k)], &fixed, g).unwrap()[3]),
        ),
        (
            "scene-f64",
            Box::new(move |k| {
                let x = magic_core::rtm::inputs_from_learned(&z[at(k)], &fixed);
                full.scene(&x, g).unwrap().crown.fcd
            }),
        ),
        (
            "forward-f32-full",
            Box::new(move |k| full.forward_learned(&z32[at(k)], &fixed, g).unwrap()[3] as f64),
        ),
        (
            "forward-f64-packed",
            Box::new(move |k| {
                let mut y = [0.0; 11];
                packed
                    .forward_learned(&z[at(k)], &fixed, g, &mut y)
                    .unwrap();
                y[3]
            }),
        ),
        (
            "forward-f32-packed",
            Box::new(move |k| {
                let p = model.problem.packed().unwrap();
                let mut y = [0f32; 11];
                p.forward_learned(&z32b[at(k)], &fixed, g, &mut y).unwrap();
                y[3] as f64
            }),
        ),
        (
            "jacobian-f64-full",
            Box::new(move |k| full.jacobian(&z[at(k)], &fixed, g).unwrap().1[3][1]),
        ),
        (
            "jacobian-f64-packed",
            Box::new(move |k| {
                let (mut y, mut j) = ([0.0; 11], [[0.0; N_LEARNED]; 11]);
                packed
                    .jacobian(&z[at(k)], &fixed, g, &mut y, &mut j)
                    .unwrap();
                j[3][1]
            }),
        ),
        (
            "invert-f64",
            Box::new(move |k| {
                invert::<f64>(model, &pixels[at(k)], &mut ws)
                    .unwrap()
                    .params[4]
            }),
        ),
        (
            "invert-f32",
            Box::new(move |k| {
                invert::<f32>(model, &pixels[at(k)], &mut ws32)
                    .unwrap()
                    .params[4] as f64
            }),
        ),
    ]
}

/// Thread CPU time per evaluation of `f` (µs), over `n` evaluations. (Not inlined: a profiler
/// can count this function alone, e.g. `valgrind --tool=callgrind --toggle-collect='*per_call*'`.)
#[inline(never)]
fn per_call(n: usize, f: &mut dyn FnMut(usize) -> f64) -> f64 {
    let t0 = thread_seconds();
    let mut acc = 0.0;
    for k in 0..n {
        acc += f(k);
    }
    black_box(acc);
    (thread_seconds() - t0) / n as f64 * 1e6
}

fn bench(c: &mut Criterion) {
    let s = Setup::load();
    let model = s.released.model(s.problem());
    let mut all = cases(&s, &model);

    if let Ok(only) = std::env::var("MAGIC_BENCH_ONLY") {
        let n = std::env::var("MAGIC_BENCH_N")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(2000);
        let Some((_, f)) = all.iter_mut().find(|(name, _)| *name == only) else {
            let names: Vec<&str> = all.iter().map(|(n, _)| *n).collect();
            eprintln!(
                "error: MAGIC_BENCH_ONLY={only}: no such case ({})",
                names.join(", ")
            );
            std::process::exit(2);
        };
        let us = per_call(n, f.as_mut());
        eprintln!("{only}: {n} calls, {us:.2} us each (thread CPU time)");
        std::process::exit(0);
    }

    let full = Inform::new(s.tables.tables()).unwrap();
    eprintln!(
        "rows evaluated: 13 bands {} wavelengths, 11 bands {} rows ({} KiB in f32)",
        full.sensor().n_active(),
        s.spectral.len() / 13,
        (s.spectral32.len() + s.weights32.len() + s.beta32.len()) / 1024
    );
    // Thread CPU time per call first (best of three runs of N_POINTS × 50 calls).
    eprintln!("thread CPU time per call (best of 3):");
    for (name, f) in all.iter_mut() {
        let n = if name.starts_with("jacobian") {
            1000
        } else {
            3200
        };
        let best = (0..3)
            .map(|_| per_call(n, f.as_mut()))
            .fold(f64::INFINITY, f64::min);
        eprintln!("  {name:<22} {best:8.2} us");
    }

    let mut grp = c.benchmark_group("inform");
    for (name, f) in all.iter_mut() {
        let mut k = 0usize;
        grp.bench_function(*name, |b| {
            b.iter(|| {
                k += 1;
                black_box(f(k))
            })
        });
    }
    grp.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
