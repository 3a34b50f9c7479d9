//! `magic loop`: close the loop between residuals and physics.
//!
//! Round 0 trains B (encoder + F) and C (+ correction) with the plain Mogi model. Each round then
//! analyses B's residuals against candidate effects (scored on held-out data and against chance,
//! [`crate::residuals`]), adds the top significant effect to F as declared physics, and retrains —
//! at most three rounds, and only while an effect is significant. Every round is scored the same
//! way: train/valid/test MSE of B and C, B's physics-only error, the per-day classical fit
//! (Levenberg–Marquardt with the latent effects declared so far), and the plausibility of the
//! source on the test split. The report is Markdown + JSON + PNG plots.

use crate::classical::fit_split;
use crate::data::gnss::GnssData;
use crate::demo::{plausibility, split_rows};
use crate::eval::evaluate;
use crate::export::{OwnedEffect, OwnedModel};
use crate::pipeline::train_mogi_with;
use crate::plots;
use crate::residuals::{analyse, AnalysisOptions, Candidate};
use crate::train::TrainConfig;
use anyhow::{anyhow, Context, Result};
use magic_core::{invert_at, Model, Variant, Workspace};
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// Options of the loop.
#[derive(Clone, Debug)]
pub struct LoopOptions {
    /// Training seed.
    pub seed: u64,
    /// Training recipe.
    pub train: TrainConfig,
    /// Most effects added.
    pub max_rounds: usize,
    /// Also run the classical per-day fit each round.
    pub classical: bool,
}

/// MSE of one model on the three splits.
#[derive(Clone, Debug, Serialize)]
pub struct Scores {
    /// Train, valid, test MSE (standardised units).
    pub mse: [f64; 3],
    /// Physics-only test MSE.
    pub physics_test: Option<f64>,
    /// Share of test days with depth < 10 km and |ΔV| < 5·10⁶ m³.
    pub plausible_share: f64,
    /// Largest ΔV on the test split (10⁶ m³) and the depth then (km).
    pub peak_dv: f64,
    /// Depth at the peak.
    pub peak_depth: f64,
}

/// A candidate effect as reported.
#[derive(Clone, Debug, Serialize)]
pub struct CandidateSummary {
    /// Family.
    pub family: String,
    /// Share of residual variance explained on held-out data.
    pub variance_explained: f64,
    /// Share explained by chance.
    pub chance_level: f64,
    /// Significant.
    pub significant: bool,
    /// Fitted parameters.
    pub params: serde_json::Value,
    /// Whether it can be added to F as declared physics.
    pub declarable: bool,
}

impl From<&Candidate> for CandidateSummary {
    fn from(c: &Candidate) -> Self {
        CandidateSummary {
            family: c.family.clone(),
            variance_explained: c.variance_explained,
            chance_level: c.chance_level,
            significant: c.significant,
            params: c.params.clone(),
            declarable: c.effect.is_some(),
        }
    }
}

/// One round of the loop.
#[derive(Clone, Debug, Serialize)]
pub struct Round {
    /// 0 for the plain model.
    pub round: usize,
    /// Effects declared in F this round.
    pub effects: Vec<String>,
    /// The effect added for this round and why (none in round 0).
    pub added: Option<CandidateSummary>,
    /// Encoder + F.
    pub b: Scores,
    /// Encoder + F + correction.
    pub c: Scores,
    /// Classical per-day fit with the same declared effects: test MSE, if run.
    pub classical_test_mse: Option<f64>,
    /// Classical fit's plausible share and 2008 peak.
    pub classical: Option<serde_json::Value>,
    /// The residual analysis of this round's B model, ranked.
    pub candidates: Vec<CandidateSummary>,
    /// Why the loop stopped after this round (empty when it went on).
    pub stop: String,
}

fn scores(model: &OwnedModel, data: &GnssData) -> Result<(Scores, Vec<u8>)> {
    let bytes = model.encode()?;
    let (r, (peak_dv, peak_depth, share)) = {
        let m = Model::decode(&bytes).map_err(|e| anyhow!("{e}"))?;
        let r = [
            evaluate(&m, &data.train, "train")?,
            evaluate(&m, &data.valid, "valid")?,
            evaluate(&m, &data.test, "test")?,
        ];
        let p = plausibility(&m, &split_rows(data, "test")?)?;
        (r, p)
    };
    Ok((
        Scores {
            mse: [r[0].mse, r[1].mse, r[2].mse],
            physics_test: r[2].physics_mse,
            plausible_share: share,
            peak_dv,
            peak_depth,
        },
        bytes,
    ))
}

/// Runs the loop and writes the report into `dir`.
pub fn run(data: &GnssData, opts: &LoopOptions, dir: &Path) -> Result<Vec<Round>> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut effects: Vec<OwnedEffect> = Vec::new();
    let mut rounds: Vec<Round> = Vec::new();
    let mut added: Option<CandidateSummary> = None;
    let mut first_b: Option<Vec<u8>> = None;
    let mut last_b: Vec<u8> = Vec::new();
    for round in 0..=opts.max_rounds {
        eprintln!(
            "round {round}: F = Mogi{}",
            effects
                .iter()
                .map(|e| format!(" + {}", e.family()))
                .collect::<String>()
        );
        let (bm, _) = train_mogi_with(data, Variant::B, &effects, &opts.train, opts.seed)?;
        let (cm, _) = train_mogi_with(data, Variant::C, &effects, &opts.train, opts.seed)?;
        let (b, bbytes) = scores(&bm, data)?;
        let (c, _) = scores(&cm, data)?;
        std::fs::write(dir.join(format!("round{round}_B.magic")), &bbytes)?;
        let classical = if opts.classical {
            Some(fit_split(data, "test", &effects)?)
        } else {
            None
        };
        let analysis = {
            let model = Model::decode(&bbytes).map_err(|e| anyhow!("{e}"))?;
            analyse(&model, data, &AnalysisOptions::default())?
        };
        let candidates: Vec<CandidateSummary> = analysis
            .effects
            .iter()
            .map(CandidateSummary::from)
            .collect();
        let labels: Vec<String> = candidates.iter().map(|c| c.family.clone()).collect();
        let ve: Vec<f64> = candidates.iter().map(|c| c.variance_explained).collect();
        let ch: Vec<f64> = candidates.iter().map(|c| c.chance_level).collect();
        if !labels.is_empty() {
            plots::bar_chart(
                &dir.join(format!("round{round}_effects.png")),
                &format!("round {round}: residual variance explained (bars) vs chance (ticks)"),
                &labels,
                &ve,
                &ch,
            )?;
        }
        rounds.push(Round {
            round,
            effects: effects.iter().map(|e| e.family().to_string()).collect(),
            added: added.take(),
            b,
            c,
            classical_test_mse: classical.as_ref().map(|r| r.mse),
            classical: classical.as_ref().map(|r| {
                json!({"test_mse": r.mse, "plausible_share": r.plausible_share, "peak_dv": r.peak_dv, "peak_depth": r.peak_depth, "peak_date": r.peak_date})
            }),
            candidates,
            stop: String::new(),
        });
        if first_b.is_none() {
            first_b = Some(bbytes.clone());
        }
        last_b = bbytes;
        if round == opts.max_rounds {
            if let Some(r) = rounds.last_mut() {
                r.stop = format!("the round limit ({}) was reached", opts.max_rounds);
            }
            break;
        }
        let have: Vec<&str> = effects.iter().map(|e| e.family()).collect();
        let next = analysis
            .effects
            .iter()
            .find(|c| c.significant && c.effect.is_some() && !have.contains(&c.family.as_str()));
        match next {
            Some(c) => {
                effects.push(
                    c.effect
                        .clone()
                        .ok_or_else(|| anyhow!("candidate without an effect"))?,
                );
                added = Some(CandidateSummary::from(c));
            }
            None => {
                if let Some(r) = rounds.last_mut() {
                    r.stop = "no further effect explains more residual variance than chance".into();
                }
                break;
            }
        }
    }
    let first = first_b.ok_or_else(|| anyhow!("no round ran"))?;
    before_after_plots(data, &first, &last_b, dir)?;
    write_report(data, &rounds, dir)?;
    Ok(rounds)
}

/// Time series of one station's vertical (observed, B before, B after) on the test split, and
/// residual maps (mean vertical residual colour, horizontal residual RMS arrows) before and after.
fn before_after_plots(data: &GnssData, first: &[u8], last: &[u8], dir: &Path) -> Result<()> {
    let m0 = Model::decode(first).map_err(|e| anyhow!("{e}"))?;
    let m1 = Model::decode(last).map_err(|e| anyhow!("{e}"))?;
    let split = &data.test;
    let days = split.days();
    let ns = data.names.len();
    let station = data.names.iter().position(|n| n == "AV08").unwrap_or(0);
    let c = 2 * ns + station;
    let mut ws = Workspace::default();
    let (mut obs_s, mut before, mut after) = (vec![], vec![], vec![]);
    let mut res = [vec![[0f64; 3]; ns], vec![[0f64; 3]; ns]];
    for (row, t) in split.x.iter().zip(&days) {
        let obs: Vec<f32> = row
            .iter()
            .enumerate()
            .map(|(k, v)| data.to_mm(k, *v as f64) as f32)
            .collect();
        let i0 = invert_at::<f64>(&m0, &obs, *t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        let i1 = invert_at::<f64>(&m1, &obs, *t, &mut ws).map_err(|e| anyhow!("{e}"))?;
        obs_s.push(obs[c] as f64);
        before.push(i0.physics[c]);
        after.push(i1.physics[c]);
        for (k, inv) in [i0, i1].iter().enumerate() {
            for s in 0..ns {
                for comp in 0..3 {
                    let r = obs[comp * ns + s] as f64 - inv.physics[comp * ns + s];
                    res[k][s][comp] += r * r;
                }
            }
        }
    }
    let name = &data.names[station];
    plots::time_series(
        &dir.join(format!("timeseries_{name}_up.png")),
        &format!("{name} vertical (mm), test split: observed, F before and after the loop"),
        &days,
        &[
            ("observed", &obs_s),
            ("F, round 0", &before),
            ("F, last round", &after),
        ],
    )?;
    let st: Vec<(String, f64, f64)> = data
        .names
        .iter()
        .zip(&data.stations)
        .map(|(n, s)| (n.clone(), s.x_km, s.y_km))
        .collect();
    let n = split.len().max(1) as f64;
    for (k, label) in ["before", "after"].iter().enumerate() {
        let vec: Vec<(f64, f64)> = res[k]
            .iter()
            .map(|r| ((r[0] / n).sqrt(), (r[1] / n).sqrt()))
            .collect();
        let val: Vec<f64> = res[k].iter().map(|r| (r[2] / n).sqrt()).collect();
        plots::station_map(
            &dir.join(format!("residual_map_{label}.png")),
            &format!("residual RMS of F {label} the loop (arrows: E, N; colour: U), test split"),
            &st,
            &vec,
            &val,
        )?;
    }
    Ok(())
}

fn write_report(data: &GnssData, rounds: &[Round], dir: &Path) -> Result<()> {
    let mut md = String::new();
    let _ = writeln!(md, "# The loop on {}\n", data.source);
    let _ = writeln!(md, "MSE in standardised units (paper Table 4: A 0.632, B 0.810, C 0.711). Plausible: share of test days with depth < 10 km and |ΔV| < 5·10⁶ m³.\n");
    let _ = writeln!(
        md,
        "Classical: the per-day Levenberg–Marquardt fit of the same F (no encoder).\n"
    );
    let _ = writeln!(md, "| round | F | added (excess over chance) | B train / valid / test | B physics-only test | C test | classical test | B plausible | B peak ΔV @ depth |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|");
    for r in rounds {
        let f = if r.effects.is_empty() {
            "Mogi".to_string()
        } else {
            format!("Mogi + {}", r.effects.join(" + "))
        };
        let a = r.added.as_ref().map_or("–".to_string(), |c| {
            format!(
                "{} ({:.3} vs chance {:.3})",
                c.family, c.variance_explained, c.chance_level
            )
        });
        let _ = writeln!(
            md,
            "| {} | {f} | {a} | {:.4} / {:.4} / {:.4} | {:.4} | {:.4} | {} | {:.0} % | {:.2} @ {:.1} km |",
            r.round,
            r.b.mse[0],
            r.b.mse[1],
            r.b.mse[2],
            r.b.physics_test.unwrap_or(f64::NAN),
            r.c.mse[2],
            r.classical_test_mse.map_or("–".into(), |v| format!("{v:.4}")),
            100.0 * r.b.plausible_share,
            r.b.peak_dv,
            r.b.peak_depth
        );
    }
    if let Some(r) = rounds.last() {
        let _ = writeln!(
            md,
            "\nThe loop stopped after round {}: {}.",
            r.round, r.stop
        );
    }
    let _ = writeln!(md, "\n## Candidates per round (B's residuals)\n");
    for r in rounds {
        let _ = writeln!(md, "Round {}:\n\n| family | variance explained (held out) | chance | significant | params |\n|---|---|---|---|---|", r.round);
        for c in &r.candidates {
            let _ = writeln!(
                md,
                "| {} | {:.4} | {:.4} | {} | `{}` |",
                c.family, c.variance_explained, c.chance_level, c.significant, c.params
            );
        }
        let _ = writeln!(
            md,
            "\n![effects, round {0}](round{0}_effects.png)\n",
            r.round
        );
    }
    let _ = writeln!(md, "## Before and after\n\n![time series](timeseries_AV08_up.png)\n\n![before](residual_map_before.png) ![after](residual_map_after.png)");
    std::fs::write(dir.join("report.md"), md)?;
    std::fs::write(
        dir.join("report.json"),
        serde_json::to_string_pretty(&json!({"data": data.source, "rounds": rounds}))?,
    )?;
    Ok(())
}
