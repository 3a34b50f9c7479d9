//! 4SAIL canopy reflectance (Verhoef 1984; Verhoef, Jia, Xiao & Su 2007): a turbid layer of
//! leaves with a leaf inclination distribution (LIDF) over a Lambertian background.
//!
//! The work is split by what it depends on, so a spectrum costs little:
//!
//! * [`Lidf`] — leaf inclination weights (beta table rows or Campbell's ellipsoidal distribution);
//! * [`extinction`] — per geometry: extinction coefficients `ks`, `ko`, the bidirectional
//!   scattering coefficients `sob`, `sof`, `bf` and the hotspot distance `dso` (Verhoef's
//!   `volscatt` summed over the LIDF). No wavelength enters.
//! * [`layer`] — per geometry and LAI: direct transmittances `tss`, `too`, the hotspot-corrected
//!   joint transmittance `tsstoo` and the single-scattering integral `sumint` (exponential
//!   Simpson integration with Bréon's 2/(ks+ko) correction).
//! * [`medium`] — per wavelength and LIDF: the diffuse scattering coefficients, the attenuation
//!   eigenvalue `m` and the infinite-layer reflectance `rinf` (independent of sun and view).
//! * [`directional`] — per wavelength and geometry: the medium's sources along sun and view;
//! * [`slab`] — per wavelength and LAI: the diffuse reflectance and transmittance of the layer;
//! * [`sail_parts`] (or [`sail`], which builds the parts) — per wavelength and layer: the four
//!   reflectance factors `rsot`, `rdot`, `rsdt`, `rddt` of canopy + background, and the layer
//!   transmittances.
//!
//! INFORM runs four 4SAIL calls per wavelength that share the medium, two geometries and three
//! LAIs; sharing these parts divides the per-wavelength work.
//!
//! The per-wavelength functions ([`medium`], [`directional`], [`slab`], [`sail_parts`],
//! [`mixed_reflectance`]) branch only through [`Real::select`], so they run on lanes of several
//! wavelengths ([`crate::real::F64x4`]). The per-geometry ones ([`Lidf`], [`extinction`],
//! [`layer`]) branch on [`Real::value`] and run once per spectrum on scalars; their results are
//! broadcast to lanes with `map`.
//!
//! Details that follow the reference implementation because they change outputs: the `J1`
//! function switches to its series form when `|(k − l)·LAI| ≤ 1e-3`, and in
//! [`HotspotRule::Reference`] the hotspot parameter `alf` is capped at 200 (and set to 200 when
//! the hotspot size is 0) and the hotspot integral uses 19 segments (the reference overwrites its
//! 19th abscissa with 1). [`HotspotRule::Physical`] follows the published model (and the `prosail`
//! package) instead: 20 segments, no cap, and hotspot 0 means no hotspot correlation
//! (`tsstoo = tss·too`).

use super::prospect::LeafOptics;
use crate::real::{Cmp, Real};
use core::f64::consts::{FRAC_PI_2, PI};

mod lidf;
pub use lidf::{CampbellBins, Lidf, LITAB_DEG, MAX_BINS};

/// Below this `|(k − l)·LAI|` the `J1` function uses its series form (reference threshold).
pub const J1_SERIES_THRESHOLD: f64 = 1e-3;

/// Largest hotspot parameter `alf` in [`HotspotRule::Reference`].
pub const REFERENCE_ALF_CAP: f64 = 200.0;

/// Sun and view geometry as 4SAIL uses it: angles in radians and their trigonometric values.
///
/// The fields are public because the reference implementation runs 4SAIL on an inconsistent
/// state (see [`SunView::reference_view_transmittance`]); [`SunView::from_degrees`] builds the
/// consistent one.
#[derive(Clone, Copy, Debug)]
pub struct SunView<R> {
    /// Sun zenith angle (radians).
    pub tts: R,
    /// View zenith angle (radians).
    pub tto: R,
    /// Relative azimuth (radians).
    pub psi: R,
    /// sin(tts).
    pub sintts: R,
    /// cos(tts).
    pub costts: R,
    /// sin(tto).
    pub sintto: R,
    /// cos(tto).
    pub costto: R,
    /// cos(psi).
    pub cospsi: R,
    /// tan(tts).
    pub tantts: R,
    /// tan(tto).
    pub tantto: R,
}

impl<R: Real> SunView<R> {
    /// A consistent geometry from sun zenith, view zenith and relative azimuth in degrees.
    pub fn from_degrees(tts: R, tto: R, psi: R) -> Self {
        let d = R::c(PI / 180.0);
        Self::from_radians(tts * d, tto * d, psi * d)
    }

    /// A consistent geometry from angles in radians.
    pub fn from_radians(tts: R, tto: R, psi: R) -> Self {
        SunView {
            tts,
            tto,
            psi,
            sintts: tts.sin(),
            costts: tts.cos(),
            sintto: tto.sin(),
            costto: tto.cos(),
            cospsi: psi.cos(),
            tantts: tts.tan(),
            tantto: tto.tan(),
        }
    }

    /// The state the reference implementation runs its view-direction "transmittance" call in:
    /// the sun angle is replaced by the view angle (`tts = tto`, `tan tts = tan tto`), but both
    /// `sin tts` and `cos tts` are set to `cos tto`. Only [`Geometry::Reference`] uses it.
    ///
    /// [`Geometry::Reference`]: super::inform::Geometry::Reference
    pub fn reference_view_transmittance(&self) -> Self {
        SunView {
            tts: self.tto,
            tantts: self.tantto,
            sintts: self.costto,
            costts: self.costto,
            ..*self
        }
    }
}

/// Geometry × LIDF terms of 4SAIL (no wavelength, no LAI).
#[derive(Clone, Copy, Debug)]
pub struct Extinction<R> {
    /// Extinction coefficient in the sun direction.
    pub ks: R,
    /// Extinction coefficient in the view direction.
    pub ko: R,
    /// Weighted cos² of the leaf inclination (diffuse backscatter fraction term).
    pub bf: R,
    /// Bidirectional backscatter coefficient (multiplies leaf reflectance).
    pub sob: R,
    /// Bidirectional forward-scatter coefficient (multiplies leaf transmittance).
    pub sof: R,
    /// Hotspot distance `sqrt(tan²tts + tan²tto − 2 tan tts tan tto cos psi)`.
    pub dso: R,
}

impl<R: Copy> Extinction<R> {
    /// The terms with `f` applied to each (to broadcast them to lanes).
    pub fn map<S>(&self, f: impl Fn(R) -> S) -> Extinction<S> {
        Extinction {
            ks: f(self.ks),
            ko: f(self.ko),
            bf: f(self.bf),
            sob: f(self.sob),
            sof: f(self.sof),
            dso: f(self.dso),
        }
    }
}

/// Square root that is zero (with zero derivative) for arguments ≤ 0, so dual numbers stay finite
/// at the hotspot and at exact zeros.
#[inline]
pub(crate) fn sqrt0<R: Real>(x: R) -> R {
    x.select(Cmp::Gt(0.0), || x.sqrt(), R::zero)
}

/// `sqrt(tan²a + tan²b − 2 tan a tan b cos ψ)` given `tan a`, `tan b` and ψ, evaluated as
/// `sqrt((tan a − tan b)² + 4 tan a tan b sin²(ψ/2))`, which does not cancel when ψ is small or
/// the two directions nearly coincide (f32 loses every digit in the textbook form there).
#[inline]
pub(crate) fn tan_distance<R: Real>(ta: R, tb: R, psi: R) -> R {
    let d = ta - tb;
    let s = (psi * R::c(0.5)).sin();
    sqrt0(d * d + R::c(4.0) * ta * tb * s * s)
}

/// Verhoef's volume scattering function for one leaf inclination: interception `chi_s`, `chi_o`
/// and the fractions `frho`, `ftau` that multiply leaf reflectance and transmittance.
#[inline]
fn volscatt<R: Real>(g: &SunView<R>, cttl: f64, sttl: f64) -> (R, R, R, R) {
    let pi = R::c(PI);
    let half_pi = R::c(FRAC_PI_2);
    let cs = g.costts * R::c(cttl);
    let co = g.costto * R::c(cttl);
    let ss = g.sintts * R::c(sttl);
    let so = g.sintto * R::c(sttl);
    let cosbts = if ss.value().abs() > 1e-6 {
        -cs / ss
    } else {
        R::c(5.0)
    };
    let cosbto = if so.value().abs() > 1e-6 {
        -co / so
    } else {
        R::c(5.0)
    };
    let (bts, ds) = if cosbts.value().abs() < 1.0 {
        (cosbts.acos(), ss)
    } else {
        (pi, cs)
    };
    let chi_s = R::c(2.0 / PI) * ((bts - half_pi) * cs + bts.sin() * ss);
    let (bto, doo) = if cosbto.value().abs() < 1.0 {
        (cosbto.acos(), so)
    } else if g.tto.value() < FRAC_PI_2 {
        (pi, co)
    } else {
        (R::zero(), -co)
    };
    let chi_o = R::c(2.0 / PI) * ((bto - half_pi) * co + bto.sin() * so);
    let btran1 = (bts - bto).abs();
    let btran2 = pi - (bts + bto - pi).abs();
    let psi = g.psi;
    let (bt1, bt2, bt3) = if psi.value() <= btran1.value() {
        (psi, btran1, btran2)
    } else if psi.value() <= btran2.value() {
        (btran1, psi, btran2)
    } else {
        (btran1, btran2, psi)
    };
    let t1 = R::c(2.0) * cs * co + ss * so * g.cospsi;
    let t2 = if bt2.value() > 0.0 {
        bt2.sin() * (R::c(2.0) * ds * doo + ss * so * bt1.cos() * bt3.cos())
    } else {
        R::zero()
    };
    let denom = R::c(2.0 * PI * PI);
    let mut frho = ((pi - bt2) * t1 + t2) / denom;
    let mut ftau = (-bt2 * t1 + t2) / denom;
    if frho.value() < 0.0 {
        frho = R::zero();
    }
    if ftau.value() < 0.0 {
        ftau = R::zero();
    }
    (chi_s, chi_o, frho, ftau)
}

/// The geometry × LIDF terms: `volscatt` summed over the inclination bins.
pub fn extinction<R: Real>(g: &SunView<R>, lidf: &Lidf<R>) -> Extinction<R> {
    let mut ks = R::zero();
    let mut ko = R::zero();
    let mut bf = R::zero();
    let mut sob = R::zero();
    let mut sof = R::zero();
    let ctscto = g.costts * g.costto;
    for (&a, &w) in lidf.angles_deg().iter().zip(lidf.weights()) {
        let ttl = a * PI / 180.0;
        let (cttl, sttl) = (libm::cos(ttl), libm::sin(ttl));
        let (chi_s, chi_o, frho, ftau) = volscatt(g, cttl, sttl);
        ks += chi_s / g.costts * w;
        ko += chi_o / g.costto * w;
        bf += R::c(cttl * cttl) * w;
        sob += frho * R::c(PI) / ctscto * w;
        sof += ftau * R::c(PI) / ctscto * w;
    }
    let dso = tan_distance(g.tantts, g.tantto, g.psi);
    Extinction {
        ks,
        ko,
        bf,
        sob,
        sof,
        dso,
    }
}

/// How the hotspot parameter is treated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HotspotRule {
    /// As the reference: `alf = 2·dso / (hotspot·(ks + ko))` capped at 200, hotspot 0 gives 200,
    /// 19 integration segments.
    Reference,
    /// As published: 20 integration segments, no cap, hotspot 0 gives no hotspot correlation.
    Physical,
}

/// Per geometry and LAI terms of one 4SAIL layer (no wavelength).
#[derive(Clone, Copy, Debug)]
pub struct Layer<R> {
    /// Leaf area index.
    pub lai: R,
    /// Direct transmittance in the sun direction, exp(−ks·LAI).
    pub tss: R,
    /// Direct transmittance in the view direction, exp(−ko·LAI).
    pub too: R,
    /// Joint sun-view gap probability including the hotspot correlation.
    pub tsstoo: R,
    /// Single-scattering depth integral (hotspot-corrected).
    pub sumint: R,
    /// `J2(ks, ko, LAI) = (1 − exp(−(ks + ko)·LAI)) / (ks + ko)`.
    pub z: R,
    /// The hotspot parameter `alf` used (for diagnostics).
    pub alf: R,
}

impl<R: Copy> Layer<R> {
    /// The terms with `f` applied to each (to broadcast them to lanes).
    pub fn map<S>(&self, f: impl Fn(R) -> S) -> Layer<S> {
        Layer {
            lai: f(self.lai),
            tss: f(self.tss),
            too: f(self.too),
            tsstoo: f(self.tsstoo),
            sumint: f(self.sumint),
            z: f(self.z),
            alf: f(self.alf),
        }
    }
}

/// The layer terms for `lai` (> 0) with hotspot size `hotspot` (leaf size / canopy height).
pub fn layer<R: Real>(e: &Extinction<R>, lai: R, hotspot: R, rule: HotspotRule) -> Layer<R> {
    let one = R::one();
    let tss = (-e.ks * lai).exp();
    let too = (-e.ko * lai).exp();
    let kk = e.ks + e.ko;
    let z = (one - (-kk * lai).exp()) / kk;
    // The reference integrates in 19 segments (its 19th abscissa is overwritten by 1), the
    // published model in 20.
    let segments = match rule {
        HotspotRule::Reference => 19,
        HotspotRule::Physical => 20,
    };
    let with_alf = |alf: R| -> (R, R) {
        if alf.value() == 0.0 {
            // The pure hotspot: sun and view paths coincide.
            return (tss, (one - tss) / (e.ks * lai));
        }
        let fhot = lai * (e.ko * e.ks).sqrt();
        let fint = (one - (-alf).exp()) * R::c(0.05);
        let (mut x1, mut y1, mut f1) = (R::zero(), R::zero(), one);
        let mut sumint = R::zero();
        for istep in 1..=segments {
            let x2 = if istep < segments {
                -(one - R::c(istep as f64) * fint).ln() / alf
            } else {
                one
            };
            let y2 = -kk * lai * x2 + fhot * (one - (-alf * x2).exp()) / alf;
            let f2 = y2.exp();
            sumint += (f2 - f1) * (x2 - x1) / (y2 - y1);
            x1 = x2;
            y1 = y2;
            f1 = f2;
        }
        (f1, sumint)
    };
    let (alf, tsstoo, sumint) = match rule {
        HotspotRule::Reference => {
            let mut alf = if hotspot.value() > 0.0 {
                e.dso / hotspot * R::c(2.0) / kk
            } else {
                R::c(REFERENCE_ALF_CAP)
            };
            if alf.value() > REFERENCE_ALF_CAP {
                alf = R::c(REFERENCE_ALF_CAP);
            }
            let (t, s) = with_alf(alf);
            (alf, t, s)
        }
        HotspotRule::Physical => {
            if hotspot.value() > 0.0 {
                let alf = e.dso / hotspot * R::c(2.0) / kk;
                let (t, s) = with_alf(alf);
                (alf, t, s)
            } else {
                // No hotspot correlation: the limit alf → ∞ of the integral.
                let t = tss * too;
                (R::c(f64::INFINITY), t, (one - t) / (kk * lai))
            }
        }
    };
    Layer {
        lai,
        tss,
        too,
        tsstoo,
        sumint,
        z,
        alf,
    }
}

/// Per wavelength terms of the leaf medium that do not depend on sun or view (only on `bf`).
#[derive(Clone, Copy, Debug)]
pub struct Medium<R> {
    /// Leaf reflectance.
    pub rho: R,
    /// Leaf transmittance.
    pub tau: R,
    /// Diffuse backscatter coefficient.
    pub sigb: R,
    /// Diffuse attenuation `1 − sigf`.
    pub att: R,
    /// Attenuation eigenvalue `sqrt(att² − sigb²)`.
    pub m: R,
    /// Reflectance of an infinitely thick layer.
    pub rinf: R,
    /// `1 / (1 − rinf²)`.
    pub inv_1m_rinf2: R,
}

/// The medium terms from leaf optics and the LIDF's `bf`.
#[inline]
pub fn medium<R: Real>(bf: R, leaf: LeafOptics<R>) -> Medium<R> {
    let one = R::one();
    let half = R::c(0.5);
    let ddb = half * (one + bf);
    let ddf = half * (one - bf);
    let rho = leaf.refl;
    let tau = leaf.trans;
    let sigb = ddb * rho + ddf * tau;
    let sigf = ddf * rho + ddb * tau;
    let att = one - sigf;
    let m = sqrt0((att + sigb) * (att - sigb));
    // rinf = (att − m)/sigb = sigb/(att + m) (no cancellation when sigb is small), and
    // 1 − rinf² = 2m/(att + m): both from one division (m > 0 for any absorbing leaf).
    let u = att + m;
    let two_m = R::c(2.0) * m;
    let p = one / (two_m * u);
    let rinf = sigb * two_m * p;
    let inv_1m_rinf2 = u * u * p;
    Medium {
        rho,
        tau,
        sigb,
        att,
        m,
        rinf,
        inv_1m_rinf2,
    }
}

/// Per wavelength terms of a medium seen in one sun/view geometry, shared by every layer with
/// that geometry (any LAI).
#[derive(Clone, Copy, Debug)]
pub struct Directional<R> {
    /// `sf + sb·rinf` (sun-direction source into the downward diffuse stream).
    pub s_down: R,
    /// `sf·rinf + sb`.
    pub s_up: R,
    /// `vf + vb·rinf` (view-direction source).
    pub v_down: R,
    /// `vf·rinf + vb`.
    pub v_up: R,
    /// Bidirectional scattering `sob·rho + sof·tau`.
    pub w: R,
    /// `ks − m`.
    pub ks_m: R,
    /// `ko − m`.
    pub ko_m: R,
    /// `1 / (ks − m)` (0 when `ks = m` exactly; only used away from that point).
    pub inv_ks_m: R,
    /// `1 / (ko − m)` (as `inv_ks_m`).
    pub inv_ko_m: R,
    /// `1 / (ks + m)`.
    pub inv_ks_p: R,
    /// `1 / (ko + m)`.
    pub inv_ko_p: R,
}

/// `1/x`, or 0 where `x` is exactly 0.
#[inline]
fn inv_or_zero<R: Real>(x: R) -> R {
    x.select(Cmp::Ne(0.0), || R::one() / x, R::zero)
}

/// The directional terms of medium `md` in geometry `e`.
#[inline]
pub fn directional<R: Real>(e: &Extinction<R>, md: &Medium<R>) -> Directional<R> {
    let half = R::c(0.5);
    let (rho, tau, m, rinf) = (md.rho, md.tau, md.m, md.rinf);
    let dob = half * (e.ko + e.bf);
    let dof = half * (e.ko - e.bf);
    let vb = dob * rho + dof * tau;
    let vf = dof * rho + dob * tau;
    let (inv_ko_m, inv_ko_p) = inv_pair(e.ko, m);
    let zero = R::zero();
    // The view terms; the sun terms follow.
    let view = Directional {
        v_down: vf + vb * rinf,
        v_up: vf * rinf + vb,
        ko_m: e.ko - m,
        inv_ko_m,
        inv_ko_p,
        s_down: zero,
        s_up: zero,
        w: zero,
        ks_m: zero,
        inv_ks_m: zero,
        inv_ks_p: zero,
    };
    directional_sun(e, md, &view)
}

/// The directional terms of medium `md` in geometry `e` whose view direction is that of `view`
/// (the same `ko` and `bf`): the sun terms are computed, the view terms taken from `view`.
#[inline]
pub fn directional_sun<R: Real>(
    e: &Extinction<R>,
    md: &Medium<R>,
    view: &Directional<R>,
) -> Directional<R> {
    let half = R::c(0.5);
    let (rho, tau, m, rinf) = (md.rho, md.tau, md.m, md.rinf);
    let sdb = half * (e.ks + e.bf);
    let sdf = half * (e.ks - e.bf);
    let sb = sdb * rho + sdf * tau;
    let sf = sdf * rho + sdb * tau;
    let (inv_ks_m, inv_ks_p) = inv_pair(e.ks, m);
    Directional {
        s_down: sf + sb * rinf,
        s_up: sf * rinf + sb,
        w: e.sob * rho + e.sof * tau,
        ks_m: e.ks - m,
        inv_ks_m,
        inv_ks_p,
        ..*view
    }
}

/// `(1/(k − m), 1/(k + m))` from one division; the first is 0 where `k = m` exactly (where
/// `J1` uses its series form instead).
#[inline]
fn inv_pair<R: Real>(k: R, m: R) -> (R, R) {
    let (d, s) = (k - m, k + m);
    let q = inv_or_zero(d * s);
    (s * q, d.select(Cmp::Ne(0.0), || d * q, || R::one() / s))
}

/// Per wavelength diffuse terms of a layer of the medium with a given LAI, shared by every
/// geometry.
#[derive(Clone, Copy, Debug)]
pub struct Slab<R> {
    /// `exp(−m·LAI)`.
    pub e1: R,
    /// `rinf·e1`.
    pub re: R,
    /// `1 / (1 − rinf²·e1²)`.
    pub inv_denom: R,
    /// Diffuse reflectance of the layer.
    pub rdd: R,
    /// Diffuse transmittance of the layer.
    pub tdd: R,
}

/// The diffuse terms of a layer of medium `md` with leaf area index `lai`.
#[inline]
pub fn slab<R: Real>(md: &Medium<R>, lai: R) -> Slab<R> {
    let one = R::one();
    let e1 = (-md.m * lai).exp();
    let e2 = e1 * e1;
    let rinf2 = md.rinf * md.rinf;
    let inv_denom = one / (one - rinf2 * e2);
    Slab {
        e1,
        re: md.rinf * e1,
        inv_denom,
        rdd: md.rinf * (one - e2) * inv_denom,
        tdd: (one - rinf2) * e1 * inv_denom,
    }
}

/// Outputs of 4SAIL for one layer over a Lambertian background at one wavelength.
#[derive(Clone, Copy, Debug)]
pub struct SailOutput<R> {
    /// Bidirectional reflectance factor of canopy + background.
    pub rsot: R,
    /// Hemispherical-directional reflectance factor (diffuse in, view direction out).
    pub rdot: R,
    /// Directional-hemispherical reflectance factor (sun in, hemisphere out).
    pub rsdt: R,
    /// Bihemispherical reflectance factor.
    pub rddt: R,
    /// Layer: direct transmittance, sun direction.
    pub tss: R,
    /// Layer: direct transmittance, view direction.
    pub too: R,
    /// Layer: directional (sun) to diffuse transmittance.
    pub tsd: R,
    /// Layer: diffuse to directional (view) transmittance.
    pub tdo: R,
    /// Layer: diffuse transmittance.
    pub tdd: R,
    /// Layer: diffuse reflectance.
    pub rdd: R,
}

/// `J1(k, m, t) = (e^(−m t) − e^(−k t)) / (k − m)` with its series form near `k = m`, given
/// `k − m`, its inverse, `emt = e^(−m t)` and `ekt = e^(−k t)`.
#[inline]
fn jfunc1<R: Real>(k_m: R, inv_k_m: R, t: R, emt: R, ekt: R) -> R {
    let del = k_m * t;
    del.select(
        Cmp::AbsGt(J1_SERIES_THRESHOLD),
        || (emt - ekt) * inv_k_m,
        || R::c(0.5) * t * (ekt + emt) * (R::one() - del * del / R::c(12.0)),
    )
}

/// 4SAIL at one wavelength: layer `l` (geometry `e`) of medium `md` over background reflectance
/// `soil`. Convenience form of [`sail_parts`].
#[inline]
pub fn sail<R: Real>(e: &Extinction<R>, l: &Layer<R>, md: &Medium<R>, soil: R) -> SailOutput<R> {
    sail_parts(l, md, &directional(e, md), &slab(md, l.lai), soil)
}

/// 4SAIL at one wavelength from its shared parts: the layer `l`, medium `md`, the medium's
/// directional terms `d` in the layer's geometry and its diffuse terms `s` for the layer's LAI.
#[inline]
pub fn sail_parts<R: Real>(
    l: &Layer<R>,
    md: &Medium<R>,
    d: &Directional<R>,
    s: &Slab<R>,
    soil: R,
) -> SailOutput<R> {
    sail_core::<R, true>(l, md, d, s, soil)
}

/// [`sail_parts`] without the hemispherical reflectances: `rsdt` and `rddt` are left at zero
/// (INFORM needs only `rsot`, `rdot` and the transmittances).
#[inline]
pub(crate) fn sail_view<R: Real>(
    l: &Layer<R>,
    md: &Medium<R>,
    d: &Directional<R>,
    s: &Slab<R>,
    soil: R,
) -> SailOutput<R> {
    sail_core::<R, false>(l, md, d, s, soil)
}

/// The view-direction terms of 4SAIL for one layer over a background: everything that does not
/// involve the sun direction, so calls that differ only in the sun direction (the reference's two
/// crown "transmittance" calls) share it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ViewTerms<R> {
    j1ko: R,
    tdo: R,
    rdo: R,
    inv_dn: R,
    rdot: R,
    soil_tdd_dn: R,
}

/// The [`ViewTerms`] of layer `l` of medium `md` (directional terms `d`, diffuse terms `s`) over
/// background reflectance `soil`.
#[inline]
pub(crate) fn view_terms<R: Real>(
    l: &Layer<R>,
    d: &Directional<R>,
    s: &Slab<R>,
    soil: R,
) -> ViewTerms<R> {
    let one = R::one();
    let (lai, too) = (l.lai, l.too);
    let j1ko = jfunc1(d.ko_m, d.inv_ko_m, lai, s.e1, too);
    let j2ko = (one - too * s.e1) * d.inv_ko_p;
    let pv = d.v_down * j1ko;
    let qv = d.v_up * j2ko;
    let tdo = (pv - s.re * qv) * s.inv_denom;
    let rdo = (qv - s.re * pv) * s.inv_denom;
    let inv_dn = one / (one - soil * s.rdd);
    let soil_tdd_dn = soil * s.tdd * inv_dn;
    ViewTerms {
        j1ko,
        tdo,
        rdo,
        inv_dn,
        rdot: rdo + (tdo + too) * soil_tdd_dn,
        soil_tdd_dn,
    }
}

/// 4SAIL at one wavelength from its view terms `v` (of the same layer LAI, view direction,
/// medium, slab and background): the sun-direction terms and the outputs.
#[inline]
pub(crate) fn sail_sun<R: Real, const HEMI: bool>(
    l: &Layer<R>,
    md: &Medium<R>,
    d: &Directional<R>,
    s: &Slab<R>,
    soil: R,
    v: &ViewTerms<R>,
) -> SailOutput<R> {
    let one = R::one();
    let (lai, tss, too) = (l.lai, l.tss, l.too);
    let rinf = md.rinf;

    let j1ks = jfunc1(d.ks_m, d.inv_ks_m, lai, s.e1, tss);
    let j2ks = (one - tss * s.e1) * d.inv_ks_p;

    let ps = d.s_down * j1ks;
    let qs = d.s_up * j2ks;

    let (rdd, tdd) = (s.rdd, s.tdd);
    let tsd = (ps - s.re * qs) * s.inv_denom;
    let (tdo, rdo) = (v.tdo, v.rdo);

    let g1 = (l.z - j1ks * too) * d.inv_ko_p;
    let g2 = (l.z - v.j1ko * tss) * d.inv_ks_p;
    let t1 = d.v_up * g1 * d.s_down;
    let t2 = d.v_down * g2 * d.s_up;
    let t3 = (rdo * qs + tdo * ps) * rinf;
    let rsod = (t1 + t2 - t3) * md.inv_1m_rinf2;
    let rsos = d.w * lai * l.sumint;

    let inv_dn = v.inv_dn;
    let rsodt = rsod + ((tss + tsd) * tdo + (tsd + tss * soil * rdd) * too) * soil * inv_dn;
    let rsost = rsos + l.tsstoo * soil;
    let rsot = rsost + rsodt;
    let (rsdt, rddt) = if HEMI {
        let rsd = (qs - s.re * ps) * s.inv_denom;
        (rsd + (tsd + tss) * v.soil_tdd_dn, rdd + tdd * v.soil_tdd_dn)
    } else {
        (R::zero(), R::zero())
    };
    SailOutput {
        rsot,
        rdot: v.rdot,
        rsdt,
        rddt,
        tss,
        too,
        tsd,
        tdo,
        tdd,
        rdd,
    }
}

#[inline]
fn sail_core<R: Real, const HEMI: bool>(
    l: &Layer<R>,
    md: &Medium<R>,
    d: &Directional<R>,
    s: &Slab<R>,
    soil: R,
) -> SailOutput<R> {
    sail_sun::<R, HEMI>(l, md, d, s, soil, &view_terms(l, d, s, soil))
}

/// Fraction of diffuse (sky) irradiance for sun zenith `tts` in radians (François et al. 2002):
/// `0.847 − 1.61·sin(90° − tts) + 1.04·sin²(90° − tts)`.
#[inline]
pub fn skyl<R: Real>(tts: R) -> R {
    let s = (R::c(FRAC_PI_2) - tts).sin();
    R::c(0.847) - R::c(1.61) * s + R::c(1.04) * s * s
}

/// Reflectance under mixed direct (`es`) and diffuse (`ed`) irradiance with diffuse fraction
/// `skyl`: `(rdot·skyl·ed + rsot·(1 − skyl)·es) / ((1 − skyl)·es + skyl·ed)`.
#[inline]
pub fn mixed_reflectance<R: Real>(rsot: R, rdot: R, skyl: R, es: R::Plain, ed: R::Plain) -> R {
    let (w_dir, w_dif) = irradiance_weights(skyl, es, ed);
    rsot * w_dir + rdot * w_dif
}

/// The weights of the direct (`rsot`) and diffuse (`rdot`) reflectance in
/// [`mixed_reflectance`]: `(1 − skyl)·es` and `skyl·ed`, normalised to sum 1 (one division,
/// shared by every call with the same irradiance).
#[inline]
pub fn irradiance_weights<R: Real>(skyl: R, es: R::Plain, ed: R::Plain) -> (R, R) {
    let dir = (R::one() - skyl).scale(es);
    let dif = skyl.scale(ed);
    let inv = R::one() / (dir + dif);
    (dir * inv, dif * inv)
}

#[cfg(test)]
mod tests;
