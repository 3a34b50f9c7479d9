//! `magic classical`: the classical baseline — a least-squares fit of the Mogi source (and
//! declared latent effects) for every day, no encoder.

use super::args::{DataArgs, JsonOut};
use crate::data::SplitName;
use crate::gnss::classical::{fit_split_with, parse_grid, summary_line, write_csv};
use crate::gnss::LatentEffect;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `magic classical`.
#[derive(Args, Clone, Debug)]
pub struct ClassicalCmd {
    #[command(flatten)]
    data: DataArgs,
    /// Splits, comma-separated.
    #[arg(long, value_enum, default_value = "test", value_delimiter = ',')]
    split: Vec<SplitName>,
    /// Latent effects fitted with the source, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',')]
    effects: Vec<LatentEffect>,
    /// Start grid NX,NY,ND,KEEP: points over x, y, depth, and how many of the best are refined.
    #[arg(long, default_value = "12,12,10,8")]
    grid: String,
    #[command(flatten)]
    json: JsonOut,
    /// Write the per-day fits as CSV here.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// Runs `magic classical`: one summary line per split, the summaries as JSON and the per-day fits
/// as CSV when asked.
pub fn run(a: &ClassicalCmd) -> Result<()> {
    let grid = parse_grid(&a.grid)?;
    let p = a.data.gnss()?;
    let effects: Vec<_> = a.effects.iter().map(|e| p.latent_effect(*e)).collect();
    let mut results = Vec::new();
    for &split in &a.split {
        let r = fit_split_with(&p, split, &effects, &grid)?;
        println!("{}", summary_line(&r));
        results.push(r);
    }
    a.json.write(&results)?;
    if let Some(path) = &a.csv {
        write_csv(path, &results)?;
    }
    Ok(())
}
