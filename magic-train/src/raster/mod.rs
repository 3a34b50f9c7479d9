//! Maps from Sentinel-2 images: GeoTIFF in, GeoTIFF out (`magic map`).
//!
//! * [`reader`] — a TIFF read by windows of rows, chunk by chunk (any layout the `tiff` crate
//!   decodes, band-interleaved included);
//! * [`input`] — the model's bands from one multi-band file or a folder of single-band files, as
//!   reflectance;
//! * [`scl`] — the L2A scene classification as a mask;
//! * [`geo`] — the GeoTIFF georeferencing tags, copied from the input to the map;
//! * [`writer`] — a streaming TIFF writer (strips appended as rows arrive, deflated in parallel);
//! * [`pixel`] — one pixel: `magic invert`'s columns and the standard deviations;
//! * [`calibrate`] — calibration of the standard deviations on synthetic spectra;
//! * [`map`] — the pipeline, window by window, in parallel;
//! * [`preview`] — a PNG of one band.

pub mod calibrate;
pub mod geo;
pub mod input;
pub mod map;
pub mod pixel;
pub mod preview;
pub mod reader;
pub mod scl;
pub mod writer;

/// The `tiff` crate the reader uses (for callers that make or inspect TIFF files with it).
pub use tiff;
