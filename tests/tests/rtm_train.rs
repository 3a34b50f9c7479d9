//! The forest-spectra inversion end to end: RTM model files (f32 table rows, round trip against
//! the f64 tables, corruption and inconsistency), a short training run of B, and
//! `magic forward rtm` against the oracle.
//!
//! Data are found through `MAGIC_DATA` or `../shared/data` next to the workspace; without them the
//! tests fail, saying what to set.

use magic_core::model_file::{Model, Problem};
use magic_core::rtm::{Fixed, Geometry, N_LEARNED};
use magic_core::{invert, Error, Variant, Workspace};
use magic_train::rtm::{RtmTables, S2_DATA_BANDS};
use magic_train::{
    train_model, Dataset, ModelKind, OwnedEffect, OwnedModel, Problem as _, RtmProblem, TrainConfig,
};
use std::path::PathBuf;
use std::sync::OnceLock;

// Tolerances: the measured difference (printed by `-- --nocapture`) times 10, rounded up, unless
// stated otherwise.

/// How far an inverted variable may sit outside its bound, relative to the bound (f64 path; the
/// sigmoid maps into the bounds): measured 0; the rounding of `min + (max − min) · u`.
const BOUND_SLACK_REL: f64 = 4.0 * f64::EPSILON;
/// Crown diameter and height derived from fc against the paper's eqs. 7–8 written out here,
/// relative: measured 0 (the same operations); a few ulps.
const CROWN_MAX_REL_ERROR: f64 = 4.0 * f64::EPSILON;
/// The model file's f32 table rows against the f64 tables (band reflectance): measured 3.5e-9.
const F32_ROWS_MAX_ERROR: f64 = 4e-8;
/// The f32 inversion's reconstruction against the f64 one (reflectance): measured 6.1e-8.
const F32_RECON_MAX_ERROR: f64 = 7e-7;
/// `magic forward rtm` against the oracle file: measured 3.0e-14.
const CLI_FORWARD_MAX_ERROR: f64 = 4e-13;
/// `magic forward prosail` against the prosail package's file (the four factors, printed with
/// 17 significant digits): measured 9.1e-14 (the core's own error against it, see rtm_oracle).
const CLI_PROSAIL_MAX_ERROR: f64 = 1e-12;
/// The board's variables (printed with 6 decimals) against the host's, relative to
/// max(|host|, 0.01): measured 3.9e-5 and 3.7e-5 (f32 INFORM and the printing).
const BOARD_MAX_REL_ERROR: f64 = 4e-4;
/// The board's residual RMS against the host's (reflectance): measured 4.8e-7 and 4.2e-7.
const BOARD_RESIDUAL_MAX_ERROR: f64 = 5e-6;
/// Band offsets added to INFORM's bands against the declared offsets (f32 in the file):
/// measured 1.6e-9.
const OFFSET_MAX_ERROR: f64 = 2e-8;

/// The data folder, with the RTM tables and the Sentinel-2 extract (a test failure without them).
fn data_dir() -> PathBuf {
    magic_tests::data_with(&["rtm/prospect_d_coefficients.csv", "s2/train.csv", "oracle"])
}

fn setup() -> &'static RtmProblem {
    static S: OnceLock<RtmProblem> = OnceLock::new();
    S.get_or_init(|| {
        let d = data_dir();
        RtmProblem::read(&d.join("s2"), &d.join("rtm"), Geometry::Reference).unwrap()
    })
}

/// A short training run of B (few hundred spectra, 2 epochs), shared by the tests.
fn trained_b() -> &'static (OwnedModel, Vec<u8>) {
    static M: OnceLock<(OwnedModel, Vec<u8>)> = OnceLock::new();
    M.get_or_init(|| {
        let s = setup();
        let cfg = TrainConfig {
            epochs: 2,
            progress: false,
            ..TrainConfig::s2()
        };
        let mut small = s.clone();
        small.data.train = s.data.train.head(300);
        small.data.valid = s.data.valid.head(200);
        let (model, log) = train_model(&small, ModelKind::B, &[], &cfg, 7).unwrap();
        assert_eq!(log.epochs, 2);
        assert!(
            log.best_valid.is_finite() && log.best_valid < 5.0,
            "valid MSE {}",
            log.best_valid
        );
        let bytes = model.encode().unwrap();
        (model, bytes)
    })
}

fn physical(data: &Dataset, row: &[f32]) -> Vec<f32> {
    row.iter()
        .enumerate()
        .map(|(c, v)| (*v as f64 * data.scale[c] + data.mean[c]) as f32)
        .collect()
}

#[test]
fn short_training_run_of_b_gives_a_valid_small_model() {
    let (model, bytes) = trained_b();
    assert_eq!(model.variant, Variant::B);
    assert!(
        bytes.len() <= 256 * 1024,
        "RTM model is {} bytes",
        bytes.len()
    );
    let m = Model::decode(bytes).unwrap();
    assert_eq!(m.n_obs(), 11);
    assert_eq!(m.n_params(), N_LEARNED);
    let s = setup();
    let mut ws = Workspace::default();
    let (mut outside, mut crown) = (0f64, 0f64);
    for row in s.data.test.x.iter().take(50) {
        let inv = invert::<f64>(&m, &physical(&s.data, row), &mut ws).unwrap();
        // 7 learned variables, then cd and h.
        assert_eq!(inv.n_params, N_LEARNED + 2);
        for (j, b) in m.bounds.iter().enumerate() {
            let out = (b[0] as f64 - inv.params[j]).max(inv.params[j] - b[1] as f64);
            outside = outside.max(out);
            let slack = BOUND_SLACK_REL * b[0].abs().max(b[1].abs()) as f64;
            assert!(
                out <= slack,
                "variable {j}: {} outside {b:?}",
                inv.params[j]
            );
        }
        let (cd, h) = (inv.params[7], inv.params[8]);
        let want_cd = 2.0 * (inv.params[6] * 1e4 / (std::f64::consts::PI * 500.0)).sqrt();
        let want_h = (2.117 + 0.507 * cd.ln()).exp();
        let err = ((cd - want_cd) / want_cd)
            .abs()
            .max(((h - want_h) / want_h).abs());
        crown = crown.max(err);
        assert!(err <= CROWN_MAX_REL_ERROR, "cd {cd}, h {h}: {err:e}");
        assert!(inv.recon[..11]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0 && *v < 1.0));
    }
    eprintln!("RTM B: largest excursion outside a bound {outside:.2e}, crown formulas {crown:.2e}");
}

#[test]
fn model_file_round_trip_matches_the_f64_tables() {
    let (_, bytes) = trained_b();
    let d = data_dir();
    let tables = RtmTables::read(&d.join("rtm")).unwrap();
    let full = tables.inform().unwrap();
    let s = setup();
    let m = Model::decode(bytes).unwrap();
    // Decode → encode again gives the same bytes.
    assert_eq!(&OwnedModel::from_model(&m).encode().unwrap(), bytes);
    let mut ws = Workspace::default();
    let mut worst = 0f64;
    for row in s.data.test.x.iter().step_by(37).take(100) {
        let inv = invert::<f64>(&m, &physical(&s.data, row), &mut ws).unwrap();
        let z: [f64; N_LEARNED] = inv.params[..N_LEARNED].try_into().unwrap();
        let y = full
            .forward_learned(&z, &Fixed::default(), Geometry::Reference)
            .unwrap();
        for (k, &b) in S2_DATA_BANDS.iter().enumerate() {
            worst = worst.max((inv.recon[k] - y[b]).abs());
        }
    }
    assert!(
        worst <= F32_ROWS_MAX_ERROR,
        "f32 table rows vs f64 tables: {worst}"
    );
    // f32 physics on the board's path agrees too.
    let row = physical(&s.data, &s.data.test.x[0]);
    let a = invert::<f64>(&m, &row, &mut ws).unwrap();
    let b = invert::<f32>(&m, &row, &mut ws).unwrap();
    let mut recon = 0f64;
    for k in 0..11 {
        let d = (a.recon[k] - b.recon[k] as f64).abs();
        recon = recon.max(d);
        assert!(
            d <= F32_RECON_MAX_ERROR,
            "band {k}: {} vs {}",
            a.recon[k],
            b.recon[k]
        );
    }
    eprintln!(
        "RTM model file: f32 rows vs f64 tables {worst:.2e}, f32 vs f64 reconstruction {recon:.2e}"
    );
}

#[test]
fn corrupt_and_inconsistent_rtm_files_are_errors() {
    let (model, bytes) = trained_b();
    // Flipped bits anywhere (CRC).
    for i in (0..bytes.len()).step_by(bytes.len() / 97) {
        let mut c = bytes.clone();
        c[i] ^= 0x10;
        assert!(Model::decode(&c).is_err(), "flip at {i} accepted");
    }
    // Truncated.
    assert_eq!(
        Model::decode(&bytes[..bytes.len() - 1]).unwrap_err(),
        Error::Truncated
    );
    // An RTM model where a Mogi model is expected.
    let m = Model::decode(bytes).unwrap();
    assert_eq!(m.stations().unwrap_err(), Error::WrongProblem);

    let with = |f: &dyn Fn(&mut OwnedModel)| {
        let mut o = model.clone();
        f(&mut o);
        o.encode().unwrap_err().to_string()
    };
    let Problem::Rtm {
        spectral,
        weights,
        lidf_beta,
        ..
    } = model.problem.clone()
    else {
        panic!("not RTM")
    };
    // The band mask does not match the 11 observations.
    let e = with(&|o| {
        if let Problem::Rtm { bands, .. } = &mut o.problem {
            *bands &= !(1 << 12);
        }
    });
    assert!(e.contains("observations"), "{e}");
    // A band beyond B12.
    let e = with(&|o| {
        if let Problem::Rtm { bands, .. } = &mut o.problem {
            *bands |= 1 << 14;
        }
    });
    assert!(e.contains("band"), "{e}");
    // Table rows cut short / weights that do not match the rows.
    let e = with(&|o| {
        if let Problem::Rtm { spectral: s, .. } = &mut o.problem {
            *s = magic_core::quant::LeF32(&spectral.0[..spectral.0.len() - 4]);
        }
    });
    assert!(e.contains("spectral"), "{e}");
    let e = with(&|o| {
        if let Problem::Rtm { weights: w, .. } = &mut o.problem {
            *w = magic_core::quant::LeF32(&weights.0[..weights.0.len() - 44]);
        }
    });
    assert!(e.contains("weights"), "{e}");
    let e = with(&|o| {
        if let Problem::Rtm { lidf_beta: l, .. } = &mut o.problem {
            *l = magic_core::quant::LeF32(&lidf_beta.0[..12 * 4]);
        }
    });
    assert!(e.contains("lidf"), "{e}");
    // Fixed inputs the forward model rejects: a beta row that does not exist, sun at the horizon.
    let e = with(&|o| {
        if let Problem::Rtm { fixed, .. } = &mut o.problem {
            fixed.lidf = 9.0;
        }
    });
    assert!(e.contains("LIDF"), "{e}");
    let e = with(&|o| {
        if let Problem::Rtm { fixed, .. } = &mut o.problem {
            fixed.tts = 95.0;
        }
    });
    assert!(e.contains("tts"), "{e}");
    // Bounds the physics cannot take; the wrong number of variables.
    let e = with(&|o| o.bounds[4][0] = -1.0);
    assert!(e.contains("positive"), "{e}");
    let e = with(&|o| {
        o.bounds.pop();
    });
    assert!(!e.is_empty());
    // GNSS effects are not RTM effects; illumination needs the physical geometry (this model is
    // in the reference geometry).
    let e = with(&|o| o.effects.push(OwnedEffect::CommonMode));
    assert!(e.contains("not an RTM effect"), "{e}");
    let e = with(&|o| o.effects.push(setup().illumination()));
    assert!(e.contains("physical geometry"), "{e}");
}

/// Runs `magic forward <model>` (with `extra` arguments) on the first `rows` rows of an oracle
/// file and returns the largest difference from the file over the output columns it writes,
/// checking one output row per input row, the `sample_id`s and the header `want`; `column`
/// names the oracle's column for an output column.
fn forward_command_error(
    model: &str,
    oracle: &str,
    rows: usize,
    extra: &[&str],
    want: &[String],
    column: &dyn Fn(&str) -> String,
) -> f64 {
    let d = data_dir();
    let text = std::fs::read_to_string(d.join("oracle").join(oracle)).unwrap();
    let head: String = text
        .lines()
        .take(rows + 1)
        .map(|l| format!("{l}\n"))
        .collect();
    let dir = std::env::temp_dir().join(format!("magic-{model}-forward-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (input, output) = (dir.join("in.csv"), dir.join("out.csv"));
    std::fs::write(&input, &head).unwrap();
    let status = std::process::Command::new(magic_tests::magic_bin())
        .args(["forward", model])
        .args(extra)
        .arg("--input")
        .arg(&input)
        .arg("--output")
        .arg(&output)
        .arg("--tables")
        .arg(d.join("rtm"))
        .status()
        .unwrap();
    assert!(status.success(), "magic forward {model}");
    let mut rdr = csv::Reader::from_path(&input).unwrap();
    let want_header = rdr.headers().unwrap().clone();
    let expected: Vec<_> = rdr.into_records().map(|r| r.unwrap()).collect();
    let mut rdr = csv::Reader::from_path(&output).unwrap();
    let header = rdr.headers().unwrap().clone();
    let got: Vec<_> = rdr.into_records().map(|r| r.unwrap()).collect();
    assert_eq!(got.len(), rows, "one output row per input row");
    assert_eq!(
        header.iter().skip(1).collect::<Vec<_>>(),
        want.iter().map(|s| s.as_str()).collect::<Vec<_>>()
    );
    let mut worst = 0f64;
    for (g, w) in got.iter().zip(&expected) {
        assert_eq!(&g[0], &w[0], "sample_id");
        for (k, name) in want.iter().enumerate() {
            let c = want_header.iter().position(|h| h == column(name)).unwrap();
            let a: f64 = g[k + 1].parse().unwrap();
            let e: f64 = w[c].parse().unwrap();
            worst = worst.max((a - e).abs());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    worst
}

#[test]
fn forward_rtm_command_matches_the_oracle() {
    let bands: Vec<String> = magic_core::rtm::S2_BANDS
        .iter()
        .map(|b| b.to_string())
        .collect();
    let worst = forward_command_error(
        "rtm",
        "rtm_inform_s2_10k.csv",
        300,
        &["--geometry", "reference"],
        &bands,
        &|c| c.to_string(),
    );
    eprintln!("forward rtm vs oracle: {worst:.2e}");
    assert!(
        worst <= CLI_FORWARD_MAX_ERROR,
        "forward rtm vs oracle: {worst}"
    );
}

#[test]
fn forward_prosail_command_matches_the_prosail_package() {
    let names: Vec<String> = magic_core::rtm::prosail::FACTOR_NAMES
        .iter()
        .flat_map(|f| {
            magic_core::rtm::S2_BANDS
                .iter()
                .map(move |b| format!("{f}_{b}"))
        })
        .collect();
    // The file's `rdot_*` and `rddt_*` columns are swapped (see rtm_oracle's PROSAIL test).
    let swapped = |c: &str| {
        if let Some(b) = c.strip_prefix("rdot_") {
            format!("rddt_{b}")
        } else if let Some(b) = c.strip_prefix("rddt_") {
            format!("rdot_{b}")
        } else {
            c.to_string()
        }
    };
    let worst = forward_command_error(
        "prosail",
        "sail_4sail_s2_1k.csv",
        300,
        &[],
        &names,
        &swapped,
    );
    eprintln!("forward prosail vs the prosail package: {worst:.2e}");
    assert!(
        worst <= CLI_PROSAIL_MAX_ERROR,
        "forward prosail vs the prosail package: {worst}"
    );
}

/// The board's variables (`got`, a result line parsed) against the host's inversion, relative to
/// max(|host|, 0.01); returns the largest difference.
fn board_agrees(got: &[f64], inv: &magic_core::Inversion<f64>, line: &str) -> f64 {
    let mut worst = 0f64;
    for (j, (&a, &e)) in got.iter().zip(&inv.params[..inv.n_params]).enumerate() {
        let rel = (a - e).abs() / e.abs().max(1e-2);
        worst = worst.max(rel);
        assert!(
            rel <= BOARD_MAX_REL_ERROR,
            "{line}: variable {j}: board {a}, host {e}"
        );
    }
    worst
}

/// The RTM model on the Cortex-M4F under QEMU (f32 physics from the model file's f32 rows)
/// agrees with the host's f64 inversion. Skipped when the toolchain or QEMU is missing.
#[test]
fn rtm_model_runs_on_the_firmware_under_qemu() {
    let (_, bytes) = trained_b();
    if !magic_tests::toolchain_ready() {
        return;
    }
    let s = setup();
    let dir = std::env::temp_dir().join(format!("magic-rtm-fw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rtm_b.magic");
    std::fs::write(&path, bytes).unwrap();
    let elf = magic_train::firmware::qemu::build_firmware(&path).unwrap();
    let rows: Vec<Vec<f32>> = s
        .data
        .test
        .x
        .iter()
        .take(8)
        .map(|r| physical(&s.data, r))
        .collect();
    let input: String = rows
        .iter()
        .map(|r| {
            r.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(",")
                + "\n"
        })
        .collect();
    let run = magic_train::firmware::qemu::run_firmware(&elf, &input, 300).unwrap();
    assert!(run.success, "firmware failed: {}", run.stderr);
    assert_eq!(run.results.len(), rows.len());
    let m = Model::decode(bytes).unwrap();
    let mut ws = Workspace::default();
    let (mut worst_res, mut worst_var) = (0f64, 0f64);
    for (row, line) in rows.iter().zip(&run.results) {
        let inv = invert::<f64>(&m, row, &mut ws).unwrap();
        let got: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(got.len(), inv.n_params + 3, "{line}");
        worst_var = worst_var.max(board_agrees(&got, &inv, line));
        // The residual RMS (reflectance) of the board's f32 INFORM reconstruction against the
        // host's f64 one: it differs by at most the largest difference of the reconstructions.
        let res = got[inv.n_params];
        worst_res = worst_res.max((res - inv.residual_rms).abs());
        assert!(
            (res - inv.residual_rms).abs() <= BOARD_RESIDUAL_MAX_ERROR,
            "residual: board {res}, host {}",
            inv.residual_rms
        );
    }
    eprintln!(
        "RTM board vs host: variables {worst_var:.2e} (relative), residual RMS {worst_res:.2e}"
    );
    eprintln!(
        "RTM on the board: {:?} instructions per inversion, stack {:?} bytes, flash {:?} bytes",
        run.instructions_per_inversion, run.stack_bytes, run.flash_bytes
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The paper's released C weights, run through our INFORM (model file, f32 rows) and the core's
/// `invert`, reproduce its Table 3 test MSE and its physics-only MSE.
#[test]
fn released_c_weights_reproduce_the_paper_through_our_forward_model() {
    let s = setup();
    let w = data_dir().join("oracle/pretrained_rtm_c_weights.json");
    let model = magic_train::rtm::released::released_c(s, &w).unwrap();
    let bytes = model.encode().unwrap();
    let m = Model::decode(&bytes).unwrap();
    let r = magic_train::evaluate(&m, &s.data.test, "test").unwrap();
    let p = r.physics_mse.unwrap();
    eprintln!(
        "released C through our F: test MSE {:.6}, physics-only {p:.6}",
        r.mse
    );
    // The paper prints 0.0217 and 1.04 (Table 3): ours must round to the same digits.
    assert!((r.mse - 0.0217).abs() <= 0.5e-4, "test MSE {}", r.mse);
    assert!((p - 1.04).abs() <= 0.5e-2, "physics-only MSE {p}");
}

/// The S2 reader names the file, line and column of a bad cell, and finds bands by prefix.
#[test]
fn s2_reader_reports_bad_cells_by_file_line_and_column() {
    let dir = std::env::temp_dir().join(format!("magic-s2-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bands = "B02_BLUE,B03_GREEN,B04_RED,B05_RE1,B06_RE2,B07_RE3,B08_NIR1,B8A_NIR2,B09_WV,B11_SWI1,B12_SWI2";
    let good = "0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1.0,1.1,Fagus sylvatica,3,2018.07.02";
    let write = |name: &str, body: &str| std::fs::write(dir.join(name), body).unwrap();
    write("train_x_mean.csv", &"0.05\n".repeat(11));
    write("train_x_scale.csv", &"0.01\n".repeat(11));
    let split = |rows: &[&str]| format!("{bands},class,sample_id,date\n{}\n", rows.join("\n"));
    write("train.csv", &split(&[good, good]));
    write("valid.csv", &split(&[good]));
    write("test.csv", &split(&[good]));
    let read = magic_train::rtm::data::read_dir;
    let d = read(&dir).unwrap();
    assert_eq!((d.train.len(), d.n_obs(), d.train.ids[1]), (2, 11, 3));
    assert_eq!(d.columns[7], "B8A_NIR2");
    write("train.csv", &split(&[good, &good.replacen("0.2", "x", 1)]));
    let e = read(&dir).unwrap_err().to_string();
    assert!(
        e.contains("train.csv:3:5") && e.contains("B03_GREEN"),
        "{e}"
    );
    write("train.csv", &split(&[&good.replace("2018.07.02", "July")]));
    let e = read(&dir).unwrap_err().to_string();
    // (Locations are the file's line and the character column where the cell starts.)
    let date_column = good.rfind(',').unwrap() + 2;
    assert!(
        e.contains(&format!("train.csv:2:{date_column}:")) && e.contains("date"),
        "{e}"
    );
    write("train.csv", &split(&[good]).replace("B09_WV", "B10"));
    let e = read(&dir).unwrap_err().to_string();
    assert!(e.contains("B09"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Synthetic spectra that hold an effect nobody declared to the model: INFORM (physical
/// geometry) with each acquisition's true sun, from random variables, on the dates and species of
/// the S2 splits, plus noise. A B model trained with the paper's fixed sun must leave a residual
/// the analysis traces to `illumination` (ranked first, significant), and nothing else; with the
/// effect declared, the family is no longer a candidate (its pattern is zero).
#[test]
fn undeclared_illumination_is_found_in_synthetic_spectra() {
    use magic_train::{analyse, AnalysisOptions};
    use rand::{Rng, SeedableRng};
    let d = data_dir();
    let mut setup = RtmProblem::read(&d.join("s2"), &d.join("rtm"), Geometry::Physical).unwrap();
    let truth = setup.physics(&[setup.illumination()]).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let bounds = magic_core::rtm::LEARNED_BOUNDS;
    let data = setup.data.clone();
    let mut synth = |split: &magic_train::Split, n: usize| {
        let mut s = split.head(n);
        let days = s.days();
        for (row, t) in s.x.iter_mut().zip(&days) {
            // Variables in the middle 80 % of their ranges.
            let z: Vec<f64> = bounds
                .iter()
                .map(|b| b[0] + (b[1] - b[0]) * (0.1 + 0.8 * rng.random::<f64>()))
                .collect();
            let mut y = vec![0.0; row.len()];
            truth.forward(&z, *t, &mut y).unwrap();
            for (c, v) in row.iter_mut().enumerate() {
                let noise = 0.002 * (rng.random::<f64>() - 0.5);
                *v = ((y[c] + noise - data.mean[c]) / data.scale[c]) as f32;
            }
        }
        s
    };
    setup.data.train = synth(&data.train, 2400);
    setup.data.valid = synth(&data.valid, 800);
    setup.data.test = synth(&data.test, 200);
    let cfg = TrainConfig {
        epochs: 8,
        progress: false,
        ..TrainConfig::s2()
    };
    let (b0, _) = train_model(&setup, ModelKind::B, &[], &cfg, 3).unwrap();
    let bytes0 = b0.encode().unwrap();
    let m0 = Model::decode(&bytes0).unwrap();
    let opts = AnalysisOptions::default();
    let (a0, _) = analyse(&setup, &m0, &opts).unwrap();
    eprintln!("fixed sun:\n{}", a0.table());
    let top = &a0.effects[0];
    assert_eq!(top.family, "illumination", "{}", a0.table());
    assert!(top.significant, "{}", a0.table());
    assert!(
        a0.effects[1..].iter().all(|c| !c.significant),
        "{}",
        a0.table()
    );
    // How sure: the pattern's weight with its bootstrap sd (fitting spectra drawn with
    // replacement).
    let w = top
        .uncertainty
        .iter()
        .find(|p| p.name == "weight")
        .expect("the illumination weight carries a bootstrap sd");
    eprintln!("illumination weight {:.3} ± {:.3}", w.value, w.sd);
    assert!(
        w.sd > 0.0 && w.sd.is_finite() && w.sd < w.value.abs(),
        "{w:?}"
    );

    let (b1, _) = train_model(&setup, ModelKind::B, &[setup.illumination()], &cfg, 3).unwrap();
    let bytes1 = b1.encode().unwrap();
    let m1 = Model::decode(&bytes1).unwrap();
    assert!(m1.needs_time());
    let (a1, _) = analyse(&setup, &m1, &opts).unwrap();
    eprintln!("true sun:\n{}", a1.table());
    // (B's error with the true sun is not asserted: the encoder does not see the date, so it
    // cannot undo a date-dependent sun exactly, and after a few epochs it is still far from
    // converged; the loop on the measured data reports the full-recipe numbers.)
    let ill = a1
        .effects
        .iter()
        .find(|c| c.family == "illumination")
        .unwrap();
    assert!(ill.effect.is_none() && ill.variance_explained == 0.0);
}

/// An RTM model with the illumination effect (physical geometry) and band offsets reads a date on
/// each line on the board, and the board's sun (computed there from the date) gives the host's
/// results.
#[test]
fn rtm_illumination_model_runs_on_the_firmware() {
    let (model, _) = trained_b();
    if !magic_tests::toolchain_ready() {
        return;
    }
    let mut m = model.clone();
    if let Problem::Rtm { geometry, .. } = &mut m.problem {
        *geometry = Geometry::Physical;
    }
    m.effects = vec![
        setup().illumination(),
        OwnedEffect::BandOffset {
            offset: (0..11).map(|b| 0.002 * b as f32 - 0.01).collect(),
        },
    ];
    let bytes = m.encode().unwrap();
    let decoded = Model::decode(&bytes).unwrap();
    assert!(decoded.needs_time());
    // The offsets add to INFORM's bands.
    let z = [1.5, 40.0, 0.01, 0.01, 3.0, 0.5, 0.6];
    let (mut with, mut without) = ([0.0; 11], [0.0; 11]);
    magic_core::invert::forward::<f64>(&decoded, &z, 17_700.0, &mut with).unwrap();
    let mut plain = decoded.clone();
    plain.effects.truncate(1);
    magic_core::invert::forward::<f64>(&plain, &z, 17_700.0, &mut without).unwrap();
    let mut off = 0f64;
    for (b, (w, o)) in with.iter().zip(&without).enumerate() {
        let d = (w - o - (0.002 * b as f64 - 0.01)).abs();
        off = off.max(d);
        assert!(d <= OFFSET_MAX_ERROR, "band {b}: {d:e}");
    }
    let s = setup();
    let dir = std::env::temp_dir().join(format!("magic-rtm-ill-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rtm_ill.magic");
    std::fs::write(&path, &bytes).unwrap();
    let elf = magic_train::firmware::qemu::build_firmware(&path).unwrap();
    let test = &s.data.test;
    let idx: Vec<usize> = (0..test.len()).step_by(test.len() / 6).take(6).collect();
    let lines: Vec<String> = idx
        .iter()
        .map(|&i| {
            let date = test.dates[i].replace('.', "-");
            let vals: Vec<String> = physical(&s.data, &test.x[i])
                .iter()
                .map(|v| format!("{v}"))
                .collect();
            format!("{date},{}", vals.join(","))
        })
        .collect();
    let input: String = lines.iter().map(|l| format!("{l}\n")).collect();
    let run = magic_train::firmware::qemu::run_firmware(&elf, &input, 300).unwrap();
    assert!(run.success, "firmware failed: {}", run.stderr);
    assert_eq!(run.results.len(), lines.len());
    let mut ws = Workspace::default();
    let (mut worst_var, mut worst_res) = (0f64, 0f64);
    for (line, got) in lines.iter().zip(&run.results) {
        let mut obs = vec![0f32; 11];
        let day = magic_core::line::parse_record(line, true, &mut obs).unwrap();
        let inv = magic_core::invert_at::<f64>(&decoded, &obs, day, &mut ws).unwrap();
        let got: Vec<f64> = got.split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(got.len(), inv.n_params + 3);
        worst_var = worst_var.max(board_agrees(&got, &inv, line));
        let res = (got[inv.n_params] - inv.residual_rms).abs();
        worst_res = worst_res.max(res);
        assert!(res <= BOARD_RESIDUAL_MAX_ERROR, "{line}: residual {res:e}");
    }
    eprintln!(
        "RTM illumination model, board vs host: variables {worst_var:.2e} (relative), residual RMS \
         {worst_res:.2e}; band offsets {off:.2e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
