//! The forest problem: INFORM (PROSPECT-D leaves, 4SAIL canopy and understory, forest crowns)
//! under Sentinel-2 spectra of Austrian forest sites, with the effects a season of acquisitions
//! holds besides the forest — each acquisition's own sun, band biases, per-species structure.

pub mod data;
pub mod families;
pub mod lai;
pub mod physics;
pub mod released;
pub mod residuals;
pub mod tables;

pub use physics::RtmPhysics;
pub use residuals::SpectraResiduals;
pub use tables::{PackedRows, RtmTables, S2_DATA_BANDS};

use crate::analysis::{Analysis, AnalysisOptions, DynFamily};
use crate::data::{Dataset, SplitName};
use crate::model::OwnedEffect;
use crate::physics::Physics;
use crate::problem::{Metric, PaperRow, Problem};
use crate::train::{ModelKind, TrainConfig};
use anyhow::{bail, Result};
use magic_core::rtm::{Fixed, Geometry, LEARNED_BOUNDS};
use magic_core::Model;
use std::path::Path;
use std::sync::Arc;

/// The representative site of the S2 data (its README: 47.5° N, 14.5° E puts the sun within
/// about 2° of each site's own).
pub const S2_SITE: [f32; 2] = [47.5, 14.5];
/// Overpass time of the S2 data (hours UTC): 10:30 local mean solar time, descending, is about
/// 10:00 UTC over Austria.
pub const S2_OVERPASS_UTC: f32 = 10.0;

/// Paper Table 3 (train, valid, test; D: test only).
pub const PAPER_TABLE3: [PaperRow; 4] = [
    (ModelKind::A, [0.0193, 0.0219, 0.0191]),
    (ModelKind::B, [0.0875, 0.0833, 0.0856]),
    (ModelKind::C, [0.0210, 0.0235, 0.0217]),
    (ModelKind::D, [f64::NAN, f64::NAN, 0.6676]),
];

/// Physics-only test MSE of the paper's released C model (`pretrained_rtm_c_test_outputs.csv`).
pub const PAPER_C_PHYSICS_ONLY: f64 = 1.04;

/// A declarable RTM effect by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum RtmEffect {
    /// Each spectrum's own sun from its date at the site and overpass time (physical geometry).
    Illumination,
}

/// INFORM's geometry mode (see `magic_core::rtm::Geometry`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum GeometryArg {
    /// The paper's implementation (cosines handed to INFORM where angles are expected).
    Reference,
    /// The published equations.
    Physical,
}

impl From<GeometryArg> for Geometry {
    fn from(g: GeometryArg) -> Geometry {
        match g {
            GeometryArg::Reference => Geometry::Reference,
            GeometryArg::Physical => Geometry::Physical,
        }
    }
}

/// The forest problem: spectra, the tables' rows of their bands, the fixed inputs and the
/// geometry mode.
#[derive(Clone, Debug)]
pub struct RtmProblem {
    /// The spectra (labels: species; ids: site).
    pub data: Dataset,
    /// The tables' rows for the observed bands (f64).
    pub rows: PackedRows,
    /// Fixed inputs (the paper's: sun at 30°, nadir view, …).
    pub fixed: Fixed,
    /// Geometry mode.
    pub geometry: Geometry,
    /// The SNAP site extract (LAI reference), when found beside the spectra.
    pub extract: Option<data::Extract>,
}

impl RtmProblem {
    /// Reads the S2 folder and the tables folder; the paper's fixed inputs. The site extract
    /// `BPWW_extract_2018.csv` is read when present.
    pub fn read(data_dir: &Path, tables_dir: &Path, geometry: Geometry) -> Result<RtmProblem> {
        let data = data::read_dir(data_dir)?;
        let rows = RtmTables::read(tables_dir)?.pack(&S2_DATA_BANDS)?;
        let ext = data_dir.join("BPWW_extract_2018.csv");
        let extract = if ext.is_file() {
            Some(data::Extract::read(&ext)?)
        } else {
            None
        };
        Ok(RtmProblem {
            data,
            rows,
            fixed: Fixed::default(),
            geometry,
            extract,
        })
    }

    /// The illumination effect for the S2 data: each spectrum's sun at [`S2_SITE`] and
    /// [`S2_OVERPASS_UTC`] on its date; nadir view (the view azimuth then does not matter).
    pub fn illumination(&self) -> OwnedEffect {
        OwnedEffect::Illumination {
            lat_deg: S2_SITE[0],
            lon_deg: S2_SITE[1],
            utc_hours: S2_OVERPASS_UTC,
            view_azimuth_deg: 0.0,
        }
    }

    /// The effect `e`.
    pub fn effect(&self, e: RtmEffect) -> OwnedEffect {
        match e {
            RtmEffect::Illumination => self.illumination(),
        }
    }
}

impl Problem for RtmProblem {
    type Residuals = SpectraResiduals;

    fn name(&self) -> &'static str {
        "rtm"
    }
    fn physics_name(&self) -> &'static str {
        "INFORM"
    }
    fn data(&self) -> &Dataset {
        &self.data
    }
    fn recipe(&self) -> TrainConfig {
        TrainConfig::s2()
    }
    fn bounds(&self, _effects: &[OwnedEffect]) -> Vec<[f64; 2]> {
        LEARNED_BOUNDS.to_vec()
    }
    fn physics(&self, effects: &[OwnedEffect]) -> Result<Arc<dyn Physics>> {
        let p = RtmPhysics::new(self.rows.clone(), self.fixed, self.geometry)
            .and_then(|p| p.with_effects(effects.to_vec()))
            .map_err(|e| anyhow::anyhow!("RTM model: {e}"))?;
        Ok(Arc::new(p))
    }
    fn check_effects(&self, effects: &[OwnedEffect]) -> Result<()> {
        for e in effects {
            if e.n_latent() > 0
                || !matches!(
                    e,
                    OwnedEffect::Illumination { .. } | OwnedEffect::BandOffset { .. }
                )
            {
                bail!(
                    "{} is an effect of a GNSS network, not of the forest spectra",
                    e.family()
                );
            }
        }
        // The geometry rule (illumination needs the physical geometry) is the core's.
        RtmPhysics::new(self.rows.clone(), self.fixed, self.geometry)
            .and_then(|p| p.with_effects(effects.to_vec()))
            .map(|_| ())
            .map_err(|e| anyhow::anyhow!("RTM model: {e}"))
    }
    fn spec(&self) -> Result<magic_core::Problem<'static>> {
        Ok(self.rows.problem(self.fixed, self.geometry))
    }
    fn paper_table(&self) -> Vec<PaperRow> {
        PAPER_TABLE3.to_vec()
    }
    fn metrics(&self, model: &Model<'_>) -> Result<Vec<Metric>> {
        match &self.extract {
            Some(ext) if model.variant != magic_core::Variant::A => {
                let d = &self.data;
                let r = lai::lai_vs_snap(model, d, &[&d.train, &d.valid, &d.test], ext)?;
                Ok(lai::metrics(&r))
            }
            _ => Ok(vec![]),
        }
    }
    /// Fitted on the training sites, scored on the validation sites.
    fn default_splits(&self) -> Vec<SplitName> {
        vec![SplitName::Train, SplitName::Valid]
    }
    fn residuals(&self, model: &Model<'_>, opts: &AnalysisOptions) -> Result<SpectraResiduals> {
        let splits = opts.splits_for(self);
        let [fit, held, ..] = splits[..] else {
            bail!("the forest-spectra analysis fits on one split and scores on another: name two");
        };
        residuals::residuals(self, model, fit, held)
    }
    fn families(&self, _: &AnalysisOptions) -> Vec<Box<dyn DynFamily<SpectraResiduals>>> {
        families::all()
    }
    fn describe_residuals(&self, res: &SpectraResiduals) -> (serde_json::Value, String) {
        res.describe()
    }
    fn analysis_plots(&self, res: &SpectraResiduals, a: &Analysis, dir: &Path) -> Result<()> {
        report_plots(res, a, dir)
    }
    fn direct_tests(&self) -> Vec<OwnedEffect> {
        if self.geometry == Geometry::Physical {
            vec![self.illumination()]
        } else {
            vec![]
        }
    }
    fn loop_plots(
        &self,
        _first: &Model<'_>,
        _last: &Model<'_>,
        _dir: &Path,
    ) -> Result<Vec<String>> {
        Ok(vec![])
    }
}

/// `effects.png` (explained vs chance per family) and `residual_by_date.png` (held-out residual
/// per acquisition date: RMS over bands of the date's mean projected residual, with the sun
/// zenith at the overpass).
fn report_plots(res: &SpectraResiduals, a: &Analysis, dir: &Path) -> Result<()> {
    use anyhow::Context as _;
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    crate::analysis::effects_chart(
        &dir.join("effects.png"),
        &format!(
            "Projected residual explained on {}, % (tick: chance, *: significant)",
            res.ctx.splits[1]
        ),
        &a.effects,
    )?;
    let days: Vec<f64> = res.ctx.dates.iter().map(|d| d.1).collect();
    let rms: Vec<f64> = a.residuals["date_band_mean"]
        .as_array()
        .map(|rows| {
            rows.iter()
                .map(|m| {
                    let v: Vec<f64> = m
                        .as_array()
                        .map(|x| x.iter().filter_map(|y| y.as_f64()).collect())
                        .unwrap_or_default();
                    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
                })
                .collect()
        })
        .unwrap_or_default();
    let sun = res.ctx.sun.borrow(&[]);
    let zen: Vec<f64> = days
        .iter()
        .map(|&d| {
            magic_core::effects::rtm_fixed_at(&[sun], &Fixed::default(), d)
                .map_or(f64::NAN, |f| f.tts / 100.0)
        })
        .collect();
    crate::report::plots::time_series(
        &dir.join("residual_by_date.png"),
        "Mean residual per acquisition date (RMS over bands, standardised) and sun zenith / 100°",
        &days,
        &[("residual", &rms), ("sun zenith / 100°", &zen)],
    )
}
