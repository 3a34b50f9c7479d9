//! The loop's report: `report.md` (a table of the rounds with the problem's metrics, the stop
//! reason, every round's candidates and the figures), `report.json`, and a bar chart of B's test
//! MSE per round.

use super::{f4, markdown_table, plots};
use crate::closed_loop::{LoopReport, Scores};
use anyhow::Result;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// `train / valid / test`.
fn three(v: &[f64; 3]) -> String {
    format!("{} / {} / {}", f4(v[0]), f4(v[1]), f4(v[2]))
}

/// The rounds' table, with the direct tests below them.
pub fn rounds_table(l: &LoopReport) -> String {
    let metric_labels: Vec<String> = l
        .first()
        .b
        .metrics
        .iter()
        .map(|m| format!("B {}", m.label))
        .collect();
    let baseline_labels: Vec<String> = l
        .first()
        .baseline
        .iter()
        .map(|m| m.label.to_string())
        .collect();
    let mut header: Vec<String> = [
        "round",
        "F",
        "added (explained vs chance)",
        "B train / valid / test",
        "C train / valid / test",
        "C physics-only test",
        "C correction",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    header.extend(metric_labels);
    header.extend(baseline_labels);
    let row = |round: String,
               f: String,
               added: String,
               b: &Scores,
               c: &Scores,
               base: &[crate::problem::Metric]| {
        let mut r = vec![
            round,
            f,
            added,
            three(&b.mse),
            three(&c.mse),
            f4(c.physics[2]),
            f4(c.correction_ms),
        ];
        r.extend(b.metrics.iter().map(|m| m.text.clone()));
        r.extend(base.iter().map(|m| m.text.clone()));
        r
    };
    let f_of = |effects: &[String]| {
        std::iter::once(l.physics.clone())
            .chain(effects.iter().cloned())
            .collect::<Vec<_>>()
            .join(" + ")
    };
    let mut rows: Vec<Vec<String>> = l
        .rounds
        .iter()
        .map(|r| {
            let added = r.added.as_ref().map_or("–".to_string(), |c| c.short());
            let round = if r.kept {
                r.round.to_string()
            } else {
                format!("{} (taken out)", r.round)
            };
            row(round, f_of(&r.effects), added, &r.b, &r.c, &r.baseline)
        })
        .collect();
    let kept = l.last_kept();
    for d in &l.direct {
        let mut effects = kept.effects.clone();
        effects.push(d.family.clone());
        let blank =
            vec![crate::problem::Metric::new("", "", f64::NAN, "–".into()); kept.baseline.len()];
        rows.push(row(
            "test".into(),
            f_of(&effects),
            "(direct test)".into(),
            &d.b,
            &d.c,
            &blank,
        ));
    }
    markdown_table(&header, &rows)
}

/// A line per effect taken out before the last round: its validation MSE without and with it,
/// and that the next candidate of the last F kept was tried in its place.
fn tried_next(l: &LoopReport) -> String {
    let mut s = String::new();
    let mut kept = 0;
    for (i, r) in l.rounds.iter().enumerate() {
        if r.kept {
            kept = i;
            continue;
        }
        let Some(next) = l.rounds.get(i + 1) else {
            break;
        };
        let Some(valid) = r.valid else {
            continue;
        };
        let family = r.added.as_ref().map_or("?", |a| a.family.as_str());
        let _ = writeln!(
            s,
            "\nRound {}'s {family} did not lower B's validation MSE ({} → {}) and was taken out; round {} tried the next candidate of round {kept}'s analysis in its place.",
            r.round,
            f4(valid[0]),
            f4(valid[1]),
            next.round
        );
    }
    s
}

/// Writes `report.md`, `report.json` and `b_test_mse.png` into `dir`; `figures` are Markdown
/// image lines of the problem's own before/after figures.
pub fn write(l: &LoopReport, figures: &[String], dir: &Path) -> Result<()> {
    let mut md = String::new();
    let _ = writeln!(md, "# The loop on {}\n", l.data);
    let _ = writeln!(
        md,
        "F = {} with the effects added so far. MSE in standardised units (the paper's metric); physics-only: F(E(x)) without the correction; C correction: mean squared C(F(E(x))) − F(E(x)) on the test split.\n",
        l.physics
    );
    md.push_str(&rounds_table(l));
    md.push_str(&tried_next(l));
    let _ = writeln!(
        md,
        "\nThe loop stopped after round {}: {}.",
        l.rounds.len() - 1,
        l.stop
    );
    for r in &l.rounds {
        if let Some(j) = &r.interleaved {
            let why = if j.acts.is_episode() {
                "the validation years cannot judge it"
            } else {
                "retraining on them cannot learn it"
            };
            let what = format!("{}, so {why}", j.acts.when());
            let (years, days) = (j.acts.years(), j.acts.days());
            let _ = writeln!(
                md,
                "\nRound {}'s effect {what}: the keep rule compared B without and with it, both trained on blocks of {} rows of {years} dealt out again in two folds that hold out each of the {} days {days} once (validation MSE on them: {:.4} → {:.4}).",
                r.round, j.block, j.days, j.valid[0], j.valid[1]
            );
        }
    }
    for r in &l.rounds {
        let _ = writeln!(md, "\n## Round {}: B's residuals\n", r.round);
        let rows: Vec<Vec<String>> = r
            .candidates
            .iter()
            .map(|c| {
                vec![
                    c.family.clone(),
                    format!("{:.4}", c.variance_explained),
                    format!("{:.4}", c.chance_level),
                    if c.significant { "yes" } else { "no" }.into(),
                    if c.effect.is_some() { "yes" } else { "no" }.into(),
                    uncertainty_cell(&c.uncertainty),
                    format!("`{}`", c.params),
                ]
            })
            .collect();
        let header: Vec<String> = [
            "family",
            "explained (held out)",
            "chance",
            "significant",
            "declarable",
            "key parameters ± sd (bootstrap)",
            "params",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        md.push_str(&markdown_table(&header, &rows));
        let _ = writeln!(md, "\n![effects, round {0}](round{0}/effects.png)", r.round);
    }
    if !figures.is_empty() {
        let _ = writeln!(md, "\n## Before and after\n\n{}", figures.join("\n\n"));
    }
    std::fs::write(dir.join("report.md"), &md)?;
    std::fs::write(
        dir.join("report.json"),
        serde_json::to_string_pretty(&json!({ "loop": l }))?,
    )?;
    let labels: Vec<String> = l
        .rounds
        .iter()
        .map(|r| format!("round {}", r.round))
        .chain(l.direct.iter().map(|d| format!("+ {}", d.family)))
        .collect();
    let b: Vec<f64> = l
        .rounds
        .iter()
        .map(|r| r.b.mse[2])
        .chain(l.direct.iter().map(|d| d.b.mse[2]))
        .collect();
    plots::bar_chart(
        &dir.join("b_test_mse.png"),
        "B test MSE (= its physics-only error) per round",
        &labels,
        &b,
        &[],
    )
}

/// A candidate's key parameters with their bootstrap standard deviations (`name v ± sd`), or `–`.
fn uncertainty_cell(u: &[crate::analysis::ParamSd]) -> String {
    if u.is_empty() {
        return "–".into();
    }
    u.iter()
        .map(|p| format!("{} {:.3} ± {:.3}", p.name, p.value, p.sd))
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::Candidate;
    use crate::closed_loop::{Round, StopReason};

    fn round(i: usize, family: Option<&str>, valid: f64, kept: bool, before: f64) -> Round {
        let scores = Scores {
            mse: [0.5, valid, 0.7],
            physics: [1.0; 3],
            correction_ms: 0.0,
            metrics: vec![],
            best_epoch: 1,
        };
        Round {
            round: i,
            effects: vec![],
            added: family
                .map(|f| Candidate::from_scores(f, 0.05, vec![0.0; 4], 0.95, json!({}), None)),
            b: scores.clone(),
            c: scores,
            baseline: vec![],
            candidates: vec![],
            kept,
            interleaved: None,
            valid: family.map(|_| [before, valid]),
        }
    }

    #[test]
    fn an_effect_taken_out_before_the_last_round_says_what_came_next() {
        let l = LoopReport {
            problem: "mogi".into(),
            physics: "Mogi".into(),
            data: "test".into(),
            rounds: vec![
                round(0, None, 1.6, true, f64::NAN),
                round(1, Some("common_mode"), 1.7, false, 1.6),
                round(2, Some("seasonal"), 1.5, true, 1.6),
                round(3, Some("step"), 1.55, false, 1.5),
            ],
            stop: StopReason::RoundLimit { rounds: 3 },
            direct: vec![],
        };
        let s = tried_next(&l);
        assert_eq!(
            s.trim(),
            "Round 1's common_mode did not lower B's validation MSE (1.6000 → 1.7000) and was taken out; round 2 tried the next candidate of round 0's analysis in its place."
        );
    }
}
