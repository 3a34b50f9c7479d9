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
use crate::gnss::plausibility::{plausibility, Plausibility};
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

/// The built-in record's main source on its test days, as injected: what the inferred source
/// is held to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueSource {
    /// The largest ΔV of the test days (10⁶ m³).
    pub peak_dv: f64,
    /// The source's depth (km).
    pub depth_km: f64,
    /// The day of that peak (days since 1970-01-01).
    pub peak_day: f64,
}

/// The main source's largest ΔV over the test days of a synthetic record (`dv`: the record's
/// daily ΔV in time order, from its first day), or `None` where a test day lies outside it.
pub fn true_source(s: &synth::Synthetic) -> Option<TrueSource> {
    let d = &s.problem.data;
    let first = [&d.train, &d.valid, &d.test]
        .iter()
        .flat_map(|x| x.days())
        .fold(f64::INFINITY, f64::min);
    let depth_km = s.truth["source"]["depth_km"].as_f64()?;
    let mut best: Option<TrueSource> = None;
    for t in d.test.days() {
        let i = (t - first).round();
        let dv = *s.dv.get(usize::try_from(i as i64).ok()?)?;
        if best.is_none_or(|b| dv > b.peak_dv) {
            best = Some(TrueSource {
                peak_dv: dv,
                depth_km,
                peak_day: t,
            });
        }
    }
    best
}

/// The data: measured when found, else the built-in synthetic record with its source's truth.
fn data(data_dir: Option<&Path>, seed: u64) -> Result<(GnssProblem, Option<TrueSource>)> {
    match data::locate(data_dir, "gnss") {
        Some(d) => Ok((GnssProblem::read(&d)?, None)),
        None => {
            eprintln!(
                "no GNSS data found (--data-dir, $MAGIC_DATA, ../shared/data): using the built-in synthetic record, with an effect the model is not told about ({})",
                BUILT_IN.name()
            );
            let s = synth::generate(BUILT_IN, seed);
            let truth = true_source(&s);
            Ok((s.problem, truth))
        }
    }
}

/// A split's peak source as a line: `peak ΔV v ± sd·10⁶ m³ at depth d ± sd km (date)`.
fn source_line(p: &Plausibility) -> String {
    format!(
        "peak ΔV {}·10⁶ m³ at depth {} km ({})",
        p.peak_dv_text(),
        p.peak_depth_text(),
        crate::gnss::families::iso_date(p.peak_day)
    )
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
    let (p, truth) = data(data_dir, seed)?;
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
        "its source on the test period: {} (± the Laplace sd of that day, raw); {:.0} % of test days with depth < 10 km and |ΔV| < 5·10⁶ m³",
        source_line(&p),
        100.0 * p.share
    );
    let b_bytes = std::fs::read(dir.join(format!("round{k}_B.magic")))?;
    let pb = plausibility(&Model::decode(&b_bytes)?, d, SplitName::Test)?;
    println!(
        "B's (no black box): {}; {:.0} % of test days so",
        source_line(&pb),
        100.0 * pb.share
    );
    if let Some(t) = truth {
        println!(
            "the built-in record's truth: peak ΔV {:.2}·10⁶ m³ at depth {:.1} km ({})",
            t.peak_dv,
            t.depth_km,
            crate::gnss::families::iso_date(t.peak_day)
        );
    }
    let mut summary = json!({
        "data": d.source,
        "loop": l,
        "int8": {"round": k, "test_mse": eq[2].mse, "f32_test_mse": ef[2].mse, "max_param_diff": quant_diff},
        "plausibility": plausibility_json(&p),
        "plausibility_b": plausibility_json(&pb),
    });
    if let Some(t) = truth {
        summary["truth"] =
            json!({"peak_dv": t.peak_dv, "depth_km": t.depth_km, "peak_day": t.peak_day});
    }
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

/// A split's peak source and plausible share, for `summary.json`.
fn plausibility_json(p: &Plausibility) -> serde_json::Value {
    json!({"peak_dv": p.peak_dv, "peak_dv_sd": p.peak_dv_sd, "peak_depth": p.peak_depth,
        "peak_depth_sd": p.peak_depth_sd, "peak_day": p.peak_day, "plausible_share": p.share})
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in record's test days are its first: the truth is the largest ΔV among the
    /// record's first test-length days, at the injected depth, on the day it happens.
    #[test]
    fn the_true_source_is_the_largest_test_day_volume_at_the_injected_depth() {
        let s = synth::generate(BUILT_IN, 0);
        let t = true_source(&s).expect("the built-in record holds its test days");
        let d = &s.problem.data;
        let n = d.test.len();
        let (i, peak) = s.dv[..n]
            .iter()
            .copied()
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |b, x| if x.1 > b.1 { x } else { b });
        assert_eq!(t.peak_dv, peak);
        assert_eq!(t.peak_day, d.test.days()[i]);
        assert_eq!(t.depth_km, 7.0);
        // The built-in record's first episode: 5·10⁶ m³, reached 450 days in.
        assert!((t.peak_dv - 5.0).abs() < 1e-6, "{t:?}");
        assert_eq!(crate::gnss::families::iso_date(t.peak_day), "2007-03-27");
    }
}
