//! A problem: what one inversion task brings to the trainer, the evaluation, the residual
//! analysis and the loop — its data, its physics with effects, the bounds of its variables, the
//! metrics its reports show and the effect families that can be looked for. Everything else is
//! written once over this trait.
//!
//! Two problems exist: [`crate::gnss::GnssProblem`] (a Mogi source under a GNSS network) and
//! [`crate::rtm::RtmProblem`] (INFORM under Sentinel-2 forest spectra). A trait rather than an
//! enum: each problem has its own residual type (a network's daily time series; spectra with a
//! tangent space each), and its families are typed against it, so pairing a family with the
//! wrong problem does not compile. Adding a problem is one new module implementing this trait.

use crate::analysis::{Analysis, AnalysisOptions, Candidate, DynFamily};
use crate::data::{Dataset, SplitName};
use crate::model::OwnedEffect;
use crate::physics::Physics;
use crate::train::{ModelKind, TrainConfig};
use anyhow::Result;
use magic_core::Model;
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;

/// A figure a report shows for a model (plausibility of the source, LAI against SNAP, …).
#[derive(Clone, Debug, Serialize)]
pub struct Metric {
    /// Key in JSON reports.
    pub key: &'static str,
    /// Column heading in Markdown reports.
    pub label: &'static str,
    /// The value (NaN when it could not be computed).
    pub value: f64,
    /// The value as a report prints it.
    pub text: String,
    /// The value's standard deviation, where the metric has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sd: Option<f64>,
}

impl Metric {
    /// A metric printed with `text`.
    pub fn new(key: &'static str, label: &'static str, value: f64, text: String) -> Metric {
        Metric {
            key,
            label,
            value,
            text,
            sd: None,
        }
    }

    /// The metric with a standard deviation (kept only if finite).
    pub fn with_sd(mut self, sd: f64) -> Metric {
        self.sd = sd.is_finite().then_some(sd);
        self
    }
}

/// The paper's numbers for one model kind: train, valid, test MSE (NaN where not published).
pub type PaperRow = (ModelKind, [f64; 3]);

/// One inversion task.
pub trait Problem: Sync {
    /// What this problem's effect families are fitted to.
    type Residuals: Send + Sync;

    /// Short name: `mogi`, `rtm` (model files, reports, the CLI).
    fn name(&self) -> &'static str;
    /// The forward model's name in reports (`Mogi`, `INFORM`).
    fn physics_name(&self) -> &'static str;
    /// The data: three splits, standardisation, channel names.
    fn data(&self) -> &Dataset;
    /// The paper's training recipe for this problem.
    fn recipe(&self) -> TrainConfig;
    /// Bounds of F's variables with the latent variables of `effects`.
    fn bounds(&self, effects: &[OwnedEffect]) -> Vec<[f64; 2]>;
    /// F with `effects` declared, for the trainer (values and exact Jacobian).
    fn physics(&self, effects: &[OwnedEffect]) -> Result<Arc<dyn Physics>>;
    /// Whether `effects` can be declared in this problem's F.
    fn check_effects(&self, effects: &[OwnedEffect]) -> Result<()>;
    /// The problem description a model file carries.
    fn spec(&self) -> Result<magic_core::Problem<'static>>;
    /// The paper's table for this problem (Table 4, Table 3).
    fn paper_table(&self) -> Vec<PaperRow>;
    /// The figures a report shows for a model besides its MSE.
    fn metrics(&self, model: &Model<'_>) -> Result<Vec<Metric>>;
    /// A classical baseline with the same declared effects, where the problem has one.
    fn baseline(&self, _effects: &[OwnedEffect]) -> Result<Vec<Metric>> {
        Ok(vec![])
    }

    /// The splits the residual analysis looks at by default.
    fn default_splits(&self) -> Vec<SplitName>;
    /// The residuals of a model (variant B or C) for the analysis.
    fn residuals(&self, model: &Model<'_>, opts: &AnalysisOptions) -> Result<Self::Residuals>;
    /// The effect families that can be looked for, in report order.
    fn families(&self, opts: &AnalysisOptions) -> Vec<Box<dyn DynFamily<Self::Residuals>>>;
    /// Marks the candidates a higher-ranked one accounts for (`effects` ranked, best first) as
    /// not significant, with the reason: one signal two families see. None by default.
    fn reconcile(&self, _res: &Self::Residuals, _effects: &mut [Candidate]) {}
    /// What the analysis reports about the residuals themselves (JSON) and its one-line summary.
    fn describe_residuals(&self, res: &Self::Residuals) -> (serde_json::Value, String);
    /// Figures of an analysis (PNG files into `dir`).
    fn analysis_plots(&self, res: &Self::Residuals, a: &Analysis, dir: &Path) -> Result<()>;
    /// Writes the residual series the families search, as CSV files into `dir` (`magic residuals
    /// --series`); an error for a problem without one.
    fn write_series(&self, _res: &Self::Residuals, _dir: &Path) -> Result<()> {
        anyhow::bail!("--series: only a volcano (GNSS) model's residuals form a series of days")
    }

    /// Effects the loop tests directly (retrains with them) when it did not add them itself.
    fn direct_tests(&self) -> Vec<OwnedEffect> {
        vec![]
    }
    /// Before/after figures of the loop (first and last B model) into `dir`: Markdown image
    /// lines for the report.
    fn loop_plots(&self, first: &Model<'_>, last: &Model<'_>, dir: &Path) -> Result<Vec<String>>;
}
