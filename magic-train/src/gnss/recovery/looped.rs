//! The whole loop against the truth (`magic synth-loop`): which effects it added and kept, by
//! the rules of [`recovery`] applied to the kept additions (an injected effect
//! counts when an effect of its kind was kept with its key parameters recovered; any other kept
//! addition the noise does not hold is a false one, and so is a copy of an injected kind beyond
//! as many as were injected), and the test MSE before and after, over seeds.

use super::{frac, recovery, same_effect, Recovery};
use crate::analysis::Candidate;
use crate::gnss::synth::truth::injected;
use crate::numerics::mean_std;
use std::fmt::Write as _;

/// One run of the loop on one synthetic dataset.
#[derive(Clone, Debug)]
pub struct LoopRun {
    /// The kept additions compared with the truth.
    pub recovery: Recovery,
    /// The kept additions, in order, as `family (explained vs chance)`.
    pub added: Vec<String>,
    /// B's test MSE before (plain F) and after (last F kept).
    pub b: [f64; 2],
    /// C's test MSE before and after.
    pub c: [f64; 2],
}

impl LoopRun {
    /// Compares the loop's kept additions (`added`, the candidates it declared and kept) with a
    /// truth of `magic synth`.
    pub fn new(truth: &serde_json::Value, added: &[Candidate], b: [f64; 2], c: [f64; 2]) -> Self {
        let mut recovery = recovery(truth, added);
        recovery.false_additions.extend(copies(truth, added));
        LoopRun {
            recovery,
            added: added.iter().map(Candidate::short).collect(),
            b,
            c,
        }
    }

    /// A finished run read back: `report` the loop's report (`report.json` of `magic loop` and
    /// `magic synth-loop`), `truth` the dataset's `truth.json` beside it.
    pub fn from_report(
        truth: &serde_json::Value,
        report: &serde_json::Value,
    ) -> Result<LoopRun, String> {
        let rounds = report
            .pointer("/loop/rounds")
            .and_then(serde_json::Value::as_array)
            .filter(|r| !r.is_empty())
            .ok_or("no rounds under loop.rounds")?;
        let kept = |r: &&serde_json::Value| r.get("kept").and_then(|k| k.as_bool()) == Some(true);
        let added = rounds
            .iter()
            .filter(kept)
            .filter_map(|r| r.get("added").filter(|a| !a.is_null()))
            .map(Candidate::from_report)
            .collect::<Result<Vec<_>, _>>()?;
        let last = rounds.iter().rev().find(kept).unwrap_or(&rounds[0]);
        let test_mse = |r: &serde_json::Value, v: &str| {
            r.pointer(&format!("/{v}/mse/2"))
                .and_then(serde_json::Value::as_f64)
                .ok_or(format!("round {}: no {v}.mse", r["round"]))
        };
        Ok(LoopRun::new(
            truth,
            &added,
            [test_mse(&rounds[0], "b")?, test_mse(last, "b")?],
            [test_mse(&rounds[0], "c")?, test_mse(last, "c")?],
        ))
    }

    /// Every injected effect kept with its parameters recovered, and no false addition kept.
    pub fn ok(&self) -> bool {
        self.recovery.all_found() && self.recovery.false_additions.is_empty()
    }
}

/// The kept additions beyond as many of a kind ([`same_effect`]) as the truth injects, each as
/// `family (again)`: a second source kept twice for one injected is one false addition, though
/// either copy alone would recover it.
fn copies(truth: &serde_json::Value, added: &[Candidate]) -> Vec<String> {
    let injected = injected(truth);
    let mut out = Vec::new();
    for (i, c) in added.iter().enumerate() {
        let kind = |f: &str| same_effect(f, &c.family);
        let before = added[..i].iter().filter(|a| kind(&a.family)).count();
        let allowed = injected.iter().filter(|e| kind(&e.family)).count();
        if allowed > 0 && before >= allowed {
            out.push(format!("{} (again)", c.family));
        }
    }
    out
}

/// `mean ± sd → mean ± sd` of before/after pairs.
fn before_after(v: &[[f64; 2]]) -> String {
    let part = |i: usize| {
        let (m, s) = mean_std(&v.iter().map(|x| x[i]).collect::<Vec<_>>());
        if v.len() > 1 {
            format!("{m:.4} ± {s:.4}")
        } else {
            format!("{m:.4}")
        }
    };
    format!("{} → {}", part(0), part(1))
}

/// The summary table (Markdown): a line per scenario, placement and noise model; counts out of
/// the seeds of each injected effect kept with its parameters recovered, of runs with a false
/// addition kept (and which), of what the noise holds kept, and of runs that kept exactly the
/// injected effects; B's and C's test MSE before → after (mean ± sd over the seeds).
pub fn loop_table(runs: &[LoopRun]) -> String {
    let mut s = String::from(
        "| injected | placement | noise | seeds | kept, parameters recovered | false additions kept | noise's own kept | ok | B test before → after | C test before → after |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let key = |r: &LoopRun| {
        (
            r.recovery.scenario.clone(),
            r.recovery.placement.clone(),
            r.recovery.noise.clone(),
        )
    };
    let mut keys = Vec::new();
    for r in runs {
        if !keys.contains(&key(r)) {
            keys.push(key(r));
        }
    }
    for k in keys {
        let g: Vec<&LoopRun> = runs.iter().filter(|r| key(r) == k).collect();
        let n = g.len();
        let count = |f: &dyn Fn(&LoopRun) -> bool| g.iter().filter(|r| f(r)).count();
        let effects = &g[0].recovery.effects;
        let found = if effects.is_empty() {
            "-".to_string()
        } else {
            (0..effects.len())
                .map(|i| {
                    let c = count(&|r| r.recovery.effects.get(i).is_some_and(|e| e.found()));
                    format!("{} {}", effects[i].family, frac(c, n))
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        let lists = |f: &dyn Fn(&LoopRun) -> &Vec<String>| -> String {
            let k = count(&|r| !f(r).is_empty());
            if k == 0 {
                return frac(0, n);
            }
            let ls: Vec<&Vec<String>> = g.iter().map(|r| f(r)).collect();
            format!("{} ({})", frac(k, n), super::tally(&ls, n))
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {n} | {found} | {} | {} | {} | {} | {} |",
            k.0,
            k.1,
            k.2,
            lists(&|r| &r.recovery.false_additions),
            lists(&|r| &r.recovery.background_found),
            frac(count(&LoopRun::ok), n),
            before_after(&g.iter().map(|r| r.b).collect::<Vec<_>>()),
            before_after(&g.iter().map(|r| r.c).collect::<Vec<_>>()),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn added(family: &str, params: serde_json::Value) -> Candidate {
        let mut c = Candidate::from_scores(family, 0.05, vec![0.0; 20], 0.95, params, None);
        c.effect = Some(crate::model::OwnedEffect::CommonMode);
        c
    }

    #[test]
    fn kept_additions_are_judged_by_the_recovery_rules() {
        let truth = json!({"scenario": "step", "noise": "paper", "placement": "valid", "seed": 3,
            "effects": [{"family": "step", "params": {"station": "AV13", "epoch": "2014-05-23",
            "offset_mm": [1.0, 2.0, 8.0]}}]});
        let step = added(
            "step",
            json!({"station": "AV13", "epoch": "2014-05-25", "offset_mm": [1.2, 2.1, 7.0]}),
        );
        let wrong = added(
            "step",
            json!({"station": "AV08", "epoch": "2014-05-25", "offset_mm": [1.2, 2.1, 7.0]}),
        );
        let drift = added(
            "drift",
            json!({"rate_mm_per_yr": {"AV08": [1.0, 0.0, 0.0]}}),
        );
        let runs = vec![
            LoopRun::new(&truth, std::slice::from_ref(&step), [0.8, 0.7], [0.9, 0.85]),
            LoopRun::new(&truth, &[step, drift], [0.8, 0.6], [0.9, 0.75]),
            LoopRun::new(&truth, &[wrong], [0.8, 0.8], [0.9, 0.9]),
        ];
        assert!(runs[0].ok() && !runs[1].ok() && !runs[2].ok());
        let t = loop_table(&runs);
        let row = t.lines().nth(2).unwrap();
        assert!(
            row.starts_with(
                "| step | valid | paper | 3 | step 2/3 | 1/3 (drift 1/3) | 0/3 | 1/3 |"
            ),
            "{row}"
        );
        assert!(row.contains("0.8000 ± 0.0000 → 0.7000 ± 0.1000"), "{row}");
    }

    #[test]
    fn a_run_reads_back_from_its_report() {
        let truth = json!({"scenario": "step", "noise": "paper", "placement": "train", "seed": 2,
            "effects": [{"family": "step", "params": {"station": "AV13", "epoch": "2014-05-23",
            "offset_mm": [1.0, 2.0, 8.0]}}]});
        let step = added(
            "step",
            json!({"station": "AV13", "epoch": "2014-05-25", "offset_mm": [1.2, 2.1, 7.0]}),
        );
        let drift = added(
            "drift",
            json!({"rate_mm_per_yr": {"AV08": [1.0, 0.0, 0.0]}}),
        );
        let scores = |test: f64| json!({"mse": [0.5, 0.9, test], "best_epoch": 60});
        // Round 2's drift was taken out again: the last kept round is 1.
        let report = json!({"loop": {"rounds": [
            {"round": 0, "added": null, "kept": true, "b": scores(0.8), "c": scores(0.9)},
            {"round": 1, "added": step, "kept": true, "b": scores(0.7), "c": scores(0.85)},
            {"round": 2, "added": drift, "kept": false, "b": scores(0.75), "c": scores(0.8)},
        ]}});
        let run = LoopRun::from_report(&truth, &report).unwrap();
        let direct = LoopRun::new(&truth, &[step], [0.8, 0.7], [0.9, 0.85]);
        assert!(run.ok());
        assert_eq!(
            (run.b, run.c, &run.added),
            (direct.b, direct.c, &direct.added)
        );
        assert_eq!(loop_table(&[run]), loop_table(&[direct]));
        let err = LoopRun::from_report(&truth, &json!({"loop": {"rounds": []}})).unwrap_err();
        assert!(err.contains("no rounds"), "{err}");
    }

    #[test]
    fn a_source_kept_twice_for_one_injected_is_a_false_addition() {
        let truth = json!({"scenario": "lasting_deflation_near", "seed": 4,
            "effects": [{"family": "lasting_source", "params": {"x_km": -0.8, "y_km": 3.3,
            "depth_km": 3.4}}]});
        let at = |x: f64, y: f64| json!({"x_km": x, "y_km": y, "depth_km": 4.0});
        let right = added("lasting_source", at(-0.75, 3.5));
        let mirror = added("lasting_source", at(1.0, -4.0));
        let once = LoopRun::new(&truth, std::slice::from_ref(&right), [0.7, 0.6], [0.9, 0.8]);
        assert!(once.ok(), "{:?}", once.recovery.false_additions);
        let twice = LoopRun::new(&truth, &[right, mirror], [0.7, 0.5], [0.9, 0.8]);
        assert!(twice.recovery.all_found());
        assert_eq!(twice.recovery.false_additions, ["lasting_source (again)"]);
        assert!(!twice.ok());
    }
}
