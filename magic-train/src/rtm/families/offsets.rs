//! The least-squares constant offset per band in the projected space shared by `band_offset`
//! and `species`: `(Σ Pᵢ)⁻¹ Σ Pᵢ rᵢ` over spectra (a pseudo-inverse: directions every
//! spectrum's F can fit have no offset to find), scored by its projected prediction on the
//! held-out spectra.

use super::super::residuals::Spectrum;
use crate::analysis::score::share;
use nalgebra::{DMatrix, DVector};

/// Constant offset per band over `spectra` with weights `w` (±1 for sign surrogates); `None`
/// when there are no spectra.
pub fn offset(spectra: &[&Spectrum], w: &[f64], nb: usize) -> Option<Vec<f64>> {
    if spectra.is_empty() {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(nb, nb);
    let mut b = DVector::<f64>::zeros(nb);
    for (s, &wi) in spectra.iter().zip(w) {
        for i in 0..nb {
            a[(i, i)] += 1.0;
            b[i] += wi * s.r[i];
        }
        for c in &s.q {
            for i in 0..nb {
                for j in 0..nb {
                    a[(i, j)] -= c[i] * c[j];
                }
            }
        }
    }
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    let x = svd.solve(&b, 1e-3 * smax).ok()?;
    Some(x.iter().copied().collect())
}

/// Share of the held-out projected residual variance predicted by per-group offsets
/// (`group(i)`: the offset of held-out spectrum i, or none).
pub fn held_share<'a>(
    held: &[Spectrum],
    nb: usize,
    offset_of: &dyn Fn(usize) -> Option<&'a [f64]>,
) -> f64 {
    let r: Vec<&[f64]> = held.iter().map(|s| s.r.as_slice()).collect();
    let p: Vec<Vec<f64>> = held
        .iter()
        .enumerate()
        .map(|(i, s)| match offset_of(i) {
            Some(b) => s.project(b),
            None => vec![0.0; nb],
        })
        .collect();
    share(&r, &p)
}
