//! The paper's released C model of the forest spectra (`oracle/pretrained_rtm_c_weights.json`)
//! as a model file over our INFORM: evaluating it measures the released encoder and correction
//! through our F.

use super::RtmProblem;
use crate::model::{OwnedLayer, OwnedModel, OwnedWeights};
use crate::problem::Problem;
use anyhow::{anyhow, bail, Result};
use magic_core::nn::Activation;
use magic_core::Variant;
use std::path::Path;

/// The paper's released C model (`oracle/pretrained_rtm_c_weights.json`: PyTorch `Linear`
/// layers `encoder.0/2/4/6`, `correction.0/2`, standardisation and bounds) as a model file over
/// this setup's INFORM: evaluating it measures the released encoder and correction through our F.
pub fn released_c(p: &RtmProblem, json_path: &Path) -> Result<OwnedModel> {
    let text = std::fs::read_to_string(json_path)
        .map_err(|e| anyhow!("{}: cannot read: {e}", json_path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| anyhow!("{}: not valid JSON: {e}", json_path.display()))?;
    let floats = |x: &serde_json::Value, what: &str| -> Result<Vec<f32>> {
        let mut out = Vec::new();
        let mut stack = vec![x];
        while let Some(x) = stack.pop() {
            match x {
                serde_json::Value::Array(a) => stack.extend(a.iter().rev()),
                serde_json::Value::Number(n) => out.push(n.as_f64().unwrap_or(f64::NAN) as f32),
                _ => bail!("{}: `{what}`: expected numbers", json_path.display()),
            }
        }
        Ok(out)
    };
    let layer = |name: &str, act: Activation| -> Result<OwnedLayer> {
        let w = &v["layers"][format!("{name}.weight")];
        let b = &v["layers"][format!("{name}.bias")];
        let shape = floats(&w["shape"], name)?;
        if shape.len() != 2 {
            bail!(
                "{}: `{name}.weight`: expected a 2-D shape",
                json_path.display()
            );
        }
        let (rows, cols) = (shape[0] as usize, shape[1] as usize);
        let (w, b) = (floats(&w["values"], name)?, floats(&b["values"], name)?);
        if w.len() != rows * cols || b.len() != rows {
            bail!(
                "{}: `{name}`: sizes do not match its shape",
                json_path.display()
            );
        }
        Ok(OwnedLayer {
            rows,
            cols,
            act,
            weights: OwnedWeights::F32 { w, b },
        })
    };
    let encoder = vec![
        layer("encoder.0", Activation::Relu)?,
        layer("encoder.2", Activation::Relu)?,
        layer("encoder.4", Activation::Relu)?,
        layer("encoder.6", Activation::Sigmoid)?,
    ];
    let decoder = vec![
        layer("correction.0", Activation::Relu)?,
        layer("correction.2", Activation::Linear)?,
    ];
    let names = ["N", "cab", "cw", "cm", "LAI", "LAIu", "fc"];
    let bounds = names
        .iter()
        .map(|n| {
            let r = &v["latent_ranges"][n];
            match (r["min"].as_f64(), r["max"].as_f64()) {
                (Some(lo), Some(hi)) => Ok([lo as f32, hi as f32]),
                _ => Err(anyhow!(
                    "{}: latent_ranges.{n} missing",
                    json_path.display()
                )),
            }
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(OwnedModel {
        variant: Variant::C,
        problem: p.spec()?,
        mean: floats(&v["standardization"]["x_mean"], "x_mean")?,
        scale: floats(&v["standardization"]["x_scale"], "x_scale")?,
        bounds,
        encoder,
        decoder,
        residual_threshold: 0.0,
        effects: vec![],
    })
}
