//! `magic tenv3`: a folder of NGL `<STA>.tenv3` files to daily displacement rows (mm) for
//! `magic invert`.

use super::args::{decode, read_model};
use crate::gnss::{tenv3, Network};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

/// `magic tenv3`.
#[derive(Args, Clone, Debug)]
pub struct Tenv3Cmd {
    /// Folder holding `<STA>.tenv3` files.
    #[arg(long)]
    dir: PathBuf,
    /// Output CSV (`ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S, `date`; NaN = missing).
    #[arg(long)]
    out: PathBuf,
    /// Station order from a `stations.json` (default: every file in the folder, by name).
    #[arg(long, conflicts_with = "model")]
    stations: Option<PathBuf>,
    /// Station order from a model file.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Reference epoch `YYYY-MM-DD` (default: the first day every station has data).
    #[arg(long)]
    reference: Option<String>,
}

/// Runs `magic tenv3`.
pub fn run(a: &Tenv3Cmd) -> Result<()> {
    let names = match (&a.stations, &a.model) {
        (Some(p), _) => Some(Network::read_json(p, None)?.names),
        (_, Some(p)) => Some(tenv3::model_station_names(&decode(p, &read_model(p)?)?)?),
        _ => None,
    };
    let reference = match &a.reference {
        Some(r) => tenv3::Reference::Day(
            tenv3::parse_ymd(r).with_context(|| format!("--reference {r}: expected YYYY-MM-DD"))?,
        ),
        None => tenv3::Reference::Auto,
    };
    let read = tenv3::read_dir(&a.dir, names.as_deref(), reference)?;
    for e in &read.errors {
        eprintln!("{e}");
    }
    for n in &read.notes {
        eprintln!("note: {n}");
    }
    read.daily.write_csv(&a.out)?;
    let d = &read.daily;
    let span = if d.is_empty() {
        String::new()
    } else {
        format!(", {} … {}", d.date(0), d.date(d.len() - 1))
    };
    eprintln!(
        "{} stations, {} days{span}, {} bad lines skipped -> {}",
        d.stations.len(),
        d.len(),
        read.errors.len(),
        a.out.display()
    );
    if !read.errors.is_empty() {
        bail!(
            "{} bad lines or files in {} (skipped; everything else was written)",
            read.errors.len(),
            a.dir.display()
        );
    }
    Ok(())
}
