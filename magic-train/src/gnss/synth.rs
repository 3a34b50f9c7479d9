//! Synthetic GNSS data on the Akutan network: Mogi transients plus realistic noise, in the exact
//! layout of the paper's `gnss/` folder, so every command reads it like measured data.
//!
//! The generator: a source near the volcano's summit (x 0.3 km, y 0.2 km, depth 7 km) whose volume
//! changes through smooth inflation/deflation episodes (one large early event in the test period,
//! like 2008, and smaller ones later); per series white noise and a slow AR(1) random walk; a daily
//! network common mode; optionally one injected effect (see [`Scenario`]). Standardisation uses
//! the training split's mean and standard deviation, as in the release.

use super::{GnssProblem, Network};
use crate::data::{Dataset, Split};
use anyhow::Result;
use magic_core::mogi::{self, Station};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::f64::consts::TAU;

/// The 12-station Akutan network (names and local coordinates in km, from the paper's release).
pub const AKUTAN: [(&str, f64, f64, f64); 12] = [
    ("AKGG", -4.244574836673032, 6.221955042489944, 0.350196119),
    ("AKLV", -1.7677533644105052, 2.2725848191107487, 0.54330034),
    ("AKMO", -5.477920742318134, -5.790374836251886, 0.297990048),
    ("AKRB", -9.32902438456132, -1.4528091110080028, 0.364130125),
    ("AV06", 10.695067474877963, 0.5454036872172899, 0.463075431),
    ("AV07", -7.188493723225915, 2.29941031417796, 0.521042586),
    ("AV08", -6.519939868860499, -0.6656350960809836, 0.598389266),
    ("AV10", -0.3225714797235971, -4.97215110923805, 0.329520899),
    ("AV12", 2.0491837994025177, 7.626908495832568, 0.404696868),
    ("AV13", 2.034404208043046, 1.2023486352773183, 0.494730786),
    ("AV14", 5.726242766165519, -2.6029585922179708, 0.396322137),
    ("AV15", 14.35703605108024, -4.684531481081493, 0.457414694),
];

/// Days in the test, training and validation periods (in that order in time, as in the release).
pub const PERIODS: [usize; 3] = [900, 1900, 500];

/// The scenario: which effect, if any, is hidden in the data.
///
/// Every scenario starts from the same clean data for a given seed (the effect draws its random
/// parameters from a separate generator), so `generate(X, s)` is `generate(Clean, s)` plus one
/// effect. Amplitudes are of the order of the noise (a few mm). Effects that are not events are
/// present in all three periods; the step and the second source happen inside the training period.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum Scenario {
    /// Mogi transients and noise only.
    Clean,
    /// A network translation (E, N, U) wandering over weeks to months (an AR(1) with a 60-day time
    /// scale), RMS 1.5–3 mm horizontally and 3–6 mm vertically.
    CommonMode,
    /// Per-station annual and semiannual terms with random amplitudes and phases.
    Seasonal,
    /// A vertical term `k(t) · (zᵢ − z̄)` with k varying over weeks and seasons (RMS 25–50 mm/km).
    Elevation,
    /// A step of a few mm at one station at an epoch inside the training period.
    Step,
    /// A second Mogi source (4–8 km deep, at least 5 km from the main one and resolvable from it:
    /// see [`resolvable`]) inflating then
    /// deflating once (or the reverse) within a window of 200–500 days inside the training period,
    /// with 6–9 mm (network RMS at the peak) of its field beyond what moving the main source can
    /// mimic (the main source: about 8 mm per 3·10⁶ m³).
    SecondSource,
    /// A linear drift (a few mm/yr) at one to three stations over the whole record.
    Drift,
}

impl Scenario {
    /// Every scenario, `clean` first.
    pub const ALL: [Scenario; 7] = [
        Scenario::Clean,
        Scenario::CommonMode,
        Scenario::Seasonal,
        Scenario::Elevation,
        Scenario::Step,
        Scenario::SecondSource,
        Scenario::Drift,
    ];

    /// The scenario's name (the effect family it injects, or `clean`).
    pub fn name(self) -> &'static str {
        match self {
            Scenario::Clean => "clean",
            Scenario::CommonMode => "common_mode",
            Scenario::Seasonal => "seasonal",
            Scenario::Elevation => "elevation",
            Scenario::Step => "step",
            Scenario::SecondSource => "second_source",
            Scenario::Drift => "drift",
        }
    }

    /// Parses a scenario name.
    pub fn parse(name: &str) -> Result<Scenario> {
        Scenario::ALL
            .iter()
            .copied()
            .find(|s| s.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = Scenario::ALL.iter().map(|s| s.name()).collect();
                anyhow::anyhow!(
                    "unknown scenario `{name}` (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// A generated dataset with the truth behind it.
pub struct Synthetic {
    /// The data, standardised like the release.
    pub problem: GnssProblem,
    /// Source volume change per day (10⁶ m³), over all periods in time order.
    pub dv: Vec<f64>,
    /// What was injected (JSON).
    pub truth: serde_json::Value,
}

/// The true source position and depth.
pub const SOURCE: [f64; 3] = [0.3, 0.2, 7.0];

/// A standard normal sample (Box–Muller).
pub fn normal(rng: &mut StdRng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

fn episode(t: f64, start: f64, rise: f64, peak: f64, decay: f64) -> f64 {
    if t < start {
        return 0.0;
    }
    let up = 0.5 * (1.0 - (std::f64::consts::PI * ((t - start) / rise).min(1.0)).cos());
    let down = if t > start + rise {
        (-(t - start - rise) / decay).exp()
    } else {
        1.0
    };
    peak * up * (0.4 + 0.6 * down)
}

/// Generates a dataset.
pub fn generate(scenario: Scenario, seed: u64) -> Synthetic {
    let mut rng = StdRng::seed_from_u64(seed);
    let stations: Vec<Station> = AKUTAN
        .iter()
        .map(|s| Station {
            x_km: s.1,
            y_km: s.2,
            z_km: s.3,
        })
        .collect();
    let names: Vec<String> = AKUTAN.iter().map(|s| s.0.to_string()).collect();
    let ns = stations.len();
    let n_days: usize = PERIODS.iter().sum();
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
    let dv: Vec<f64> = (0..n_days)
        .map(|t| {
            eps.iter()
                .map(|e| episode(t as f64, e.0, e.1, e.2, e.3))
                .sum()
        })
        .collect();
    let sigma_white = [1.2, 1.2, 3.5];
    let sigma_ar = [0.15, 0.15, 0.4];
    let sigma_cm = [0.8, 0.8, 2.0];
    let phi = 0.995;
    let mut ar = vec![0.0f64; 3 * ns];
    let mut mm = vec![vec![0.0f64; 3 * ns]; n_days];
    let mut u = vec![0.0f64; 3 * ns];
    for (t, row) in mm.iter_mut().enumerate() {
        let p = [SOURCE[0], SOURCE[1], SOURCE[2], dv[t]];
        mogi::field(&stations, &p, &mut u).expect("valid synthetic source");
        let cm: [f64; 3] = core::array::from_fn(|k| sigma_cm[k] * normal(&mut rng));
        for c in 0..3 * ns {
            let k = c / ns;
            ar[c] = phi * ar[c] + sigma_ar[k] * normal(&mut rng);
            row[c] = u[c] + cm[k] + ar[c] + sigma_white[k] * normal(&mut rng);
        }
    }
    let day0 = 13_149; // 2006-01-01
    let effect = inject(scenario, seed, &stations, &names, day0, &mut mm);
    // Splits: test first (holds the big event), then train, then valid.
    let [n_test, n_train, _] = PERIODS;
    let ranges = [
        (n_test, n_test + n_train),
        (n_test + n_train, n_days),
        (0, n_test),
    ];
    let train_rows = &mm[ranges[0].0..ranges[0].1];
    let n = 3 * ns;
    let mean: Vec<f64> = (0..n)
        .map(|c| train_rows.iter().map(|r| r[c]).sum::<f64>() / train_rows.len() as f64)
        .collect();
    let scale: Vec<f64> = (0..n)
        .map(|c| {
            (train_rows
                .iter()
                .map(|r| (r[c] - mean[c]).powi(2))
                .sum::<f64>()
                / train_rows.len() as f64)
                .sqrt()
        })
        .collect();
    let split = |(a, b): (usize, usize)| Split {
        x: mm[a..b]
            .iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .map(|(c, v)| ((v - mean[c]) / scale[c]) as f32)
                    .collect()
            })
            .collect(),
        dates: (a..b)
            .map(|t| {
                let (y, m, d) = magic_core::time::civil_from_days(day0 + t as i64);
                format!("{y:04}.{m:02}.{d:02}")
            })
            .collect(),
        ..Split::default()
    };
    let (train, valid, test) = (split(ranges[0]), split(ranges[1]), split(ranges[2]));
    let network = Network { names, stations };
    let data = Dataset {
        columns: network.channel_names(),
        mean,
        scale,
        train,
        valid,
        test,
        source: format!("synthetic (scenario {}, seed {seed})", scenario.name()),
    };
    let truth = json!({
        "scenario": scenario.name(),
        "seed": seed,
        "source": {"x_km": SOURCE[0], "y_km": SOURCE[1], "depth_km": SOURCE[2]},
        "episodes": eps.iter().map(|e| json!({"start_day": e.0, "rise_days": e.1, "peak_dv_1e6m3": e.2, "decay_days": e.3})).collect::<Vec<_>>(),
        "effect": effect,
    });
    Synthetic {
        problem: GnssProblem {
            network,
            data,
            source_bounds: super::SourceBounds::paper(),
        },
        dv,
        truth,
    }
}

/// `YYYY-MM-DD` of a day number.
pub fn iso_date(days: i64) -> String {
    let (y, m, d) = magic_core::time::civil_from_days(days);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Period of the training split in the synthetic record (day indices `[start, end)`).
pub fn train_range() -> (usize, usize) {
    (PERIODS[0], PERIODS[0] + PERIODS[1])
}

/// An AR(1) series of `n` values with time scale `tau` days (stationary start, unit innovations).
fn ar1(rng: &mut StdRng, n: usize, tau: f64) -> Vec<f64> {
    let phi = (-1.0 / tau).exp();
    let mut x = normal(rng) / (1.0 - phi * phi).sqrt();
    (0..n)
        .map(|_| {
            x = phi * x + normal(rng);
            x
        })
        .collect()
}

/// Rescales `v` so that, over the training period and about its mean there, its RMS is `rms`
/// (the residual analysis works on the training split, where constants are removed).
fn set_train_rms(v: &mut [f64], rms: f64) {
    let (a, b) = train_range();
    let n = (b - a) as f64;
    let mean = v[a..b].iter().sum::<f64>() / n;
    let cur = (v[a..b].iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    for x in v.iter_mut() {
        *x = (*x - mean) * rms / cur;
    }
}

fn sym(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    let v = rng.random_range(lo..hi);
    if rng.random::<bool>() {
        v
    } else {
        -v
    }
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// How distinct a second source at `p` is from the main one for this network: the share (in
/// norm, channels weighted by the white noise) of its displacement field that the main source
/// cannot produce by changing its position, depth or volume to first order. Near the main source
/// it is close to 0: the encoder would simply move the main source and nothing would be left to
/// find.
pub fn resolvable(stations: &[Station], p: [f64; 3]) -> f64 {
    let ns = stations.len();
    let w = |c: usize| [1.0 / 1.2, 1.0 / 1.2, 1.0 / 3.5][c / ns];
    let field = |q: [f64; 4]| -> Vec<f64> {
        let mut u = vec![0.0; 3 * ns];
        mogi::field(stations, &q, &mut u).expect("valid source");
        u.iter().enumerate().map(|(c, v)| v * w(c)).collect()
    };
    let main = [SOURCE[0], SOURCE[1], SOURCE[2], 1.0];
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

/// Adds the scenario's effect to the rows (mm, channel order uₑ ×S, uₙ ×S, uᵥ ×S; row `t` is day
/// `day0 + t`) and returns its description `{"family", "params"}` (null for `clean`). The effect's
/// random draws come from their own generator so the noise and the source are the clean ones.
fn inject(
    scenario: Scenario,
    seed: u64,
    stations: &[Station],
    names: &[String],
    day0: i64,
    mm: &mut [Vec<f64>],
) -> serde_json::Value {
    let ns = stations.len();
    let n_days = mm.len();
    let idx = Scenario::ALL
        .iter()
        .position(|s| *s == scenario)
        .unwrap_or(0) as u64;
    let mut rng =
        StdRng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (0xEFFE_C700 + idx));
    let (tr0, tr1) = train_range();
    let day = |t: usize| (day0 + t as i64) as f64;
    let per_station = |v: &dyn Fn(usize) -> [f64; 3]| -> serde_json::Value {
        let mut m = serde_json::Map::new();
        for (i, n) in names.iter().enumerate() {
            m.insert(n.clone(), json!(v(i).map(round3)));
        }
        serde_json::Value::Object(m)
    };
    let params = match scenario {
        Scenario::Clean => return serde_json::Value::Null,
        Scenario::CommonMode => {
            let rms = [
                rng.random_range(1.5..3.0),
                rng.random_range(1.5..3.0),
                rng.random_range(3.0..6.0),
            ];
            for (k, r) in rms.iter().enumerate() {
                let mut v = ar1(&mut rng, n_days, 60.0);
                set_train_rms(&mut v, *r);
                for (t, row) in mm.iter_mut().enumerate() {
                    for o in &mut row[k * ns..(k + 1) * ns] {
                        *o += v[t];
                    }
                }
            }
            json!({"rms_mm": rms.map(round3)})
        }
        Scenario::Seasonal => {
            // Per channel: annual amplitude and phase, semiannual amplitude (a fraction of the
            // annual) and phase; the basis is that of the Seasonal effect (t = day number).
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
            for (t, row) in mm.iter_mut().enumerate() {
                let w = TAU * day(t) / 365.25;
                let b = [w.sin(), w.cos(), (2.0 * w).sin(), (2.0 * w).cos()];
                for (c, o) in row.iter_mut().enumerate() {
                    *o += (0..4).map(|j| coef[c][j] * b[j]).sum::<f64>();
                }
            }
            json!({
                "annual_mm": per_station(&|i| [amp[i][0], amp[ns + i][0], amp[2 * ns + i][0]]),
                "semiannual_mm": per_station(&|i| [amp[i][1], amp[ns + i][1], amp[2 * ns + i][1]]),
            })
        }
        Scenario::Elevation => {
            let rate = rng.random_range(25.0..50.0);
            let z_ref = stations.iter().map(|s| s.z_km).sum::<f64>() / ns as f64;
            // Weather (an AR(1) over ~20 days) plus a season, then scaled to the RMS.
            let mut k = ar1(&mut rng, n_days, 20.0);
            let (ph, w_s) = (rng.random_range(0.0..TAU), rng.random_range(0.5..1.5));
            for (t, v) in k.iter_mut().enumerate() {
                *v += w_s * (TAU * day(t) / 365.25 + ph).sin();
            }
            set_train_rms(&mut k, rate);
            for (t, row) in mm.iter_mut().enumerate() {
                for (i, st) in stations.iter().enumerate() {
                    row[2 * ns + i] += k[t] * (st.z_km - z_ref);
                }
            }
            json!({"mm_per_km": round3(rate), "z_ref_km": z_ref})
        }
        Scenario::Step => {
            let i = rng.random_range(0..ns);
            let len = (tr1 - tr0) as f64;
            let e = tr0 + rng.random_range(0.2 * len..0.8 * len) as usize;
            let off = [
                sym(&mut rng, 3.0, 6.0),
                sym(&mut rng, 3.0, 6.0),
                sym(&mut rng, 6.0, 12.0),
            ];
            for row in &mut mm[e..] {
                for k in 0..3 {
                    row[k * ns + i] += off[k];
                }
            }
            json!({"station": names[i], "epoch": iso_date(day0 + e as i64), "offset_mm": off.map(round3)})
        }
        Scenario::SecondSource => {
            let (x, y, depth, res) = loop {
                let (x, y, d) = (
                    rng.random_range(-8.0..12.0),
                    rng.random_range(-5.0..7.0),
                    rng.random_range(4.0..8.0),
                );
                let res = resolvable(stations, [x, y, d]);
                if (x - SOURCE[0]).hypot(y - SOURCE[1]) >= 5.0 && res >= 0.5 {
                    break (x, y, d, res);
                }
            };
            // Peak ΔV: the part of the field the main source cannot mimic has a network RMS of
            // 6–9 mm at the peak (the whole field at most 30 mm at any station); inflation or
            // deflation.
            let mut u = vec![0.0; 3 * ns];
            mogi::field(stations, &[x, y, depth, 1.0], &mut u).expect("valid second source");
            let norms: Vec<f64> = (0..ns)
                .map(|i| (0..3).map(|k| u[k * ns + i].powi(2)).sum::<f64>().sqrt())
                .collect();
            let umax = norms.iter().fold(0.0f64, |a, b| a.max(*b));
            let urms = (norms.iter().map(|v| v * v).sum::<f64>() / ns as f64).sqrt();
            let target = rng.random_range(6.0..9.0);
            let peak = (target / (res * urms)).min(30.0 / umax)
                * if rng.random::<bool>() { 1.0 } else { -1.0 };
            let dur = rng.random_range(200..500usize);
            let start = rng.random_range(tr0 + 100..tr1 - 100 - dur);
            for (t, row) in mm.iter_mut().enumerate().skip(start).take(dur + 1) {
                let dv = peak
                    * (std::f64::consts::PI * (t - start) as f64 / dur as f64)
                        .sin()
                        .powi(2);
                mogi::field(stations, &[x, y, depth, dv], &mut u).expect("valid second source");
                for (o, v) in row.iter_mut().zip(&u) {
                    *o += v;
                }
            }
            json!({
                "x_km": round3(x), "y_km": round3(y), "depth_km": round3(depth),
                "start": iso_date(day0 + start as i64), "end": iso_date(day0 + (start + dur) as i64),
                "peak_dv_1e6m3": (peak * 1e4).round() / 1e4,
            })
        }
        Scenario::Drift => {
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
                let r = [
                    sym(&mut rng, 2.0, 4.0),
                    sym(&mut rng, 2.0, 4.0),
                    sym(&mut rng, 4.0, 8.0),
                ];
                for (t, row) in mm.iter_mut().enumerate() {
                    let dt = (t as f64 - t0) / 365.25;
                    for k in 0..3 {
                        row[k * ns + i] += r[k] * dt;
                    }
                }
                rates.insert(names[i].clone(), json!(r.map(round3)));
            }
            json!({"rate_mm_per_yr": rates, "t0": iso_date(day0 + t0 as i64)})
        }
    };
    json!({"family": scenario.name(), "params": params})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(magic_core::time::civil_from_days(13_149), (2006, 1, 1));
        assert_eq!(crate::gnss::data::day_of_year("2008.03.01"), 61.0);
    }

    #[test]
    fn dataset_is_standardised_and_repeatable() {
        let a = generate(Scenario::Clean, 3);
        let b = generate(Scenario::Clean, 3);
        assert_eq!(a.problem.data.test.x[10], b.problem.data.test.x[10]);
        let n = a.problem.data.train.len() as f64;
        let m: f64 = a
            .problem
            .data
            .train
            .x
            .iter()
            .map(|r| r[5] as f64)
            .sum::<f64>()
            / n;
        assert!(m.abs() < 1e-5);
        assert_eq!(a.problem.data.test.len(), PERIODS[0]);
        assert_eq!(a.problem.data.test.dates[0], "2006.01.01");
    }
}
