//! # magic-train
//!
//! The host side of **magic**: one trainer for every inversion problem. A [`Problem`] (the
//! volcano: [`GnssProblem`]; the forest: [`RtmProblem`]) brings its data, its physics with
//! declared effects, its bounds, its report metrics and its effect [`Family`]s; training
//! ([`train_model`], one loop around a pluggable [`Objective`]), evaluation ([`evaluate`]), the
//! residual analysis ([`analyse`]), the loop ([`closed_loop::run`]), the reports and the `magic`
//! command line ([`cli`]) are written once over those two interfaces.
//!
//! The physics is magic-core's, differentiated exactly: [`PhysicsOp`] is a candle op whose
//! backward pass uses the core's Jacobian (dual numbers). Models are written as magic-core model
//! files ([`OwnedModel`]), f32 or int8, and run by the same `invert` on the host, in Python and
//! on the board ([`firmware`]).
//!
//! Layout: `problem` · `physics` · `nets` · `train` · `eval` · `model/` · `analysis/` ·
//! `closed_loop` · `reproduce` · `numerics/` · `report/` · `data/` · `gnss/` · `rtm/` ·
//! `firmware/` · `cli/`.
#![deny(missing_docs)]
// Numerical kernels index several arrays in step (channels, stations, days); iterator chains
// would hide the indices the equations are written in.
#![allow(clippy::needless_range_loop)]

pub mod analysis;
pub mod cli;
pub mod closed_loop;
pub mod data;
pub mod demo;
pub mod eval;
pub mod firmware;
pub mod gnss;
pub mod model;
pub mod nets;
pub mod numerics;
pub mod physics;
pub mod problem;
pub mod raster;
pub mod report;
pub mod reproduce;
pub mod rtm;
pub mod train;

pub use analysis::{analyse, Analysis, AnalysisOptions, Candidate, DynFamily, Family, MainSource};
pub use data::{Dataset, Split, SplitName};
pub use eval::{evaluate, evaluate_splits, EvalResult};
pub use gnss::{GnssProblem, MogiPhysics, Network};
pub use model::{OwnedEffect, OwnedModel};
pub use nets::Net;
pub use physics::{Physics, PhysicsOp};
pub use problem::{Metric, Problem};
pub use rtm::{RtmProblem, RtmTables};
pub use train::{train_model, ModelKind, Objective, TrainConfig, TrainLog};
