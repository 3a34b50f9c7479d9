//! Station coordinates: WGS-84 geodetic latitude, longitude and height → Earth-centred,
//! Earth-fixed (ECEF) Cartesian coordinates → local east, north, up about an origin (a local
//! tangent plane), and back.
//!
//! The ellipsoid is WGS-84 (NIMA TR8350.2: a = 6 378 137 m, 1/f = 298.257 223 563). With
//! e² = f (2 − f) and the prime-vertical radius N(φ) = a / √(1 − e² sin² φ), a point at latitude
//! φ, longitude λ and ellipsoidal height h is at
//!
//! ```text
//! X = (N + h) cos φ cos λ,   Y = (N + h) cos φ sin λ,   Z = (N (1 − e²) + h) sin φ,
//! ```
//!
//! and its offset d = P − P₀ from the origin (φ₀, λ₀) is rotated into the origin's east, north
//! and up directions:
//!
//! ```text
//! e = −sin λ₀ dX + cos λ₀ dY
//! n = −sin φ₀ cos λ₀ dX − sin φ₀ sin λ₀ dY + cos φ₀ dZ
//! u =  cos φ₀ cos λ₀ dX + cos φ₀ sin λ₀ dY + sin φ₀ dZ
//! ```
//!
//! The way back (ECEF → geodetic) iterates the latitude (it converges to 1e-12° in a few passes
//! for any point above the ellipsoid's centre region).

/// WGS-84 semi-major axis (m).
pub const WGS84_A: f64 = 6_378_137.0;

/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// First eccentricity squared, e² = f (2 − f).
pub fn e2() -> f64 {
    WGS84_F * (2.0 - WGS84_F)
}

/// A longitude in degrees wrapped into (−180°, 180°]. NGL's `tenv3` files write longitudes
/// unwrapped: −268.896° is 91.104° E.
///
/// ```
/// use magic_train::gnss::geodesy::wrap_longitude;
/// assert!((wrap_longitude(-268.896) - 91.104).abs() < 1e-9);
/// assert_eq!(wrap_longitude(180.0), 180.0);
/// assert_eq!(wrap_longitude(-180.0), 180.0);
/// ```
pub fn wrap_longitude(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    if w > 180.0 {
        w - 360.0
    } else {
        w
    }
}

/// ECEF coordinates (m) of latitude, longitude (°) and ellipsoidal height (m).
pub fn ecef(lat_deg: f64, lon_deg: f64, h_m: f64) -> [f64; 3] {
    let (sp, cp) = lat_deg.to_radians().sin_cos();
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - e2() * sp * sp).sqrt();
    [
        (n + h_m) * cp * cl,
        (n + h_m) * cp * sl,
        (n * (1.0 - e2()) + h_m) * sp,
    ]
}

/// Latitude, longitude (°, wrapped) and ellipsoidal height (m) of ECEF coordinates (m).
pub fn geodetic(p: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = p;
    let lon = y.atan2(x);
    let r = x.hypot(y);
    let mut lat = z.atan2(r * (1.0 - e2()));
    let mut h = 0.0;
    for _ in 0..10 {
        let s = lat.sin();
        let n = WGS84_A / (1.0 - e2() * s * s).sqrt();
        h = if lat.cos().abs() > 1e-9 {
            r / lat.cos() - n
        } else {
            z.abs() - n * (1.0 - e2())
        };
        lat = z.atan2(r * (1.0 - e2() * n / (n + h)));
    }
    [lat.to_degrees(), wrap_longitude(lon.to_degrees()), h]
}

/// A local east-north-up frame about an origin on or above the ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalFrame {
    /// Origin latitude, longitude (°) and ellipsoidal height (m).
    pub origin: [f64; 3],
    origin_ecef: [f64; 3],
    /// Rows: the unit east, north and up vectors in ECEF.
    axes: [[f64; 3]; 3],
}

impl LocalFrame {
    /// The frame about latitude, longitude (°) and height (m).
    pub fn new(lat_deg: f64, lon_deg: f64, h_m: f64) -> LocalFrame {
        let (sp, cp) = lat_deg.to_radians().sin_cos();
        let (sl, cl) = lon_deg.to_radians().sin_cos();
        LocalFrame {
            origin: [lat_deg, wrap_longitude(lon_deg), h_m],
            origin_ecef: ecef(lat_deg, lon_deg, h_m),
            axes: [
                [-sl, cl, 0.0],
                [-sp * cl, -sp * sl, cp],
                [cp * cl, cp * sl, sp],
            ],
        }
    }

    /// East, north, up (m) of a point given by latitude, longitude (°) and height (m).
    ///
    /// ```
    /// use magic_train::gnss::geodesy::LocalFrame;
    /// let f = LocalFrame::new(54.13, -165.97, 0.0);
    /// let [e, n, u] = f.enu(54.13, -165.97 + 360.0, 410.0); // an unwrapped longitude
    /// assert!(e.abs() < 1e-6 && n.abs() < 1e-6 && (u - 410.0).abs() < 1e-6);
    /// ```
    pub fn enu(&self, lat_deg: f64, lon_deg: f64, h_m: f64) -> [f64; 3] {
        let p = ecef(lat_deg, lon_deg, h_m);
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - self.origin_ecef[k]);
        self.axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
    }

    /// Latitude, longitude (°) and height (m) of a point east, north, up (m) of the origin.
    pub fn geodetic(&self, enu: [f64; 3]) -> [f64; 3] {
        let a = &self.axes;
        let p: [f64; 3] = std::array::from_fn(|k| {
            self.origin_ecef[k] + a[0][k] * enu[0] + a[1][k] * enu[1] + a[2][k] * enu[2]
        });
        geodetic(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Round-trip tolerance: metres (1e-6 m) and degrees (1e-11° ≈ 1 µm).
    const ROUND_TRIP_M: f64 = 1e-6;

    #[test]
    fn ecef_of_reference_points() {
        let b = WGS84_A * (1.0 - WGS84_F);
        let close = |p: [f64; 3], q: [f64; 3]| (0..3).all(|k| (p[k] - q[k]).abs() < ROUND_TRIP_M);
        assert!(close(ecef(0.0, 0.0, 0.0), [WGS84_A, 0.0, 0.0]));
        assert!(close(ecef(0.0, 90.0, 10.0), [0.0, WGS84_A + 10.0, 0.0]));
        assert!(close(ecef(90.0, 0.0, 0.0), [0.0, 0.0, b]));
        assert!(close(ecef(-90.0, 33.0, 5.0), [0.0, 0.0, -b - 5.0]));
    }

    #[test]
    fn geodetic_round_trip() {
        for &(lat, lon, h) in &[
            (54.13, -165.97, 410.3),
            (-33.9, 151.2, 12.0),
            (0.0, 180.0, -30.0),
            (89.9, 91.104, 2000.0),
            (19.4, -155.3, 4100.0),
        ] {
            let g = geodetic(ecef(lat, lon, h));
            assert!((g[0] - lat).abs() < 1e-11, "{g:?}");
            assert!(wrap_longitude(g[1] - lon).abs() < 1e-11, "{g:?}");
            assert!((g[2] - h).abs() < ROUND_TRIP_M, "{g:?}");
        }
    }

    #[test]
    fn local_frame_directions_and_round_trip() {
        let f = LocalFrame::new(54.13, -165.97, 0.0);
        // A small step north along the meridian: the meridional radius of curvature
        // M = a (1 − e²) / (1 − e² sin² φ)^(3/2) sets its length; up drops by d²/(2M).
        let phi = 54.13f64.to_radians();
        let w = 1.0 - e2() * phi.sin().powi(2);
        let m = WGS84_A * (1.0 - e2()) / w.powf(1.5);
        let dphi = 0.01f64.to_radians();
        let [e, n, u] = f.enu(54.14, -165.97, 0.0);
        assert!(e.abs() < 1e-6, "{e}");
        assert!((n / (m * dphi) - 1.0).abs() < 1e-4, "{n} vs {}", m * dphi);
        assert!((u + n * n / (2.0 * m)).abs() < 0.01, "{u}");
        // East along the parallel: N cos φ per radian.
        let nn = WGS84_A / w.sqrt();
        let [e, n, _] = f.enu(54.13, -165.96, 0.0);
        assert!((e / (nn * phi.cos() * dphi) - 1.0).abs() < 1e-4);
        assert!(
            n.abs() < 1.0,
            "the parallel curves away from the tangent plane: {n}"
        );
        // Round trip through the frame.
        for enu in [
            [-9329.0, -1452.8, 364.1],
            [14357.0, -4684.5, 457.4],
            [0.0, 0.0, 0.0],
        ] {
            let g = f.geodetic(enu);
            let back = f.enu(g[0], g[1], g[2]);
            for k in 0..3 {
                assert!(
                    (back[k] - enu[k]).abs() < ROUND_TRIP_M,
                    "{back:?} vs {enu:?}"
                );
            }
        }
    }
}
