//! Calibration of the bootstrap standard deviations on synthetic data: for every significant
//! candidate of an injected family that carries an uncertainty, the share of its key parameters
//! whose true value lies within ±1 and ±2 standard deviations (about 68 % and 95 % if the sds tell
//! the truth); and beside them the estimates' mean error against the shift the bootstrap sees
//! (its draws' mean less the estimate): a bias the draws reproduce shows in both, one they miss
//! only in the first; and the factor that would calibrate the draws' own standard deviations
//! (the 68.27 % quantile of |estimate − truth| / raw sd), which a family sets on trial seeds
//! ([`Family::sd_factor`](crate::analysis::Family::sd_factor)), per noise model and over both. A
//! step counts only at the right station (another station's offsets say nothing).

use crate::analysis::Analysis;
use crate::data::dataset::day_number;
use crate::gnss::synth::truth::Injected;
use crate::numerics::{quantile, ONE_SIGMA};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// What is counted per (family, parameter, noise model).
#[derive(Clone, Debug, Default)]
struct Row {
    /// Estimates with a standard deviation.
    n: usize,
    /// Those within ±1 and ±2 sd of the truth.
    within: [usize; 2],
    /// Sum of the estimates' errors (estimate − truth).
    error: f64,
    /// Sum of the bootstrap's shifts (draws' mean − estimate).
    shift: f64,
    /// Each estimate's |error| in its draws' own standard deviations.
    raw_z: Vec<f64>,
}

impl Row {
    /// Adds `other`'s counts to these.
    fn merge(&mut self, other: &Row) {
        self.n += other.n;
        self.within[0] += other.within[0];
        self.within[1] += other.within[1];
        self.error += other.error;
        self.shift += other.shift;
        self.raw_z.extend_from_slice(&other.raw_z);
    }
}

/// Counts per (family, parameter, noise model).
#[derive(Clone, Debug, Default)]
pub struct Coverage {
    rows: BTreeMap<(String, String, String), Row>,
}

/// The true value of a key parameter (as the families name them) from the injected parameters.
///
/// ```
/// use magic_train::gnss::recovery::coverage::truth_value;
/// let p = serde_json::json!({"offset_mm": [1.0, -2.0, 3.5], "epoch": "1970-01-11"});
/// assert_eq!(truth_value("offset_u_mm", &p), Some(3.5));
/// assert_eq!(truth_value("epoch_day", &p), Some(10.0));
/// assert_eq!(truth_value("rms_n_mm", &p), None);
/// // A parameter on a log scale: the logarithm of the named one, if positive.
/// let s = serde_json::json!({"depth_km": 3.5, "dv": -1.0});
/// assert_eq!(truth_value("ln_depth_km", &s), Some(3.5f64.ln()));
/// assert_eq!(truth_value("ln_dv", &s), None);
/// ```
pub fn truth_value(param: &str, truth: &Value) -> Option<f64> {
    if let Some(rest) = param.strip_prefix("ln_") {
        return truth_value(rest, truth).filter(|v| *v > 0.0).map(f64::ln);
    }
    let component = |name: &str, k: usize| truth.get(name)?.get(k)?.as_f64();
    let axis = |s: &str| ["e", "n", "u"].iter().position(|a| *a == s);
    if let Some(rest) = param
        .strip_prefix("offset_")
        .and_then(|r| r.strip_suffix("_mm"))
    {
        return component("offset_mm", axis(rest)?);
    }
    if let Some(rest) = param
        .strip_prefix("rms_")
        .and_then(|r| r.strip_suffix("_mm"))
    {
        return component("rms_mm", axis(rest)?);
    }
    if param == "epoch_day" {
        let d = day_number(truth.get("epoch")?.as_str()?);
        return d.is_finite().then_some(d);
    }
    truth.get(param)?.as_f64()
}

/// `v` with three significant digits (`0` for zero; no exponent).
fn significant3(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

impl Coverage {
    /// Adds the analysis of one synthetic dataset (its injected effects, its noise model).
    pub fn add(&mut self, analysis: &Analysis, injected: &[Injected], noise: &str) {
        for inj in injected {
            let Some(c) = analysis
                .effects
                .iter()
                .find(|c| c.family == inj.family && c.significant)
            else {
                continue;
            };
            if inj.family == "step" && c.params.get("station") != inj.params.get("station") {
                continue;
            }
            for p in &c.uncertainty {
                let Some(truth) = truth_value(&p.name, &inj.params) else {
                    continue;
                };
                if p.sd.is_nan() || p.sd <= 0.0 {
                    continue;
                }
                let z = (p.value - truth).abs() / p.sd;
                let key = (inj.family.clone(), p.name.clone(), noise.to_string());
                let row = self.rows.entry(key).or_default();
                row.n += 1;
                row.within[0] += usize::from(z <= 1.0);
                row.within[1] += usize::from(z <= 2.0);
                row.error += p.value - truth;
                row.shift += p.draws_mean - p.value;
                if p.sd_raw > 0.0 {
                    row.raw_z.push((p.value - truth).abs() / p.sd_raw);
                }
            }
        }
    }

    /// The Markdown table: family, parameter, noise model (and `both`, where there are two or
    /// more), estimates, shares within ±1 and ±2 sd, the estimates' mean error, the bootstrap's
    /// mean shift (three significant digits, in the parameter's units) and the factor that would
    /// calibrate the draws' own sds (two decimals).
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| family | parameter | noise | n | within ±1 sd | within ±2 sd | mean error | bootstrap's mean shift | raw sd's factor |\n|---|---|---|---|---|---|---|---|---|\n",
        );
        let mut pooled: BTreeMap<(String, String), (usize, Row)> = BTreeMap::new();
        for ((family, param, _), r) in &self.rows {
            let e = pooled.entry((family.clone(), param.clone())).or_default();
            e.0 += 1;
            e.1.merge(r);
        }
        let both: BTreeMap<(String, String, String), Row> = pooled
            .into_iter()
            .filter(|(_, (k, _))| *k > 1)
            .map(|((f, p), (_, r))| ((f, p, "both".to_string()), r))
            .collect();
        for ((family, param, noise), r) in self.rows.iter().chain(&both) {
            let n = r.n.max(1) as f64;
            let pct = |k: usize| 100.0 * k as f64 / n;
            let _ = writeln!(
                s,
                "| {family} | {param} | {noise} | {} | {:.0} % | {:.0} % | {} | {} | {:.2} |",
                r.n,
                pct(r.within[0]),
                pct(r.within[1]),
                significant3(r.error / n),
                significant3(r.shift / n),
                quantile(&r.raw_z, ONE_SIGMA)
            );
        }
        s
    }

    /// Whether nothing was counted.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::{Candidate, ParamSd};
    use serde_json::json;

    fn analysis(station: &str, value: f64, sd: f64) -> Analysis {
        analysis_drawn(station, value, sd, value)
    }

    fn analysis_drawn(station: &str, value: f64, sd: f64, draws_mean: f64) -> Analysis {
        analysis_scaled(station, value, sd, draws_mean, 1.0)
    }

    /// A step at `station` whose offset's sd is the draws' `sd_raw` times `factor`.
    fn analysis_scaled(
        station: &str,
        value: f64,
        sd_raw: f64,
        draws_mean: f64,
        factor: f64,
    ) -> Analysis {
        let mut c = Candidate::from_scores(
            "step",
            0.5,
            vec![0.0; 20],
            0.95,
            json!({"station": station}),
            None,
        );
        c.uncertainty = vec![ParamSd {
            name: "offset_u_mm".into(),
            value,
            sd: sd_raw * factor,
            sd_raw,
            draws_mean,
        }];
        Analysis {
            problem: "mogi",
            splits: vec![],
            effects: vec![c],
            residuals: json!({}),
            summary: String::new(),
            seconds: 0.0,
        }
    }

    /// A 10 mm vertical step at AV13, as the truth lists it.
    fn step_at_av13() -> [Injected; 1] {
        [Injected::new(
            "step",
            json!({"station": "AV13", "offset_mm": [0.0, 0.0, 10.0]}),
        )]
    }

    #[test]
    fn counts_within_one_and_two_sd_at_the_right_station_only() {
        let truth = step_at_av13();
        let mut c = Coverage::default();
        c.add(&analysis("AV13", 10.5, 1.0), &truth, "paper"); // within 1
        c.add(&analysis("AV13", 11.5, 1.0), &truth, "paper"); // within 2
        c.add(&analysis("AV13", 13.0, 1.0), &truth, "paper"); // beyond 2
        c.add(&analysis("AV06", 10.0, 1.0), &truth, "paper"); // wrong station: not counted
        let t = c.table();
        assert!(
            t.contains("| step | offset_u_mm | paper | 3 | 33 % | 67 % | 1.67 | 0 | 2.05 |"),
            "{t}"
        );
    }

    #[test]
    fn sets_the_mean_error_beside_the_shift_the_bootstrap_sees() {
        let truth = step_at_av13();
        let mut c = Coverage::default();
        // Estimates 0.5 and 0.7 low; draws 0.1 and 0.3 below them.
        c.add(&analysis_drawn("AV13", 9.5, 1.0, 9.4), &truth, "red");
        c.add(&analysis_drawn("AV13", 9.3, 1.0, 9.0), &truth, "red");
        let t = c.table();
        assert!(
            t.contains("| step | offset_u_mm | red | 2 | 100 % | 100 % | -0.600 | -0.200 | 0.64 |"),
            "{t}"
        );
    }

    #[test]
    fn counts_against_the_scaled_sd_and_gives_the_raw_one_s_factor_per_model_and_over_both() {
        let truth = step_at_av13();
        let mut c = Coverage::default();
        // Errors 1 and 3 raw sds, scaled by 2: within ±1 and ±2 of the scaled sd.
        c.add(
            &analysis_scaled("AV13", 11.0, 1.0, 11.0, 2.0),
            &truth,
            "paper",
        );
        c.add(
            &analysis_scaled("AV13", 13.0, 1.0, 13.0, 2.0),
            &truth,
            "paper",
        );
        // Error 2 raw sds, unscaled: within ±2.
        c.add(&analysis_scaled("AV13", 8.0, 1.0, 8.0, 1.0), &truth, "red");
        let t = c.table();
        assert!(
            t.contains("| step | offset_u_mm | paper | 2 | 50 % | 100 % | 2.00 | 0 | 2.37 |"),
            "{t}"
        );
        assert!(
            t.contains("| step | offset_u_mm | red | 1 | 0 % | 100 % | -2.00 | 0 | 2.00 |"),
            "{t}"
        );
        // Over both: raw |errors| 1, 2, 3 in sds; their 68.27 % quantile 2 + 0.365.
        assert!(
            t.contains("| step | offset_u_mm | both | 3 | 33 % | 100 % | 0.667 | 0 | 2.37 |"),
            "{t}"
        );
    }

    #[test]
    fn rounds_to_three_significant_digits() {
        assert_eq!(significant3(-0.6), "-0.600");
        assert_eq!(significant3(12.345), "12.3");
        assert_eq!(significant3(1234.4), "1234");
        assert_eq!(significant3(0.001234), "0.00123");
        assert_eq!(significant3(0.0), "0");
    }
}
