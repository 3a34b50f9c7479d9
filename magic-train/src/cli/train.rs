//! `magic train mogi|rtm`: train a model of a kind and write its f32 model file.

use super::args::{write_file, DataArgs, Warmup};
use crate::gnss::LatentEffect;
use crate::problem::Problem;
use crate::rtm::{GeometryArg, RtmEffect};
use crate::train::{train_model, ModelKind, TrainConfig, TrainLog};
use anyhow::Result;
use clap::{Args, Subcommand, ValueEnum};
use std::path::PathBuf;

/// How the smoothness term of eq. 19 is reduced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SmoothArg {
    /// Summed, as eq. 19 is printed (it then outweighs the MSE).
    Sum,
    /// Averaged over its elements, like the MSE it is added to.
    Mean,
}

/// The options every `train` command has.
#[derive(Args, Clone, Debug)]
pub struct Common {
    /// Model kind: A (autoencoder), B (encoder + F), C (+ correction), D (regressor on simulated
    /// data).
    #[arg(long = "variant", value_enum, default_value = "C")]
    pub kind: ModelKind,
    /// Where the data is.
    #[command(flatten)]
    pub data: DataArgs,
    /// Maximum epochs.
    #[arg(long, default_value_t = 100)]
    pub epochs: usize,
    /// Epochs early stopping does not watch.
    #[command(flatten)]
    pub warmup: Warmup,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Training runs from different initialisations; the one with the lowest validation MSE
    /// is kept (1: the paper's single run).
    #[arg(long, default_value_t = 1)]
    pub restarts: usize,
    /// Output model file (f32).
    #[arg(long)]
    pub out: PathBuf,
}

/// `magic train`.
#[derive(Subcommand, Clone, Debug)]
pub enum TrainCmd {
    /// The Mogi source under the GNSS network.
    Mogi {
        /// The options of every `train` command.
        #[command(flatten)]
        common: Common,
        /// Weight of the smoothness term (eq. 19).
        #[arg(long, default_value_t = 0.01)]
        lambda: f64,
        /// Declared latent effects added to F, comma-separated.
        #[arg(long, value_enum, value_delimiter = ',')]
        effects: Vec<LatentEffect>,
        /// How the smoothness term is reduced.
        #[arg(long, value_enum, default_value = "mean")]
        smooth: SmoothArg,
    },
    /// INFORM under the Sentinel-2 forest spectra.
    Rtm {
        /// The options of every `train` command.
        #[command(flatten)]
        common: Common,
        /// INFORM geometry mode.
        #[arg(long, value_enum, default_value = "reference")]
        geometry: GeometryArg,
        /// Train on the first N training spectra only (0: all).
        #[arg(long, default_value_t = 0)]
        limit: usize,
        /// Declared effects, comma-separated (illumination: each spectrum's own sun from its date
        /// at 47.5° N 14.5° E, 10:00 UTC; with `--geometry physical`).
        #[arg(long, value_enum, value_delimiter = ',')]
        effects: Vec<RtmEffect>,
    },
}

fn finish(
    problem: &impl Problem,
    c: &Common,
    effects: &[crate::model::OwnedEffect],
    cfg: &TrainConfig,
) -> Result<()> {
    let (model, log): (_, TrainLog) = train_model(problem, c.kind, effects, cfg, c.seed)?;
    let bytes = model.encode()?;
    write_file(&c.out, &bytes)?;
    if log.restart_valid.len() > 1 {
        let v: Vec<String> = log
            .restart_valid
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect();
        eprintln!(
            "{} runs, best validation MSE per run: {}; kept run {}",
            v.len(),
            v.join(", "),
            log.restart
        );
    }
    eprintln!(
        "trained {} {:?} on {} rows: {} epochs ({:.2} s/epoch, {:.1} s), best valid {} {:.4} at epoch {} -> {} ({} bytes)",
        problem.name(),
        c.kind,
        problem.data().train.len(),
        log.epochs,
        log.seconds_per_epoch(),
        log.seconds,
        if c.kind == ModelKind::D { "variable MSE (simulated)" } else { "MSE" },
        log.best_valid,
        log.best_epoch,
        c.out.display(),
        bytes.len()
    );
    Ok(())
}

/// Runs `magic train`.
pub fn run(cmd: &TrainCmd) -> Result<()> {
    match cmd {
        TrainCmd::Mogi {
            common,
            lambda,
            effects,
            smooth,
        } => {
            let p = common.data.gnss()?;
            let cfg = TrainConfig {
                lambda: *lambda,
                smooth_mean: *smooth == SmoothArg::Mean,
                ..p.recipe()
                    .with(common.epochs, false)
                    .with_restarts(common.restarts)
                    .with_warmup(common.warmup.get())
            };
            let effects: Vec<_> = effects.iter().map(|e| p.latent_effect(*e)).collect();
            finish(&p, common, &effects, &cfg)
        }
        TrainCmd::Rtm {
            common,
            geometry,
            limit,
            effects,
        } => {
            let mut p = common.data.rtm((*geometry).into())?;
            if *limit > 0 {
                p.data.train = p.data.train.head(*limit);
            }
            let cfg = p
                .recipe()
                .with(common.epochs, false)
                .with_restarts(common.restarts)
                .with_warmup(common.warmup.get());
            let effects: Vec<_> = effects.iter().map(|e| p.effect(*e)).collect();
            finish(&p, common, &effects, &cfg)
        }
    }
}
