//! The noise models, each with its main-source history and its record ([`NoiseModel`]), and what
//! the noise itself holds that an analysis may rightly find ([`Background`]).
//!
//! - `paper`: per series white noise (1.2 mm horizontal, 3.5 mm vertical) and a slow AR(1)
//!   (φ = 0.995, innovations 0.15 / 0.4 mm), and a white daily common mode (0.8 / 2.0 mm): its
//!   common mode does not persist from day to day, so the noise holds no effect.
//! - `red`: per series white noise of differing levels (1.0–1.8 mm horizontal, 2.5–4.5 mm
//!   vertical), an AR(1) per series with φ = 0.98 (a 50-day time scale; standard deviation
//!   1.0–2.5 mm horizontal, 2.5–6 mm vertical), and a network common mode that is itself an
//!   AR(1) (φ = 0.9; 0.6–1.2 mm horizontal, 1.5–3 mm vertical) plus an annual term (0.5–1 mm
//!   horizontal, 1.5–3 mm vertical, random phase). That common mode persists: the noise holds a
//!   `common_mode` and a network-wide `seasonal` term, listed as the truth's `background`.

use super::draw::{ar1_phi, normal, rms_about_mean, round3, stream};
use super::record::Layout;
use super::source::{self, History};
use super::truth::Injected;
use crate::gnss::Network;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::f64::consts::TAU;

/// Which generator makes the noise and the main source's history.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum NoiseModel {
    /// The original generator (white + slow AR(1) per series, white daily common mode; five
    /// source episodes on a 2006–2015 record).
    Paper,
    /// An independent one (white of differing levels + AR(1) with φ = 0.98 per series, an
    /// AR(1) network common mode with an annual term; the 2008 inflation and a 2021 pulse on
    /// the release's 2006–2024 record).
    Red,
}

/// What the noise holds that is itself an effect family's signal.
#[derive(Clone, Debug, Default)]
pub struct Background {
    /// The persistent network common mode per component E, N, U (mm per day of the record).
    pub common: Option<[Vec<f64>; 3]>,
    /// Its annual and semiannual coefficients per component, in the basis
    /// `[sin ω, cos ω, sin 2ω, cos 2ω]` with `ω = 2π · day / 365.25`.
    pub seasonal: Option<[[f64; 4]; 3]>,
    /// The background effects as the truth lists them (`{"family", "params"}`).
    pub described: Vec<Injected>,
}

/// Salts of the `red` generator's streams.
const SALT_SOURCE: u64 = 0x52ED_0001;
const SALT_WHITE: u64 = 0x52ED_0002;
const SALT_SERIES: u64 = 0x52ED_0003;
const SALT_COMMON: u64 = 0x52ED_0004;

/// Persistence of the `red` per-series AR(1).
pub const RED_SERIES_PHI: f64 = 0.98;
/// Persistence of the `red` network common mode's AR(1).
pub const RED_COMMON_PHI: f64 = 0.9;

impl NoiseModel {
    /// Both models, `paper` first.
    pub const ALL: [NoiseModel; 2] = [NoiseModel::Paper, NoiseModel::Red];

    /// `paper` or `red`.
    pub fn name(self) -> &'static str {
        match self {
            NoiseModel::Paper => "paper",
            NoiseModel::Red => "red",
        }
    }

    /// The record this generator covers.
    pub fn layout(self) -> Layout {
        match self {
            NoiseModel::Paper => Layout::PAPER,
            NoiseModel::Red => Layout::RELEASE,
        }
    }

    /// The clean record: the main source's history, its field plus the noise (mm, one row per
    /// day, channels `uₑ ×S, uₙ ×S, uᵥ ×S`) and what the noise holds.
    pub fn clean_rows(
        self,
        seed: u64,
        network: &Network,
        main: [f64; 3],
        layout: &Layout,
    ) -> (History, Vec<Vec<f64>>, Background) {
        match self {
            NoiseModel::Paper => {
                // One generator for the history and the noise, in this order.
                let mut rng = StdRng::seed_from_u64(seed);
                let history = source::paper(&mut rng, layout);
                let mut rows = super::source_rows(network, main, &history.dv);
                paper(&mut rng, network.len(), &mut rows);
                (history, rows, Background::default())
            }
            NoiseModel::Red => {
                let history = source::red(&mut stream(seed, SALT_SOURCE), layout);
                let mut rows = super::source_rows(network, main, &history.dv);
                let background = red(seed, network, layout, &mut rows);
                (history, rows, background)
            }
        }
    }
}

/// Adds the `paper` noise to `rows`.
fn paper(rng: &mut StdRng, ns: usize, rows: &mut [Vec<f64>]) {
    let sigma_white = [1.2, 1.2, 3.5];
    let sigma_ar = [0.15, 0.15, 0.4];
    let sigma_cm = [0.8, 0.8, 2.0];
    let phi = 0.995;
    let mut ar = vec![0.0f64; 3 * ns];
    for row in rows.iter_mut() {
        let cm: [f64; 3] = core::array::from_fn(|k| sigma_cm[k] * normal(rng));
        for c in 0..3 * ns {
            let k = c / ns;
            ar[c] = phi * ar[c] + sigma_ar[k] * normal(rng);
            row[c] = row[c] + cm[k] + ar[c] + sigma_white[k] * normal(rng);
        }
    }
}

/// Levels of the `red` noise per series: white standard deviation and AR(1) standard deviation
/// (mm).
pub fn red_levels(seed: u64, ns: usize) -> Vec<[f64; 2]> {
    let mut rng = stream(seed, SALT_WHITE);
    (0..3 * ns)
        .map(|c| {
            if c < 2 * ns {
                [rng.random_range(1.0..1.8), rng.random_range(1.0..2.5)]
            } else {
                [rng.random_range(2.5..4.5), rng.random_range(2.5..6.0)]
            }
        })
        .collect()
}

/// The `red` per-series noise (white + AR(1)), `n` days × `3·ns` channels.
pub fn red_series(seed: u64, ns: usize, n: usize) -> Vec<Vec<f64>> {
    let levels = red_levels(seed, ns);
    let mut rng = stream(seed, SALT_SERIES);
    let phi = RED_SERIES_PHI;
    let cols: Vec<Vec<f64>> = levels
        .iter()
        .map(|[w, s]| {
            let ar = ar1_phi(&mut rng, n, phi, s * (1.0 - phi * phi).sqrt());
            ar.iter().map(|a| a + w * normal(&mut rng)).collect()
        })
        .collect();
    (0..n)
        .map(|t| cols.iter().map(|col| col[t]).collect())
        .collect()
}

/// The `red` network common mode per component (AR(1) plus annual term, mm) and the annual
/// term's coefficients.
pub fn red_common(seed: u64, layout: &Layout) -> ([Vec<f64>; 3], [[f64; 4]; 3]) {
    let mut rng = stream(seed, SALT_COMMON);
    let phi = RED_COMMON_PHI;
    let mut coef = [[0.0; 4]; 3];
    let series = core::array::from_fn(|k| {
        let (sd, amp) = if k < 2 {
            (rng.random_range(0.6..1.2), rng.random_range(0.5..1.0))
        } else {
            (rng.random_range(1.5..3.0), rng.random_range(1.5..3.0))
        };
        let ph: f64 = rng.random_range(0.0..TAU);
        coef[k] = [amp * ph.cos(), amp * ph.sin(), 0.0, 0.0];
        let ar = ar1_phi(
            &mut rng,
            layout.n_days(),
            phi,
            sd * (1.0 - phi * phi).sqrt(),
        );
        ar.iter()
            .enumerate()
            .map(|(t, a)| a + amp * (TAU * layout.day(t) as f64 / 365.25 + ph).sin())
            .collect()
    });
    (series, coef)
}

/// Adds the `red` noise to `rows` and returns what it holds.
fn red(seed: u64, network: &Network, layout: &Layout, rows: &mut [Vec<f64>]) -> Background {
    let ns = network.len();
    let series = red_series(seed, ns, rows.len());
    let (common, coef) = red_common(seed, layout);
    for (t, (row, s)) in rows.iter_mut().zip(&series).enumerate() {
        for (c, (o, v)) in row.iter_mut().zip(s).enumerate() {
            *o += v + common[c / ns][t];
        }
    }
    let rms: Vec<f64> = common.iter().map(|v| round3(rms_about_mean(v))).collect();
    let per_station = |j: usize| {
        let v: [f64; 3] = core::array::from_fn(|k| round3(coef[k][j].hypot(coef[k][j + 1])));
        let m: serde_json::Map<String, serde_json::Value> = network
            .names
            .iter()
            .map(|n| (n.clone(), json!(v)))
            .collect();
        serde_json::Value::Object(m)
    };
    Background {
        described: vec![
            Injected::new("common_mode", json!({"rms_mm": rms})),
            Injected::new(
                "seasonal",
                json!({"annual_mm": per_station(0), "semiannual_mm": per_station(2)}),
            ),
        ],
        common: Some(common),
        seasonal: Some(coef),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lag-one autocorrelation.
    fn lag1(v: &[f64]) -> f64 {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let num: f64 = v.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
        num / v.iter().map(|x| (x - m).powi(2)).sum::<f64>()
    }

    #[test]
    fn red_noise_has_its_stated_persistence_and_levels() {
        let (ns, n) = (12, 50_000);
        let s = red_series(4, ns, n);
        let levels = red_levels(4, ns);
        for c in [0, 7, 30] {
            let col: Vec<f64> = s.iter().map(|r| r[c]).collect();
            let [w, a] = levels[c];
            // Variance: white plus AR(1); lag-one autocorrelation φ·a²/(a² + w²). The sample
            // variance of a 50 000-day AR(1) with φ = 0.98 scatters by about 4.5 %: 15 % and
            // 0.05 leave more than three of those.
            let var = rms_about_mean(&col).powi(2);
            assert!(
                (var / (w * w + a * a) - 1.0).abs() < 0.15,
                "channel {c}: {var}"
            );
            let want = RED_SERIES_PHI * a * a / (a * a + w * w);
            assert!((lag1(&col) - want).abs() < 0.05, "channel {c}");
        }
        // Vertical levels 2–3 times the horizontal ones on average.
        let h: f64 = levels[..2 * ns].iter().map(|l| l[0] + l[1]).sum::<f64>() / (2 * ns) as f64;
        let v: f64 = levels[2 * ns..].iter().map(|l| l[0] + l[1]).sum::<f64>() / ns as f64;
        assert!((2.0..3.0).contains(&(v / h)), "{}", v / h);
    }

    #[test]
    fn the_red_common_mode_holds_its_annual_term() {
        let layout = Layout::RELEASE;
        let (series, coef) = red_common(9, &layout);
        for k in 0..3 {
            // Least-squares annual term of the series: its coefficients within 0.5 mm (the
            // AR(1) part over 18 years).
            let (mut s, mut c, mut n) = (0.0, 0.0, 0.0);
            for (t, v) in series[k].iter().enumerate() {
                let w = TAU * layout.day(t) as f64 / 365.25;
                s += v * w.sin();
                c += v * w.cos();
                n += 1.0;
            }
            let (s, c) = (2.0 * s / n, 2.0 * c / n);
            assert!((s - coef[k][0]).abs() < 0.5, "{k}: {s} vs {}", coef[k][0]);
            assert!((c - coef[k][1]).abs() < 0.5, "{k}: {c} vs {}", coef[k][1]);
        }
    }
}
