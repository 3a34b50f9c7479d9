//! Train → export → core: a tiny training run on synthetic data, exported to f32 and int8 model
//! files, decoded by the core and evaluated through `invert` like the board does.

use magic_core::Model;
use magic_train::gnss::synth;
use magic_train::{evaluate, train_model, ModelKind, TrainConfig};

/// The exported f32 model's validation MSE through the core (`invert`, physics in f64) against
/// the trainer's (candle, f32): measured 2.3e-7 (MSE ≈ 1); 10× that.
const CORE_VS_TRAINER_MAX_MSE_GAP: f64 = 2.5e-6;
/// The int8 model's test MSE against the f32 model's (the runs are seeded, hence repeatable):
/// measured 3.1e-4; 10× that, rounded up.
const INT8_VS_F32_MAX_MSE_GAP: f64 = 3.5e-3;

#[test]
fn tiny_training_exports_and_inverts() {
    let p = synth::generate(synth::Scenario::Clean, 11).problem;
    let data = &p.data;
    let cfg = TrainConfig {
        epochs: 4,
        progress: false,
        ..TrainConfig::gnss()
    };
    let (model, log) = train_model(&p, ModelKind::C, &[], &cfg, 11).unwrap();
    assert_eq!(log.epochs, 4);
    assert!(log
        .history
        .iter()
        .all(|(l, v)| l.is_finite() && v.is_finite()));
    let f = model.encode().unwrap();
    let q = model
        .quantize_int8(&data.train.x)
        .unwrap()
        .encode()
        .unwrap();
    let fm = Model::decode(&f).unwrap();
    let qm = Model::decode(&q).unwrap();
    let ef = evaluate(&fm, &data.test, "test").unwrap();
    let eq = evaluate(&qm, &data.test, "test").unwrap();
    // Training lowered the validation error from the first epoch's.
    assert!(log.best_valid <= log.history[0].1);
    // Early-stopping restores the best weights: the exported model scores its best validation MSE.
    let ev = evaluate(&fm, &data.valid, "valid").unwrap();
    eprintln!(
        "valid MSE: core {:.3e} off the trainer's; test MSE: int8 {:.3e} off f32",
        (ev.mse - log.best_valid).abs(),
        (eq.mse - ef.mse).abs()
    );
    assert!(
        (ev.mse - log.best_valid).abs() <= CORE_VS_TRAINER_MAX_MSE_GAP,
        "{} vs {}",
        ev.mse,
        log.best_valid
    );
    assert!(
        (eq.mse - ef.mse).abs() <= INT8_VS_F32_MAX_MSE_GAP,
        "int8 {} vs f32 {}",
        eq.mse,
        ef.mse
    );
    assert!(q.len() < f.len() / 2);
}

#[test]
fn seeds_make_runs_repeatable() {
    let p = synth::generate(synth::Scenario::Clean, 4).problem;
    let cfg = TrainConfig {
        epochs: 2,
        progress: false,
        ..TrainConfig::gnss()
    };
    let a = train_model(&p, ModelKind::B, &[], &cfg, 9)
        .unwrap()
        .0
        .encode()
        .unwrap();
    let b = train_model(&p, ModelKind::B, &[], &cfg, 9)
        .unwrap()
        .0
        .encode()
        .unwrap();
    assert_eq!(a, b);
}

/// Restarts keep the run with the lowest validation loss: the first run is the single run of
/// the same seed, and the model kept is that run's or a better one on validation.
#[test]
fn restarts_keep_the_best_run_on_validation() {
    let p = synth::generate(synth::Scenario::Clean, 4).problem;
    let cfg = TrainConfig {
        epochs: 3,
        progress: false,
        ..TrainConfig::gnss()
    };
    let (single, one) = train_model(&p, ModelKind::C, &[], &cfg, 5).unwrap();
    let (kept, log) = train_model(&p, ModelKind::C, &[], &cfg.clone().with_restarts(3), 5).unwrap();
    assert_eq!(log.restart_valid.len(), 3);
    assert_eq!(
        log.restart_valid[0], one.best_valid,
        "run 0 is the single run"
    );
    let min = log
        .restart_valid
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    assert_eq!(log.best_valid, min);
    assert_eq!(log.restart_valid[log.restart], min);
    if log.restart == 0 {
        assert_eq!(kept.encode().unwrap(), single.encode().unwrap());
    } else {
        assert!(log.best_valid < one.best_valid);
    }
}
