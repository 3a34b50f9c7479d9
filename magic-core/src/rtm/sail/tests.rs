//! 4SAIL against its reference values, its limits and its derivatives.

use super::*;
use crate::real::Dual;

const UNIFORM: [f64; 13] = [
    0.1111111, 0.1111111, 0.1111111, 0.1111111, 0.1111111, 0.1111111, 0.1111111, 0.1111111,
    0.0222222, 0.0222222, 0.0222222, 0.0222222, 0.0222222,
];

fn uniform() -> Lidf<f64> {
    Lidf::from_beta_table(&UNIFORM, 0).unwrap()
}

fn leaf() -> LeafOptics<f64> {
    LeafOptics {
        refl: 0.45,
        trans: 0.45,
    }
}

fn run(
    tts: f64,
    tto: f64,
    psi: f64,
    lai: f64,
    hot: f64,
    soil: f64,
    lidf: &Lidf<f64>,
) -> SailOutput<f64> {
    let g = SunView::from_degrees(tts, tto, psi);
    let e = extinction(&g, lidf);
    let l = layer(&e, lai, hot, HotspotRule::Physical);
    sail(&e, &l, &medium(e.bf, leaf()), soil)
}

#[test]
fn campbell_is_normalised_and_shifts_with_angle() {
    for bins in [CampbellBins::Reference13, CampbellBins::Uniform18] {
        for &ala in &[10.0, 30.0, 57.0, 70.0, 85.0] {
            let l = Lidf::campbell(ala, bins).unwrap();
            let s: f64 = l.weights().iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
            assert!(l.weights().iter().all(|w| *w >= 0.0));
        }
        let mean = |ala: f64| {
            let l = Lidf::campbell(ala, bins).unwrap();
            l.weights()
                .iter()
                .zip(l.angles_deg())
                .map(|(w, a)| w * a)
                .sum::<f64>()
        };
        assert!(mean(20.0) < mean(45.0) && mean(45.0) < mean(70.0));
    }
    assert!(Lidf::<f64>::campbell(95.0, CampbellBins::Uniform18).is_err());
    assert!(Lidf::<f64>::campbell(f64::NAN, CampbellBins::Uniform18).is_err());
}

#[test]
fn beta_table_errors() {
    assert!(Lidf::<f64>::from_beta_table(&UNIFORM, 1).is_err());
    assert!(Lidf::<f64>::from_beta_table(&UNIFORM[..12], 0).is_err());
    assert!(Lidf::<f64>::from_beta_table(&[], 0).is_err());
}

#[test]
fn spherical_extinction_is_half_over_cos() {
    // A near-spherical distribution (Campbell, ala ≈ 57°) has G ≈ 0.5 in every direction.
    let l = Lidf::campbell(57.3, CampbellBins::Uniform18).unwrap();
    for &tts in &[0.0, 20.0, 45.0, 60.0] {
        let e = extinction(&SunView::from_degrees(tts, 10.0, 0.0), &l);
        let want = 0.5 / libm::cos(tts * PI / 180.0);
        assert!(
            (e.ks - want).abs() < 0.05 * want,
            "tts {tts}: {} vs {want}",
            e.ks
        );
    }
}

#[test]
fn reflectances_are_bounded_and_soil_dominates_thin_canopies() {
    let l = uniform();
    for &lai in &[0.01, 0.5, 3.0, 15.0] {
        let o = run(30.0, 10.0, 45.0, lai, 0.05, 0.2, &l);
        for r in [o.rsot, o.rdot, o.rsdt, o.rddt] {
            assert!(r > 0.0 && r < 1.0, "{o:?}");
        }
    }
    let thin = run(30.0, 10.0, 45.0, 1e-4, 0.05, 0.2, &l);
    assert!((thin.rddt - 0.2).abs() < 1e-3 && (thin.rsot - 0.2).abs() < 1e-3);
}

#[test]
fn reciprocity_of_sun_and_view() {
    // Swapping sun and view leaves rsot unchanged (Helmholtz reciprocity of 4SAIL).
    let l = Lidf::campbell(40.0, CampbellBins::Uniform18).unwrap();
    let a = run(35.0, 15.0, 60.0, 2.0, 0.1, 0.15, &l);
    let b = run(15.0, 35.0, 60.0, 2.0, 0.1, 0.15, &l);
    assert!((a.rsot - b.rsot).abs() < 1e-12, "{} {}", a.rsot, b.rsot);
    assert!((a.rdot - b.rsdt).abs() < 1e-12, "{} {}", a.rdot, b.rsdt);
}

#[test]
fn jfunc1_branches_agree() {
    let (k, t) = (0.7, 2.0);
    for &l in &[0.7 - 6e-4, 0.7 - 4e-4, 0.7 + 4e-4, 0.7 + 6e-4] {
        let exact = (libm::exp(-l * t) - libm::exp(-k * t)) / (k - l);
        let j = jfunc1(
            k - l,
            1.0 / (k - l),
            t,
            libm::exp(-l * t),
            libm::exp(-k * t),
        );
        assert!((j - exact).abs() < 1e-9, "{j} {exact}");
    }
}

#[test]
fn hotspot_rules() {
    let l = uniform();
    let e = extinction(&SunView::from_degrees(30.0, 0.0, 0.0), &l);
    let none = layer(&e, 2.0, 0.0, HotspotRule::Physical);
    assert!((none.tsstoo - none.tss * none.too).abs() < 1e-15);
    let r = layer(&e, 2.0, 0.0, HotspotRule::Reference);
    assert_eq!(r.alf, REFERENCE_ALF_CAP);
    // A large alf converges to the no-hotspot limit.
    let big = layer(&e, 2.0, 1e-6, HotspotRule::Physical);
    assert!((big.tsstoo - none.tsstoo).abs() < 1e-5);
    assert!(
        (big.sumint - none.sumint).abs() < 1e-6,
        "{} {}",
        big.sumint,
        none.sumint
    );
    // In the exact hotspot direction tsstoo = tss.
    let e0 = extinction(&SunView::from_degrees(30.0, 30.0, 0.0), &l);
    let h = layer(&e0, 2.0, 0.1, HotspotRule::Physical);
    assert!((h.tsstoo - h.tss).abs() < 1e-15);
}

#[test]
fn dual_lai_derivative() {
    let l: Lidf<Dual<1>> = Lidf::from_beta_table(&UNIFORM, 0).unwrap();
    let g = SunView::from_degrees(Dual::c(30.0), Dual::c(5.0), Dual::c(20.0));
    let e = extinction(&g, &l);
    let f = |lai: Dual<1>| {
        let ly = layer(&e, lai, Dual::c(0.05), HotspotRule::Reference);
        let md = medium(
            e.bf,
            LeafOptics {
                refl: Dual::c(0.45),
                trans: Dual::c(0.4),
            },
        );
        sail(&e, &ly, &md, Dual::c(0.2)).rsot
    };
    let d = f(Dual::var(1.3, 0)).d[0];
    let h = 1e-6;
    let fd = (f(Dual::c(1.3 + h)).v - f(Dual::c(1.3 - h)).v) / (2.0 * h);
    assert!((d - fd).abs() < 1e-7, "{d} {fd}");
}
