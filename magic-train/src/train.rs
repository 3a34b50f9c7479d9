//! Training, written once for every problem and model kind: the paper's recipe (A.7, A.8) —
//! AdamW (lr 1e-3, weight decay 1e-4), learning rate ×0.1 after 50 epochs, at most 100 epochs,
//! early stop after 10 epochs without validation gain (the best weights are kept) — around a
//! pluggable [`Objective`]:
//!
//! * [`Reconstruction`] (A, B, C): the MSE of the reconstruction, plus for sequential data (GNSS:
//!   batches of 12 sequences × 5 consecutive days) the smoothness term of eq. 19 on F's output;
//! * [`Regression`] (D, the paper's regressor baseline): the encoder regresses the normalised
//!   variables of spectra simulated by F.
//!
//! [`train_model`] builds the network of a model kind for a [`Problem`], trains it and returns
//! the f32 model file. The paper used PyTorch's Adam with (coupled) L2 weight decay; candle offers
//! AdamW (decoupled decay), which is what is used here.

use crate::data::Dataset;
use crate::model::{OwnedEffect, OwnedModel};
use crate::nets::{days_tensor, mse, smoothness, to_tensor, Net};
use crate::physics::Physics;
use crate::problem::Problem;
use anyhow::{anyhow, bail, Result};
use candle_core::{Tensor, Var};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use indicatif::{ProgressBar, ProgressStyle};
use magic_core::Variant;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use std::time::Instant;

/// The model kinds of the paper: three autoencoders and the regressor baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize)]
pub enum ModelKind {
    /// Plain autoencoder (no physics).
    #[value(name = "A", alias = "a")]
    A,
    /// Encoder + F.
    #[value(name = "B", alias = "b")]
    B,
    /// Encoder + F + correction C.
    #[value(name = "C", alias = "c")]
    C,
    /// Regressor: the encoder trained on spectra simulated by F, applied to the real data
    /// (exported as a variant-B model file: encoder + F).
    #[value(name = "D", alias = "d")]
    D,
}

impl ModelKind {
    /// The model-file variant it is exported as.
    pub fn variant(self) -> Variant {
        match self {
            ModelKind::A => Variant::A,
            ModelKind::B | ModelKind::D => Variant::B,
            ModelKind::C => Variant::C,
        }
    }
}

/// Training hyperparameters.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Maximum epochs.
    pub epochs: usize,
    /// Initial learning rate.
    pub lr: f64,
    /// Weight decay.
    pub weight_decay: f64,
    /// Epoch after which the learning rate is divided by 10.
    pub lr_step: usize,
    /// Epochs without validation gain before stopping.
    pub patience: usize,
    /// Epochs early stopping does not watch: their weights are never kept and they do not count
    /// towards the patience, so a lucky early validation value cannot end a run (0: the paper's
    /// rule; the last epoch is always watched).
    pub warmup: usize,
    /// Sequences per batch.
    pub batch_seqs: usize,
    /// Consecutive rows per sequence (1 for independent samples).
    pub seq_len: usize,
    /// Weight of the smoothness term (0 disables it).
    pub lambda: f64,
    /// Reduce the smoothness term by its mean over elements instead of the sum of eq. 19.
    pub smooth_mean: bool,
    /// Show a progress bar.
    pub progress: bool,
    /// Training runs from different initialisations (the seed, then seeds derived from it); the
    /// run with the lowest validation loss is kept. 1 is the paper's single run.
    pub restarts: usize,
}

impl TrainConfig {
    /// The paper's GNSS recipe: batches of 12 sequences × 5 consecutive days, λ = 0.01, and
    /// early stopping that watches from the learning-rate step on (`warmup` 50; the paper's
    /// rule, 0, lets a lucky epoch of the noisy high-rate phase end the run: measured in the
    /// README, *Table 4*).
    pub fn gnss() -> Self {
        TrainConfig {
            epochs: 100,
            lr: 1e-3,
            weight_decay: 1e-4,
            lr_step: 50,
            patience: 10,
            warmup: 50,
            batch_seqs: 12,
            seq_len: 5,
            lambda: 0.01,
            smooth_mean: true,
            progress: true,
            restarts: 1,
        }
    }

    /// The paper's S2 recipe (A.8): batches of 64 independent spectra, no smoothness term,
    /// early stopping as the paper's (no warm-up: not measured on the forest).
    pub fn s2() -> Self {
        TrainConfig {
            warmup: 0,
            batch_seqs: 64,
            seq_len: 1,
            lambda: 0.0,
            ..TrainConfig::gnss()
        }
    }

    /// This recipe with at most `epochs` epochs and no progress bar when `quiet`.
    pub fn with(self, epochs: usize, quiet: bool) -> Self {
        TrainConfig {
            epochs,
            progress: self.progress && !quiet,
            ..self
        }
    }

    /// This recipe with early stopping watching from epoch `warmup + 1` on (`None`: the
    /// recipe's own warm-up).
    pub fn with_warmup(self, warmup: Option<usize>) -> Self {
        TrainConfig {
            warmup: warmup.unwrap_or(self.warmup),
            ..self
        }
    }

    /// This recipe with `restarts` runs (at least 1), the best on validation kept.
    pub fn with_restarts(self, restarts: usize) -> Self {
        TrainConfig {
            restarts: restarts.max(1),
            ..self
        }
    }
}

/// What a training run measured.
#[derive(Clone, Debug, Default)]
pub struct TrainLog {
    /// Epochs run.
    pub epochs: usize,
    /// Epoch (1-based) of the best validation loss.
    pub best_epoch: usize,
    /// Best validation loss (the reconstruction MSE; D: the variables' MSE on simulated data).
    pub best_valid: f64,
    /// Mean training loss and validation loss per epoch.
    pub history: Vec<(f64, f64)>,
    /// Wall-clock seconds in all (of the run kept).
    pub seconds: f64,
    /// Which of the [`TrainConfig::restarts`] runs was kept (0: the one from the seed itself).
    pub restart: usize,
    /// Best validation loss of every run.
    pub restart_valid: Vec<f64>,
}

impl TrainLog {
    /// Mean seconds per epoch.
    pub fn seconds_per_epoch(&self) -> f64 {
        self.seconds / self.epochs.max(1) as f64
    }
}

/// What a training run minimises.
pub trait Objective {
    /// Name shown on the progress bar.
    fn label(&self, net: &Net) -> String;
    /// The variables the optimiser moves.
    fn vars(&self, net: &Net) -> Vec<Var>;
    /// The units an epoch shuffles and batches (sequence starts, or samples).
    fn units(&self) -> Vec<usize>;
    /// The loss of a batch of units.
    fn loss(&self, net: &Net, units: &[usize]) -> Result<Tensor>;
    /// The early-stopping criterion (lower is better).
    fn valid(&self, net: &Net) -> Result<f64>;
}

/// Rows of standardised observations with their day numbers.
#[derive(Clone, Copy)]
pub struct Rows<'a> {
    /// Observations.
    pub x: &'a [Vec<f32>],
    /// Day numbers (NaN where unknown), one per row.
    pub days: &'a [f64],
}

/// The autoencoders' objective: reconstruction MSE (+ λ × the smoothness of F's output over
/// consecutive rows, eq. 19, when `seq_len > 1`).
pub struct Reconstruction<'a> {
    /// Training rows, in time order when `seq_len > 1`.
    pub train: Rows<'a>,
    /// Validation rows.
    pub valid: Rows<'a>,
    /// Consecutive rows per sequence.
    pub seq_len: usize,
    /// Weight of the smoothness term.
    pub lambda: f64,
    /// Smoothness averaged over its elements (else summed, as eq. 19 is printed).
    pub smooth_mean: bool,
}

/// Validation MSE of the final reconstruction (standardised units, over the observed channels),
/// in chunks of 1 024 rows.
pub fn valid_mse(net: &Net, data: Rows<'_>) -> Result<f64> {
    let n = data.x.first().map_or(0, |r| r.len());
    let mut sum = 0.0;
    // Rows' worth of observed cells (whole rows when nothing is missing).
    let mut count = 0.0;
    for (ci, chunk) in data.x.chunks(1024).enumerate() {
        let rows: Vec<&[f32]> = chunk.iter().map(|r| r.as_slice()).collect();
        let d = days_tensor(&data.days[ci * 1024..ci * 1024 + chunk.len()])?;
        let (e, cells, _) = batch_mse(net, &rows, n, &d)?;
        let weight = cells as f64 / n.max(1) as f64;
        sum += e.to_scalar::<f32>()? as f64 * weight;
        count += weight;
    }
    Ok(sum / f64::max(count, 1.0))
}

/// The reconstruction MSE of a batch of rows (standardised, NaN = missing) made on `days`, over
/// its observed cells, with the number of those cells and F's output (B, C).
///
/// A missing channel enters the encoder as 0 — the training mean, as the core fills it on the
/// first pass of an inversion — and is left out of the error: the model is never asked to
/// reproduce a value nobody observed (imputing the target would teach it to predict the mean
/// on such days). A batch without missing channels takes the plain mean over all elements.
pub fn batch_mse(
    net: &Net,
    rows: &[&[f32]],
    n: usize,
    days: &Tensor,
) -> Result<(Tensor, usize, Option<Tensor>)> {
    let missing = rows
        .iter()
        .flat_map(|r| r.iter())
        .filter(|v| v.is_nan())
        .count();
    if missing == 0 {
        let x = to_tensor(rows, n)?;
        let out = net.forward(&x, days)?;
        return Ok((mse(&out.recon, &x)?, rows.len() * n, out.physics));
    }
    let filled: Vec<Vec<f32>> = rows
        .iter()
        .map(|r| {
            r.iter()
                .map(|v| if v.is_nan() { 0.0 } else { *v })
                .collect()
        })
        .collect();
    let mask: Vec<Vec<f32>> = rows
        .iter()
        .map(|r| {
            r.iter()
                .map(|v| if v.is_nan() { 0.0 } else { 1.0 })
                .collect()
        })
        .collect();
    let x = to_tensor(&filled.iter().map(Vec::as_slice).collect::<Vec<_>>(), n)?;
    let m = to_tensor(&mask.iter().map(Vec::as_slice).collect::<Vec<_>>(), n)?;
    let out = net.forward(&x, days)?;
    let cells = rows.len() * n - missing;
    let sq = out.recon.sub(&x)?.sqr()?.mul(&m)?.sum_all()?;
    Ok(((sq / cells.max(1) as f64)?, cells, out.physics))
}

impl Objective for Reconstruction<'_> {
    fn label(&self, net: &Net) -> String {
        format!("train {:?}", net.variant)
    }
    fn vars(&self, net: &Net) -> Vec<Var> {
        net.vars()
    }
    fn units(&self) -> Vec<usize> {
        let t = self.seq_len.max(1);
        (0..self.train.x.len() / t).map(|i| i * t).collect()
    }
    fn loss(&self, net: &Net, starts: &[usize]) -> Result<Tensor> {
        let t = self.seq_len.max(1);
        let n = self.train.x.first().map_or(0, |r| r.len());
        let rows: Vec<&[f32]> = starts
            .iter()
            .flat_map(|&s| self.train.x[s..s + t].iter().map(|r| r.as_slice()))
            .collect();
        let days: Vec<f64> = starts
            .iter()
            .flat_map(|&s| self.train.days[s..s + t].iter().copied())
            .collect();
        let (mut loss, _, physics) = batch_mse(net, &rows, n, &days_tensor(&days)?)?;
        if let (Some(f), true) = (&physics, self.lambda > 0.0 && t > 1) {
            let mut s = smoothness(f, starts.len(), t)?;
            if self.smooth_mean {
                s = (s / (starts.len() * (t - 1) * n) as f64)?;
            }
            loss = (loss + (s * self.lambda)?)?;
        }
        Ok(loss)
    }
    fn valid(&self, net: &Net) -> Result<f64> {
        valid_mse(net, self.valid)
    }
}

/// Spectra simulated by F from variables uniform in their bounds.
pub struct Simulated {
    /// Normalised variables (in [0, 1]).
    pub units: Vec<Vec<f32>>,
    /// Standardised simulated observations.
    pub x: Vec<Vec<f32>>,
}

/// `n` observations simulated by `physics` from variables uniform in `bounds` (no date),
/// standardised with `mean` and `scale`.
pub fn simulate(
    physics: &dyn Physics,
    bounds: &[[f64; 2]],
    mean: &[f64],
    scale: &[f64],
    n: usize,
    rng: &mut StdRng,
) -> Result<Simulated> {
    use rayon::prelude::*;
    let units: Vec<Vec<f32>> = (0..n)
        .map(|_| (0..bounds.len()).map(|_| rng.random::<f32>()).collect())
        .collect();
    let x = units
        .par_iter()
        .map(|u| {
            let z: Vec<f64> = u
                .iter()
                .zip(bounds)
                .map(|(v, b)| b[0] + (b[1] - b[0]) * *v as f64)
                .collect();
            let mut y = vec![0.0; mean.len()];
            physics
                .forward(&z, f64::NAN, &mut y)
                .map_err(|e| anyhow!("simulating observations: {e}"))?;
            Ok(y.iter()
                .enumerate()
                .map(|(c, v)| ((v - mean[c]) / scale[c]) as f32)
                .collect())
        })
        .collect::<Result<Vec<Vec<f32>>>>()?;
    Ok(Simulated { units, x })
}

/// The regressor's objective: the encoder's outputs against the normalised variables of
/// simulated observations (MSE in [0, 1] units), early-stopping on simulated validation data.
pub struct Regression {
    /// Simulated training data.
    pub train: Simulated,
    /// Simulated validation data.
    pub valid: Simulated,
}

impl Regression {
    fn batch_loss(net: &Net, x: &[&[f32]], u: &[&[f32]]) -> Result<Tensor> {
        let n = x.first().map_or(0, |r| r.len());
        let nu = u.first().map_or(0, |r| r.len());
        let p = net.encoder.forward(&to_tensor(x, n)?)?;
        Ok(mse(&p, &to_tensor(u, nu)?)?)
    }
}

impl Objective for Regression {
    fn label(&self, _net: &Net) -> String {
        "train D (regressor)".into()
    }
    fn vars(&self, net: &Net) -> Vec<Var> {
        net.encoder.vars()
    }
    fn units(&self) -> Vec<usize> {
        (0..self.train.x.len()).collect()
    }
    fn loss(&self, net: &Net, units: &[usize]) -> Result<Tensor> {
        let x: Vec<&[f32]> = units.iter().map(|&i| self.train.x[i].as_slice()).collect();
        let u: Vec<&[f32]> = units
            .iter()
            .map(|&i| self.train.units[i].as_slice())
            .collect();
        Regression::batch_loss(net, &x, &u)
    }
    fn valid(&self, net: &Net) -> Result<f64> {
        let x: Vec<&[f32]> = self.valid.x.iter().map(|r| r.as_slice()).collect();
        let u: Vec<&[f32]> = self.valid.units.iter().map(|r| r.as_slice()).collect();
        Ok(Regression::batch_loss(net, &x, &u)?.to_scalar::<f32>()? as f64)
    }
}

/// The training loop: AdamW over the objective's variables, shuffled batches of
/// `cfg.batch_seqs` units per step, the learning-rate step, early stopping (after
/// `cfg.warmup` epochs) with the best weights restored.
pub fn fit(
    net: &Net,
    objective: &dyn Objective,
    cfg: &TrainConfig,
    rng: &mut StdRng,
) -> Result<TrainLog> {
    let mut units = objective.units();
    let mut opt = AdamW::new(
        objective.vars(net),
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
    bar.set_prefix(objective.label(net));
    let start = Instant::now();
    let mut log = TrainLog {
        best_valid: f64::INFINITY,
        ..TrainLog::default()
    };
    let mut best = net.snapshot()?;
    let mut since_best = 0;
    let watch_from = cfg.warmup.min(cfg.epochs.saturating_sub(1)) + 1;
    for epoch in 1..=cfg.epochs {
        if epoch == cfg.lr_step + 1 {
            opt.set_learning_rate(cfg.lr * 0.1);
        }
        units.shuffle(rng);
        let mut loss_sum = 0.0;
        let mut batches = 0usize;
        for group in units.chunks(cfg.batch_seqs) {
            let loss = objective.loss(net, group)?;
            opt.backward_step(&loss)?;
            loss_sum += loss.to_scalar::<f32>()? as f64;
            batches += 1;
        }
        let v = objective.valid(net)?;
        let train_loss = loss_sum / batches.max(1) as f64;
        log.history.push((train_loss, v));
        log.epochs = epoch;
        // The warm-up's epochs are neither kept nor counted towards the patience.
        let watched = epoch >= watch_from;
        if watched && v < log.best_valid {
            log.best_valid = v;
            log.best_epoch = epoch;
            best = net.snapshot()?;
            since_best = 0;
        } else if watched {
            since_best += 1;
        }
        bar.set_message(format!("loss {train_loss:.4} valid {v:.4}"));
        bar.inc(1);
        if since_best >= cfg.patience {
            break;
        }
    }
    bar.finish_and_clear();
    net.restore(&best)?;
    log.seconds = start.elapsed().as_secs_f64();
    Ok(log)
}

/// Number of simulated observations for the regressor D (the paper's split sizes of the S2 data:
/// 11 520 / 2 880).
pub const D_SAMPLES: [usize; 2] = [11_520, 2_880];

/// Trains a model of `kind` for `problem` with declared `effects` (training on the problem's
/// training split, early stopping on its validation split) and returns the f32 model file with
/// its log and its residual threshold set on the validation split.
pub fn train_model<P: Problem + ?Sized>(
    problem: &P,
    kind: ModelKind,
    effects: &[OwnedEffect],
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    train_model_on(problem, problem.data(), kind, effects, cfg, seed)
}

/// [`train_model`] on other splits of the problem's observations (the loop's keep rule for an
/// effect that starts after the training years: [`crate::data::onset_folds`]).
pub fn train_model_on<P: Problem + ?Sized>(
    problem: &P,
    data: &Dataset,
    kind: ModelKind,
    effects: &[OwnedEffect],
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    let mut best: Option<(OwnedModel, TrainLog)> = None;
    let mut valid = Vec::new();
    for r in 0..cfg.restarts.max(1) {
        let (model, log) = train_once(problem, data, kind, effects, cfg, restart_seed(seed, r))?;
        valid.push(log.best_valid);
        if best
            .as_ref()
            .is_none_or(|(_, b)| log.best_valid < b.best_valid)
        {
            best = Some((model, TrainLog { restart: r, ..log }));
        }
    }
    let (model, log) = best.ok_or_else(|| anyhow::anyhow!("no training run"))?;
    Ok((
        model,
        TrainLog {
            restart_valid: valid,
            ..log
        },
    ))
}

/// The seed of restart `r` (restart 0: `seed` itself).
pub fn restart_seed(seed: u64, r: usize) -> u64 {
    seed ^ (r as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// One training run from `seed`.
fn train_once<P: Problem + ?Sized>(
    problem: &P,
    data: &Dataset,
    kind: ModelKind,
    effects: &[OwnedEffect],
    cfg: &TrainConfig,
    seed: u64,
) -> Result<(OwnedModel, TrainLog)> {
    if kind == ModelKind::D && !effects.is_empty() {
        bail!("the regressor D is trained on simulated observations without dates: no effects");
    }
    problem.check_effects(effects)?;
    let mut rng = StdRng::seed_from_u64(seed);
    let physics = problem.physics(effects)?;
    let bounds = problem.bounds(effects);
    let net = Net::new(
        kind.variant(),
        data,
        (kind != ModelKind::A).then_some(physics.clone()),
        bounds.clone(),
        problem.bounds(&[]).len(),
        &mut rng,
    )?;
    let log = match kind {
        ModelKind::D => {
            let sim = |n, rng: &mut StdRng| {
                simulate(physics.as_ref(), &bounds, &data.mean, &data.scale, n, rng)
            };
            let train = sim(D_SAMPLES[0], &mut rng)?;
            let valid = sim(D_SAMPLES[1], &mut rng)?;
            fit(&net, &Regression { train, valid }, cfg, &mut rng)?
        }
        _ => {
            let (td, vd) = (data.train.days(), data.valid.days());
            let objective = Reconstruction {
                train: Rows {
                    x: &data.train.x,
                    days: &td,
                },
                valid: Rows {
                    x: &data.valid.x,
                    days: &vd,
                },
                seq_len: cfg.seq_len,
                lambda: cfg.lambda,
                smooth_mean: cfg.smooth_mean,
            };
            fit(&net, &objective, cfg, &mut rng)?
        }
    };
    let mut model = OwnedModel::from_net(&net, problem.spec()?, effects.to_vec())?;
    model.residual_threshold = model.residual_threshold(&data.valid)?;
    Ok((model, log))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Dataset, Split};

    /// Agreement of the f32 losses with the same sums in f64 (24 cells of order 1).
    const F32_SUM_TOLERANCE: f64 = 1e-5;

    /// A plain autoencoder on `n` channels with identity standardisation.
    fn net(n: usize) -> Net {
        let data = Dataset {
            columns: (0..n).map(|c| format!("c{c}")).collect(),
            mean: vec![0.0; n],
            scale: vec![1.0; n],
            train: Split::default(),
            valid: Split::default(),
            test: Split::default(),
            source: "test".into(),
        };
        Net::new(
            Variant::A,
            &data,
            None,
            vec![],
            3,
            &mut StdRng::seed_from_u64(3),
        )
        .unwrap()
    }

    /// An objective whose validation loss follows a script, one value per epoch.
    struct Scripted {
        valid: Vec<f64>,
        epoch: std::cell::Cell<usize>,
    }

    impl Objective for Scripted {
        fn label(&self, _: &Net) -> String {
            "scripted".into()
        }
        fn vars(&self, _: &Net) -> Vec<Var> {
            vec![]
        }
        fn units(&self) -> Vec<usize> {
            vec![0]
        }
        fn loss(&self, _: &Net, _: &[usize]) -> Result<Tensor> {
            Ok(Tensor::new(1f32, &candle_core::Device::Cpu)?)
        }
        fn valid(&self, _: &Net) -> Result<f64> {
            let e = self.epoch.get();
            self.epoch.set(e + 1);
            Ok(self.valid[e.min(self.valid.len() - 1)])
        }
    }

    /// (epochs run, epoch kept) for a scripted validation curve.
    fn stopping(curve: &[f64], warmup: usize, epochs: usize) -> (usize, usize) {
        let objective = Scripted {
            valid: curve.to_vec(),
            epoch: 0.into(),
        };
        let cfg = TrainConfig {
            patience: 3,
            progress: false,
            ..TrainConfig::gnss()
                .with(epochs, true)
                .with_warmup(Some(warmup))
        };
        let log = fit(&net(2), &objective, &cfg, &mut StdRng::seed_from_u64(1)).unwrap();
        (log.epochs, log.best_epoch)
    }

    #[test]
    fn the_warm_up_is_neither_kept_nor_counted() {
        // A lucky second epoch, then a noisy curve that goes lower only later.
        let curve = [
            1.8, 1.2, 1.6, 1.5, 1.4, 1.3, 1.1, 1.0, 1.05, 1.02, 1.03, 1.04, 1.06,
        ];
        // The paper's rule: epoch 2 is kept and three epochs without gain end the run.
        assert_eq!(stopping(&curve, 0, 100), (5, 2));
        // Watched from epoch 4 on: epoch 8 is kept, the run ends three epochs later.
        assert_eq!(stopping(&curve, 3, 100), (11, 8));
        // A warm-up as long as the run still watches its last epoch.
        assert_eq!(stopping(&curve, 50, 6), (6, 6));
    }

    #[test]
    fn missing_channels_are_left_out_of_the_loss_not_the_day() {
        let n = 6;
        let net = net(n);
        let rows: Vec<Vec<f32>> = (0..4)
            .map(|r| (0..n).map(|c| ((r * n + c) as f32 * 0.37).sin()).collect())
            .collect();
        let mut gappy = rows.clone();
        gappy[1][2] = f32::NAN;
        gappy[3][0] = f32::NAN;
        gappy[3][5] = f32::NAN;
        let days = days_tensor(&[0.0, 1.0, 2.0, 3.0]).unwrap();
        fn refs(r: &[Vec<f32>]) -> Vec<&[f32]> {
            r.iter().map(Vec::as_slice).collect()
        }
        let (loss, cells, _) = batch_mse(&net, &refs(&gappy), n, &days).unwrap();
        assert_eq!(cells, 4 * n - 3);
        // By hand: the network fed the rows with the missing cells at the mean (0), the squared
        // error summed over the observed cells only.
        let filled: Vec<Vec<f32>> = gappy
            .iter()
            .map(|r| {
                r.iter()
                    .map(|v| if v.is_nan() { 0.0 } else { *v })
                    .collect()
            })
            .collect();
        let out = net
            .forward(&to_tensor(&refs(&filled), n).unwrap(), &days)
            .unwrap();
        let recon: Vec<Vec<f32>> = out.recon.to_vec2().unwrap();
        let (mut sq, mut k) = (0.0f64, 0usize);
        for (r, row) in gappy.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                if !v.is_nan() {
                    sq += ((recon[r][c] - v) as f64).powi(2);
                    k += 1;
                }
            }
        }
        let got = loss.to_scalar::<f32>().unwrap() as f64;
        assert!(
            (got - sq / k as f64).abs() < F32_SUM_TOLERANCE,
            "{got} vs {}",
            sq / k as f64
        );
        // Without missing cells: the plain mean over every cell.
        let (full, cells, _) = batch_mse(&net, &refs(&rows), n, &days).unwrap();
        assert_eq!(cells, 4 * n);
        let plain = mse(
            &net.forward(&to_tensor(&refs(&rows), n).unwrap(), &days)
                .unwrap()
                .recon,
            &to_tensor(&refs(&rows), n).unwrap(),
        )
        .unwrap();
        assert_eq!(
            full.to_scalar::<f32>().unwrap(),
            plain.to_scalar::<f32>().unwrap()
        );
        // The validation MSE counts observed cells: finite on gappy rows.
        let d = [0.0, 1.0, 2.0, 3.0];
        let v = valid_mse(
            &net,
            Rows {
                x: &gappy,
                days: &d,
            },
        )
        .unwrap();
        assert!((v - sq / k as f64).abs() < F32_SUM_TOLERANCE, "{v}");
    }
}
