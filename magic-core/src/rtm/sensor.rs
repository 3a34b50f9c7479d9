//! Band integration: a sensor's spectral response as a resampling matrix.
//!
//! Band `b` of a spectrum `R(λ)` sampled on the model's wavelength grid is
//! `Σ_λ M[λ, b]·R(λ)`, with `M` a borrowed `n_wavelengths × n_bands` row-major matrix whose columns
//! sum to 1 (`sentinel2_full_resampling_matrix.csv` for Sentinel-2). Most of `M` is zero, so
//! [`Resampling::new`] records the wavelength spans where any band has weight and the model is
//! evaluated only there (884 of 2101 wavelengths for Sentinel-2), and each band's first and last
//! wavelength with weight: a batch of wavelengths evaluated together (lanes) is added only to the
//! bands it meets (one or two of the 13 for most batches), lane by lane.

use crate::real::{Lanes, Real};
use crate::Error;

/// Sentinel-2 band names in the order of the resampling matrix's columns.
pub const S2_BANDS: [&str; 13] = [
    "B01", "B02", "B03", "B04", "B05", "B06", "B07", "B08", "B8A", "B09", "B10", "B11", "B12",
];

/// Largest number of bands a [`Resampling`] handles.
pub const MAX_BANDS: usize = 16;

/// A resampling matrix with the wavelength spans where it is non-zero.
#[derive(Clone, Copy, Debug)]
pub struct Resampling<'a> {
    matrix: &'a [f64],
    n_wl: usize,
    n_bands: usize,
    spans: [(usize, usize); MAX_BANDS],
    n_spans: usize,
    /// Per band: first and last wavelength index with weight (`(1, 0)` for a band without).
    ranges: [(usize, usize); MAX_BANDS],
}

impl<'a> Resampling<'a> {
    /// Wraps `matrix` (`n_wl × n_bands`, row-major). Fails when the length does not match, a
    /// weight is not finite, or `n_bands` is 0 or above [`MAX_BANDS`].
    pub fn new(matrix: &'a [f64], n_wl: usize, n_bands: usize) -> Result<Self, Error> {
        if n_bands == 0 || n_bands > MAX_BANDS {
            return Err(Error::OutOfRange {
                what: "number of sensor bands",
            });
        }
        if matrix.len() != n_wl * n_bands {
            return Err(Error::SizeMismatch {
                what: "resampling matrix",
                expected: n_wl * n_bands,
                found: matrix.len(),
            });
        }
        if let Some(i) = matrix.iter().position(|w| !w.is_finite()) {
            return Err(Error::NonFinite {
                what: "resampling matrix",
                index: i,
            });
        }
        // Per band: first and last wavelength with non-zero weight.
        let ranges = band_ranges(n_wl, n_bands, |i, b| matrix[i * n_bands + b]);
        // Sort the band ranges by start and merge overlapping or adjacent ones.
        let mut list = [(usize::MAX, 0usize); MAX_BANDS];
        let mut n = 0;
        for r in ranges[..n_bands].iter().filter(|r| r.0 <= r.1) {
            list[n] = *r;
            n += 1;
        }
        list[..n].sort_unstable();
        let mut spans = [(0usize, 0usize); MAX_BANDS];
        let mut n_spans = 0;
        for &(a, b) in &list[..n] {
            if n_spans > 0 && a <= spans[n_spans - 1].1 + 1 {
                let last = &mut spans[n_spans - 1];
                last.1 = last.1.max(b);
            } else {
                spans[n_spans] = (a, b);
                n_spans += 1;
            }
        }
        Ok(Resampling {
            matrix,
            n_wl,
            n_bands,
            spans,
            n_spans,
            ranges,
        })
    }

    /// Number of bands.
    pub fn n_bands(&self) -> usize {
        self.n_bands
    }

    /// Number of wavelengths of the grid.
    pub fn n_wavelengths(&self) -> usize {
        self.n_wl
    }

    /// Inclusive wavelength-index spans where some band has weight.
    pub fn spans(&self) -> &[(usize, usize)] {
        &self.spans[..self.n_spans]
    }

    /// The weights of wavelength index `i` (one per band).
    #[inline]
    pub fn weights(&self, i: usize) -> &[f64] {
        &self.matrix[i * self.n_bands..(i + 1) * self.n_bands]
    }

    /// Number of wavelengths where some band has weight.
    pub fn n_active(&self) -> usize {
        self.active().count()
    }

    fn check_out<R>(&self, out: &[R]) -> Result<(), Error> {
        crate::error::check_len("band output", self.n_bands, out.len())
    }

    /// The wavelength indices where some band has weight, in ascending order.
    pub fn active(&self) -> impl Iterator<Item = usize> + '_ {
        self.spans()
            .iter()
            .flat_map(|&(a, b)| a..=b)
            .filter(|&i| self.weights(i).iter().any(|&w| w != 0.0))
    }

    /// Adds the value `r` at wavelength index `i`, weighted, to each band of `out`.
    #[inline]
    pub fn accumulate<R: Real>(&self, i: usize, r: R, out: &mut [R]) {
        for (o, &wb) in out.iter_mut().zip(self.weights(i)) {
            if wb != 0.0 {
                *o += r.scale(<R::Plain as Real>::c(wb));
            }
        }
    }

    /// Integrates a spectrum given as a function of the wavelength index, evaluating it only
    /// where some band has weight; `out` (length `n_bands`) receives the band values.
    pub fn integrate<R: Real>(
        &self,
        mut spectrum: impl FnMut(usize) -> R,
        out: &mut [R],
    ) -> Result<(), Error> {
        self.check_out(out)?;
        out.iter_mut().for_each(|o| *o = R::zero());
        for i in self.active() {
            self.accumulate(i, spectrum(i), out);
        }
        Ok(())
    }

    /// [`Resampling::integrate`] with the spectrum evaluated `W::WIDTH` consecutive wavelengths
    /// at a time: `spectrum(i0)` returns lanes whose lane `j` is the value at wavelength index
    /// `i0 + j`. Runs start at the beginning of each span of [`Resampling::spans`], so a span's
    /// last run may reach past it (or past the grid, which the caller clamps); those lanes are
    /// ignored, as are wavelengths without weight. The bands are summed lane by lane
    /// (each band keeps lanes of partial sums), so the order of the additions differs from
    /// [`Resampling::integrate`]'s.
    pub fn integrate_lanes<R: Real, W: Lanes<R>>(
        &self,
        mut spectrum: impl FnMut(usize) -> W,
        out: &mut [R],
    ) -> Result<(), Error> {
        self.check_out(out)?;
        let mut sums = BandSums::<W>::new(&self.ranges[..self.n_bands]);
        for &(a, b) in self.spans() {
            for i0 in (a..=b).step_by(W::WIDTH.max(1)) {
                sums.add(i0, b, spectrum(i0), |i, band| {
                    self.matrix[i * self.n_bands + band]
                });
            }
        }
        sums.finish(out);
        Ok(())
    }

    /// Integrates a full spectrum (`n_wavelengths` values).
    pub fn integrate_slice<R: Real>(&self, spectrum: &[R], out: &mut [R]) -> Result<(), Error> {
        if spectrum.len() != self.n_wl {
            return Err(Error::SizeMismatch {
                what: "spectrum",
                expected: self.n_wl,
                found: spectrum.len(),
            });
        }
        self.integrate(|i| spectrum[i], out)
    }
}

/// Per band: the first and last of `n_rows` rows whose weight `weight(row, band)` is not zero
/// (`(1, 0)` for a band without), for bands `0..n_bands` (at most [`MAX_BANDS`]).
pub(crate) fn band_ranges(
    n_rows: usize,
    n_bands: usize,
    weight: impl Fn(usize, usize) -> f64,
) -> [(usize, usize); MAX_BANDS] {
    let mut ranges = [(1usize, 0usize); MAX_BANDS];
    for (b, r) in ranges.iter_mut().enumerate().take(n_bands) {
        if let Some(first) = (0..n_rows).find(|&i| weight(i, b) != 0.0) {
            let last = (first..n_rows).rev().find(|&i| weight(i, b) != 0.0);
            *r = (first, last.unwrap_or(first));
        }
    }
    ranges
}

/// Band values accumulated from batches of lanes: each band keeps lanes of partial sums, to
/// which a batch of rows `i0, i0 + 1, …` is added weighted when it meets the band's row range;
/// [`BandSums::finish`] sums the lanes. Lanes with zero weight add nothing (a NaN value in a
/// band's range makes the band NaN).
pub(crate) struct BandSums<'r, W> {
    ranges: &'r [(usize, usize)],
    acc: [W; MAX_BANDS],
}

impl<'r, W: Real> BandSums<'r, W> {
    /// Zero sums for bands with row ranges `ranges` (at most [`MAX_BANDS`]).
    #[inline(always)]
    pub(crate) fn new(ranges: &'r [(usize, usize)]) -> Self {
        BandSums {
            ranges,
            acc: [W::zero(); MAX_BANDS],
        }
    }

    /// Adds the lanes `v` of rows `i0, i0 + 1, …` (those after `last` are not rows of this
    /// run and are left out), weighted by `weight(row, band)`, to the bands they meet.
    #[inline(always)]
    pub(crate) fn add<R: Real>(
        &mut self,
        i0: usize,
        last: usize,
        v: W,
        weight: impl Fn(usize, usize) -> f64,
    ) where
        W: Lanes<R>,
    {
        let end = last.min(i0 + W::WIDTH - 1);
        for b in 0..self.ranges.len().min(MAX_BANDS) {
            let (lo, hi) = self.ranges[b];
            if lo > end || hi < i0 {
                continue;
            }
            let (from, to) = (lo.max(i0), hi.min(end));
            let w = W::plain_from_fn(|j| {
                let i = i0 + j;
                if i >= from && i <= to {
                    weight(i, b)
                } else {
                    0.0
                }
            });
            self.acc[b] += v.scale(w);
        }
    }

    /// The band values (one per range): each band's lanes summed.
    #[inline(always)]
    pub(crate) fn finish<R: Real>(&self, out: &mut [R])
    where
        W: Lanes<R>,
    {
        for (o, acc) in out.iter_mut().zip(&self.acc) {
            let mut s = acc.lane(0);
            for j in 1..W::WIDTH {
                s += acc.lane(j);
            }
            *o = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::F64x4;

    #[test]
    fn spans_and_integration() {
        // 6 wavelengths, 2 bands: band 0 on 1..=2, band 1 on 4..=4.
        let m = [0.0, 0.0, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let r = Resampling::new(&m, 6, 2).unwrap();
        assert_eq!(r.spans(), &[(1, 2), (4, 4)]);
        assert_eq!(r.n_active(), 3);
        let mut calls = 0;
        let mut out = [0.0; 2];
        r.integrate(
            |i| {
                calls += 1;
                i as f64
            },
            &mut out,
        )
        .unwrap();
        assert_eq!(calls, 3);
        assert_eq!(out, [1.5, 4.0]);
        let mut out2 = [0.0; 2];
        r.integrate_slice(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], &mut out2)
            .unwrap();
        assert_eq!(out, out2);
        let mut out3 = [0.0; 2];
        r.integrate_lanes(|i| i as f64, &mut out3).unwrap();
        assert_eq!(out, out3);
        // Runs of four from the start of each span: 1..=4 and 4..=7 (lanes past the spans and
        // the grid are evaluated but ignored).
        let mut out4 = [0.0; 2];
        let mut starts = [0; 2];
        let mut batches = 0;
        r.integrate_lanes(
            |i0| {
                starts[batches] = i0;
                batches += 1;
                F64x4::new(core::array::from_fn(|j| (i0 + j) as f64))
            },
            &mut out4,
        )
        .unwrap();
        assert_eq!((out, batches, starts), (out4, 2, [1, 4]));
    }

    #[test]
    fn size_errors() {
        let m = [0.0; 12];
        assert!(Resampling::new(&m, 5, 2).is_err());
        assert!(Resampling::new(&m, 12, 0).is_err());
        assert!(Resampling::new(&[f64::NAN, 1.0], 1, 2).is_err());
        let r = Resampling::new(&m, 6, 2).unwrap();
        assert!(r.integrate(|_| 0.0, &mut [0.0; 3]).is_err());
        assert!(r.integrate_slice(&[0.0; 5], &mut [0.0; 2]).is_err());
    }
}
