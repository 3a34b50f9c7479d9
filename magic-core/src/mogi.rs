//! The Mogi point pressure source in an elastic half-space (Mogi 1958; paper eqs. 9–13).
//!
//! A source at horizontal position (x, y) km, depth d km, with volume change ΔV (10⁶ m³) displaces a
//! surface station at (xᵢ, yᵢ) by
//!
//! ```text
//! (uₑ, uₙ, uᵥ) = α · (xᵢ − x, yᵢ − y, d) / Rᵢ³,   α = (1 − ν) ΔV / π,
//! Rᵢ = √((xᵢ − x)² + (yᵢ − y)² + d²)
//! ```
//!
//! with Poisson's ratio ν = 0.25. Station elevation is neglected (half-space), as in the paper and
//! its reference implementation. With ΔV in 10⁶ m³ and lengths in km the displacement comes out in
//! metres; this module returns millimetres.
//!
//! The code is generic over [`Real`]: `f32` on the board, `f64` on the host, [`Dual`] for the exact
//! Jacobian used in training and in Gauss–Newton refinement.

use crate::real::{Dual, Real};
use crate::Error;
use serde::{Deserialize, Serialize};

/// Poisson's ratio of the crust.
pub const POISSON: f64 = 0.25;

/// Number of source parameters: x (km east), y (km north), depth (km), ΔV (10⁶ m³).
pub const N_PARAMS: usize = 4;

/// Names of the source parameters, in order, as used in CSV headers.
pub const PARAM_NAMES: [&str; N_PARAMS] = ["x_km", "y_km", "depth_km", "dv_1e6m3"];

/// The paper's bounds (Table 2): min and max of x, y, depth, ΔV.
pub const PAPER_BOUNDS: [[f64; 2]; N_PARAMS] =
    [[-9.33, 14.35], [-5.80, 7.62], [2.0, 20.0], [-10.0, 10.0]];

/// A GNSS station in local coordinates (km east, km north, km elevation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Station {
    /// East of the network origin, km.
    pub x_km: f64,
    /// North of the network origin, km.
    pub y_km: f64,
    /// Elevation, km (not used by the half-space model; kept for effects that need it).
    pub z_km: f64,
}

/// A list of stations: a slice of [`Station`]s (the host) or the little-endian bytes of a model
/// file ([`Stations`], read in place on the board).
pub trait Network {
    /// Number of stations.
    fn n_stations(&self) -> usize;
    /// Station `i`; implementations return a station at the origin past the end rather than
    /// panicking (callers iterate over `0..n_stations()`).
    fn station(&self, i: usize) -> Station;
}

/// The origin, returned past the end of a [`Network`].
const ORIGIN: Station = Station {
    x_km: 0.0,
    y_km: 0.0,
    z_km: 0.0,
};

impl Network for [Station] {
    #[inline]
    fn n_stations(&self) -> usize {
        self.len()
    }
    #[inline]
    fn station(&self, i: usize) -> Station {
        self.get(i).copied().unwrap_or(ORIGIN)
    }
}

/// Bytes per station in a model file: east, north, elevation as little-endian `f64` (km).
pub const STATION_BYTES: usize = 24;

/// Station positions borrowed from a model file: [`STATION_BYTES`] per station, east, north and
/// elevation as little-endian `f64` km (no alignment requirement, nothing copied).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Stations<'a>(#[serde(borrow)] pub &'a [u8]);

impl<'a> Stations<'a> {
    /// Number of whole stations (trailing partial bytes are ignored; validation rejects them).
    #[inline]
    pub fn len(&self) -> usize {
        self.0.len() / STATION_BYTES
    }
    /// Whether there are none.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Station `i`, or the origin past the end.
    #[inline]
    pub fn get(&self, i: usize) -> Station {
        match self
            .0
            .get(STATION_BYTES * i..STATION_BYTES * (i + 1))
            .and_then(|b| <&[u8; STATION_BYTES]>::try_from(b).ok())
        {
            Some(b) => {
                let f = |k: usize| {
                    f64::from_le_bytes([
                        b[8 * k],
                        b[8 * k + 1],
                        b[8 * k + 2],
                        b[8 * k + 3],
                        b[8 * k + 4],
                        b[8 * k + 5],
                        b[8 * k + 6],
                        b[8 * k + 7],
                    ])
                };
                Station {
                    x_km: f(0),
                    y_km: f(1),
                    z_km: f(2),
                }
            }
            None => ORIGIN,
        }
    }
    /// The stations in order.
    pub fn iter(&self) -> impl Iterator<Item = Station> + 'a {
        let s = *self;
        (0..s.len()).map(move |i| s.get(i))
    }
    /// The bytes of `stations` in this layout (for writing a model file).
    pub fn encode(stations: &[Station], out: &mut [u8]) -> Result<(), Error> {
        if out.len() != STATION_BYTES * stations.len() {
            return Err(Error::BufferTooSmall {
                needed: STATION_BYTES * stations.len(),
            });
        }
        for (st, b) in stations.iter().zip(out.chunks_exact_mut(STATION_BYTES)) {
            b[..8].copy_from_slice(&st.x_km.to_le_bytes());
            b[8..16].copy_from_slice(&st.y_km.to_le_bytes());
            b[16..].copy_from_slice(&st.z_km.to_le_bytes());
        }
        Ok(())
    }
}

impl Network for Stations<'_> {
    #[inline]
    fn n_stations(&self) -> usize {
        self.len()
    }
    #[inline]
    fn station(&self, i: usize) -> Station {
        self.get(i)
    }
}

pub use crate::real::sqrt::sqrt;

/// Displacement (east, north, up) in mm at one station from a source `p = [x, y, depth, ΔV]`.
#[inline]
pub fn displacement<R: Real>(station: &Station, p: &[R; N_PARAMS]) -> [R; 3] {
    let dx = R::c(station.x_km) - p[0];
    let dy = R::c(station.y_km) - p[1];
    let d = p[2];
    let r2 = dx * dx + dy * dy + d * d;
    let r3 = r2 * sqrt(r2);
    // α in mm·km²: (1 − ν) ΔV / π × 1000 (m → mm)
    let alpha = p[3] * R::c((1.0 - POISSON) / core::f64::consts::PI * 1000.0);
    let k = alpha / r3;
    [k * dx, k * dy, k * d]
}

/// The displacement field of a network: `out` receives uₑ for every station, then uₙ, then uᵥ
/// (3 × stations values, the column order of the GNSS data files).
///
/// ```
/// use magic_core::mogi::{field, Station};
/// let stations = [Station { x_km: 3.0, y_km: 4.0, z_km: 0.0 }];
/// let mut u = [0.0f64; 3];
/// field(&stations, &[0.0, 0.0, 5.0, 1.0], &mut u).unwrap();
/// assert!(u[2] > 0.0); // inflation lifts the surface
/// ```
pub fn field<R: Real>(stations: &[Station], p: &[R; N_PARAMS], out: &mut [R]) -> Result<(), Error> {
    field_of(stations, p, out)
}

/// [`field`] for any [`Network`] (e.g. the [`Stations`] of a model file).
pub fn field_of<R: Real, N: Network + ?Sized>(
    stations: &N,
    p: &[R; N_PARAMS],
    out: &mut [R],
) -> Result<(), Error> {
    let s = stations.n_stations();
    if out.len() != 3 * s {
        return Err(Error::SizeMismatch {
            what: "mogi output",
            expected: 3 * s,
            found: out.len(),
        });
    }
    if p[2].value() <= 0.0 || !p[2].value().is_finite() {
        return Err(Error::OutOfRange {
            what: "source depth",
        });
    }
    // (Checked splits: no panic path even where the compiler cannot see that 3 · s fits.)
    let Some((ue, rest)) = out.split_at_mut_checked(s) else {
        return Err(Error::SizeMismatch {
            what: "mogi output",
            expected: 3 * s,
            found: 0,
        });
    };
    let (un, uu) = rest.split_at_mut(rest.len() / 2);
    for (i, ((e, n), u)) in ue.iter_mut().zip(un).zip(uu).enumerate() {
        let d = displacement(&stations.station(i), p);
        (*e, *n, *u) = (d[0], d[1], d[2]);
    }
    Ok(())
}

/// Field and exact Jacobian: `jac[c][j]` = ∂`out[c]` / ∂`p[j]`. `out` and `jac` hold 3 × stations
/// rows.
pub fn field_jacobian(
    stations: &[Station],
    p: &[f64; N_PARAMS],
    out: &mut [f64],
    jac: &mut [[f64; N_PARAMS]],
) -> Result<(), Error> {
    let s = stations.len();
    if out.len() != 3 * s {
        return Err(Error::SizeMismatch {
            what: "mogi output",
            expected: 3 * s,
            found: out.len(),
        });
    }
    if jac.len() != 3 * s {
        return Err(Error::SizeMismatch {
            what: "mogi jacobian",
            expected: 3 * s,
            found: jac.len(),
        });
    }
    if p[2] <= 0.0 || !p[2].is_finite() {
        return Err(Error::OutOfRange {
            what: "source depth",
        });
    }
    let pd: [Dual<N_PARAMS>; N_PARAMS] = core::array::from_fn(|j| Dual::var(p[j], j));
    for (i, st) in stations.iter().enumerate() {
        let u = displacement(st, &pd);
        for (k, uk) in u.iter().enumerate() {
            out[k * s + i] = uk.v;
            jac[k * s + i] = uk.d;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const NET: [Station; 3] = [
        Station {
            x_km: -4.2,
            y_km: 6.2,
            z_km: 0.35,
        },
        Station {
            x_km: 10.7,
            y_km: 0.5,
            z_km: 0.46,
        },
        Station {
            x_km: 2.0,
            y_km: 1.2,
            z_km: 0.49,
        },
    ];

    /// The exact Jacobian against central differences (step 1e-6 of the value), relative to
    /// max(|difference|, 1e-3): measured 1.6e-8; 10× that, rounded up.
    const JACOBIAN_MAX_REL_ERROR: f64 = 2e-7;
    /// Symmetric stations, and the field at twice the volume (values of tens of mm): measured 0;
    /// a few ulps (an ulp of 40 mm is 7e-15 mm).
    const SYMMETRY_MAX_ERROR_MM: f64 = 3e-14;

    #[test]
    fn jacobian_matches_central_differences() {
        extern crate std;
        let mut worst = 0f64;
        let p = [1.5, -0.7, 6.3, 2.2];
        let mut out = [0.0; 9];
        let mut jac = [[0.0; 4]; 9];
        field_jacobian(&NET, &p, &mut out, &mut jac).unwrap();
        for j in 0..4 {
            let h = 1e-6 * (1.0 + p[j].abs());
            let (mut a, mut b) = (p, p);
            a[j] += h;
            b[j] -= h;
            let (mut fa, mut fb) = ([0.0; 9], [0.0; 9]);
            field(&NET, &a, &mut fa).unwrap();
            field(&NET, &b, &mut fb).unwrap();
            for c in 0..9 {
                let fd = (fa[c] - fb[c]) / (2.0 * h);
                let scale = fd.abs().max(1e-3);
                let rel = (jac[c][j] - fd).abs() / scale;
                worst = worst.max(rel);
                assert!(
                    rel <= JACOBIAN_MAX_REL_ERROR,
                    "c{c} p{j}: {} vs {fd}",
                    jac[c][j]
                );
            }
        }
        std::eprintln!("mogi Jacobian vs central differences: {worst:.2e}");
    }

    #[test]
    fn radial_symmetry_and_linearity_in_volume() {
        let st = [
            Station {
                x_km: 3.0,
                y_km: 4.0,
                z_km: 0.0,
            },
            Station {
                x_km: -3.0,
                y_km: -4.0,
                z_km: 0.0,
            },
        ];
        extern crate std;
        let mut u = [0.0; 6];
        field(&st, &[0.0, 0.0, 5.0, 2.0], &mut u).unwrap();
        let mut worst = (u[0] + u[1])
            .abs()
            .max((u[2] + u[3]).abs())
            .max((u[4] - u[5]).abs());
        let mut v = [0.0; 6];
        field(&st, &[0.0, 0.0, 5.0, 4.0], &mut v).unwrap();
        for i in 0..6 {
            worst = worst.max((v[i] - 2.0 * u[i]).abs());
        }
        std::eprintln!("mogi symmetry and linearity: {worst:.2e} mm");
        assert!(worst <= SYMMETRY_MAX_ERROR_MM, "{worst:e}");
    }

    #[test]
    fn model_file_stations_read_back_exactly() {
        let mut bytes = [0u8; 3 * STATION_BYTES];
        Stations::encode(&NET, &mut bytes).unwrap();
        let st = Stations(&bytes);
        assert_eq!(st.len(), 3);
        assert!(st.iter().eq(NET.iter().copied()));
        assert_eq!(st.get(3), ORIGIN, "past the end");
        assert_eq!(
            Stations(&bytes[..50]).len(),
            2,
            "partial stations are not counted"
        );
        assert!(Stations::encode(&NET, &mut [0u8; 10]).is_err());
        let p = [0.4, -1.0, 5.5, 2.0];
        let (mut a, mut b) = ([0.0; 9], [0.0; 9]);
        field(&NET, &p, &mut a).unwrap();
        field_of(&st, &p, &mut b).unwrap();
        assert_eq!(a, b, "same field from the slice and from the bytes");
    }

    #[test]
    fn rejects_bad_sizes_and_depth() {
        let mut u = [0.0; 5];
        assert!(matches!(
            field(&NET, &[0.0, 0.0, 5.0, 1.0], &mut u),
            Err(Error::SizeMismatch { .. })
        ));
        let mut u = [0.0; 9];
        assert!(matches!(
            field(&NET, &[0.0, 0.0, 0.0, 1.0], &mut u),
            Err(Error::OutOfRange { .. })
        ));
        assert!(field(&NET, &[0.0, 0.0, f64::NAN, 1.0], &mut u).is_err());
    }
}
