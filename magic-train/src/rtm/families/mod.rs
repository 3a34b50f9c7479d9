//! The forest-spectra effect families, one type per file; [`all`] registers them (one line each).

pub mod band_offset;
pub mod illumination;
mod offsets;
pub mod species;

use crate::analysis::DynFamily;
use crate::rtm::residuals::SpectraResiduals;

/// Every forest-spectra family, in report order.
pub fn all() -> Vec<Box<dyn DynFamily<SpectraResiduals>>> {
    vec![
        Box::new(illumination::Illumination),
        Box::new(band_offset::BandOffset),
        Box::new(species::Species),
    ]
}
