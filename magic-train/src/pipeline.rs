//! End-to-end jobs shared by the CLI and the tests: train a Mogi model of a variant on a GNSS
//! dataset and turn it into a model file.

use crate::data::gnss::GnssData;
use crate::data::rtm_tables::intern;
use crate::export::{OwnedEffect, OwnedModel};
use crate::nets::Net;
use crate::physics::{MogiPhysics, Physics};
use crate::train::{train, Rows, TrainConfig, TrainLog};
use anyhow::{anyhow, Result};
use magic_core::model_file::{Names, Problem};
use magic_core::mogi::{Station, Stations, PAPER_BOUNDS, STATION_BYTES};
use magic_core::{invert_at, Model, Variant, Workspace};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::sync::Arc;

/// The Mogi problem description of a network (stations and names interned: `'static` bytes in
/// the layout of the model file).
pub fn mogi_problem(names: &[String], stations: &[Station]) -> Result<Problem<'static>> {
    let max = magic_core::model_file::MAX_STATIONS;
    if stations.len() > max || names.len() > max {
        return Err(anyhow!("more stations than the core supports ({max})"));
    }
    if names.len() != stations.len() {
        return Err(anyhow!(
            "{} station names for {} stations",
            names.len(),
            stations.len()
        ));
    }
    for name in names {
        if name.is_empty() || name.len() > magic_core::model_file::MAX_NAME || name.contains(',') {
            return Err(anyhow!(
                "station name `{name}` is empty, longer than 8 bytes or contains a comma"
            ));
        }
    }
    let mut bytes = vec![0u8; STATION_BYTES * stations.len()];
    Stations::encode(stations, &mut bytes).map_err(|e| anyhow!("{e}"))?;
    let joined = intern(names.join(",").into_bytes());
    let names = std::str::from_utf8(joined).map_err(|e| anyhow!("station names: {e}"))?;
    Ok(Problem::Mogi {
        stations: Stations(intern(bytes)),
        names: Names(names),
    })
}

/// Trains a Mogi model of `variant` on `data` and returns it as an f32 model with its log.
pub fn train_mogi(
    data: &GnssData,
    variant: Variant,
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    train_mogi_with(data, variant, &[], cfg, seed)
}

/// A latent effect by family name, for a network (`common_mode`, `elevation`).
pub fn latent_effect(name: &str, data: &GnssData) -> Result<OwnedEffect> {
    match name {
        "common_mode" => Ok(OwnedEffect::CommonMode),
        "elevation" => {
            let z = data.stations.iter().map(|s| s.z_km).sum::<f64>() / data.stations.len().max(1) as f64;
            Ok(OwnedEffect::Elevation { z_ref_km: z as f32 })
        }
        other => anyhow::bail!("unknown latent effect `{other}` (expected common_mode or elevation; fitted effects come from `magic loop`)"),
    }
}

/// Latent-variable bounds of an effect.
pub fn effect_bounds(e: &OwnedEffect) -> Vec<[f64; 2]> {
    match e {
        OwnedEffect::CommonMode => vec![[-30.0, 30.0]; 3],
        OwnedEffect::Elevation { .. } => vec![[-200.0, 200.0]],
        OwnedEffect::SecondSource { .. } => vec![[-10.0, 10.0]],
        _ => vec![],
    }
}

/// [`train_mogi`] with declared effects added to F.
pub fn train_mogi_with(
    data: &GnssData,
    variant: Variant,
    effects: &[OwnedEffect],
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    let mut rng = StdRng::seed_from_u64(seed);
    let physics: Arc<dyn Physics> = Arc::new(MogiPhysics {
        stations: data.stations.clone(),
        effects: effects.to_vec(),
    });
    let mut bounds: Vec<[f64; 2]> = PAPER_BOUNDS.to_vec();
    for e in effects {
        bounds.extend(effect_bounds(e));
    }
    let net = Net::new(
        variant,
        data.n_obs(),
        (variant != Variant::A).then_some(physics),
        bounds,
        data.mean.clone(),
        data.scale.clone(),
        4,
        &mut rng,
    )?;
    let (td, vd) = (data.train.days(), data.valid.days());
    let log = train(
        &net,
        Rows {
            x: &data.train.x,
            days: &td,
        },
        Rows {
            x: &data.valid.x,
            days: &vd,
        },
        cfg,
        &mut rng,
    )?;
    let mut model = OwnedModel::from_net(
        &net,
        mogi_problem(&data.names, &data.stations)?,
        effects.to_vec(),
    )?;
    model.residual_threshold = residual_threshold(&model, &data.valid.x, &vd)?;
    Ok((model, log))
}

/// The 99th percentile of the standardised residual RMS on `x`: inversions above it are flagged.
pub fn residual_threshold(model: &OwnedModel, x: &[Vec<f32>], days: &[f64]) -> Result<f32> {
    let bytes = model.encode()?;
    let m = Model::decode(&bytes).map_err(|e| anyhow!("{e}"))?;
    let mut ws = Workspace::default();
    let mut r = Vec::with_capacity(x.len());
    for (row, t) in x.iter().zip(days) {
        let obs: Vec<f32> = row
            .iter()
            .enumerate()
            .map(|(c, v)| v * model.scale[c] + model.mean[c])
            .collect();
        r.push(
            invert_at::<f64>(&m, &obs, *t, &mut ws)
                .map_err(|e| anyhow!("{e}"))?
                .residual_rms_std,
        );
    }
    if r.is_empty() {
        return Ok(0.0);
    }
    r.sort_by(f64::total_cmp);
    Ok(r[((r.len() - 1) as f64 * 0.99) as usize] as f32)
}
