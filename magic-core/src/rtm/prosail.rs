//! PROSAIL: PROSPECT-D leaves in one 4SAIL canopy layer over a soil, in Sentinel-2 bands.
//!
//! The classic canopy model alone, without INFORM's crowns: 14 inputs
//! ([`INPUT_NAMES`]: leaf N, cab, car, anth, cbrown, cw, cm; canopy LAI, mean leaf angle `ala`,
//! hotspot; sun zenith, view zenith, relative azimuth in degrees; soil brightness `psoil`) →
//! the four reflectance factors of 4SAIL ([`FACTOR_NAMES`], Verhoef's meanings: `rsot`
//! bidirectional, `rdot` hemispherical-directional, `rsdt` directional-hemispherical, `rddt`
//! bihemispherical) integrated to the 13 Sentinel-2 bands.
//!
//! It follows the published model, as the `prosail` package runs it: physical sun/view
//! geometry ([`SunView::from_degrees`]), Campbell's ellipsoidal leaf angles over 18 bins of 5°
//! ([`CampbellBins::Uniform18`]), the published hotspot rule ([`HotspotRule::Physical`]), and a
//! soil that is the `psoil` mix of the dry and wet soil spectra. It is composed from the same
//! PROSPECT-D ([`leaf_optics`]), 4SAIL ([`extinction`], [`layer`], [`medium`], [`sail`]) and band
//! integration ([`Resampling`]) as INFORM; the wavelength work runs on lanes of several
//! wavelengths ([`Real::Lanes`]) and only where some band has weight.

use super::model::{Tables, N_BANDS};
use super::prospect::{leaf_optics, CoefRow, Coefficients, Leaf};
use super::sail::{extinction, layer, medium, sail, CampbellBins, HotspotRule, Lidf, SunView};
use super::sensor::Resampling;
use crate::real::{Lanes, Real};
use crate::Error;

/// Number of inputs.
pub const N_INPUTS: usize = 14;

/// Input names, in order (the input columns of `oracle/sail_4sail_s2_1k.csv`; angles in degrees).
pub const INPUT_NAMES: [&str; N_INPUTS] = [
    "N", "cab", "car", "anth", "cbrown", "cw", "cm", "lai", "ala", "hspot", "tts", "tto", "psi",
    "psoil",
];

/// Number of reflectance factors.
pub const N_FACTORS: usize = 4;

/// The reflectance factors, in output order.
pub const FACTOR_NAMES: [&str; N_FACTORS] = ["rsot", "rdot", "rsdt", "rddt"];

/// The four reflectance factors (rows, [`FACTOR_NAMES`] order) in the 13 bands (columns).
pub type Factors<R> = [[R; N_BANDS]; N_FACTORS];

/// PROSAIL over borrowed tables (PROSPECT-D coefficients, the two soil spectra and the
/// resampling matrix of [`Tables`]; the irradiance and beta leaf-angle tables are not used).
#[derive(Clone, Copy, Debug)]
pub struct Prosail<'a> {
    prospect: Coefficients<'a>,
    soil_dry: &'a [f64],
    soil_wet: &'a [f64],
    sensor: Resampling<'a>,
}

impl<'a> Prosail<'a> {
    /// Checks the sizes of the tables it uses (every spectral column one length `n`, the
    /// resampling matrix `n × 13`) and prepares the band integration.
    pub fn new(tables: &Tables<'a>) -> Result<Self, Error> {
        let n = tables.prospect.len();
        if n == 0 {
            return Err(Error::SizeMismatch {
                what: "prospect nr",
                expected: 1,
                found: 0,
            });
        }
        for (what, col) in tables.prospect.columns() {
            crate::error::check_len(what, n, col.len())?;
        }
        crate::error::check_len("soil dry", n, tables.soil_dry.len())?;
        crate::error::check_len("soil wet", n, tables.soil_wet.len())?;
        Ok(Prosail {
            prospect: tables.prospect,
            soil_dry: tables.soil_dry,
            soil_wet: tables.soil_wet,
            sensor: Resampling::new(tables.resampling, n, N_BANDS)?,
        })
    }

    /// The four reflectance factors in the 13 bands for the 14 inputs ([`INPUT_NAMES`]).
    ///
    /// Errors: a non-finite input ([`Error::NonFinite`] with its index); N, LAI ≤ 0, a negative
    /// content or hotspot, `ala` outside (0, 90), a zenith outside [0, 90) or `psoil` outside
    /// [0, 1] ([`Error::OutOfRange`]).
    ///
    /// ```
    /// use magic_core::rtm::prospect::Coefficients;
    /// use magic_core::rtm::prosail::Prosail;
    /// use magic_core::rtm::Tables;
    /// // One wavelength, every band reading it (a toy table, not the published one).
    /// let col = |v: f64| [v];
    /// let (nr, kab, k0, kw, km) = (col(1.45), col(0.01), col(0.0), col(0.01), col(20.0));
    /// let (t12, t90) = (col(0.96), col(0.9));
    /// let (dry, wet, one) = (col(0.3), col(0.1), col(1.0));
    /// let tables = Tables {
    ///     prospect: Coefficients { nr: &nr, k_cab: &kab, k_car: &k0, k_anth: &k0,
    ///         k_brown: &k0, k_cw: &kw, k_cm: &km, t12: &t12, tav90n: &t90 },
    ///     soil_dry: &dry, soil_wet: &wet, es: &one, ed: &one, lidf_beta: &[],
    ///     resampling: &[1.0; 13],
    /// };
    /// let model = Prosail::new(&tables)?;
    /// let x = [1.5, 40.0, 8.0, 0.0, 0.0, 0.01, 0.009, 3.0, 57.0, 0.05, 30.0, 0.0, 0.0, 0.5];
    /// let [rsot, rdot, rsdt, rddt] = model.forward(&x)?;
    /// assert!([rsot[0], rdot[0], rsdt[0], rddt[0]].iter().all(|r| *r > 0.0 && *r < 1.0));
    /// # Ok::<(), magic_core::Error>(())
    /// ```
    pub fn forward<R: Real>(&self, x: &[R; N_INPUTS]) -> Result<Factors<R>, Error> {
        validate(x)?;
        let [n, cab, car, anth, cbrown, cw, cm, lai, ala, hspot, tts, tto, psi, psoil] = *x;
        // Per spectrum: leaf angles, extinction and the layer (no wavelength).
        let lidf = Lidf::campbell(ala, CampbellBins::Uniform18)?;
        let ext = extinction(&SunView::from_degrees(tts, tto, psi), &lidf);
        let lay = layer(&ext, lai, hspot, HotspotRule::Physical);
        let leaf = Leaf {
            n,
            cab,
            car,
            anth,
            cbrown,
            cw,
            cm,
        };
        // Per wavelength, several at a time.
        let splat = <R::Lanes as Lanes<R>>::splat;
        let (ext, lay, leaf, psoil) = (
            ext.map(splat),
            lay.map(splat),
            leaf.map(splat),
            splat(psoil),
        );
        let width = <R::Lanes as Lanes<R>>::WIDTH;
        let mut out = [[R::zero(); N_BANDS]; N_FACTORS];
        for &(a, b) in self.sensor.spans() {
            for i0 in (a..=b).step_by(width.max(1)) {
                let (coef, dry, wet) = self.rows::<R, R::Lanes>(i0);
                let soil = psoil.scale(dry) + (<R::Lanes as Real>::one() - psoil).scale(wet);
                let o = sail(&ext, &lay, &medium(ext.bf, leaf_optics(&coef, &leaf)), soil);
                for (j, i) in (i0..=b.min(i0 + width - 1)).enumerate() {
                    for (f, v) in out.iter_mut().zip([o.rsot, o.rdot, o.rsdt, o.rddt]) {
                        self.sensor.accumulate(i, v.lane(j), f);
                    }
                }
            }
        }
        Ok(out)
    }

    /// PROSPECT-D coefficients and the two soils at wavelength indices `i0, i0 + 1, …` as
    /// lanes (indices past the grid read its last row).
    #[inline]
    fn rows<S: Real, W: Lanes<S>>(&self, i0: usize) -> (CoefRow<W::Plain>, W::Plain, W::Plain) {
        let lanes = |col: &[f64]| {
            W::plain_from_fn(|j| col.get(i0 + j).or(col.last()).copied().unwrap_or(0.0))
        };
        let p = &self.prospect;
        let coef = CoefRow {
            nr: lanes(p.nr),
            k_cab: lanes(p.k_cab),
            k_car: lanes(p.k_car),
            k_anth: lanes(p.k_anth),
            k_brown: lanes(p.k_brown),
            k_cw: lanes(p.k_cw),
            k_cm: lanes(p.k_cm),
            t12: lanes(p.t12),
            tav90n: lanes(p.tav90n),
        };
        (coef, lanes(self.soil_dry), lanes(self.soil_wet))
    }
}

/// Checks the 14 inputs: finite, and inside the model's domain.
fn validate<R: Real>(x: &[R; N_INPUTS]) -> Result<(), Error> {
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "prosail input",
            index,
        });
    }
    let v = |i: usize| x[i].value();
    if v(0) <= 0.0 {
        return Err(Error::OutOfRange {
            what: "N (must be > 0)",
        });
    }
    for (i, what) in [
        (1, "cab (must be >= 0)"),
        (2, "car (must be >= 0)"),
        (3, "anth (must be >= 0)"),
        (4, "cbrown (must be >= 0)"),
        (5, "cw (must be >= 0)"),
        (6, "cm (must be >= 0)"),
        (9, "hspot (must be >= 0)"),
    ] {
        if v(i) < 0.0 {
            return Err(Error::OutOfRange { what });
        }
    }
    if v(7) <= 0.0 {
        return Err(Error::OutOfRange {
            what: "lai (must be > 0)",
        });
    }
    if !(0.0..90.0).contains(&v(10)) {
        return Err(Error::OutOfRange {
            what: "tts (0..90 degrees)",
        });
    }
    if !(0.0..90.0).contains(&v(11)) {
        return Err(Error::OutOfRange {
            what: "tto (0..90 degrees)",
        });
    }
    if !(0.0..=1.0).contains(&v(13)) {
        return Err(Error::OutOfRange {
            what: "psoil (0..1)",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Dual;

    /// A synthetic grid of 4 wavelengths (not the published tables): visible-like to NIR-like
    /// absorption; band 0 averages wavelengths 0..=1, band 1 reads wavelength 3, the others
    /// nothing.
    struct Synthetic {
        cols: [[f64; 4]; 9],
        soil: [[f64; 4]; 2],
        m: [f64; 4 * N_BANDS],
    }

    fn synthetic() -> Synthetic {
        let nr = [1.5, 1.49, 1.47, 1.45];
        let mut cols = [[0.0; 4]; 9];
        for i in 0..4 {
            cols[0][i] = nr[i];
            cols[1][i] = [0.07, 0.02, 0.001, 0.0][i];
            cols[2][i] = [0.15, 0.0, 0.0, 0.0][i];
            cols[3][i] = [0.05, 0.0, 0.0, 0.0][i];
            cols[4][i] = [0.5, 0.3, 0.2, 0.05][i];
            cols[5][i] = [1e-4, 1e-3, 0.01, 20.0][i];
            cols[6][i] = [100.0, 40.0, 10.0, 20.0][i];
            cols[7][i] = crate::rtm::prospect::tav(40.0, nr[i]);
            cols[8][i] = crate::rtm::prospect::tav(90.0, nr[i]);
        }
        let mut m = [0.0; 4 * N_BANDS];
        m[0] = 0.5;
        m[N_BANDS] = 0.5;
        m[3 * N_BANDS + 1] = 1.0;
        Synthetic {
            cols,
            soil: [[0.2, 0.25, 0.3, 0.35], [0.05, 0.08, 0.1, 0.12]],
            m,
        }
    }

    fn tables(s: &Synthetic) -> Tables<'_> {
        let c = &s.cols;
        Tables {
            prospect: Coefficients::from_columns(c),
            soil_dry: &s.soil[0],
            soil_wet: &s.soil[1],
            es: &s.soil[0],
            ed: &s.soil[0],
            lidf_beta: &[],
            resampling: &s.m,
        }
    }

    const X: [f64; N_INPUTS] = [
        1.6, 45.0, 9.0, 1.0, 0.1, 0.012, 0.01, 2.5, 50.0, 0.05, 35.0, 10.0, 60.0, 0.6,
    ];

    /// The composed functions evaluated one wavelength at a time, as a reader would write them.
    fn scalar(t: &Tables<'_>, x: &[f64; N_INPUTS]) -> Factors<f64> {
        let lidf = Lidf::campbell(x[8], CampbellBins::Uniform18).unwrap();
        let e = extinction(&SunView::from_degrees(x[10], x[11], x[12]), &lidf);
        let l = layer(&e, x[7], x[9], HotspotRule::Physical);
        let leaf = Leaf {
            n: x[0],
            cab: x[1],
            car: x[2],
            anth: x[3],
            cbrown: x[4],
            cw: x[5],
            cm: x[6],
        };
        let sensor = Resampling::new(t.resampling, t.prospect.len(), N_BANDS).unwrap();
        let mut out = [[0.0; N_BANDS]; N_FACTORS];
        for (k, f) in out.iter_mut().enumerate() {
            sensor
                .integrate(
                    |i| {
                        let optics = leaf_optics(&t.prospect.row(i).unwrap(), &leaf);
                        let soil = x[13] * t.soil_dry[i] + (1.0 - x[13]) * t.soil_wet[i];
                        let o = sail(&e, &l, &medium(e.bf, optics), soil);
                        [o.rsot, o.rdot, o.rsdt, o.rddt][k]
                    },
                    f,
                )
                .unwrap();
        }
        out
    }

    #[test]
    fn lanes_equal_one_wavelength_at_a_time() {
        let s = synthetic();
        let t = tables(&s);
        let y = Prosail::new(&t).unwrap().forward(&X).unwrap();
        let want = scalar(&t, &X);
        for (a, b) in y.iter().flatten().zip(want.iter().flatten()) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a} {b}");
        }
        for f in &y {
            assert!(f[..2].iter().all(|r| *r > 0.0 && *r < 1.0), "{y:?}");
            assert!(f[2..].iter().all(|r| *r == 0.0));
        }
    }

    #[test]
    fn thin_canopy_shows_the_soil() {
        let s = synthetic();
        let model = Prosail::new(&tables(&s)).unwrap();
        let mut x = X;
        x[7] = 1e-6;
        let y = model.forward(&x).unwrap();
        let soil = |i: usize| 0.6 * s.soil[0][i] + 0.4 * s.soil[1][i];
        let want = [0.5 * (soil(0) + soil(1)), soil(3)];
        for f in &y {
            for b in 0..2 {
                assert!((f[b] - want[b]).abs() < 1e-5, "{} {}", f[b], want[b]);
            }
        }
    }

    #[test]
    fn f32_and_dual_agree_with_f64() {
        let s = synthetic();
        let model = Prosail::new(&tables(&s)).unwrap();
        let y = model.forward(&X).unwrap();
        let y32 = model.forward(&X.map(|v| v as f32)).unwrap();
        for (a, b) in y.iter().flatten().zip(y32.iter().flatten()) {
            assert!((a - *b as f64).abs() < 1e-5, "{a} {b}");
        }
        // d(factor)/d(LAI) by dual numbers against a central difference.
        let mut xd = X.map(Dual::<1>::constant);
        xd[7] = Dual::var(X[7], 0);
        let yd = model.forward(&xd).unwrap();
        let h = 1e-6;
        let (mut xp, mut xm) = (X, X);
        xp[7] += h;
        xm[7] -= h;
        let (yp, ym) = (model.forward(&xp).unwrap(), model.forward(&xm).unwrap());
        for k in 0..N_FACTORS {
            for b in 0..2 {
                assert!(
                    (yd[k][b].v - y[k][b]).abs() <= 1e-15,
                    "{} {}",
                    yd[k][b].v,
                    y[k][b]
                );
                let fd = (yp[k][b] - ym[k][b]) / (2.0 * h);
                assert!((yd[k][b].d[0] - fd).abs() < 1e-7, "{} {fd}", yd[k][b].d[0]);
            }
        }
    }

    #[test]
    fn errors() {
        let s = synthetic();
        let t = tables(&s);
        let model = Prosail::new(&t).unwrap();
        let mut bad = X;
        bad[4] = f64::NAN;
        assert_eq!(
            model.forward(&bad),
            Err(Error::NonFinite {
                what: "prosail input",
                index: 4
            })
        );
        for (i, v) in [
            (0, 0.0),
            (1, -1.0),
            (7, 0.0),
            (8, 90.0),
            (9, -0.1),
            (10, 90.0),
            (11, -1.0),
            (13, 1.5),
        ] {
            let mut bad = X;
            bad[i] = v;
            assert!(
                matches!(model.forward(&bad), Err(Error::OutOfRange { .. })),
                "input {i} = {v}"
            );
        }
        let short = Tables {
            soil_wet: &s.soil[1][..3],
            ..t
        };
        assert!(matches!(
            Prosail::new(&short),
            Err(Error::SizeMismatch {
                what: "soil wet",
                ..
            })
        ));
        let no_bands = Tables {
            resampling: &s.m[..4],
            ..t
        };
        assert!(Prosail::new(&no_bands).is_err());
    }
}
