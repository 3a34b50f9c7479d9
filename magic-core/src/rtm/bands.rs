//! INFORM on the table rows a set of observed bands needs, from `f64` slices (host) or from the
//! little-endian `f32` bytes of a model file (board).
//!
//! A model file cannot carry the 2101-wavelength tables of [`Tables`] (213 KiB in f32 with
//! the full resampling matrix) and does not need to: a band only sees the wavelengths
//! where its spectral response is non-zero. [`Packed`] keeps, for each such wavelength in
//! ascending order, one *spectral row* of [`ROW_WIDTH`] values
//!
//! ```text
//! nr k_cab k_car k_anth k_brown k_cw k_cm t12 tav90n | soil_dry soil_wet | es ed
//! ```
//!
//! and one *weight row* (the resampling weights of the observed bands, in band order), plus the
//! beta leaf-angle table (13 angles × rows, angle-major as in `lidf_tables.csv`). For the 11 bands
//! of the S2 dataset that is 798 rows, 75 KiB in f32.
//!
//! [`Packed::forward`] evaluates exactly what [`Inform::forward`] does, restricted to these rows,
//! in any [`Real`] (`f32` on the board), without allocation; [`Packed::jacobian`] is the
//! split-chain-rule Jacobian of [`Inform::jacobian`] for the learned variables.

use super::inform::{Geometry, Scene, SpectralRow};
use super::model::{
    inputs_from_learned, Fixed, Inform, JacobianLanes, LearnedJacobian, Tables, N_BANDS, N_INPUTS,
    N_LEARNED,
};
use super::prospect::{CoefRow, Coefficients};
use super::sail::LITAB_DEG;
use super::sensor::BandSums;
use crate::quant::LeF32;
use crate::real::{Dual, DualScalar, Lanes, Real};
use crate::Error;

/// Values per spectral row (9 PROSPECT-D coefficients, 2 soil spectra, 2 irradiances).
pub const ROW_WIDTH: usize = 13;

/// Largest number of beta leaf-angle distributions (table rows) a packed model carries.
pub const MAX_BETA_ROWS: usize = 8;

/// Largest number of spectral rows (the whole 1 nm grid from 400 to 2500 nm).
pub const MAX_ROWS: usize = 2101;

/// Where the packed numbers live: `f64` slices or little-endian `f32` bytes.
pub trait Values: Copy {
    /// Number of values.
    fn len(&self) -> usize;
    /// Whether empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Value `i` (0 past the end; lengths are checked by [`Packed::new`]).
    fn at(&self, i: usize) -> f64;
    /// Whether every value is finite (the first that is not: found with [`Values::at`]).
    fn all_finite(&self) -> bool {
        (0..self.len()).all(|i| self.at(i).is_finite())
    }
    /// Values `start..start + out.len()` into `out` (0 past the end).
    #[inline]
    fn copy_to(&self, start: usize, out: &mut [f64]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.at(start + i);
        }
    }
    /// Values `start..start + len` as an `f64` slice, when they are stored as one (not for
    /// `f32` bytes).
    #[inline]
    fn run(&self, _start: usize, _len: usize) -> Option<&[f64]> {
        None
    }
}

impl Values for &[f64] {
    #[inline]
    fn len(&self) -> usize {
        <[f64]>::len(self)
    }
    #[inline]
    fn at(&self, i: usize) -> f64 {
        self.get(i).copied().unwrap_or(0.0)
    }
    #[inline]
    fn run(&self, start: usize, len: usize) -> Option<&[f64]> {
        self.get(start..start + len)
    }
    fn all_finite(&self) -> bool {
        // (A fold rather than `all`: no early exit, so the compiler checks many at once.)
        self.iter().fold(true, |ok, x| ok & x.is_finite())
    }
    #[inline]
    fn copy_to(&self, start: usize, out: &mut [f64]) {
        match self.get(start..start + out.len()) {
            Some(v) => out.copy_from_slice(v),
            None => out
                .iter_mut()
                .enumerate()
                .for_each(|(i, o)| *o = self.at(start + i)),
        }
    }
}

impl Values for LeF32<'_> {
    #[inline]
    fn len(&self) -> usize {
        LeF32::len(self)
    }
    #[inline]
    fn at(&self, i: usize) -> f64 {
        self.get(i) as f64
    }
    #[inline]
    fn copy_to(&self, start: usize, out: &mut [f64]) {
        match self.0.get(4 * start..4 * (start + out.len())) {
            Some(bytes) => {
                for (o, b) in out.iter_mut().zip(bytes.chunks_exact(4)) {
                    *o = f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
                }
            }
            None => out
                .iter_mut()
                .enumerate()
                .for_each(|(i, o)| *o = self.at(start + i)),
        }
    }
    fn all_finite(&self) -> bool {
        // An f32 is finite when its exponent bits are not all set; checked on the bytes.
        self.0.chunks_exact(4).fold(true, |ok, b| {
            let bits = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            ok & (bits & 0x7f80_0000 != 0x7f80_0000)
        })
    }
}

/// INFORM restricted to the rows of a set of observed bands.
#[derive(Clone, Copy, Debug)]
pub struct Packed<V> {
    spectral: V,
    weights: V,
    lidf_beta: V,
    n_rows: usize,
    n_bands: usize,
    /// Per band: first and last row with weight (`(1, 0)` for a band without).
    ranges: [(usize, usize); N_BANDS],
}

/// Most rows read together (the widest lanes: 16 `f32`).
const MAX_LANES: usize = 16;

/// Per band: the first and last of `n_rows` rows whose weight is not zero (`(1, 0)` for a band
/// without), for the `n_rows × n_bands` weights (row-major). The weights are read a block of rows
/// at a time; a band's rows are looked for only in the blocks where it has weight.
fn band_ranges<V: Values>(weights: V, n_rows: usize, n_bands: usize) -> [(usize, usize); N_BANDS] {
    const BLOCK: usize = 16;
    let mut ranges = [(1usize, 0usize); N_BANDS];
    let mut buf = [0.0; BLOCK * N_BANDS];
    for r0 in (0..n_rows).step_by(BLOCK) {
        let rows = BLOCK.min(n_rows - r0);
        let block = &mut buf[..rows * n_bands];
        weights.copy_to(r0 * n_bands, block);
        // Per band: the bits of its weights in the block, sign left out (−0 is no weight).
        let mut any = [0u64; N_BANDS];
        for row in block.chunks_exact(n_bands) {
            for (a, w) in any.iter_mut().zip(row) {
                *a |= w.to_bits() << 1;
            }
        }
        let block = &*block;
        for (b, r) in ranges.iter_mut().enumerate().take(n_bands) {
            if any[b] == 0 {
                continue;
            }
            let nonzero = |row: &usize| block[row * n_bands + b] != 0.0;
            if r.0 > r.1 {
                r.0 = r0 + (0..rows).find(nonzero).unwrap_or(0);
            }
            r.1 = r0 + (0..rows).rev().find(nonzero).unwrap_or(0);
        }
    }
    ranges
}

/// Zero-length stand-ins for the spectral tables when only the wavelength-independent part of
/// INFORM ([`Inform::scene`]) is needed.
const NO_WL: [f64; 1] = [0.0];
const NO_BANDS: [f64; N_BANDS] = [0.0; N_BANDS];

impl<V: Values> Packed<V> {
    /// Wraps packed rows: `spectral` (`n_rows × ROW_WIDTH`), `weights` (`n_rows × n_bands`),
    /// `lidf_beta` (`13 × k`, `1 ≤ k ≤ MAX_BETA_ROWS`). Fails on sizes that do not agree, on more
    /// than [`MAX_ROWS`] rows or [`N_BANDS`] bands, and on non-finite values.
    pub fn new(spectral: V, weights: V, lidf_beta: V, n_bands: usize) -> Result<Self, Error> {
        if n_bands == 0 || n_bands > N_BANDS {
            return Err(Error::OutOfRange {
                what: "number of observed bands",
            });
        }
        let n_rows = spectral.len() / ROW_WIDTH;
        if n_rows == 0 || n_rows > MAX_ROWS || n_rows * ROW_WIDTH != spectral.len() {
            return Err(Error::SizeMismatch {
                what: "packed spectral rows (13 values per row)",
                expected: n_rows.clamp(1, MAX_ROWS) * ROW_WIDTH,
                found: spectral.len(),
            });
        }
        if weights.len() != n_rows * n_bands {
            return Err(Error::SizeMismatch {
                what: "packed band weights",
                expected: n_rows * n_bands,
                found: weights.len(),
            });
        }
        let nb = LITAB_DEG.len();
        let k = lidf_beta.len() / nb;
        if k == 0 || k > MAX_BETA_ROWS || k * nb != lidf_beta.len() {
            return Err(Error::SizeMismatch {
                what: "lidf beta table (13 angles x rows)",
                expected: k.clamp(1, MAX_BETA_ROWS) * nb,
                found: lidf_beta.len(),
            });
        }
        for (what, v) in [
            ("packed spectral rows", spectral),
            ("packed band weights", weights),
            ("lidf beta table", lidf_beta),
        ] {
            if !v.all_finite() {
                let index = (0..v.len()).find(|&i| !v.at(i).is_finite()).unwrap_or(0);
                return Err(Error::NonFinite { what, index });
            }
        }
        let ranges = band_ranges(weights, n_rows, n_bands);
        Ok(Packed {
            spectral,
            weights,
            lidf_beta,
            n_rows,
            n_bands,
            ranges,
        })
    }

    /// Number of spectral rows.
    pub fn n_rows(&self) -> usize {
        self.n_rows
    }

    /// Number of observed bands.
    pub fn n_bands(&self) -> usize {
        self.n_bands
    }

    /// Number of beta leaf-angle distributions.
    pub fn n_beta_rows(&self) -> usize {
        self.lidf_beta.len() / LITAB_DEG.len()
    }

    /// Spectral row `i` (`i < n_rows`).
    #[inline]
    pub fn row(&self, i: usize) -> SpectralRow {
        let b = i * ROW_WIDTH;
        let s = |k: usize| self.spectral.at(b + k);
        SpectralRow {
            coef: CoefRow {
                nr: s(0),
                k_cab: s(1),
                k_car: s(2),
                k_anth: s(3),
                k_brown: s(4),
                k_cw: s(5),
                k_cm: s(6),
                t12: s(7),
                tav90n: s(8),
            },
            soil_dry: s(9),
            soil_wet: s(10),
            es: s(11),
            ed: s(12),
        }
    }

    /// Rows `i0, i0 + 1, …` as lanes of `W`, row `i0 + j` in lane `j`; lanes past the last row
    /// repeat it.
    #[inline(always)]
    fn rows<S: Real, W: Lanes<S>>(&self, i0: usize) -> SpectralRow<W::Plain> {
        if let Some(block) = self.spectral.run(i0 * ROW_WIDTH, W::WIDTH * ROW_WIDTH) {
            return SpectralRow::from_fn(|k| W::plain_from_fn(|j| block[j * ROW_WIDTH + k]));
        }
        let last = self.n_rows - 1;
        if W::WIDTH == 1 {
            return SpectralRow::from_fn(|k| {
                W::plain_from_fn(|_| self.spectral.at(i0.min(last) * ROW_WIDTH + k))
            });
        }
        // Several rows: read them at once (f32 bytes decoded in one pass); lanes past the last
        // row repeat it.
        let mut buf = [0.0; MAX_LANES * ROW_WIDTH];
        let i0 = i0.min(last);
        let n = (self.n_rows - i0).min(W::WIDTH).min(MAX_LANES);
        let (rows, rest) = buf.split_at_mut(n * ROW_WIDTH);
        self.spectral.copy_to(i0 * ROW_WIDTH, rows);
        let last_row = &rows[(n - 1) * ROW_WIDTH..];
        for r in rest.chunks_exact_mut(ROW_WIDTH) {
            r.copy_from_slice(last_row);
        }
        SpectralRow::from_fn(|k| W::plain_from_fn(|j| buf[j * ROW_WIDTH + k]))
    }

    /// Weight of row `i` in band `b`.
    #[inline]
    pub fn weight(&self, i: usize, b: usize) -> f64 {
        self.weights.at(i * self.n_bands + b)
    }

    /// Validates the 21 inputs and computes the wavelength-independent terms (the checks and the
    /// scene of [`Inform::scene`], with this model's beta table).
    pub fn scene<R: Real>(&self, x: &[R; N_INPUTS], geometry: Geometry) -> Result<Scene<R>, Error> {
        let mut beta = [0f64; 13 * MAX_BETA_ROWS];
        let n = self.lidf_beta.len();
        for (i, b) in beta[..n].iter_mut().enumerate() {
            *b = self.lidf_beta.at(i);
        }
        let c = &NO_WL[..];
        let tables = Tables {
            prospect: Coefficients {
                nr: c,
                k_cab: c,
                k_car: c,
                k_anth: c,
                k_brown: c,
                k_cw: c,
                k_cm: c,
                t12: c,
                tav90n: c,
            },
            soil_dry: c,
            soil_wet: c,
            es: c,
            ed: c,
            lidf_beta: &beta[..n],
            resampling: &NO_BANDS,
        };
        Inform::new(tables)?.scene(x, geometry)
    }

    fn check_out<T>(&self, out: &[T]) -> Result<(), Error> {
        crate::error::check_len("band output", self.n_bands, out.len())
    }

    /// The observed bands for the 21 inputs (`out.len()` = number of bands). Errors as
    /// [`Inform::forward`].
    pub fn forward<R: Real>(
        &self,
        x: &[R; N_INPUTS],
        geometry: Geometry,
        out: &mut [R],
    ) -> Result<(), Error> {
        self.check_out(out)?;
        let scene = self.scene(x, geometry)?.lanes();
        let mut sums = BandSums::<R::Lanes>::new(&self.ranges[..self.n_bands]);
        let last = self.n_rows - 1;
        for i0 in (0..self.n_rows).step_by(<R::Lanes as Lanes<R>>::WIDTH) {
            let r = scene.wavelength(&self.rows::<R, R::Lanes>(i0)).r_forest;
            sums.add(i0, last, r, |i, b| self.weight(i, b));
        }
        sums.finish(out);
        Ok(())
    }

    /// The observed bands from the learned variables `[N, cab, cw, cm, LAI, LAIu, fc]`.
    pub fn forward_learned<R: Real>(
        &self,
        z: &[R; N_LEARNED],
        fixed: &Fixed,
        geometry: Geometry,
        out: &mut [R],
    ) -> Result<(), Error> {
        if let Some(i) = z.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "learned variable",
                index: i,
            });
        }
        if z[6].value() <= 0.0 {
            return Err(Error::OutOfRange {
                what: "fc (must be > 0)",
            });
        }
        self.forward(&inputs_from_learned(z, fixed), geometry, out)
    }

    /// Bands and exact Jacobian `∂band/∂z` (`jac[b]`, 7 per band) at the learned variables, by
    /// the split chain rule of [`Inform::jacobian`], in `f64`.
    pub fn jacobian(
        &self,
        z: &[f64; N_LEARNED],
        fixed: &Fixed,
        geometry: Geometry,
        out: &mut [f64],
        jac: &mut [[f64; N_LEARNED]],
    ) -> Result<(), Error> {
        self.jacobian_in::<f64>(z, fixed, geometry, out, jac)
    }

    /// [`Packed::jacobian`] computed in the scalar `T`: `f32` computes eight wavelengths per
    /// vector instead of four on SIMD targets, within [`JACOBIAN_F32_MAX_REL_ERROR`] of `f64`.
    pub fn jacobian_in<T: DualScalar>(
        &self,
        z: &[f64; N_LEARNED],
        fixed: &Fixed,
        geometry: Geometry,
        out: &mut [f64],
        jac: &mut [[f64; N_LEARNED]],
    ) -> Result<(), Error> {
        self.check_out(out)?;
        self.check_out(jac)?;
        let lj = LearnedJacobian::<T>::new(z, fixed, |x| self.scene(x, geometry))?;
        let mut sums = BandSums::<JacobianLanes<T>>::new(&self.ranges[..self.n_bands]);
        let last = self.n_rows - 1;
        let width = <JacobianLanes<T> as Lanes<Dual<N_LEARNED, T>>>::WIDTH;
        for i0 in (0..self.n_rows).step_by(width) {
            let r = lj.wavelengths(&self.rows::<Dual<N_LEARNED, T>, JacobianLanes<T>>(i0));
            sums.add::<Dual<N_LEARNED, T>>(i0, last, r, |i, b| self.weight(i, b));
        }
        let mut bands = [Dual::<N_LEARNED, T>::c(0.0); N_BANDS];
        sums.finish(&mut bands[..self.n_bands]);
        for ((o, j), d) in out.iter_mut().zip(jac.iter_mut()).zip(&bands) {
            *o = d.v.value();
            *j = d.d.map(|x| x.value());
        }
        Ok(())
    }
}

/// Largest error of [`Packed::jacobian_in`] in `f32` against `f64` over the learned box (bands
/// relative to their value; derivatives scaled by the variable's range and relative to the
/// largest of their column): measured 1.6e-3 (B10 and B07 at high cab, cw and cm: single
/// precision in PROSPECT's strong absorptions) at the centre and 128 corners; 3× that.
pub const JACOBIAN_F32_MAX_REL_ERROR: f64 = 5e-3;

#[cfg(test)]
mod tests {
    use super::*;

    /// Two wavelengths, two bands, uniform beta row: packed f64 and f32 bytes agree, the
    /// Jacobian agrees with Dual<7> forward mode.
    #[test]
    fn f64_and_f32_rows_agree() {
        let row = |nr: f64, k: f64| {
            [
                nr, k, 0.1, 0.02, 0.3, 0.01, 50.0, 0.95, 0.9, 0.25, 0.08, 1.0, 0.6,
            ]
        };
        let mut spectral = [0.0; 2 * ROW_WIDTH];
        spectral[..13].copy_from_slice(&row(1.5, 0.05));
        spectral[13..].copy_from_slice(&row(1.45, 0.0));
        let weights = [0.7, 0.0, 0.3, 1.0];
        let beta = [1.0 / 13.0; 13];
        let p = Packed::new(&spectral[..], &weights[..], &beta[..], 2).unwrap();
        let fixed = Fixed {
            lidf: 0.0,
            ..Fixed::default()
        };
        let z = [1.6, 45.0, 0.012, 0.01, 2.5, 0.4, 0.6];
        let mut y = [0.0; 2];
        p.forward_learned(&z, &fixed, Geometry::Reference, &mut y)
            .unwrap();
        assert!(y.iter().all(|v| *v > 0.0 && *v < 1.0), "{y:?}");

        let bytes = |v: &[f64]| {
            let mut b = [0u8; 4 * 2 * ROW_WIDTH];
            for (c, x) in b.chunks_exact_mut(4).zip(v) {
                c.copy_from_slice(&(*x as f32).to_le_bytes());
            }
            (b, 4 * v.len())
        };
        let (sb, sn) = bytes(&spectral);
        let (wb, wn) = bytes(&weights);
        let (bb, bn) = bytes(&beta);
        let q = Packed::new(LeF32(&sb[..sn]), LeF32(&wb[..wn]), LeF32(&bb[..bn]), 2).unwrap();
        let mut y32 = [0f32; 2];
        q.forward_learned(&z.map(|v| v as f32), &fixed, Geometry::Reference, &mut y32)
            .unwrap();
        for (a, b) in y.iter().zip(&y32) {
            assert!((a - *b as f64).abs() < 1e-5, "{a} {b}");
        }

        let (mut yj, mut jac) = ([0.0; 2], [[0.0; N_LEARNED]; 2]);
        p.jacobian(&z, &fixed, Geometry::Physical, &mut yj, &mut jac)
            .unwrap();
        let z7: [Dual<N_LEARNED>; N_LEARNED] = core::array::from_fn(|i| Dual::var(z[i], i));
        let mut full = [Dual::<N_LEARNED>::constant(0.0); 2];
        p.forward_learned(&z7, &fixed, Geometry::Physical, &mut full)
            .unwrap();
        for b in 0..2 {
            assert!((yj[b] - full[b].v).abs() < 1e-15);
            for (a, e) in jac[b].iter().zip(&full[b].d) {
                assert!((a - e).abs() <= 1e-12 * (1.0 + e.abs()));
            }
        }
    }

    #[test]
    fn size_errors() {
        let s = [0.5; ROW_WIDTH];
        let beta = [1.0 / 13.0; 13];
        assert!(Packed::new(&s[..], &[1.0][..], &beta[..], 1).is_ok());
        assert!(Packed::new(&s[..12], &[1.0][..], &beta[..], 1).is_err());
        assert!(Packed::new(&s[..], &[1.0, 0.0][..], &beta[..], 1).is_err());
        assert!(Packed::new(&s[..], &[1.0][..], &beta[..12], 1).is_err());
        assert!(Packed::new(&s[..], &[f64::NAN][..], &beta[..], 1).is_err());
        assert!(Packed::new(&s[..], &[1.0][..], &beta[..], 0).is_err());
        let p = Packed::new(&s[..], &[1.0][..], &beta[..], 1).unwrap();
        let fixed = Fixed {
            lidf: 1.0,
            ..Fixed::default()
        }; // beta row 1 does not exist
        let z = [1.6, 45.0, 0.012, 0.01, 2.5, 0.4, 0.6];
        assert!(p
            .forward_learned(&z, &fixed, Geometry::Reference, &mut [0.0])
            .is_err());
        assert!(p
            .forward_learned(
                &z,
                &Fixed { lidf: 0.0, ..fixed },
                Geometry::Reference,
                &mut [0.0; 2]
            )
            .is_err());
    }
}
