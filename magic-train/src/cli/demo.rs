//! `magic demo`: the main job.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `magic demo`.
#[derive(Args, Clone, Debug)]
pub struct DemoCmd {
    /// Data folder laid out like `shared/data/gnss` (default: `$MAGIC_DATA/gnss`,
    /// `../shared/data/gnss`, else a built-in synthetic dataset).
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Maximum epochs.
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    /// Folder for the model files and results.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Skip the firmware run under QEMU.
    #[arg(long)]
    no_qemu: bool,
}

/// Runs `magic demo`.
pub fn run(a: &DemoCmd) -> Result<()> {
    crate::demo::run(a.data_dir.as_deref(), a.seed, a.epochs, &a.out, !a.no_qemu)
}
