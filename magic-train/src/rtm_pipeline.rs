//! The forest-spectra inversion end to end: the S2 data and INFORM tables, training of the
//! paper's variants A, B, C and the regressor baseline D, evaluation through the core's
//! `invert`, the paper's Table 3 over seeds, and retrieved LAI against the SNAP LAI.

use crate::data::gnss::Split;
use crate::data::rtm_tables::{PackedRows, RtmTables, S2_DATA_BANDS};
use crate::data::s2::{Extract, S2Data, S2Split};
use crate::eval::{evaluate, EvalResult};
use crate::export::{OwnedEffect, OwnedModel};
use crate::nets::{mse, to_tensor, Net};
use crate::physics::Physics;
use crate::pipeline::residual_threshold;
use crate::reproduce::mean_std;
use crate::rtm_physics::{paper_fixed, RtmPhysics};
use crate::train::{train, Rows, TrainConfig, TrainLog};
use anyhow::{anyhow, bail, Result};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use indicatif::{ProgressBar, ProgressStyle};
use magic_core::rtm::{Fixed, Geometry, LEARNED_BOUNDS, N_LEARNED};
use magic_core::{invert, Model, Variant, Workspace};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// The paper's RTM models: the three autoencoders and the regressor baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RtmVariant {
    /// Plain autoencoder.
    A,
    /// Encoder + INFORM.
    B,
    /// Encoder + INFORM + correction 11-44-11.
    C,
    /// Regressor trained on INFORM simulations, applied to the real spectra (exported as a
    /// variant-B model file: encoder + INFORM).
    D,
}

impl RtmVariant {
    /// Parses `A`, `B`, `C` or `D`.
    pub fn parse(s: &str) -> Result<RtmVariant> {
        Ok(match s {
            "A" | "a" => RtmVariant::A,
            "B" | "b" => RtmVariant::B,
            "C" | "c" => RtmVariant::C,
            "D" | "d" => RtmVariant::D,
            _ => bail!("unknown RTM variant `{s}` (expected A, B, C or D)"),
        })
    }
}

/// Paper Table 3 (train, valid, test; D: test only).
pub const PAPER_TABLE3: [(RtmVariant, [f64; 3]); 4] = [
    (RtmVariant::A, [0.0193, 0.0219, 0.0191]),
    (RtmVariant::B, [0.0875, 0.0833, 0.0856]),
    (RtmVariant::C, [0.0210, 0.0235, 0.0217]),
    (RtmVariant::D, [f64::NAN, f64::NAN, 0.6676]),
];

/// Physics-only test MSE of the paper's released C model (`pretrained_rtm_c_test_outputs.csv`).
pub const PAPER_C_PHYSICS_ONLY: f64 = 1.04;

/// The representative site of the S2 data (its README: 47.5° N, 14.5° E puts the sun within about
/// 2° of each site's own) and the overpass time (10:30 local mean solar time, descending: about
/// 10:00 UTC over Austria).
pub const S2_SITE: [f32; 2] = [47.5, 14.5];
/// Overpass time of the S2 data (hours UTC).
pub const S2_OVERPASS_UTC: f32 = 10.0;

/// The illumination effect for the S2 data: each spectrum's sun at [`S2_SITE`] and
/// [`S2_OVERPASS_UTC`] on its date; nadir view (the view azimuth then does not matter).
pub fn s2_illumination() -> OwnedEffect {
    OwnedEffect::Illumination {
        lat_deg: S2_SITE[0],
        lon_deg: S2_SITE[1],
        utc_hours: S2_OVERPASS_UTC,
        view_azimuth_deg: 0.0,
    }
}

/// An RTM effect by family name (`illumination`).
pub fn rtm_effect(name: &str) -> Result<OwnedEffect> {
    match name {
        "illumination" => Ok(s2_illumination()),
        other => bail!("unknown RTM effect `{other}` (expected illumination)"),
    }
}

/// Everything an RTM job needs: the spectra, the tables' rows for the 11 bands, fixed inputs,
/// geometry and declared effects.
pub struct RtmSetup {
    /// The S2 splits.
    pub data: S2Data,
    /// The tables' rows for the observed bands (f64).
    pub rows: PackedRows,
    /// Fixed inputs.
    pub fixed: Fixed,
    /// Geometry mode.
    pub geometry: Geometry,
    /// Declared effects (illumination).
    pub effects: Vec<OwnedEffect>,
}

impl RtmSetup {
    /// Reads the S2 folder and the tables folder; the paper's fixed inputs.
    pub fn read(data_dir: &Path, tables_dir: &Path, geometry: Geometry) -> Result<RtmSetup> {
        let data = S2Data::read(data_dir)?;
        let tables = RtmTables::read(tables_dir)?;
        let rows = tables.pack(&S2_DATA_BANDS)?;
        Ok(RtmSetup {
            data,
            rows,
            fixed: paper_fixed(),
            geometry,
            effects: vec![],
        })
    }

    /// The forward model for training.
    pub fn physics(&self) -> Result<RtmPhysics> {
        RtmPhysics::new(self.rows.clone(), self.fixed, self.geometry)
            .and_then(|p| p.with_effects(self.effects.clone()))
            .map_err(|e| anyhow!("RTM model: {e}"))
    }

    /// The learned variables' bounds (paper Table 1).
    pub fn bounds() -> Vec<[f64; 2]> {
        LEARNED_BOUNDS.to_vec()
    }
}

impl TrainConfig {
    /// The paper's S2 recipe (A.8): batches of 64 independent spectra, no smoothness term.
    pub fn s2() -> Self {
        TrainConfig {
            batch_seqs: 64,
            seq_len: 1,
            lambda: 0.0,
            ..TrainConfig::gnss()
        }
    }
}

/// Trains `variant` on `setup` (training on `train`, early stopping on `valid`), returning the
/// f32 model with its log.
pub fn train_rtm(
    setup: &RtmSetup,
    train_split: &S2Split,
    valid: &S2Split,
    variant: RtmVariant,
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    let mut rng = StdRng::seed_from_u64(seed);
    let d = &setup.data;
    if variant == RtmVariant::D && !setup.effects.is_empty() {
        bail!("the regressor D is trained on simulated spectra without dates: no effects");
    }
    let physics: Arc<dyn Physics> = Arc::new(setup.physics()?);
    let core_variant = match variant {
        RtmVariant::A => Variant::A,
        RtmVariant::B | RtmVariant::D => Variant::B,
        RtmVariant::C => Variant::C,
    };
    let net = Net::new(
        core_variant,
        d.n_obs(),
        (core_variant != Variant::A).then_some(physics.clone()),
        RtmSetup::bounds(),
        d.mean.clone(),
        d.scale.clone(),
        N_LEARNED,
        &mut rng,
    )?;
    let log = if variant == RtmVariant::D {
        train_regressor(&net, physics.as_ref(), d, cfg, &mut rng)?
    } else {
        let (td, vd) = (train_split.rows.days(), valid.rows.days());
        train(
            &net,
            Rows {
                x: &train_split.rows.x,
                days: &td,
            },
            Rows {
                x: &valid.rows.x,
                days: &vd,
            },
            cfg,
            &mut rng,
        )?
    };
    let problem = setup.rows.problem(setup.fixed, setup.geometry);
    let mut model = OwnedModel::from_net(&net, problem, setup.effects.clone())?;
    model.residual_threshold = residual_threshold(&model, &valid.rows.x, &valid.rows.days())?;
    Ok((model, log))
}

/// Number of simulated spectra for the regressor D (the paper's split sizes: 11 520 / 2 880 /
/// 3 600).
pub const D_SAMPLES: [usize; 3] = [11_520, 2_880, 3_600];

/// Simulated data: variables uniform in the bounds (as units in [0, 1]) and their standardised
/// spectra.
pub struct Simulated {
    /// Normalised variables.
    pub units: Vec<Vec<f32>>,
    /// Standardised spectra.
    pub x: Vec<Vec<f32>>,
}

/// `n` spectra simulated by `physics` from variables uniform in Table 1's bounds, standardised
/// with the real data's mean and scale.
pub fn simulate(
    physics: &dyn Physics,
    mean: &[f64],
    scale: &[f64],
    n: usize,
    rng: &mut StdRng,
) -> Result<Simulated> {
    use rayon::prelude::*;
    let units: Vec<Vec<f32>> = (0..n)
        .map(|_| (0..N_LEARNED).map(|_| rng.random::<f32>()).collect())
        .collect();
    let x = units
        .par_iter()
        .map(|u| {
            let z: Vec<f64> = u
                .iter()
                .zip(LEARNED_BOUNDS)
                .map(|(v, b)| b[0] + (b[1] - b[0]) * *v as f64)
                .collect();
            let mut y = vec![0.0; mean.len()];
            physics
                .forward(&z, f64::NAN, &mut y)
                .map_err(|e| anyhow!("simulating spectra: {e}"))?;
            Ok(y.iter()
                .enumerate()
                .map(|(c, v)| ((v - mean[c]) / scale[c]) as f32)
                .collect())
        })
        .collect::<Result<Vec<Vec<f32>>>>()?;
    Ok(Simulated { units, x })
}

/// The regressor baseline: the encoder trained to regress normalised variables from simulated
/// spectra (MSE in [0, 1] units), the paper's recipe with early stopping on simulated
/// validation spectra.
fn train_regressor(
    net: &Net,
    physics: &dyn Physics,
    d: &S2Data,
    cfg: &TrainConfig,
    rng: &mut StdRng,
) -> Result<TrainLog> {
    let tr = simulate(physics, &d.mean, &d.scale, D_SAMPLES[0], rng)?;
    let va = simulate(physics, &d.mean, &d.scale, D_SAMPLES[1], rng)?;
    let n = d.n_obs();
    let mut opt = AdamW::new(
        net.encoder.vars(),
        ParamsAdamW {
            lr: cfg.lr,
            weight_decay: cfg.weight_decay,
            ..ParamsAdamW::default()
        },
    )?;
    let bar = if cfg.progress {
        ProgressBar::new(cfg.epochs as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} epochs {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix("train D (regressor)");
    let start = Instant::now();
    let mut log = TrainLog {
        best_valid: f64::INFINITY,
        ..TrainLog::default()
    };
    let mut best = net.snapshot()?;
    let mut since = 0;
    let mut order: Vec<usize> = (0..tr.x.len()).collect();
    let eval = |s: &Simulated| -> Result<f64> {
        let rows: Vec<&[f32]> = s.x.iter().map(|r| r.as_slice()).collect();
        let us: Vec<&[f32]> = s.units.iter().map(|r| r.as_slice()).collect();
        let p = net.encoder.forward(&to_tensor(&rows, n)?)?;
        Ok(mse(&p, &to_tensor(&us, N_LEARNED)?)?.to_scalar::<f32>()? as f64)
    };
    for epoch in 1..=cfg.epochs {
        if epoch == cfg.lr_step + 1 {
            opt.set_learning_rate(cfg.lr * 0.1);
        }
        order.shuffle(rng);
        let (mut sum, mut nb) = (0.0, 0usize);
        for g in order.chunks(cfg.batch_seqs) {
            let rows: Vec<&[f32]> = g.iter().map(|&i| tr.x[i].as_slice()).collect();
            let us: Vec<&[f32]> = g.iter().map(|&i| tr.units[i].as_slice()).collect();
            let p = net.encoder.forward(&to_tensor(&rows, n)?)?;
            let loss = mse(&p, &to_tensor(&us, N_LEARNED)?)?;
            opt.backward_step(&loss)?;
            sum += loss.to_scalar::<f32>()? as f64;
            nb += 1;
        }
        let v = eval(&va)?;
        let tl = sum / nb.max(1) as f64;
        log.history.push((tl, v));
        log.epochs = epoch;
        if v < log.best_valid {
            log.best_valid = v;
            log.best_epoch = epoch;
            best = net.snapshot()?;
            since = 0;
        } else {
            since += 1;
        }
        bar.set_message(format!("loss {tl:.4} valid {v:.4}"));
        bar.inc(1);
        if since >= cfg.patience {
            break;
        }
    }
    bar.finish_and_clear();
    net.restore(&best)?;
    log.seconds = start.elapsed().as_secs_f64();
    Ok(log)
}

/// Evaluates a model file's bytes on the three splits (the paper's MSE through the core's
/// `invert`; physics-only MSE for models with F).
pub fn evaluate_splits(bytes: &[u8], data: &S2Data) -> Result<Vec<EvalResult>> {
    let m = Model::decode(bytes).map_err(|e| anyhow!("{e}"))?;
    [
        ("train", &data.train),
        ("valid", &data.valid),
        ("test", &data.test),
    ]
    .iter()
    .map(|(name, s)| evaluate_par(&m, &s.rows, name))
    .collect()
}

/// [`evaluate`] in parallel chunks (same numbers).
pub fn evaluate_par(model: &Model<'_>, split: &Split, name: &str) -> Result<EvalResult> {
    use rayon::prelude::*;
    let chunk = 512;
    let parts: Vec<EvalResult> = (0..split.len().div_ceil(chunk))
        .into_par_iter()
        .map(|k| {
            let lo = k * chunk;
            let hi = (lo + chunk).min(split.len());
            let s = Split {
                x: split.x[lo..hi].to_vec(),
                dates: split.dates[lo..hi].to_vec(),
            };
            evaluate(model, &s, name)
        })
        .collect::<Result<_>>()?;
    let n: usize = parts.iter().map(|p| p.n).sum();
    let nf = n.max(1) as f64;
    let n_obs = model.n_obs();
    let mut per = vec![0.0; n_obs];
    let mut phys = 0.0;
    for p in &parts {
        for (a, b) in per.iter_mut().zip(&p.mse_per_channel) {
            *a += b * p.n as f64 / nf;
        }
        phys += p.physics_mse.unwrap_or(0.0) * p.n as f64 / nf;
    }
    Ok(EvalResult {
        split: name.to_string(),
        n,
        mse: per.iter().sum::<f64>() / n_obs as f64,
        mse_per_channel: per,
        physics_mse: (model.variant != Variant::A).then_some(phys),
    })
}

/// The paper's released C model (`oracle/pretrained_rtm_c_weights.json`: PyTorch `Linear`
/// layers `encoder.0/2/4/6`, `correction.0/2`, standardisation and bounds) as a model file over
/// this setup's INFORM: evaluating it measures the released encoder and correction through our F.
pub fn released_c(setup: &RtmSetup, json_path: &Path) -> Result<OwnedModel> {
    use crate::export::{OwnedLayer, OwnedWeights};
    use magic_core::nn::Activation;
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
        problem: setup.rows.problem(setup.fixed, setup.geometry),
        mean: floats(&v["standardization"]["x_mean"], "x_mean")?,
        scale: floats(&v["standardization"]["x_scale"], "x_scale")?,
        bounds,
        encoder,
        decoder,
        residual_threshold: 0.0,
        effects: vec![],
    })
}

/// Table 3: every variant with every seed; prints a Markdown table and returns JSON.
pub fn table3(
    setup: &RtmSetup,
    seeds: &[u64],
    cfg: &TrainConfig,
    variants: &[RtmVariant],
) -> Result<serde_json::Value> {
    let mut rows = Vec::new();
    let d = &setup.data;
    println!(
        "| model | train | valid | test | physics-only test | paper test | epochs | s/epoch |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &(variant, paper) in PAPER_TABLE3.iter().filter(|(v, _)| variants.contains(v)) {
        let mut per: [Vec<f64>; 4] = Default::default();
        let (mut spe, mut epochs) = (Vec::new(), Vec::new());
        for &seed in seeds {
            let (model, log) = train_rtm(setup, &d.train, &d.valid, variant, cfg, seed)?;
            let r = evaluate_splits(&model.encode()?, d)?;
            for k in 0..3 {
                per[k].push(r[k].mse);
            }
            if let Some(p) = r[2].physics_mse {
                per[3].push(p);
            }
            spe.push(log.seconds_per_epoch());
            epochs.push(log.epochs);
            eprintln!(
                "{variant:?} seed {seed}: {} epochs ({:.1} s/epoch), test MSE {:.4}{}",
                log.epochs,
                log.seconds_per_epoch(),
                r[2].mse,
                r[2].physics_mse
                    .map_or(String::new(), |p| format!(", physics-only {p:.4}"))
            );
        }
        let f = crate::reproduce::mean_std_text;
        println!(
            "| {variant:?} | {} | {} | {} | {} | {:.4} | {:?} | {:.2} |",
            f(&per[0]),
            f(&per[1]),
            f(&per[2]),
            f(&per[3]),
            paper[2],
            epochs,
            mean_std(&spe).0
        );
        rows.push(json!({
            "variant": format!("{variant:?}"), "seeds": seeds, "epochs": epochs,
            "train": per[0], "valid": per[1], "test": per[2], "physics_only_test": per[3],
            "paper_test": paper[2], "seconds_per_epoch": spe,
        }));
    }
    println!("(paper's released C: physics-only test MSE {PAPER_C_PHYSICS_ONLY})");
    Ok(
        json!({ "data": d.source, "max_epochs": cfg.epochs, "rows": rows, "paper_c_physics_only": PAPER_C_PHYSICS_ONLY }),
    )
}

/// Spearman rank correlation (average ranks for ties); NaN with fewer than 3 pairs.
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    fn ranks(v: &[f64]) -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        let mut i = 0;
        while i < idx.len() {
            let mut j = i;
            while j + 1 < idx.len() && v[idx[j + 1]] == v[idx[i]] {
                j += 1;
            }
            for k in i..=j {
                r[idx[k]] = (i + j) as f64 / 2.0;
            }
            i = j + 1;
        }
        r
    }
    if a.len() < 3 {
        return f64::NAN;
    }
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    sab / (saa * sbb).sqrt()
}

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

/// Retrieved LAI (model `bytes`, variant B/C/D) on `splits` against the SNAP LAI of the
/// extract: spectra are matched to extract rows by `sample_id` (0-based row) and `date`, the
/// match is checked on the bands and the species, and rank correlations are computed per
/// species and date (groups with at least 10 spectra).
pub fn lai_vs_snap(
    bytes: &[u8],
    data: &S2Data,
    splits: &[&S2Split],
    extract: &Extract,
) -> Result<LaiMatch> {
    let m = Model::decode(bytes).map_err(|e| anyhow!("{e}"))?;
    if m.variant == Variant::A {
        bail!("variant A has no physical variables: use a B, C or D model");
    }
    let mut ws = Workspace::default();
    let mut pairs: Vec<(String, String, f64, f64)> = Vec::new();
    let (mut spectra, mut bands_agree, mut class_agree) = (0, 0, 0);
    for s in splits {
        for i in 0..s.len() {
            spectra += 1;
            let key = (s.sample_id[i], s.rows.dates[i].clone());
            let Some(&snap) = extract.lai.get(&key) else {
                continue;
            };
            if let Some(b) = extract.bands.get(&key) {
                let ok = (0..11).all(|c| {
                    let refl = s.rows.x[i][c] as f64 * data.scale[c] + data.mean[c];
                    (refl * 1e4 - b[c]).abs() <= 0.5 + 1e-3 * b[c].abs()
                });
                bands_agree += ok as usize;
            }
            if extract
                .class
                .get(key.0 as usize)
                .is_some_and(|c| *c == s.class[i])
            {
                class_agree += 1;
            }
            let obs: Vec<f32> = (0..11)
                .map(|c| (s.rows.x[i][c] as f64 * data.scale[c] + data.mean[c]) as f32)
                .collect();
            let inv = invert::<f64>(&m, &obs, &mut ws).map_err(|e| anyhow!("{e}"))?;
            pairs.push((s.class[i].clone(), key.1, inv.params[4], snap / 1000.0));
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
