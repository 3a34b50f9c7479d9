//! The line format of [`magic_core::line`] without core's float parsing and formatting.
//!
//! `magic_core::line::parse_obs` uses `str::parse::<f32>` and `write_result` uses `{:.6}` on
//! `f64`: on the board those two pull in about 26 KB of flash (the decimal-to-float tables and
//! the float-to-decimal algorithms), more than half of the 49 KiB budget once the model is in. This
//! module reads and writes the same text in integer arithmetic (no soft-float f64 either):
//!
//! * [`parse_obs_bytes`] has the contract of `magic_core::line::parse_obs` (same fields, same
//!   [`LineError`]s, the same accepted number syntax: sign, digits, point, exponent, `inf`,
//!   `infinity`, `nan` in any case) on raw bytes: no UTF-8 check and ASCII-only trimming, which
//!   saves another 0.6 KB (a field padded with non-ASCII white space is not a number here).
//!   Numbers are correctly rounded, as core rounds them: up to 7 significant digits with a
//!   decimal exponent within ±10 by one exact f32 operation, all others (up to 19 significant
//!   digits are kept; later ones only scale) by multiplying or long-dividing the digits by powers
//!   of five in 64-bit integers with a sticky bit and rounding once. Dates (`YYYY-MM-DD`) are
//!   read by [`parse_date_bytes`], in 32-bit integers.
//! * [`write_result`] prints what `magic_core::line::write_result` prints: variables and residual
//!   with six decimals, rounded half to even, `NaN`, `inf`, `-inf` and `-0.000000` as Rust
//!   prints them. The board's values are f32 (its residual too) and are formatted exactly, in
//!   integer arithmetic, so the text is identical. Magnitudes of 2³² and more (never produced by
//!   a valid model) are written in exponent form.
//! * [`write_u32`], [`write_hex32`] and [`write_hex8`] print integers without `core::fmt` (its formatting
//!   machinery costs about 2 KB of flash), for the result rows, the cost figures and the errors.

use core::fmt::{self, Write};
use magic_core::line::LineError;
use magic_core::Inversion;

/// Largest accepted observation magnitude (as [`magic_core::invert::MAX_ABS_OBS`], in f32).
const MAX_ABS: f32 = magic_core::invert::MAX_ABS_OBS as f32;

/// Parses one line of comma-separated numbers into `out` (all of it), NaN for missing fields;
/// the contract of `magic_core::line::parse_obs` for text.
#[cfg(test)]
pub fn parse_obs(line: &str, out: &mut [f32]) -> Result<(), LineError> {
    parse_obs_bytes(line.as_bytes(), out)
}

/// `parse_obs` on raw bytes (the board does not check UTF-8: a non-ASCII byte is simply not
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
    let day = parse_date_bytes(&line[..comma]).ok_or(LineError::BadDate)?;
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

/// `magic_core::time::parse_date` on bytes, in 32-bit integer arithmetic: `YYYY-MM-DD` or
/// `YYYY.MM.DD` (ASCII white space around it ignored), each field as `i32`/`u32::from_str`
/// reads it (an optional `+`, or `-` for the year, then digits), a real date of the proleptic
/// Gregorian calendar. Returns the day number (days since 1970-01-01). Core's version parses
/// `str`s and divides in 64 bits, which costs about 2.5 KB of flash on the board.
pub fn parse_date_bytes(b: &[u8]) -> Option<i32> {
    let &[y0, y1, y2, y3, s1, m0, m1, s2, d0, d1] = b.trim_ascii() else {
        return None;
    };
    if !(s1 == b'-' || s1 == b'.') || s2 != s1 {
        return None;
    }
    let y = int_field(&[y0, y1, y2, y3], true)?;
    let m = int_field(&[m0, m1], false)?;
    let d = int_field(&[d0, d1], false)?;
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let month_days = match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return None,
    };
    if !(1..=month_days).contains(&d) {
        return None;
    }
    // days_from_civil (H. Hinnant), in i32: years −999..=9999 stay far from overflow.
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * ((m + 9) % 12) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some(era * 146_097 + doe - 719_468)
}

/// A field of digits as `i32::from_str` (`signed`) or `u32::from_str` reads it.
fn int_field(f: &[u8], signed: bool) -> Option<i32> {
    let (neg, digits) = match f {
        [b'+', rest @ ..] => (false, rest),
        [b'-', rest @ ..] if signed => (true, rest),
        _ => (false, f),
    };
    if digits.is_empty() {
        return None;
    }
    let mut v = 0i32;
    for &c in digits {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (c - b'0') as i32;
    }
    Some(if neg { -v } else { v })
}

const POW10_F32: [f32; 11] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10];

/// Parses a number in the syntax `str::parse::<f32>` accepts; `None` when it is not one.
#[cfg(test)]
pub fn parse_f32(s: &str) -> Option<f32> {
    parse_f32_bytes(s.as_bytes())
}

/// `parse_f32` (host tests) on bytes.
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
    } else {
        decimal_to_f32(mant, exp10)
    };
    Some(if neg { -v } else { v })
}

/// Powers of five that fit in 64 bits: 5⁰ ..= 5²⁷.
const POW5: [u64; 28] = {
    let mut p = [1u64; 28];
    let mut i = 1;
    while i < 28 {
        p[i] = p[i - 1] * 5;
        i += 1;
    }
    p
};

/// `mant · 10^e10` (mant > 0) correctly rounded to f32, in integer arithmetic: `10^e = 5^e · 2^e`;
/// a positive exponent multiplies by `5^e` (keeping the top 64 bits of the product and a sticky
/// bit), a negative one divides by `5^|e|` by binary long division (27 powers at a time), then
/// [`round_to_f32`] rounds once, half to even.
fn decimal_to_f32(mant: u64, e10: i32) -> f32 {
    if e10 > 38 {
        return f32::INFINITY; // mant ≥ 1: at least 10³⁹
    }
    if e10 >= 0 {
        let (mut q, mut e2, mut sticky) = (mant, e10, false);
        let mut k = e10 as usize;
        while k > 0 {
            let kk = k.min(27);
            let (hi, lo) = mul_wide(q, POW5.get(kk).copied().unwrap_or(1));
            if hi == 0 {
                q = lo;
            } else {
                let z = hi.leading_zeros();
                q = if z == 0 {
                    hi
                } else {
                    (hi << z) | (lo >> (64 - z))
                };
                sticky |= (lo << z) != 0;
                e2 += 64 - z as i32;
            }
            k -= kk;
        }
        return round_to_f32(q, e2, sticky);
    }
    let (mut q, mut e2, mut sticky) = (mant, 0i32, false);
    let mut k = e10.unsigned_abs() as usize;
    // Below 10⁻⁷⁰ every input of at most 19 digits is far below the smallest f32.
    if k > 70 {
        return 0.0;
    }
    while k > 0 {
        let kk = k.min(27);
        let d = POW5.get(kk).copied().unwrap_or(1);
        // The last division needs 26 quotient bits (24, a rounding bit, and one spare); an
        // intermediate one keeps all 64.
        let bits = if k == kk { 26 } else { 64 };
        let z = q.leading_zeros();
        let (nq, c, st) = div_bits(q << z, d, bits);
        // q · 2^−z / 5^kk = (nq + frac) · 2^(64 − c − z), and 10^−kk brings 2^−kk.
        e2 += 64 - c as i32 - z as i32 - kk as i32;
        q = nq;
        sticky |= st;
        k -= kk;
    }
    round_to_f32(q, e2, sticky)
}

/// The 128-bit product `a · b` as (high, low) 64-bit words, from 32-bit limbs (no 128-bit
/// multiplication routine).
fn mul_wide(a: u64, b: u64) -> (u64, u64) {
    let (a0, a1, b0, b1) = (a & 0xFFFF_FFFF, a >> 32, b & 0xFFFF_FFFF, b >> 32);
    let (p00, p01, p10, p11) = (a0 * b0, a0 * b1, a1 * b0, a1 * b1);
    let mid = (p00 >> 32) + (p01 & 0xFFFF_FFFF) + (p10 & 0xFFFF_FFFF);
    let lo = (p00 & 0xFFFF_FFFF) | (mid << 32);
    let hi = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
    (hi, lo)
}

/// `m / d` for `m ≥ 2⁶³` and `d < 2⁶³`, by binary long division over the bits of `m`, until
/// the quotient has `bits` bits: returns the quotient `q`, the number `c` of dividend bits
/// consumed (`m / d = (q + f) · 2^(64 − c)`, 0 ≤ f < 1) and whether `f > 0`.
fn div_bits(m: u64, d: u64, bits: u32) -> (u64, u32, bool) {
    // The first (bit length of d) − 1 bits of m are below d: no quotient bit.
    let c0 = 63 - d.leading_zeros();
    if d < 1 << 31 && bits <= 32 && c0 + bits + 1 < 64 {
        // The usual case (up to 5¹³, a short quotient): remainder and quotient in 32 bits, the
        // dividend's bits shifted out of a 64-bit word (about 10 instructions a bit).
        let (d32, mut rest) = (d as u32, m << c0);
        let (mut c, mut r, mut q) = (c0, (m >> 1 >> (63 - c0)) as u32, 0u32);
        while q < 1 << (bits - 1) && c < 63 {
            c += 1;
            r = (r << 1) | (rest >> 63) as u32;
            rest <<= 1;
            q <<= 1;
            if r >= d32 {
                r -= d32;
                q |= 1;
            }
        }
        return (q as u64, c, r != 0 || rest != 0);
    }
    let (mut c, mut r, mut q) = (c0, if c0 == 0 { 0 } else { m >> (64 - c0) }, 0u64);
    while q < 1 << (bits - 1) && c < 200 {
        c += 1;
        let bit = if c <= 64 { (m >> (64 - c)) & 1 } else { 0 };
        r = (r << 1) | bit;
        q <<= 1;
        if r >= d {
            r -= d;
            q |= 1;
        }
    }
    let low = if c < 64 {
        m & ((1u64 << (64 - c)) - 1)
    } else {
        0
    };
    (q, c, r != 0 || low != 0)
}

/// `(q + f) · 2^e2` (q > 0; `sticky` when the fraction f > 0) rounded to the nearest f32, ties
/// to even, subnormals included; `q` must carry at least 26 bits when `sticky`.
fn round_to_f32(q: u64, e2: i32, sticky: bool) -> f32 {
    let n = 64 - q.leading_zeros() as i32; // bit length of q
                                           // Bits of q below the f32's last place: 24 significant bits, or fewer near 2^−149.
    let sh = (n - 24).max(-149 - e2);
    let (mut m, exp) = if sh <= 0 {
        (q << (-sh).min(63), e2 + sh)
    } else if sh > 64 {
        (0, e2 + sh)
    } else {
        let m = if sh == 64 { 0 } else { q >> sh };
        let rem = if sh == 64 { q } else { q & ((1u64 << sh) - 1) };
        let half = 1u64 << (sh - 1);
        let up = rem > half || (rem == half && (sticky || m & 1 == 1));
        (m + up as u64, e2 + sh)
    };
    // The value is m · 2^exp with m < 2^25; renormalise a carry out of 24 bits.
    let mut exp = exp;
    if m == 1 << 24 {
        m >>= 1;
        exp += 1;
    }
    if m == 0 {
        return 0.0;
    }
    // Normal: m ∈ [2²³, 2²⁴), biased exponent exp + 150; subnormal: exp = −149, m < 2²³.
    let biased = exp + 150;
    if biased >= 255 {
        f32::INFINITY
    } else if m < 1 << 23 {
        f32::from_bits(m as u32)
    } else {
        f32::from_bits(((biased as u32) << 23) | (m as u32 & 0x7F_FFFF))
    }
}

/// Writes the result row of an inversion (no newline), as `magic_core::line::write_result`
/// prints it. The board's inversion is in f32, its residual too (stored as f64, converted back
/// exactly), so everything is printed by [`write_fixed6`] from f32.
pub fn write_result<W: Write>(w: &mut W, inv: &Inversion<f32>) -> fmt::Result {
    for &p in inv.params.iter().take(inv.n_params) {
        write_fixed6(w, p)?;
        w.write_char(',')?;
    }
    write_fixed6(w, inv.residual_rms as f32)?;
    w.write_char(',')?;
    write_u32(w, u32::from(inv.flags.0))?;
    w.write_char(',')?;
    write_u32(w, inv.used)
}

/// Writes `v` in decimal, as `{v}` does.
pub fn write_u32<W: Write>(w: &mut W, v: u32) -> fmt::Result {
    write_digits(w, v, 1)
}

/// Writes `v` in decimal with at least `min` digits (zeros in front; `min` up to 10).
fn write_digits<W: Write>(w: &mut W, mut v: u32, min: usize) -> fmt::Result {
    let mut buf = [b'0'; 10];
    let mut i = buf.len();
    while v > 0 || buf.len() - i < min {
        let Some(slot) = i.checked_sub(1) else { break };
        i = slot;
        if let Some(b) = buf.get_mut(i) {
            *b = b'0' + (v % 10) as u8;
        }
        v /= 10;
    }
    for &b in buf.get(i..).unwrap_or(&[]) {
        w.write_char(char::from(b))?;
    }
    Ok(())
}

/// Writes `v` as `{v:#010x}` does: `0x` and eight lower-case hex digits.
pub fn write_hex32<W: Write>(w: &mut W, v: u32) -> fmt::Result {
    w.write_str("0x")?;
    write_hex8(w, v)
}

/// Writes `v` as `{v:08x}` does: eight lower-case hex digits (a model's id on the board's
/// answers).
pub fn write_hex8<W: Write>(w: &mut W, v: u32) -> fmt::Result {
    for k in (0..8).rev() {
        let d = ((v >> (4 * k)) & 0xF) as u8;
        w.write_char(char::from(if d < 10 { b'0' + d } else { b'a' + d - 10 }))?;
    }
    Ok(())
}

/// Writes `v` as `format!("{v:.6}")` does, exactly, in integer arithmetic (no soft-float f64 on
/// the board). `v = m · 2^e` with a 24-bit `m`: the integer part is `m` shifted, the fraction's
/// 10⁶-multiple `⌊(m mod 2^−e) · 10⁶ / 2^−e⌉` (half to even) fits in 64 bits. Magnitudes of 2³²
/// and more (never produced by a valid model) are written in exponent form (not Rust's output).
pub fn write_fixed6<W: Write>(w: &mut W, v: f32) -> fmt::Result {
    if v.is_nan() {
        return w.write_str("NaN");
    }
    let sign = if v.is_sign_negative() { "-" } else { "" };
    let a = v.abs();
    if a.is_infinite() {
        w.write_str(sign)?;
        return w.write_str("inf");
    }
    if a < 4_294_967_296.0 {
        let bits = a.to_bits();
        let (biased, frac) = (bits >> 23, bits & 0x7F_FFFF);
        let (m, e) = if biased == 0 {
            (frac, -149)
        } else {
            (frac | 0x80_0000, biased as i32 - 150)
        };
        let (mut ip, mut q) = if e >= 0 {
            ((m as u64) << e, 0u64)
        } else {
            let s = e.unsigned_abs();
            // Beyond 44 bits of shift the fraction · 10⁶ (< 2^44) is below half a unit: 0.
            if s > 44 {
                (0, 0)
            } else {
                let ip = if s >= 32 { 0 } else { (m >> s) as u64 };
                let f = (m as u64 & ((1u64 << s) - 1)) * 1_000_000;
                let (mut q, r, half) = (f >> s, f & ((1u64 << s) - 1), 1u64 << (s - 1));
                if r > half || (r == half && q & 1 == 1) {
                    q += 1;
                }
                (ip, q)
            }
        };
        if q == 1_000_000 {
            ip += 1;
            q = 0;
        }
        if let Ok(ip) = u32::try_from(ip) {
            w.write_str(sign)?;
            write_u32(w, ip)?;
            w.write_char('.')?;
            return write_digits(w, q as u32, 6);
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
    w.write_str(sign)?;
    write_u32(w, q / 1_000_000)?;
    w.write_char('.')?;
    write_digits(w, q % 1_000_000, 6)?;
    w.write_char('e')?;
    write_u32(w, k)
}

#[cfg(test)]
mod tests;
