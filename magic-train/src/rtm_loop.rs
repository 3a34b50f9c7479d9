//! `magic loop --problem rtm`: the loop between residuals and physics on the forest spectra.
//!
//! Round 0 trains B (encoder + INFORM) and C (+ correction 11-44-11) with INFORM as published
//! (`physical` geometry: the sun zenith, view zenith and relative azimuth enter as the equations
//! say) and the paper's fixed sun at 30°. Each round analyses B's residuals
//! ([`crate::rtm_residuals`]: illumination, per-band and per-species structure, each scored on
//! held-out spectra against surrogates), adds the top significant family that can be declared in
//! F (illumination, band offsets), retrains, and repeats (at most `max_rounds`); an added effect
//! that does not lower B's validation MSE is taken out again and the loop stops. Families found but
//! not declarable (a per-species structure: the species is not an input of the inversion) are
//! reported.
//!
//! The illumination effect is also tested directly when the loop did not add it: B and C are
//! retrained with each spectrum's own sun, and the report says whether the physics-only error
//! drops and how much smaller C's correction becomes (mean squared size of C(F(E(x))) − F(E(x)) on
//! the test split, standardised units).

use crate::closed_loop::CandidateSummary;
use crate::data::s2::S2Split;
use crate::export::OwnedModel;
use crate::plots;
use crate::rtm_pipeline::{evaluate_splits, s2_illumination, train_rtm, RtmSetup, RtmVariant};
use crate::rtm_residuals::{analyse_rtm, RtmAnalysisOptions};
use crate::train::TrainConfig;
use anyhow::{anyhow, Context, Result};
use magic_core::{invert_at, Model, Workspace};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// Options of the RTM loop.
#[derive(Clone, Debug)]
pub struct RtmLoopOptions {
    /// Training seed.
    pub seed: u64,
    /// Training recipe.
    pub train: TrainConfig,
    /// Most effects added.
    pub max_rounds: usize,
    /// Surrogates per family.
    pub surrogates: usize,
}

/// Scores of one model.
#[derive(Clone, Debug, Serialize)]
pub struct RtmScores {
    /// Train, valid, test MSE (standardised).
    pub mse: [f64; 3],
    /// Physics-only MSE (F(E(x)), standardised) on train, valid, test.
    pub physics: [f64; 3],
    /// Mean squared size of the correction C(F(E(x))) − F(E(x)) on the test split (0 for B).
    pub correction_ms: f64,
}

/// One round.
#[derive(Clone, Debug, Serialize)]
pub struct RtmRound {
    /// Round number.
    pub round: usize,
    /// Declared effects.
    pub effects: Vec<String>,
    /// The effect added before this round.
    pub added: Option<CandidateSummary>,
    /// B's scores.
    pub b: RtmScores,
    /// C's scores.
    pub c: RtmScores,
    /// B's residual analysis.
    pub candidates: Vec<CandidateSummary>,
    /// Why the loop stopped after this round (empty if it went on).
    pub stop: String,
    /// Whether this round's F was kept (false when its added effect was taken out again).
    pub kept: bool,
}

/// The loop's result.
#[derive(Clone, Debug, Serialize)]
pub struct RtmLoop {
    /// Rounds.
    pub rounds: Vec<RtmRound>,
    /// B and C retrained with the illumination effect when the loop did not add it.
    pub illumination_test: Option<[RtmScores; 2]>,
}

/// Mean squared correction on a split: `(C(F(E(x))) − F(E(x)))²` per band, standardised.
fn correction_ms(model: &Model<'_>, split: &S2Split) -> Result<f64> {
    let days = split.rows.days();
    let mean: Vec<f32> = model.obs_mean.iter().collect();
    let scale: Vec<f32> = model.obs_scale.iter().collect();
    let nb = mean.len();
    let total: f64 = (0..split.len())
        .into_par_iter()
        .map_init(Workspace::default, |ws, i| -> Result<f64> {
            let obs: Vec<f32> = split.rows.x[i]
                .iter()
                .enumerate()
                .map(|(c, v)| v * scale[c] + mean[c])
                .collect();
            let inv = invert_at::<f64>(model, &obs, days[i], ws)
                .map_err(|e| anyhow!("spectrum {}: {e}", i + 1))?;
            Ok((0..nb)
                .map(|c| ((inv.recon[c] - inv.physics[c]) / scale[c] as f64).powi(2))
                .sum())
        })
        .sum::<Result<f64>>()?;
    Ok(total / (split.len() * nb).max(1) as f64)
}

fn scores(model: &OwnedModel, setup: &RtmSetup) -> Result<(RtmScores, Vec<u8>)> {
    let bytes = model.encode()?;
    let r = evaluate_splits(&bytes, &setup.data)?;
    let corr = {
        let m = Model::decode(&bytes).map_err(|e| anyhow!("{e}"))?;
        if m.variant == magic_core::Variant::C {
            correction_ms(&m, &setup.data.test)?
        } else {
            0.0
        }
    };
    let phys = |i: usize| r[i].physics_mse.unwrap_or(f64::NAN);
    Ok((
        RtmScores {
            mse: [r[0].mse, r[1].mse, r[2].mse],
            physics: [phys(0), phys(1), phys(2)],
            correction_ms: corr,
        },
        bytes,
    ))
}

/// A trained model's scores and its model-file bytes.
type Scored = (RtmScores, Vec<u8>);

/// B and C trained on `setup`.
fn train_pair(setup: &RtmSetup, opts: &RtmLoopOptions) -> Result<(Scored, Scored)> {
    let d = &setup.data;
    let (bm, _) = train_rtm(
        setup,
        &d.train,
        &d.valid,
        RtmVariant::B,
        &opts.train,
        opts.seed,
    )?;
    let (cm, _) = train_rtm(
        setup,
        &d.train,
        &d.valid,
        RtmVariant::C,
        &opts.train,
        opts.seed,
    )?;
    Ok((scores(&bm, setup)?, scores(&cm, setup)?))
}

/// Runs the loop on `setup` (its geometry; its effects are the starting F) and writes the report
/// (`report.md`, `report.json`, PNG plots) into `dir`.
pub fn run(setup: &mut RtmSetup, opts: &RtmLoopOptions, dir: &Path) -> Result<RtmLoop> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut rounds: Vec<RtmRound> = Vec::new();
    let mut added: Option<CandidateSummary> = None;
    for round in 0..=opts.max_rounds {
        eprintln!(
            "round {round}: F = INFORM{}",
            setup
                .effects
                .iter()
                .map(|e| format!(" + {}", e.family()))
                .collect::<String>()
        );
        let ((b, bbytes), (c, cbytes)) = train_pair(setup, opts)?;
        std::fs::write(dir.join(format!("round{round}_B.magic")), &bbytes)?;
        std::fs::write(dir.join(format!("round{round}_C.magic")), &cbytes)?;
        let analysis = {
            let m = Model::decode(&bbytes).map_err(|e| anyhow!("{e}"))?;
            analyse_rtm(
                &m,
                &setup.data,
                &RtmAnalysisOptions {
                    surrogates: opts.surrogates,
                    ..Default::default()
                },
            )?
        };
        eprint!("{}", analysis.table());
        crate::rtm_residuals::write_plots(&analysis, &dir.join(format!("round{round}")))?;
        let candidates: Vec<CandidateSummary> = analysis
            .effects
            .iter()
            .map(CandidateSummary::from)
            .collect();
        rounds.push(RtmRound {
            round,
            effects: setup
                .effects
                .iter()
                .map(|e| e.family().to_string())
                .collect(),
            added: added.take(),
            b,
            c,
            candidates,
            stop: String::new(),
            kept: true,
        });
        let last = rounds.len() - 1;
        // An effect that does not lower B's validation error is taken out again: significance in
        // the residuals is necessary, not sufficient.
        if last > 0 && rounds[last].b.mse[1] >= rounds[last - 1].b.mse[1] {
            let removed = setup.effects.pop().map(|e| e.family()).unwrap_or("?");
            rounds[last].kept = false;
            rounds[last].stop = format!(
                "{removed} did not lower B's validation MSE ({:.4} → {:.4}) and was taken out of F again",
                rounds[last - 1].b.mse[1],
                rounds[last].b.mse[1]
            );
            break;
        }
        if round == opts.max_rounds {
            rounds[last].stop = format!("the round limit ({}) was reached", opts.max_rounds);
            break;
        }
        // (A family already in F has no effect to propose.)
        match analysis.top_declarable() {
            Some(cand) => {
                setup.effects.push(
                    cand.effect
                        .clone()
                        .ok_or_else(|| anyhow!("candidate without an effect"))?,
                );
                added = Some(CandidateSummary::from(cand));
            }
            None => {
                let found: Vec<String> = analysis
                    .effects
                    .iter()
                    .filter(|c| c.significant)
                    .map(|c| c.family.clone())
                    .collect();
                rounds[last].stop = if found.is_empty() {
                    "no family explains more residual variance than chance".into()
                } else {
                    format!(
                        "significant but not declarable as physics: {} (no further effect to add)",
                        found.join(", ")
                    )
                };
                break;
            }
        }
    }
    let has_ill = setup.effects.iter().any(|e| e.family() == "illumination");
    let illumination_test = if has_ill {
        None
    } else {
        eprintln!("direct test: F = INFORM + illumination (each spectrum's own sun)");
        let saved = setup.effects.clone();
        setup.effects.push(s2_illumination());
        let r = train_pair(setup, opts);
        setup.effects = saved;
        let ((b, bb), (c, cb)) = r?;
        std::fs::write(dir.join("illumination_B.magic"), &bb)?;
        std::fs::write(dir.join("illumination_C.magic"), &cb)?;
        Some([b, c])
    };
    let out = RtmLoop {
        rounds,
        illumination_test,
    };
    write_report(setup, &out, dir)?;
    Ok(out)
}

fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "–".into()
    }
}

fn write_report(setup: &RtmSetup, l: &RtmLoop, dir: &Path) -> Result<()> {
    let mut md = String::new();
    let _ = writeln!(md, "# The loop on {}\n", setup.data.source);
    let _ = writeln!(
        md,
        "INFORM in `{:?}` geometry. MSE in standardised units (paper Table 3: B 0.0856, C 0.0217; physics-only MSE of the paper's C 1.04). Correction: mean squared C(F(E(x))) − F(E(x)) on the test split.\n",
        setup.geometry
    );
    let _ = writeln!(md, "| round | F | added (explained vs chance) | B train / valid / test | C train / valid / test | C physics-only test | C correction |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    let row = |f: &str, added: &str, b: &RtmScores, c: &RtmScores| {
        format!(
            "| {f} | {added} | {} / {} / {} | {} / {} / {} | {} | {} |",
            f4(b.mse[0]),
            f4(b.mse[1]),
            f4(b.mse[2]),
            f4(c.mse[0]),
            f4(c.mse[1]),
            f4(c.mse[2]),
            f4(c.physics[2]),
            f4(c.correction_ms)
        )
    };
    for r in &l.rounds {
        let f = std::iter::once("INFORM".to_string())
            .chain(r.effects.iter().cloned())
            .collect::<Vec<_>>()
            .join(" + ");
        let added = r.added.as_ref().map_or("–".to_string(), |a| {
            format!(
                "{} ({:.3} vs {:.3})",
                a.family, a.variance_explained, a.chance_level
            )
        });
        let _ = writeln!(md, "| {} |{}", r.round, &row(&f, &added, &r.b, &r.c)[1..]);
    }
    // The illumination test adds the sun to the last F that was kept.
    let kept = l.rounds.iter().rev().find(|r| r.kept);
    if let Some([b, c]) = &l.illumination_test {
        let f = std::iter::once("INFORM".to_string())
            .chain(kept.iter().flat_map(|r| r.effects.iter().cloned()))
            .chain(["illumination".to_string()])
            .collect::<Vec<_>>()
            .join(" + ");
        let _ = writeln!(md, "| test |{}", &row(&f, "(direct test)", b, c)[1..]);
    }
    let _ = writeln!(md);
    for r in &l.rounds {
        let _ = writeln!(md, "## Round {}: B's residuals\n", r.round);
        let _ = writeln!(
            md,
            "| family | explained (held-out) | chance | significant | declarable |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|");
        for c in &r.candidates {
            let _ = writeln!(
                md,
                "| {} | {:.4} | {:.4} | {} | {} |",
                c.family,
                c.variance_explained,
                c.chance_level,
                if c.significant { "yes" } else { "no" },
                if c.declarable { "yes" } else { "no" }
            );
        }
        if !r.stop.is_empty() {
            let _ = writeln!(md, "\nStopped: {}.", r.stop);
        }
        let _ = writeln!(md);
    }
    if let (Some([b1, c1]), Some(r0)) = (&l.illumination_test, kept) {
        let _ = writeln!(md, "## Illumination, tested directly\n");
        let rel = |a: f64, b: f64| 100.0 * (b - a) / a;
        let _ = writeln!(
            md,
            "With each spectrum's own sun added to the last F kept (round {}): B test MSE (= its physics-only error) {} → {} ({:+.1} %); C physics-only test {} → {}; C's correction {} → {} ({:+.1} %).",
            r0.round,
            f4(r0.b.mse[2]),
            f4(b1.mse[2]),
            rel(r0.b.mse[2], b1.mse[2]),
            f4(r0.c.physics[2]),
            f4(c1.physics[2]),
            f4(r0.c.correction_ms),
            f4(c1.correction_ms),
            rel(r0.c.correction_ms, c1.correction_ms)
        );
    }
    std::fs::write(dir.join("report.md"), &md)?;
    std::fs::write(
        dir.join("report.json"),
        serde_json::to_string_pretty(
            &json!({ "geometry": format!("{:?}", setup.geometry), "loop": l }),
        )?,
    )?;
    let labels: Vec<String> = l
        .rounds
        .iter()
        .map(|r| format!("round {}", r.round))
        .chain(
            l.illumination_test
                .iter()
                .map(|_| "+ illumination".to_string()),
        )
        .collect();
    let b: Vec<f64> = l
        .rounds
        .iter()
        .map(|r| r.b.mse[2])
        .chain(l.illumination_test.iter().map(|s| s[0].mse[2]))
        .collect();
    plots::bar_chart(
        &dir.join("b_test_mse.png"),
        "B test MSE (= physics-only error) per round",
        &labels,
        &b,
        &[],
    )?;
    Ok(())
}
