//! `magic synth`, `magic synth-check`, `magic synth-loop`: synthetic GNSS data with one injected
//! effect, and how well the analysis and the loop recover it.

use super::args::{write_file, JsonOut};
use crate::analysis::AnalysisOptions;
use crate::closed_loop::{self, LoopOptions};
use crate::gnss::data::write_dir;
use crate::gnss::recovery::{check_one, recovery_table};
use crate::gnss::synth::{self, Scenario};
use crate::problem::Problem;
use anyhow::Result;
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

/// `magic synth`.
#[derive(Args, Clone, Debug)]
pub struct SynthCmd {
    /// Scenario: `clean`, or the effect family injected.
    #[arg(long, value_enum, default_value = "clean")]
    scenario: Scenario,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output folder (the release layout, plus `truth.json`).
    #[arg(long)]
    out: PathBuf,
}

/// Runs `magic synth`.
pub fn synth(a: &SynthCmd) -> Result<()> {
    let s = synth::generate(a.scenario, a.seed);
    write_dir(&s.problem, &a.out)?;
    write_file(
        &a.out.join("truth.json"),
        serde_json::to_string_pretty(&s.truth)?,
    )?;
    eprintln!(
        "wrote synthetic dataset ({}) -> {}",
        s.problem.data.source,
        a.out.display()
    );
    Ok(())
}

/// Scenarios (default: all), comma-separated.
fn scenarios(list: &[Scenario]) -> Vec<Scenario> {
    if list.is_empty() {
        Scenario::ALL.to_vec()
    } else {
        list.to_vec()
    }
}

/// `magic synth-check`.
#[derive(Args, Clone, Debug)]
pub struct SynthCheckCmd {
    /// Number of seeds per scenario (first-seed, first-seed + 1, …).
    #[arg(long, default_value_t = 10)]
    seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    first_seed: u64,
    /// Scenarios, comma-separated (default: all).
    #[arg(long, value_enum, value_delimiter = ',')]
    scenarios: Vec<Scenario>,
    /// Training epochs of the B models.
    #[arg(long, default_value_t = 15)]
    epochs: usize,
    #[command(flatten)]
    json: JsonOut,
}

/// Runs `magic synth-check`: for every scenario and seed, generate the data, train a B model
/// briefly, analyse it and compare with the injected truth.
pub fn check(a: &SynthCheckCmd) -> Result<()> {
    let cfg = crate::train::TrainConfig::gnss().with(a.epochs, true);
    let opts = AnalysisOptions::default();
    let (mut rows, mut out) = (Vec::new(), Vec::new());
    for sc in scenarios(&a.scenarios) {
        for seed in a.first_seed..a.first_seed + a.seeds {
            let (r, an) = check_one(sc, seed, &cfg, &opts)?;
            eprintln!(
                "{:<14} seed {:>3}: top {:<14} {}  {}",
                sc.name(),
                seed,
                r.top,
                if r.ok() { "ok  " } else { "FAIL" },
                r.detail
            );
            out.push(json!({"scenario": sc.name(), "seed": seed, "ok": r.ok(), "ranked_first": r.ranked_first,
                "significant": r.significant, "params_ok": r.params_ok, "detail": r.detail, "analysis": an.to_json()}));
            rows.push(r);
        }
    }
    print!("{}", recovery_table(&rows));
    a.json.write(&out)
}

/// `magic synth-loop`.
#[derive(Args, Clone, Debug)]
pub struct SynthLoopCmd {
    /// Scenarios, comma-separated (default: all).
    #[arg(long, value_enum, value_delimiter = ',')]
    scenarios: Vec<Scenario>,
    /// Seed of the data and the training.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Maximum epochs per training.
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    /// Most effects to add.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Folder for each scenario's loop report.
    #[arg(long, default_value = "out/synth-loop")]
    out: PathBuf,
}

/// Runs `magic synth-loop`: the loop on one synthetic dataset per scenario, with a table of the
/// effects it added and the test MSE of B and C before and after.
pub fn run_loop(a: &SynthLoopCmd) -> Result<()> {
    let mut table = String::from(
        "| injected | effects added (explained vs chance) | B test before → after | C test before → after |\n|---|---|---|---|\n",
    );
    for sc in scenarios(&a.scenarios) {
        let s = synth::generate(sc, a.seed);
        let opts = LoopOptions {
            seed: a.seed,
            train: s.problem.recipe().with(a.epochs, true),
            max_rounds: a.rounds,
            baseline: false,
            analysis: AnalysisOptions::default(),
        };
        let dir = a.out.join(sc.name());
        eprintln!("scenario {} (seed {})", sc.name(), a.seed);
        let r = closed_loop::run(&s.problem, &opts, &dir)?;
        write_file(
            &dir.join("truth.json"),
            serde_json::to_string_pretty(&s.truth)?,
        )?;
        let (first, last) = (r.first(), r.last_kept());
        let added = r.added();
        table += &format!(
            "| {} | {} | {:.4} → {:.4} | {:.4} → {:.4} |\n",
            sc.name(),
            if added.is_empty() {
                "none".to_string()
            } else {
                added.join(", ")
            },
            first.b.mse[2],
            last.b.mse[2],
            first.c.mse[2],
            last.c.mse[2]
        );
    }
    print!("{table}");
    std::fs::create_dir_all(&a.out)?;
    write_file(&a.out.join("table.md"), &table)
}
