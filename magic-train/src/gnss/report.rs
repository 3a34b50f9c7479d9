//! The volcano's figures: the residual analysis (each family's score against chance, the dominant
//! residual pattern on the network, residual RMS per station) and the loop's before/after (one
//! station's vertical with F before and after, residual maps).

use super::{GnssProblem, GnssResiduals};
use crate::analysis::{effects_chart, Analysis};
use crate::report::plots;
use anyhow::{Context, Result};
use magic_core::{invert_at, Model, Workspace};
use std::path::Path;

/// The analysed splits as a label.
fn splits(a: &Analysis) -> String {
    let s: Vec<&str> = a.splits.iter().map(|s| s.as_str()).collect();
    s.join(" + ")
}

/// Stations as the map plots take them: name, east, north (km).
fn stations(res_or_net: &super::Network) -> Vec<(String, f64, f64)> {
    res_or_net
        .names
        .iter()
        .zip(&res_or_net.stations)
        .map(|(n, s)| (n.clone(), s.x_km, s.y_km))
        .collect()
}

/// `[[e, n, u], …]` per station from the analysis JSON.
fn triples(v: &serde_json::Value) -> Vec<[f64; 3]> {
    v.as_array()
        .map(|a| {
            a.iter()
                .map(|t| core::array::from_fn(|k| t[k].as_f64().unwrap_or(f64::NAN)))
                .collect()
        })
        .unwrap_or_default()
}

/// Writes `effects.png` (each family's held-out score as a bar, its chance level as a tick),
/// `residual_pattern.png` (the dominant residual pattern on the network: horizontal arrows, the
/// vertical as colour) and `residual_rms.png` (residual RMS per station, all components).
pub fn analysis_plots(res: &GnssResiduals, a: &Analysis, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    effects_chart(
        &dir.join("effects.png"),
        &format!(
            "Residual variance explained on held-out data, % ({}; tick: chance, *: significant)",
            splits(a)
        ),
        &a.effects,
    )?;
    let st = stations(&res.ctx.network);
    let pattern = triples(&a.residuals["pattern_mm"]);
    let share = a.residuals["pattern_share"].as_f64().unwrap_or(0.0);
    plots::station_map(
        &dir.join("residual_pattern.png"),
        &format!(
            "Dominant residual pattern ({:.0} % of the residual variance; arrows E/N, colour U, mm RMS)",
            100.0 * share
        ),
        &st,
        &pattern.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
        &pattern.iter().map(|p| p[2]).collect::<Vec<_>>(),
    )?;
    let rms = triples(&a.residuals["station_rms_mm"]);
    plots::station_map(
        &dir.join("residual_rms.png"),
        &format!(
            "Residual RMS per station, mm ({}, all components)",
            splits(a)
        ),
        &st,
        &[],
        &rms.iter()
            .map(|v| (v.iter().map(|x| x * x).sum::<f64>() / 3.0).sqrt())
            .collect::<Vec<_>>(),
    )?;
    Ok(())
}

/// Time series of one station's vertical (observed, F before, F after) on the test split, and
/// residual maps (horizontal residual RMS as arrows, vertical as colour) before and after.
/// Returns the Markdown image lines.
pub fn before_after(
    p: &GnssProblem,
    first: &Model<'_>,
    last: &Model<'_>,
    dir: &Path,
) -> Result<Vec<String>> {
    let split = &p.data.test;
    let days = split.days();
    let ns = p.network.len();
    // The station with the largest vertical variance on the test split shows the source best.
    let station = (0..ns)
        .max_by(|&a, &b| {
            let var = |s: usize| {
                split
                    .x
                    .iter()
                    .map(|r| (r[2 * ns + s] as f64 * p.data.scale[2 * ns + s]).powi(2))
                    .filter(|v| v.is_finite())
                    .sum::<f64>()
            };
            var(a).total_cmp(&var(b))
        })
        .unwrap_or(0);
    let c = 2 * ns + station;
    let mut ws = Workspace::default();
    let (mut obs_s, mut before, mut after) = (vec![], vec![], vec![]);
    let mut res = [vec![[0f64; 3]; ns], vec![[0f64; 3]; ns]];
    // Days each channel is observed (missing channels leave the residual maps alone).
    let mut seen = vec![[0usize; 3]; ns];
    for (row, t) in split.x.iter().zip(&days) {
        let obs = p.data.physical_row(row);
        let i0 = invert_at::<f64>(first, &obs, *t, &mut ws)?;
        let i1 = invert_at::<f64>(last, &obs, *t, &mut ws)?;
        obs_s.push(obs[c] as f64);
        before.push(i0.physics[c]);
        after.push(i1.physics[c]);
        for s in 0..ns {
            for comp in 0..3 {
                if !obs[comp * ns + s].is_nan() {
                    seen[s][comp] += 1;
                }
            }
        }
        for (k, inv) in [i0, i1].iter().enumerate() {
            for s in 0..ns {
                for comp in 0..3 {
                    let r = obs[comp * ns + s] as f64 - inv.physics[comp * ns + s];
                    if r.is_finite() {
                        res[k][s][comp] += r * r;
                    }
                }
            }
        }
    }
    let name = &p.network.names[station];
    let ts = format!("timeseries_{name}_up.png");
    plots::time_series(
        &dir.join(&ts),
        &format!("{name} vertical (mm), test split: observed, F before and after the loop"),
        &days,
        &[
            ("observed", &obs_s),
            ("F, round 0", &before),
            ("F, last round", &after),
        ],
    )?;
    let st = stations(&p.network);
    let rms = |r: &[f64; 3], s: usize, comp: usize| (r[comp] / seen[s][comp].max(1) as f64).sqrt();
    for (k, label) in ["before", "after"].iter().enumerate() {
        let vec: Vec<(f64, f64)> = res[k]
            .iter()
            .enumerate()
            .map(|(s, r)| (rms(r, s, 0), rms(r, s, 1)))
            .collect();
        let val: Vec<f64> = res[k]
            .iter()
            .enumerate()
            .map(|(s, r)| rms(r, s, 2))
            .collect();
        plots::station_map(
            &dir.join(format!("residual_map_{label}.png")),
            &format!("residual RMS of F {label} the loop (arrows: E, N; colour: U), test split"),
            &st,
            &vec,
            &val,
        )?;
    }
    Ok(vec![
        format!("![time series]({ts})"),
        "![before](residual_map_before.png) ![after](residual_map_after.png)".to_string(),
    ])
}
