//! The layer runner against a plain reference: unvalidated layers are errors, and the packed int8
//! path is bit-identical to the reference.

extern crate std;
use super::*;

#[test]
fn run_answers_unvalidated_layers_with_errors() {
    // Regression (fuzzing): `run` indexed weight and shift bytes without checking their
    // lengths, so a layer that skipped `validate` panicked instead of returning an error.
    let (w, b) = ([0u8; 4 * 3], [0u8; 4 * 2]);
    let short_f32 = Layer {
        rows: 2,
        cols: 2,
        act: Activation::Linear,
        weights: Weights::F32 {
            w: LeF32(&w),
            bias: LeF32(&b),
        },
    };
    let mut out = [0f32; 2];
    let e = run(&[short_f32], &[1.0, 2.0], &mut out, &mut Scratch::default());
    assert_eq!(
        e,
        Err(Error::SizeMismatch {
            what: "f32 layer weight bytes",
            expected: 16,
            found: 12
        })
    );

    let int8 = |w: &'static [u8], shift: &'static [u8]| Layer {
        rows: 2,
        cols: 2,
        act: Activation::Relu,
        weights: Weights::Int8 {
            pad: &[],
            w,
            bias: LeI32(&[0; 8]),
            w_scale: LeF32(&[0, 0, 128, 63, 0, 0, 128, 63]),
            mult: LeI32(&[0, 0, 0, 64, 0, 0, 0, 64]),
            shift,
            in_scale: 1.0,
            out_scale: 1.0,
        },
    };
    let e = run(
        &[int8(&[1u8; 3], &[0u8; 2])],
        &[1.0, 2.0],
        &mut out,
        &mut Scratch::default(),
    );
    assert!(
        matches!(
            e,
            Err(Error::SizeMismatch {
                what: "int8 layer weight bytes",
                ..
            })
        ),
        "{e:?}"
    );
    let e = run(
        &[int8(&[1u8; 4], &[0u8; 1]), int8(&[1u8; 4], &[0u8; 2])],
        &[1.0, 2.0],
        &mut out,
        &mut Scratch::default(),
    );
    assert!(
        matches!(
            e,
            Err(Error::SizeMismatch {
                what: "int8 layer shift bytes",
                ..
            })
        ),
        "{e:?}"
    );
    // The same layers with whole byte arrays run.
    assert!(run(
        &[int8(&[1u8; 4], &[0u8; 2]), int8(&[1u8; 4], &[0u8; 2])],
        &[1.0, 2.0],
        &mut out,
        &mut Scratch::default()
    )
    .is_ok());
}

/// The int8 path as the reference defines it: int8 activations in a plain buffer, the plain
/// dot product [`crate::quant::dot_i8`], [`crate::quant::requantize_reference`].
fn run_reference(layers: &[Layer<'_>], input: &[f32]) -> std::vec::Vec<f32> {
    use crate::quant::{dot_i8, requantize_reference};
    let mut f: std::vec::Vec<f32> = input.to_vec();
    let mut q: std::vec::Vec<i8> = std::vec::Vec::new();
    let mut in_int8 = false;
    for (i, l) in layers.iter().enumerate() {
        let (rows, cols) = (l.rows as usize, l.cols as usize);
        let next = layers.get(i + 1);
        match l.weights {
            Weights::F32 { w, bias } => {
                let y: std::vec::Vec<f32> = (0..rows)
                    .map(|r| {
                        let mut acc = bias.get(r);
                        for (c, x) in f.iter().enumerate().take(cols) {
                            acc += LeF32(&w.0[4 * (r * cols + c)..]).get(0) * x;
                        }
                        activate(acc, l.act)
                    })
                    .collect();
                f = y;
                if let Some(Layer {
                    weights: Weights::Int8 { in_scale, .. },
                    ..
                }) = next
                {
                    q = f.iter().map(|&v| quantize(v, 1.0 / in_scale)).collect();
                    in_int8 = true;
                }
            }
            Weights::Int8 {
                w,
                bias,
                w_scale,
                mult,
                shift,
                in_scale,
                ..
            } => {
                if !in_int8 {
                    q = f.iter().map(|&v| quantize(v, 1.0 / in_scale)).collect();
                }
                let next_int8 = next.is_some_and(|n| n.is_int8());
                let accs: std::vec::Vec<i32> = (0..rows)
                    .map(|r| {
                        let mut row = std::vec![0u8; cols];
                        crate::quant::blocked_row(w, rows, cols, r, &mut row);
                        dot_i8(&row, &q).saturating_add(bias.get(r))
                    })
                    .collect();
                if next_int8 {
                    q = accs
                        .iter()
                        .enumerate()
                        .map(|(r, &a)| {
                            let v = requantize_reference(a, mult.get(r), shift[r] as i8);
                            if l.act == Activation::Relu {
                                v.max(0)
                            } else {
                                v
                            }
                        })
                        .collect();
                } else {
                    f = accs
                        .iter()
                        .enumerate()
                        .map(|(r, &a)| activate(a as f32 * (w_scale.get(r) * in_scale), l.act))
                        .collect();
                }
                in_int8 = next_int8;
            }
        }
    }
    f
}

/// A deterministic int8 chain `sizes[0] → … → sizes[n]` (ReLU between, linear at the end)
/// with byte arrays owned by the returned vector.
fn int8_chain(sizes: &[usize], seed: u64) -> std::vec::Vec<[std::vec::Vec<u8>; 5]> {
    let mut x = seed | 1;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    sizes
        .windows(2)
        .map(|p| {
            let (cols, rows) = (p[0], p[1]);
            let w: std::vec::Vec<u8> = (0..rows * cols)
                .map(|_| ((next() % 255) as i32 - 127) as i8 as u8)
                .collect();
            let bias = (0..rows)
                .flat_map(|_| ((next() % 20001) as i32 - 10000).to_le_bytes())
                .collect();
            let w_scale = (0..rows)
                .flat_map(|_| (0.001 + (next() % 1000) as f32 * 1e-5).to_le_bytes())
                .collect();
            let mut mult = std::vec::Vec::new();
            let mut shift = std::vec::Vec::new();
            for _ in 0..rows {
                let m = 1e-4 * (1 + next() % 20000) as f64;
                let (mq, sh) = crate::quant::quantize_multiplier(m).unwrap();
                mult.extend_from_slice(&mq.to_le_bytes());
                shift.push(sh as u8);
            }
            let mut blocked = std::vec![0u8; rows * cols];
            crate::quant::block_rows(&w, rows, cols, &mut blocked).unwrap();
            [blocked, bias, w_scale, mult, shift]
        })
        .collect()
}

#[test]
fn packed_int8_path_is_bit_identical_to_the_reference() {
    // Widths that exercise the 16-column blocks, single groups, columns beyond the last
    // group, and row counts that are not multiples of four.
    for (k, sizes) in [
        &[36usize, 64, 32, 16, 4][..],
        &[36, 144, 36],
        &[39, 21, 7, 5],
        &[3, 2, 1],
        &[17, 33, 250],
    ]
    .iter()
    .enumerate()
    {
        let bytes = int8_chain(sizes, 0x9E37_79B9 + k as u64);
        let n = bytes.len();
        let layers: std::vec::Vec<Layer<'_>> = bytes
            .iter()
            .zip(sizes.windows(2))
            .enumerate()
            .map(|(i, (b, p))| Layer {
                rows: p[1] as u16,
                cols: p[0] as u16,
                // (Odd chains keep their hidden layers linear: requantised to ±127, no ReLU.)
                act: if i + 1 == n || k % 2 == 1 {
                    Activation::Linear
                } else {
                    Activation::Relu
                },
                weights: Weights::Int8 {
                    pad: &[],
                    w: &b[0],
                    bias: LeI32(&b[1]),
                    w_scale: LeF32(&b[2]),
                    mult: LeI32(&b[3]),
                    shift: &b[4],
                    in_scale: 0.05,
                    out_scale: 0.05,
                },
            })
            .collect();
        let mut s = Scratch::default();
        for t in 0..20 {
            let input: std::vec::Vec<f32> = (0..sizes[0])
                .map(|i| ((i * 7 + t * 13) % 23) as f32 * 0.4 - 4.0)
                .collect();
            let mut out = std::vec![0f32; sizes[n]];
            run(&layers, &input, &mut out, &mut s).unwrap();
            let want = run_reference(&layers, &input);
            assert_eq!(
                out.iter()
                    .map(|v| v.to_bits())
                    .collect::<std::vec::Vec<_>>(),
                want.iter()
                    .map(|v| v.to_bits())
                    .collect::<std::vec::Vec<_>>(),
                "sizes {sizes:?}, input {t}"
            );
        }
    }
}

#[test]
fn requantize_packed_is_requantize_then_pack_i8_pairs() {
    // `requantize_packed` writes the packed layout itself (on the accumulators, sparing an int8
    // buffer): it must equal requantising each value and packing with `pack_i8_pairs`, for
    // every length (whole groups of four and each tail) and both floors.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for n in 0..=13usize {
        for relu in [false, true] {
            for _ in 0..50 {
                let acc: std::vec::Vec<i32> = (0..n).map(|_| next() as i32 >> 8).collect();
                let bias: std::vec::Vec<u8> = (0..n)
                    .flat_map(|_| ((next() as i32) >> 12).to_le_bytes())
                    .collect();
                let mult: std::vec::Vec<u8> = (0..n)
                    .flat_map(|_| (0x4000_0000 + (next() % 0x3FFF_FFFF) as i32).to_le_bytes())
                    .collect();
                let shift: std::vec::Vec<u8> = (0..n).map(|_| (next() % 40) as u8).collect();
                let floor = if relu { 0 } else { -127 };
                let q: std::vec::Vec<i8> = (0..n)
                    .map(|i| {
                        let b = i32::from_le_bytes(bias[4 * i..4 * i + 4].try_into().unwrap());
                        let m = i32::from_le_bytes(mult[4 * i..4 * i + 4].try_into().unwrap());
                        requantize_floor(acc[i].saturating_add(b), m, shift[i] as i8, floor)
                    })
                    .collect();
                let words = 2 * n.div_ceil(4);
                let mut want = std::vec![0u32; words];
                crate::quant::layout::pack_i8_pairs(&q, &mut want);
                let (mut got, mut a) = (std::vec![0u32; words], acc.clone());
                requantize_packed(&mut a, &bias, &mult, &shift, relu, &mut got);
                assert_eq!(got, want, "n {n}, relu {relu}, acc {acc:?}");
            }
        }
    }
}
