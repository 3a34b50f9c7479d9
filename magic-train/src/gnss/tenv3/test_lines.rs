//! Lines of station files for the tests of this module.

use super::dates::{MJD_1970, MONTHS};
use super::layout::OLD_FIELDS;

/// The header of the 23-field layout.
pub const HEAD: &str = "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)";

/// 2010-07-28 as a day number.
pub const D0: i64 = 14_818;

/// A line of the 23-field layout for `day` (days since 1970), position parts given.
pub fn line(site: &str, day: i64, int: [i64; 3], frac: [f64; 3], sig: [f64; 3]) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(day);
    let mjd = day + MJD_1970;
    format!(
        "{site} {:02}{}{:02} {:.4} {mjd} {} {} -166 {} {:.6} {} {:.6} {} {:.6} 0.0000 {:.6} {:.6} {:.6} 0.0123 -0.0204 0.0071 54.1271930 -165.9743172 410.3188",
        y % 100,
        MONTHS[m as usize - 1],
        d,
        y as f64 + 0.5,
        (mjd - 44_244) / 7,
        (mjd - 44_244) % 7,
        int[0],
        frac[0],
        int[1],
        frac[1],
        int[2],
        frac[2],
        sig[0],
        sig[1],
        sig[2],
    )
}

/// A line of the older 20-field layout.
pub fn old_line(site: &str, day: i64, int: [i64; 3], frac: [f64; 3]) -> String {
    let l = line(site, day, int, frac, [0.001, 0.001, 0.004]);
    l.split_whitespace()
        .take(OLD_FIELDS)
        .collect::<Vec<_>>()
        .join(" ")
}
