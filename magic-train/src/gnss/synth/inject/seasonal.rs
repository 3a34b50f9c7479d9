//! `seasonal`: per-station annual and semiannual terms. Per channel an annual amplitude (1–2.5 mm
//! horizontal, 2–5 mm vertical) and phase, a semiannual amplitude (20–60 % of the annual) and
//! phase, in the basis of the Seasonal effect (`[sin ω, cos ω, sin 2ω, cos 2ω]`,
//! `ω = 2π · day / 365.25`).

use super::Ctx;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;
use std::f64::consts::TAU;

/// Adds the terms; `annual_mm` and `semiannual_mm` are the amplitudes per station (E, N, U) of
/// the terms the data hold (these, plus the noise's network-wide ones where it has some).
pub fn inject(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>]) -> serde_json::Value {
    let ns = ctx.ns();
    let mut amp = vec![[0.0; 2]; 3 * ns];
    let mut coef = vec![[0.0; 4]; 3 * ns];
    for c in 0..3 * ns {
        let a1 = if c < 2 * ns {
            rng.random_range(1.0..2.5)
        } else {
            rng.random_range(2.0..5.0)
        };
        let a2 = a1 * rng.random_range(0.2..0.6);
        let (p1, p2): (f64, f64) = (rng.random_range(0.0..TAU), rng.random_range(0.0..TAU));
        amp[c] = [a1, a2];
        coef[c] = [a1 * p1.cos(), a1 * p1.sin(), a2 * p2.cos(), a2 * p2.sin()];
    }
    for (t, row) in rows.iter_mut().enumerate() {
        let w = TAU * ctx.day(t) / 365.25;
        let b = [w.sin(), w.cos(), (2.0 * w).sin(), (2.0 * w).cos()];
        for (c, o) in row.iter_mut().enumerate() {
            *o += (0..4).map(|j| coef[c][j] * b[j]).sum::<f64>();
        }
    }
    if let Some(bg) = &ctx.background.seasonal {
        for c in 0..3 * ns {
            let t: Vec<f64> = (0..4).map(|j| coef[c][j] + bg[c / ns][j]).collect();
            amp[c] = [t[0].hypot(t[1]), t[2].hypot(t[3])];
        }
    }
    json!({
        "annual_mm": ctx.per_station(&|i| [amp[i][0], amp[ns + i][0], amp[2 * ns + i][0]]),
        "semiannual_mm": ctx.per_station(&|i| [amp[i][1], amp[ns + i][1], amp[2 * ns + i][1]]),
    })
}
