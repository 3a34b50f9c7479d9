//! `magic eval`: the paper's MSE of a model on a split (standardised units).

use super::args::{decode, DataArgs, ModelArg};
use crate::data::SplitName;
use crate::eval::evaluate;
use crate::with_problem;
use anyhow::Result;
use clap::Args;

/// `magic eval`.
#[derive(Args, Clone, Debug)]
pub struct EvalCmd {
    #[command(flatten)]
    model: ModelArg,
    #[command(flatten)]
    data: DataArgs,
    /// Split to evaluate.
    #[arg(long, value_enum, default_value = "test")]
    split: SplitName,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Runs `magic eval`.
pub fn run(a: &EvalCmd) -> Result<()> {
    let bytes = a.model.read()?;
    let m = decode(&a.model.model, &bytes)?;
    let p = a.data.problem_of(&m)?;
    let r = with_problem!(&p, |p| evaluate(
        &m,
        crate::problem::Problem::data(p).split(a.split),
        a.split.as_str()
    )?);
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        print!("{}: n = {}, MSE = {:.4}", a.split, r.n, r.mse);
        if let Some(p) = r.physics_mse {
            print!(", physics-only MSE = {p:.4}");
        }
        println!();
    }
    Ok(())
}
