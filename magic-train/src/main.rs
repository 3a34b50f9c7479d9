//! `magic`: train, evaluate, export and run learned inversions of physical models.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use magic_core::{Model, Variant};
use magic_train::data::{self, gnss::GnssData};
use magic_train::{evaluate, pipeline, OwnedModel, TrainConfig};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(name = "magic", version, about = "Learned inversion of physical models with bias correction")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum VariantArg {
    #[value(name = "A", alias = "a")]
    A,
    #[value(name = "B", alias = "b")]
    B,
    #[value(name = "C", alias = "c")]
    C,
}

impl From<VariantArg> for Variant {
    fn from(v: VariantArg) -> Variant {
        match v {
            VariantArg::A => Variant::A,
            VariantArg::B => Variant::B,
            VariantArg::C => Variant::C,
        }
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a model.
    Train {
        #[command(subcommand)]
        problem: TrainProblem,
    },
    /// The paper's MSE of a model on a split (standardised units).
    Eval {
        /// Model file.
        #[arg(long)]
        model: PathBuf,
        /// Data folder laid out like `shared/data/gnss` (default: $MAGIC_DATA/gnss or ../shared/data/gnss).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Split to evaluate.
        #[arg(long, default_value = "test")]
        split: String,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Quantise a trained model for the microcontroller.
    Export {
        /// Trained (f32) model file.
        #[arg(long)]
        model: PathBuf,
        /// Quantisation.
        #[arg(long, default_value = "int8")]
        quant: String,
        /// Calibration data folder (default as for `eval`).
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Output model file.
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum TrainProblem {
    /// The Mogi source under the GNSS network.
    Mogi {
        /// Paper variant.
        #[arg(long, value_enum, default_value = "C")]
        variant: VariantArg,
        /// Data folder laid out like `shared/data/gnss`.
        #[arg(long)]
        data_dir: Option<PathBuf>,
        /// Maximum epochs.
        #[arg(long, default_value_t = 100)]
        epochs: usize,
        /// Random seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Weight of the smoothness term (eq. 19).
        #[arg(long, default_value_t = 0.01)]
        lambda: f64,
        /// How the smoothness term is reduced: `sum` (eq. 19 as printed) or `mean` (per element,
        /// the scale of the MSE term).
        #[arg(long, default_value = "mean")]
        smooth: String,
        /// Output model file (f32).
        #[arg(long)]
        out: PathBuf,
    },
}

fn load_gnss(dir: Option<&Path>) -> Result<GnssData> {
    let Some(d) = data::locate(dir, "gnss") else {
        bail!("no GNSS data: pass --data-dir, set MAGIC_DATA, or run next to shared/data")
    };
    GnssData::read(&d)
}

fn read_model(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{}: cannot read model file", path.display()))
}

fn decode<'a>(path: &Path, bytes: &'a [u8]) -> Result<Model<'a>> {
    Model::decode(bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn main() {
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Train { problem: TrainProblem::Mogi { variant, data_dir, epochs, seed, lambda, smooth, out } } => {
            let data = load_gnss(data_dir.as_deref())?;
            let smooth_mean = match smooth.as_str() {
                "sum" => false,
                "mean" => true,
                other => bail!("--smooth {other}: expected `sum` or `mean`"),
            };
            let cfg = TrainConfig { epochs, lambda, smooth_mean, ..TrainConfig::gnss() };
            let (model, log) = pipeline::train_mogi(&data, variant.into(), &cfg, seed)?;
            std::fs::write(&out, model.encode()?).with_context(|| format!("{}: cannot write", out.display()))?;
            eprintln!(
                "trained {:?}: {} epochs ({:.2} s/epoch, {:.1} s), best valid MSE {:.4} at epoch {} -> {}",
                Variant::from(variant),
                log.epochs,
                log.seconds_per_epoch(),
                log.seconds,
                log.best_valid,
                log.best_epoch,
                out.display()
            );
        }
        Cmd::Eval { model, data_dir, split, json } => {
            let data = load_gnss(data_dir.as_deref())?;
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let r = evaluate(&m, data.split(&split)?, &split)?;
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                print!("{split}: n = {}, MSE = {:.4}", r.n, r.mse);
                if let Some(p) = r.physics_mse {
                    print!(", physics-only MSE = {p:.4}");
                }
                println!();
            }
        }
        Cmd::Export { model, quant, data_dir, out } => {
            if quant != "int8" {
                bail!("--quant {quant}: only int8 is supported");
            }
            let data = load_gnss(data_dir.as_deref())?;
            let bytes = read_model(&model)?;
            let m = decode(&model, &bytes)?;
            let q = OwnedModel::from_model(&m).quantize_int8(&data.train.x)?;
            let qb = q.encode()?;
            std::fs::write(&out, &qb).with_context(|| format!("{}: cannot write", out.display()))?;
            eprintln!("exported int8 model: {} bytes -> {}", qb.len(), out.display());
        }
    }
    Ok(())
}
