//! INFORM, the INvertible FOrest Reflectance Model (Atzberger 2000; Schlerf & Atzberger 2006):
//! FLIM's mixture of crowns, shadows and gaps (Rosema et al. 1992) with 4SAIL for the optics.
//!
//! A stand is an understory (4SAIL with `LAIu` on the soil) under tree crowns of diameter `cd`,
//! height `h`, at stem density `sd` per hectare. 4SAIL gives
//!
//! * the understory reflectance `r_u` (LAIu over soil),
//! * the reflectance of an optically thick crown layer `r_inf` (LAI = 15 over the understory),
//! * the crown transmittances `t_s` (sun direction) and `t_o` (view direction) of a crown layer
//!   with the single-tree LAI over the understory, hotspot 0.
//!
//! The crown geometry gives the crown cover seen from the view (`co`) and sun (`cs`) directions,
//! `co = 1 − exp(−k·sd / cos θo)`, `cs = 1 − exp(−k·sd / cos θs)`, `k = π (cd/2)² / 10⁴`, the
//! correlation of crowns and their shadows `p = exp(−g·h/cd)` with
//! `g = sqrt(tan²θo + tan²θs − 2 tan θo tan θs cos ψ)`, and four area fractions (crowns over shaded
//! / sunlit ground, shaded / sunlit gaps) from which
//!
//! ```text
//! G = Fcd·t_s·t_o + Fcs·t_o + Fod·t_s + Fos,   C = Fcd·(1 − t_s·t_o),   R = r_inf·C + r_u·G.
//! ```
//!
//! ## Two geometry modes, one physics
//!
//! [`Geometry::Reference`] reproduces the paper's reference implementation exactly, including
//! three departures from the published model (all geometry or bookkeeping, none in the optics):
//!
//! 1. The view-direction crown "transmittance" call replaces the sun angle by the view angle but
//!    sets **both** `sin θs` and `cos θs` to `cos θo` (so its `ks`, `sob`, `sof` are those of an
//!    impossible direction), see [`SunView::reference_view_transmittance`].
//! 2. The crown-geometry terms receive, where they expect the sun zenith, view zenith and
//!    relative azimuth **in radians**, the values `cos θo`, `cos θo` and `cos ψ` left in the 4SAIL
//!    state by that call. For the training geometry (θo = 0, ψ = 0) INFORM therefore sees
//!    θs = θo = ψ = 1 rad (57.3°) instead of θs = 30°, θo = 0, ψ = 0.
//! 3. The crown "transmittances" are not transmittances but the reflectance-type quantity that
//!    4SAIL returns in that mode, `rdot·skyl + rsot·(1 − skyl)`.
//!
//! The 4SAIL hotspot is also treated as the reference does ([`HotspotRule::Reference`]).
//!
//! [`Geometry::Physical`] uses the published equations with the true angles: the crown geometry
//! gets θs, θo, ψ; ψ is folded into [0°, 180°]; both transmittances come from one consistent 4SAIL
//! run of the crown layer over the understory (by reciprocity the view-direction transmittance
//! uses `too` and `tdo`), as in Atzberger's `TRANS_S`:
//!
//! ```text
//! t_s = (1 − skyl)·(tss + (tsd + tss·r_u·rdd) / (1 − r_u·rdd)) + skyl·tdd / (1 − r_u·rdd)
//! t_o = (1 − skyl)·(too + (tdo + too·r_u·rdd) / (1 − r_u·rdd)) + skyl·tdd / (1 − r_u·rdd)
//! ```
//!
//! and the hotspot follows [`HotspotRule::Physical`]. Everything else (PROSPECT-D, 4SAIL, the
//! direct/diffuse weighting, FLIM) is the same code in both modes.

use super::prospect::{leaf_optics, CoefRow, Leaf, LeafOptics};
use super::sail::{
    directional, directional_sun, extinction, irradiance_weights, layer, medium, sail_sun,
    sail_view, skyl, slab, sqrt0, tan_distance, view_terms, Extinction, HotspotRule, Layer, Lidf,
    SailOutput, SunView,
};
use crate::real::{Lanes, Real};
use core::f64::consts::PI;

/// LAI of the optically thick crown layer (reference value).
pub const CROWN_INF_LAI: f64 = 15.0;

/// Which geometry INFORM is run with (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Geometry {
    /// Bit-for-bit the paper's reference implementation, including its geometry slips.
    Reference,
    /// The published equations with the true sun zenith, view zenith and relative azimuth.
    Physical,
}

/// FLIM crown-geometry terms (no wavelength).
#[derive(Clone, Copy, Debug)]
pub struct CrownGeometry<R> {
    /// Crown projection area per stem (ha): `π (cd/2)² / 10⁴`.
    pub k: R,
    /// Crown cover seen from the view direction.
    pub co: R,
    /// Crown cover seen from the sun (shadow cover).
    pub cs: R,
    /// Geometrical factor `sqrt(tan²θo + tan²θs − 2 tan θo tan θs cos ψ)`.
    pub g: R,
    /// Correlation between crowns and their shadows, `exp(−g·h/cd)`.
    pub p: R,
    /// Fraction of crowns over shaded background.
    pub fcd: R,
    /// Fraction of crowns over sunlit background.
    pub fcs: R,
    /// Fraction of shaded gaps.
    pub fod: R,
    /// Fraction of sunlit gaps.
    pub fos: R,
}

impl<R: Copy> CrownGeometry<R> {
    /// The terms with `f` applied to each (to broadcast them to lanes).
    pub fn map<S>(&self, f: impl Fn(R) -> S) -> CrownGeometry<S> {
        CrownGeometry {
            k: f(self.k),
            co: f(self.co),
            cs: f(self.cs),
            g: f(self.g),
            p: f(self.p),
            fcd: f(self.fcd),
            fcs: f(self.fcs),
            fod: f(self.fod),
            fos: f(self.fos),
        }
    }
}

/// FLIM crown geometry for crown diameter `cd` (m), stem density `sd` (ha⁻¹), height `h` (m) and
/// sun zenith `tts`, view zenith `tto`, relative azimuth `psi` in radians.
pub fn crown_geometry<R: Real>(cd: R, sd: R, h: R, tts: R, tto: R, psi: R) -> CrownGeometry<R> {
    let one = R::one();
    let half = cd * R::c(0.5);
    let k = R::c(PI) * half * half / R::c(10_000.0);
    let co = one - (-k * sd / tto.cos()).exp();
    let cs = one - (-k * sd / tts.cos()).exp();
    let g = tan_distance(tto.tan(), tts.tan(), psi);
    let p = (-g * h / cd).exp();
    let q = p * sqrt0(co * (one - co) * cs * (one - cs));
    CrownGeometry {
        k,
        co,
        cs,
        g,
        p,
        fcd: co * cs + q,
        fcs: co * (one - cs) - q,
        fod: (one - co) * cs - q,
        fos: (one - co) * (one - cs) + q,
    }
}

/// FLIM forest reflectance from understory `r_u`, thick-crown `r_inf` and crown transmittances.
#[inline]
pub fn forest_reflectance<R: Real>(cg: &CrownGeometry<R>, r_u: R, r_inf: R, t_s: R, t_o: R) -> R {
    let tst = t_s * t_o;
    let g = cg.fcd * tst + cg.fcs * t_o + cg.fod * t_s + cg.fos;
    let c = cg.fcd * (R::one() - tst);
    r_inf * c + r_u * g
}

/// The forest reflectance per unit of each crown fraction: [`forest_reflectance`] is
/// `fcd·B[0] + fcs·B[1] + fod·B[2] + fos·B[3]` with these `B` (so its derivative with respect to
/// anything that moves only the fractions, such as the cover, is `Σ ∂F_i·B[i]`).
#[inline]
pub fn crown_fraction_terms<R: Real>(r_u: R, r_inf: R, t_s: R, t_o: R) -> [R; 4] {
    let tst = t_s * t_o;
    [
        r_inf * (R::one() - tst) + r_u * tst,
        r_u * t_o,
        r_u * t_s,
        r_u,
    ]
}

/// Crown diameter (m) and tree height (m) from fractional cover `fc` and stem density `sd` (ha⁻¹),
/// paper eqs. 7–8: `cd = 2·sqrt(fc·10⁴ / (π·sd))`, `h = exp(2.117 + 0.507·ln cd)`.
#[inline]
pub fn crown_from_cover<R: Real>(fc: R, sd: R) -> (R, R) {
    let cd = R::c(2.0) * (fc * R::c(10_000.0) / (R::c(PI) * sd)).sqrt();
    let h = (R::c(2.117) + R::c(0.507) * cd.ln()).exp();
    (cd, h)
}

/// Stand description for one INFORM run (angles in degrees).
#[derive(Clone, Copy, Debug)]
pub struct Stand<R> {
    /// PROSPECT-D leaf parameters (shared by crowns and understory).
    pub leaf: Leaf<R>,
    /// Single-tree leaf area index.
    pub lai: R,
    /// Understory leaf area index.
    pub lai_u: R,
    /// 4SAIL hotspot size.
    pub hspot: R,
    /// Soil brightness: soil = psoil·dry + (1 − psoil)·wet.
    pub psoil: R,
    /// Sun zenith (degrees).
    pub tts: R,
    /// View zenith (degrees).
    pub tto: R,
    /// Relative azimuth (degrees).
    pub psi: R,
    /// Crown diameter (m).
    pub cd: R,
    /// Stem density (ha⁻¹).
    pub sd: R,
    /// Tree height (m).
    pub h: R,
}

/// One wavelength of the spectral tables INFORM needs, in `f64` as read from the tables, or in
/// another plain type (`f32`, or lanes holding one wavelength each).
#[derive(Clone, Copy, Debug)]
pub struct SpectralRow<T = f64> {
    /// PROSPECT-D coefficients.
    pub coef: CoefRow<T>,
    /// Dry soil reflectance.
    pub soil_dry: T,
    /// Wet soil reflectance.
    pub soil_wet: T,
    /// Direct solar irradiance.
    pub es: T,
    /// Diffuse sky irradiance.
    pub ed: T,
}

impl<T: Copy> SpectralRow<T> {
    /// The row with `f` applied to every value (to convert it to another plain type).
    #[inline]
    pub fn map<U>(&self, f: impl Fn(T) -> U) -> SpectralRow<U> {
        SpectralRow {
            coef: self.coef.map(&f),
            soil_dry: f(self.soil_dry),
            soil_wet: f(self.soil_wet),
            es: f(self.es),
            ed: f(self.ed),
        }
    }

    /// The row whose value `k` is `f(k)`, `k` counting the 13 values in the order of
    /// [`crate::rtm::bands::ROW_WIDTH`]: 9 PROSPECT-D coefficients, dry and wet soil, direct and
    /// diffuse irradiance.
    #[inline]
    pub fn from_fn(mut f: impl FnMut(usize) -> T) -> Self {
        SpectralRow {
            coef: CoefRow {
                nr: f(0),
                k_cab: f(1),
                k_car: f(2),
                k_anth: f(3),
                k_brown: f(4),
                k_cw: f(5),
                k_cm: f(6),
                t12: f(7),
                tav90n: f(8),
            },
            soil_dry: f(9),
            soil_wet: f(10),
            es: f(11),
            ed: f(12),
        }
    }
}

/// Every intermediate INFORM result at one wavelength (for stepwise checks).
#[derive(Clone, Copy, Debug)]
pub struct WavelengthTerms<R> {
    /// Leaf reflectance and transmittance.
    pub leaf: LeafOptics<R>,
    /// Understory reflectance (direct/diffuse weighted).
    pub r_understory: R,
    /// Thick crown layer reflectance (direct/diffuse weighted).
    pub r_crown_inf: R,
    /// Crown "transmittance" for the sun direction.
    pub t_s: R,
    /// Crown "transmittance" for the view direction.
    pub t_o: R,
    /// Forest reflectance.
    pub r_forest: R,
}

/// Everything of an INFORM run that does not depend on wavelength, computed once per spectrum.
#[derive(Clone, Copy, Debug)]
pub struct Scene<R> {
    geometry: Geometry,
    leaf: Leaf<R>,
    psoil: R,
    /// Sun/view extinction terms (understory, thick crown and sun-transmittance calls).
    pub ext: Extinction<R>,
    /// Extinction terms of the reference's view-transmittance call (equal to `ext` in
    /// [`Geometry::Physical`]).
    pub ext_o: Extinction<R>,
    /// Understory layer.
    pub understory: Layer<R>,
    /// Thick crown layer (LAI 15).
    pub crown_inf: Layer<R>,
    /// Crown layer for the sun-direction transmittance.
    pub crown_s: Layer<R>,
    /// Crown layer for the view-direction transmittance.
    pub crown_o: Layer<R>,
    /// Diffuse fraction for the sun direction.
    pub skyl_s: R,
    /// Diffuse fraction of the reference's view-transmittance call.
    pub skyl_o: R,
    /// FLIM crown geometry.
    pub crown: CrownGeometry<R>,
    /// The angles (radians) the crown geometry was computed with: sun zenith, view zenith, azimuth.
    pub inform_angles: [R; 3],
    /// Weights of `rsot` and `rdot` in the reference's crown "transmittances" (unit irradiances,
    /// diffuse fractions `skyl_s` and `skyl_o`).
    crown_weights: [(R, R); 2],
}

impl<R: Real> Scene<R> {
    /// The per-spectrum terms of a stand with leaf angle distribution `lidf`.
    pub fn new(stand: &Stand<R>, lidf: &Lidf<R>, geometry: Geometry) -> Self {
        let zero = R::zero();
        match geometry {
            Geometry::Reference => {
                let rule = HotspotRule::Reference;
                let sv = SunView::from_degrees(stand.tts, stand.tto, stand.psi);
                let ext = extinction(&sv, lidf);
                let sv_o = sv.reference_view_transmittance();
                let ext_o = extinction(&sv_o, lidf);
                let angles = [sv_o.costts, sv_o.costto, sv_o.cospsi];
                Scene {
                    geometry,
                    leaf: stand.leaf,
                    psoil: stand.psoil,
                    ext,
                    ext_o,
                    understory: layer(&ext, stand.lai_u, stand.hspot, rule),
                    crown_inf: layer(&ext, R::c(CROWN_INF_LAI), stand.hspot, rule),
                    crown_s: layer(&ext, stand.lai, zero, rule),
                    crown_o: layer(&ext_o, stand.lai, zero, rule),
                    skyl_s: skyl(sv.tts),
                    skyl_o: skyl(sv_o.tts),
                    crown: crown_geometry(
                        stand.cd, stand.sd, stand.h, angles[0], angles[1], angles[2],
                    ),
                    inform_angles: angles,
                    crown_weights: [skyl(sv.tts), skyl(sv_o.tts)].map(unit_irradiance_weights),
                }
            }
            Geometry::Physical => {
                let rule = HotspotRule::Physical;
                let psi = fold_azimuth(stand.psi);
                let sv = SunView::from_degrees(stand.tts, stand.tto, psi);
                let ext = extinction(&sv, lidf);
                let crown = layer(&ext, stand.lai, zero, rule);
                let s = skyl(sv.tts);
                Scene {
                    geometry,
                    leaf: stand.leaf,
                    psoil: stand.psoil,
                    ext,
                    ext_o: ext,
                    understory: layer(&ext, stand.lai_u, stand.hspot, rule),
                    crown_inf: layer(&ext, R::c(CROWN_INF_LAI), stand.hspot, rule),
                    crown_s: crown,
                    crown_o: crown,
                    skyl_s: s,
                    skyl_o: s,
                    crown: crown_geometry(stand.cd, stand.sd, stand.h, sv.tts, sv.tto, sv.psi),
                    inform_angles: [sv.tts, sv.tto, sv.psi],
                    crown_weights: [unit_irradiance_weights(s); 2],
                }
            }
        }
    }

    /// The scene broadcast to lanes ([`Real::Lanes`]: several wavelengths per evaluation on
    /// SIMD targets, eight for `f64`, four for `f32` and duals).
    pub fn lanes(&self) -> Scene<R::Lanes> {
        let f = <R::Lanes as Lanes<R>>::splat;
        Scene {
            geometry: self.geometry,
            leaf: self.leaf.map(f),
            psoil: f(self.psoil),
            ext: self.ext.map(f),
            ext_o: self.ext_o.map(f),
            understory: self.understory.map(f),
            crown_inf: self.crown_inf.map(f),
            crown_s: self.crown_s.map(f),
            crown_o: self.crown_o.map(f),
            skyl_s: f(self.skyl_s),
            skyl_o: f(self.skyl_o),
            crown: self.crown.map(f),
            inform_angles: self.inform_angles.map(f),
            crown_weights: self.crown_weights.map(|(a, b)| (f(a), f(b))),
        }
    }

    /// INFORM at one wavelength (the table row in the plain type of `R`), with every
    /// intermediate result. On a scene of lanes ([`Scene::lanes`]) with a row of lanes, this is
    /// INFORM at several wavelengths at once.
    #[inline]
    pub fn wavelength(&self, row: &SpectralRow<R::Plain>) -> WavelengthTerms<R> {
        self.wavelength_with_leaf(row, leaf_optics(&row.coef, &self.leaf))
    }

    /// [`Scene::wavelength`] with the leaf optics given instead of computed from the scene's
    /// leaf parameters (used to split the Jacobian into a leaf part and a canopy part).
    #[inline]
    pub fn wavelength_with_leaf(
        &self,
        row: &SpectralRow<R::Plain>,
        leaf: LeafOptics<R>,
    ) -> WavelengthTerms<R> {
        // bf depends on the LIDF only, so one medium serves every 4SAIL call; the calls share
        // the sun/view terms (one or two geometries) and the diffuse terms of each LAI.
        let md = medium(self.ext.bf, leaf);
        let dir = directional(&self.ext, &md);
        let slab_c = slab(&md, self.crown_s.lai);
        // The understory (LAIu) on the soil.
        let soil = self.psoil.scale(row.soil_dry) + (R::one() - self.psoil).scale(row.soil_wet);
        let u = sail_view(
            &self.understory,
            &md,
            &dir,
            &slab(&md, self.understory.lai),
            soil,
        );
        // Direct and diffuse reflectance weighted by the irradiance (mixed_reflectance).
        let (w_dir, w_dif) = irradiance_weights(self.skyl_s, row.es, row.ed);
        let r_u = u.rsot * w_dir + u.rdot * w_dif;
        // The optically thick crown layer on the understory.
        let slab_inf = slab(&md, self.crown_inf.lai);
        let inf = sail_view(&self.crown_inf, &md, &dir, &slab_inf, r_u);
        let r_inf = inf.rsot * w_dir + inf.rdot * w_dif;
        // The crown layer (single-tree LAI) on the understory: its transmittances.
        let (t_s, t_o) = match self.geometry {
            Geometry::Reference => {
                // The two calls differ only in the sun direction (the reference's view call
                // keeps the view angles: same `ko`, `bf` and `too`), so they share the view terms.
                let view = view_terms(&self.crown_s, &dir, &slab_c, r_u);
                let s = sail_sun::<R, false>(&self.crown_s, &md, &dir, &slab_c, r_u, &view);
                let dir_o = directional_sun(&self.ext_o, &md, &dir);
                let o = sail_sun::<R, false>(&self.crown_o, &md, &dir_o, &slab_c, r_u, &view);
                let [(s_dir, s_dif), (o_dir, o_dif)] = self.crown_weights;
                (
                    s.rsot * s_dir + s.rdot * s_dif,
                    o.rsot * o_dir + o.rdot * o_dif,
                )
            }
            Geometry::Physical => {
                let c = sail_view(&self.crown_s, &md, &dir, &slab_c, r_u);
                crown_transmittances(&c, r_u, self.skyl_s)
            }
        };
        WavelengthTerms {
            leaf,
            r_understory: r_u,
            r_crown_inf: r_inf,
            t_s,
            t_o,
            r_forest: forest_reflectance(&self.crown, r_u, r_inf, t_s, t_o),
        }
    }
}

/// Hemispherical transmittances of a crown layer over background `r_b` for the sun and the view
/// direction (Atzberger's `TRANS_S`, with multiple reflection between layer and background).
#[inline]
pub fn crown_transmittances<R: Real>(c: &SailOutput<R>, r_b: R, skyl: R) -> (R, R) {
    let one = R::one();
    let inv_dn = one / (one - r_b * c.rdd);
    let diffuse = skyl * c.tdd * inv_dn;
    let t_s = (one - skyl) * (c.tss + (c.tsd + c.tss * r_b * c.rdd) * inv_dn) + diffuse;
    let t_o = (one - skyl) * (c.too + (c.tdo + c.too * r_b * c.rdd) * inv_dn) + diffuse;
    (t_s, t_o)
}

/// [`irradiance_weights`] for unit direct and diffuse irradiance.
fn unit_irradiance_weights<R: Real>(skyl: R) -> (R, R) {
    let one = <R::Plain as Real>::one();
    irradiance_weights(skyl, one, one)
}

/// Relative azimuth folded into [0°, 180°] (4SAIL's `volscatt` assumes that range).
fn fold_azimuth<R: Real>(psi: R) -> R {
    let v = psi.value();
    let turns = libm::floor(v / 360.0);
    let mut p = psi - R::c(turns * 360.0);
    if p.value() > 180.0 {
        p = R::c(360.0) - p;
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Dual;

    #[test]
    fn crown_fractions_sum_to_one() {
        for &(tts, tto, psi) in &[(0.5, 0.0, 0.0), (1.0, 1.0, 1.0), (0.3, 0.2, 2.0)] {
            let cg = crown_geometry(4.0, 500.0, 17.0, tts, tto, psi);
            let s = cg.fcd + cg.fcs + cg.fod + cg.fos;
            assert!((s - 1.0).abs() < 1e-14);
            assert!(
                cg.fcd >= 0.0 && cg.fcs >= 0.0 && cg.fod >= 0.0 && cg.fos >= 0.0,
                "{cg:?}"
            );
        }
    }

    #[test]
    fn reference_scalars_of_the_training_geometry() {
        // Sample 0 of the stepwise oracle: cd 4.0334, sd 500, h 16.845, INFORM angles 1 rad.
        let cg = crown_geometry(4.033435326322356, 500.0, 16.845297786281748, 1.0, 1.0, 1.0);
        assert!((cg.k - 0.0012777328978585128).abs() < 1e-15);
        assert!((cg.co - 0.693465223018799).abs() < 1e-12);
        assert!((cg.g - 1.4933220744380455).abs() < 1e-12);
        assert!((cg.p - 0.001956238139513971).abs() < 1e-12);
        assert!((cg.fcd - 0.48130985543995203).abs() < 1e-12);
        assert!((cg.fos - 0.09437940940235402).abs() < 1e-12);
    }

    #[test]
    fn cover_matches_crown_projection() {
        // k·sd equals fc by construction of eq. 7.
        for &fc in &[0.1, 0.5, 1.0] {
            let (cd, h) = crown_from_cover(fc, 500.0);
            let cg = crown_geometry(cd, 500.0, h, 0.0, 0.0, 0.0);
            assert!((cg.k * 500.0 - fc).abs() < 1e-14);
            assert!(h > 0.0);
        }
        let (cd, h): (Dual<1>, Dual<1>) = crown_from_cover(Dual::var(0.4, 0), Dual::c(500.0));
        let e = 1e-7;
        let (cp, hp) = crown_from_cover(0.4 + e, 500.0);
        let (cm, hm) = crown_from_cover(0.4 - e, 500.0);
        assert!((cd.d[0] - (cp - cm) / (2.0 * e)).abs() < 1e-6);
        assert!((h.d[0] - (hp - hm) / (2.0 * e)).abs() < 1e-5);
    }

    #[test]
    fn transmittances_bounded() {
        let c = SailOutput {
            rsot: 0.0,
            rdot: 0.0,
            rsdt: 0.0,
            rddt: 0.0,
            tss: 0.3,
            too: 0.4,
            tsd: 0.2,
            tdo: 0.2,
            tdd: 0.4,
            rdd: 0.1,
        };
        let (ts, to) = crown_transmittances(&c, 0.2, 0.2);
        assert!(ts > 0.0 && ts < 1.0 && to > 0.0 && to < 1.0);
    }

    /// The reference's view-transmittance call keeps the view direction, so it shares the view
    /// terms of the sun-transmittance call: same `ko`, `bf`, `too`, and the shared evaluation
    /// equals a separate 4SAIL call bit for bit.
    #[test]
    fn reference_view_call_shares_the_view_terms() {
        use crate::rtm::prospect::Leaf;
        use crate::rtm::sail::{sail_view, CampbellBins};
        let leaf = Leaf::<f64> {
            n: 1.6,
            cab: 40.0,
            car: 10.0,
            anth: 2.0,
            cbrown: 0.25,
            cw: 0.01,
            cm: 0.01,
        };
        let row = SpectralRow::from_fn(|k| {
            [
                1.45, 0.02, 0.01, 0.005, 0.1, 0.5, 20.0, 0.96, 0.9, 0.3, 0.1, 1.0, 0.5,
            ][k]
        });
        for (tts, tto, psi, ala) in [
            (30.0, 0.0, 0.0, 40.0),
            (55.0, 10.0, 120.0, 70.0),
            (20.0, 5.0, 10.0, 25.0),
        ] {
            let lidf = Lidf::campbell(ala, CampbellBins::Reference13).unwrap();
            let stand = Stand {
                leaf,
                lai: 3.0,
                lai_u: 0.5,
                hspot: 0.01,
                psoil: 0.8,
                tts,
                tto,
                psi,
                cd: 4.0,
                sd: 500.0,
                h: 17.0,
            };
            let sc = Scene::new(&stand, &lidf, Geometry::Reference);
            assert_eq!(sc.ext_o.ko.to_bits(), sc.ext.ko.to_bits());
            assert_eq!(sc.ext_o.bf.to_bits(), sc.ext.bf.to_bits());
            assert_eq!(sc.crown_o.too.to_bits(), sc.crown_s.too.to_bits());
            let t = sc.wavelength(&row);
            let md = medium(sc.ext.bf, t.leaf);
            let dir_o = directional(&sc.ext_o, &md);
            let o = sail_view(
                &sc.crown_o,
                &md,
                &dir_o,
                &slab(&md, sc.crown_o.lai),
                t.r_understory,
            );
            let [_, (o_dir, o_dif)] = sc.crown_weights;
            assert_eq!(t.t_o.to_bits(), (o.rsot * o_dir + o.rdot * o_dif).to_bits());
        }
    }

    #[test]
    fn azimuth_folding() {
        assert_eq!(fold_azimuth(190.0), 170.0);
        assert_eq!(fold_azimuth(-30.0), 30.0);
        assert_eq!(fold_azimuth(45.0), 45.0);
        assert_eq!(fold_azimuth(360.0), 0.0);
    }
}
