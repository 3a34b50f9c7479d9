//! Declared extra physics: terms added to the forward model F when residual analysis traces a
//! systematic error to a named effect (the loop of `magic loop`).
//!
//! Two kinds:
//! * **latent** effects add variables the encoder infers for every observation, with their own
//!   bounds (a daily network translation, a vertical term linear in station elevation, the volume
//!   change of a second source at a found position);
//! * **fitted** effects are constants found by the residual analysis and applied as a function of
//!   the observation's date (per-channel annual and semiannual terms, a step at one station from an
//!   epoch, per-channel drift).
//!
//! One effect belongs to the forest-spectra problem instead: **illumination** hands INFORM the
//! true sun of each spectrum's acquisition (zenith and relative azimuth from its date, the
//! overpass time and the site, [`crate::sun`]) in place of the fixed sun of the paper; it changes
//! the fixed inputs of the RTM model ([`rtm_fixed_at`]), not the observation channels.
//!
//! Every term is generic over [`Real`] so the trainer differentiates through it exactly and the
//! board evaluates it in f32. Times are day numbers (days since 1970-01-01, see [`crate::time`]).

use crate::mogi::{self, Network, Station};
use crate::quant::LeF32;
use crate::{Error, Real};
use serde::{Deserialize, Serialize};

/// Largest number of effects in one model.
pub const MAX_EFFECTS: usize = 4;

const TWO_PI: f64 = core::f64::consts::TAU;
const YEAR_DAYS: f64 = 365.25;

/// One declared effect. Observation channels are uₑ ×S, uₙ ×S, uᵥ ×S (mm).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Effect<'a> {
    /// Daily translation of the whole network: 3 latent variables (E, N, U in mm).
    CommonMode,
    /// Vertical displacement `k · (zᵢ − z_ref)`: 1 latent variable k (mm per km of elevation).
    Elevation {
        /// Reference elevation (km), the network mean.
        z_ref_km: f32,
    },
    /// A second Mogi source at a fixed position: 1 latent variable, its volume change (10⁶ m³).
    SecondSource {
        /// East (km).
        x_km: f32,
        /// North (km).
        y_km: f32,
        /// Depth (km).
        depth_km: f32,
    },
    /// Per-channel annual and semiannual terms: `coef` holds, per channel, the amplitudes of
    /// sin(ωt), cos(ωt), sin(2ωt), cos(2ωt) with ω = 2π / 365.25 d (4 × channels f32).
    Seasonal {
        /// Coefficients (mm).
        #[serde(borrow)]
        coef: LeF32<'a>,
    },
    /// A step of `offset_mm` (E, N, U) at one station from `epoch_day` on.
    Step {
        /// Station index.
        station: u16,
        /// First day of the new position.
        epoch_day: f32,
        /// Offset (mm).
        offset_mm: [f32; 3],
    },
    /// Per-channel linear drift `rate · (t − t0) / 365.25` (mm per year).
    Drift {
        /// Reference day.
        t0_day: f32,
        /// Rates (mm/yr), one per channel.
        #[serde(borrow)]
        rate: LeF32<'a>,
    },
    /// RTM models only: the sun of each acquisition from its date (no latent variable, no fitted
    /// constant): sun zenith and azimuth at `utc_hours` on the observation's day at the site,
    /// relative azimuth to the sensor's `view_azimuth_deg`.
    Illumination {
        /// Site latitude (degrees north).
        lat_deg: f32,
        /// Site longitude (degrees east).
        lon_deg: f32,
        /// Acquisition time of day (hours UTC).
        utc_hours: f32,
        /// Azimuth of the sensor's viewing direction (degrees from north; irrelevant for a
        /// nadir view).
        view_azimuth_deg: f32,
    },
    /// RTM models only: a constant reflectance added to each observed band (a bias of the band
    /// model, the sensor or the atmospheric correction, fitted by the residual analysis).
    BandOffset {
        /// One offset per observed band (reflectance, f32).
        #[serde(borrow)]
        offset: LeF32<'a>,
    },
}

impl Effect<'_> {
    /// Number of latent variables the encoder infers for this effect.
    pub fn n_latent(&self) -> usize {
        match self {
            Effect::CommonMode => 3,
            Effect::Elevation { .. } | Effect::SecondSource { .. } => 1,
            _ => 0,
        }
    }

    /// Whether the effect needs the observation's date.
    pub fn needs_time(&self) -> bool {
        matches!(
            self,
            Effect::Seasonal { .. }
                | Effect::Step { .. }
                | Effect::Drift { .. }
                | Effect::Illumination { .. }
        )
    }

    /// The family name used in reports.
    pub fn family(&self) -> &'static str {
        match self {
            Effect::CommonMode => "common_mode",
            Effect::Elevation { .. } => "elevation",
            Effect::SecondSource { .. } => "second_source",
            Effect::Seasonal { .. } => "seasonal",
            Effect::Step { .. } => "step",
            Effect::Drift { .. } => "drift",
            Effect::Illumination { .. } => "illumination",
            Effect::BandOffset { .. } => "band_offset",
        }
    }

    /// Checks the effect against a network of `n_stations`.
    pub fn validate(&self, n_stations: usize) -> Result<(), Error> {
        let n_obs = 3 * n_stations;
        let finite = |v: f32| v.is_finite();
        match *self {
            Effect::CommonMode => Ok(()),
            Effect::Elevation { z_ref_km } if finite(z_ref_km) => Ok(()),
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } if finite(x_km) && finite(y_km) && depth_km > 0.0 => Ok(()),
            Effect::Seasonal { coef } if coef.0.len() == 16 * n_obs && coef.iter().all(finite) => {
                Ok(())
            }
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } if (station as usize) < n_stations
                && finite(epoch_day)
                && offset_mm.iter().all(|v| v.is_finite()) =>
            {
                Ok(())
            }
            Effect::Drift { t0_day, rate }
                if finite(t0_day) && rate.0.len() == 4 * n_obs && rate.iter().all(finite) =>
            {
                Ok(())
            }
            Effect::Illumination { .. } | Effect::BandOffset { .. } => Err(Error::InvalidModel(
                "illumination and band offsets belong to RTM models, not to a GNSS network",
            )),
            _ => Err(Error::InvalidModel(
                "effect parameters invalid or sized for another network",
            )),
        }
    }

    /// Adds the effect to `out` (uₑ ×S, uₙ ×S, uᵥ ×S in mm). `latent` holds this effect's latent
    /// variables; `t_day` the date (needed by fitted effects).
    pub fn apply<R: Real>(
        &self,
        stations: &[Station],
        latent: &[R],
        t_day: f64,
        out: &mut [R],
    ) -> Result<(), Error> {
        self.apply_to(stations, latent, t_day, out)
    }

    /// [`Effect::apply`] for any [`Network`] (e.g. the stations of a model file).
    ///
    /// Everything is computed in `R` (f32 on the board): the date enters through one reduction of
    /// `t_day` to the phase within the year (seasonal) or to years since the reference (drift).
    pub fn apply_to<R: Real, N: Network + ?Sized>(
        &self,
        stations: &N,
        latent: &[R],
        t_day: f64,
        out: &mut [R],
    ) -> Result<(), Error> {
        let s = stations.n_stations();
        if out.len() != 3 * s || latent.len() != self.n_latent() {
            return Err(Error::SizeMismatch {
                what: "effect inputs",
                expected: 3 * s,
                found: out.len(),
            });
        }
        // The date in R (exact for whole days in f32): every use of it below is R arithmetic,
        // so the board's f32 build does no soft-float f64 work here.
        let t = R::c(t_day);
        if self.needs_time() && !t.is_finite() {
            return Err(Error::OutOfRange {
                what: "date (the model has time-dependent effects)",
            });
        }
        match *self {
            Effect::CommonMode => {
                // One translation per component (E, N, U), each added to every station.
                for (comp, &l) in out.chunks_exact_mut(s.max(1)).zip(latent) {
                    for o in comp {
                        *o += l;
                    }
                }
            }
            Effect::Elevation { z_ref_km } => {
                let (Some(&k), Some(up)) = (latent.first(), out.get_mut(2 * s..)) else {
                    return Ok(());
                };
                let z_ref = R::c(z_ref_km as f64);
                for (i, o) in up.iter_mut().enumerate() {
                    *o += k * (R::c(stations.station(i).z_km) - z_ref);
                }
            }
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => {
                let Some(&dv) = latent.first() else {
                    return Ok(());
                };
                let p = [
                    R::c(x_km as f64),
                    R::c(y_km as f64),
                    R::c(depth_km as f64),
                    dv,
                ];
                let Some((ue, rest)) = out.split_at_mut_checked(s) else {
                    return Ok(());
                };
                let (un, uu) = rest.split_at_mut(rest.len() / 2);
                for (i, ((e, n), u)) in ue.iter_mut().zip(un).zip(uu).enumerate() {
                    let d = mogi::displacement(&stations.station(i), &p);
                    *e += d[0];
                    *n += d[1];
                    *u += d[2];
                }
            }
            Effect::Seasonal { coef } => {
                // The phase within the year and its sine and cosine, in R (see `sin_cos_turn`;
                // no f64 arithmetic on the board), the semiannual terms by the double-angle
                // formulas.
                let (sn, cs) = sin_cos_turn::<R>(fraction(t / R::c(YEAR_DAYS)));
                let basis = [sn, cs, R::c(2.0) * sn * cs, cs * cs - sn * sn];
                for (o, c) in out.iter_mut().zip(coef.0.chunks_exact(16)) {
                    let mut v = R::zero();
                    for (b, cb) in basis.iter().zip(c.chunks_exact(4)) {
                        let x = f32::from_le_bytes([cb[0], cb[1], cb[2], cb[3]]);
                        v += R::c(x as f64) * *b;
                    }
                    *o += v;
                }
            }
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } => {
                if t >= R::c(epoch_day as f64) {
                    let i = station as usize;
                    for (k, off) in offset_mm.iter().enumerate() {
                        if let Some(o) = out.get_mut(k * s + i) {
                            *o += R::c(*off as f64);
                        }
                    }
                }
            }
            Effect::Drift { t0_day, rate } => {
                let years = (t - R::c(t0_day as f64)) / R::c(YEAR_DAYS);
                for (o, r) in out.iter_mut().zip(rate.iter()) {
                    *o += R::c(r as f64) * years;
                }
            }
            Effect::Illumination { .. } | Effect::BandOffset { .. } => {
                return Err(Error::InvalidModel(
                    "illumination and band offsets belong to RTM models, not to a GNSS network",
                ))
            }
        }
        Ok(())
    }

    /// Checks an effect of an RTM model with `n_bands` observed bands in `geometry`:
    /// [`Effect::Illumination`] with a site on Earth and an hour of the day (physical geometry
    /// only: the reference geometry hands INFORM cosines where angles are expected), or
    /// [`Effect::BandOffset`] with one finite offset (|offset| < 1) per band.
    pub fn validate_rtm(
        &self,
        n_bands: usize,
        geometry: crate::rtm::Geometry,
    ) -> Result<(), Error> {
        match *self {
            Effect::Illumination { .. } if geometry == crate::rtm::Geometry::Reference => {
                Err(Error::InvalidModel(ILLUMINATION_NEEDS_PHYSICAL))
            }
            Effect::BandOffset { offset }
                if offset.0.len() == 4 * n_bands && offset.iter().all(|v| v.abs() < 1.0) =>
            {
                Ok(())
            }
            Effect::BandOffset { .. } => Err(Error::InvalidModel(
                "band offsets: one per observed band, finite and below 1 in reflectance",
            )),
            Effect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            } if (-90.0..=90.0).contains(&lat_deg)
                && (-180.0..=360.0).contains(&lon_deg)
                && (0.0..=24.0).contains(&utc_hours)
                && view_azimuth_deg.is_finite() =>
            {
                Ok(())
            }
            Effect::Illumination { .. } => Err(Error::InvalidModel(
                "illumination: latitude, longitude, hour or view azimuth out of range",
            )),
            _ => Err(Error::InvalidModel(
                "RTM models declare only the illumination and band-offset effects",
            )),
        }
    }
}

/// Why an RTM model in the reference geometry cannot declare the illumination effect.
pub const ILLUMINATION_NEEDS_PHYSICAL: &str = "the illumination effect needs the physical geometry (the reference geometry hands INFORM cosines where angles are expected)";

/// Adds the [`Effect::BandOffset`]s of `effects` to an RTM model's bands `out` (the others leave
/// it unchanged).
pub fn rtm_add_offsets<R: Real>(effects: &[Effect<'_>], out: &mut [R]) -> Result<(), Error> {
    for e in effects {
        if let Effect::BandOffset { offset } = *e {
            if offset.0.len() != 4 * out.len() {
                return Err(Error::SizeMismatch {
                    what: "band offsets",
                    expected: out.len(),
                    found: offset.0.len() / 4,
                });
            }
            for (o, v) in out.iter_mut().zip(offset.iter()) {
                *o += R::c(v as f64);
            }
        }
    }
    Ok(())
}

/// The fixed INFORM inputs of an observation made on day `t_day`: `fixed` with the sun zenith
/// `tts` and the relative azimuth `psi` of every [`Effect::Illumination`] in `effects` (the
/// others leave it unchanged). A sun within 1° of the horizon or below is an error: no forest
/// spectrum is taken then.
///
/// ```
/// use magic_core::effects::{rtm_fixed_at, Effect};
/// use magic_core::rtm::Fixed;
/// let sun = Effect::Illumination { lat_deg: 47.5, lon_deg: 14.5, utc_hours: 10.0, view_azimuth_deg: 0.0 };
/// let day = magic_core::time::days_from_civil(2018, 10, 30) as f64;
/// let f = rtm_fixed_at(&[sun], &Fixed::default(), day).unwrap();
/// assert!(f.tts > 60.0 && f.tts < 66.0); // late October: a low sun, not the paper's 30°
/// assert_eq!(rtm_fixed_at(&[], &Fixed::default(), day).unwrap(), Fixed::default());
/// ```
pub fn rtm_fixed_at(
    effects: &[Effect<'_>],
    fixed: &crate::rtm::Fixed,
    t_day: f64,
) -> Result<crate::rtm::Fixed, Error> {
    let mut f = *fixed;
    for e in effects {
        if let Effect::Illumination {
            lat_deg,
            lon_deg,
            utc_hours,
            view_azimuth_deg,
        } = *e
        {
            if !t_day.is_finite() {
                return Err(Error::OutOfRange {
                    what: "date (the model has time-dependent effects)",
                });
            }
            let p = crate::sun::position(t_day, utc_hours as f64, lat_deg as f64, lon_deg as f64)?;
            if p.zenith_deg >= 89.0 {
                return Err(Error::OutOfRange {
                    what: "sun zenith of the acquisition (sun at or below the horizon)",
                });
            }
            f.tts = p.zenith_deg;
            f.psi = crate::sun::relative_azimuth(p.azimuth_deg, view_azimuth_deg as f64);
        }
    }
    Ok(f)
}

/// `x − ⌊x⌋` in `R`, exactly, by subtracting powers of two (Sterbenz: each subtraction is exact),
/// for |x| < 2³¹: no conversion to an integer, which in f32 would go through f64 (soft-float on
/// the board).
fn fraction<R: Real>(x: R) -> R {
    let neg = x < R::zero();
    let mut f = if neg { -x } else { x };
    for k in (0..31).rev() {
        let p = R::c((1u32 << k) as f64);
        if f >= p {
            f -= p;
        }
    }
    if neg && f > R::zero() {
        R::one() - f
    } else {
        f
    }
}

/// `sin(2πf)` and `cos(2πf)` for a fraction of a turn `f` in [0, 1), in `R`: the nearest quarter
/// turn is taken out, and the rest, |x| ≤ π/4, goes through the Taylor series
/// up to x¹⁷ / x¹⁸ (truncation below 1e-19), evaluated in `R`. No library call: on the board
/// (`R = f32`) libm's `sinf`/`cosf` would bring their f64 argument reduction (about 3 KB of
/// flash) for this one term; on the host (`R = f64`) the result is within a few ulps of libm's.
fn sin_cos_turn<R: Real>(f: R) -> (R, R) {
    // 1 / ((2k)(2k + 1)), k = 1..=8, and 1 / ((2k − 1)(2k)), k = 1..=9.
    const S: [f64; 8] = [
        1.0 / 6.0,
        1.0 / 20.0,
        1.0 / 42.0,
        1.0 / 72.0,
        1.0 / 110.0,
        1.0 / 156.0,
        1.0 / 210.0,
        1.0 / 272.0,
    ];
    const C: [f64; 9] = [
        1.0 / 2.0,
        1.0 / 12.0,
        1.0 / 30.0,
        1.0 / 56.0,
        1.0 / 90.0,
        1.0 / 132.0,
        1.0 / 182.0,
        1.0 / 240.0,
        1.0 / 306.0,
    ];
    // The nearest quarter turn, by comparisons (the bounds are exact in binary).
    let q = [0.125, 0.375, 0.625, 0.875]
        .iter()
        .filter(|&&b| f >= R::c(b))
        .count();
    let quarter = [0.0, 0.25, 0.5, 0.75, 1.0].get(q).copied().unwrap_or(0.0);
    let x = R::c(TWO_PI) * (f - R::c(quarter));
    let x2 = x * x;
    // Horner on x²: sin x = x (1 − x²/(2·3) (1 − x²/(4·5) (…))), cos x = 1 − x²/(1·2) (…).
    let mut s = R::one();
    for &k in S.iter().rev() {
        s = R::one() - x2 * s * R::c(k);
    }
    let mut c = R::one();
    for &k in C.iter().rev() {
        c = R::one() - x2 * c * R::c(k);
    }
    let s = x * s;
    match q % 4 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// F with effects: the Mogi field of `params[..4]` plus every effect, whose latent variables
/// follow in `params[4..]` in the order of `effects`.
pub fn mogi_with_effects<R: Real>(
    stations: &[Station],
    effects: &[Effect<'_>],
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    mogi_with_effects_of(stations, effects, params, t_day, out)
}

/// [`mogi_with_effects`] for any [`Network`] (e.g. the stations of a model file).
pub fn mogi_with_effects_of<R: Real, N: Network + ?Sized>(
    stations: &N,
    effects: &[Effect<'_>],
    params: &[R],
    t_day: f64,
    out: &mut [R],
) -> Result<(), Error> {
    let p: [R; mogi::N_PARAMS] = params
        .get(..mogi::N_PARAMS)
        .and_then(|s| s.try_into().ok())
        .ok_or(Error::SizeMismatch {
            what: "mogi parameters",
            expected: mogi::N_PARAMS,
            found: params.len(),
        })?;
    mogi::field_of(stations, &p, out)?;
    let mut k = mogi::N_PARAMS;
    for e in effects {
        let n = e.n_latent();
        let lat = params.get(k..k + n).ok_or(Error::SizeMismatch {
            what: "effect latent variables",
            expected: k + n,
            found: params.len(),
        })?;
        e.apply_to(stations, lat, t_day, out)?;
        k += n;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Dual;

    const NET: [Station; 2] = [
        Station {
            x_km: 1.0,
            y_km: 2.0,
            z_km: 0.3,
        },
        Station {
            x_km: -3.0,
            y_km: 0.5,
            z_km: 0.6,
        },
    ];

    #[test]
    fn latent_effects_are_linear_with_exact_derivatives() {
        let effects = [Effect::CommonMode, Effect::Elevation { z_ref_km: 0.45 }];
        let p: [Dual<8>; 8] =
            core::array::from_fn(|i| Dual::var([0.5, 0.1, 6.0, 1.0, 2.0, -1.0, 3.0, 10.0][i], i));
        let mut out = [Dual::<8>::c(0.0); 6];
        mogi_with_effects(&NET, &effects, &p, f64::NAN, &mut out).unwrap();
        // ∂u_E(station 0)/∂t_E = 1, ∂u_U(station 1)/∂k = z − z_ref = 0.15
        assert_eq!(out[0].d[4], 1.0);
        assert!((out[5].d[7] - 0.15).abs() < 1e-6);
    }

    #[test]
    fn fractions_of_a_year() {
        for x in [
            0.0,
            0.25,
            1.0,
            54.75,
            54.999_999,
            -0.25,
            -1.0,
            -3.5,
            1e6 + 0.5,
            16_777_215.0,
        ] {
            assert_eq!(fraction(x), x - libm::floor(x), "{x}");
            let x32 = x as f32;
            assert_eq!(fraction(x32), x32 - libm::floorf(x32), "{x}");
        }
    }

    #[test]
    fn seasonal_sine_and_cosine_match_libm() {
        let mut worst = 0f64;
        for i in 0..=4000 {
            let f = i as f64 / 4000.0 * 0.999_999_9;
            let (s, c) = sin_cos_turn::<f64>(f);
            let (s32, c32) = sin_cos_turn::<f32>(f as f32);
            let w = TWO_PI * f;
            worst = worst
                .max((s - libm::sin(w)).abs())
                .max((c - libm::cos(w)).abs());
            assert!(
                (s32 as f64 - libm::sin(w)).abs() < 3e-7
                    && (c32 as f64 - libm::cos(w)).abs() < 3e-7
            );
        }
        assert!(worst < 1e-15, "{worst:e}");
    }

    #[test]
    fn time_effects_need_a_date() {
        let rate = [0u8; 24];
        let e = Effect::Drift {
            t0_day: 0.0,
            rate: LeF32(&rate),
        };
        let mut out = [0.0f64; 6];
        assert!(e.apply(&NET, &[], f64::NAN, &mut out).is_err());
        assert!(e.apply(&NET, &[], 10.0, &mut out).is_ok());
        let step = Effect::Step {
            station: 1,
            epoch_day: 100.0,
            offset_mm: [1.0, 2.0, 3.0],
        };
        step.apply(&NET, &[], 99.0, &mut out).unwrap();
        assert_eq!(out, [0.0; 6]);
        step.apply(&NET, &[], 100.0, &mut out).unwrap();
        assert_eq!(out, [0.0, 1.0, 0.0, 2.0, 0.0, 3.0]);
        assert!(Effect::Step {
            station: 2,
            epoch_day: 0.0,
            offset_mm: [0.0; 3]
        }
        .validate(2)
        .is_err());
    }

    #[test]
    fn illumination_sets_the_sun_of_rtm_models_only() {
        let sun = Effect::Illumination {
            lat_deg: 47.5,
            lon_deg: 14.5,
            utc_hours: 10.0,
            view_azimuth_deg: 100.0,
        };
        assert!(sun.needs_time() && sun.n_latent() == 0);
        assert_eq!(sun.family(), "illumination");
        // Not a GNSS term.
        assert!(sun.validate(2).is_err());
        let mut out = [0.0f64; 6];
        assert!(sun.apply(&NET, &[], 14_000.0, &mut out).is_err());
        // An RTM term: the sun of the day, relative azimuth to the view.
        assert!(sun.validate_rtm(11, crate::rtm::Geometry::Physical).is_ok());
        assert!(Effect::CommonMode
            .validate_rtm(11, crate::rtm::Geometry::Physical)
            .is_err());
        let day = crate::time::days_from_civil(2018, 7, 2) as f64;
        let f = rtm_fixed_at(&[sun], &crate::rtm::Fixed::default(), day).unwrap();
        let p = crate::sun::position(day, 10.0, 47.5, 14.5).unwrap();
        assert_eq!(f.tts, p.zenith_deg);
        assert_eq!(f.psi, crate::sun::relative_azimuth(p.azimuth_deg, 100.0));
        assert_eq!(f.sd, crate::rtm::Fixed::default().sd);
        // Undated spectra, a site off the globe, night: errors.
        assert!(rtm_fixed_at(&[sun], &crate::rtm::Fixed::default(), f64::NAN).is_err());
        let night = Effect::Illumination {
            lat_deg: 47.5,
            lon_deg: 14.5,
            utc_hours: 23.0,
            view_azimuth_deg: 0.0,
        };
        assert!(rtm_fixed_at(&[night], &crate::rtm::Fixed::default(), day).is_err());
        let off = Effect::Illumination {
            lat_deg: 95.0,
            lon_deg: 14.5,
            utc_hours: 10.0,
            view_azimuth_deg: 0.0,
        };
        assert!(off
            .validate_rtm(11, crate::rtm::Geometry::Physical)
            .is_err());
    }

    #[test]
    fn band_offsets_add_to_rtm_bands() {
        let mut bytes = [0u8; 8];
        bytes[..4].copy_from_slice(&0.01f32.to_le_bytes());
        bytes[4..].copy_from_slice(&(-0.02f32).to_le_bytes());
        let e = Effect::BandOffset {
            offset: LeF32(&bytes),
        };
        assert!(!e.needs_time() && e.n_latent() == 0 && e.family() == "band_offset");
        assert!(e.validate_rtm(2, crate::rtm::Geometry::Physical).is_ok());
        assert!(e.validate_rtm(3, crate::rtm::Geometry::Physical).is_err());
        assert!(e.validate(2).is_err());
        let mut out = [0.1f64, 0.2];
        rtm_add_offsets(&[e], &mut out).unwrap();
        assert!((out[0] - 0.11).abs() < 1e-8 && (out[1] - 0.18).abs() < 1e-8);
        assert!(rtm_add_offsets(&[e], &mut [0.0f64; 3]).is_err());
        let mut big = [0u8; 8];
        big[..4].copy_from_slice(&2.0f32.to_le_bytes());
        assert!(Effect::BandOffset {
            offset: LeF32(&big)
        }
        .validate_rtm(2, crate::rtm::Geometry::Physical)
        .is_err());
    }
}
