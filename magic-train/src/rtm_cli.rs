//! The RTM commands of `magic`: `train rtm`, `forward rtm`, `reproduce rtm`, `lai`, and the RTM
//! branches of `eval` and `export`.

use crate::data::rtm_tables::{self, RtmTables};
use crate::data::s2::{Extract, S2Data};
use crate::data::table::Table;
use crate::export::OwnedModel;
use crate::rtm_pipeline::{evaluate_par, lai_vs_snap, table3, train_rtm, RtmSetup, RtmVariant};
use crate::train::TrainConfig;
use anyhow::{anyhow, bail, Context, Result};
use magic_core::rtm::{Geometry, INPUT_NAMES, N_BANDS, N_INPUTS, S2_BANDS};
use magic_core::Model;
use std::path::{Path, PathBuf};

/// Parses `reference` or `physical`.
pub fn parse_geometry(s: &str) -> Result<Geometry> {
    match s {
        "reference" => Ok(Geometry::Reference),
        "physical" => Ok(Geometry::Physical),
        _ => bail!("--geometry {s}: expected `reference` or `physical`"),
    }
}

/// The S2 folder: `--data-dir`, else `$MAGIC_DATA/s2`, else `../shared/data/s2`.
pub fn locate_s2(dir: Option<&Path>) -> Result<PathBuf> {
    crate::data::locate(dir, "s2")
        .context("no S2 data: pass --data-dir, set MAGIC_DATA, or run next to shared/data")
}

/// Options of `magic train rtm`.
pub struct TrainArgs {
    /// `A`, `B`, `C` or `D`.
    pub variant: String,
    /// S2 folder.
    pub data_dir: Option<PathBuf>,
    /// Tables folder.
    pub tables: Option<PathBuf>,
    /// Maximum epochs.
    pub epochs: usize,
    /// Seed.
    pub seed: u64,
    /// Geometry mode.
    pub geometry: String,
    /// Train on the first N training spectra only (0: all).
    pub limit: usize,
    /// Declared effects (`illumination`).
    pub effects: Vec<String>,
    /// Output model file.
    pub out: PathBuf,
}

/// `magic train rtm`.
pub fn train(a: &TrainArgs) -> Result<()> {
    let variant = RtmVariant::parse(&a.variant)?;
    let mut setup = RtmSetup::read(
        &locate_s2(a.data_dir.as_deref())?,
        &rtm_tables::locate(a.tables.as_deref())?,
        parse_geometry(&a.geometry)?,
    )?;
    setup.effects = a
        .effects
        .iter()
        .map(|e| crate::rtm_pipeline::rtm_effect(e))
        .collect::<Result<_>>()?;
    let cfg = TrainConfig {
        epochs: a.epochs,
        ..TrainConfig::s2()
    };
    let d = &setup.data;
    let tr = if a.limit > 0 {
        d.train.head(a.limit)
    } else {
        d.train.clone()
    };
    let (model, log) = train_rtm(&setup, &tr, &d.valid, variant, &cfg, a.seed)?;
    let bytes = model.encode()?;
    std::fs::write(&a.out, &bytes).with_context(|| format!("{}: cannot write", a.out.display()))?;
    eprintln!(
        "trained RTM {variant:?} on {} spectra: {} epochs ({:.2} s/epoch, {:.1} s), best valid {} {:.4} at epoch {} -> {} ({} bytes)",
        tr.len(),
        log.epochs,
        log.seconds_per_epoch(),
        log.seconds,
        if variant == RtmVariant::D { "variable MSE (simulated)" } else { "MSE" },
        log.best_valid,
        log.best_epoch,
        a.out.display(),
        bytes.len()
    );
    Ok(())
}

/// `magic eval` for an RTM model.
pub fn eval(model: &Model<'_>, data_dir: Option<&Path>, split: &str, json: bool) -> Result<()> {
    let data = S2Data::read(&locate_s2(data_dir)?)?;
    let r = evaluate_par(model, &data.split(split)?.rows, split)?;
    if json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        print!("{split}: n = {}, MSE = {:.4}", r.n, r.mse);
        if let Some(p) = r.physics_mse {
            print!(", physics-only MSE = {p:.4}");
        }
        println!();
    }
    Ok(())
}

/// `magic export` for an RTM model: int8 layers calibrated on the S2 training spectra.
pub fn export_int8(model: &Model<'_>, data_dir: Option<&Path>) -> Result<Vec<u8>> {
    let data = S2Data::read(&locate_s2(data_dir)?)?;
    OwnedModel::from_model(model)
        .quantize_int8_at(&data.train.rows.x, &data.train.rows.days())?
        .encode()
}

/// `magic forward rtm`: rows of the 21 INFORM inputs (columns named as in
/// `rtm_inform_s2_10k.csv`; a `sample_id` column is carried) → the 13 bands B01…B12.
pub fn forward(input: &Path, output: &Path, tables: Option<&Path>, geometry: &str) -> Result<()> {
    let geometry = parse_geometry(geometry)?;
    let t = RtmTables::read(&rtm_tables::locate(tables)?)?;
    let model = t.inform().map_err(|e| anyhow!("RTM tables: {e}"))?;
    let csv = Table::read(input, b',')?;
    let cols: Vec<usize> = INPUT_NAMES
        .iter()
        .map(|c| csv.col(c))
        .collect::<Result<_>>()?;
    let id = csv.col("sample_id").ok();
    let mut text = String::new();
    if id.is_some() {
        text.push_str("sample_id,");
    }
    text.push_str(&S2_BANDS.join(","));
    text.push('\n');
    let mut errors = 0;
    for r in 0..csv.rows.len() {
        let mut x = [0f64; N_INPUTS];
        for (k, &c) in cols.iter().enumerate() {
            x[k] = csv.num(r, c, false)?;
        }
        if let Some(c) = id {
            text.push_str(csv.text(r, c));
            text.push(',');
        }
        match model.forward(&x, geometry) {
            Ok(y) => {
                let f: Vec<String> = y.iter().map(|v| format!("{v:e}")).collect();
                text.push_str(&f.join(","));
            }
            Err(e) => {
                eprintln!("{}:{}: {e}", csv.path, csv.line(r));
                errors += 1;
                text.push_str(&vec!["NaN"; N_BANDS].join(","));
            }
        }
        text.push('\n');
    }
    std::fs::write(output, text).with_context(|| format!("{}: cannot write", output.display()))?;
    eprintln!("{} rows -> {}", csv.rows.len(), output.display());
    if errors > 0 {
        bail!(
            "{errors} of {} rows are outside the model's domain (NaN rows written)",
            csv.rows.len()
        );
    }
    Ok(())
}

/// `magic reproduce rtm`: Table 3 over seeds.
pub fn reproduce(
    data_dir: Option<&Path>,
    tables: Option<&Path>,
    seeds: &[u64],
    epochs: usize,
    variants: &str,
    json: Option<&Path>,
) -> Result<()> {
    let setup = RtmSetup::read(
        &locate_s2(data_dir)?,
        &rtm_tables::locate(tables)?,
        Geometry::Reference,
    )?;
    let variants = variants
        .split(',')
        .map(|v| RtmVariant::parse(v.trim()))
        .collect::<Result<Vec<_>>>()?;
    let cfg = TrainConfig {
        epochs,
        ..TrainConfig::s2()
    };
    let v = table3(&setup, seeds, &cfg, &variants)?;
    if let Some(p) = json {
        std::fs::write(p, serde_json::to_string_pretty(&v)?)
            .with_context(|| format!("{}: cannot write", p.display()))?;
    }
    Ok(())
}

/// `magic lai`: retrieved LAI against the SNAP LAI of the site extract.
pub fn lai(model: &Path, data_dir: Option<&Path>, json: Option<&Path>) -> Result<()> {
    let dir = locate_s2(data_dir)?;
    let data = S2Data::read(&dir)?;
    let extract = Extract::read(&dir.join("BPWW_extract_2018.csv"))?;
    let bytes = std::fs::read(model)
        .with_context(|| format!("{}: cannot read model file", model.display()))?;
    let r = lai_vs_snap(
        &bytes,
        &data,
        &[&data.train, &data.valid, &data.test],
        &extract,
    )?;
    println!(
        "{} spectra; {} matched to the extract by (sample_id = row, date); bands agree for {}, species for {}",
        r.spectra, r.matched, r.bands_agree, r.class_agree
    );
    let row = |g: &crate::rtm_pipeline::LaiGroup| {
        println!(
            "| {} | {} | {} | {:.3} | {:.2} | {:.2} |",
            g.class, g.date, g.n, g.spearman, g.mean_lai, g.mean_snap
        )
    };
    let head = || {
        println!("| species | date | n | Spearman ρ | mean LAI (ours) | mean LAI (SNAP) |");
        println!("|---|---|---|---|---|---|");
    };
    let pooled = |g: &&crate::rtm_pipeline::LaiGroup| g.class == "all" || g.date == "all";
    println!("\nPooled over dates or species:");
    head();
    r.groups.iter().filter(pooled).for_each(row);
    let mut per: Vec<f64> = r
        .groups
        .iter()
        .filter(|g| !pooled(g))
        .map(|g| g.spearman)
        .collect();
    per.sort_by(f64::total_cmp);
    if !per.is_empty() {
        let pos = per.iter().filter(|v| **v > 0.0).count();
        println!(
            "\nPer species and date ({} groups of at least 10 spectra): median ρ {:.3}, {pos} positive",
            per.len(),
            per[per.len() / 2]
        );
    }
    head();
    r.groups.iter().filter(|g| !pooled(g)).for_each(row);
    if let Some(p) = json {
        std::fs::write(p, serde_json::to_string_pretty(&r)?)
            .with_context(|| format!("{}: cannot write", p.display()))?;
    }
    Ok(())
}
