//! The classical baseline: per-observation nonlinear least squares for the Mogi source and the
//! latent variables of declared effects.
//!
//! For one day's observations y (mm; NaN = missing channel, left out) the fit minimises
//!
//! ```text
//! cost(p) = 1/m · Σ_c ((F(p)_c − y_c) / s_c)²      over the m observed channels c
//! ```
//!
//! where F is [`mogi_with_effects`](magic_core::effects::mogi_with_effects) and s the per-channel standardisation scale, so `cost` is the
//! paper's MSE of that day in standardised units. The unknowns are `p = [x, y, depth, ΔV]` followed
//! by the latent variables of the effects, inside box bounds.
//!
//! The solver is a projected Levenberg–Marquardt method:
//!
//! * the Jacobian is exact, from forward-mode [`Dual`] numbers through the same F the encoder
//!   models use (no finite differences);
//! * each step solves the damped normal equations `(JᵀJ + λ·D) δ = −Jᵀr` (D the diagonal of JᵀJ,
//!   Marquardt's scaling) with a fixed-size Cholesky factorisation ([`nalgebra::SMatrix`], at most
//!   [`MAX_UNKNOWNS`] unknowns, no allocation); a factorisation that fails raises λ instead;
//! * bounds: the trial point is projected onto the box, and unknowns sitting on a bound with the
//!   gradient pushing outwards are held fixed for that step (a simple active set), so a solution
//!   on a bound is reached and recognised as converged.
//!
//! F is linear in ΔV and in every latent variable of the effects; only x, y and depth are
//! nonlinear. [`fit_grid`] uses that for its start points: on a coarse grid over (x, y, depth) the
//! linear unknowns are solved exactly (one Gauss–Newton step), the best grid points are kept and
//! refined by Levenberg–Marquardt, and the best refinement wins.
//!
//! No function here panics on input: wrong sizes, non-finite values, empty or inverted bounds and
//! too few observed channels are [`Error`](magic_core::Error)s; singular normal equations are damped.

mod grid;
mod normal;
mod problem;
mod solver;
#[cfg(test)]
mod tests;

pub use grid::{fit_grid, Grid};
pub use problem::{cost, Problem};
pub use solver::{fit, Fit, Options};

use magic_core::Dual;
use nalgebra::{SMatrix, SVector};

/// Largest number of unknowns (4 source parameters plus the effects' latent variables).
pub const MAX_UNKNOWNS: usize = 8;

/// Largest number of grid points [`fit_grid`] refines.
pub const MAX_KEEP: usize = 8;

type Mat = SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>;
type Vector = SVector<f64, MAX_UNKNOWNS>;
type D = Dual<MAX_UNKNOWNS>;
