//! The board's number and line text against core's: printing, parsing, dates and result rows.

use super::*;

#[test]
fn integers_print_as_fmt_prints_them() {
    let mut vals = std::vec![0u32, 1, 9, 10, 99, 100, 4095, 65_535, 999_999, 1_000_000];
    vals.extend([u32::MAX, u32::MAX - 1, 0x8000_0000, 0xDEAD_BEEF]);
    let mut x = 0x1234_5678u32;
    for _ in 0..2000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        vals.push(x >> (x % 32));
    }
    for v in vals {
        let (mut a, mut b) = (String::new(), String::new());
        write_u32(&mut a, v).unwrap();
        assert_eq!(a, std::format!("{v}"));
        write_hex32(&mut b, v).unwrap();
        assert_eq!(b, std::format!("{v:#010x}"));
        let mut h = String::new();
        write_hex8(&mut h, v).unwrap();
        assert_eq!(h, std::format!("{v:08x}"));
        if v < 1_000_000 {
            let mut c = String::new();
            write_digits(&mut c, v, 6).unwrap();
            assert_eq!(c, std::format!("{v:06}"));
        }
    }
}

#[test]
fn dates_as_core_parses_them() {
    let check = |t: &str| {
        let want = magic_core::time::parse_date(t);
        assert_eq!(parse_date_bytes(t.as_bytes()).map(i64::from), want, "{t:?}");
    };
    for y in (-999..=9999)
        .step_by(7)
        .chain([0, 1, 1900, 2000, 2004, 2100, 2400])
    {
        for m in 0..=13 {
            for d in 0..=32 {
                check(&format!("{y:04}-{m:02}-{d:02}"));
            }
        }
    }
    for y in 1890..=2110 {
        for (m, d) in [
            (2, 28),
            (2, 29),
            (2, 30),
            (12, 31),
            (1, 1),
            (4, 31),
            (6, 30),
        ] {
            check(&format!("{y:04}.{m:02}.{d:02}"));
        }
    }
    for t in [
        "2006-01-02",
        " 2006-01-02\t",
        "+999-01-01",
        "-999-01-01",
        "2006-+1-01",
        "2006-01-+1",
        "2006--1-01",
        "2006-1-012",
        "2006-01.02",
        "2006/01/02",
        "20060102",
        "2006-01-0x",
        "",
        "-",
        "2006-01-02,",
        "+-99-01-01",
        "-+99-01-01",
        "0000-02-29",
        "0100-02-29",
    ] {
        check(t);
    }
}
use std::string::String;

fn fixed(v: f32) -> String {
    let mut s = String::new();
    write_fixed6(&mut s, v).unwrap();
    s
}

#[test]
fn numbers_parse_like_core() {
    let cases = [
        "0",
        "-0",
        "+5",
        "5.",
        ".5",
        "+.5",
        "-.5",
        "1e3",
        "1E+3",
        "2.5e-3",
        "-12.345678",
        "3.4028235e38",
        "1e39",
        "1e-50",
        "123456789012345678901234",
        "0.000000000000000000001234",
        "16777217",
        "9007199254740993",
        "0.1",
        "0.2",
        "0.3",
        "1.0000001",
        "-9999.999",
        "10000",
        "10000.001",
        "00012.5000",
        "1_0",
        "0x10",
        "1e",
        "e5",
        ".",
        "",
        "+",
        "-",
        "1.2.3",
        "inf",
        "-Infinity",
        "NaN",
        "+nan",
        "infinit",
        "1e+",
        "--1",
        "1 2",
        "١",
    ];
    for s in cases {
        let want = s.parse::<f32>().ok();
        let got = parse_f32(s);
        match (want, got) {
            (Some(a), Some(b)) => assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{s}: {a} vs {b}"
            ),
            (None, None) => {}
            _ => panic!("{s}: core {want:?}, ours {got:?}"),
        }
    }
}

#[test]
fn far_exponents_parse_exactly() {
    for s in [
        "7.038531e-26",
        "0.00000000000000000000000007038531",
        "1.17549435e-38",
        "1e-45",
        "7e-46",
        "1.4e-45",
        "3.4e37",
        "2.2e-30",
        "3.4028235e38",
        "3.4028236e38",
        "1e38",
        "9999999999999999999e19",
    ] {
        let (want, got) = (s.parse::<f32>().unwrap(), parse_f32(s).unwrap());
        assert_eq!(want.to_bits(), got.to_bits(), "{s}: {want:e} vs {got:e}");
    }
}

#[test]
fn random_decimals_parse_exactly() {
    // Up to 19 significant digits, decimal exponents from −70 to +40: every result is core's
    // correctly rounded one (integer arithmetic, one rounding).
    let mut x = 0x0DDB_A11Cu64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for _ in 0..300_000 {
        let digits = 1 + next() % 19;
        let mut m = std::string::String::new();
        for _ in 0..digits {
            m.push((b'0' + (next() % 10) as u8) as char);
        }
        let e = (next() % 111) as i32 - 70;
        let text = std::format!("{m}e{e}");
        let want = text.parse::<f32>().unwrap();
        let got = parse_f32(&text).unwrap();
        assert_eq!(want.to_bits(), got.to_bits(), "{text}");
    }
}

#[test]
fn shortest_f32_text_round_trips() {
    // Every f32 printed the way the host writes observations parses back to itself.
    let mut x = 0x1234_5678u32;
    for _ in 0..200_000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let v = f32::from_bits(x);
        if !v.is_finite() {
            continue;
        }
        // Within the exact paths: 10^-12 ≤ |v| ≤ 10^12 with up to 9 significant digits.
        if !(1e-12..=1e12).contains(&v.abs()) {
            continue;
        }
        for text in [
            std::format!("{v}"),
            std::format!("{v:e}"),
            std::format!("{v:.3}"),
        ] {
            let want = text.parse::<f32>().unwrap();
            let got = parse_f32(&text).unwrap();
            assert_eq!(want.to_bits(), got.to_bits(), "{text}");
        }
    }
}

#[test]
fn mm_scale_decimals_parse_exactly() {
    // Observations in mm with up to 9 significant digits, as test files hold them.
    let mut x = 0x9E37_79B9u32;
    for _ in 0..200_000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let v = (x as i32 as f64) / 2f64.powi(31) * 9999.0;
        for d in 0..=6 {
            let text = std::format!("{v:.d$}");
            assert_eq!(
                text.parse::<f32>().unwrap().to_bits(),
                parse_f32(&text).unwrap().to_bits(),
                "{text}"
            );
        }
    }
}

#[test]
fn dated_records_parse_like_core() {
    let lines = [
        "2006-01-02,1,2",
        "2006.01.02,1,x",
        "2006-13-02,1,2",
        "1,2",
        "2006-01-02,1",
        "nodate",
        "2006-01-02,1,2,3",
    ];
    for l in lines {
        let (mut a, mut b) = ([0f32; 2], [0f32; 2]);
        let want = magic_core::line::parse_record(l, true, &mut a);
        let got = parse_record_bytes(l.as_bytes(), true, &mut b);
        match (want, got) {
            (Ok(x), Ok(y)) => assert!(x == y && a == b, "{l}"),
            (w, g) => assert_eq!(w.err(), g.err(), "{l}"),
        }
    }
}

#[test]
fn result_rows_match_core() {
    use magic_core::{Flags, Inversion};
    let mut inv = Inversion::<f32> {
        n_params: 4,
        params: [0.0; magic_core::model_file::MAX_PARAMS],
        unit: [0.5; magic_core::model_file::MAX_PARAMS],
        n_obs: 3,
        physics: [0.0; magic_core::model_file::MAX_OBS],
        recon: [0.0; magic_core::model_file::MAX_OBS],
        residual_rms: 1.234_567_9f32 as f64,
        residual_rms_std: 0.5,
        flags: Flags(5),
        used: 0xFFF,
    };
    inv.params[..4].copy_from_slice(&[-3.125_976_5, 0.0078125, 12.5, -0.000_000_3]);
    let (mut a, mut b) = (String::new(), String::new());
    magic_core::line::write_result(&mut a, &inv).unwrap();
    write_result(&mut b, &inv).unwrap();
    assert_eq!(a, b);
}

#[test]
fn lines_parse_like_core() {
    let lines = [
        "1,2,3",
        " 1.5, ,nan",
        "1,2",
        "1,2,3,4",
        "1,x,3",
        "1,inf,3",
        "1,2,1e5",
        "1,2,3\r\n",
        "",
        "1,,",
        ",,",
        "-0,+0,0",
        "1,2,-10000",
        "1,2,10000.5",
        "1,2,NaN",
        "1,2,+nan",
    ];
    for l in lines {
        let (mut a, mut b) = ([0f32; 3], [0f32; 3]);
        let want = magic_core::line::parse_obs(l, &mut a);
        let got = parse_obs(l, &mut b);
        assert_eq!(want, got, "{l:?}");
        if want.is_ok() {
            for (x, y) in a.iter().zip(&b) {
                assert!(
                    x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                    "{l:?}"
                );
            }
        }
    }
}

#[test]
fn fixed6_matches_core_formatting() {
    let specials = [
        0.0f32,
        -0.0,
        0.0078125,
        0.0234375,
        -0.0000001,
        2.5e-7,
        5e-7,
        4.9999997e-7,
        5.0000004e-7,
        1.5e-6,
        2.5e-6,
        4e9,
        4294967000.0,
        0.9999995,
        1.9999996,
        f32::MIN_POSITIVE,
        1e-45,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -3.25,
        1.0 / 3.0,
    ];
    for v in specials {
        assert_eq!(fixed(v), std::format!("{:.6}", v as f64), "{v:e}");
    }
    // Every value below 2^32 prints as Rust prints its exact (f64) value.
    let mut x = 0xDEAD_BEEFu32;
    for _ in 0..1_000_000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let v = f32::from_bits(x);
        if v.is_finite() && v.abs() < 4e9 {
            assert_eq!(fixed(v), std::format!("{:.6}", v as f64), "{v:e}");
            assert_eq!(fixed(v), std::format!("{v:.6}"), "{v:e}");
        }
    }
    // Values near ties at the sixth decimal (k/10⁶ ± half a unit, in f32).
    for k in 0..200_000u32 {
        let t = (k as f64 + 0.5) / 1e6;
        for v in [t as f32, f32::from_bits((t as f32).to_bits() + 1)] {
            assert_eq!(fixed(v), std::format!("{:.6}", v as f64), "{v:e}");
        }
    }
}
