//! Declared effects owned by the host: the trainer's copy of `magic_core::effects::Effect`, with
//! the bytes the core's view borrows.

use super::le_f32_bytes;
use magic_core::effects::Effect;
use magic_core::quant::LeF32;

/// A declared effect owned by the host (see `magic_core::effects::Effect`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "family", rename_all = "snake_case")]
pub enum OwnedEffect {
    /// Daily network translation (3 latent variables).
    CommonMode,
    /// Vertical term linear in elevation (1 latent variable).
    Elevation {
        /// Reference elevation (km).
        z_ref_km: f32,
    },
    /// Second Mogi source at a fixed position (1 latent variable: its ΔV).
    SecondSource {
        /// East (km).
        x_km: f32,
        /// North (km).
        y_km: f32,
        /// Depth (km).
        depth_km: f32,
    },
    /// Per-channel annual + semiannual coefficients (4 per channel).
    Seasonal {
        /// Coefficients (mm).
        coef: Vec<f32>,
    },
    /// A step at one station.
    Step {
        /// Station index.
        station: u16,
        /// First day with the offset.
        epoch_day: f32,
        /// Offset (mm, E N U).
        offset_mm: [f32; 3],
    },
    /// Per-channel drift.
    Drift {
        /// Reference day.
        t0_day: f32,
        /// Rates (mm/yr).
        rate: Vec<f32>,
    },
    /// RTM: each spectrum's true sun from its date (see `magic_core::effects`).
    Illumination {
        /// Site latitude (degrees north).
        lat_deg: f32,
        /// Site longitude (degrees east).
        lon_deg: f32,
        /// Acquisition time (hours UTC).
        utc_hours: f32,
        /// Sensor view azimuth (degrees).
        view_azimuth_deg: f32,
    },
    /// RTM: a constant reflectance per observed band.
    BandOffset {
        /// Offsets (reflectance), one per observed band.
        offset: Vec<f32>,
    },
}

impl OwnedEffect {
    /// Little-endian bytes of the effect's arrays (empty for effects without arrays).
    pub fn bytes(&self) -> Vec<u8> {
        match self {
            OwnedEffect::Seasonal { coef } => le_f32_bytes(coef),
            OwnedEffect::Drift { rate, .. } => le_f32_bytes(rate),
            OwnedEffect::BandOffset { offset } => le_f32_bytes(offset),
            _ => vec![],
        }
    }

    /// The core's view, borrowing `bytes` (from [`OwnedEffect::bytes`]).
    pub fn borrow<'a>(&self, bytes: &'a [u8]) -> Effect<'a> {
        match *self {
            OwnedEffect::CommonMode => Effect::CommonMode,
            OwnedEffect::Elevation { z_ref_km } => Effect::Elevation { z_ref_km },
            OwnedEffect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            },
            OwnedEffect::Seasonal { .. } => Effect::Seasonal { coef: LeF32(bytes) },
            OwnedEffect::Step {
                station,
                epoch_day,
                offset_mm,
            } => Effect::Step {
                station,
                epoch_day,
                offset_mm,
            },
            OwnedEffect::Drift { t0_day, .. } => Effect::Drift {
                t0_day,
                rate: LeF32(bytes),
            },
            OwnedEffect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            } => Effect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            },
            OwnedEffect::BandOffset { .. } => Effect::BandOffset {
                offset: LeF32(bytes),
            },
        }
    }

    /// Copies a core effect.
    pub fn from_core(e: &Effect<'_>) -> OwnedEffect {
        match *e {
            Effect::CommonMode => OwnedEffect::CommonMode,
            Effect::Elevation { z_ref_km } => OwnedEffect::Elevation { z_ref_km },
            Effect::SecondSource {
                x_km,
                y_km,
                depth_km,
            } => OwnedEffect::SecondSource {
                x_km,
                y_km,
                depth_km,
            },
            Effect::Seasonal { coef } => OwnedEffect::Seasonal {
                coef: coef.iter().collect(),
            },
            Effect::Step {
                station,
                epoch_day,
                offset_mm,
            } => OwnedEffect::Step {
                station,
                epoch_day,
                offset_mm,
            },
            Effect::Drift { t0_day, rate } => OwnedEffect::Drift {
                t0_day,
                rate: rate.iter().collect(),
            },
            Effect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            } => OwnedEffect::Illumination {
                lat_deg,
                lon_deg,
                utc_hours,
                view_azimuth_deg,
            },
            Effect::BandOffset { offset } => OwnedEffect::BandOffset {
                offset: offset.iter().collect(),
            },
        }
    }

    /// Number of latent variables.
    pub fn n_latent(&self) -> usize {
        self.borrow(&[]).n_latent()
    }

    /// Family name.
    pub fn family(&self) -> &'static str {
        self.borrow(&[]).family()
    }

    /// The first day (days since 1970-01-01) on which the term can differ from zero, for an
    /// effect with an onset (a step); `None` for one that acts on every row.
    pub fn onset_day(&self) -> Option<f64> {
        match self {
            OwnedEffect::Step { epoch_day, .. } => Some(*epoch_day as f64),
            _ => None,
        }
    }

    /// Whether `other` is the same term of F: two second sources less than [`SAME_SOURCE_KM`]
    /// apart horizontally (a source's depth is the least resolved of its coordinates), two steps
    /// at one station less than [`SAME_STEP_DAYS`] apart, any two other effects of one family.
    /// Sources farther apart and steps elsewhere or at other times are other terms.
    pub fn same_term(&self, other: &OwnedEffect) -> bool {
        match (self, other) {
            (
                OwnedEffect::SecondSource { x_km, y_km, .. },
                OwnedEffect::SecondSource {
                    x_km: x, y_km: y, ..
                },
            ) => f64::from(x_km - x).hypot(f64::from(y_km - y)) < SAME_SOURCE_KM,
            (
                OwnedEffect::Step {
                    station, epoch_day, ..
                },
                OwnedEffect::Step {
                    station: s,
                    epoch_day: e,
                    ..
                },
            ) => station == s && f64::from(epoch_day - e).abs() < SAME_STEP_DAYS,
            _ => self.family() == other.family(),
        }
    }
}

/// Horizontal distance (km) within which a second source found again is the one F declares:
/// the synthetic recovery check's position tolerance, within which a located source is the
/// injected one.
pub const SAME_SOURCE_KM: f64 = 2.0;

/// Days within which a step found again at a station is the one F declares there: the step
/// scan's margin ([`STEP_SCAN_DAYS`](crate::gnss::families::step::STEP_SCAN_DAYS)), the days a
/// step needs on each side to be told from the noise, and so from another step.
pub const SAME_STEP_DAYS: f64 = 30.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn step(station: u16, epoch_day: f32) -> OwnedEffect {
        OwnedEffect::Step {
            station,
            epoch_day,
            offset_mm: [1.0, 0.0, 5.0],
        }
    }

    #[test]
    fn steps_are_one_term_at_one_station_and_time() {
        assert!(step(2, 15_000.0).same_term(&step(2, 15_012.0)));
        assert!(!step(2, 15_000.0).same_term(&step(2, 15_200.0)));
        assert!(!step(2, 15_000.0).same_term(&step(3, 15_000.0)));
        assert!(!step(2, 15_000.0).same_term(&OwnedEffect::CommonMode));
        assert!(OwnedEffect::CommonMode.same_term(&OwnedEffect::CommonMode));
    }
}
