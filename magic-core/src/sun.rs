//! The sun's position in the sky from a date, a time of day and a place: the illumination
//! geometry of a satellite acquisition.
//!
//! The paper's INFORM inversion fixes the sun at 30° from the zenith for every Sentinel-2 spectrum,
//! whatever its date; over Austria between April and October the sun stands 27–62° from the zenith
//! at the overpass (about 10:00 UTC). [`position`] gives the true zenith and azimuth, so that the
//! declared effect [`crate::effects::Effect::Illumination`] can hand INFORM each spectrum's own
//! sun.
//!
//! The equations are the Astronomical Almanac's low-precision solar coordinates (also Michalsky,
//! 1988, Solar Energy 40: 227–235): from the days since J2000.0, the sun's mean longitude and mean
//! anomaly give its ecliptic longitude, the obliquity of the ecliptic turns that into right
//! ascension and declination, and the Greenwich mean sidereal time gives the local hour angle.
//! They hold the sun's coordinates to about 0.01° between 1950 and 2050 (tested against the
//! published instants of solstices and equinoxes), far below what the unknown site location
//! (±2° over the data's region) leaves. No refraction is applied (it matters only near the
//! horizon). Computed in f64 (host, and the RTM firmware, where it costs a few thousand
//! instructions per spectrum against millions for INFORM).

use crate::Error;

/// The sun's position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunPosition {
    /// Angle from the zenith (degrees, 0 overhead, 90 on the horizon).
    pub zenith_deg: f64,
    /// Azimuth, clockwise from north (degrees, 0–360; 180 due south).
    pub azimuth_deg: f64,
}

/// The sun's position at day number `day` (days since 1970-01-01; whole days), `utc_hours`
/// (0–24) on that day, seen from latitude `lat_deg` (north positive) and longitude `lon_deg` (east
/// positive).
///
/// ```
/// use magic_core::{sun, time};
/// // Local solar noon near the June solstice at 47.5° N: the sun stands about 47.5 − 23.4 degrees
/// // from the zenith, due south.
/// let day = time::days_from_civil(2018, 6, 21) as f64;
/// let noon = 12.0 - 14.5 / 15.0 + 0.0257; // 14.5° E, equation of time −1.5 min
/// let p = sun::position(day, noon, 47.5, 14.5).unwrap();
/// assert!((p.zenith_deg - 24.06).abs() < 0.1, "{p:?}");
/// assert!((p.azimuth_deg - 180.0).abs() < 0.5, "{p:?}");
/// ```
pub fn position(
    day: f64,
    utc_hours: f64,
    lat_deg: f64,
    lon_deg: f64,
) -> Result<SunPosition, Error> {
    if !day.is_finite() || day.abs() > 1e7 {
        return Err(Error::OutOfRange {
            what: "date of the sun's position",
        });
    }
    if !(0.0..=24.0).contains(&utc_hours) {
        return Err(Error::OutOfRange {
            what: "UTC hour of the sun's position (0..24)",
        });
    }
    if !(-90.0..=90.0).contains(&lat_deg) || !(-180.0..=360.0).contains(&lon_deg) {
        return Err(Error::OutOfRange {
            what: "site latitude (-90..90) or longitude (-180..360)",
        });
    }
    let (decl, ra, gmst_h) = equatorial(day + utc_hours / 24.0);
    let ha = (gmst_h * 15.0 + lon_deg).to_radians() - ra;
    let lat = lat_deg.to_radians();
    let (sl, cl) = (libm::sin(lat), libm::cos(lat));
    let (sd, cd) = (libm::sin(decl), libm::cos(decl));
    let ch = libm::cos(ha);
    let cos_z = (sl * sd + cl * cd * ch).clamp(-1.0, 1.0);
    let zenith = libm::acos(cos_z);
    // Azimuth from north, clockwise: atan2 of the east and north components of the sun's direction.
    let east = -libm::sin(ha) * cd;
    let north = cl * sd - sl * cd * ch;
    let mut az = libm::atan2(east, north).to_degrees();
    if az < 0.0 {
        az += 360.0;
    }
    Ok(SunPosition {
        zenith_deg: zenith.to_degrees(),
        azimuth_deg: az,
    })
}

/// The sun's declination and right ascension (radians) and the Greenwich mean sidereal time
/// (hours, 0–24) at `t` days since 1970-01-01 00:00 UTC.
fn equatorial(t: f64) -> (f64, f64, f64) {
    let n = t - 10_957.5; // days since J2000.0 (2000-01-01 12:00 UT)
    let l = libm::fmod(280.460 + 0.985_647_4 * n, 360.0);
    let g = libm::fmod(357.528 + 0.985_600_3 * n, 360.0).to_radians();
    let lambda = (l + 1.915 * libm::sin(g) + 0.020 * libm::sin(2.0 * g)).to_radians();
    let eps = (23.439 - 0.000_000_4 * n).to_radians();
    let (sl, cl) = (libm::sin(lambda), libm::cos(lambda));
    let ra = libm::atan2(libm::cos(eps) * sl, cl);
    let decl = libm::asin(libm::sin(eps) * sl);
    let gmst = libm::fmod(18.697_374_558 + 24.065_709_824_419_08 * n, 24.0);
    (decl, ra, gmst)
}

/// The relative azimuth between sun and view, folded to 0–180° (what 4SAIL and INFORM take as
/// `psi`).
pub fn relative_azimuth(sun_azimuth_deg: f64, view_azimuth_deg: f64) -> f64 {
    let d = libm::fmod(libm::fabs(sun_azimuth_deg - view_azimuth_deg), 360.0);
    if d > 180.0 {
        360.0 - d
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::time::days_from_civil;

    /// Days since 1970 of a UTC instant.
    fn at(y: i32, m: u32, d: u32, h: f64, min: f64) -> f64 {
        days_from_civil(y, m, d) as f64 + (h + min / 60.0) / 24.0
    }

    /// Declination at the published instants (given to the minute; the obliquity to 0.001°):
    /// measured 2.6e-3°; 7.7× that.
    const DECLINATION_MAX_ERROR_DEG: f64 = 0.02;
    /// Zenith at computed solar noon against |latitude − declination|: measured 1.6e-7°; 10× that,
    /// rounded up.
    const NOON_ZENITH_MAX_ERROR_DEG: f64 = 2e-6;
    /// Azimuth at computed solar noon against due south (the noon estimate uses the declination
    /// of 12:00): measured 5.5e-3°; 10× that, rounded up.
    const NOON_AZIMUTH_MAX_ERROR_DEG: f64 = 0.06;

    /// Solstices and equinoxes (published UTC instants, to the minute): the declination is
    /// ±23.44° (the obliquity) or 0 there.
    #[test]
    fn declination_at_solstices_and_equinoxes() {
        let eps = 23.436;
        let cases = [
            (at(2018, 3, 20, 16.0, 15.0), 0.0),
            (at(2018, 6, 21, 10.0, 7.0), eps),
            (at(2018, 9, 23, 1.0, 54.0), 0.0),
            (at(2018, 12, 21, 22.0, 23.0), -eps),
            (at(2008, 3, 20, 5.0, 48.0), 0.0),
            (at(2008, 6, 20, 23.0, 59.0), eps),
            (at(2024, 9, 22, 12.0, 44.0), 0.0),
            (at(2024, 12, 21, 9.0, 20.0), -eps),
        ];
        let mut worst = 0f64;
        for (t, want) in cases {
            let (decl, _, _) = equatorial(t);
            worst = worst.max((decl.to_degrees() - want).abs());
            assert!(
                (decl.to_degrees() - want).abs() <= DECLINATION_MAX_ERROR_DEG,
                "{t}: {}",
                decl.to_degrees()
            );
        }
        std::eprintln!("declination at solstices and equinoxes: {worst:.2e} deg");
    }

    /// At local solar noon (hour angle 0) the sun is due south (north of the tropic) at
    /// |latitude − declination| from the zenith; the equation of time stays within its known
    /// range (−14.3 … +16.5 min).
    #[test]
    fn solar_noon() {
        let (mut zenith, mut azimuth) = (0f64, 0f64);
        for doy in (0..365).step_by(7) {
            let day = (days_from_civil(2018, 1, 1) + doy) as f64;
            let (_, ra, gmst) = equatorial(day + 0.5);
            // Hour angle at 12:00 UTC on the Greenwich meridian, in minutes of time: the equation
            // of time.
            let ha = libm::remainder(gmst * 15.0 - ra.to_degrees(), 360.0);
            assert!(
                (-14.3..=16.5).contains(&(ha * 4.0)),
                "doy {doy}: {}",
                ha * 4.0
            );
            let noon = 12.0 - ha / 15.0 - 14.5 / 15.0;
            let p = position(day, noon, 47.5, 14.5).unwrap();
            let want = 47.5 - equatorial(day + noon / 24.0).0.to_degrees();
            zenith = zenith.max((p.zenith_deg - want).abs());
            azimuth = azimuth.max((p.azimuth_deg - 180.0).abs());
            assert!(
                (p.zenith_deg - want).abs() <= NOON_ZENITH_MAX_ERROR_DEG,
                "doy {doy}: {p:?} vs {want}"
            );
            assert!(
                (p.azimuth_deg - 180.0).abs() <= NOON_AZIMUTH_MAX_ERROR_DEG,
                "doy {doy}: {p:?}"
            );
        }
        std::eprintln!("solar noon: zenith {zenith:.2e} deg, azimuth {azimuth:.2e} deg");
    }

    #[test]
    fn austrian_overpass_spans_the_season() {
        // 10:00 UTC at 47.5° N 14.5° E: the dates of the Sentinel-2 data.
        let z = |m, d| {
            let day = days_from_civil(2018, m, d) as f64;
            position(day, 10.0, 47.5, 14.5).unwrap()
        };
        let (apr, jul, oct) = (z(4, 8), z(7, 2), z(10, 30));
        assert!((40.0..46.0).contains(&apr.zenith_deg), "{apr:?}");
        assert!((25.0..30.0).contains(&jul.zenith_deg), "{jul:?}");
        assert!((60.0..66.0).contains(&oct.zenith_deg), "{oct:?}");
        // Before local solar noon: the sun is south-east of south.
        for p in [apr, jul, oct] {
            assert!((130.0..180.0).contains(&p.azimuth_deg), "{p:?}");
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(position(f64::NAN, 10.0, 47.5, 14.5).is_err());
        assert!(position(17_000.0, 25.0, 47.5, 14.5).is_err());
        assert!(position(17_000.0, 10.0, 91.0, 14.5).is_err());
        assert!(position(17_000.0, f64::NAN, 47.5, 14.5).is_err());
        assert!(position(17_000.0, 10.0, 47.5, f64::INFINITY).is_err());
    }

    #[test]
    fn relative_azimuth_folds() {
        assert_eq!(relative_azimuth(150.0, 100.0), 50.0);
        assert_eq!(relative_azimuth(10.0, 350.0), 20.0);
        assert_eq!(relative_azimuth(0.0, 180.0), 180.0);
        assert_eq!(relative_azimuth(200.0, 10.0), 170.0);
    }
}
