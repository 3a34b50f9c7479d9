//! PROSPECT-D leaf optics at one wavelength (Féret et al. 2017; plate model of Jacquemoud & Baret
//! 1990 with Stokes' equations for N layers, Allen's transmissivity `tav`).
//!
//! A leaf is `N` identical absorbing plates separated by air. The absorption coefficient of one
//! plate is the content-weighted sum of the specific absorption coefficients divided by `N`:
//!
//! ```text
//! k = (cab·k_cab + car·k_car + anth·k_anth + cbrown·k_brown + cw·k_cw + cm·k_cm) / N
//! τ = (1 − k)·e^(−k) + k²·E1(k)                       (transmissivity of one plate's interior)
//! ```
//!
//! The surface of a plate transmits `tav(40°, n)` of the incident light (`t12`, rough upper
//! surface) and `tav(90°, n)` of diffuse light (`tav90n`); both are precomputed per wavelength in
//! the coefficient table. The elementary layer's reflectance `ra` and transmittance `ta` follow
//! from the interface terms and τ; the N-layer leaf from Stokes' system solved for `N − 1` more
//! layers (`r90`, `t90`, `va`, `vb`).
//!
//! Numerical guards reproduced from the reference implementation (they change outputs, so they are
//! part of the model): a plate absorption `k = 0` is replaced by the f64 machine epsilon, and the
//! denominator `va·(β − r90)` of `vb` is floored at 1e-14.

use crate::real::{Cmp, Real};

/// One row of the PROSPECT-D coefficient table (one wavelength), in `f64` as read from the
/// table, or in another plain type (`f32`, or lanes holding one wavelength each).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoefRow<T = f64> {
    /// Refractive index of the leaf material.
    pub nr: T,
    /// Specific absorption of chlorophyll a+b (cm² µg⁻¹).
    pub k_cab: T,
    /// Specific absorption of carotenoids (cm² µg⁻¹).
    pub k_car: T,
    /// Specific absorption of anthocyanins (cm² µg⁻¹).
    pub k_anth: T,
    /// Specific absorption of brown pigments (arbitrary units).
    pub k_brown: T,
    /// Specific absorption of water (cm⁻¹).
    pub k_cw: T,
    /// Specific absorption of dry matter (cm² g⁻¹).
    pub k_cm: T,
    /// `tav(40°, nr)`: transmissivity of the upper leaf surface.
    pub t12: T,
    /// `tav(90°, nr)`: transmissivity of a surface for isotropic light.
    pub tav90n: T,
}

impl<T: Copy> CoefRow<T> {
    /// The row with `f` applied to every value (to convert it to another plain type).
    #[inline]
    pub fn map<U>(&self, f: impl Fn(T) -> U) -> CoefRow<U> {
        CoefRow {
            nr: f(self.nr),
            k_cab: f(self.k_cab),
            k_car: f(self.k_car),
            k_anth: f(self.k_anth),
            k_brown: f(self.k_brown),
            k_cw: f(self.k_cw),
            k_cm: f(self.k_cm),
            t12: f(self.t12),
            tav90n: f(self.tav90n),
        }
    }
}

/// The PROSPECT-D coefficient table as borrowed columns (one value per wavelength, all the same
/// length), as in `prospect_d_coefficients.csv`.
#[derive(Clone, Copy, Debug)]
pub struct Coefficients<'a> {
    /// Refractive index.
    pub nr: &'a [f64],
    /// Chlorophyll a+b specific absorption.
    pub k_cab: &'a [f64],
    /// Carotenoid specific absorption.
    pub k_car: &'a [f64],
    /// Anthocyanin specific absorption.
    pub k_anth: &'a [f64],
    /// Brown pigment specific absorption.
    pub k_brown: &'a [f64],
    /// Water specific absorption.
    pub k_cw: &'a [f64],
    /// Dry matter specific absorption.
    pub k_cm: &'a [f64],
    /// `tav(40°, nr)`.
    pub t12: &'a [f64],
    /// `tav(90°, nr)`.
    pub tav90n: &'a [f64],
}

impl<'a> Coefficients<'a> {
    /// The nine columns in the file's order: `nr, k_cab, k_car, k_anth, k_brown, k_cw, k_cm, t12,
    /// tav90n`.
    pub fn from_columns<C: AsRef<[f64]>>(c: &'a [C; 9]) -> Self {
        Coefficients {
            nr: c[0].as_ref(),
            k_cab: c[1].as_ref(),
            k_car: c[2].as_ref(),
            k_anth: c[3].as_ref(),
            k_brown: c[4].as_ref(),
            k_cw: c[5].as_ref(),
            k_cm: c[6].as_ref(),
            t12: c[7].as_ref(),
            tav90n: c[8].as_ref(),
        }
    }

    /// Number of wavelengths (length of the `nr` column).
    pub fn len(&self) -> usize {
        self.nr.len()
    }

    /// Whether the table has no wavelength.
    pub fn is_empty(&self) -> bool {
        self.nr.is_empty()
    }

    /// The columns with their names, for size checks.
    pub fn columns(&self) -> [(&'static str, &'a [f64]); 9] {
        [
            ("prospect nr", self.nr),
            ("prospect k_cab", self.k_cab),
            ("prospect k_car", self.k_car),
            ("prospect k_anth", self.k_anth),
            ("prospect k_brown", self.k_brown),
            ("prospect k_cw", self.k_cw),
            ("prospect k_cm", self.k_cm),
            ("prospect t12", self.t12),
            ("prospect tav90n", self.tav90n),
        ]
    }

    /// The row of wavelength index `i`, or `None` when `i` is past the end of any column.
    #[inline]
    pub fn row(&self, i: usize) -> Option<CoefRow> {
        Some(CoefRow {
            nr: *self.nr.get(i)?,
            k_cab: *self.k_cab.get(i)?,
            k_car: *self.k_car.get(i)?,
            k_anth: *self.k_anth.get(i)?,
            k_brown: *self.k_brown.get(i)?,
            k_cw: *self.k_cw.get(i)?,
            k_cm: *self.k_cm.get(i)?,
            t12: *self.t12.get(i)?,
            tav90n: *self.tav90n.get(i)?,
        })
    }
}

/// PROSPECT-D leaf parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leaf<R> {
    /// Leaf structure parameter (number of plates, ≥ 1 for real leaves).
    pub n: R,
    /// Chlorophyll a+b content (µg cm⁻²).
    pub cab: R,
    /// Carotenoid content (µg cm⁻²).
    pub car: R,
    /// Anthocyanin content (µg cm⁻²).
    pub anth: R,
    /// Brown pigment content (arbitrary units).
    pub cbrown: R,
    /// Equivalent water thickness (cm).
    pub cw: R,
    /// Dry matter content (g cm⁻²).
    pub cm: R,
}

impl<R: Copy> Leaf<R> {
    /// The parameters with `f` applied to each (to broadcast them to lanes).
    pub fn map<S>(&self, f: impl Fn(R) -> S) -> Leaf<S> {
        Leaf {
            n: f(self.n),
            cab: f(self.cab),
            car: f(self.car),
            anth: f(self.anth),
            cbrown: f(self.cbrown),
            cw: f(self.cw),
            cm: f(self.cm),
        }
    }
}

/// Leaf hemispherical reflectance and transmittance at one wavelength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafOptics<R> {
    /// Reflectance.
    pub refl: R,
    /// Transmittance.
    pub trans: R,
}

/// Floor of `va·(β − r90)` in the `vb` term (reference implementation).
const VB_FLOOR: f64 = 1e-14;

/// PROSPECT-D reflectance and transmittance of a leaf at the wavelength of `c` (the table row
/// in the plain type of `R`: `f64` for `f64` and duals, lanes of rows for lanes).
///
/// Written as scalar code; on lanes ([`crate::real::F64x4`]) it evaluates four wavelengths at
/// once, each lane taking its own branch of the guards (see [`Real::select`]).
///
/// ```
/// use magic_core::rtm::prospect::{leaf_optics, CoefRow, Leaf};
/// let c = CoefRow { nr: 1.45, k_cab: 0.0, k_car: 0.0, k_anth: 0.0, k_brown: 0.0,
///                   k_cw: 0.2, k_cm: 10.0, t12: 0.965, tav90n: 0.92 };
/// let leaf = Leaf { n: 1.5, cab: 40.0, car: 10.0, anth: 2.0, cbrown: 0.0, cw: 0.01, cm: 0.01 };
/// let o = leaf_optics(&c, &leaf);
/// assert!(o.refl > 0.0 && o.trans > 0.0 && o.refl + o.trans < 1.0);
/// ```
#[inline]
pub fn leaf_optics<R: Real>(c: &CoefRow<R::Plain>, leaf: &Leaf<R>) -> LeafOptics<R> {
    let one = R::one();
    let tau = plate_interior(c, leaf);
    let plate = elementary_layer(c, tau);
    let (va, va_inv, vb2) = stokes_terms(plate.r90, plate.t90);
    // The N − 1 further layers (Stokes): with vbnn = vb^(N−1) (ln vb = ln(vb²)/2),
    //   d = vbnn − 1/vbnn,  s3 = va·vbnn − 1/(va·vbnn) − r90·d,
    //   R = ra + ta·t90·d/s3,  T = ta·(va − 1/va)/s3,
    // multiplied through by vbnn, with W = vbnn²: d·vbnn = W − 1 and
    // s3·vbnn = va·W − 1/va − r90·(W − 1) (one division instead of two).
    let vbnn = ((leaf.n - one) * R::c(0.5) * vb2.ln()).exp();
    let w = vbnn * vbnn;
    let inv = one / (va * w - va_inv - plate.r90 * (w - one));
    LeafOptics {
        refl: plate.ra + plate.ta * plate.t90 * (w - one) * inv,
        trans: plate.ta * (va - va_inv) * vbnn * inv,
    }
}

/// The transmissivity `τ` of one plate's interior: the plate absorption `k` from the contents
/// and specific absorptions, then `τ(k) = (1 − k)·e^(−k) + k²·E1(k)` (as
/// [`plate_transmissivity`]).
#[inline]
fn plate_interior<R: Real>(c: &CoefRow<R::Plain>, leaf: &Leaf<R>) -> R {
    let k = (leaf.cab.scale(c.k_cab)
        + leaf.car.scale(c.k_car)
        + leaf.anth.scale(c.k_anth)
        + leaf.cbrown.scale(c.k_brown)
        + leaf.cw.scale(c.k_cw)
        + leaf.cm.scale(c.k_cm))
        * (R::one() / leaf.n);
    // Reference guard: E1(0) is infinite; the reference substitutes the f64 epsilon.
    let k = k.select(Cmp::Eq(0.0), || R::c(f64::EPSILON), || k);
    let (e1, ek) = k.e1_and_exp();
    (R::one() - k) * ek + k * k * e1
}

/// The elementary layer (N = 1): reflectance and transmittance for the incident light and for
/// isotropic light at both faces.
struct Plate<R> {
    ra: R,
    ta: R,
    r90: R,
    t90: R,
}

/// The elementary layer from the rough upper surface (`t12`), the interior `tau` and the lower
/// surface for isotropic light (`tav90n`). The isotropic case replaces `t12` by `tav90n` at the
/// upper surface: `r90 = (ra − (1 − t12))·tav90n/t12 + 1 − tav90n`, `t90 = ta·tav90n/t12`, with
/// `ra − (1 − t12)` the light scattered back out of the interior (computed directly, so no
/// cancellation).
#[inline]
fn elementary_layer<R: Real>(c: &CoefRow<R::Plain>, tau: R) -> Plate<R> {
    let one = <R::Plain as Real>::one();
    let t21 = c.tav90n / (c.nr * c.nr);
    let r21 = one - t21;
    let inv_den = R::one() / (R::one() - (tau * tau).scale(r21 * r21));
    let ta = tau.scale(c.t12 * t21) * inv_den;
    let scattered = ta.scale(r21) * tau;
    let inv_x = c.tav90n / c.t12;
    Plate {
        ra: R::from_plain(one - c.t12) + scattered,
        ta,
        r90: scattered.scale(inv_x) + R::from_plain(one - c.tav90n),
        t90: ta.scale(inv_x),
    }
}

/// Stokes' terms `(va, 1/va, vb²)` of a layer with diffuse reflectance `r` and transmittance
/// `t`, in a cancellation-free form (the textbook form loses up to 4 digits in β − r when the
/// plate is nearly opaque, too many for f32):
///
/// ```text
/// A = 1 + r² − t²,  B = 1 − r² + t²,  δ = sqrt(A² − 4r²) = sqrt((1 − (r+t)²)(1 − (r−t)²)),
/// C = 1 − r² − t² + δ,  va = (A + δ)/(2r),  β = 1/va = 2r/(A + δ),  va − r = C/(2r),
/// va·(β − r) = 2t²/(B + δ),  vb² = β·(va − r) / (va·(β − r)) = C·(B + δ) / ((A + δ)·2t²).
/// ```
///
/// The reference floors `va·(β − r)` at 1e-14, i.e. `2t²` at `g = 1e-14·(B + δ)`. The three
/// terms share one division `e = 1/((A + δ)·2r·g)`: `va = (A + δ)²·g·e`, `β = (2r)²·g·e`,
/// `vb² = C·(B + δ)·2r·e`.
#[inline]
fn stokes_terms<R: Real>(r: R, t: R) -> (R, R, R) {
    let one = R::one();
    let two = R::c(2.0);
    let delta = ((one - (r + t) * (r + t)) * (one - (r - t) * (r - t))).sqrt();
    let (r2, t2) = (r * r, t * t);
    let a_plus = one + r2 - t2 + delta;
    let b_plus = one - r2 + t2 + delta;
    let c = one - r2 - t2 + delta;
    let two_r = two * r;
    let g = (two * t2).max(b_plus * R::c(VB_FLOOR));
    let e = one / (a_plus * two_r * g);
    let ge = g * e;
    (
        a_plus * a_plus * ge,
        two_r * two_r * ge,
        c * b_plus * two_r * e,
    )
}

/// The transmissivity of a plate's interior `τ(k) = (1 − k)·e^(−k) + k²·E1(k)` and its derivative
/// `dτ/dk = 2·(k·E1(k) − e^(−k))`.
#[inline]
pub fn plate_transmissivity(k: f64) -> (f64, f64) {
    let ek = libm::exp(-k);
    let e1 = crate::real::e1_with_exp(k, ek);
    ((1.0 - k) * ek + k * k * e1, 2.0 * (k * e1 - ek))
}

/// Allen's average transmissivity of a dielectric plane surface for light incident within a
/// solid angle of half-angle `alpha_deg` (degrees), refractive index `nr` (Stern 1964; Allen 1973).
///
/// The coefficient table carries `tav(40°)` and `tav(90°)` precomputed; this function lets users
/// build a table for another refractive index and is checked against those columns in the tests.
pub fn tav(alpha_deg: f64, nr: f64) -> f64 {
    use core::f64::consts::PI;
    let n2 = nr * nr;
    let np = n2 + 1.0;
    let nm = n2 - 1.0;
    let a = (nr + 1.0) * (nr + 1.0) / 2.0;
    let k = -(n2 - 1.0) * (n2 - 1.0) / 4.0;
    let sa = libm::sin(alpha_deg * PI / 180.0);
    if alpha_deg == 0.0 {
        return 4.0 * nr / ((nr + 1.0) * (nr + 1.0));
    }
    let b2 = sa * sa - np / 2.0;
    let b1 = if alpha_deg == 90.0 {
        0.0
    } else {
        libm::sqrt(b2 * b2 + k)
    };
    let b = b1 - b2;
    let b3 = b * b * b;
    let a3 = a * a * a;
    let ts = (k * k / (6.0 * b3) + k / b - b / 2.0) - (k * k / (6.0 * a3) + k / a - a / 2.0);
    let tp1 = -2.0 * n2 * (b - a) / (np * np);
    let tp2 = -2.0 * n2 * np * libm::log(b / a) / (nm * nm);
    let tp3 = n2 * (1.0 / b - 1.0 / a) / 2.0;
    let tp4 = 16.0
        * n2
        * n2
        * (n2 * n2 + 1.0)
        * libm::log((2.0 * np * b - nm * nm) / (2.0 * np * a - nm * nm))
        / (np * np * np * nm * nm);
    let tp5 =
        16.0 * n2 * n2 * n2 * (1.0 / (2.0 * np * b - nm * nm) - 1.0 / (2.0 * np * a - nm * nm))
            / (np * np * np);
    let tp = tp1 + tp2 + tp3 + tp4 + tp5;
    (ts + tp) / (2.0 * sa * sa)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Dual;

    fn row(nr: f64, k_cab: f64, k_cw: f64, k_cm: f64) -> CoefRow {
        CoefRow {
            nr,
            k_cab,
            k_car: 0.01,
            k_anth: 0.005,
            k_brown: 0.1,
            k_cw,
            k_cm,
            t12: tav(40.0, nr),
            tav90n: tav(90.0, nr),
        }
    }

    fn leaf(n: f64) -> Leaf<f64> {
        Leaf {
            n,
            cab: 40.0,
            car: 10.0,
            anth: 2.0,
            cbrown: 0.25,
            cw: 0.01,
            cm: 0.01,
        }
    }

    #[test]
    fn plate_transmissivity_derivative() {
        for &k in &[1e-6, 0.1, 1.0, 2.0, 2.5, 7.0, 30.0] {
            let (_, d) = plate_transmissivity(k);
            let h = 1e-3 * k;
            let fd = (plate_transmissivity(k + h).0 - plate_transmissivity(k - h).0) / (2.0 * h);
            assert!((d - fd).abs() < 1e-6 * (1.0 + fd.abs()), "k {k}: {d} {fd}");
        }
    }

    #[test]
    fn tav_matches_table_values() {
        // Values of the published coefficient table at 400 nm (nr = 1.5115).
        assert!((tav(40.0, 1.5115) - 0.9569218055075089).abs() < 1e-12);
        assert!((tav(90.0, 1.5115) - 0.9065355562992279).abs() < 1e-12);
    }

    #[test]
    fn energy_is_conserved() {
        for &(kc, kw, km) in &[
            (0.0, 0.0, 0.0),
            (0.05, 1e-4, 100.0),
            (1e-4, 50.0, 10.0),
            (0.0, 1e-5, 1.0),
        ] {
            for &n in &[1.0, 1.5, 2.5, 3.0] {
                let o = leaf_optics(&row(1.45, kc, kw, km), &leaf(n));
                assert!(o.refl > 0.0 && o.trans >= 0.0, "{o:?}");
                assert!(o.refl + o.trans <= 1.0 + 1e-12, "{o:?}");
            }
        }
    }

    #[test]
    fn zero_absorption_is_guarded() {
        let c = CoefRow {
            nr: 1.45,
            k_cab: 0.0,
            k_car: 0.0,
            k_anth: 0.0,
            k_brown: 0.0,
            k_cw: 0.0,
            k_cm: 0.0,
            t12: 0.96,
            tav90n: 0.9,
        };
        let o = leaf_optics(&c, &leaf(1.5));
        assert!(o.refl.is_finite() && o.trans.is_finite());
        // Almost no absorption: nearly all light is reflected or transmitted.
        assert!((o.refl + o.trans - 1.0).abs() < 1e-6, "{o:?}");
    }

    #[test]
    fn more_layers_reflect_more() {
        let c = row(1.45, 1e-4, 1e-3, 5.0);
        let r1 = leaf_optics(&c, &leaf(1.0)).refl;
        let r2 = leaf_optics(&c, &leaf(2.0)).refl;
        assert!(r2 > r1);
    }

    #[test]
    fn dual_matches_central_differences() {
        let c = row(1.45, 0.02, 0.5, 20.0);
        for &n in &[1.0, 1.7, 2.9] {
            let l = Leaf {
                n: Dual::<2>::var(n, 0),
                cab: Dual::var(35.0, 1),
                car: Dual::c(10.0),
                anth: Dual::c(2.0),
                cbrown: Dual::c(0.25),
                cw: Dual::c(0.01),
                cm: Dual::c(0.02),
            };
            let o = leaf_optics(&c, &l);
            let f = |n: f64, cab: f64| {
                leaf_optics(
                    &c,
                    &Leaf {
                        n,
                        cab,
                        car: 10.0,
                        anth: 2.0,
                        cbrown: 0.25,
                        cw: 0.01,
                        cm: 0.02,
                    },
                )
            };
            let h = 1e-6;
            let dn = (f(n + h, 35.0).refl - f(n - h, 35.0).refl) / (2.0 * h);
            let dc = (f(n, 35.0 + h).trans - f(n, 35.0 - h).trans) / (2.0 * h);
            assert!(
                (o.refl.d[0] - dn).abs() < 1e-7 * (1.0 + dn.abs()),
                "{} {dn}",
                o.refl.d[0]
            );
            assert!(
                (o.trans.d[1] - dc).abs() < 1e-7 * (1.0 + dc.abs()),
                "{} {dc}",
                o.trans.d[1]
            );
        }
    }

    #[test]
    fn f32_close_to_f64() {
        let c = row(1.45, 0.02, 0.5, 20.0);
        let o64 = leaf_optics(&c, &leaf(1.7));
        let l32 = Leaf {
            n: 1.7f32,
            cab: 40.0,
            car: 10.0,
            anth: 2.0,
            cbrown: 0.25,
            cw: 0.01,
            cm: 0.01,
        };
        let o32 = leaf_optics(&c.map(|v| v as f32), &l32);
        assert!((o32.refl as f64 - o64.refl).abs() < 1e-5);
        assert!((o32.trans as f64 - o64.trans).abs() < 1e-5);
    }
}
