//! The main job (`magic demo`): train C and B on the measured data when found (else on a built-in
//! synthetic dataset on the same network), evaluate, export int8, and run the test days through
//! the firmware under QEMU, then print the results table.

use crate::data::records;
use crate::data::{self, SplitName};
use crate::eval::{evaluate_splits, EvalResult};
use crate::gnss::plausibility::plausibility;
use crate::gnss::{synth, GnssProblem};
use crate::train::{train_model, ModelKind, TrainConfig, TrainLog};
use anyhow::{anyhow, Context, Result};
use magic_core::mogi::PARAM_NAMES;
use magic_core::Model;
use serde_json::json;
use std::path::Path;

/// Evaluations of one model on the three splits.
pub struct Scores {
    /// Train, valid, test.
    pub splits: Vec<EvalResult>,
}

fn scores(bytes: &[u8], p: &GnssProblem) -> Result<Scores> {
    Ok(Scores {
        splits: evaluate_splits(&Model::decode(bytes)?, &p.data)?.to_vec(),
    })
}

/// Largest absolute difference per parameter between two sets of result lines.
pub fn max_param_diff(a: &[String], b: &[String], n_params: usize) -> Vec<f64> {
    let mut d = vec![0f64; n_params];
    for (x, y) in a.iter().zip(b) {
        let px: Vec<f64> = x
            .split(',')
            .take(n_params)
            .filter_map(|v| v.parse().ok())
            .collect();
        let py: Vec<f64> = y
            .split(',')
            .take(n_params)
            .filter_map(|v| v.parse().ok())
            .collect();
        if px.len() == n_params && py.len() == n_params {
            for j in 0..n_params {
                d[j] = d[j].max((px[j] - py[j]).abs());
            }
        }
    }
    d
}

/// Runs the main job.
pub fn run(
    data_dir: Option<&Path>,
    seed: u64,
    epochs: usize,
    out: &Path,
    qemu: bool,
) -> Result<()> {
    let p = match data::locate(data_dir, "gnss") {
        Some(d) => GnssProblem::read(&d)?,
        None => {
            eprintln!("no GNSS data found (--data-dir, $MAGIC_DATA, ../shared/data): using the built-in synthetic dataset");
            synth::generate(synth::Scenario::Clean, seed).problem
        }
    };
    let data = &p.data;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    eprintln!(
        "data: {} ({} / {} / {} days)",
        data.source,
        data.train.len(),
        data.valid.len(),
        data.test.len()
    );
    let cfg = TrainConfig {
        epochs,
        ..TrainConfig::gnss()
    };
    let mut table = Vec::new();
    let mut logs: Vec<(ModelKind, TrainLog)> = Vec::new();
    let mut c_model = None;
    for kind in [ModelKind::C, ModelKind::B] {
        let (model, log) = train_model(&p, kind, &[], &cfg, seed)?;
        let bytes = model.encode()?;
        std::fs::write(out.join(format!("mogi_{kind:?}.magic")), &bytes)?;
        table.push((format!("{kind:?} (f32)"), scores(&bytes, &p)?));
        logs.push((kind, log));
        if kind == ModelKind::C {
            c_model = Some(model);
        }
    }
    let c_model = c_model.ok_or_else(|| anyhow!("C was not trained"))?;
    let q = c_model.quantize_int8(&data.train.x)?;
    let qbytes = q.encode()?;
    let qpath = out.join("mogi_C_int8.magic");
    std::fs::write(&qpath, &qbytes)?;
    table.push(("C (int8)".to_string(), scores(&qbytes, &p)?));

    // f32 vs int8 on the test days, in physical units.
    let fbytes = c_model.encode()?;
    let fm = Model::decode(&fbytes)?;
    let qm = Model::decode(&qbytes)?;
    let rows = records::split_rows(data, SplitName::Test);
    let f_lines = records::invert_rows(&fm, &rows);
    let q_lines = records::invert_rows(&qm, &rows);
    let quant_diff = max_param_diff(&f_lines, &q_lines, 4);
    records::write_results(&out.join("test_inversions.csv"), &qm, &rows, &q_lines)?;

    println!("\nTest MSE in standardised units (paper Table 4: A 0.632, B 0.810, C 0.711)\n");
    println!("| model | train | valid | test | physics-only test |");
    println!("|---|---|---|---|---|");
    for (name, s) in &table {
        let p = s.splits[2]
            .physics_mse
            .map_or("-".to_string(), |v| format!("{v:.4}"));
        println!(
            "| {name} | {:.4} | {:.4} | {:.4} | {p} |",
            s.splits[0].mse, s.splits[1].mse, s.splits[2].mse
        );
    }
    println!();
    for (v, l) in &logs {
        println!(
            "training {v:?}: {} epochs, {:.3} s/epoch, {:.1} s in all (best epoch {})",
            l.epochs,
            l.seconds_per_epoch(),
            l.seconds,
            l.best_epoch
        );
    }
    println!(
        "int8 vs f32 (test days): MSE {:+.4}; largest parameter difference: {}",
        table[2].1.splits[2].mse - table[0].1.splits[2].mse,
        PARAM_NAMES
            .iter()
            .zip(&quant_diff)
            .map(|(n, d)| format!("{n} {d:.4}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let plaus = plausibility(&qm, data, SplitName::Test)?;
    println!(
        "2008-like event (test period): peak ΔV {:.2}·10⁶ m³ at depth {:.1} km; {:.0} % of test days with depth < 10 km and |ΔV| < 5·10⁶ m³",
        plaus.0, plaus.1, 100.0 * plaus.2
    );
    let mut summary = json!({
        "data": data.source,
        "models": table.iter().map(|(n, s)| json!({"model": n, "splits": s.splits})).collect::<Vec<_>>(),
        "training": logs.iter().map(|(v, l)| json!({"variant": format!("{v:?}"), "epochs": l.epochs, "seconds_per_epoch": l.seconds_per_epoch(), "seconds": l.seconds})).collect::<Vec<_>>(),
        "int8_max_param_diff": quant_diff,
    });
    if qemu {
        let fw = crate::firmware::run_test_days(&qpath, &qm, &rows, &q_lines)?;
        summary["firmware"] = fw;
    }
    std::fs::write(
        out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    println!("\nmodels and results in {}", out.display());
    Ok(())
}
