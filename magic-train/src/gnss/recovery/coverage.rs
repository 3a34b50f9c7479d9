//! Calibration of the bootstrap standard deviations on synthetic data: for every significant
//! candidate of an injected family that carries an uncertainty, the share of its key parameters
//! whose true value lies within ±1 and ±2 standard deviations (about 68 % and 95 % if the sds tell
//! the truth); and beside them the estimates' mean error against the shift the bootstrap sees
//! (its draws' mean less the estimate): a bias the draws reproduce shows in both, one they miss
//! only in the first. A step counts only at the right station (another station's offsets say
//! nothing).

use crate::analysis::Analysis;
use crate::data::dataset::day_number;
use crate::gnss::synth::truth::Injected;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// What is counted per (family, parameter, noise model).
#[derive(Clone, Copy, Debug, Default)]
struct Row {
    /// Estimates with a standard deviation.
    n: usize,
    /// Those within ±1 and ±2 sd of the truth.
    within: [usize; 2],
    /// Sum of the estimates' errors (estimate − truth).
    error: f64,
    /// Sum of the bootstrap's shifts (draws' mean − estimate).
    shift: f64,
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
            }
        }
    }

    /// The Markdown table: family, parameter, noise model, estimates, shares within ±1 and
    /// ±2 sd, the estimates' mean error and the bootstrap's mean shift (three significant
    /// digits, in the parameter's units).
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| family | parameter | noise | n | within ±1 sd | within ±2 sd | mean error | bootstrap's mean shift |\n|---|---|---|---|---|---|---|---|\n",
        );
        for ((family, param, noise), r) in &self.rows {
            let n = r.n.max(1) as f64;
            let pct = |k: usize| 100.0 * k as f64 / n;
            let _ = writeln!(
                s,
                "| {family} | {param} | {noise} | {} | {:.0} % | {:.0} % | {} | {} |",
                r.n,
                pct(r.within[0]),
                pct(r.within[1]),
                significant3(r.error / n),
                significant3(r.shift / n)
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
            sd,
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
            t.contains("| step | offset_u_mm | paper | 3 | 33 % | 67 % | 1.67 | 0 |"),
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
            t.contains("| step | offset_u_mm | red | 2 | 100 % | 100 % | -0.600 | -0.200 |"),
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
