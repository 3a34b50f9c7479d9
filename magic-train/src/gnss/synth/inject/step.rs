//! `step`: an offset at one station (3–6 mm horizontal, 6–12 mm vertical, random signs) from an
//! epoch between 20 % and 80 % of the placement's period on; a second one elsewhere for
//! `step+step`.

use super::super::draw::{round3, sym};
use super::Ctx;
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;

/// Adds the step; `station`, `epoch` (first day with the offset), `offset_mm` (E, N, U).
pub fn inject(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>]) -> serde_json::Value {
    let i = station(ctx, rng);
    add(ctx, rng, rows, i)
}

/// The step's station: the first draw of its stream.
pub fn station(ctx: &Ctx<'_>, rng: &mut StdRng) -> usize {
    rng.random_range(0..ctx.ns())
}

/// Adds a step like [`inject`]'s at another station than `first`, each of the others as likely.
pub fn inject_elsewhere(
    ctx: &Ctx<'_>,
    rng: &mut StdRng,
    rows: &mut [Vec<f64>],
    first: usize,
) -> serde_json::Value {
    let ns = ctx.ns();
    let i = (first + 1 + rng.random_range(0..ns.saturating_sub(1).max(1))) % ns.max(1);
    add(ctx, rng, rows, i)
}

/// Adds a step at station `i`, its epoch and offset drawn from `rng`.
fn add(ctx: &Ctx<'_>, rng: &mut StdRng, rows: &mut [Vec<f64>], i: usize) -> serde_json::Value {
    let ns = ctx.ns();
    let (p0, p1) = ctx.period();
    let len = (p1 - p0) as f64;
    let e = p0 + rng.random_range(0.2 * len..0.8 * len) as usize;
    let off = [sym(rng, 3.0, 6.0), sym(rng, 3.0, 6.0), sym(rng, 6.0, 12.0)];
    for row in &mut rows[e..] {
        for k in 0..3 {
            row[k * ns + i] += off[k];
        }
    }
    json!({"station": ctx.network.names[i], "epoch": ctx.date(e), "offset_mm": off.map(round3)})
}
