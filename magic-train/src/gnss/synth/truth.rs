//! `truth.json`: what a synthetic dataset holds, in the terms the residual analysis reports.
//!
//! ```json
//! {"scenario": "step+elevation", "seed": 1, "noise": "paper", "placement": "train",
//!  "source": {"x_km", "y_km", "depth_km"}, "episodes": [...],
//!  "effects": [{"family": "step", "params": {"station", "epoch", "offset_mm"}},
//!              {"family": "elevation", "params": {"mm_per_km", "z_ref_km"}}],
//!  "background": [...]}
//! ```
//!
//! `effects` lists the injected effects with the parameter names of the analysis's families
//! (`gnss/families/*.rs`): step `station`, `epoch` (YYYY-MM-DD), `offset_mm` (E, N, U);
//! second_source `x_km`, `y_km`, `depth_km`, `start`, `end`, `peak_dv_1e6m3` (and `shape`:
//! `pulse` or `lasting`); elevation `mm_per_km` (RMS of the daily slope over the whole
//! record); common_mode `rms_mm` (E, N, U over the whole record); seasonal `annual_mm`,
//! `semiannual_mm` per station; drift `rate_mm_per_yr` per drifting station. Where the noise
//! itself holds a family's signal (the `red` model's common mode and its annual term), an
//! injected effect of that family states what the data hold in all (injected plus noise), and
//! `background` lists what the noise holds alone: an analysis that finds those families on
//! clean data is right, not wrong. Single-effect scenarios also carry the effect as `effect`
//! (`null` for `clean`), as files written before `effects` existed did.

use super::source::History;
use super::Spec;
use serde::{Deserialize, Serialize};
use serde_json::json;

/// An effect in the data: its family and parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Injected {
    /// Family name (`step`, `second_source`, …).
    pub family: String,
    /// Parameters, named as the analysis reports them.
    pub params: serde_json::Value,
}

impl Injected {
    /// An effect of `family` with `params`.
    pub fn new(family: &str, params: serde_json::Value) -> Injected {
        Injected {
            family: family.to_string(),
            params,
        }
    }
}

/// The truth of a generated dataset.
pub fn truth(
    spec: &Spec,
    source: [f64; 3],
    history: &History,
    effects: &[Injected],
    background: &[Injected],
) -> serde_json::Value {
    let mut t = json!({
        "scenario": spec.scenario.name(),
        "seed": spec.seed,
        "noise": spec.noise.name(),
        "placement": spec.placement_label(),
        "source": {"x_km": source[0], "y_km": source[1], "depth_km": source[2]},
        "episodes": history.episodes,
        "effects": effects,
        "background": background,
    });
    if effects.len() <= 1 {
        t["effect"] = effects
            .first()
            .map_or(serde_json::Value::Null, |e| json!(e));
    }
    t
}

fn list(v: Option<&serde_json::Value>) -> Vec<Injected> {
    v.and_then(|v| serde_json::from_value::<Vec<Injected>>(v.clone()).ok())
        .unwrap_or_default()
}

/// The injected effects of a truth: its `effects`, or for files that only have it, the single
/// `effect` (none when it is `null`).
pub fn injected(truth: &serde_json::Value) -> Vec<Injected> {
    if truth.get("effects").is_some() {
        return list(truth.get("effects"));
    }
    truth
        .get("effect")
        .filter(|e| !e.is_null())
        .and_then(|e| serde_json::from_value(e.clone()).ok())
        .into_iter()
        .collect()
}

/// What the noise of a truth holds (empty when it holds no effect, or the file predates it).
pub fn background(truth: &serde_json::Value) -> Vec<Injected> {
    list(truth.get("background"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn older_truth_files_are_read() {
        let old = json!({"scenario": "step", "seed": 1,
            "effect": {"family": "step", "params": {"station": "AV13"}}});
        let e = injected(&old);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].family, "step");
        assert_eq!(e[0].params["station"], "AV13");
        assert!(injected(&json!({"scenario": "clean", "effect": null})).is_empty());
        assert!(background(&old).is_empty());
    }
}
