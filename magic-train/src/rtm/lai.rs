//! Retrieved LAI against the SNAP biophysical processor's LAI of the same site and date (the
//! site extract `BPWW_extract_2018.csv`): Spearman rank correlation per species and date — an
//! external check that the encoder's LAI ranks sites and dates sensibly.

use super::data::Extract;
use crate::data::{Dataset, Split};
use crate::numerics::spearman;
use crate::problem::Metric;
use anyhow::{bail, Result};
use magic_core::{invert, Model, Variant, Workspace};
use std::collections::HashMap;

/// One group of the LAI comparison.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LaiGroup {
    /// Species (or `all`).
    pub class: String,
    /// Date (or `all`).
    pub date: String,
    /// Matched spectra.
    pub n: usize,
    /// Spearman correlation of retrieved LAI with SNAP LAI.
    pub spearman: f64,
    /// Mean retrieved LAI.
    pub mean_lai: f64,
    /// Mean SNAP LAI (÷ 1000).
    pub mean_snap: f64,
}

/// How the S2 spectra were matched to the extract.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LaiMatch {
    /// Spectra considered.
    pub spectra: usize,
    /// Spectra whose `(sample_id, date)` has a SNAP LAI in the extract.
    pub matched: usize,
    /// Matched spectra whose 11 bands equal the extract's (reflectance × 10⁴, to 0.5).
    pub bands_agree: usize,
    /// Matched spectra whose species equals the extract row's `class`.
    pub class_agree: usize,
    /// Per species and date, per species, per date and overall.
    pub groups: Vec<LaiGroup>,
}

/// Retrieved LAI (a model of variant B/C/D) on `splits` against the SNAP LAI of the
/// extract: spectra are matched to extract rows by `sample_id` (0-based row) and `date`, the
/// match is checked on the bands and the species, and rank correlations are computed per
/// species and date (groups with at least 10 spectra).
pub fn lai_vs_snap(
    m: &Model<'_>,
    data: &Dataset,
    splits: &[&Split],
    extract: &Extract,
) -> Result<LaiMatch> {
    if m.variant == Variant::A {
        bail!("variant A has no physical variables: use a B, C or D model");
    }
    let mut ws = Workspace::default();
    let mut pairs: Vec<(String, String, f64, f64)> = Vec::new();
    let (mut spectra, mut bands_agree, mut class_agree) = (0, 0, 0);
    for s in splits {
        for i in 0..s.len() {
            spectra += 1;
            let key = (s.ids[i], s.dates[i].clone());
            let Some(&snap) = extract.lai.get(&key) else {
                continue;
            };
            if let Some(b) = extract.bands.get(&key) {
                let ok = (0..11).all(|c| {
                    let refl = data.to_physical(c, s.x[i][c] as f64);
                    (refl * 1e4 - b[c]).abs() <= 0.5 + 1e-3 * b[c].abs()
                });
                bands_agree += ok as usize;
            }
            if extract
                .class
                .get(key.0 as usize)
                .is_some_and(|c| *c == s.labels[i])
            {
                class_agree += 1;
            }
            let obs = data.physical_row(&s.x[i]);
            let inv = invert::<f64>(m, &obs, &mut ws)?;
            pairs.push((s.labels[i].clone(), key.1, inv.params[4], snap / 1000.0));
        }
    }
    let mut groups: HashMap<(String, String), Vec<(f64, f64)>> = HashMap::new();
    for (c, d, lai, snap) in &pairs {
        for key in [
            (c.clone(), d.clone()),
            (c.clone(), "all".into()),
            ("all".into(), d.clone()),
            ("all".into(), "all".into()),
        ] {
            groups.entry(key).or_default().push((*lai, *snap));
        }
    }
    let mut out: Vec<LaiGroup> = groups
        .into_iter()
        .filter(|(_, v)| v.len() >= 10)
        .map(|((class, date), v)| {
            let a: Vec<f64> = v.iter().map(|p| p.0).collect();
            let b: Vec<f64> = v.iter().map(|p| p.1).collect();
            let n = v.len() as f64;
            LaiGroup {
                class,
                date,
                n: v.len(),
                spearman: spearman(&a, &b),
                mean_lai: a.iter().sum::<f64>() / n,
                mean_snap: b.iter().sum::<f64>() / n,
            }
        })
        .collect();
    out.sort_by(|a, b| {
        (a.class == "all", &a.class, a.date == "all", &a.date).cmp(&(
            b.class == "all",
            &b.class,
            b.date == "all",
            &b.date,
        ))
    });
    Ok(LaiMatch {
        spectra,
        matched: pairs.len(),
        bands_agree,
        class_agree,
        groups: out,
    })
}

/// The LAI comparison as report metrics: overall ρ, median ρ per species × date and the share
/// of groups with ρ > 0.
pub fn metrics(r: &LaiMatch) -> Vec<Metric> {
    let overall = r
        .groups
        .iter()
        .find(|g| g.class == "all" && g.date == "all")
        .map_or(f64::NAN, |g| g.spearman);
    let mut per: Vec<f64> = r
        .groups
        .iter()
        .filter(|g| g.class != "all" && g.date != "all")
        .map(|g| g.spearman)
        .collect();
    let positive = per.iter().filter(|v| **v > 0.0).count();
    let median = if per.is_empty() {
        f64::NAN
    } else {
        crate::numerics::median(&mut per)
    };
    vec![
        Metric::new("lai_rho", "LAI vs SNAP ρ", overall, format!("{overall:.3}")),
        Metric::new(
            "lai_rho_median",
            "median ρ per species × date",
            median,
            format!("{median:.3} ({positive}/{} > 0)", per.len()),
        ),
    ]
}
