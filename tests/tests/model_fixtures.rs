//! Model files written by an earlier build still load and invert to the same numbers.
//!
//! The fixtures in `tests/fixtures/` (see its README) were made with the `magic` CLI: a synthetic
//! dataset (`magic synth --seed 7`), a Mogi C model trained for 2 epochs and exported to int8, and
//! a Mogi B model with a declared common mode kept in f32. `mogi_obs_mm.csv` holds 13 test rows in
//! mm (one with a station missing); `*.expected.csv` the inversions that build computed from them,
//! on the host (f64) and with the board's scalar (f32), every number printed so that it reads back
//! exactly; `*.invert.csv` is `magic invert --standardized` on the same rows (`mogi_obs_std.csv`).
//!
//! The decoding and the arithmetic of the inversion are meant to stay as they are, so the numbers
//! must come out bit for bit the same: any difference is a change of behaviour to look at.

use magic_core::effects::Effect;
use magic_core::line::write_result;
use magic_core::model_file::Problem;
use magic_core::{invert, Inversion, Model, Real, Variant, Workspace};
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

fn read(name: &str) -> Vec<u8> {
    let p = fixture(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn text(name: &str) -> String {
    String::from_utf8(read(name)).expect("fixture is UTF-8")
}

/// The observation rows in mm (an empty field is a missing channel: NaN).
fn observations() -> Vec<Vec<f32>> {
    text("mogi_obs_mm.csv")
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|c| {
                    if c.is_empty() {
                        f32::NAN
                    } else {
                        c.parse().unwrap()
                    }
                })
                .collect()
        })
        .collect()
}

/// One inversion as the generator printed it (`{:?}` of every number, lists joined by `;`).
fn line<R: Real + std::fmt::Debug>(tag: &str, row: usize, inv: &Inversion<R>) -> String {
    fn join<T: std::fmt::Debug>(v: &[T]) -> String {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(";")
    }
    format!(
        "{tag},{row},{},{},{:?},{:?},{},{},{}",
        join(&inv.params[..inv.n_params]),
        join(&inv.unit[..inv.n_params]),
        inv.residual_rms,
        inv.residual_rms_std,
        inv.flags.0,
        inv.used,
        join(&inv.recon[..inv.n_obs])
    )
}

fn check_inversions(file: &str, model: &Model<'_>) {
    let rows = observations();
    assert_eq!(rows.len(), 13);
    let expected = text(&format!("{file}.expected.csv"));
    let expected: Vec<&str> = expected.lines().skip(1).collect();
    let mut ws = Workspace::default();
    let mut got = Vec::new();
    for (i, obs) in rows.iter().enumerate() {
        got.push(line("f64", i, &invert::<f64>(model, obs, &mut ws).unwrap()));
    }
    for (i, obs) in rows.iter().enumerate() {
        got.push(line("f32", i, &invert::<f32>(model, obs, &mut ws).unwrap()));
    }
    assert_eq!(got.len(), expected.len());
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!(g, e, "{file}: inversion differs from the stored one");
    }
    // The CLI's result rows (date first, six decimals) from the same build.
    let cli = text(&format!("{file}.invert.csv"));
    for (i, (obs, cli_line)) in rows.iter().zip(cli.lines().skip(1)).enumerate() {
        let inv = invert::<f64>(model, obs, &mut ws).unwrap();
        let mut s = String::new();
        write_result(&mut s, &inv).unwrap();
        let (_date, rest) = cli_line.split_once(',').unwrap();
        assert_eq!(s, rest, "{file}: CLI row {i}");
    }
}

#[test]
fn int8_c_model_written_before_still_decodes_and_inverts_the_same() {
    let bytes = read("mogi_c_int8.magic");
    let m = Model::decode(&bytes).expect("the stored int8 model decodes");
    assert_eq!(m.variant, Variant::C);
    assert_eq!((m.n_obs(), m.n_params()), (36, 4));
    assert_eq!((m.encoder.len(), m.decoder.len()), (4, 2));
    assert!(m.encoder[..3].iter().all(|l| l.is_int8()));
    assert!(m.effects.is_empty());
    let Problem::Mogi { names, .. } = &m.problem else {
        panic!("not a Mogi model");
    };
    assert_eq!(names.len(), 12);
    check_inversions("mogi_c_int8", &m);
}

#[test]
fn f32_b_model_with_common_mode_written_before_still_decodes_and_inverts_the_same() {
    let bytes = read("mogi_b_common_mode_f32.magic");
    let m = Model::decode(&bytes).expect("the stored f32 model decodes");
    assert_eq!(m.variant, Variant::B);
    assert_eq!((m.n_obs(), m.n_params()), (36, 7));
    assert!(m.encoder.iter().all(|l| !l.is_int8()));
    assert_eq!(m.effects.len(), 1);
    assert!(matches!(m.effects[0], Effect::CommonMode));
    check_inversions("mogi_b_common_mode_f32", &m);
}

/// Re-encoding a decoded file gives the same body: the format is unchanged both ways but for
/// the version in the header (the files are format 5; version 6 changed what a variant-C model
/// with dated terms means, which neither holds) and the CRC that covers it.
#[test]
fn stored_models_re_encode_to_the_same_bytes() {
    for name in ["mogi_c_int8.magic", "mogi_b_common_mode_f32.magic"] {
        let bytes = read(name);
        let m = Model::decode(&bytes).unwrap();
        let mut buf = vec![0u8; bytes.len() + 64];
        let n = m.encode(&mut buf).unwrap();
        assert_eq!(n, bytes.len(), "{name}");
        assert_eq!(&bytes[4..6], &5u16.to_le_bytes(), "{name}");
        assert_eq!(&buf[4..6], &magic_core::model_file::VERSION.to_le_bytes());
        assert_eq!(&buf[..4], &bytes[..4], "{name}");
        assert_eq!(&buf[6..n - 4], &bytes[6..n - 4], "{name}");
    }
}
