//! Dates as NGL writes them (`YYMMMDD`, MJD) and as the rest of magic writes them
//! (`YYYY.MM.DD`, `YYYY-MM-DD`), all as day numbers (days since 1970-01-01).

/// Modified Julian Date of 1970-01-01 (day numbers here count days from 1970-01-01).
pub const MJD_1970: i64 = 40_587;

/// Month abbreviations of `YYMMMDD`.
pub const MONTHS: [&str; 12] = [
    "JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC",
];

/// `YYYY<sep>MM<sep>DD` of a day number.
pub fn format_date(day: i64, sep: char) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(day);
    format!("{y:04}{sep}{m:02}{sep}{d:02}")
}

/// Parses `YYYY-MM-DD` or `YYYY.MM.DD` into a day number (the core's date parser).
pub fn parse_ymd(s: &str) -> Option<i64> {
    magic_core::time::parse_date(s)
}

/// Parses NGL's `YYMMMDD` (`10JUL28` → 2010-07-28) into a day number. Two-digit years 80–99 are
/// 1980–1999, 00–79 are 2000–2079 (the MJD cross-check catches anything else).
///
/// ```
/// use magic_train::gnss::tenv3::{format_date, parse_yymmmdd};
/// assert_eq!(format_date(parse_yymmmdd("10JUL28").unwrap(), '-'), "2010-07-28");
/// ```
pub fn parse_yymmmdd(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 7 || !b[..2].iter().chain(&b[5..]).all(u8::is_ascii_digit) {
        return None;
    }
    let yy = ((b[0] - b'0') * 10 + (b[1] - b'0')) as i64;
    let mon = std::str::from_utf8(&b[2..5]).ok()?.to_ascii_uppercase();
    let m = MONTHS.iter().position(|x| *x == mon)? as u32 + 1;
    let d = ((b[5] - b'0') * 10 + (b[6] - b'0')) as u32;
    let y = if yy >= 80 { 1900 + yy } else { 2000 + yy };
    magic_core::time::parse_date(&format!("{y:04}-{m:02}-{d:02}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::tenv3::test_lines::D0;

    #[test]
    fn dates() {
        assert_eq!(parse_yymmmdd("10JUL28"), Some(D0));
        assert_eq!(format_date(D0, '-'), "2010-07-28");
        assert_eq!(
            parse_yymmmdd("96feb29"),
            Some(magic_core::time::days_from_civil(1996, 2, 29))
        );
        assert_eq!(parse_yymmmdd("97FEB29"), None);
        assert_eq!(parse_yymmmdd("10JUX28"), None);
        assert_eq!(parse_yymmmdd("10JUL2"), None);
        assert_eq!(parse_ymd("2010-07-28"), Some(D0));
        assert_eq!(parse_ymd("2010.07.28"), Some(D0));
        assert_eq!(parse_ymd("2010-13-01"), None);
        for day in [-1000, 0, 59, 10_000, 14_818, 20_000, 40_000] {
            let (y, m, d) = magic_core::time::civil_from_days(day);
            assert_eq!(magic_core::time::days_from_civil(y, m, d), day);
        }
        // 1858-11-17 is MJD 0.
        assert_eq!(magic_core::time::days_from_civil(1858, 11, 17), -MJD_1970);
    }
}
