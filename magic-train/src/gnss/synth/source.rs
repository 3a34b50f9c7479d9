//! The main source's history: a Mogi source near the volcano's summit (x 0.3 km, y 0.2 km,
//! depth 7 km) whose volume changes through episodes, one history per generator.
//!
//! - `paper`: a large inflation early in the test period (like 2008) and four smaller
//!   inflations and deflations later, each rising smoothly and relaxing partly.
//! - `red`: an inflation in early 2008 (4–6·10⁶ m³, rising over 2–5 months, then relaxing by
//!   40–70 % over one to three years) and a smaller pulse of the same source in 2021
//!   (1–2·10⁶ m³, up and back down within 6–12 months, starting in the training period).

use super::record::{iso_date, Layout};
use rand::rngs::StdRng;
use rand::Rng;
use serde_json::json;
use std::f64::consts::PI;

/// The true source position and depth (km).
pub const SOURCE: [f64; 3] = [0.3, 0.2, 7.0];

/// A history of the main source's volume change.
pub struct History {
    /// ΔV per day of the record (10⁶ m³).
    pub dv: Vec<f64>,
    /// The episodes as `truth.json` lists them.
    pub episodes: serde_json::Value,
}

/// One `paper` episode at day `t`: a raised-cosine rise over `rise` days from `start` to `peak`,
/// then 60 % of it decaying with time constant `decay`.
fn paper_episode(t: f64, start: f64, rise: f64, peak: f64, decay: f64) -> f64 {
    if t < start {
        return 0.0;
    }
    let up = 0.5 * (1.0 - (PI * ((t - start) / rise).min(1.0)).cos());
    let down = if t > start + rise {
        (-(t - start - rise) / decay).exp()
    } else {
        1.0
    };
    peak * up * (0.4 + 0.6 * down)
}

/// The `paper` history (draws from `rng`, before the noise does).
pub fn paper(rng: &mut StdRng, layout: &Layout) -> History {
    // Episodes: (start day, rise days, peak ΔV, decay days), jittered by the seed.
    let mut eps = vec![(300.0, 150.0, 5.0, 400.0)];
    for (start, peak) in [(1200.0, 3.0), (1900.0, -2.0), (2500.0, 3.5), (3000.0, 2.5)] {
        let j = rng.random_range(-60.0..60.0);
        eps.push((
            start + j,
            rng.random_range(60.0..160.0),
            peak * rng.random_range(0.7..1.3),
            rng.random_range(200.0..500.0),
        ));
    }
    let dv = (0..layout.n_days())
        .map(|t| {
            eps.iter()
                .map(|e| paper_episode(t as f64, e.0, e.1, e.2, e.3))
                .sum()
        })
        .collect();
    let episodes = eps
        .iter()
        .map(|e| json!({"start_day": e.0, "rise_days": e.1, "peak_dv_1e6m3": e.2, "decay_days": e.3}))
        .collect::<Vec<_>>();
    History {
        dv,
        episodes: json!(episodes),
    }
}

/// Day number of 1 January of `year`.
pub fn jan1(year: i32) -> i64 {
    magic_core::time::days_from_civil(year, 1, 1)
}

/// The `red` history on `layout` (2008 inflation and relaxation, 2021 pulse).
pub fn red(rng: &mut StdRng, layout: &Layout) -> History {
    let d0 = layout.day0 as f64;
    let start = (jan1(2008) as f64 - d0) + rng.random_range(0.0..75.0);
    let rise = rng.random_range(60.0..150.0);
    let peak = rng.random_range(4.0..6.0);
    let keep = rng.random_range(0.3..0.6);
    let relax = rng.random_range(365.0..1100.0);
    let p_start = (jan1(2021) as f64 - d0) + rng.random_range(0.0..120.0);
    let p_days = rng.random_range(180.0..360.0);
    let p_peak = rng.random_range(1.0..2.0);
    let dv = (0..layout.n_days())
        .map(|t| {
            let t = t as f64;
            let inflation = if t < start {
                0.0
            } else if t < start + rise {
                peak * 0.5 * (1.0 - (PI * (t - start) / rise).cos())
            } else {
                peak * (keep + (1.0 - keep) * (-(t - start - rise) / relax).exp())
            };
            let pulse = if t >= p_start && t <= p_start + p_days {
                p_peak * (PI * (t - p_start) / p_days).sin().powi(2)
            } else {
                0.0
            };
            inflation + pulse
        })
        .collect();
    let date = |t: f64| iso_date(layout.day0 + t.round() as i64);
    History {
        dv,
        episodes: json!([
            {"kind": "inflation", "start": date(start), "rise_days": rise, "peak_dv_1e6m3": peak,
             "kept_share": keep, "relax_days": relax},
            {"kind": "pulse", "start": date(p_start), "days": p_days, "peak_dv_1e6m3": p_peak},
        ]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::SplitName;
    use rand::SeedableRng;

    #[test]
    fn the_red_history_has_its_events_where_stated() {
        let l = Layout::RELEASE;
        for seed in 0..5 {
            let h = red(&mut StdRng::seed_from_u64(seed), &l);
            assert_eq!(h.dv.len(), l.n_days());
            // The 2008 inflation: nothing before 2008, its peak within 2008, inside the test
            // period.
            let t08 = l.row(jan1(2008)).unwrap();
            assert!(h.dv[..t08].iter().all(|v| *v == 0.0));
            let (ipk, pk) = h.dv[..l.range(SplitName::Train).0]
                .iter()
                .enumerate()
                .fold((0, 0.0), |b, (i, v)| if *v > b.1 { (i, *v) } else { b });
            assert!((4.0..6.0).contains(&pk), "peak {pk}");
            assert!(iso_date(l.day(ipk)).starts_with("2008"));
            // The 2021 pulse starts in the training period.
            let s = h.episodes[1]["start"].as_str().unwrap();
            let t = l.row(magic_core::time::parse_date(s).unwrap()).unwrap();
            let (a, b) = l.range(SplitName::Train);
            assert!(a <= t && t < b, "{s}");
        }
    }
}
