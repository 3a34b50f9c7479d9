//! Synthetic GNSS data on the Akutan network (or another, [`Site`]), in the exact layout of the
//! paper's `gnss/` folder,
//! so every command reads it like measured data; with the truth behind it (`truth.json`), so the
//! residual analysis and the loop can be checked against what was injected
//! ([`crate::gnss::recovery`]).
//!
//! A dataset is a [`Spec`]: a [`Scenario`] (which effects are hidden in the data, see
//! [`Scenario::ALL`]), a seed, a [`NoiseModel`] (the generator of the noise and of the main
//! source's history, on its own [`Layout`] of the record) and a placement (the period —
//! training, validation or test — in which events such as a step or a second source begin).
//! The data are the main source's field ([`source`]) plus the noise ([`noise`]) plus every
//! injected effect ([`inject`], one module per family); standardisation uses the training
//! split's mean and standard deviation, as in the release ([`record`]).
//!
//! Two generators, so the project's recovery check is not tuned to one: `paper` (the original
//! one: white noise and a slow AR(1) per series, a white daily common mode, five source
//! episodes) and `red` (an independent one: per-series white noise of differing levels, AR(1)
//! per series with φ = 0.98, a network common mode that is itself AR(1) with an annual term,
//! a 2008 inflation and a smaller 2021 pulse of the main source, on the release's 2006–2024
//! record).

pub(crate) mod draw;
pub mod inject;
pub mod noise;
pub mod record;
pub mod scenario;
pub mod site;
pub mod source;
pub mod truth;

pub use draw::normal;
pub use inject::second_source::resolvable;
pub use noise::NoiseModel;
pub use record::{iso_date, Layout};
pub use scenario::{Distance, Injection, Scenario, Shape};
pub use site::Site;
pub use source::SOURCE;

use super::{GnssProblem, Network};
use crate::data::SplitName;
use inject::Ctx;
use magic_core::mogi;

/// The 12-station Akutan network (names and local coordinates in km, from the paper's release).
pub const AKUTAN: [(&str, f64, f64, f64); 12] = [
    ("AKGG", -4.244574836673032, 6.221955042489944, 0.350196119),
    ("AKLV", -1.7677533644105052, 2.2725848191107487, 0.54330034),
    ("AKMO", -5.477920742318134, -5.790374836251886, 0.297990048),
    ("AKRB", -9.32902438456132, -1.4528091110080028, 0.364130125),
    ("AV06", 10.695067474877963, 0.5454036872172899, 0.463075431),
    ("AV07", -7.188493723225915, 2.29941031417796, 0.521042586),
    ("AV08", -6.519939868860499, -0.6656350960809836, 0.598389266),
    ("AV10", -0.3225714797235971, -4.97215110923805, 0.329520899),
    ("AV12", 2.0491837994025177, 7.626908495832568, 0.404696868),
    ("AV13", 2.034404208043046, 1.2023486352773183, 0.494730786),
    ("AV14", 5.726242766165519, -2.6029585922179708, 0.396322137),
    ("AV15", 14.35703605108024, -4.684531481081493, 0.457414694),
];

/// Days in the test, training and validation periods of the `paper` generator (in that order
/// in time).
pub const PERIODS: [usize; 3] = Layout::PAPER.periods;

/// What to generate: scenario, seed, noise model and the period events are placed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Spec {
    /// Which effects are hidden in the data.
    pub scenario: Scenario,
    /// Random seed.
    pub seed: u64,
    /// The generator of the noise and of the main source's history.
    pub noise: NoiseModel,
    /// The period in which events (a step, a second source) begin.
    pub placement: SplitName,
}

impl Spec {
    /// `scenario` with the original generator, events in the training period.
    pub fn new(scenario: Scenario, seed: u64) -> Spec {
        Spec {
            scenario,
            seed,
            noise: NoiseModel::Paper,
            placement: SplitName::Train,
        }
    }

    /// The same with another noise model.
    pub fn noise(self, noise: NoiseModel) -> Spec {
        Spec { noise, ..self }
    }

    /// The same with events placed in `placement`.
    pub fn placed(self, placement: SplitName) -> Spec {
        Spec { placement, ..self }
    }

    /// The placement as reports print it: `-` when the scenario has no event to place.
    pub fn placement_label(&self) -> &'static str {
        if self.scenario.has_event() {
            self.placement.as_str()
        } else {
            "-"
        }
    }

    /// Generates the dataset on the Akutan network ([`Site::akutan`]).
    pub fn generate(&self) -> Synthetic {
        self.generate_on(&Site::akutan())
            .expect("every scenario has room on the Akutan network (tested)")
    }

    /// Generates the dataset on `site`; an error when a scenario's source has no room on its
    /// network.
    pub fn generate_on(&self, site: &Site) -> anyhow::Result<Synthetic> {
        let layout = self.noise.layout();
        let network = site.network.clone();
        let (history, mut mm, background) =
            self.noise
                .clean_rows(self.seed, &network, site.source, &layout);
        let ctx = Ctx {
            network: &network,
            main: site.source,
            apart_box: site.apart_box,
            layout,
            placement: self.placement,
            background: &background,
            seed: self.seed,
        };
        let effects: Vec<truth::Injected> = self
            .scenario
            .injections()
            .iter()
            .map(|inj| inj.inject(&ctx, &mut mm))
            .collect::<anyhow::Result<_>>()?;
        let data = record::dataset(&layout, &network, &mm, self.source_label());
        let truth = truth::truth(self, site.source, &history, &effects, &background.described);
        Ok(Synthetic {
            problem: GnssProblem {
                network,
                data,
                source_bounds: site.bounds,
            },
            dv: history.dv,
            truth,
        })
    }

    fn source_label(&self) -> String {
        let base = format!(
            "synthetic (scenario {}, seed {}",
            self.scenario.name(),
            self.seed
        );
        if self.noise == NoiseModel::Paper && self.placement == SplitName::Train {
            base + ")"
        } else {
            format!(
                "{base}, noise {}, placement {})",
                self.noise.name(),
                self.placement_label()
            )
        }
    }
}

/// A generated dataset with the truth behind it.
pub struct Synthetic {
    /// The data, standardised like the release.
    pub problem: GnssProblem,
    /// The main source's volume change per day (10⁶ m³), over the record in time order.
    pub dv: Vec<f64>,
    /// What was injected (`truth.json`, see [`truth`]).
    pub truth: serde_json::Value,
}

/// Generates `scenario` with the original (`paper`) generator, events in the training period.
pub fn generate(scenario: Scenario, seed: u64) -> Synthetic {
    Spec::new(scenario, seed).generate()
}

/// The main source's field at `main` (mm, channel order uₑ ×S, uₙ ×S, uᵥ ×S) on every day of `dv`.
fn source_rows(network: &Network, main: [f64; 3], dv: &[f64]) -> Vec<Vec<f64>> {
    let mut u = vec![0.0f64; 3 * network.len()];
    dv.iter()
        .map(|v| {
            let p = [main[0], main[1], main[2], *v];
            mogi::field(&network.stations, &p, &mut u).expect("valid synthetic source");
            u.clone()
        })
        .collect()
}

#[cfg(test)]
mod tests;
