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
//! Every term is generic over [`Real`](crate::Real) so the trainer differentiates through it exactly and the
//! board evaluates it in f32. Times are day numbers (days since 1970-01-01, see [`crate::time`]).
//!
//! [`gnss`] holds the GNSS terms (checks, evaluation, F with effects), [`rtm`] the forest-spectra
//! ones; the functions of both are re-exported here.

pub mod gnss;
pub mod rtm;

pub use gnss::{dated_part_of, mogi_terms_of, mogi_with_effects};
pub use rtm::{rtm_add_offsets, rtm_fixed_at, ILLUMINATION_NEEDS_PHYSICAL};

use crate::quant::LeF32;
use crate::{EffectFault, Error};
use serde::{Deserialize, Serialize};

/// Largest number of effects in one model.
pub const MAX_EFFECTS: usize = 4;

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

    /// Whether the effect is a dated term: a function of the date alone that holds a date of its
    /// own and moves the series for good from it (a step from its epoch, a drift from its t0). A
    /// variant-C model corrects F without these terms and adds them after C
    /// ([`crate::invert::model_correction`]): C is fitted over the training years, and a term that
    /// leaves their range (a drift that keeps growing, a step after them) would take C's input
    /// where it was never fitted. Annual terms come back every year, so the training years hold
    /// their whole range: they stay in C's input, where C can correct their declared shape.
    pub fn is_dated(&self) -> bool {
        matches!(self, Effect::Step { .. } | Effect::Drift { .. })
    }

    /// [`Error::InvalidEffect`] for this effect.
    pub fn invalid(&self, fault: EffectFault) -> Error {
        Error::InvalidEffect {
            family: self.family(),
            fault,
        }
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
}
