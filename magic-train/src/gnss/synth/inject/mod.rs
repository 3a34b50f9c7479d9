//! The injectors, one per effect family: each adds its effect to the record's rows (mm, channel
//! order uₑ ×S, uₙ ×S, uᵥ ×S; row `t` is day `layout.day0 + t`), drawing its parameters from its
//! own stream, and returns them as the analysis would report them (see [`super::truth`]).

pub mod common_mode;
pub mod drift;
pub mod elevation;
pub mod seasonal;
pub mod second_source;
pub mod step;

use super::noise::Background;
use super::record::Layout;
use crate::data::SplitName;
use crate::gnss::Network;

/// What an injector knows about the record.
pub struct Ctx<'a> {
    /// The network.
    pub network: &'a Network,
    /// The main source's position and depth (km).
    pub main: [f64; 3],
    /// The box (x0, x1, y0, y1; km) a second source apart from the main one is drawn over.
    pub apart_box: [f64; 4],
    /// The record.
    pub layout: Layout,
    /// The period in which events begin.
    pub placement: SplitName,
    /// What the noise holds (an injector of the same family states the total).
    pub background: &'a Background,
    /// The dataset's seed.
    pub seed: u64,
}

impl Ctx<'_> {
    /// Number of stations.
    pub fn ns(&self) -> usize {
        self.network.len()
    }

    /// Rows `[start, end)` of the placement's period.
    pub fn period(&self) -> (usize, usize) {
        self.layout.range(self.placement)
    }

    /// Rows `[start, end)` of the training period.
    pub fn train(&self) -> (usize, usize) {
        self.layout.range(SplitName::Train)
    }

    /// Day number of row `t`, as a real.
    pub fn day(&self, t: usize) -> f64 {
        self.layout.day(t) as f64
    }

    /// `YYYY-MM-DD` of row `t`.
    pub fn date(&self, t: usize) -> String {
        super::iso_date(self.layout.day(t))
    }

    /// A value per station (`{"AKGG": [e, n, u], …}`, rounded to three decimals).
    pub fn per_station(&self, v: &dyn Fn(usize) -> [f64; 3]) -> serde_json::Value {
        let m: serde_json::Map<String, serde_json::Value> = self
            .network
            .names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), serde_json::json!(v(i).map(super::draw::round3))))
            .collect();
        serde_json::Value::Object(m)
    }

    /// Rescales `v` so that, over the training period and about its mean there, its RMS is
    /// `rms` (the residual analysis works on the training split, where constants are removed).
    pub fn set_train_rms(&self, v: &mut [f64], rms: f64) {
        let (a, b) = self.train();
        let n = (b - a) as f64;
        let mean = v[a..b].iter().sum::<f64>() / n;
        let cur = (v[a..b].iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        for x in v.iter_mut() {
            *x = (*x - mean) * rms / cur;
        }
    }
}
