//! `magic missing`: inversion with stations down — 1, 2, 4 random stations and the two nearest
//! the source.

use super::args::{decode, DataArgs, JsonOut, ModelArg};
use crate::data::SplitName;
use crate::gnss::missing::{evaluate_missing, print_table};
use anyhow::Result;
use clap::Args;

/// `magic missing`.
#[derive(Args, Clone, Debug)]
pub struct MissingCmd {
    #[command(flatten)]
    model: ModelArg,
    #[command(flatten)]
    data: DataArgs,
    /// Split.
    #[arg(long, value_enum, default_value = "test")]
    split: SplitName,
    /// Seed for the random removals.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    json: JsonOut,
}

/// Runs `magic missing`.
pub fn run(a: &MissingCmd) -> Result<()> {
    let p = a.data.gnss()?;
    let bytes = a.model.read()?;
    let m = decode(&a.model.model, &bytes)?;
    let rows = evaluate_missing(&m, &p, a.split, a.seed)?;
    print_table(&rows);
    a.json.write(&rows)
}
