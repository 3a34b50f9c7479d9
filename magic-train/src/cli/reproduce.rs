//! `magic reproduce mogi|rtm`: a table of the paper over several seeds (mean ± std).

use super::args::{DataArgs, JsonOut, ProblemArg, Warmup};
use crate::problem::Problem;
use crate::reproduce::table;
use crate::rtm::GeometryArg;
use crate::train::ModelKind;
use crate::with_problem;
use anyhow::Result;
use clap::Args;

/// `magic reproduce`.
#[derive(Args, Clone, Debug)]
pub struct ReproduceCmd {
    /// Which problem: `mogi` (Table 4) or `rtm` (Table 3).
    #[arg(value_enum)]
    problem: ProblemArg,
    #[command(flatten)]
    data: DataArgs,
    /// Forest: INFORM geometry mode (the paper's tables use its implementation's).
    #[arg(long, value_enum, default_value = "reference")]
    geometry: GeometryArg,
    /// Model kinds, comma-separated (default: every kind of the paper's table).
    #[arg(long = "variants", value_enum, value_delimiter = ',')]
    kinds: Vec<ModelKind>,
    /// Seeds, comma-separated.
    #[arg(long, default_value = "1,2,3", value_delimiter = ',')]
    seeds: Vec<u64>,
    /// Maximum epochs.
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    #[command(flatten)]
    warmup: Warmup,
    /// Training runs per model and seed; the one with the lowest validation MSE is kept (1: the
    /// paper's single run).
    #[arg(long, default_value_t = 1)]
    restarts: usize,
    #[command(flatten)]
    json: JsonOut,
}

/// Runs `magic reproduce`.
pub fn run(a: &ReproduceCmd) -> Result<()> {
    let p = a.data.problem(a.problem, a.geometry)?;
    let v = with_problem!(&p, |p| {
        let kinds: Vec<ModelKind> = if a.kinds.is_empty() {
            p.paper_table().iter().map(|r| r.0).collect()
        } else {
            a.kinds.clone()
        };
        let cfg = p
            .recipe()
            .with(a.epochs, false)
            .with_restarts(a.restarts)
            .with_warmup(a.warmup.get());
        table(p, &kinds, &a.seeds, &cfg)?
    });
    a.json.write(&v)
}
