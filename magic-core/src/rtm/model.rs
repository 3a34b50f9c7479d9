//! The INFORM + Sentinel-2 forward model bound to its tables: 21 inputs → 13 bands.
//!
//! [`Tables`] borrows every spectral table (the crate ships none); [`Inform::new`] checks their
//! sizes once and finds the wavelengths the bands need; [`Inform::forward`] validates the inputs,
//! computes the wavelength-independent terms once ([`Scene`]) and evaluates PROSPECT-D, four 4SAIL
//! calls and FLIM only at those wavelengths, several wavelengths per evaluation on SIMD targets
//! (eight for `f64`, four for `f32` and duals: [`Real::Lanes`]). Everything is generic over
//! [`Real`]: `f64`, `f32`, and [`Dual`] for the exact Jacobian ([`Inform::jacobian`]).

use super::inform::{
    crown_fraction_terms, crown_from_cover, crown_geometry, Geometry, Scene, SpectralRow, Stand,
    WavelengthTerms,
};
use super::prospect::{leaf_optics, Coefficients, Leaf, LeafOptics};
use super::sail::{CampbellBins, Lidf, LITAB_DEG};
use super::sensor::Resampling;
use crate::real::{Dual, DualScalar, Lanes, Real};
use crate::Error;

/// Number of model inputs.
pub const N_INPUTS: usize = 21;

/// Input names, in order (the columns of `rtm_inform_s2_*.csv`).
pub const INPUT_NAMES: [&str; N_INPUTS] = [
    "N", "cab", "car", "anth", "cbrown", "cw", "cm", "cp", "cbc", "LAI", "typeLIDF", "LIDF",
    "hspot", "psoil", "tts", "tto", "psi", "LAIu", "cd", "sd", "h",
];

/// Number of Sentinel-2 bands.
pub const N_BANDS: usize = 13;

/// Number of learned variables.
pub const N_LEARNED: usize = 7;

/// The learned variables, in order (paper Table 1); `cd` and `h` are derived from `fc`.
pub const LEARNED_NAMES: [&str; N_LEARNED] = ["N", "cab", "cw", "cm", "LAI", "LAIu", "fc"];

/// The paper's bounds of the learned variables (min, max).
pub const LEARNED_BOUNDS: [[f64; 2]; N_LEARNED] = [
    [1.0, 3.0],
    [10.0, 80.0],
    [0.001, 0.02],
    [0.005, 0.05],
    [0.01, 5.0],
    [0.01, 1.0],
    [0.1, 1.0],
];

/// The borrowed tables, one value per wavelength on a common grid (1 nm, 400–2500 nm for the
/// published tables), plus the leaf-angle beta table and the sensor's resampling matrix.
#[derive(Clone, Copy, Debug)]
pub struct Tables<'a> {
    /// PROSPECT-D coefficients.
    pub prospect: Coefficients<'a>,
    /// Dry soil reflectance.
    pub soil_dry: &'a [f64],
    /// Wet soil reflectance.
    pub soil_wet: &'a [f64],
    /// Direct solar irradiance.
    pub es: &'a [f64],
    /// Diffuse sky irradiance.
    pub ed: &'a [f64],
    /// Beta leaf-angle table, 13 angles × rows, angle-major (`beta_0…beta_5` of
    /// `lidf_tables.csv`).
    pub lidf_beta: &'a [f64],
    /// Resampling matrix, wavelengths × bands, row-major.
    pub resampling: &'a [f64],
}

/// The INFORM + sensor model over borrowed tables.
#[derive(Clone, Copy, Debug)]
pub struct Inform<'a> {
    tables: Tables<'a>,
    sensor: Resampling<'a>,
}

/// Fixed (not learned) inputs for [`Inform::forward_learned`]; `Default` gives the paper's values
/// (Appendix A.3): car 10, anth 2, cbrown 0.25, cp 0.0015, cbc 0.01, beta LIDF row 5, hotspot
/// 0.01, psoil 0.8, sun zenith 30°, view zenith 0°, azimuth 0°, stem density 500 ha⁻¹.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed {
    /// Carotenoids.
    pub car: f64,
    /// Anthocyanins.
    pub anth: f64,
    /// Brown pigments.
    pub cbrown: f64,
    /// Proteins (not used by PROSPECT-D).
    pub cp: f64,
    /// Carbon-based constituents (not used by PROSPECT-D).
    pub cbc: f64,
    /// Leaf angle distribution type: 1 beta table, 2 Campbell.
    pub type_lidf: f64,
    /// Beta table row (type 1) or mean leaf angle in degrees (type 2).
    pub lidf: f64,
    /// Hotspot size.
    pub hspot: f64,
    /// Soil brightness.
    pub psoil: f64,
    /// Sun zenith (degrees).
    pub tts: f64,
    /// View zenith (degrees).
    pub tto: f64,
    /// Relative azimuth (degrees).
    pub psi: f64,
    /// Stem density (ha⁻¹).
    pub sd: f64,
}

impl Default for Fixed {
    fn default() -> Self {
        Fixed {
            car: 10.0,
            anth: 2.0,
            cbrown: 0.25,
            cp: 0.0015,
            cbc: 0.01,
            type_lidf: 1.0,
            lidf: 5.0,
            hspot: 0.01,
            psoil: 0.8,
            tts: 30.0,
            tto: 0.0,
            psi: 0.0,
            sd: 500.0,
        }
    }
}

/// The 21 model inputs from the 7 learned variables `[N, cab, cw, cm, LAI, LAIu, fc]` and the fixed
/// ones; `cd` and `h` follow from `fc` and `sd` (paper eqs. 7–8).
pub fn inputs_from_learned<R: Real>(z: &[R; N_LEARNED], f: &Fixed) -> [R; N_INPUTS] {
    let sd = R::c(f.sd);
    let (cd, h) = crown_from_cover(z[6], sd);
    [
        z[0],
        z[1],
        R::c(f.car),
        R::c(f.anth),
        R::c(f.cbrown),
        z[2],
        z[3],
        R::c(f.cp),
        R::c(f.cbc),
        z[4],
        R::c(f.type_lidf),
        R::c(f.lidf),
        R::c(f.hspot),
        R::c(f.psoil),
        R::c(f.tts),
        R::c(f.tto),
        R::c(f.psi),
        z[5],
        cd,
        sd,
        h,
    ]
}

fn check_len(what: &'static str, s: &[f64], n: usize) -> Result<(), Error> {
    crate::error::check_len(what, n, s.len())
}

impl<'a> Inform<'a> {
    /// Checks the table sizes (all spectral columns of one length `n`, the beta table a multiple
    /// of 13, the resampling matrix `n × 13`) and prepares the band integration.
    pub fn new(tables: Tables<'a>) -> Result<Self, Error> {
        let n = tables.prospect.len();
        if n == 0 {
            return Err(Error::SizeMismatch {
                what: "prospect nr",
                expected: 1,
                found: 0,
            });
        }
        for (what, col) in tables.prospect.columns() {
            check_len(what, col, n)?;
        }
        check_len("soil dry", tables.soil_dry, n)?;
        check_len("soil wet", tables.soil_wet, n)?;
        check_len("solar direct", tables.es, n)?;
        check_len("solar diffuse", tables.ed, n)?;
        let nb = LITAB_DEG.len();
        if tables.lidf_beta.is_empty() || tables.lidf_beta.len() / nb * nb != tables.lidf_beta.len()
        {
            let rows = (tables.lidf_beta.len() / nb).max(1);
            return Err(Error::SizeMismatch {
                what: "lidf beta table",
                expected: rows * nb,
                found: tables.lidf_beta.len(),
            });
        }
        let sensor = Resampling::new(tables.resampling, n, N_BANDS)?;
        Ok(Inform { tables, sensor })
    }

    /// The tables.
    pub fn tables(&self) -> &Tables<'a> {
        &self.tables
    }

    /// The band integration.
    pub fn sensor(&self) -> &Resampling<'a> {
        &self.sensor
    }

    /// Number of wavelengths of the table grid.
    pub fn n_wavelengths(&self) -> usize {
        self.tables.prospect.len()
    }

    /// The spectral row of wavelength index `i` (`None` past the end).
    #[inline]
    pub fn row(&self, i: usize) -> Option<SpectralRow> {
        let t = &self.tables;
        Some(SpectralRow {
            coef: t.prospect.row(i)?,
            soil_dry: *t.soil_dry.get(i)?,
            soil_wet: *t.soil_wet.get(i)?,
            es: *t.es.get(i)?,
            ed: *t.ed.get(i)?,
        })
    }

    /// The spectral rows of wavelength indices `i0, i0 + 1, …` as lanes, row `i0 + j` in lane `j`
    /// (indices past the grid read its last row).
    #[inline]
    fn rows<S: Real, W: Lanes<S>>(&self, i0: usize) -> SpectralRow<W::Plain> {
        let t = &self.tables;
        let p = &t.prospect;
        let cols = [
            p.nr, p.k_cab, p.k_car, p.k_anth, p.k_brown, p.k_cw, p.k_cm, p.t12, p.tav90n,
            t.soil_dry, t.soil_wet, t.es, t.ed,
        ];
        SpectralRow::from_fn(|k| {
            let col = cols[k];
            match col.get(i0..i0 + W::WIDTH) {
                Some(run) => W::plain_from_fn(|j| run[j]),
                None => {
                    W::plain_from_fn(|j| col.get(i0 + j).or(col.last()).copied().unwrap_or(0.0))
                }
            }
        })
    }

    /// Validates the 21 inputs and computes the wavelength-independent terms.
    pub fn scene<R: Real>(&self, x: &[R; N_INPUTS], geometry: Geometry) -> Result<Scene<R>, Error> {
        for (i, v) in x.iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::NonFinite {
                    what: "inform input",
                    index: i,
                });
            }
        }
        let v = |i: usize| x[i].value();
        if v(0) <= 0.0 {
            return Err(Error::OutOfRange {
                what: "N (must be > 0)",
            });
        }
        for (i, name) in [
            (1, "cab"),
            (2, "car"),
            (3, "anth"),
            (4, "cbrown"),
            (5, "cw"),
            (6, "cm"),
        ] {
            if v(i) < 0.0 {
                return Err(Error::OutOfRange { what: name });
            }
        }
        if v(9) <= 0.0 {
            return Err(Error::OutOfRange {
                what: "LAI (must be > 0)",
            });
        }
        if v(17) <= 0.0 {
            return Err(Error::OutOfRange {
                what: "LAIu (must be > 0)",
            });
        }
        if v(12) < 0.0 {
            return Err(Error::OutOfRange { what: "hspot" });
        }
        if !(0.0..=1.0).contains(&v(13)) {
            return Err(Error::OutOfRange {
                what: "psoil (0..1)",
            });
        }
        if !(0.0..90.0).contains(&v(14)) {
            return Err(Error::OutOfRange {
                what: "tts (0..90 degrees)",
            });
        }
        if !(0.0..90.0).contains(&v(15)) {
            return Err(Error::OutOfRange {
                what: "tto (0..90 degrees)",
            });
        }
        if v(18) <= 0.0 || v(19) <= 0.0 || v(20) < 0.0 {
            return Err(Error::OutOfRange {
                what: "cd, sd (> 0) or h (>= 0)",
            });
        }
        let type_lidf = v(10);
        let lidf = if type_lidf == 1.0 {
            let row = v(11);
            let n_rows = self.tables.lidf_beta.len() / LITAB_DEG.len();
            if !(row >= 0.0 && row < n_rows as f64) {
                return Err(Error::OutOfRange {
                    what: "LIDF beta table row",
                });
            }
            // The reference truncates the row index to an integer.
            Lidf::from_beta_table(self.tables.lidf_beta, row as usize)?
        } else if type_lidf == 2.0 {
            Lidf::campbell(x[11], CampbellBins::Reference13)?
        } else {
            return Err(Error::OutOfRange {
                what: "typeLIDF (1 beta table, 2 Campbell)",
            });
        };
        let stand = Stand {
            leaf: Leaf {
                n: x[0],
                cab: x[1],
                car: x[2],
                anth: x[3],
                cbrown: x[4],
                cw: x[5],
                cm: x[6],
            },
            lai: x[9],
            lai_u: x[17],
            hspot: x[12],
            psoil: x[13],
            tts: x[14],
            tto: x[15],
            psi: x[16],
            cd: x[18],
            sd: x[19],
            h: x[20],
        };
        Ok(Scene::new(&stand, &lidf, geometry))
    }

    /// The 13 Sentinel-2 bands for the 21 inputs.
    ///
    /// Errors: a non-finite input ([`Error::NonFinite`] with its index), an input outside the
    /// model's domain or an unknown `typeLIDF` / beta row ([`Error::OutOfRange`]).
    pub fn forward<R: Real>(
        &self,
        x: &[R; N_INPUTS],
        geometry: Geometry,
    ) -> Result<[R; N_BANDS], Error> {
        let scene = self.scene(x, geometry)?.lanes();
        let mut out = [R::zero(); N_BANDS];
        self.sensor.integrate_lanes(
            |i0| scene.wavelength(&self.rows::<R, R::Lanes>(i0)).r_forest,
            &mut out,
        )?;
        Ok(out)
    }

    /// Every intermediate result at wavelength index `i` (for stepwise checks and plots).
    pub fn wavelength<R: Real>(
        &self,
        x: &[R; N_INPUTS],
        geometry: Geometry,
        i: usize,
    ) -> Result<WavelengthTerms<R>, Error> {
        let scene = self.scene(x, geometry)?;
        let row = self.row(i).ok_or(Error::OutOfRange {
            what: "wavelength index",
        })?;
        Ok(scene.wavelength(&row.map(<R::Plain as Real>::c)))
    }

    /// The forest reflectance at every wavelength of the grid (`out.len()` = number of
    /// wavelengths).
    pub fn spectrum<R: Real>(
        &self,
        x: &[R; N_INPUTS],
        geometry: Geometry,
        out: &mut [R],
    ) -> Result<(), Error> {
        let n = self.n_wavelengths();
        if out.len() != n {
            return Err(Error::SizeMismatch {
                what: "spectrum output",
                expected: n,
                found: out.len(),
            });
        }
        let scene = self.scene(x, geometry)?;
        for (i, o) in out.iter_mut().enumerate() {
            let row = self.row(i).ok_or(Error::OutOfRange {
                what: "wavelength index",
            })?;
            *o = scene.wavelength(&row.map(<R::Plain as Real>::c)).r_forest;
        }
        Ok(())
    }

    /// The 13 bands from the 7 learned variables `[N, cab, cw, cm, LAI, LAIu, fc]`.
    pub fn forward_learned<R: Real>(
        &self,
        z: &[R; N_LEARNED],
        fixed: &Fixed,
        geometry: Geometry,
    ) -> Result<[R; N_BANDS], Error> {
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
        self.forward(&inputs_from_learned(z, fixed), geometry)
    }

    /// Bands and exact Jacobian `∂band/∂z` (13 × 7) at the learned variables
    /// `z = [N, cab, cw, cm, LAI, LAIu, fc]`, by forward-mode differentiation with the chain rule
    /// split so that each part carries few derivatives: PROSPECT-D on [`Dual<4>`] in
    /// (N, cab, cw, cm), the canopy on `Dual<4>` in (leaf reflectance, leaf transmittance, LAI,
    /// LAIu), the cover through the crown fractions, which the forest reflectance is linear in;
    /// four wavelengths at a time (duals on SIMD lanes). The result equals
    /// [`Inform::forward_learned`] on [`Dual<7>`] up to round-off.
    pub fn jacobian(
        &self,
        z: &[f64; N_LEARNED],
        fixed: &Fixed,
        geometry: Geometry,
    ) -> Result<([f64; N_BANDS], [[f64; N_LEARNED]; N_BANDS]), Error> {
        let lj = LearnedJacobian::<f64>::new(z, fixed, |x| self.scene(x, geometry))?;
        let mut out = [Dual::<N_LEARNED>::constant(0.0); N_BANDS];
        self.sensor.integrate_lanes(
            |i0| lj.wavelengths(&self.rows::<Dual<N_LEARNED>, JacobianLanes>(i0)),
            &mut out,
        )?;
        let mut y = [0.0; N_BANDS];
        let mut jac = [[0.0; N_LEARNED]; N_BANDS];
        for (b, o) in out.iter().enumerate() {
            y[b] = o.v;
            jac[b] = o.d;
        }
        Ok((y, jac))
    }
}

/// Lanes of wavelengths' forest reflectance with its 7 derivatives ([`Dual`] on lanes of the
/// scalar `T`: four `f64` or eight `f32` with AVX).
pub(crate) type JacobianLanes<T = f64> = <Dual<N_LEARNED, T> as Real>::Lanes;

/// A dual in 4 variables on lanes of wavelengths.
type Lanes4<T> = <Dual<4, T> as Real>::Lanes;

/// Plain values on the lanes of [`Lanes4`].
type PlainLanes<T> = <Lanes4<T> as Real>::Plain;

/// The exact derivatives of the forest reflectance with respect to the learned variables
/// `z = [N, cab, cw, cm, LAI, LAIu, fc]`, for lanes of wavelengths, computed in the scalar `T`
/// (`f64`, or `f32` where a Jacobian to single precision is enough), with the chain rule split
/// so that each part carries few derivatives:
///
/// * PROSPECT-D on [`Dual<4>`] in (N, cab, cw, cm) gives the leaf reflectance ρ and
///   transmittance τ with their derivatives;
/// * the canopy on [`Dual<4>`] in (ρ, τ, LAI, LAIu), with ρ and τ seeded per wavelength, gives
///   `∂R/∂ρ`, `∂R/∂τ`, `∂R/∂LAI`, `∂R/∂LAIu`; then `∂R/∂leaf = ∂R/∂ρ·∂ρ/∂leaf + ∂R/∂τ·∂τ/∂leaf`;
/// * the cover fc moves only the four crown fractions F (through crown diameter and height), and
///   R is linear in them ([`crown_fraction_terms`]): `∂R/∂fc = Σ ∂F_i/∂fc·B_i`, with `∂F/∂fc`
///   computed once per spectrum.
pub(crate) struct LearnedJacobian<T: DualScalar = f64> {
    /// The canopy scene: LAI and LAIu in derivative slots 2 and 3 (0 and 1 are ρ and τ).
    canopy: Scene<Lanes4<T>>,
    /// The leaf with N, cab, cw, cm in slots 0 to 3.
    leaf: Leaf<Lanes4<T>>,
    /// `∂F/∂fc` of the crown fractions `[fcd, fcs, fod, fos]`.
    dfractions_dfc: [f64; 4],
}

impl<T: DualScalar> LearnedJacobian<T> {
    /// The per-spectrum part at `z`, with the scene built (and the inputs validated) by `scene`.
    pub(crate) fn new(
        z: &[f64; N_LEARNED],
        fixed: &Fixed,
        scene: impl FnOnce(&[Dual<4, T>; N_INPUTS]) -> Result<Scene<Dual<4, T>>, Error>,
    ) -> Result<Self, Error> {
        if let Some(i) = z.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "learned variable",
                index: i,
            });
        }
        if z[6] <= 0.0 {
            return Err(Error::OutOfRange {
                what: "fc (must be > 0)",
            });
        }
        let var = |v: f64, slot: usize| Dual::<4, T>::seed(T::c(v), slot);
        let z4: [Dual<4, T>; N_LEARNED] = core::array::from_fn(|i| match i {
            4 => var(z[4], 2),
            5 => var(z[5], 3),
            _ => Dual::c(z[i]),
        });
        let canopy = scene(&inputs_from_learned(&z4, fixed))?;
        // The crown fractions as functions of fc, at the angles the scene's crown geometry used
        // (always in f64: once per spectrum).
        let sd = Dual::<1>::constant(fixed.sd);
        let (cd, h) = crown_from_cover(Dual::var(z[6], 0), sd);
        let [tts, tto, psi] = canopy.inform_angles.map(|a| Dual::constant(a.v.value()));
        let cg = crown_geometry(cd, sd, h, tts, tto, psi);
        let leaf = Leaf {
            n: var(z[0], 0),
            cab: var(z[1], 1),
            car: Dual::c(fixed.car),
            anth: Dual::c(fixed.anth),
            cbrown: Dual::c(fixed.cbrown),
            cw: var(z[2], 2),
            cm: var(z[3], 3),
        };
        Ok(LearnedJacobian {
            canopy: canopy.lanes(),
            leaf: leaf.map(<Lanes4<T> as Lanes<Dual<4, T>>>::splat),
            dfractions_dfc: [cg.fcd.d[0], cg.fcs.d[0], cg.fod.d[0], cg.fos.d[0]],
        })
    }

    /// The forest reflectance at the wavelengths of `rows` (one per lane) with its derivatives
    /// with respect to `z`.
    #[inline]
    pub(crate) fn wavelengths(&self, rows: &SpectralRow<PlainLanes<T>>) -> JacobianLanes<T> {
        let lo = leaf_optics(&rows.coef, &self.leaf);
        let seeded = LeafOptics {
            refl: Dual::seed(lo.refl.v, 0),
            trans: Dual::seed(lo.trans.v, 1),
        };
        let t = self.canopy.wavelength_with_leaf(rows, seeded);
        let r = t.r_forest;
        let mut d = [PlainLanes::<T>::c(0.0); N_LEARNED];
        for (k, dk) in d.iter_mut().take(4).enumerate() {
            *dk = r.d[0] * lo.refl.d[k] + r.d[1] * lo.trans.d[k];
        }
        d[4] = r.d[2];
        d[5] = r.d[3];
        let basis = crown_fraction_terms(t.r_understory.v, t.r_crown_inf.v, t.t_s.v, t.t_o.v);
        for (db, b) in self.dfractions_dfc.iter().zip(basis) {
            d[6] += b * PlainLanes::<T>::c(*db);
        }
        Dual { v: r.v, d }
    }
}

/// One-shot convenience: builds an [`Inform`] over `tables` and runs [`Inform::forward`]. Prefer
/// keeping an [`Inform`] when running many spectra (it scans the resampling matrix once).
pub fn inform_s2<R: Real>(
    tables: &Tables<'_>,
    x: &[R; N_INPUTS],
    geometry: Geometry,
) -> Result<[R; N_BANDS], Error> {
    Inform::new(*tables)?.forward(x, geometry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtm::prospect::tav;

    /// A synthetic 6-wavelength grid (not the published tables): visible-like, red-edge-like and
    /// NIR-like absorption, two bands.
    struct Synthetic {
        cols: [[f64; 6]; 9],
        soil: [[f64; 6]; 2],
        sun: [[f64; 6]; 2],
        beta: [f64; 26],
        m: [f64; 12],
    }

    fn synthetic() -> Synthetic {
        let nr = [1.5, 1.49, 1.48, 1.47, 1.46, 1.45];
        let mut cols = [[0.0; 6]; 9];
        for i in 0..6 {
            cols[0][i] = nr[i];
            cols[1][i] = [0.07, 0.05, 0.02, 0.001, 0.0, 0.0][i];
            cols[2][i] = [0.15, 0.1, 0.0, 0.0, 0.0, 0.0][i];
            cols[3][i] = [0.05, 0.02, 0.0, 0.0, 0.0, 0.0][i];
            cols[4][i] = [0.5, 0.4, 0.3, 0.2, 0.1, 0.05][i];
            cols[5][i] = [1e-4, 1e-4, 1e-3, 0.01, 0.1, 20.0][i];
            cols[6][i] = [100.0, 80.0, 40.0, 10.0, 5.0, 20.0][i];
            cols[7][i] = tav(40.0, nr[i]);
            cols[8][i] = tav(90.0, nr[i]);
        }
        // Two beta rows: uniform-like and planophile-like (13 angles × 2, angle-major).
        let mut beta = [0.0; 26];
        for a in 0..13 {
            beta[2 * a] = if a < 8 { 0.1111111 } else { 0.0222222 };
            beta[2 * a + 1] = if a < 8 { (8 - a) as f64 / 36.0 } else { 0.0 };
        }
        // Band 0 averages wavelengths 0..=2, band 1 wavelengths 4..=5.
        let m = [
            1.0 / 3.0,
            0.0,
            1.0 / 3.0,
            0.0,
            1.0 / 3.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.5,
            0.0,
            0.5,
        ];
        Synthetic {
            cols,
            soil: [
                [0.2, 0.22, 0.25, 0.3, 0.35, 0.3],
                [0.05, 0.06, 0.08, 0.1, 0.12, 0.05],
            ],
            sun: [
                [1.0, 1.1, 1.2, 1.0, 0.8, 0.3],
                [2.0, 1.8, 1.0, 0.6, 0.3, 0.1],
            ],
            beta,
            m,
        }
    }

    fn tables(s: &Synthetic) -> Tables<'_> {
        let c = &s.cols;
        Tables {
            prospect: Coefficients::from_columns(c),
            soil_dry: &s.soil[0],
            soil_wet: &s.soil[1],
            es: &s.sun[0],
            ed: &s.sun[1],
            lidf_beta: &s.beta,
            resampling: &s.m,
        }
    }

    fn inputs() -> [f64; N_INPUTS] {
        let fixed = Fixed {
            lidf: 1.0,
            ..Fixed::default()
        };
        inputs_from_learned(&[1.6, 45.0, 0.012, 0.01, 2.5, 0.4, 0.6], &fixed)
    }

    #[test]
    fn forward_agrees_with_spectrum_and_lanes() {
        let s = synthetic();
        // The synthetic matrix has 2 bands, the model expects 13.
        assert!(matches!(
            Inform::new(tables(&s)),
            Err(Error::SizeMismatch { .. })
        ));
        // Rebuild with 13 bands: band 0 and 1 as above, the others empty.
        let mut m = [0.0; 6 * N_BANDS];
        for i in 0..6 {
            m[i * N_BANDS] = s.m[i * 2];
            m[i * N_BANDS + 1] = s.m[i * 2 + 1];
        }
        let t = Tables {
            resampling: &m,
            ..tables(&s)
        };
        let model = Inform::new(t).unwrap();
        for geometry in [Geometry::Reference, Geometry::Physical] {
            let y = model.forward(&inputs(), geometry).unwrap();
            let mut spec = [0.0; 6];
            model.spectrum(&inputs(), geometry, &mut spec).unwrap();
            let want0 = (spec[0] + spec[1] + spec[2]) / 3.0;
            let want1 = (spec[4] + spec[5]) / 2.0;
            assert!((y[0] - want0).abs() < 1e-15 && (y[1] - want1).abs() < 1e-15);
            assert!(y[2..].iter().all(|&v| v == 0.0));
            assert!(spec.iter().all(|&r| r > 0.0 && r < 1.0), "{spec:?}");
            // Lanes and single wavelengths give identical results.
            let scene = model.scene(&inputs(), geometry).unwrap();
            let lanes = scene
                .lanes()
                .wavelength(&model.rows::<f64, <f64 as Real>::Lanes>(0));
            for i in 0..6 {
                let one = scene.wavelength(&model.row(i).unwrap());
                let lane = |x: <f64 as Real>::Lanes| -> f64 { x.lane(i) };
                assert_eq!(lane(lanes.r_forest).to_bits(), one.r_forest.to_bits());
                assert_eq!(lane(lanes.leaf.trans).to_bits(), one.leaf.trans.to_bits());
            }
            // f32 and dual values agree with f64.
            let y32 = model
                .forward(&inputs().map(|v| v as f32), geometry)
                .unwrap();
            assert!((y32[0] as f64 - y[0]).abs() < 1e-5);
            let z = [1.6, 45.0, 0.012, 0.01, 2.5, 0.4, 0.6];
            let fixed = Fixed {
                lidf: 1.0,
                ..Fixed::default()
            };
            let (yd, jac) = model.jacobian(&z, &fixed, geometry).unwrap();
            assert!((yd[1] - y[1]).abs() < 1e-15);
            assert!(jac.iter().flatten().all(|d| d.is_finite()));
            // The split chain rule equals plain Dual<7> forward mode.
            let z7: [Dual<N_LEARNED>; N_LEARNED] = core::array::from_fn(|i| Dual::var(z[i], i));
            let full = model.forward_learned(&z7, &fixed, geometry).unwrap();
            for (row, f) in jac.iter().zip(full.iter()).take(2) {
                for (&a, &e) in row.iter().zip(f.d.iter()) {
                    assert!((a - e).abs() <= 1e-12 * (1.0 + e.abs()), "{a} {e}");
                }
            }
        }
    }

    #[test]
    fn errors() {
        let s = synthetic();
        let mut m = [0.0; 6 * N_BANDS];
        m[0] = 1.0;
        let t = Tables {
            resampling: &m,
            ..tables(&s)
        };
        let model = Inform::new(t).unwrap();
        let x = inputs();
        let mut bad = x;
        bad[20] = f64::NAN;
        assert_eq!(
            model.forward(&bad, Geometry::Reference),
            Err(Error::NonFinite {
                what: "inform input",
                index: 20
            })
        );
        let mut bad = x;
        bad[11] = 2.0; // only rows 0 and 1 exist
        assert!(matches!(
            model.forward(&bad, Geometry::Reference),
            Err(Error::OutOfRange { .. })
        ));
        assert!(model.wavelength(&x, Geometry::Reference, 6).is_err());
        assert!(model
            .spectrum(&x, Geometry::Reference, &mut [0.0; 5])
            .is_err());
        let short = Tables {
            es: &s.sun[0][..5],
            ..t
        };
        assert!(matches!(
            Inform::new(short),
            Err(Error::SizeMismatch {
                what: "solar direct",
                ..
            })
        ));
        let empty = Tables {
            lidf_beta: &[],
            ..t
        };
        assert!(Inform::new(empty).is_err());
        assert!(inform_s2(&t, &x, Geometry::Physical).is_ok());
    }
}
