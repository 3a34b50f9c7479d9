//! `magic loop mogi|rtm`: close the loop — train, trace the residual to a missing effect, add it
//! to F, retrain, report.

use super::args::{DataArgs, ProblemArg, Warmup};
use crate::analysis::{AnalysisOptions, LastingStatistic, MainSource};
use crate::closed_loop::{run as run_loop, LoopOptions};
use crate::problem::Problem;
use crate::rtm::GeometryArg;
use crate::with_problem;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `magic loop`.
#[derive(Args, Clone, Debug)]
pub struct LoopCmd {
    /// Problem: `mogi` (GNSS) or `rtm` (Sentinel-2 forest spectra).
    #[arg(value_enum, default_value = "mogi")]
    problem: ProblemArg,
    #[command(flatten)]
    data: DataArgs,
    /// Forest: INFORM geometry mode (`physical`: the published equations; `reference`: the
    /// paper's implementation, which hands INFORM cosines where angles are expected, so a
    /// declared sun would not mean what it says).
    #[arg(long, value_enum, default_value = "physical")]
    geometry: GeometryArg,
    /// Surrogates per family in the residual analysis.
    #[arg(long, default_value_t = 20)]
    surrogates: usize,
    /// The volcano's main source in the residual analysis: `free` to move every day (whatever
    /// moving it produces is projected off; point sources are located and scored with it held) or
    /// `held` in place (only its field's direction is projected off, so a second source near
    /// it stays visible and counts whole).
    #[arg(long, value_enum, default_value_t)]
    main_source: MainSource,
    /// The volcano: how a change that stays is detected — `matched` (a matched filter under
    /// noise fitted to the residuals; the README's tables) or `scan` (the offsets over 180-day
    /// windows, detected by the held-out gain; the earlier default, docs/matched-filter.md).
    #[arg(long, value_enum, default_value_t)]
    lasting: LastingStatistic,
    /// The volcano: the most extra point sources F may hold (the loop adds a second beside a
    /// first only where the main source does not trade with that one; measured in
    /// docs/synthetic-check.md, *A second source term in F*).
    #[arg(long, default_value_t = 1, value_parser = super::args::terms)]
    extra_sources: usize,
    /// The volcano: the most steps F may hold, each at its own station and time (measured in
    /// docs/synthetic-check.md, *Steps at several stations*).
    #[arg(long, default_value_t = 1, value_parser = super::args::terms)]
    steps: usize,
    /// Report folder (Markdown, JSON, PNG, the rounds' model files).
    #[arg(long, default_value = "out/loop")]
    report: PathBuf,
    /// Training seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Maximum epochs per training.
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    #[command(flatten)]
    warmup: Warmup,
    /// Most rounds after the first, each adding one effect (kept, or taken out again and the
    /// next candidate tried in the following round).
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Skip the classical baseline (volcano: a per-day least-squares fit each round).
    #[arg(long)]
    no_classical: bool,
}

/// Runs `magic loop`.
pub fn run(a: &LoopCmd) -> Result<()> {
    let p = a.data.problem(a.problem, a.geometry)?;
    let r = with_problem!(&p, |p| {
        let opts = LoopOptions {
            seed: a.seed,
            train: p.recipe().with(a.epochs, false).with_warmup(a.warmup.get()),
            max_rounds: a.rounds,
            baseline: !a.no_classical,
            analysis: AnalysisOptions {
                surrogates: a.surrogates,
                main_source: a.main_source,
                lasting: a.lasting,
                extra_sources: a.extra_sources,
                steps: a.steps,
                ..AnalysisOptions::default()
            },
        };
        run_loop(p, &opts, &a.report)?
    });
    let md = std::fs::read_to_string(a.report.join("report.md"))?;
    print!("{}", md.split("\n## ").next().unwrap_or(""));
    eprintln!(
        "{} rounds; report in {}",
        r.rounds.len(),
        a.report.display()
    );
    Ok(())
}
