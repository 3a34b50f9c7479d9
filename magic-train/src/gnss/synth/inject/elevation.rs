//! `elevation`: a vertical term `k(t) · (zᵢ − z̄)` linear in station elevation (a tropospheric
//! delay error), with `k` weather (an AR(1) over ~20 days) plus a season, scaled to an RMS of
//! 25–50 mm/km over the training period.

use super::super::draw::{ar1, rms_about_mean, round3};
use super::Ctx;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;
use std::f64::consts::TAU;

/// Adds the term (`k` scaled to its RMS over the training period); `mm_per_km` is the RMS of `k`
/// over the whole record (what an analysis of every day estimates), `z_ref_km` the mean station
/// elevation.
pub fn inject(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>]) -> serde_json::Value {
    let ns = ctx.ns();
    let stations = &ctx.network.stations;
    let rate = rng.random_range(25.0..50.0);
    let z_ref = stations.iter().map(|s| s.z_km).sum::<f64>() / ns as f64;
    let mut k = ar1(rng, rows.len(), 20.0);
    let (ph, w_s) = (rng.random_range(0.0..TAU), rng.random_range(0.5..1.5));
    for (t, v) in k.iter_mut().enumerate() {
        *v += w_s * (TAU * ctx.day(t) / 365.25 + ph).sin();
    }
    ctx.set_train_rms(&mut k, rate);
    for (t, row) in rows.iter_mut().enumerate() {
        for (i, st) in stations.iter().enumerate() {
            row[2 * ns + i] += k[t] * (st.z_km - z_ref);
        }
    }
    json!({"mm_per_km": round3(rms_about_mean(&k)), "z_ref_km": z_ref})
}
