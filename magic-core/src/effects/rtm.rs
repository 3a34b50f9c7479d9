//! The forest-spectra effects: the sun of each acquisition ([`Effect::Illumination`], which
//! changes INFORM's fixed inputs) and a constant offset per band ([`Effect::BandOffset`]).

use super::Effect;
use crate::rtm::{Fixed, Geometry};
use crate::Real;
use crate::{EffectFault, Error};

impl Effect<'_> {
    /// Checks an effect of an RTM model with `n_bands` observed bands in `geometry`:
    /// [`Effect::Illumination`] with a site on Earth and an hour of the day (physical geometry
    /// only: the reference geometry hands INFORM cosines where angles are expected), or
    /// [`Effect::BandOffset`] with one finite offset (|offset| < 1) per band.
    pub fn validate_rtm(&self, n_bands: usize, geometry: Geometry) -> Result<(), Error> {
        match *self {
            Effect::Illumination { .. } if geometry == Geometry::Reference => {
                Err(self.invalid(EffectFault::NeedsPhysicalGeometry))
            }
            Effect::BandOffset { offset }
                if offset.0.len() == 4 * n_bands && offset.iter().all(|v| v.abs() < 1.0) =>
            {
                Ok(())
            }
            Effect::BandOffset { .. } => Err(self.invalid(EffectFault::Parameters)),
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
            Effect::Illumination { .. } => Err(self.invalid(EffectFault::Parameters)),
            _ => Err(self.invalid(EffectFault::NotRtm)),
        }
    }
}

/// Why an RTM model in the reference geometry cannot declare the illumination effect (the long
/// form of [`EffectFault::NeedsPhysicalGeometry`]).
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
pub fn rtm_fixed_at(effects: &[Effect<'_>], fixed: &Fixed, t_day: f64) -> Result<Fixed, Error> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mogi::Station;
    use crate::quant::LeF32;

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
        assert!(sun.validate_rtm(11, Geometry::Physical).is_ok());
        assert!(Effect::CommonMode
            .validate_rtm(11, Geometry::Physical)
            .is_err());
        let day = crate::time::days_from_civil(2018, 7, 2) as f64;
        let f = rtm_fixed_at(&[sun], &Fixed::default(), day).unwrap();
        let p = crate::sun::position(day, 10.0, 47.5, 14.5).unwrap();
        assert_eq!(f.tts, p.zenith_deg);
        assert_eq!(f.psi, crate::sun::relative_azimuth(p.azimuth_deg, 100.0));
        assert_eq!(f.sd, Fixed::default().sd);
        // Undated spectra, a site off the globe, night: errors.
        assert!(rtm_fixed_at(&[sun], &Fixed::default(), f64::NAN).is_err());
        let night = Effect::Illumination {
            lat_deg: 47.5,
            lon_deg: 14.5,
            utc_hours: 23.0,
            view_azimuth_deg: 0.0,
        };
        assert!(rtm_fixed_at(&[night], &Fixed::default(), day).is_err());
        let off = Effect::Illumination {
            lat_deg: 95.0,
            lon_deg: 14.5,
            utc_hours: 10.0,
            view_azimuth_deg: 0.0,
        };
        assert!(off.validate_rtm(11, Geometry::Physical).is_err());
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
        assert!(e.validate_rtm(2, Geometry::Physical).is_ok());
        assert!(e.validate_rtm(3, Geometry::Physical).is_err());
        assert!(e.validate(2).is_err());
        let mut out = [0.1f64, 0.2];
        rtm_add_offsets(&[e], &mut out).unwrap();
        // Up to the f32 rounding of the offsets (half an ulp of 0.02 is 9.3e-10) and of the sums.
        let rounding = 0.02 * f32::EPSILON as f64 / 2.0 + 4.0 * f64::EPSILON;
        assert!((out[0] - 0.11).abs() <= rounding && (out[1] - 0.18).abs() <= rounding);
        assert!(rtm_add_offsets(&[e], &mut [0.0f64; 3]).is_err());
        let mut big = [0u8; 8];
        big[..4].copy_from_slice(&2.0f32.to_le_bytes());
        assert!(Effect::BandOffset {
            offset: LeF32(&big)
        }
        .validate_rtm(2, Geometry::Physical)
        .is_err());
    }
}
