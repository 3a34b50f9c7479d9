//! Shared by the deployable firmware's QEMU tests (`firmware_uart.rs`, `firmware_station.rs`):
//! the toolchain check, an int8 model and synthetic days on the Akutan network, the comparison
//! of a board's answer with the host's, and a station connected to a QEMU board.
#![allow(dead_code)]

use magic_core::{Flags, Model, Variant};
pub use magic_tests::toolchain_ready;
use magic_train::data::records::{self, ObsRow};
use magic_train::firmware::qemu_uart::UartQemu;
use magic_train::firmware::station::{Link, Station};
use magic_train::gnss::synth;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Board (f32) against host (f64): largest difference of a variable as a fraction of its
/// range. Measured on these models: below 1e-5 (printed by the stream test); 1e-4 is the
/// margin the semihosting test (firmware_qemu.rs) holds the board to as well.
pub const HOST_TOLERANCE: f64 = 1e-4;
/// Days in the stream (and in [`days`]' file).
pub const DAYS: usize = 10_000;

/// An int8 variant-C model on the Akutan network (random weights, standardisation and
/// calibration from the synthetic dataset of `seed`), as model-file bytes.
pub fn model(seed: u64) -> Vec<u8> {
    let owned = magic_tests::random_mogi_model(Variant::C, seed);
    let s = synth::generate(synth::Scenario::Clean, seed);
    let calib: Vec<Vec<f32>> = s
        .problem
        .data
        .train
        .x
        .iter()
        .filter(|r| r.iter().all(|v| v.is_finite()))
        .take(256)
        .cloned()
        .collect();
    owned.quantize_int8(&calib).unwrap().encode().unwrap()
}

/// `DAYS` observation rows in mm (the synthetic dataset's days, cycled, at 0.1 mm: finer than GNSS
/// daily noise of about 1 mm, and short lines for the slow emulated UART), written as a
/// CSV `name` in `dir` with the network's columns and read back as `magic invert` reads it.
pub fn days(model: &Model<'_>, dir: &Path, name: &str) -> (PathBuf, Vec<ObsRow>) {
    let s = synth::generate(synth::Scenario::Clean, 1);
    let d = &s.problem.data;
    let all: Vec<&Vec<f32>> = d
        .train
        .x
        .iter()
        .chain(&d.valid.x)
        .chain(&d.test.x)
        .collect();
    let mut text = d.columns.join(",");
    text.push('\n');
    for i in 0..DAYS {
        let row = all[i % all.len()];
        let cells: Vec<String> = row
            .iter()
            .enumerate()
            .map(|(c, &z)| {
                if z.is_nan() {
                    String::new()
                } else {
                    format!("{:.1}", z as f64 * d.scale[c] + d.mean[c])
                }
            })
            .collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let rows = records::read_obs(&path, model, false).unwrap();
    assert_eq!(rows.len(), DAYS);
    (path, rows)
}

/// Checks a board result against the host's: same error text, or every variable within
/// [`HOST_TOLERANCE`] of its range with the same flags (but the residual threshold's) and
/// stations. Returns the largest difference.
pub fn agrees(model: &Model<'_>, board: &str, host: &str, what: &str) -> f64 {
    if host.starts_with("error,") || board.starts_with("error,") {
        assert_eq!(board, host, "{what}");
        return 0.0;
    }
    let b: Vec<&str> = board.split(',').collect();
    let h: Vec<&str> = host.split(',').collect();
    let n = model.n_params();
    assert_eq!(b.len(), h.len(), "{what}: {board} vs {host}");
    let mut worst = 0f64;
    for j in 0..n {
        let (x, y): (f64, f64) = (b[j].parse().unwrap(), h[j].parse().unwrap());
        let [lo, hi] = model.bounds[j];
        let rel = (x - y).abs() / (hi - lo) as f64;
        assert!(
            rel <= HOST_TOLERANCE,
            "{what}: variable {j}: board {x}, host {y}"
        );
        worst = worst.max(rel);
    }
    let flags = |v: &str| v.parse::<u8>().unwrap() & !Flags::HIGH_RESIDUAL;
    assert_eq!(flags(b[n + 1]), flags(h[n + 1]), "{what}: flags");
    assert_eq!(b[n + 2], h[n + 2], "{what}: stations used");
    worst
}

pub fn connect(qemu: &mut UartQemu) -> Station {
    let stream = qemu
        .connect(Duration::from_secs(20))
        .expect("connecting to QEMU");
    Station::connect(Link::tcp(stream, &qemu.address()).unwrap()).expect("board status")
}
