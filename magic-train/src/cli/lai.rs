//! `magic lai`: the retrieved LAI of a forest model (B, C or D) against the SNAP LAI of the site
//! extract — rank correlation per species and date.

use super::args::{decode, DataArgs, JsonOut, ModelArg};
use crate::rtm::lai::{lai_vs_snap, LaiGroup};
use anyhow::{Context, Result};
use clap::Args;

/// `magic lai`.
#[derive(Args, Clone, Debug)]
pub struct LaiCmd {
    #[command(flatten)]
    model: ModelArg,
    #[command(flatten)]
    data: DataArgs,
    #[command(flatten)]
    json: JsonOut,
}

fn table(groups: &[&LaiGroup]) {
    println!("| species | date | n | Spearman ρ | mean LAI (ours) | mean LAI (SNAP) |");
    println!("|---|---|---|---|---|---|");
    for g in groups {
        println!(
            "| {} | {} | {} | {:.3} | {:.2} | {:.2} |",
            g.class, g.date, g.n, g.spearman, g.mean_lai, g.mean_snap
        );
    }
}

/// Runs `magic lai`.
pub fn run(a: &LaiCmd) -> Result<()> {
    let bytes = a.model.read()?;
    let m = decode(&a.model.model, &bytes)?;
    let magic_core::Problem::Rtm { geometry, .. } = m.problem else {
        anyhow::bail!("{}: not a forest (RTM) model", a.model.model.display());
    };
    let p = a.data.rtm(geometry)?;
    let ext = p
        .extract
        .as_ref()
        .context("no site extract `BPWW_extract_2018.csv` beside the S2 data")?;
    let d = &p.data;
    let r = lai_vs_snap(&m, d, &[&d.train, &d.valid, &d.test], ext)?;
    println!(
        "{} spectra; {} matched to the extract by (sample_id = row, date); bands agree for {}, species for {}",
        r.spectra, r.matched, r.bands_agree, r.class_agree
    );
    let pooled = |g: &&LaiGroup| g.class == "all" || g.date == "all";
    println!("\nPooled over dates or species:");
    table(&r.groups.iter().filter(pooled).collect::<Vec<_>>());
    let per: Vec<&LaiGroup> = r.groups.iter().filter(|g| !pooled(g)).collect();
    let mut rho: Vec<f64> = per.iter().map(|g| g.spearman).collect();
    if !rho.is_empty() {
        let pos = rho.iter().filter(|v| **v > 0.0).count();
        println!(
            "\nPer species and date ({} groups of at least 10 spectra): median ρ {:.3}, {pos} positive",
            rho.len(),
            crate::numerics::median(&mut rho)
        );
    }
    table(&per);
    a.json.write(&r)
}
