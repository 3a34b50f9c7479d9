//! INFORM's exact Jacobian (split chain rule on dual numbers) held to central differences over
//! the learned box, finite on its faces, and the packed rows' Jacobian in f32 held to f64.
//!
//! Data are found through `MAGIC_DATA` or `../shared/data` next to the workspace; without them the
//! tests fail, saying what to set.

// Index loops over several parallel arrays (bands × variables) read more plainly here.
#![allow(clippy::needless_range_loop)]

mod rtm_common;

use magic_core::rtm::inform::Geometry;
use magic_core::rtm::{Fixed, Inform, LEARNED_BOUNDS, N_BANDS, N_LEARNED};
use rtm_common::{box_point, data, OwnedTables};

// Tolerances: the measured error (printed by `-- --nocapture`) times 10, rounded up, unless
// stated otherwise; the proptest bound was measured on 600 random points.

/// The dual number's value against the plain f64 forward model: measured 2.2e-16 (one ulp).
const DUAL_VALUE_MAX_ERROR: f64 = 2.5e-15;
/// The exact Jacobian against central differences (relative, see `jacobian_error`): measured
/// 1.2e-7 / 1.7e-7 (reference / physical geometry) at the centre and corners, 2.4e-7 on 600
/// random points of the box: the central differences' own error.
const JACOBIAN_MAX_REL_ERROR: f64 = 2.5e-6;
/// The packed rows' Jacobian in f32 against f64 (bands relative to their value, derivatives
/// scaled by the variable's range and relative to the column's largest, floored at 1e-4):
/// measured 1.6e-3 at the centre and the 128 corners, both geometries (the bound is the core's).
const JACOBIAN_F32_VS_F64_MAX_REL_ERROR: f64 = magic_core::rtm::bands::JACOBIAN_F32_MAX_REL_ERROR;
// ---------------------------------------------------------------------------------------------
// Exact Jacobian (Dual<7>) against central differences

/// Relative agreement of an exact derivative with a central difference. Derivatives are scaled by
/// the variable's range (so each is "band change over the whole range"); the comparison is
/// relative to the larger of the two, floored at 1e-4 (a derivative that moves a band by less than
/// 1e-4 reflectance over the whole range is compared in absolute terms).
fn jacobian_error(model: &Inform<'_>, z: &[f64; N_LEARNED], geometry: Geometry) -> f64 {
    let fixed = Fixed::default();
    let (y, jac) = model.jacobian(z, &fixed, geometry).unwrap();
    let y0 = model.forward_learned(z, &fixed, geometry).unwrap();
    for b in 0..N_BANDS {
        assert!(
            (y[b] - y0[b]).abs() <= DUAL_VALUE_MAX_ERROR,
            "dual value differs from f64 value"
        );
    }
    let mut worst = 0.0f64;
    for i in 0..N_LEARNED {
        let range = LEARNED_BOUNDS[i][1] - LEARNED_BOUNDS[i][0];
        let h = 1e-5 * range;
        let mut zp = *z;
        let mut zm = *z;
        zp[i] += h;
        zm[i] -= h;
        let yp = model.forward_learned(&zp, &fixed, geometry).unwrap();
        let ym = model.forward_learned(&zm, &fixed, geometry).unwrap();
        for b in 0..N_BANDS {
            assert!(
                jac[b][i].is_finite(),
                "non-finite derivative d{}/dz{i} at {z:?}",
                magic_core::rtm::S2_BANDS[b]
            );
            let fd = (yp[b] - ym[b]) / (2.0 * h) * range;
            let ex = jac[b][i] * range;
            let err = (ex - fd).abs() / fd.abs().max(ex.abs()).max(1e-4);
            worst = worst.max(err);
        }
    }
    worst
}

#[test]
fn jacobian_matches_central_differences_at_corners_and_centre() {
    let d = data();
    let model = Inform::new(d.tables.tables()).unwrap();
    let mut worst = [0.0f64; 2];
    let mut points = vec![[0.5; N_LEARNED]];
    // All 128 corners of the box.
    for mask in 0..(1u32 << N_LEARNED) {
        let mut u = [0.0; N_LEARNED];
        for (i, ui) in u.iter_mut().enumerate() {
            *ui = ((mask >> i) & 1) as f64;
        }
        points.push(u);
    }
    for u in &points {
        let z = box_point(u);
        for (g, geometry) in [Geometry::Reference, Geometry::Physical]
            .into_iter()
            .enumerate()
        {
            worst[g] = worst[g].max(jacobian_error(&model, &z, geometry));
        }
    }
    eprintln!(
        "Jacobian vs central differences, centre + 128 corners: max relative error reference {:.3e}, physical {:.3e}",
        worst[0], worst[1]
    );
    assert!(
        worst[0] <= JACOBIAN_MAX_REL_ERROR && worst[1] <= JACOBIAN_MAX_REL_ERROR,
        "{worst:?}"
    );
}

/// The rows of all 13 bands, packed as the trainer packs them (rows with weight in some band).
fn packed_rows(t: &OwnedTables) -> (Vec<f64>, Vec<f64>) {
    let (mut spectral, mut weights) = (Vec::new(), Vec::new());
    for i in 0..t.es.len() {
        let w = &t.resampling[i * N_BANDS..(i + 1) * N_BANDS];
        if w.iter().all(|x| *x == 0.0) {
            continue;
        }
        spectral.extend(t.cols.iter().map(|c| c[i]));
        spectral.extend([t.soil_dry[i], t.soil_wet[i], t.es[i], t.ed[i]]);
        weights.extend_from_slice(w);
    }
    (spectral, weights)
}

#[test]
fn packed_jacobian_in_f32_agrees_with_f64() {
    let d = data();
    let (spectral, weights) = packed_rows(&d.tables);
    let p = magic_core::rtm::bands::Packed::new(
        &spectral[..],
        &weights[..],
        &d.tables.beta[..],
        N_BANDS,
    )
    .unwrap();
    let fixed = Fixed::default();
    let mut worst = 0.0f64;
    for mask in 0..=(1u32 << N_LEARNED) {
        // The 128 corners, then the centre.
        let u: [f64; N_LEARNED] = core::array::from_fn(|i| {
            if mask == 1 << N_LEARNED {
                0.5
            } else {
                ((mask >> i) & 1) as f64
            }
        });
        let z = box_point(&u);
        for geometry in [Geometry::Reference, Geometry::Physical] {
            let (mut y, mut jac) = ([0.0; N_BANDS], [[0.0; N_LEARNED]; N_BANDS]);
            let (mut y32, mut jac32) = ([0.0; N_BANDS], [[0.0; N_LEARNED]; N_BANDS]);
            p.jacobian(&z, &fixed, geometry, &mut y, &mut jac).unwrap();
            p.jacobian_in::<f32>(&z, &fixed, geometry, &mut y32, &mut jac32)
                .unwrap();
            for b in 0..N_BANDS {
                worst = worst.max((y32[b] - y[b]).abs() / y[b].abs());
            }
            for k in 0..N_LEARNED {
                let range = LEARNED_BOUNDS[k][1] - LEARNED_BOUNDS[k][0];
                let big = (0..N_BANDS)
                    .map(|b| (jac[b][k] * range).abs())
                    .fold(1e-4, f64::max);
                for b in 0..N_BANDS {
                    worst = worst.max((jac32[b][k] - jac[b][k]).abs() * range / big);
                }
            }
        }
    }
    eprintln!("packed Jacobian f32 vs f64, centre + 128 corners: max relative error {worst:.3e}");
    assert!(worst <= JACOBIAN_F32_VS_F64_MAX_REL_ERROR, "{worst:e}");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 48, ..Default::default() })]

    #[test]
    fn jacobian_matches_central_differences_in_the_box(
        u in proptest::array::uniform7(0.0f64..=1.0),
        physical in proptest::bool::ANY,
    ) {
        let d = data();
        let model = Inform::new(d.tables.tables()).unwrap();
        let geometry = if physical { Geometry::Physical } else { Geometry::Reference };
        let err = jacobian_error(&model, &box_point(&u), geometry);
        proptest::prop_assert!(err <= JACOBIAN_MAX_REL_ERROR, "relative error {err:e} at {u:?}");
    }

    #[test]
    fn jacobian_is_finite_on_the_box_faces(
        u in proptest::array::uniform7(0.0f64..=1.0),
        face in 0usize..N_LEARNED,
        high in proptest::bool::ANY,
        physical in proptest::bool::ANY,
    ) {
        let d = data();
        let model = Inform::new(d.tables.tables()).unwrap();
        let mut u = u;
        u[face] = if high { 1.0 } else { 0.0 };
        let geometry = if physical { Geometry::Physical } else { Geometry::Reference };
        let (y, jac) = model.jacobian(&box_point(&u), &Fixed::default(), geometry).unwrap();
        for b in 0..N_BANDS {
            proptest::prop_assert!(y[b].is_finite());
            for i in 0..N_LEARNED {
                proptest::prop_assert!(jac[b][i].is_finite(), "d{}/d{} at {u:?}", b, i);
            }
        }
    }
}
