//! `common_mode`: a translation of the whole network (E, N, U) wandering over weeks to months —
//! an AR(1) with a 60-day time scale per component, RMS over the training period 1.5–3 mm
//! horizontally and 3–6 mm vertically.

use super::super::draw::{ar1, rms_about_mean, round3};
use super::Ctx;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;

/// Adds the translation (scaled to its RMS over the training period); `rms_mm` is the RMS over
/// the whole record of the persistent common mode the data hold (this one, plus the noise's where
/// it has one): what an analysis of every day estimates.
pub fn inject(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>]) -> serde_json::Value {
    let (ns, n_days) = (ctx.ns(), rows.len());
    let rms = [
        rng.random_range(1.5..3.0),
        rng.random_range(1.5..3.0),
        rng.random_range(3.0..6.0),
    ];
    let mut total = [0.0; 3];
    for (k, r) in rms.iter().enumerate() {
        let mut v = ar1(rng, n_days, 60.0);
        ctx.set_train_rms(&mut v, *r);
        for (t, row) in rows.iter_mut().enumerate() {
            for o in &mut row[k * ns..(k + 1) * ns] {
                *o += v[t];
            }
        }
        total[k] = match &ctx.background.common {
            Some(bg) => {
                rms_about_mean(&v.iter().zip(&bg[k]).map(|(x, b)| x + b).collect::<Vec<_>>())
            }
            None => rms_about_mean(&v),
        };
    }
    json!({"rms_mm": total.map(round3)})
}
