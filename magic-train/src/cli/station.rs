//! `magic station`: the host end of the deployable firmware's line protocol
//! ([`crate::firmware::station`]) over a serial port or TCP.

use crate::firmware::station::{run_cli, Options};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `magic station`.
#[derive(Args, Clone, Debug)]
pub struct StationCmd {
    /// `tcp:HOST:PORT` (QEMU's `-serial tcp::PORT,server`) or a serial device (`/dev/ttyUSB0`).
    #[arg(long)]
    port: String,
    /// Model file (int8, from `magic export`): uploaded unless the board runs it already.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Observation CSV, as for `magic invert` (needs --model).
    #[arg(long)]
    days: Option<PathBuf>,
    /// Result CSV: the date, the model id, then `magic invert`'s columns, and the `*_sd`
    /// columns of `magic invert --sd` when the board's firmware has the feature `sd` (default:
    /// stdout).
    #[arg(long)]
    output: Option<PathBuf>,
    /// The days hold standardised values.
    #[arg(long)]
    standardized: bool,
}

/// Runs `magic station`.
pub fn run(a: &StationCmd) -> Result<()> {
    run_cli(&Options {
        port: a.port.clone(),
        model: a.model.clone(),
        days: a.days.clone(),
        output: a.output.clone(),
        standardized: a.standardized,
    })
}
