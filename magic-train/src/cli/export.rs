//! `magic export`: quantise a trained model for the microcontroller.

use super::args::{decode, write_file, DataArgs, ModelArg};
use crate::model::OwnedModel;
use crate::with_problem;
use anyhow::Result;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// Quantisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Quant {
    /// int8 layers (the encoder head stays f32), activation scales calibrated on the training
    /// split.
    Int8,
}

/// `magic export`.
#[derive(Args, Clone, Debug)]
pub struct ExportCmd {
    #[command(flatten)]
    model: ModelArg,
    /// Quantisation.
    #[arg(long, value_enum, default_value = "int8")]
    quant: Quant,
    #[command(flatten)]
    data: DataArgs,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
}

/// Runs `magic export`.
pub fn run(a: &ExportCmd) -> Result<()> {
    let bytes = a.model.read()?;
    let m = decode(&a.model.model, &bytes)?;
    let p = a.data.problem_of(&m)?;
    let Quant::Int8 = a.quant;
    let train = with_problem!(&p, |p| crate::problem::Problem::data(p).train.clone());
    let q = OwnedModel::from_model(&m).quantize_int8_at(&train.x, &train.days())?;
    let qb = q.encode()?;
    write_file(&a.out, &qb)?;
    eprintln!(
        "exported int8 model: {} bytes -> {}",
        qb.len(),
        a.out.display()
    );
    Ok(())
}
