//! `second_source`: a second Mogi source — another reservoir, a hydrothermal system — at a
//! fixed position, resolvable from the main source ([`resolvable`]), whose volume changes once:
//!
//! - a *pulse*: inflating then deflating back (or the reverse, sin² over 200–500 days), with
//!   6–9 mm (network RMS at the peak) of its field beyond what moving the main source can mimic,
//!   at most 30 mm at any station;
//! - a *lasting* deflation: ΔV −0.8 to −1.1·10⁶ m³, building over 60–120 days (raised cosine)
//!   and then staying, seen by at least one station ([`MIN_VISIBLE_MM`]); *under a station*, the
//!   ΔV that moves that station 20–40 mm ([`UNDER_STATION_MM`]).
//!
//! Its position: at least 5 km from the main source anywhere over the network, 4–8 km deep (the
//! original scenario); 2–4 km from it (*near*), 3–4 km deep; or 6–12 km from it within the
//! network's box ± 2 km (*far*), 4–8 km deep for a pulse and 3–4 km for a lasting change; or
//! within 1 km of a station at least [`UNDER_STATION_APART_KM`] from it, 1.5–2.5 km deep
//! (*under a station*: the station sees most of it). Its start lies in the placement's period.
//!
//! Resolvable: a near source is mostly what the main source, moved a little, would produce —
//! within 4 km of it at most about 40 % of a 3–4 km deep source's field (in norm) is beyond the
//! main source's first-order reach, and at most about 25 % of a 4–8 km deep one's. Near sources
//! are therefore shallow and need [`MIN_RESOLVABLE_NEAR`]; the others [`MIN_RESOLVABLE`].

use super::super::draw::round3;
use super::super::scenario::{Distance, Shape};
use super::Ctx;
use anyhow::{bail, Result};
use magic_core::mogi::{self, Station};
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;
use std::f64::consts::{PI, TAU};

/// Smallest share of a second source's field the main source cannot mimic ([`resolvable`]).
pub const MIN_RESOLVABLE: f64 = 0.5;
/// The same for a source 2–4 km from the main one (the median share there is about 0.3).
pub const MIN_RESOLVABLE_NEAR: f64 = 0.25;
/// Draws of a position before giving up (on Akutan the constants above admit most draws; on
/// another network a failure says its geometry leaves no room for the scenario).
const MAX_DRAWS: usize = 100_000;
/// Smallest displacement (mm, norm at the most displaced station) of a lasting deflation at its
/// final volume.
pub const MIN_VISIBLE_MM: f64 = 8.0;
/// Displacement (mm, norm) of the station a source *under a station* lies under, at its final
/// volume: drawn in this range.
pub const UNDER_STATION_MM: [f64; 2] = [20.0, 40.0];
/// Least distance (km) from the main source of the station a source lies under.
pub const UNDER_STATION_APART_KM: f64 = 5.0;
/// Margin (km) around the network's box within which a far source lies.
pub const BOX_MARGIN_KM: f64 = 2.0;

/// How distinct a second source at `p` is from the main one at `main` (x, y, depth in km) for
/// this network: the share (in
/// norm, channels weighted by the white noise) of its displacement field that the main source
/// cannot produce by changing its position, depth or volume to first order. Near the main source
/// it is close to 0: the encoder would simply move the main source and nothing would be left to
/// find.
pub fn resolvable(stations: &[Station], main: [f64; 3], p: [f64; 3]) -> f64 {
    let ns = stations.len();
    let w = |c: usize| [1.0 / 1.2, 1.0 / 1.2, 1.0 / 3.5][c / ns];
    let field = |q: [f64; 4]| -> Vec<f64> {
        let mut u = vec![0.0; 3 * ns];
        mogi::field(stations, &q, &mut u).expect("valid source");
        u.iter().enumerate().map(|(c, v)| v * w(c)).collect()
    };
    let main = [main[0], main[1], main[2], 1.0];
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for j in 0..4 {
        let h = 1e-4;
        let (mut a, mut b) = (main, main);
        a[j] += h;
        b[j] -= h;
        let mut v: Vec<f64> = field(a)
            .iter()
            .zip(field(b))
            .map(|(x, y)| (x - y) / (2.0 * h))
            .collect();
        for q in &basis {
            let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(q).for_each(|(x, y)| *x -= d * y);
        }
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.iter_mut().for_each(|x| *x /= n);
        basis.push(v);
    }
    let g = field([p[0], p[1], p[2], 1.0]);
    let mut v = g.clone();
    for q in &basis {
        let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
        v.iter_mut().zip(q).for_each(|(x, y)| *x -= d * y);
    }
    (v.iter().map(|x| x * x).sum::<f64>() / g.iter().map(|x| x * x).sum::<f64>()).sqrt()
}

/// The network's box (x0, x1, y0, y1) widened by `m` km.
pub fn network_box(stations: &[Station], m: f64) -> [f64; 4] {
    stations.iter().fold(
        [f64::MAX, f64::MIN, f64::MAX, f64::MIN],
        |[x0, x1, y0, y1], s| {
            [
                x0.min(s.x_km - m),
                x1.max(s.x_km + m),
                y0.min(s.y_km - m),
                y1.max(s.y_km + m),
            ]
        },
    )
}

/// Norms (mm) of the displacement of every station by a source at `p` with ΔV `dv`.
fn station_norms(stations: &[Station], p: [f64; 3], dv: f64) -> Vec<f64> {
    let ns = stations.len();
    let mut u = vec![0.0; 3 * ns];
    mogi::field(stations, &[p[0], p[1], p[2], dv], &mut u).expect("valid second source");
    (0..ns)
        .map(|i| (0..3).map(|k| u[k * ns + i].powi(2)).sum::<f64>().sqrt())
        .collect()
}

/// Draws a position (x, y, depth) for `distance` and `shape` with its resolvable share;
/// `accept` adds a condition of the shape's own.
fn position(
    ctx: &Ctx<'_>,
    rng: &mut StdRng,
    shape: Shape,
    distance: Distance,
    accept: &dyn Fn([f64; 3]) -> bool,
) -> Result<([f64; 3], f64)> {
    let stations = &ctx.network.stations;
    let bx = network_box(stations, BOX_MARGIN_KM);
    let min_res = if distance == Distance::Near {
        MIN_RESOLVABLE_NEAR
    } else {
        MIN_RESOLVABLE
    };
    // The stations a source under a station may lie under.
    let apart: Vec<&Station> = (stations.iter())
        .filter(|s| (s.x_km - ctx.main[0]).hypot(s.y_km - ctx.main[1]) >= UNDER_STATION_APART_KM)
        .collect();
    if distance == Distance::UnderStation && apart.is_empty() {
        bail!(
            "no station {UNDER_STATION_APART_KM} km or more from the main source for a source \
             under a station"
        );
    }
    for _ in 0..MAX_DRAWS {
        let p = match distance {
            Distance::Apart => [
                rng.random_range(ctx.apart_box[0]..ctx.apart_box[1]),
                rng.random_range(ctx.apart_box[2]..ctx.apart_box[3]),
                rng.random_range(4.0..8.0),
            ],
            Distance::UnderStation => {
                let s = apart[rng.random_range(0..apart.len())];
                let (r, th): (f64, f64) = (rng.random_range(0.0..1.0), rng.random_range(0.0..TAU));
                [
                    s.x_km + r * th.cos(),
                    s.y_km + r * th.sin(),
                    rng.random_range(1.5..2.5),
                ]
            }
            Distance::Near | Distance::Far => {
                let (lo, hi) = if distance == Distance::Near {
                    (2.0, 4.0)
                } else {
                    (6.0, 12.0)
                };
                let (r, th): (f64, f64) = (rng.random_range(lo..hi), rng.random_range(0.0..TAU));
                let d = if shape == Shape::Pulse && distance == Distance::Far {
                    rng.random_range(4.0..8.0)
                } else {
                    rng.random_range(3.0..4.0)
                };
                [ctx.main[0] + r * th.cos(), ctx.main[1] + r * th.sin(), d]
            }
        };
        let res = resolvable(stations, ctx.main, p);
        let inside = p[0] >= bx[0] && p[0] <= bx[1] && p[1] >= bx[2] && p[1] <= bx[3];
        let apart =
            distance != Distance::Apart || (p[0] - ctx.main[0]).hypot(p[1] - ctx.main[1]) >= 5.0;
        if inside && apart && res >= min_res && accept(p) {
            return Ok((p, res));
        }
    }
    bail!(
        "no position for a {} second source ({}) on this network in {MAX_DRAWS} draws: within \
         its box ± {BOX_MARGIN_KM} km, at its distance from the main source and told apart \
         from it",
        format!("{distance:?}").to_lowercase(),
        format!("{shape:?}").to_lowercase()
    )
}

/// The share of its final (pulse: peak) volume change a source has `dt` days after its start,
/// for a course of `days` days.
pub fn course(shape: Shape, dt: f64, days: f64) -> f64 {
    if dt < 0.0 {
        return 0.0;
    }
    match shape {
        Shape::Pulse if dt > days => 0.0,
        Shape::Pulse => (PI * dt / days).sin().powi(2),
        Shape::Lasting => 0.5 * (1.0 - (PI * (dt / days).min(1.0)).cos()),
    }
}

/// Adds the source; `x_km`, `y_km`, `depth_km`, `start`, `end` (a pulse's last day, a lasting
/// change's first day at its final volume), `peak_dv_1e6m3` (the largest change), `shape`.
pub fn inject(
    ctx: &Ctx<'_>,
    rng: &mut StdRng,
    rows: &mut [Vec<f64>],
    shape: Shape,
    distance: Distance,
) -> Result<serde_json::Value> {
    let stations = &ctx.network.stations;
    let (p0, p1) = ctx.period();
    let len = p1 - p0;
    let (p, peak, start, days) = match shape {
        Shape::Pulse => {
            let (p, res) = position(ctx, rng, shape, distance, &|_| true)?;
            // Peak ΔV: the part of the field the main source cannot mimic has a network RMS of
            // 6–9 mm at the peak (the whole field at most 30 mm at any station); inflation or
            // deflation.
            let norms = station_norms(stations, p, 1.0);
            let umax = norms.iter().fold(0.0f64, |a, b| a.max(*b));
            let urms = (norms.iter().map(|v| v * v).sum::<f64>() / norms.len() as f64).sqrt();
            let target = rng.random_range(6.0..9.0);
            let peak = (target / (res * urms)).min(30.0 / umax)
                * if rng.random::<bool>() { 1.0 } else { -1.0 };
            let dur = rng.random_range(200..500usize.min(len - 201));
            let start = rng.random_range(p0 + 100..p1 - 100 - dur);
            (p, peak, start, dur)
        }
        Shape::Lasting => {
            let (p, peak) = if distance == Distance::UnderStation {
                let (p, _) = position(ctx, rng, shape, distance, &|_| true)?;
                let umax = (station_norms(stations, p, 1.0).iter()).fold(0.0f64, |a, b| a.max(*b));
                (
                    p,
                    -rng.random_range(UNDER_STATION_MM[0]..UNDER_STATION_MM[1]) / umax,
                )
            } else {
                let peak = -rng.random_range(0.8..1.1);
                let visible = |q: [f64; 3]| {
                    station_norms(stations, q, peak)
                        .iter()
                        .any(|v| *v >= MIN_VISIBLE_MM)
                };
                (position(ctx, rng, shape, distance, &visible)?.0, peak)
            };
            let rise = rng.random_range(60..=120usize);
            let margin = len / 10;
            let start = rng.random_range(p0 + margin..p1 - margin - rise);
            (p, peak, start, rise)
        }
    };
    let last = match shape {
        Shape::Pulse => start + days + 1,
        Shape::Lasting => rows.len(),
    };
    let mut u = vec![0.0; rows[0].len()];
    for (t, row) in rows.iter_mut().enumerate().take(last).skip(start) {
        let dv = peak * course(shape, (t - start) as f64, days as f64);
        mogi::field(stations, &[p[0], p[1], p[2], dv], &mut u).expect("valid second source");
        for (o, v) in row.iter_mut().zip(&u) {
            *o += v;
        }
    }
    Ok(json!({
        "x_km": round3(p[0]), "y_km": round3(p[1]), "depth_km": round3(p[2]),
        "start": ctx.date(start), "end": ctx.date(start + days),
        "peak_dv_1e6m3": (peak * 1e4).round() / 1e4,
        "shape": match shape { Shape::Pulse => "pulse", Shape::Lasting => "lasting" },
    }))
}
