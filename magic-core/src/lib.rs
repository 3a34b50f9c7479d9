//! # magic-core
//!
//! The embedded heart of **magic**: physical forward models, quantised networks, the model file and
//! the inversion, in `no_std` Rust with no allocator.
//!
//! Observations X go through an encoder E to physical variables Z, a physical forward model F
//! rebuilds X, and a small correction C absorbs systematic bias: X ≈ C(F(E(X))). The same code runs
//! on a Cortex-M4F (f32), on the host (f64) and in training (exact derivatives through [`Dual`]).
//!
//! * [`real`] — the scalar trait the physics is written against (f32, f64, dual numbers) and the
//!   numerical functions it needs, one per file with test vectors and a stated error (E1, the
//!   sine and cosine of a turn, the square root);
//! * [`mogi`] — the Mogi point source for a GNSS network;
//! * [`rtm`] — PROSPECT-D, 4SAIL, INFORM and Sentinel-2 band integration;
//! * [`quant`] and [`nn`] — int8 / f32 dense layers and the MLPs built from them;
//! * [`model_file`] — the exported model, decoded without allocation;
//! * [`sun`] — the sun's zenith and azimuth from date, time and place (illumination geometry);
//! * [`invert`](mod@invert) — observations to variables, reconstruction, residual and quality flags.
//! * [`uncertainty`] — standard deviations of the inverted variables (local curvature at the
//!   solution, exact Jacobian).
#![no_std]
#![deny(missing_docs)]
// `unsafe` is denied everywhere except the Armv7E-M int8 kernel (`quant::dsp`, feature `dsp`,
// ARM only), whose inline assembly cuts an inversion on a Cortex-M4F from 176 k to 99 k executed
// instructions (measured under QEMU; see `quant::dsp`).
#![deny(unsafe_code)]

pub mod effects;
pub mod error;
pub mod mogi;
pub mod real;
pub mod rtm;
pub mod sun;
pub mod time;
pub mod uncertainty;

pub use error::{BoundFault, EffectFault, Error, LayerArray, LayerFault, MessageSink, Net};
pub use real::{Dual, Real};
pub mod invert;
pub mod line;
pub mod model_file;
pub mod nn;
pub mod quant;

pub use invert::{invert, invert_at, Flags, Inversion, Workspace};
pub use model_file::{Model, Problem, Variant};
