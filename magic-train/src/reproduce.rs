//! `magic reproduce mogi`: the paper's Table 4 — A, B and C trained with several seeds, the MSE
//! on each split as mean ± standard deviation, next to the paper's numbers.

use crate::data::gnss::GnssData;
use crate::eval::evaluate;
use crate::pipeline::train_mogi;
use crate::train::TrainConfig;
use anyhow::{anyhow, Result};
use magic_core::{Model, Variant};
use serde_json::json;

/// Paper Table 4 (train, valid, test).
pub const PAPER_TABLE4: [(Variant, [f64; 3]); 3] = [
    (Variant::A, [0.4389, 0.9119, 0.6324]),
    (Variant::B, [0.6998, 0.9721, 0.8095]),
    (Variant::C, [0.4803, 0.9338, 0.7110]),
];

/// Mean and (sample) standard deviation.
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, var.sqrt())
}

/// `mean ± std` with four decimals, or `-` for no values.
pub fn mean_std_text(v: &[f64]) -> String {
    if v.is_empty() {
        "-".to_string()
    } else {
        let (m, s) = mean_std(v);
        format!("{m:.4} ± {s:.4}")
    }
}

/// Trains every variant with every seed; prints a Markdown table and returns the numbers as JSON.
pub fn table4(data: &GnssData, seeds: &[u64], cfg: &TrainConfig) -> Result<serde_json::Value> {
    let mut rows = Vec::new();
    println!("| model | train | valid | test | physics-only test | paper test | s/epoch |");
    println!("|---|---|---|---|---|---|---|");
    for (variant, paper) in PAPER_TABLE4 {
        let mut per: [Vec<f64>; 4] = Default::default();
        let mut spe = Vec::new();
        for &seed in seeds {
            let (model, log) = train_mogi(data, variant, cfg, seed)?;
            let bytes = model.encode()?;
            let m = Model::decode(&bytes).map_err(|e| anyhow!("{e}"))?;
            for (k, (split, name)) in [
                (&data.train, "train"),
                (&data.valid, "valid"),
                (&data.test, "test"),
            ]
            .iter()
            .enumerate()
            {
                let r = evaluate(&m, split, name)?;
                per[k].push(r.mse);
                if k == 2 {
                    if let Some(p) = r.physics_mse {
                        per[3].push(p);
                    }
                }
            }
            spe.push(log.seconds_per_epoch());
        }
        let f = mean_std_text;
        println!(
            "| {variant:?} | {} | {} | {} | {} | {:.4} | {:.3} |",
            f(&per[0]),
            f(&per[1]),
            f(&per[2]),
            f(&per[3]),
            paper[2],
            mean_std(&spe).0
        );
        rows.push(json!({
            "variant": format!("{variant:?}"), "seeds": seeds,
            "train": per[0], "valid": per[1], "test": per[2], "physics_only_test": per[3],
            "paper": {"train": paper[0], "valid": paper[1], "test": paper[2]},
            "seconds_per_epoch": spe,
        }));
    }
    Ok(json!({ "data": data.source, "rows": rows }))
}
