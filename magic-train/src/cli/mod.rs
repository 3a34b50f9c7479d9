//! The `magic` command line: one module per command, argument groups shared through
//! [`args`], and [`run`] dispatching each command to its module.

pub mod args;
pub mod classical;
pub mod closed_loop;
pub mod demo;
pub mod eval;
pub mod export;
pub mod forward;
pub mod invert;
pub mod lai;
pub mod map;
pub mod missing;
pub mod prepare;
pub mod reproduce;
pub mod residuals;
pub mod station;
pub mod synth;
pub mod tenv3;
pub mod train;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// `magic`: learned inversion of physical models with bias correction.
#[derive(Parser, Debug)]
#[command(
    name = "magic",
    version,
    about = "Learned inversion of physical models with bias correction"
)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// The commands.
#[derive(Subcommand, Debug)]
pub enum Cmd {
    /// The main job: train C and B, evaluate, export int8, run the test days on the firmware.
    Demo(demo::DemoCmd),
    /// Train a model.
    #[command(subcommand)]
    Train(train::TrainCmd),
    /// The paper's MSE of a model on a split (standardised units).
    Eval(eval::EvalCmd),
    /// Quantise a trained model for the microcontroller.
    Export(export::ExportCmd),
    /// Invert observations on the host (physics in f64): one result row per input row.
    Invert(invert::RowsArgs),
    /// Build the firmware with a model and invert observations on it under QEMU.
    Qemu(invert::RowsArgs),
    /// Talk to a board running the deployable firmware (or QEMU): upload a model, stream days.
    Station(station::StationCmd),
    /// Evaluate a forward model.
    #[command(subcommand)]
    Forward(forward::ForwardCmd),
    /// Residual analysis: rank effect families by the residual variance they explain on held-out
    /// data beyond chance.
    Residuals(residuals::ResidualsCmd),
    /// Close the loop: train, trace the residual to a missing effect, add it to F, retrain,
    /// report.
    Loop(closed_loop::LoopCmd),
    /// Reproduce a table of the paper over several seeds (mean ± std).
    Reproduce(reproduce::ReproduceCmd),
    /// Write a synthetic GNSS dataset (one injected effect) in the release layout.
    Synth(synth::SynthCmd),
    /// Check the residual analysis on synthetic data against the injected truth.
    SynthCheck(synth::SynthCheckCmd),
    /// The loop on synthetic data: one dataset per scenario and seed, what it added and kept, MSE
    /// before and after, and over the seeds what it recovered against the truth.
    SynthLoop(synth::SynthLoopCmd),
    /// Map the forest variables of a Sentinel-2 image (RTM model, variant B or C): GeoTIFF in,
    /// float32 GeoTIFF out with one band per column of `magic invert` (the variables,
    /// `residual_rms`, `flags`), then one standard-deviation band per variable (`<name>_sd`).
    Map(map::MapCmd),
    /// Retrieved LAI of a forest model against the SNAP LAI of the site extract.
    Lai(lai::LaiCmd),
    /// Inversion with stations down.
    Missing(missing::MissingCmd),
    /// The classical baseline: a least-squares fit of the Mogi source for every day.
    Classical(classical::ClassicalCmd),
    /// Convert a folder of NGL `<STA>.tenv3` files to daily displacement rows (mm).
    Tenv3(tenv3::Tenv3Cmd),
    /// Turn a folder of NGL `<STA>.tenv3` files into a training set (release layout).
    Prepare(prepare::PrepareCmd),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match &cli.cmd {
        Cmd::Demo(a) => demo::run(a),
        Cmd::Train(a) => train::run(a),
        Cmd::Eval(a) => eval::run(a),
        Cmd::Export(a) => export::run(a),
        Cmd::Invert(a) => invert::invert(a),
        Cmd::Qemu(a) => invert::qemu(a),
        Cmd::Station(a) => station::run(a),
        Cmd::Forward(a) => forward::run(a),
        Cmd::Residuals(a) => residuals::run(a),
        Cmd::Loop(a) => closed_loop::run(a),
        Cmd::Reproduce(a) => reproduce::run(a),
        Cmd::Synth(a) => synth::synth(a),
        Cmd::SynthCheck(a) => synth::check(a),
        Cmd::SynthLoop(a) => synth::run_loop(a),
        Cmd::Map(a) => map::run(a),
        Cmd::Lai(a) => lai::run(a),
        Cmd::Missing(a) => missing::run(a),
        Cmd::Classical(a) => classical::run(a),
        Cmd::Tenv3(a) => tenv3::run(a),
        Cmd::Prepare(a) => prepare::run(a),
    }
}
