//! `magic reproduce`: a table of the paper for any problem — each model kind trained with several
//! seeds, the MSE on each split as mean ± standard deviation, next to the paper's numbers
//! (Table 4 for the volcano, Table 3 for the forest spectra).

use crate::eval::evaluate_splits;
use crate::numerics::{mean_std, mean_std_text};
use crate::problem::Problem;
use crate::train::{train_model, ModelKind, TrainConfig};
use anyhow::Result;
use magic_core::Model;
use serde_json::json;

/// Trains every kind in `kinds` (in the order of the paper's table) with every seed; prints a
/// Markdown table and returns the numbers as JSON.
pub fn table<P: Problem + ?Sized>(
    problem: &P,
    kinds: &[ModelKind],
    seeds: &[u64],
    cfg: &TrainConfig,
) -> Result<serde_json::Value> {
    let mut rows = Vec::new();
    println!(
        "| model | train | valid | test | physics-only test | paper test | epochs | s/epoch |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (kind, paper) in problem
        .paper_table()
        .into_iter()
        .filter(|(k, _)| kinds.contains(k))
    {
        let mut per: [Vec<f64>; 4] = Default::default();
        let (mut spe, mut epochs) = (Vec::new(), Vec::new());
        for &seed in seeds {
            let (model, log) = train_model(problem, kind, &[], cfg, seed)?;
            let bytes = model.encode()?;
            let r = evaluate_splits(&Model::decode(&bytes)?, problem.data())?;
            for k in 0..3 {
                per[k].push(r[k].mse);
            }
            if let Some(p) = r[2].physics_mse {
                per[3].push(p);
            }
            spe.push(log.seconds_per_epoch());
            epochs.push(log.epochs);
            eprintln!(
                "{kind:?} seed {seed}: {} epochs ({:.2} s/epoch), test MSE {:.4}{}",
                log.epochs,
                log.seconds_per_epoch(),
                r[2].mse,
                r[2].physics_mse
                    .map_or(String::new(), |p| format!(", physics-only {p:.4}"))
            );
        }
        let f = mean_std_text;
        println!(
            "| {kind:?} | {} | {} | {} | {} | {:.4} | {:?} | {:.3} |",
            f(&per[0]),
            f(&per[1]),
            f(&per[2]),
            f(&per[3]),
            paper[2],
            epochs,
            mean_std(&spe).0
        );
        rows.push(json!({
            "kind": format!("{kind:?}"), "seeds": seeds, "epochs": epochs,
            "train": per[0], "valid": per[1], "test": per[2], "physics_only_test": per[3],
            "paper": {"train": paper[0], "valid": paper[1], "test": paper[2]},
            "seconds_per_epoch": spe,
        }));
    }
    Ok(
        json!({ "problem": problem.name(), "data": problem.data().source, "max_epochs": cfg.epochs, "rows": rows }),
    )
}
