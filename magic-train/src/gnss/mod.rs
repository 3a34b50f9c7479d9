//! The volcano problem: a Mogi source under a GNSS station network (daily displacements E, N, U
//! in mm), with the effects a network's records hold besides the source — a daily translation of
//! the whole network, seasonal terms, a vertical term linear in elevation, steps, a second
//! source, drifts.

pub mod bounds;
pub mod classical;
pub mod data;
pub mod families;
pub mod geodesy;
pub mod lsq;
pub mod missing;
pub mod physics;
pub mod plausibility;
pub mod prepare;
pub mod recovery;
pub mod report;
pub mod residuals;
pub mod synth;
pub mod tenv3;

pub use bounds::SourceBounds;
pub use physics::MogiPhysics;
pub use residuals::GnssResiduals;

use crate::analysis::{Analysis, AnalysisOptions, Candidate, DynFamily};
use crate::data::{Dataset, SplitName};
use crate::model::{intern, OwnedEffect};
use crate::physics::Physics;
use crate::problem::{Metric, PaperRow, Problem};
use crate::train::{ModelKind, TrainConfig};
use anyhow::{anyhow, bail, Context, Result};
use magic_core::model_file::{Names, MAX_NAME, MAX_STATIONS};
use magic_core::mogi::{Station, Stations, STATION_BYTES};
use magic_core::Model;
use std::path::Path;
use std::sync::Arc;

/// A station network: names and local positions (km east, north, up), in channel order.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    /// Station names.
    pub names: Vec<String>,
    /// Station positions.
    pub stations: Vec<Station>,
}

impl Network {
    /// The 12-station Akutan network of the paper's release.
    pub fn akutan() -> Network {
        Network {
            names: synth::AKUTAN.iter().map(|s| s.0.to_string()).collect(),
            stations: synth::AKUTAN
                .iter()
                .map(|s| Station {
                    x_km: s.1,
                    y_km: s.2,
                    z_km: s.3,
                })
                .collect(),
        }
    }

    /// Reads a `stations.json` (`{"STA": {"xE": km, "yN": km, "zV": km}, …}`), in the file's
    /// order or in the order of `names` (every one of which must be in the file).
    pub fn read_json(path: &Path, names: Option<&[String]>) -> Result<Network> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not valid JSON", path.display()))?;
        let obj = v
            .as_object()
            .with_context(|| format!("{}: expected an object of stations", path.display()))?;
        let order: Vec<String> = match names {
            Some(n) => n.to_vec(),
            None => obj.keys().cloned().collect(),
        };
        let mut stations = Vec::with_capacity(order.len());
        for n in &order {
            let s = obj.get(n).with_context(|| {
                format!(
                    "{}: station {n} (from the CSV header) is missing",
                    path.display()
                )
            })?;
            let get = |k: &str| {
                s.get(k).and_then(|v| v.as_f64()).with_context(|| {
                    format!(
                        "{}: station {n}: `{k}` missing or not a number",
                        path.display()
                    )
                })
            };
            stations.push(Station {
                x_km: get("xE")?,
                y_km: get("yN")?,
                z_km: get("zV")?,
            });
        }
        Ok(Network {
            names: order,
            stations,
        })
    }

    /// Channel names: `ux_<STA>` ×S, `uy_<STA>` ×S, `uz_<STA>` ×S.
    pub fn channel_names(&self) -> Vec<String> {
        data::channel_names(&self.names)
    }

    /// Number of stations.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether there are no stations.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Mean station elevation (km): the reference of the elevation effect.
    pub fn mean_elevation(&self) -> f64 {
        self.stations.iter().map(|s| s.z_km).sum::<f64>() / self.len().max(1) as f64
    }

    /// The model file's problem description (stations and names interned: `'static` bytes in
    /// the layout of the model file).
    pub fn spec(&self) -> Result<magic_core::Problem<'static>> {
        if self.stations.len() > MAX_STATIONS || self.names.len() > MAX_STATIONS {
            bail!("more stations than the core supports ({MAX_STATIONS})");
        }
        if self.names.len() != self.stations.len() {
            bail!(
                "{} station names for {} stations",
                self.names.len(),
                self.stations.len()
            );
        }
        for name in &self.names {
            if name.is_empty() || name.len() > MAX_NAME || name.contains(',') {
                bail!("station name `{name}` is empty, longer than {MAX_NAME} bytes or contains a comma");
            }
        }
        let mut bytes = vec![0u8; STATION_BYTES * self.stations.len()];
        Stations::encode(&self.stations, &mut bytes)?;
        let joined = intern(self.names.join(",").into_bytes());
        let names = std::str::from_utf8(joined).map_err(|e| anyhow!("station names: {e}"))?;
        Ok(magic_core::Problem::Mogi {
            stations: Stations(intern(bytes)),
            names: Names(names),
        })
    }
}

/// The volcano problem: a network and its daily displacements.
#[derive(Clone, Debug)]
pub struct GnssProblem {
    /// The station network.
    pub network: Network,
    /// Displacements (standardised) in channel order `ux ×S, uy ×S, uz ×S`.
    pub data: Dataset,
    /// Bounds of the source's variables (the paper's Table 2 unless the data folder has a
    /// `bounds.json`).
    pub source_bounds: SourceBounds,
}

/// A latent effect the user can declare by name (`common_mode`, `elevation`); fitted effects
/// come from the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum LatentEffect {
    /// A daily translation of the whole network (3 latent variables).
    CommonMode,
    /// A daily vertical term linear in station elevation (1 latent variable).
    Elevation,
}

impl GnssProblem {
    /// Reads a folder laid out like the paper's `gnss/` (with a `bounds.json` when the source's
    /// bounds are not the paper's).
    pub fn read(dir: &Path) -> Result<GnssProblem> {
        data::read_dir(dir)
    }

    /// The latent effect `e` on this network.
    pub fn latent_effect(&self, e: LatentEffect) -> OwnedEffect {
        match e {
            LatentEffect::CommonMode => OwnedEffect::CommonMode,
            LatentEffect::Elevation => OwnedEffect::Elevation {
                z_ref_km: self.network.mean_elevation() as f32,
            },
        }
    }
}

/// Bounds of an effect's latent variables (mm for a translation, mm/km for the elevation slope,
/// 10⁶ m³ for a second source's ΔV).
pub fn effect_bounds(e: &OwnedEffect) -> Vec<[f64; 2]> {
    match e {
        OwnedEffect::CommonMode => vec![[-30.0, 30.0]; 3],
        OwnedEffect::Elevation { .. } => vec![[-200.0, 200.0]],
        OwnedEffect::SecondSource { .. } => vec![[-10.0, 10.0]],
        _ => vec![],
    }
}

/// Paper Table 4 (train, valid, test).
pub const PAPER_TABLE4: [PaperRow; 3] = [
    (ModelKind::A, [0.4389, 0.9119, 0.6324]),
    (ModelKind::B, [0.6998, 0.9721, 0.8095]),
    (ModelKind::C, [0.4803, 0.9338, 0.7110]),
];

impl Problem for GnssProblem {
    type Residuals = GnssResiduals;

    fn name(&self) -> &'static str {
        "mogi"
    }
    fn physics_name(&self) -> &'static str {
        "Mogi"
    }
    fn data(&self) -> &Dataset {
        &self.data
    }
    fn recipe(&self) -> TrainConfig {
        TrainConfig::gnss()
    }
    fn bounds(&self, effects: &[OwnedEffect]) -> Vec<[f64; 2]> {
        let mut b = self.source_bounds.0.to_vec();
        for e in effects {
            b.extend(effect_bounds(e));
        }
        b
    }
    fn physics(&self, effects: &[OwnedEffect]) -> Result<Arc<dyn Physics>> {
        Ok(Arc::new(MogiPhysics::new(
            self.network.stations.clone(),
            effects.to_vec(),
        )))
    }
    fn check_effects(&self, effects: &[OwnedEffect]) -> Result<()> {
        for e in effects {
            if matches!(
                e,
                OwnedEffect::Illumination { .. } | OwnedEffect::BandOffset { .. }
            ) {
                bail!(
                    "{} is an effect of the forest spectra, not of a GNSS network",
                    e.family()
                );
            }
        }
        Ok(())
    }
    fn spec(&self) -> Result<magic_core::Problem<'static>> {
        self.network.spec()
    }
    fn paper_table(&self) -> Vec<PaperRow> {
        PAPER_TABLE4.to_vec()
    }
    fn metrics(&self, model: &Model<'_>) -> Result<Vec<Metric>> {
        plausibility::metrics(model, &self.data, SplitName::Test)
    }
    fn baseline(&self, effects: &[OwnedEffect]) -> Result<Vec<Metric>> {
        let r = classical::fit_split(self, SplitName::Test, effects)?;
        Ok(classical::metrics(&r))
    }
    /// The whole record: an effect confined to any period is looked for where it is.
    fn default_splits(&self) -> Vec<SplitName> {
        SplitName::ALL.to_vec()
    }
    fn residuals(&self, model: &Model<'_>, opts: &AnalysisOptions) -> Result<GnssResiduals> {
        residuals::residuals(
            self,
            model,
            &opts.splits_for(self),
            opts.main_source,
            opts.extra_sources,
        )
    }
    fn families(&self, opts: &AnalysisOptions) -> Vec<Box<dyn DynFamily<GnssResiduals>>> {
        families::all_with(opts.lasting)
    }
    /// A step at a higher-ranked lasting source's onset is that onset ([`families::onset`]);
    /// one at a station a higher-ranked drift moves is that drift ([`families::drifting`]).
    fn reconcile(&self, res: &GnssResiduals, effects: &mut [Candidate]) {
        families::onset::mark_onsets(&res.ctx.network, effects);
        families::drifting::mark_drifting(&res.ctx.network, effects);
    }
    fn describe_residuals(&self, res: &GnssResiduals) -> (serde_json::Value, String) {
        res.describe()
    }
    fn write_series(&self, res: &GnssResiduals, dir: &Path) -> Result<()> {
        residuals::series::write(res, dir)
    }
    fn analysis_plots(&self, res: &GnssResiduals, a: &Analysis, dir: &Path) -> Result<()> {
        report::analysis_plots(res, a, dir)
    }
    fn loop_plots(&self, first: &Model<'_>, last: &Model<'_>, dir: &Path) -> Result<Vec<String>> {
        report::before_after(self, first, last, dir)
    }
}
