//! `drift`: a linear drift (2–4 mm/yr horizontal, 4–8 mm/yr vertical, random signs) at one to
//! three stations over the whole record, zero at its middle.

use super::super::draw::{round3, sym};
use super::Ctx;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;

/// Adds the drifts; `rate_mm_per_yr` per drifting station (E, N, U), `t0` the day of zero.
pub fn inject(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>]) -> serde_json::Value {
    let (ns, n_days) = (ctx.ns(), rows.len());
    let n_st = rng.random_range(1..=3usize);
    let mut which: Vec<usize> = Vec::new();
    while which.len() < n_st {
        let i = rng.random_range(0..ns);
        if !which.contains(&i) {
            which.push(i);
        }
    }
    which.sort_unstable();
    let t0 = n_days as f64 / 2.0;
    let mut rates = serde_json::Map::new();
    for &i in &which {
        let r = [sym(rng, 2.0, 4.0), sym(rng, 2.0, 4.0), sym(rng, 4.0, 8.0)];
        for (t, row) in rows.iter_mut().enumerate() {
            let dt = (t as f64 - t0) / 365.25;
            for k in 0..3 {
                row[k * ns + i] += r[k] * dt;
            }
        }
        rates.insert(ctx.network.names[i].clone(), json!(r.map(round3)));
    }
    json!({"rate_mm_per_yr": rates, "t0": ctx.date(t0 as usize)})
}
