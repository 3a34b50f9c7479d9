//! The line format of [`magic_core::line`] without core's float parsing and formatting.
//!
//! `magic_core::line::parse_obs` uses `str::parse::<f32>` and `write_result` uses `{:.6}` on
//! `f64`: on the board those two pull in about 26 KB of flash (the decimal-to-float tables and
//! the float-to-decimal algorithms), more than half of the 48 KiB budget once the model is in. This
//! module reads and writes the same text with integer arithmetic and a few exact multiplications:
//!
//! * [`parse_obs_bytes`] has the contract of `magic_core::line::parse_obs` (same fields, same
//!   [`LineError`]s, the same accepted number syntax: sign, digits, point, exponent, `inf`,
//!   `infinity`, `nan` in any case) on raw bytes: no UTF-8 check and ASCII-only trimming, which
//!   saves another 0.6 KB (a field padded with non-ASCII white space is not a number here). Numbers with at most 19 significant digits and a decimal
//!   exponent within ±22 (every observation file written by the host) are converted with one
//!   exact operation and one rounding (f32 when the digits fit in 24 bits and the exponent in
//!   ±10, otherwise f64 then f32), so they give core's correctly rounded value except, in
//!   principle, when the f64 result falls exactly on an f32 rounding midpoint. Longer or more
//!   extreme numbers are converted approximately (last-bit differences).
//! * [`write_result`] prints what `magic_core::line::write_result` prints: variables and residual
//!   with six decimals, rounded half to even, `NaN`, `inf`, `-inf` and `-0.000000` as Rust
//!   prints them. For values that come from `f32` (the variables on the board) the scaling of the
//!   fraction by 10⁶ is exact, so the text is identical; for the f64 residual the last digit can differ in
//!   rare cases. Magnitudes of 2³² and more (never produced by a valid model) are written in
//!   exponent form.

use core::fmt::{self, Write};
use magic_core::line::LineError;
use magic_core::{Inversion, Real};

/// Largest accepted observation magnitude (as [`magic_core::invert::MAX_ABS_OBS`], in f32).
const MAX_ABS: f32 = magic_core::invert::MAX_ABS_OBS as f32;

/// Parses one line of comma-separated numbers into `out` (all of it), NaN for missing fields;
/// the contract of `magic_core::line::parse_obs` for text.
#[cfg(test)]
pub fn parse_obs(line: &str, out: &mut [f32]) -> Result<(), LineError> {
    parse_obs_bytes(line.as_bytes(), out)
}

/// [`parse_obs`] on raw bytes (the board does not check UTF-8: a non-ASCII byte is simply not
/// part of a number). Whitespace around fields is ASCII whitespace; core's `str::trim` also
/// removes other Unicode white space (e.g. U+00A0), which here makes the field not a number.
pub fn parse_obs_bytes(line: &[u8], out: &mut [f32]) -> Result<(), LineError> {
    let mut line = line;
    while let [rest @ .., b'\r' | b'\n'] = line {
        line = rest;
    }
    let mut n = 0usize;
    for (i, field) in line.split(|&b| b == b',').enumerate() {
        if i >= out.len() {
            return Err(LineError::FieldCount {
                expected: out.len(),
                found: i + 1,
            });
        }
        let t = field.trim_ascii();
        out[i] = if t.is_empty() || t.eq_ignore_ascii_case(b"nan") {
            f32::NAN
        } else {
            let v = parse_f32_bytes(t).ok_or(LineError::NotANumber { field: i + 1 })?;
            if !v.is_finite() || v.abs() > MAX_ABS {
                return Err(LineError::OutOfRange { field: i + 1 });
            }
            v
        };
        n = i + 1;
    }
    if n != out.len() {
        return Err(LineError::FieldCount {
            expected: out.len(),
            found: n,
        });
    }
    Ok(())
}

/// Parses a record: with `with_date` the first field is the observation's date (`YYYY-MM-DD` or
/// `YYYY.MM.DD`) and the observations follow; returns the day number (NaN without a date). The
/// contract of `magic_core::line::parse_record`.
pub fn parse_record_bytes(line: &[u8], with_date: bool, out: &mut [f32]) -> Result<f64, LineError> {
    if !with_date {
        return parse_obs_bytes(line, out).map(|()| f64::NAN);
    }
    let comma = line.iter().position(|&b| b == b',');
    let Some(comma) = comma else {
        return Err(LineError::FieldCount {
            expected: out.len() + 1,
            found: 1,
        });
    };
    let day = core::str::from_utf8(&line[..comma])
        .ok()
        .and_then(magic_core::time::parse_date)
        .ok_or(LineError::BadDate)?;
    parse_obs_bytes(&line[comma + 1..], out).map_err(|e| match e {
        LineError::FieldCount { expected, found } => LineError::FieldCount {
            expected: expected + 1,
            found: found + 1,
        },
        LineError::NotANumber { field } => LineError::NotANumber { field: field + 1 },
        LineError::OutOfRange { field } => LineError::OutOfRange { field: field + 1 },
        other => other,
    })?;
    Ok(day as f64)
}

const POW10_F32: [f32; 11] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10];
const POW10_F64: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Parses a number in the syntax `str::parse::<f32>` accepts; `None` when it is not one.
#[cfg(test)]
pub fn parse_f32(s: &str) -> Option<f32> {
    parse_f32_bytes(s.as_bytes())
}

/// [`parse_f32`] on bytes.
pub fn parse_f32_bytes(b: &[u8]) -> Option<f32> {
    let (neg, body) = match b.first() {
        Some(b'-') => (true, &b[1..]),
        Some(b'+') => (false, &b[1..]),
        _ => (false, b),
    };
    let special = |word: &[u8]| body.eq_ignore_ascii_case(word);
    if special(b"inf") || special(b"infinity") {
        return Some(if neg {
            f32::NEG_INFINITY
        } else {
            f32::INFINITY
        });
    }
    if special(b"nan") {
        return Some(f32::NAN);
    }
    let mut mant = 0u64;
    let mut digits = 0u32; // significant digits kept in `mant`
    let mut exp10 = 0i32;
    let mut any = false;
    let mut i = 0usize;
    let mut point = false;
    while i < body.len() {
        let c = body[i];
        match c {
            b'0'..=b'9' => {
                any = true;
                if mant == 0 && c == b'0' {
                    // Leading zero: not significant.
                    if point {
                        exp10 -= 1;
                    }
                } else if digits < 19 {
                    mant = mant * 10 + (c - b'0') as u64;
                    digits += 1;
                    if point {
                        exp10 -= 1;
                    }
                } else if !point {
                    // Dropped digit before the point: scales the value.
                    exp10 += 1;
                }
            }
            b'.' if !point => point = true,
            b'e' | b'E' => break,
            _ => return None,
        }
        i += 1;
    }
    if !any {
        return None;
    }
    if i < body.len() {
        // Exponent: [eE][+-]?digits+
        let mut j = i + 1;
        let eneg = match body.get(j) {
            Some(b'-') => {
                j += 1;
                true
            }
            Some(b'+') => {
                j += 1;
                false
            }
            _ => false,
        };
        if j == body.len() {
            return None;
        }
        let mut e = 0i32;
        for &c in body.get(j..).unwrap_or(&[]) {
            if !c.is_ascii_digit() {
                return None;
            }
            e = (e * 10 + (c - b'0') as i32).min(100_000);
        }
        exp10 = exp10.saturating_add(if eneg { -e } else { e });
    }
    let v = if mant == 0 {
        0.0
    } else if mant <= 1 << 24 && (-10..=10).contains(&exp10) {
        // Both operands exact in f32: one correctly rounded operation.
        let m = mant as u32 as f32;
        let p = POW10_F32
            .get(exp10.unsigned_abs() as usize)
            .copied()
            .unwrap_or(1.0);
        if exp10 < 0 {
            m / p
        } else {
            m * p
        }
    } else if mant <= 1 << 53 && (-22..=22).contains(&exp10) {
        let m = mant as f64;
        let p = POW10_F64
            .get(exp10.unsigned_abs() as usize)
            .copied()
            .unwrap_or(1.0);
        (if exp10 < 0 { m / p } else { m * p }) as f32
    } else {
        scale_pow10(mant as f64, exp10) as f32
    };
    Some(if neg { -v } else { v })
}

/// `m · 10^e` by steps of 10²², for the rare numbers outside the exact paths.
fn scale_pow10(mut m: f64, mut e: i32) -> f64 {
    while e > 22 && m.is_finite() {
        m *= 1e22;
        e -= 22;
    }
    while e < -22 && m != 0.0 {
        m /= 1e22;
        e += 22;
    }
    let p = POW10_F64[e.unsigned_abs().min(22) as usize];
    if e < 0 {
        m / p
    } else {
        m * p
    }
}

/// Writes the result row of an inversion (no newline), as `magic_core::line::write_result`.
pub fn write_result<R: Real, W: Write>(w: &mut W, inv: &Inversion<R>) -> fmt::Result {
    for p in inv.params.iter().take(inv.n_params) {
        write_fixed6(w, p.value())?;
        w.write_char(',')?;
    }
    write_fixed6(w, inv.residual_rms)?;
    write!(w, ",{},{}", inv.flags.0, inv.used)
}

/// Writes `v` as `format!("{v:.6}")` does (see the module documentation for the limits).
pub fn write_fixed6<W: Write>(w: &mut W, v: f64) -> fmt::Result {
    if v.is_nan() {
        return w.write_str("NaN");
    }
    let sign = if v.is_sign_negative() { "-" } else { "" };
    let a = v.abs();
    if a.is_infinite() {
        return write!(w, "{sign}inf");
    }
    if a < 4_294_967_296.0 {
        // Integer and fractional parts are exact in f64; scaling the fraction by 10^6 is exact
        // when `v` came from an f32 (at most 24 + 20 significant bits).
        let ip = a as u32;
        let s = (a - ip as f64) * 1e6;
        let mut q = s as u32;
        let rest = s - q as f64;
        // Round half to even on the last printed digit (the parity of q).
        if rest > 0.5 || (rest == 0.5 && q & 1 == 1) {
            q += 1;
        }
        let (ip, q) = if q == 1_000_000 {
            (ip as u64 + 1, 0)
        } else {
            (ip as u64, q)
        };
        if ip <= u32::MAX as u64 {
            return write!(w, "{sign}{}.{q:06}", ip as u32);
        }
    }
    // Exponent form d.dddddde<k> (not Rust's output; unreachable for valid models).
    let mut k = 0u32;
    let mut m = a;
    while m >= 10.0 {
        m /= 10.0;
        k += 1;
    }
    let q = (m * 1e6 + 0.5) as u32;
    write!(w, "{sign}{}.{:06}e{k}", q / 1_000_000, q % 1_000_000)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::String;

    fn fixed(v: f64) -> String {
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
    fn far_exponents_are_within_one_ulp() {
        // Outside the exact paths (exponent beyond ±22 from the digits) the value may be one ulp
        // off core's correctly rounded one.
        for s in [
            "7.038531e-26",
            "0.00000000000000000000000007038531",
            "1.17549435e-38",
            "3.4e37",
            "2.2e-30",
        ] {
            let (want, got) = (s.parse::<f32>().unwrap(), parse_f32(s).unwrap());
            assert!(
                want.to_bits().abs_diff(got.to_bits()) <= 1,
                "{s}: {want:e} vs {got:e}"
            );
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
            residual_rms: 1.234_567_890_123,
            residual_rms_std: 0.5,
            flags: Flags(5),
            used: 0xFFF,
        };
        inv.params[..4].copy_from_slice(&[-3.141_592_7, 0.0078125, 12.5, -0.000_000_3]);
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
            0.0,
            -0.0,
            0.0078125,
            0.0234375,
            -0.0000001,
            2.5e-7,
            5e-7,
            4e9,
            4294967295.25,
            0.9999995,
            1.9999996,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -3.25,
            1.0 / 3.0,
        ];
        for v in specials {
            assert_eq!(fixed(v), std::format!("{v:.6}"), "{v:e}");
        }
        // f64 values in general: scaling the fraction by 10^6 rounds, so a value within an ulp of
        // a decimal tie can come out one unit off in the sixth decimal.
        let last_digit = |t: &str| -> i64 { t.replace('.', "").parse().unwrap() };
        let mut y = 0x0BAD_F00Du64;
        for _ in 0..300_000 {
            y ^= y << 13;
            y ^= y >> 7;
            y ^= y << 17;
            let v = (y >> 11) as f64 / (1u64 << 53) as f64 * 2e4 - 1e4;
            let (a, b) = (fixed(v), std::format!("{v:.6}"));
            assert!((last_digit(&a) - last_digit(&b)).abs() <= 1, "{a} vs {b}");
        }
        // All values of f32 origin (the variables on the board) print identically.
        let mut x = 0xDEAD_BEEFu32;
        for _ in 0..300_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let v = f32::from_bits(x);
            if v.is_finite() && v.abs() < 4e9 {
                let v = v as f64;
                assert_eq!(fixed(v), std::format!("{v:.6}"), "{v:e}");
            }
        }
    }
}
