//! The Cortex-M4F firmware under QEMU against the host: a small int8 model built here is embedded
//! in the firmware, ~50 observation lines (some malformed) are streamed through it, and every
//! result must agree with `magic_core::invert::<f64>` on the host to [`BOARD_MAX_REL_ERROR`] of
//! each variable's range. A corrupt or truncated model must make the firmware exit non-zero with an
//! `error,model:` line.
//!
//! The firmware is also built with the feature `panic-never` (a panic handler that calls an
//! undefined function): it must link, which proves that no panic is reachable in it — the whole
//! firmware, inversion path included — and a build with a deliberately reachable panic
//! (`panic-canary`) must not.
//!
//! Needs `qemu-system-arm` and the Rust target `thumbv7em-none-eabihf`; without them the test
//! fails with a message saying how to install them, unless `MAGIC_SKIP_QEMU=1`.

use magic_core::model_file::{Model, Variant};
use magic_core::mogi::{self, Station, PAPER_BOUNDS};
use magic_core::nn::Activation;
use magic_tests::{toolchain_ready, TempDir};
use magic_train::firmware::qemu::{build_firmware, build_firmware_with, run_firmware};
use magic_train::model::{OwnedEffect, OwnedLayer, OwnedModel, OwnedWeights};
use std::path::Path;

const N_STATIONS: usize = 12;
const N_OBS: usize = 3 * N_STATIONS;
const TIMEOUT_S: u64 = 120;
/// The board's variables (f32, printed with 6 decimals) against the host's f64 inversion, as a
/// fraction of each variable's range: measured 5.4e-8 (plain model), 4.6e-8 and 5.7e-8 (effects
/// models); 10× the largest.
const BOARD_MAX_REL_ERROR: f64 = 6e-7;
/// The board's standard deviations (feature `sd`: f64 in software from its f32 inversion) against
/// the host's (from its f64 inversion), relative: measured 2.5e-6; 10× that.
const BOARD_SD_MAX_REL_ERROR: f64 = 2.5e-5;

/// A deterministic pseudo-random stream (xorshift64*), uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        v as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn stations() -> Vec<Station> {
    (0..N_STATIONS)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / N_STATIONS as f64;
            let r = 3.0 + (i % 4) as f64 * 2.5;
            Station {
                x_km: r * a.cos() + 2.0,
                y_km: r * a.sin(),
                z_km: 0.1 * (i % 3) as f64,
            }
        })
        .collect()
}

fn dense(rng: &mut Rng, rows: usize, cols: usize, act: Activation) -> OwnedLayer {
    let s = (3.0 / cols as f64).sqrt();
    let w = (0..rows * cols).map(|_| (rng.next() * s) as f32).collect();
    let b = (0..rows).map(|_| (rng.next() * 0.1) as f32).collect();
    OwnedLayer {
        rows,
        cols,
        act,
        weights: OwnedWeights::F32 { w, b },
    }
}

/// Mogi displacements (mm) of a random source inside the paper's bounds, plus noise.
fn observation(rng: &mut Rng, st: &[Station]) -> Vec<f32> {
    let p: [f64; 4] = std::array::from_fn(|j| {
        let [lo, hi] = PAPER_BOUNDS[j];
        lo + (hi - lo) * (0.5 + 0.45 * rng.next())
    });
    let mut u = vec![0f64; N_OBS];
    mogi::field(st, &p, &mut u).unwrap();
    u.iter().map(|v| (v + 0.5 * rng.next()) as f32).collect()
}

/// A variant-C model (encoder 36-64-32-16-4, correction 36-144-36) with random weights,
/// quantised to int8 with calibration rows, as model-file bytes.
fn model_bytes() -> Vec<u8> {
    model_bytes_with(vec![])
}

/// The same with declared effects: the encoder gains one output per latent variable (bounded as
/// the trainer bounds them).
fn model_bytes_with(effects: Vec<OwnedEffect>) -> Vec<u8> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let st = stations();
    let rows: Vec<Vec<f32>> = (0..128).map(|_| observation(&mut rng, &st)).collect();
    let mean: Vec<f32> = (0..N_OBS)
        .map(|c| rows.iter().map(|r| r[c]).sum::<f32>() / rows.len() as f32)
        .collect();
    let scale: Vec<f32> = (0..N_OBS)
        .map(|c| {
            let v = rows.iter().map(|r| (r[c] - mean[c]).powi(2)).sum::<f32>() / rows.len() as f32;
            v.sqrt().max(1e-3)
        })
        .collect();
    let names: Vec<String> = (0..N_STATIONS).map(|i| format!("S{i:02}")).collect();
    let problem = magic_train::Network {
        names,
        stations: st.clone(),
    }
    .spec()
    .unwrap();
    let mut bounds: Vec<[f32; 2]> = PAPER_BOUNDS
        .iter()
        .map(|b| [b[0] as f32, b[1] as f32])
        .collect();
    for e in &effects {
        bounds.extend(
            magic_train::gnss::effect_bounds(e)
                .iter()
                .map(|b| [b[0] as f32, b[1] as f32]),
        );
    }
    let n_out = bounds.len();
    let f32_model = OwnedModel {
        variant: Variant::C,
        problem,
        mean: mean.clone(),
        scale: scale.clone(),
        bounds,
        encoder: vec![
            dense(&mut rng, 64, N_OBS, Activation::Relu),
            dense(&mut rng, 32, 64, Activation::Relu),
            dense(&mut rng, 16, 32, Activation::Relu),
            dense(&mut rng, n_out, 16, Activation::Sigmoid),
        ],
        decoder: vec![
            dense(&mut rng, 4 * N_OBS, N_OBS, Activation::Relu),
            dense(&mut rng, N_OBS, 4 * N_OBS, Activation::Linear),
        ],
        residual_threshold: 2.0,
        effects,
    };
    let calib: Vec<Vec<f32>> = rows
        .iter()
        .map(|r| {
            r.iter()
                .enumerate()
                .map(|(c, v)| (v - mean[c]) / scale[c])
                .collect()
        })
        .collect();
    // Calibration days spread over the years the effects tests use (ignored without effects).
    let days: Vec<f64> = (0..calib.len())
        .map(|i| 13_500.0 + 19.0 * i as f64)
        .collect();
    f32_model
        .quantize_int8_at(&calib, &days)
        .unwrap()
        .encode()
        .unwrap()
}

/// Input lines: valid observations (some with missing channels) and malformed lines; for each,
/// whether the firmware must answer with an error.
fn input_lines() -> Vec<(String, bool)> {
    let mut rng = Rng(0xD1B5_4A32_D192_ED03);
    let st = stations();
    let fmt = |v: &[f32]| {
        v.iter()
            .map(|x| {
                if x.is_nan() {
                    String::new()
                } else {
                    format!("{x}")
                }
            })
            .collect::<Vec<_>>()
            .join(",")
    };
    let mut lines = Vec::new();
    for i in 0..44 {
        let mut obs = observation(&mut rng, &st);
        if i % 11 == 5 {
            obs[3] = f32::NAN; // a missing channel
            obs[N_STATIONS + 3] = f32::NAN;
        }
        let text = if i % 7 == 3 {
            obs.iter()
                .map(|x| format!(" {x:.3} "))
                .collect::<Vec<_>>()
                .join(",")
        } else {
            fmt(&obs)
        };
        lines.push((text, false));
    }
    let good = fmt(&observation(&mut rng, &st));
    let fields: Vec<&str> = good.split(',').collect();
    lines.push((fields[..N_OBS - 1].join(","), true)); // one field short
    lines.push((format!("{good},1.0"), true)); // one field too many
    lines.push((good.replacen(fields[4], "abc", 1), true)); // not a number
    lines.push((good.replacen(fields[7], "inf", 1), true)); // infinite
    lines.push((good.replacen(fields[9], "12345.0", 1), true)); // beyond 10 m
    lines.push((String::new(), true)); // empty line
    lines.push((vec![""; N_OBS].join(","), true)); // every channel missing
    lines.push((format!("{good}\r"), false)); // CRLF line end
    lines
}

/// Checks a board's result row against the host's inversion: as many fields, every variable
/// within [`BOARD_MAX_REL_ERROR`] of its range. Returns the largest difference (fraction of the range).
fn variables_agree(
    model: &Model<'_>,
    line: &str,
    fields: &[&str],
    inv: &magic_core::Inversion<f64>,
) -> f64 {
    assert_eq!(fields.len(), inv.n_params + 3, "{}", fields.join(","));
    assert_eq!(model.bounds.len(), inv.n_params, "one bound per variable");
    let mut worst = 0f64;
    for (j, (field, [lo, hi])) in fields
        .iter()
        .zip(&model.bounds)
        .take(inv.n_params)
        .enumerate()
    {
        let fw: f64 = field.parse().unwrap();
        let rel = (fw - inv.params[j]).abs() / (hi - lo) as f64;
        worst = worst.max(rel);
        assert!(
            rel <= BOARD_MAX_REL_ERROR,
            "variable {j} of {line:?}: board {fw}, host {} ({rel:.2e} of the range)",
            inv.params[j]
        );
    }
    worst
}

/// Runs `lines` through the firmware `elf` and checks that it succeeded with one output line
/// per input line.
fn run_lines(elf: &std::path::Path, lines: &[String]) -> magic_train::firmware::FirmwareRun {
    let input: String = lines.iter().map(|l| format!("{l}\n")).collect();
    let run = run_firmware(elf, &input, TIMEOUT_S).expect("running the firmware");
    assert!(
        run.success,
        "firmware failed: {:?}\n{}",
        run.results.last(),
        run.stderr
    );
    assert_eq!(
        run.results.len(),
        lines.len(),
        "one output line per input line"
    );
    run
}

#[test]
fn firmware_agrees_with_the_host() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model_bytes();
    let model = Model::decode(&bytes).unwrap();
    let tmp = TempDir::new("firmware");
    let path = tmp.join("model.magic");
    std::fs::write(&path, &bytes).unwrap();
    let elf = build_firmware(&path).expect("building the firmware");

    let lines = input_lines();
    let input: String = lines.iter().map(|(l, _)| format!("{l}\n")).collect();
    let run = run_firmware(&elf, &input, TIMEOUT_S).expect("running the firmware");
    assert!(
        run.success,
        "firmware failed (exit {:?}): {:?}\n{}",
        run.exit_code,
        run.results.last(),
        run.stderr
    );
    assert_eq!(
        run.results.len(),
        lines.len(),
        "one output line per input line:\n{}",
        run.results.join("\n")
    );

    let mut ws = magic_core::Workspace::default();
    let mut worst = 0f64;
    for ((line, must_fail), got) in lines.iter().zip(&run.results) {
        let mut obs = vec![0f32; N_OBS];
        let host = magic_core::line::parse_obs(line, &mut obs)
            .map_err(|e| e.to_string())
            .and_then(|()| {
                magic_core::invert::<f64>(&model, &obs, &mut ws).map_err(|e| e.to_string())
            });
        match host {
            Err(e) => {
                assert!(
                    got.starts_with("error,"),
                    "host rejects {line:?} ({e}) but the firmware printed {got}"
                );
                assert_eq!(
                    got,
                    &format!("error,{e}"),
                    "same message on host and board for {line:?}"
                );
            }
            Ok(inv) => {
                assert!(!must_fail, "{line:?} should have been rejected");
                assert!(
                    !got.starts_with("error"),
                    "firmware rejected {line:?}: {got}"
                );
                let fields: Vec<&str> = got.split(',').collect();
                worst = worst.max(variables_agree(&model, line, &fields, &inv));
                assert_eq!(
                    fields[inv.n_params + 1].parse::<u8>().unwrap()
                        & !magic_core::Flags::HIGH_RESIDUAL,
                    inv.flags.0 & !magic_core::Flags::HIGH_RESIDUAL,
                    "flags of {got}"
                );
                assert_eq!(
                    fields[inv.n_params + 2].parse::<u32>().unwrap(),
                    inv.used,
                    "station mask of {got}"
                );
            }
        }
    }
    let must_fail = lines.iter().filter(|(_, f)| *f).count();
    let errors = run
        .results
        .iter()
        .filter(|r| r.starts_with("error,"))
        .count();
    assert_eq!(errors, must_fail, "error lines");

    eprintln!("firmware vs host: largest difference {worst:.2e} of a variable's range");
    for (k, v) in &run.costs {
        eprintln!("  {k} = {v}");
    }
    assert!(
        run.instructions_per_inversion.is_some_and(|n| n > 0),
        "instruction count reported"
    );
    assert!(
        run.stack_bytes.is_some_and(|n| n > 0),
        "stack high-water mark reported"
    );
    assert_eq!(
        run.cost("clock_calibration_permille")
            .map(|c| (990..=1010).contains(&c)),
        Some(true),
        "SysTick follows -icount"
    );
}

/// A model with every effect family declared (latent: common mode, elevation, two second
/// sources; time-dependent: seasonal, step, drift) reads a date on every line; the board must agree with
/// `invert_at` on the host, and fit the 49 KiB flash budget (the link would fail otherwise).
#[test]
fn effects_models_run_on_the_firmware() {
    if !toolchain_ready() {
        return;
    }
    let mut rng = Rng(0x5DEE_CE66_D1CE_4E5B);
    // At most MAX_EFFECTS (4) per model: two models cover the six families.
    let first = vec![
        OwnedEffect::CommonMode,
        OwnedEffect::Elevation { z_ref_km: 0.1 },
        OwnedEffect::Seasonal {
            coef: (0..4 * N_OBS).map(|_| (2.0 * rng.next()) as f32).collect(),
        },
        OwnedEffect::Step {
            station: 5,
            epoch_day: 14_610.0, // 2010-01-01
            offset_mm: [3.0, -2.0, 6.0],
        },
    ];
    // Two extra sources, each with its own volume change (`magic loop --extra-sources 2`).
    let second = vec![
        OwnedEffect::SecondSource {
            x_km: -4.0,
            y_km: 3.0,
            depth_km: 6.0,
        },
        OwnedEffect::SecondSource {
            x_km: 7.0,
            y_km: -2.0,
            depth_km: 4.0,
        },
        OwnedEffect::Drift {
            t0_day: 13_880.0,
            rate: (0..N_OBS).map(|_| rng.next() as f32).collect(),
        },
    ];
    let tmp = TempDir::new("firmware");
    check_effects_model(&tmp.0, "first", first, 4 + 3 + 1, &mut rng);
    check_effects_model(&tmp.0, "second", second, 4 + 1 + 1, &mut rng);
}

/// Builds the firmware with an effects model (written into `dir`) and checks it against the host.
fn check_effects_model(
    dir: &Path,
    name: &str,
    effects: Vec<OwnedEffect>,
    n_params: usize,
    rng: &mut Rng,
) {
    let bytes = model_bytes_with(effects);
    let model = Model::decode(&bytes).unwrap();
    assert!(model.needs_time());
    let path = dir.join(format!("effects-{name}.magic"));
    std::fs::write(&path, &bytes).unwrap();
    let elf = build_firmware(&path).expect("building the firmware with an effects model");

    let st = stations();
    let mut lines = Vec::new();
    for i in 0..24 {
        let day = 13_500 + 97 * i; // 2006-12 … 2013-01, across the step
        let (y, m, d) = magic_core::time::civil_from_days(day);
        let obs = observation(rng, &st);
        let text: Vec<String> = obs.iter().map(|x| format!("{x}")).collect();
        lines.push(format!("{y:04}-{m:02}-{d:02},{}", text.join(",")));
    }
    lines.push(format!("2010-13-01,{}", vec!["1.0"; N_OBS].join(","))); // bad date
    lines.push(vec!["1.0"; N_OBS].join(",")); // no date
    let run = run_lines(&elf, &lines);

    let mut ws = magic_core::Workspace::default();
    let mut worst = 0f64;
    for (line, got) in lines.iter().zip(&run.results) {
        let mut obs = vec![0f32; N_OBS];
        let host = magic_core::line::parse_record(line, true, &mut obs)
            .map_err(|e| e.to_string())
            .and_then(|day| {
                magic_core::invert_at::<f64>(&model, &obs, day, &mut ws).map_err(|e| e.to_string())
            });
        match host {
            Err(e) => assert_eq!(got, &format!("error,{e}"), "{line:?}"),
            Ok(inv) => {
                let fields: Vec<&str> = got.split(',').collect();
                assert_eq!(inv.n_params, n_params, "source and latent variables");
                worst = worst.max(variables_agree(&model, line, &fields, &inv));
            }
        }
    }
    let errors = run
        .results
        .iter()
        .filter(|r| r.starts_with("error,"))
        .count();
    assert_eq!(errors, 2, "the bad and the missing date");
    eprintln!(
        "effects model {name} on the board: largest difference {worst:.2e} of a variable's range"
    );
    for k in [
        "instructions_per_inversion",
        "flash_bytes",
        "stack_bytes",
        "model_bytes",
    ] {
        eprintln!("  {k} = {:?}", run.cost(k));
    }
}

/// The firmware built with the feature `sd` appends each variable's standard deviation to every
/// result line, as `magic invert --sd` does; a model with a time-dependent effect, so that the
/// date reaches the Jacobian too.
#[test]
fn standard_deviations_run_on_the_firmware() {
    if !toolchain_ready() {
        return;
    }
    let effects = vec![
        OwnedEffect::CommonMode,
        OwnedEffect::Step {
            station: 5,
            epoch_day: 14_610.0, // 2010-01-01
            offset_mm: [3.0, -2.0, 6.0],
        },
    ];
    let bytes = model_bytes_with(effects);
    let model = Model::decode(&bytes).unwrap();
    let tmp = TempDir::new("firmware");
    let path = tmp.join("sd.magic");
    std::fs::write(&path, &bytes).unwrap();
    let elf = build_firmware_with(&path, &["sd"]).expect("building the firmware with `sd`");
    let mut rng = Rng(0x0DDB_A11C_AFE5_EED5);
    let st = stations();
    let mut lines = Vec::new();
    for i in 0..16 {
        let day = 13_500 + 193 * i; // across the step
        let (y, m, d) = magic_core::time::civil_from_days(day);
        let mut obs = observation(&mut rng, &st);
        if i % 5 == 0 {
            obs[..3].fill(f32::NAN); // a station down
        }
        let text: Vec<String> = obs
            .iter()
            .map(|x| {
                if x.is_nan() {
                    String::new()
                } else {
                    format!("{x}")
                }
            })
            .collect();
        lines.push(format!("{y:04}-{m:02}-{d:02},{}", text.join(",")));
    }
    lines.push(vec!["1.0"; N_OBS].join(",")); // no date: an error row, no standard deviations
    let run = run_lines(&elf, &lines);
    let (mut ws, mut sw) = (
        magic_core::Workspace::default(),
        magic_core::uncertainty::SdWorkspace::default(),
    );
    let mut worst = 0f64;
    let n = model.n_params();
    for (line, got) in lines.iter().zip(&run.results) {
        let mut obs = vec![0f32; N_OBS];
        let Ok(day) = magic_core::line::parse_record(line, true, &mut obs) else {
            assert!(got.starts_with("error,"), "{got}");
            continue;
        };
        let inv = magic_core::invert_at::<f64>(&model, &obs, day, &mut ws).unwrap();
        let u =
            magic_core::uncertainty::standard_deviations(&model, &obs, &inv, day, &mut sw).unwrap();
        let fields: Vec<&str> = got.split(',').collect();
        assert_eq!(fields.len(), n + 3 + n, "{got}");
        variables_agree(&model, line, &fields[..n + 3], &inv);
        for (k, f) in fields[n + 3..].iter().enumerate() {
            let board: f64 = f.parse().unwrap();
            let rel = (board - u.sd[k]).abs() / u.sd[k];
            worst = worst.max(rel);
            assert!(
                rel <= BOARD_SD_MAX_REL_ERROR,
                "sd {k} of {line:?}: board {board}, host {}",
                u.sd[k]
            );
        }
    }
    let cost = |k: &str| run.cost(k).unwrap_or_else(|| panic!("no `{k}` figure"));
    eprintln!(
        "standard deviations on the board: within {worst:.2e} of the host's; {} instructions each, flash {} bytes, stack {} of {} bytes",
        cost("instructions_standard_deviations"),
        cost("flash_bytes"),
        cost("stack_bytes"),
        cost("stack_available_bytes"),
    );
    assert!(cost("stack_bytes") < cost("stack_available_bytes"));
    // The standard deviations' code is panic-free too: the same build links with the
    // panic-never handler.
    build_firmware_with(&path, &["sd", "panic-never"])
        .expect("the `sd` firmware must link with the panic-never handler");
}

#[test]
fn corrupt_models_are_rejected_by_the_firmware() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model_bytes();
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x04;
    let truncated = bytes[..bytes.len() - 100].to_vec();
    let tmp = TempDir::new("firmware");
    for (name, b, want) in [
        ("flipped", flipped, "corrupt"),
        ("truncated", truncated, "truncated"),
    ] {
        let path = tmp.join(&format!("{name}.magic"));
        std::fs::write(&path, &b).unwrap();
        let elf = build_firmware(&path).expect("building the firmware");
        let run = run_firmware(&elf, "1,2,3\n", TIMEOUT_S).expect("running the firmware");
        assert!(!run.success, "{name} model: firmware exited with success");
        let first = run.results.first().cloned().unwrap_or_default();
        assert!(
            first.starts_with("error,model:") && first.contains(want),
            "{name} model: {first}"
        );
    }
}

#[test]
fn no_panic_is_reachable_in_the_firmware() {
    if !toolchain_ready() {
        return;
    }
    let bytes = model_bytes();
    let tmp = TempDir::new("firmware");
    let path = tmp.join("panic-never.magic");
    std::fs::write(&path, &bytes).unwrap();
    // Links only if the optimised firmware contains no call of the panic machinery.
    let elf = build_firmware_with(&path, &["panic-never"]).expect(
        "the firmware must link with the panic-never handler (a panic is reachable: the linker \
         names the undefined symbol magic_firmware_panic_is_reachable)",
    );
    // The proof is not vacuous: one reachable panic makes the same build fail to link.
    assert!(
        build_firmware_with(&path, &["panic-never", "panic-canary"]).is_err(),
        "a firmware with a reachable panic linked with the panic-never handler"
    );
    // And the panic-free firmware is the firmware: it inverts like the normal build.
    let lines = input_lines();
    let input: String = lines.iter().map(|(l, _)| format!("{l}\n")).collect();
    let run = run_firmware(&elf, &input, TIMEOUT_S).expect("running the firmware");
    assert!(
        run.success,
        "panic-never firmware failed: {:?}",
        run.results.last()
    );
    let normal = run_firmware(
        &build_firmware(&path).expect("building the firmware"),
        &input,
        TIMEOUT_S,
    )
    .expect("running the firmware");
    assert_eq!(run.results, normal.results);
}
