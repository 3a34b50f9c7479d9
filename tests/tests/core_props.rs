//! Property tests of the core's promises: finite observations within ±10 m always invert to finite
//! variables inside the model's bounds; decoding never panics; int8 arithmetic stays within ±127;
//! the Mogi field is finite inside the paper's bounds.
//!
//! Tolerance: variables are checked against their bounds up to two roundings of
//! `min + (max − min) · u` (2 ε of the scalar, relative to the bound); no excursion at all was
//! measured on 30 000 random observations in f64 or f32.

use magic_core::model_file::{Model, MAGIC, VERSION};
use magic_core::mogi::{self, Station, PAPER_BOUNDS};
use magic_core::quant::{quantize, requantize};
use magic_core::{invert, Flags, Real, Variant, Workspace};
use magic_tests::{crc32, random_mogi_model};
use magic_train::gnss::synth;
use proptest::prelude::*;
use std::sync::OnceLock;

/// Decoded test models: int8 C, f32 C, f32 B (bytes leaked for the life of the test binary).
fn models() -> &'static [Model<'static>] {
    static M: OnceLock<Vec<Model<'static>>> = OnceLock::new();
    M.get_or_init(|| {
        let calib = synth::generate(synth::Scenario::Clean, 11)
            .problem
            .data
            .train
            .x[..200]
            .to_vec();
        let c = random_mogi_model(Variant::C, 11);
        let files = [
            c.quantize_int8(&calib).unwrap().encode().unwrap(),
            c.encode().unwrap(),
            random_mogi_model(Variant::B, 12).encode().unwrap(),
        ];
        files
            .into_iter()
            .map(|f| Model::decode(Box::leak(f.into_boxed_slice())).expect("valid model"))
            .collect()
    })
}

fn network() -> Vec<Station> {
    synth::AKUTAN
        .iter()
        .map(|s| Station {
            x_km: s.1,
            y_km: s.2,
            z_km: s.3,
        })
        .collect()
}

/// How far a variable may sit outside its bound, relative to the bound's magnitude, in f64 and f32.
const BOUND_SLACK_F64: f64 = 2.0 * f64::EPSILON;
const BOUND_SLACK_F32: f64 = 2.0 * f32::EPSILON as f64;
/// The relative error of an integer requantisation multiplier: m ∈ [2³⁰, 2³¹) is rounded to an
/// integer, at most 2⁻³¹ relative; twice that.
const MULTIPLIER_MAX_REL_ERROR: f64 = 1.0 / (1u64 << 30) as f64;

fn check_inversion<R: Real>(m: &Model<'_>, obs: &[f32], tol: f64) -> Result<(), TestCaseError> {
    let inv = invert::<R>(m, obs, &mut Workspace::default())
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    prop_assert!(
        inv.residual_rms.is_finite() && inv.residual_rms >= 0.0,
        "residual {}",
        inv.residual_rms
    );
    prop_assert!(inv.residual_rms_std.is_finite());
    prop_assert_eq!(inv.n_params, 4);
    for j in 0..inv.n_params {
        let p = inv.params[j].value();
        let [lo, hi] = m.bounds[j];
        let slack = tol * lo.abs().max(hi.abs()) as f64;
        prop_assert!(p.is_finite(), "param {} = {}", j, p);
        prop_assert!(
            p >= lo as f64 - slack && p <= hi as f64 + slack,
            "param {} = {} outside [{}, {}]",
            j,
            p,
            lo,
            hi
        );
    }
    for i in 0..inv.n_obs {
        prop_assert!(inv.recon[i].value().is_finite());
    }
    let missing = obs.iter().any(|x| x.is_nan());
    prop_assert_eq!(inv.flags.has(Flags::MISSING), missing);
    Ok(())
}

proptest! {
    #[test]
    fn finite_observations_invert_inside_the_bounds(
        obs in proptest::collection::vec(-1.0e4f32..=1.0e4, 36),
        which in 0usize..3,
    ) {
        let m = &models()[which];
        check_inversion::<f64>(m, &obs, BOUND_SLACK_F64)?;
        check_inversion::<f32>(m, &obs, BOUND_SLACK_F32)?;
    }

    #[test]
    fn missing_channels_invert_while_enough_remain(
        obs in proptest::collection::vec(-200.0f32..=200.0, 36),
        mask in proptest::collection::vec(any::<bool>(), 36),
        which in 0usize..3,
    ) {
        let m = &models()[which];
        let obs: Vec<f32> = obs.iter().zip(&mask).map(|(x, gone)| if *gone { f32::NAN } else { *x }).collect();
        let observed = obs.iter().filter(|x| !x.is_nan()).count();
        if observed >= 4 {
            check_inversion::<f64>(m, &obs, BOUND_SLACK_F64)?;
        } else {
            prop_assert!(invert::<f64>(m, &obs, &mut Workspace::default()).is_err());
        }
    }

    #[test]
    fn decoding_arbitrary_bytes_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = Model::decode(&bytes);
    }

    #[test]
    fn decoding_sealed_arbitrary_bodies_never_panics(body in proptest::collection::vec(any::<u8>(), 0..2048)) {
        // A valid header and CRC around arbitrary contents: the structural checks must answer.
        let mut b = MAGIC.to_vec();
        b.extend(VERSION.to_le_bytes());
        b.extend((body.len() as u32).to_le_bytes());
        b.extend(&body);
        let crc = crc32(&b);
        b.extend(crc.to_le_bytes());
        let decoded = Model::decode(&b);
        if let Ok(m) = &decoded {
            let _ = invert::<f32>(m, &vec![0.0; m.n_obs()], &mut Workspace::default());
        }
    }

    #[test]
    fn requantize_stays_within_127(acc in any::<i32>(), m in any::<i32>(), shift in -30i8..=30) {
        let q = requantize(acc, m, shift);
        prop_assert!((-127..=127).contains(&q));
        // The sign follows acc · m.
        let prod = acc as i64 * m as i64;
        prop_assert!(q == 0 || (q > 0) == (prod > 0), "acc {} m {} shift {} -> {}", acc, m, shift, q);
    }

    #[test]
    fn requantize_matches_the_real_product(acc in -100_000i32..100_000, mult in 1.0e-6f64..1.0e3) {
        let (m, s) = magic_core::quant::quantize_multiplier(mult).unwrap();
        let want = (acc as f64 * mult).clamp(-127.0, 127.0);
        let got = requantize(acc, m, s) as f64;
        // Rounding to an integer (0.5) plus the multiplier's relative error on |acc · mult| (analytic
        // bounds, not measured ones), plus the f64 product's own rounding.
        let bound = 0.5 + MULTIPLIER_MAX_REL_ERROR * (acc as f64 * mult).abs() + 1e-9;
        prop_assert!((got - want).abs() <= bound, "{} vs {}", got, want);
    }

    #[test]
    fn quantize_stays_within_127(x in any::<f32>(), inv_s in any::<f32>()) {
        let q = quantize(x, inv_s);
        prop_assert!((-127..=127).contains(&q));
    }

    #[test]
    fn quantize_with_special_values_stays_within_127(
        x in prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY), Just(f32::MAX), Just(f32::MIN), Just(1e-45f32), any::<f32>()],
        inv_s in prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(0.0f32), Just(-0.0f32), Just(f32::MAX), any::<f32>()],
    ) {
        let q = quantize(x, inv_s);
        prop_assert!((-127..=127).contains(&q));
    }

    #[test]
    fn mogi_field_is_finite_inside_the_paper_bounds(
        x in PAPER_BOUNDS[0][0]..=PAPER_BOUNDS[0][1],
        y in PAPER_BOUNDS[1][0]..=PAPER_BOUNDS[1][1],
        d in PAPER_BOUNDS[2][0]..=PAPER_BOUNDS[2][1],
        dv in PAPER_BOUNDS[3][0]..=PAPER_BOUNDS[3][1],
    ) {
        let st = network();
        let mut u = vec![0f64; 36];
        mogi::field(&st, &[x, y, d, dv], &mut u).unwrap();
        prop_assert!(u.iter().all(|v| v.is_finite()));
        // Up is positive under inflation, negative under deflation (the source is below every station).
        for v in &u[24..] {
            prop_assert!(dv == 0.0 || (*v > 0.0) == (dv > 0.0) || *v == 0.0);
        }
        let mut u32 = vec![0f32; 36];
        mogi::field(&st, &[x as f32, y as f32, d as f32, dv as f32], &mut u32).unwrap();
        prop_assert!(u32.iter().all(|v| v.is_finite()));
        let mut jac = vec![[0f64; 4]; 36];
        mogi::field_jacobian(&st, &[x, y, d, dv], &mut u, &mut jac).unwrap();
        prop_assert!(jac.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn mogi_rejects_a_source_at_or_above_the_surface(d in -100.0f64..=0.0) {
        let mut u = vec![0f64; 36];
        prop_assert!(mogi::field(&network(), &[0.0, 0.0, d, 1.0], &mut u).is_err());
    }
}

/// Deterministic filler bytes for generated layers.
fn filler(seed: u64, n: usize) -> Vec<u8> {
    let mut x = seed | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

/// Owned bytes of a layer that may be inconsistent (the validation `Model::decode` performs is
/// skipped on purpose: `nn::run` is public and must answer with an error, not a panic).
struct RawLayer {
    rows: u16,
    cols: u16,
    act: magic_core::nn::Activation,
    int8: bool,
    bufs: [Vec<u8>; 5],
    scales: (f32, f32),
}

impl RawLayer {
    fn new(rows: u16, cols: u16, act: u8, int8: bool, exact: bool, seed: u64) -> RawLayer {
        use magic_core::nn::Activation;
        let (r, c) = (rows as usize, cols as usize);
        let mut s = seed;
        let mut len = |want: usize| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            if exact {
                want
            } else {
                (s >> 33) as usize % (want + 8)
            }
        };
        let bufs = if int8 {
            [
                filler(seed, len(r * c)),
                filler(seed + 1, len(4 * r)),
                filler(seed + 2, len(4 * r)),
                filler(seed + 3, len(4 * r)),
                filler(seed + 4, len(r)),
            ]
        } else {
            [
                filler(seed, len(4 * r * c)),
                filler(seed + 1, len(4 * r)),
                vec![],
                vec![],
                vec![],
            ]
        };
        let act = [Activation::Linear, Activation::Relu, Activation::Sigmoid][act as usize % 3];
        let scales = (
            f32::from_bits(seed as u32),
            f32::from_bits((seed >> 32) as u32),
        );
        RawLayer {
            rows,
            cols,
            act,
            int8,
            bufs,
            scales,
        }
    }

    fn layer(&self) -> magic_core::nn::Layer<'_> {
        use magic_core::nn::{Layer, Weights};
        use magic_core::quant::{LeF32, LeI32};
        let b = &self.bufs;
        let weights = if self.int8 {
            Weights::Int8 {
                pad: &[],
                w: &b[0],
                bias: LeI32(&b[1]),
                w_scale: LeF32(&b[2]),
                mult: LeI32(&b[3]),
                shift: &b[4],
                in_scale: self.scales.0,
                out_scale: self.scales.1,
            }
        } else {
            Weights::F32 {
                w: LeF32(&b[0]),
                bias: LeF32(&b[1]),
            }
        };
        Layer {
            rows: self.rows,
            cols: self.cols,
            act: self.act,
            weights,
        }
    }
}

proptest! {
    #[test]
    fn requantize_never_panics_on_any_shift(acc in any::<i32>(), m in any::<i32>(), shift in any::<i8>()) {
        let q = requantize(acc, m, shift);
        prop_assert!((-127..=127).contains(&q));
    }

    #[test]
    fn dot_products_never_panic(n in 0usize..4096, w in any::<u8>(), x in any::<i8>()) {
        let wv = vec![w; n];
        let xv = vec![x; n];
        let a = magic_core::quant::dot_i8(&wv, &xv);
        let mut xp = vec![0u32; magic_core::quant::packed_words(n)];
        magic_core::quant::pack_i8_pairs(&xv, &mut xp);
        prop_assert_eq!(magic_core::quant::dot_i8_packed(&wv, &xp), a);
    }

    #[test]
    fn running_unvalidated_layers_never_panics(
        dims in proptest::collection::vec((0u16..300, 0u16..300, 0u8..3, any::<bool>(), any::<bool>(), any::<u64>()), 1..4),
        chain in any::<bool>(),
        n_in in 0usize..300,
        n_out in 0usize..300,
    ) {
        // Either arbitrary sizes, or layers that chain (cols = previous rows) with arbitrary bytes.
        let mut raw = Vec::new();
        let mut width = n_in as u16;
        for &(rows, cols, act, int8, exact, seed) in &dims {
            let cols = if chain { width } else { cols };
            raw.push(RawLayer::new(rows, cols, act, int8, exact, seed));
            width = rows;
        }
        let layers: Vec<_> = raw.iter().map(RawLayer::layer).collect();
        let input: Vec<f32> = (0..n_in).map(|i| i as f32 * 0.37 - 20.0).collect();
        let mut output = vec![0f32; if chain { width as usize } else { n_out }];
        let _ = magic_core::nn::run(&layers, &input, &mut output, &mut magic_core::nn::Scratch::default());
        let _ = magic_core::nn::validate_chain(&layers, n_in, n_out, magic_core::Net::Encoder);
    }
}

#[test]
fn dot_products_of_long_extreme_slices_never_panic() {
    // Longer than any layer (MAX_WIDTH) and extreme: the i32 sum wraps as the DSP kernel's does.
    let n = 300_000;
    let w = vec![0x81u8; n]; // -127
    let x = vec![-127i8; n];
    let a = magic_core::quant::dot_i8(&w, &x);
    let mut xp = vec![0u32; magic_core::quant::packed_words(n)];
    magic_core::quant::pack_i8_pairs(&x, &mut xp);
    assert_eq!(magic_core::quant::dot_i8_packed(&w, &xp), a);
}
