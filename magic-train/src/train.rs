//! Training with the paper's recipe (A.7, A.8): AdamW (lr 1e-3, weight decay 1e-4), learning rate
//! ×0.1 after 50 epochs, at most 100 epochs, early stop after 10 epochs without validation gain
//! (the best weights are kept), and for sequential data (GNSS) batches of 12 sequences × 5
//! consecutive days with the smoothness term of eq. 19 on F's output (λ = 0.01, B and C).
//!
//! The paper used PyTorch's Adam with (coupled) L2 weight decay; candle offers AdamW (decoupled
//! decay), which is what is used here.

use crate::nets::{days_tensor, mse, smoothness, to_tensor, Net};
use anyhow::Result;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use indicatif::{ProgressBar, ProgressStyle};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use std::time::Instant;

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
}

impl TrainConfig {
    /// The paper's GNSS recipe.
    pub fn gnss() -> Self {
        TrainConfig {
            epochs: 100,
            lr: 1e-3,
            weight_decay: 1e-4,
            lr_step: 50,
            patience: 10,
            batch_seqs: 12,
            seq_len: 5,
            lambda: 0.01,
            smooth_mean: true,
            progress: true,
        }
    }
}

/// What a training run measured.
#[derive(Clone, Debug, Default)]
pub struct TrainLog {
    /// Epochs run.
    pub epochs: usize,
    /// Epoch (1-based) of the best validation MSE.
    pub best_epoch: usize,
    /// Best validation MSE.
    pub best_valid: f64,
    /// Mean training loss and validation MSE per epoch.
    pub history: Vec<(f64, f64)>,
    /// Wall-clock seconds in all.
    pub seconds: f64,
}

impl TrainLog {
    /// Mean seconds per epoch.
    pub fn seconds_per_epoch(&self) -> f64 {
        self.seconds / self.epochs.max(1) as f64
    }
}

/// Rows of standardised observations with their day numbers.
#[derive(Clone, Copy)]
pub struct Rows<'a> {
    /// Observations.
    pub x: &'a [Vec<f32>],
    /// Day numbers (NaN where unknown), one per row.
    pub days: &'a [f64],
}

/// Validation MSE of the final reconstruction (standardised units).
pub fn valid_mse(net: &Net, data: Rows<'_>) -> Result<f64> {
    let x = data.x;
    let n = x.first().map_or(0, |r| r.len());
    let mut sum = 0.0;
    let mut count = 0usize;
    for (ci, chunk) in x.chunks(1024).enumerate() {
        let rows: Vec<&[f32]> = chunk.iter().map(|r| r.as_slice()).collect();
        let t = to_tensor(&rows, n)?;
        let d = days_tensor(&data.days[ci * 1024..ci * 1024 + chunk.len()])?;
        let out = net.forward(&t, &d)?;
        let e = mse(&out.recon, &t)?.to_scalar::<f32>()? as f64;
        sum += e * chunk.len() as f64;
        count += chunk.len();
    }
    Ok(sum / count.max(1) as f64)
}

/// Trains `net` on `train` (rows of standardised observations, in time order when `seq_len > 1`),
/// early-stopping on `valid`.
pub fn train(
    net: &Net,
    train_rows: Rows<'_>,
    valid: Rows<'_>,
    cfg: &TrainConfig,
    rng: &mut StdRng,
) -> Result<TrainLog> {
    let train = train_rows.x;
    let n = train.first().map_or(0, |r| r.len());
    let t = cfg.seq_len.max(1);
    let mut starts: Vec<usize> = (0..train.len() / t).map(|i| i * t).collect();
    let mut opt = AdamW::new(
        net.vars(),
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
    bar.set_prefix(format!("train {:?}", net.variant));
    let start = Instant::now();
    let mut log = TrainLog {
        best_valid: f64::INFINITY,
        ..TrainLog::default()
    };
    let mut best = net.snapshot()?;
    let mut since_best = 0;
    for epoch in 1..=cfg.epochs {
        if epoch == cfg.lr_step + 1 {
            opt.set_learning_rate(cfg.lr * 0.1);
        }
        starts.shuffle(rng);
        let mut loss_sum = 0.0;
        let mut batches = 0usize;
        for group in starts.chunks(cfg.batch_seqs) {
            let rows: Vec<&[f32]> = group
                .iter()
                .flat_map(|&s| train[s..s + t].iter().map(|r| r.as_slice()))
                .collect();
            let x = to_tensor(&rows, n)?;
            let days: Vec<f64> = group
                .iter()
                .flat_map(|&s| train_rows.days[s..s + t].iter().copied())
                .collect();
            let out = net.forward(&x, &days_tensor(&days)?)?;
            let mut loss = mse(&out.recon, &x)?;
            if let (Some(f), true) = (&out.physics, cfg.lambda > 0.0 && t > 1) {
                let mut s = smoothness(f, group.len(), t)?;
                if cfg.smooth_mean {
                    s = (s / (group.len() * (t - 1) * n) as f64)?;
                }
                loss = (loss + (s * cfg.lambda)?)?;
            }
            opt.backward_step(&loss)?;
            loss_sum += loss.to_scalar::<f32>()? as f64;
            batches += 1;
        }
        let v = valid_mse(net, valid)?;
        let train_loss = loss_sum / batches.max(1) as f64;
        log.history.push((train_loss, v));
        log.epochs = epoch;
        if v < log.best_valid {
            log.best_valid = v;
            log.best_epoch = epoch;
            best = net.snapshot()?;
            since_best = 0;
        } else {
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
