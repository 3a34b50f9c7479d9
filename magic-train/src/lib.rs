//! # magic-train
//!
//! The host side of **magic**: data readers, the paper's models in candle with the core's physics
//! as a differentiable op, training, int8 export, evaluation and the `magic` command line.

pub mod classical;
pub mod closed_loop;
pub mod data;
pub mod demo;
pub mod demo_qemu;
pub mod eval;
pub mod export;
pub mod missing;
pub mod nets;
pub mod physics;
pub mod pipeline;
pub mod plots;
pub mod qemu;
pub mod qemu_uart;
pub mod records;
pub mod reproduce;
pub mod residuals;
pub mod rtm_cli;
pub mod rtm_loop;
pub mod rtm_physics;
pub mod rtm_pipeline;
pub mod rtm_residuals;
pub mod station;
pub mod synth;
pub mod train;

pub use data::gnss::GnssData;
pub use eval::{evaluate, EvalResult};
pub use export::OwnedModel;
pub use nets::Net;
pub use physics::{MogiPhysics, Physics, PhysicsOp};
pub use train::{train, TrainConfig, TrainLog};
