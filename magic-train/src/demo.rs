//! The main job (`magic demo`): the mission in one command. On the measured GNSS data when found
//! (else on a built-in synthetic record of the same network holding an effect nobody declared),
//! it runs the loop — trains B and C, traces B's residual to the effect F lacks, adds it as
//! physics, retrains, and prints what it found with the error before and after — then exports
//! the final C to int8 and runs the test days through the firmware under QEMU. Where QEMU or the
//! firmware's Rust target is missing, it says so before the loop and does everything else (a
//! fresh machine still runs the main job; `scripts/test-all.sh` installs both).

use crate::analysis::AnalysisOptions;
use crate::closed_loop::{self, LoopOptions, LoopReport};
use crate::data::records;
use crate::data::{self, SplitName};
use crate::eval::evaluate_splits;
use crate::gnss::plausibility::plausibility;
use crate::gnss::{synth, GnssProblem};
use crate::model::OwnedModel;
use crate::problem::Problem;
use crate::report::loop_report::rounds_table;
use anyhow::{Context, Result};
use magic_core::mogi::PARAM_NAMES;
use magic_core::Model;
use serde_json::json;
use std::path::Path;

/// The effect hidden in the built-in synthetic record: a daily translation of the whole network
/// (the effect the paper suspected in the measured data), not declared to the model.
pub const BUILT_IN: synth::Scenario = synth::Scenario::CommonMode;

/// Most effects the demo's loop adds.
pub const DEMO_ROUNDS: usize = 2;

/// Largest absolute difference per parameter between two sets of result lines.
pub fn max_param_diff(a: &[String], b: &[String], n_params: usize) -> Vec<f64> {
    let mut d = vec![0f64; n_params];
    let parse = |s: &str| -> Vec<f64> {
        s.split(',')
            .take(n_params)
            .filter_map(|v| v.parse().ok())
            .collect()
    };
    for (x, y) in a.iter().zip(b) {
        let (px, py) = (parse(x), parse(y));
        if px.len() == n_params && py.len() == n_params {
            for j in 0..n_params {
                d[j] = d[j].max((px[j] - py[j]).abs());
            }
        }
    }
    d
}

/// The data: measured when found, else the built-in synthetic record.
fn data(data_dir: Option<&Path>, seed: u64) -> Result<GnssProblem> {
    match data::locate(data_dir, "gnss") {
        Some(d) => GnssProblem::read(&d),
        None => {
            eprintln!(
                "no GNSS data found (--data-dir, $MAGIC_DATA, ../shared/data): using the built-in synthetic record, with an effect the model is not told about ({})",
                BUILT_IN.name()
            );
            Ok(synth::generate(BUILT_IN, seed).problem)
        }
    }
}

/// Prints what the loop found and the error before and after.
fn print_loop(l: &LoopReport) {
    println!("\nThe loop (MSE in standardised units; paper Table 4: A 0.632, B 0.810, C 0.711)\n");
    print!("{}", rounds_table(l));
    let (first, last) = (l.first(), l.last_kept());
    let added = l.added();
    println!(
        "\nFound and added to F: {}. B (encoder + physics, no black box) test MSE {:.4} → {:.4}; C {:.4} → {:.4}. Stopped: {}.",
        if added.is_empty() { "nothing".to_string() } else { added.join(", ") },
        first.b.mse[2],
        last.b.mse[2],
        first.c.mse[2],
        last.c.mse[2],
        l.stop
    );
    for r in l.rounds.iter().filter(|r| r.kept) {
        if let Some(c) = &r.added {
            for u in &c.uncertainty {
                println!("  {} {} = {:.3} ± {:.3}", c.family, u.name, u.value, u.sd);
            }
        }
    }
}

/// Runs the main job.
pub fn run(
    data_dir: Option<&Path>,
    seed: u64,
    epochs: usize,
    out: &Path,
    qemu: bool,
) -> Result<()> {
    let p = data(data_dir, seed)?;
    // Said before minutes of training, not after them.
    let firmware = if qemu {
        crate::firmware::qemu::ensure_toolchain().map_err(|e| {
            let why = format!("{e:#}");
            eprintln!("note: the firmware step will be skipped: {why} (`--no-qemu` skips it without this note)");
            why
        })
    } else {
        Err("--no-qemu".to_string())
    };
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let d = &p.data;
    eprintln!(
        "data: {} ({} / {} / {} days)",
        d.source,
        d.train.len(),
        d.valid.len(),
        d.test.len()
    );
    let opts = LoopOptions {
        seed,
        train: p.recipe().with(epochs, false),
        max_rounds: DEMO_ROUNDS,
        baseline: false,
        analysis: AnalysisOptions::default(),
    };
    let dir = out.join("loop");
    let l = closed_loop::run(&p, &opts, &dir)?;
    print_loop(&l);

    // The final C (the last F kept) to int8, against its f32 self on the test days.
    let k = l.last_kept().round;
    let fbytes = std::fs::read(dir.join(format!("round{k}_C.magic")))?;
    let fm = Model::decode(&fbytes)?;
    let q = OwnedModel::from_model(&fm).quantize_int8_at(&d.train.x, &d.train.days())?;
    let qbytes = q.encode()?;
    let qpath = out.join("mogi_C_int8.magic");
    std::fs::write(&qpath, &qbytes)?;
    let qm = Model::decode(&qbytes)?;
    let (ef, eq) = (evaluate_splits(&fm, d)?, evaluate_splits(&qm, d)?);
    let rows = records::split_rows(d, SplitName::Test);
    let (f_lines, q_lines) = (
        records::invert_rows(&fm, &rows),
        records::invert_rows(&qm, &rows),
    );
    let quant_diff = max_param_diff(&f_lines, &q_lines, 4);
    records::write_results(&out.join("test_inversions.csv"), &qm, &rows, &q_lines)?;
    println!(
        "\nC of round {k} to int8 for the board: test MSE {:.4} (f32 {:.4}); largest parameter difference: {}",
        eq[2].mse,
        ef[2].mse,
        PARAM_NAMES
            .iter()
            .zip(&quant_diff)
            .map(|(n, v)| format!("{n} {v:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let p = plausibility(&qm, d, SplitName::Test)?;
    println!(
        "its source on the test period: peak ΔV {}·10⁶ m³ at depth {} km ({}; ± the Laplace sd of that day, raw); {:.0} % of test days with depth < 10 km and |ΔV| < 5·10⁶ m³",
        p.peak_dv_text(),
        p.peak_depth_text(),
        crate::gnss::families::iso_date(p.peak_day),
        100.0 * p.share
    );
    let mut summary = json!({
        "data": d.source,
        "loop": l,
        "int8": {"round": k, "test_mse": eq[2].mse, "f32_test_mse": ef[2].mse, "max_param_diff": quant_diff},
        "plausibility": {"peak_dv": p.peak_dv, "peak_dv_sd": p.peak_dv_sd, "peak_depth": p.peak_depth,
            "peak_depth_sd": p.peak_depth_sd, "peak_day": p.peak_day, "plausible_share": p.share},
    });
    match &firmware {
        Ok(()) => {
            summary["firmware"] = crate::firmware::run_test_days(&qpath, &qm, &rows, &q_lines)?;
        }
        Err(why) => {
            println!("firmware: not run ({why})");
            summary["firmware"] = json!({ "skipped": why });
        }
    }
    std::fs::write(
        out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    println!("\nmodels, reports and results in {}", out.display());
    Ok(())
}
