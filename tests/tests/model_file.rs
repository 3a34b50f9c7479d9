//! Model files: host encode → core decode round trip, and corrupt bytes (truncated, flipped bits,
//! wrong version, wrong problem, sizes that do not fit) answered with a clear error, never a panic.

use magic_core::model_file::{Problem, VERSION};
use magic_core::{invert, Error, Model, Variant, Workspace};
use magic_tests::{random_mogi_model, reseal};
use magic_train::gnss::synth;

fn int8_bytes() -> Vec<u8> {
    let m = random_mogi_model(Variant::C, 5);
    let calib = synth::generate(synth::Scenario::Clean, 5)
        .problem
        .data
        .train
        .x[..200]
        .to_vec();
    m.quantize_int8(&calib).unwrap().encode().unwrap()
}

#[test]
fn round_trip_f32_and_int8() {
    for bytes in [
        random_mogi_model(Variant::C, 1).encode().unwrap(),
        int8_bytes(),
    ] {
        let m = Model::decode(&bytes).unwrap();
        assert_eq!(m.variant, Variant::C);
        assert_eq!(m.n_obs(), 36);
        assert_eq!(m.n_params(), 4);
        let inv = invert::<f64>(&m, &[0.5f32; 36], &mut Workspace::default()).unwrap();
        for j in 0..4 {
            assert!(
                inv.params[j] >= m.bounds[j][0] as f64 && inv.params[j] <= m.bounds[j][1] as f64
            );
        }
    }
}

#[test]
fn every_truncation_is_an_error() {
    let b = int8_bytes();
    for n in 0..b.len() {
        let e = Model::decode(&b[..n]).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Truncated | Error::BadMagic | Error::CrcMismatch { .. }
            ),
            "len {n}: {e}"
        );
    }
}

#[test]
fn flipped_bits_are_caught() {
    let b = int8_bytes();
    let step = (b.len() / 997).max(1);
    for i in (0..b.len()).step_by(step) {
        for bit in [0, 3, 7] {
            let mut c = b.clone();
            c[i] ^= 1 << bit;
            assert!(
                Model::decode(&c).is_err(),
                "flip at byte {i} bit {bit} accepted"
            );
        }
    }
}

#[test]
fn wrong_version_problem_and_sizes() {
    let b = int8_bytes();
    let mut v = b.clone();
    v[4..6].copy_from_slice(&(VERSION + 1).to_le_bytes());
    reseal(&mut v, false);
    assert_eq!(
        Model::decode(&v).unwrap_err(),
        Error::UnsupportedVersion {
            found: VERSION + 1,
            supported: VERSION
        }
    );

    // A model for another problem kind.
    let mut own = random_mogi_model(Variant::B, 2);
    own.problem = Problem::Rtm {
        geometry: magic_core::rtm::Geometry::Reference,
        fixed: magic_core::rtm::Fixed::default(),
        bands: 0b1_1011_1111_1110,
        spectral: magic_core::quant::LeF32(&[]),
        weights: magic_core::quant::LeF32(&[]),
        lidf_beta: magic_core::quant::LeF32(&[]),
    };
    assert!(
        own.encode().is_err(),
        "a GNSS network's model relabelled as RTM must not validate"
    );

    // Sizes that do not fit the network: one station fewer than the observation count.
    let mut own = random_mogi_model(Variant::B, 2);
    if let Problem::Mogi { stations, names } = &mut own.problem {
        stations.0 = &stations.0[..stations.0.len() - magic_core::mogi::STATION_BYTES];
        names.0 = names.0.rsplit_once(',').unwrap().0;
    }
    let e = own.encode().unwrap_err().to_string();
    assert!(e.contains("observations"), "{e}");

    // Random garbage with a valid header and CRC.
    let mut g = b.clone();
    for (i, x) in g[10..].iter_mut().enumerate() {
        *x = (i * 7919 % 251) as u8;
    }
    reseal(&mut g, false);
    assert!(Model::decode(&g).is_err());
}

#[test]
fn invert_rejects_bad_observations_without_panicking() {
    let b = int8_bytes();
    let m = Model::decode(&b).unwrap();
    let mut ws = Workspace::default();
    assert!(matches!(
        invert::<f32>(&m, &[0.0; 35], &mut ws),
        Err(Error::SizeMismatch { .. })
    ));
    let mut o = [0.0f32; 36];
    o[3] = f32::INFINITY;
    assert!(matches!(
        invert::<f32>(&m, &o, &mut ws),
        Err(Error::NonFinite { index: 3, .. })
    ));
    o[3] = 2.0e4;
    assert!(matches!(
        invert::<f32>(&m, &o, &mut ws),
        Err(Error::OutOfRange { .. })
    ));
    let all_missing = [f32::NAN; 36];
    assert!(matches!(
        invert::<f32>(&m, &all_missing, &mut ws),
        Err(Error::TooFewObservations { .. })
    ));
    o[3] = f32::NAN;
    let inv = invert::<f32>(&m, &o, &mut ws).unwrap();
    assert!(inv.flags.has(magic_core::Flags::MISSING));
    assert_eq!(
        inv.used,
        (1 << 12) - 1,
        "station 3 still has its north and up channels"
    );
}

/// A random variant-C model with a drift of 1 to 36 mm/yr per channel from day 12 000.
fn c_with_drift() -> magic_train::model::OwnedModel {
    let mut m = random_mogi_model(Variant::C, 3);
    m.effects = vec![magic_train::model::OwnedEffect::Drift {
        t0_day: 12_000.0,
        rate: (1..=36).map(|r| r as f32).collect(),
    }];
    m
}

#[test]
fn the_correction_sees_f_without_its_dated_terms() {
    // The same observation on two days six years apart: E infers the same variables, F differs
    // by the drift, and C, which sees F without it, gives the same correction — so the
    // reconstructions differ by exactly the drift's change.
    let bytes = c_with_drift().encode().unwrap();
    let m = Model::decode(&bytes).unwrap();
    let mut ws = Workspace::default();
    let (t1, t2) = (12_100.0, 12_100.0 + 6.0 * 365.25);
    let a = magic_core::invert_at::<f64>(&m, &[0.5f32; 36], t1, &mut ws).unwrap();
    let b = magic_core::invert_at::<f64>(&m, &[0.5f32; 36], t2, &mut ws).unwrap();
    assert_eq!(a.params, b.params);
    for c in 0..36 {
        let drift = (c + 1) as f64 * 6.0;
        let (df, dr) = (b.physics[c] - a.physics[c], b.recon[c] - a.recon[c]);
        // (Up to the f64 rounding of adding a few tens of mm to each.)
        assert!((df - drift).abs() < 1e-9, "channel {c}: F moved {df}");
        assert!((dr - drift).abs() < 1e-9, "channel {c}: C(F) moved {dr}");
    }
}

#[test]
fn a_version_5_file_is_read_where_it_means_what_it_meant() {
    let as_v5 = |m: &magic_train::model::OwnedModel| {
        let mut b = m.encode().unwrap();
        b[4..6].copy_from_slice(&5u16.to_le_bytes());
        reseal(&mut b, false);
        b
    };
    // No dated term (or not variant C): the same model.
    assert!(Model::decode(&as_v5(&random_mogi_model(Variant::C, 3))).is_ok());
    let mut b_drift = c_with_drift();
    b_drift.variant = Variant::B;
    b_drift.decoder.clear();
    assert!(Model::decode(&as_v5(&b_drift)).is_ok());
    // C beside a drift: written when C saw the drift too, so refused.
    assert_eq!(
        Model::decode(&as_v5(&c_with_drift())).unwrap_err(),
        Error::UnsupportedVersion {
            found: 5,
            supported: VERSION
        }
    );
    assert!(Model::decode(&c_with_drift().encode().unwrap()).is_ok());
    // The CLI says what to do with it.
    let path = std::path::Path::new("old.magic");
    let msg = format!(
        "{:#}",
        magic_train::cli::args::decode(path, &as_v5(&c_with_drift())).unwrap_err()
    );
    assert!(
        msg.starts_with("old.magic: not a usable model file ("),
        "{msg}"
    );
    assert!(msg.contains("train it again with this build"), "{msg}");
    assert!(msg.ends_with("(this build reads 6)"), "{msg}");
}
