//! The Mogi forward model against the paper implementation's reference outputs
//! (`oracle/mogi_oracle_1k.csv`) in f64 and f32, and the dual-number Jacobian against central
//! differences. The bounds below are the measured errors times 10 (rounded up): the inputs are
//! fixed, so a change that loses an order of magnitude fails.

/// Largest |F − oracle| in f64 (mm): measured 1.4e-13 (oracle values printed to ~16 digits).
const F64_MAX_ERROR_MM: f64 = 1.5e-12;
/// Largest |F − oracle| in f32 (mm): measured 5.9e-5 (f32 rounding of displacements up to a few
/// hundred mm).
const F32_MAX_ERROR_MM: f64 = 6e-4;
/// Largest relative difference of the exact Jacobian from central differences (step 1e-5 of the
/// value): measured 3.7e-9, the differences' own truncation and rounding error.
const JACOBIAN_MAX_REL_ERROR: f64 = 4e-8;

use magic_core::mogi::{field, field_jacobian, Station};
use magic_tests::shared_data;
use magic_train::data::table::Table;
use magic_train::GnssProblem;

fn load() -> (Vec<Station>, Vec<[f64; 4]>, Vec<Vec<f64>>) {
    let dir = shared_data();
    let g = GnssProblem::read(&dir.join("gnss"))
        .expect("gnss data")
        .network;
    let t = Table::read(&dir.join("oracle/mogi_oracle_1k.csv"), b',').expect("oracle");
    let pc: Vec<usize> = ["xcen_km", "ycen_km", "d_km", "dV_1e6m3"]
        .iter()
        .map(|c| t.col(c).unwrap())
        .collect();
    let oc: Vec<usize> = g
        .channel_names()
        .iter()
        .map(|c| t.col(c).unwrap())
        .collect();
    let mut p = vec![];
    let mut u = vec![];
    for r in 0..t.rows.len() {
        p.push(core::array::from_fn(|j| t.num(r, pc[j], false).unwrap()));
        u.push(oc.iter().map(|&c| t.num(r, c, false).unwrap()).collect());
    }
    (g.stations, p, u)
}

#[test]
fn forward_matches_oracle_f64_and_f32() {
    let (st, p, u) = load();
    assert_eq!(p.len(), 1000);
    let (mut e64, mut e32) = (0f64, 0f64);
    let mut o64 = vec![0f64; 36];
    let mut o32 = vec![0f32; 36];
    for (pi, ui) in p.iter().zip(&u) {
        field(&st, pi, &mut o64).unwrap();
        let p32 = pi.map(|v| v as f32);
        field(&st, &p32, &mut o32).unwrap();
        for c in 0..36 {
            e64 = e64.max((o64[c] - ui[c]).abs());
            e32 = e32.max((o32[c] as f64 - ui[c]).abs());
        }
    }
    eprintln!("mogi vs oracle: max abs error f64 {e64:.3e} mm, f32 {e32:.3e} mm");
    assert!(e64 <= F64_MAX_ERROR_MM, "f64 error {e64}");
    assert!(e32 <= F32_MAX_ERROR_MM, "f32 error {e32}");
}

#[test]
fn jacobian_matches_central_differences_on_oracle_inputs() {
    let (st, p, _) = load();
    let mut worst = 0f64;
    let mut out = vec![0f64; 36];
    let mut jac = vec![[0f64; 4]; 36];
    for pi in p.iter().take(200) {
        field_jacobian(&st, pi, &mut out, &mut jac).unwrap();
        for j in 0..4 {
            let h = 1e-5 * (1.0 + pi[j].abs());
            let (mut a, mut b) = (*pi, *pi);
            a[j] += h;
            b[j] -= h;
            let (mut fa, mut fb) = (vec![0f64; 36], vec![0f64; 36]);
            field(&st, &a, &mut fa).unwrap();
            field(&st, &b, &mut fb).unwrap();
            // Relative to the column's largest derivative (entries near zero carry no relative meaning).
            let scale = (0..36)
                .map(|c| jac[c][j].abs())
                .fold(0f64, f64::max)
                .max(1e-12);
            for c in 0..36 {
                let fd = (fa[c] - fb[c]) / (2.0 * h);
                worst = worst.max((jac[c][j] - fd).abs() / scale);
            }
        }
    }
    eprintln!("mogi Jacobian vs central differences: max relative error {worst:.3e}");
    assert!(worst <= JACOBIAN_MAX_REL_ERROR, "{worst}");
}
