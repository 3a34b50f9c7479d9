//! Synthetic GNSS data on the Akutan network: Mogi transients plus realistic noise, in the exact
//! layout of the paper's `gnss/` folder, so every command reads it like measured data.
//!
//! The generator: a source near the volcano's summit (x 0.3 km, y 0.2 km, depth 7 km) whose volume
//! changes through smooth inflation/deflation episodes (one large early event in the test period,
//! like 2008, and smaller ones later); per series white noise and a slow AR(1) random walk; a daily
//! network common mode; optionally one injected effect (see [`Scenario`]). Standardisation uses
//! the training split's mean and standard deviation, as in the release.

use crate::data::gnss::{channel_names, GnssData, Split};
use anyhow::{Context, Result};
use magic_core::mogi::{self, Station};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::path::Path;

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
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scenario {
    /// Mogi transients and noise only.
    Clean,
}

impl Scenario {
    /// Parses a scenario name.
    pub fn parse(name: &str) -> Result<Scenario> {
        match name {
            "clean" => Ok(Scenario::Clean),
            other => anyhow::bail!("unknown scenario `{other}` (expected: clean)"),
        }
    }
}

/// A generated dataset with the truth behind it.
pub struct Synthetic {
    /// The data, standardised like the release.
    pub data: GnssData,
    /// Source volume change per day (10⁶ m³), over all periods in time order.
    pub dv: Vec<f64>,
    /// What was injected (JSON).
    pub truth: serde_json::Value,
}

/// The true source position and depth.
pub const SOURCE: [f64; 3] = [0.3, 0.2, 7.0];

fn normal(rng: &mut StdRng) -> f64 {
    // Box–Muller.
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

fn episode(t: f64, start: f64, rise: f64, peak: f64, decay: f64) -> f64 {
    if t < start {
        return 0.0;
    }
    let up = 0.5 * (1.0 - (std::f64::consts::PI * ((t - start) / rise).min(1.0)).cos());
    let down = if t > start + rise { (-(t - start - rise) / decay).exp() } else { 1.0 };
    peak * up * (0.4 + 0.6 * down)
}

/// Civil date of a day number counted from 1970-01-01.
pub fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// Generates a dataset.
pub fn generate(scenario: Scenario, seed: u64) -> Synthetic {
    let mut rng = StdRng::seed_from_u64(seed);
    let stations: Vec<Station> = AKUTAN.iter().map(|s| Station { x_km: s.1, y_km: s.2, z_km: s.3 }).collect();
    let names: Vec<String> = AKUTAN.iter().map(|s| s.0.to_string()).collect();
    let ns = stations.len();
    let n_days: usize = PERIODS.iter().sum();
    // Episodes: (start day, rise days, peak ΔV, decay days), jittered by the seed.
    let mut eps = vec![(300.0, 150.0, 5.0, 400.0)];
    for (start, peak) in [(1200.0, 3.0), (1900.0, -2.0), (2500.0, 3.5), (3000.0, 2.5)] {
        let j = rng.random_range(-60.0..60.0);
        eps.push((start + j, rng.random_range(60.0..160.0), peak * rng.random_range(0.7..1.3), rng.random_range(200.0..500.0)));
    }
    let dv: Vec<f64> = (0..n_days).map(|t| eps.iter().map(|e| episode(t as f64, e.0, e.1, e.2, e.3)).sum()).collect();
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
    // Splits: test first (holds the big event), then train, then valid.
    let [n_test, n_train, _] = PERIODS;
    let ranges = [(n_test, n_test + n_train), (n_test + n_train, n_days), (0, n_test)];
    let train_rows = &mm[ranges[0].0..ranges[0].1];
    let n = 3 * ns;
    let mean: Vec<f64> = (0..n).map(|c| train_rows.iter().map(|r| r[c]).sum::<f64>() / train_rows.len() as f64).collect();
    let scale: Vec<f64> = (0..n)
        .map(|c| (train_rows.iter().map(|r| (r[c] - mean[c]).powi(2)).sum::<f64>() / train_rows.len() as f64).sqrt())
        .collect();
    let day0 = 13_149; // 2006-01-01
    let split = |(a, b): (usize, usize)| Split {
        x: mm[a..b].iter().map(|r| r.iter().enumerate().map(|(c, v)| ((v - mean[c]) / scale[c]) as f32).collect()).collect(),
        dates: (a..b)
            .map(|t| {
                let (y, m, d) = civil(day0 + t as i64);
                format!("{y:04}.{m:02}.{d:02}")
            })
            .collect(),
    };
    let (train, valid, test) = (split(ranges[0]), split(ranges[1]), split(ranges[2]));
    let data = GnssData {
        names,
        stations,
        mean,
        scale,
        train,
        valid,
        test,
        source: format!("synthetic (scenario {scenario:?}, seed {seed})"),
    };
    let truth = json!({
        "scenario": format!("{scenario:?}").to_lowercase(),
        "seed": seed,
        "source": {"x_km": SOURCE[0], "y_km": SOURCE[1], "depth_km": SOURCE[2]},
        "episodes": eps.iter().map(|e| json!({"start_day": e.0, "rise_days": e.1, "peak_dv_1e6m3": e.2, "decay_days": e.3})).collect::<Vec<_>>(),
        "effect": null,
    });
    Synthetic { data, dv, truth }
}

/// Writes a dataset in the release layout (`train.csv`, `valid.csv`, `test.csv`,
/// `train_x_mean.csv`, `train_x_scale.csv`, `stations.json`).
pub fn write_dir(data: &GnssData, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let cols = channel_names(&data.names);
    for (name, split) in [("train", &data.train), ("valid", &data.valid), ("test", &data.test)] {
        let path = dir.join(format!("{name}.csv"));
        let mut w = csv::Writer::from_path(&path).with_context(|| format!("{}: cannot write", path.display()))?;
        let mut header = cols.clone();
        header.extend(["date".to_string(), "sin_date".to_string(), "cos_date".to_string()]);
        w.write_record(&header)?;
        for (row, date) in split.x.iter().zip(&split.dates) {
            let doy = day_of_year(date);
            let ang = 2.0 * std::f64::consts::PI * doy / 365.25;
            let mut rec: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            rec.extend([date.clone(), ang.sin().to_string(), ang.cos().to_string()]);
            w.write_record(&rec)?;
        }
        w.flush()?;
    }
    let vec_file = |name: &str, v: &[f64]| -> Result<()> {
        let text: String = v.iter().map(|x| format!("{x}\n")).collect();
        std::fs::write(dir.join(name), text).with_context(|| format!("{name}: cannot write"))
    };
    vec_file("train_x_mean.csv", &data.mean)?;
    vec_file("train_x_scale.csv", &data.scale)?;
    let mut st = serde_json::Map::new();
    for (n, s) in data.names.iter().zip(&data.stations) {
        st.insert(n.clone(), json!({"xE": s.x_km, "yN": s.y_km, "zV": s.z_km}));
    }
    std::fs::write(dir.join("stations.json"), serde_json::to_string_pretty(&st)?)?;
    Ok(())
}

/// Day of year (1-based) of a `YYYY.MM.DD` date; 0 when it does not parse.
pub fn day_of_year(date: &str) -> f64 {
    let p: Vec<u32> = date.split(['.', '-']).filter_map(|s| s.parse().ok()).collect();
    if p.len() != 3 {
        return 0.0;
    }
    const CUM: [u32; 12] = [0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334];
    let leap = (p[0] % 4 == 0 && p[0] % 100 != 0) || p[0] % 400 == 0;
    let m = (p[1].clamp(1, 12) - 1) as usize;
    (CUM[m] + p[2] + u32::from(leap && m >= 2)) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(civil(0), (1970, 1, 1));
        assert_eq!(civil(13_149), (2006, 1, 1));
        assert_eq!(civil(13_149 + 59), (2006, 3, 1));
        assert_eq!(day_of_year("2008.03.01"), 61.0);
    }

    #[test]
    fn dataset_is_standardised_and_repeatable() {
        let a = generate(Scenario::Clean, 3);
        let b = generate(Scenario::Clean, 3);
        assert_eq!(a.data.test.x[10], b.data.test.x[10]);
        let n = a.data.train.len() as f64;
        let m: f64 = a.data.train.x.iter().map(|r| r[5] as f64).sum::<f64>() / n;
        assert!(m.abs() < 1e-5);
        assert_eq!(a.data.test.len(), PERIODS[0]);
        assert_eq!(a.data.test.dates[0], "2006.01.01");
    }
}
