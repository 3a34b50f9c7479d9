//! Recovery on synthetic data with a known injected effect (`magic synth-check`): does the
//! analysis rank the injected family first, call it significant, and recover its parameters?

use super::synth::{self, Scenario};
use crate::analysis::{analyse, Analysis, AnalysisOptions};
use crate::numerics::median;
use crate::train::{train_model, ModelKind, TrainConfig};
use anyhow::Result;
use magic_core::Model;
use std::fmt::Write as _;

/// How an analysis of a synthetic dataset compares with its `truth.json`.
#[derive(Clone, Debug)]
pub struct Recovery {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// Family ranked first.
    pub top: String,
    /// Its excess over chance.
    pub top_excess: f64,
    /// The injected family is ranked first.
    pub ranked_first: bool,
    /// The injected family is significant (for `clean`: nothing is).
    pub significant: bool,
    /// Significant families.
    pub n_significant: usize,
    /// The injected family's key parameters are recovered (`None` for `clean`).
    pub params_ok: Option<bool>,
    /// What was compared.
    pub detail: String,
}

impl Recovery {
    /// Detected and recovered: for `clean`, nothing significant; otherwise ranked first,
    /// significant and parameters recovered.
    pub fn ok(&self) -> bool {
        if self.scenario == "clean" {
            self.n_significant == 0
        } else {
            self.ranked_first && self.significant && self.params_ok == Some(true)
        }
    }
}

fn num(v: &serde_json::Value, k: &str) -> f64 {
    v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN)
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    core::array::from_fn(|k| v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN))
}

/// Compares an analysis with the truth of `magic synth` (its `effect` entry). Criteria: a step's
/// station and epoch within 10 days; a second source within 2 km horizontally; the elevation
/// slope within 30 %; each common-mode RMS within 30 %; the median relative error of the
/// seasonal annual amplitudes below 30 %; the drifting stations exactly.
pub fn recovery(truth: &serde_json::Value, a: &Analysis) -> Recovery {
    let scenario = truth
        .get("scenario")
        .and_then(|v| v.as_str())
        .unwrap_or("?")
        .to_string();
    let seed = truth.get("seed").and_then(|v| v.as_u64()).unwrap_or(0);
    let top = a.effects.first();
    let n_significant = a.effects.iter().filter(|c| c.significant).count();
    let mut r = Recovery {
        scenario: scenario.clone(),
        seed,
        top: top.map_or(String::new(), |c| c.family.clone()),
        top_excess: top.map_or(0.0, |c| c.excess()),
        ranked_first: false,
        significant: n_significant == 0,
        n_significant,
        params_ok: None,
        detail: String::new(),
    };
    let eff = truth.get("effect").filter(|e| !e.is_null());
    let Some(eff) = eff else {
        r.ranked_first = true;
        r.detail = format!(
            "significant: {}",
            a.effects
                .iter()
                .filter(|c| c.significant)
                .map(|c| c.family.as_str())
                .collect::<Vec<_>>()
                .join(",")
        );
        return r;
    };
    let fam = eff.get("family").and_then(|v| v.as_str()).unwrap_or("?");
    let tp = &eff["params"];
    let Some(c) = a.effects.iter().find(|c| c.family == fam) else {
        r.detail = format!("family {fam} not analysed");
        return r;
    };
    r.ranked_first = top.is_some_and(|t| t.family == fam);
    r.significant = c.significant;
    let p = &c.params;
    let (ok, detail) = match fam {
        "step" => {
            let ds = (tp["epoch"].as_str(), p["epoch"].as_str());
            let de = match ds {
                (Some(x), Some(y)) => match (
                    magic_core::time::parse_date(x),
                    magic_core::time::parse_date(y),
                ) {
                    (Some(x), Some(y)) => (y - x) as f64,
                    _ => f64::NAN,
                },
                _ => f64::NAN,
            };
            let same = tp["station"] == p["station"];
            let (to, fo) = (vec3(&tp["offset_mm"]), vec3(&p["offset_mm"]));
            (
                same && de.abs() <= 10.0,
                format!(
                    "station {} vs {}, epoch {:+} d, offset [{:.1},{:.1},{:.1}] vs [{:.1},{:.1},{:.1}] mm",
                    p["station"], tp["station"], de, fo[0], fo[1], fo[2], to[0], to[1], to[2]
                ),
            )
        }
        "second_source" => {
            let dh = (num(p, "x_km") - num(tp, "x_km")).hypot(num(p, "y_km") - num(tp, "y_km"));
            (
                dh <= 2.0,
                format!(
                    "horizontal error {dh:.2} km, depth {:.1} vs {:.1} km, window {}..{} vs {}..{}",
                    num(p, "depth_km"),
                    num(tp, "depth_km"),
                    p["start"].as_str().unwrap_or("?"),
                    p["end"].as_str().unwrap_or("?"),
                    tp["start"].as_str().unwrap_or("?"),
                    tp["end"].as_str().unwrap_or("?")
                ),
            )
        }
        "elevation" => {
            let (e, t) = (num(p, "mm_per_km"), num(tp, "mm_per_km"));
            (
                (e - t).abs() <= 0.3 * t,
                format!("{e:.1} vs {t:.1} mm/km ({:+.0} %)", 100.0 * (e / t - 1.0)),
            )
        }
        "common_mode" => {
            let (e, t) = (vec3(&p["rms_mm"]), vec3(&tp["rms_mm"]));
            let rel: Vec<f64> = (0..3).map(|k| e[k] / t[k] - 1.0).collect();
            (
                rel.iter().all(|v| v.abs() <= 0.3),
                format!(
                    "rms [{:.2},{:.2},{:.2}] vs [{:.2},{:.2},{:.2}] mm",
                    e[0], e[1], e[2], t[0], t[1], t[2]
                ),
            )
        }
        "seasonal" => {
            let mut rel = Vec::new();
            if let (Some(em), Some(tm)) = (p["annual_mm"].as_object(), tp["annual_mm"].as_object())
            {
                for (sta, tv) in tm {
                    let (t, e) = (
                        vec3(tv),
                        vec3(em.get(sta).unwrap_or(&serde_json::Value::Null)),
                    );
                    rel.extend((0..3).map(|k| (e[k] / t[k] - 1.0).abs()));
                }
            }
            let m = median(&mut rel.clone());
            (
                m <= 0.3,
                format!(
                    "annual amplitudes: median relative error {:.0} %",
                    100.0 * m
                ),
            )
        }
        "drift" => {
            let keys = |v: &serde_json::Value| {
                let mut k: Vec<String> = v["rate_mm_per_yr"]
                    .as_object()
                    .map_or(vec![], |m| m.keys().cloned().collect());
                k.sort();
                k
            };
            let (e, t) = (keys(p), keys(tp));
            (e == t, format!("stations {e:?} vs {t:?}"))
        }
        _ => (false, String::new()),
    };
    r.params_ok = Some(ok);
    r.detail = detail;
    r
}

/// Generates a scenario, trains a B model on it and analyses its residuals.
pub fn check_one(
    scenario: Scenario,
    seed: u64,
    cfg: &TrainConfig,
    opts: &AnalysisOptions,
) -> Result<(Recovery, Analysis)> {
    let s = synth::generate(scenario, seed);
    let (model, _) = train_model(&s.problem, ModelKind::B, &[], cfg, seed)?;
    let bytes = model.encode()?;
    let m = Model::decode(&bytes)?;
    let (a, _) = analyse(&s.problem, &m, opts)?;
    Ok((recovery(&s.truth, &a), a))
}

/// The recovery table over scenarios and seeds: per scenario, ranked first, significant and
/// parameters recovered as counts out of the seeds (for `clean`: false positives).
pub fn recovery_table(rows: &[Recovery]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
        "scenario", "seeds", "ranked 1st", "significant", "params", "all ok"
    );
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.scenario.as_str()) {
            names.push(&r.scenario);
        }
    }
    for n in names {
        let g: Vec<&Recovery> = rows.iter().filter(|r| r.scenario == n).collect();
        let k = |f: &dyn Fn(&Recovery) -> bool| g.iter().filter(|r| f(r)).count();
        if n == "clean" {
            let _ = writeln!(
                s,
                "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
                n,
                g.len(),
                "-",
                format!("FP {}", k(&|r| r.n_significant > 0)),
                "-",
                format!("{}/{}", k(&|r| r.ok()), g.len())
            );
        } else {
            let _ = writeln!(
                s,
                "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10}",
                n,
                g.len(),
                format!("{}/{}", k(&|r| r.ranked_first), g.len()),
                format!("{}/{}", k(&|r| r.significant), g.len()),
                format!("{}/{}", k(&|r| r.params_ok == Some(true)), g.len()),
                format!("{}/{}", k(&|r| r.ok()), g.len())
            );
        }
    }
    s
}
