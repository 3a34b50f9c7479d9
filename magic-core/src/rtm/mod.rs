//! Radiative transfer: PROSPECT-D leaf optics, 4SAIL canopy, INFORM forest, Sentinel-2 bands.
//!
//! * [`prospect`] — leaf reflectance and transmittance at one wavelength;
//! * [`sail`] — 4SAIL, split into per-geometry, per-LAI and per-wavelength work;
//! * [`inform`] — the forest model (understory, crowns, FLIM) in two geometry modes:
//!   [`Geometry::Reference`] reproduces the paper's implementation exactly,
//!   [`Geometry::Physical`] follows the published equations;
//! * [`sensor`] — band integration with a resampling matrix;
//! * [`model`] — the whole chain over borrowed tables: 21 inputs → 13 Sentinel-2 bands, with the
//!   exact Jacobian for the 7 learned variables;
//! * [`bands`] — the same model on the table rows a set of observed bands needs, from `f64`
//!   slices or a model file's `f32` bytes (what an exported RTM model carries).
//!
//! The spectral tables are inputs ([`Tables`]); this crate ships none.

pub mod bands;
pub mod inform;
pub mod model;
pub mod prosail;
pub mod prospect;
pub mod sail;
pub mod sensor;

pub use inform::Geometry;
pub use model::{
    inform_s2, inputs_from_learned, Fixed, Inform, Tables, INPUT_NAMES, LEARNED_BOUNDS,
    LEARNED_NAMES, N_BANDS, N_INPUTS, N_LEARNED,
};
pub use sensor::S2_BANDS;
