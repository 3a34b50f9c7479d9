//! The scenarios: which effects are hidden in a synthetic dataset ([`Scenario`]), each a list of
//! [`Injection`]s. `magic synth --list` prints them.

use super::inject::{self, Ctx};
use super::truth::Injected;
use anyhow::Result;

/// The time course of a second source's volume change.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// Inflating then deflating back (or the reverse) within 200–500 days.
    Pulse,
    /// A deflation (ΔV −0.8 to −1.1·10⁶ m³) building over 2–4 months, then staying.
    Lasting,
}

/// Where a second source lies relative to the main one (always resolvable from it: see
/// [`super::resolvable`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distance {
    /// At least 5 km away, anywhere over the network (the original scenario).
    Apart,
    /// 2–4 km from the main source.
    Near,
    /// 6–12 km from it, within the network's box ± 2 km.
    Far,
    /// Within 1 km (horizontally) of a station at least 5 km from it, 1.5–2.5 km deep: a
    /// source that station sees most of.
    UnderStation,
}

/// One injected effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Injection {
    /// A network translation wandering over weeks to months.
    CommonMode,
    /// Per-station annual and semiannual terms.
    Seasonal,
    /// A vertical term linear in station elevation.
    Elevation,
    /// An offset at one station from an epoch on.
    Step,
    /// Another offset like [`Injection::Step`]'s, at another station than its.
    StepElsewhere,
    /// A second Mogi source.
    SecondSource {
        /// Its time course.
        shape: Shape,
        /// Its distance from the main source.
        distance: Distance,
    },
    /// Linear drifts at one to three stations.
    Drift,
}

impl Injection {
    /// The family the analysis should find (`truth.json`'s `family`).
    pub fn family(self) -> &'static str {
        match self {
            Injection::CommonMode => "common_mode",
            Injection::Seasonal => "seasonal",
            Injection::Elevation => "elevation",
            Injection::Step | Injection::StepElsewhere => "step",
            Injection::SecondSource {
                shape: Shape::Lasting,
                ..
            } => "lasting_source",
            Injection::SecondSource { .. } => "second_source",
            Injection::Drift => "drift",
        }
    }

    /// Whether it begins at a time (and so has a placement), rather than lasting throughout.
    pub fn is_event(self) -> bool {
        matches!(
            self,
            Injection::Step | Injection::StepElsewhere | Injection::SecondSource { .. }
        )
    }

    /// The salt of its random stream. An effect draws the same parameters in every scenario
    /// holding it (`step+elevation` holds the step of `step` and the elevation term of
    /// `elevation` for the same seed); the single-family salts are those of the original
    /// generator.
    fn salt(self) -> u64 {
        let k = match self {
            Injection::CommonMode => 1,
            Injection::Seasonal => 2,
            Injection::Elevation => 3,
            Injection::Step => 4,
            Injection::SecondSource { shape, distance } => match (shape, distance) {
                (Shape::Pulse, Distance::Apart) => 5,
                (Shape::Pulse, Distance::Near) => 7,
                (Shape::Pulse, Distance::Far) => 8,
                (Shape::Lasting, Distance::Near) => 9,
                (Shape::Lasting, Distance::Far) => 10,
                (Shape::Lasting, Distance::Apart) => 11,
                (Shape::Lasting, Distance::UnderStation) => 13,
                (Shape::Pulse, Distance::UnderStation) => 14,
            },
            Injection::Drift => 6,
            Injection::StepElsewhere => 12,
        };
        0xEFFE_C700 + k
    }

    /// Adds the effect to `rows` (mm, one row per day of the record) and returns what was
    /// added.
    pub fn inject(self, ctx: &Ctx<'_>, rows: &mut [Vec<f64>]) -> anyhow::Result<Injected> {
        let mut rng = super::draw::stream(ctx.seed, self.salt());
        let rng = &mut rng;
        let params = match self {
            Injection::CommonMode => inject::common_mode::inject(ctx, rng, rows),
            Injection::Seasonal => inject::seasonal::inject(ctx, rng, rows),
            Injection::Elevation => inject::elevation::inject(ctx, rng, rows),
            Injection::Step => inject::step::inject(ctx, rng, rows),
            Injection::StepElsewhere => {
                let mut first = super::draw::stream(ctx.seed, Injection::Step.salt());
                let first = inject::step::station(ctx, &mut first);
                inject::step::inject_elsewhere(ctx, rng, rows, first)
            }
            Injection::SecondSource { shape, distance } => {
                inject::second_source::inject(ctx, rng, rows, shape, distance)?
            }
            Injection::Drift => inject::drift::inject(ctx, rng, rows),
        };
        Ok(Injected::new(self.family(), params))
    }
}

/// The scenario: which effects, if any, are hidden in the data.
///
/// Every scenario starts from the same clean data for a given seed and noise model (each effect
/// draws its parameters from a stream of its own), so a scenario is `clean` plus its effects.
/// Amplitudes are of the order of the noise (a few mm). Effects that are not events are present
/// throughout the record; events (a step, a second source) begin in the period the placement
/// names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum Scenario {
    /// Main-source transients and noise only.
    Clean,
    /// A network translation (E, N, U) wandering over weeks to months (an AR(1) with a 60-day
    /// time scale), RMS 1.5–3 mm horizontally and 3–6 mm vertically.
    CommonMode,
    /// Per-station annual and semiannual terms with random amplitudes and phases.
    Seasonal,
    /// A vertical term k(t)·(zᵢ − z̄) with k varying over weeks and seasons (RMS 25–50 mm/km).
    Elevation,
    /// A step of a few mm (3–6 mm horizontal, 6–12 mm vertical) at one station.
    Step,
    /// A second Mogi source 4–8 km deep, at least 5 km from the main one, inflating then
    /// deflating (or the reverse) within 200–500 days, with 6–9 mm (network RMS at the peak)
    /// of its field beyond what moving the main source can mimic.
    SecondSource,
    /// A linear drift (a few mm/yr) at one to three stations over the whole record.
    Drift,
    /// A second source pulse like `second_source`, 2–4 km from the main source and 3–4 km deep
    /// (resolvable share at least 0.25 there).
    SecondSourceNear,
    /// A second source pulse like `second_source`, 6–12 km from the main source (within the
    /// network's box ± 2 km).
    SecondSourceFar,
    /// A lasting deflation (−0.8 to −1.1·10⁶ m³, 3–4 km deep, building over 2–4 months, then
    /// staying) 2–4 km from the main source.
    LastingDeflationNear,
    /// The same 6–12 km from the main source (within the network's box ± 2 km).
    LastingDeflationFar,
    /// A shallow lasting deflation (1.5–2.5 km deep) within 1 km of a station at least 5 km
    /// from the main source, moving that station 20–40 mm (building over 2–4 months, then
    /// staying): a source one station sees most of, the others a few mm.
    LastingDeflationUnderStation,
    /// `step` and `elevation` together.
    #[value(name = "step+elevation")]
    StepElevation,
    /// `second_source` and `step` together.
    #[value(name = "second_source+step")]
    SecondSourceStep,
    /// `common_mode` and `seasonal` together.
    #[value(name = "common_mode+seasonal")]
    CommonModeSeasonal,
    /// Two extra sources: the pulse of `second_source` and the lasting deflation of
    /// `lasting_deflation_far`, both in the placement's period.
    #[value(name = "second_source+lasting_source")]
    TwoSources,
    /// Two steps: `step`'s and another like it at another station, its epoch drawn on its own
    /// in the same period.
    #[value(name = "step+step")]
    TwoSteps,
}

const PULSE: Injection = Injection::SecondSource {
    shape: Shape::Pulse,
    distance: Distance::Apart,
};

impl Scenario {
    /// Every scenario, `clean` first, then the single effects, then two effects at once.
    pub const ALL: [Scenario; 17] = [
        Scenario::Clean,
        Scenario::CommonMode,
        Scenario::Seasonal,
        Scenario::Elevation,
        Scenario::Step,
        Scenario::SecondSource,
        Scenario::Drift,
        Scenario::SecondSourceNear,
        Scenario::SecondSourceFar,
        Scenario::LastingDeflationNear,
        Scenario::LastingDeflationFar,
        Scenario::LastingDeflationUnderStation,
        Scenario::StepElevation,
        Scenario::SecondSourceStep,
        Scenario::CommonModeSeasonal,
        Scenario::TwoSources,
        Scenario::TwoSteps,
    ];

    /// The scenario's name (the family it injects, `clean`, or the families joined by `+`).
    pub fn name(self) -> &'static str {
        match self {
            Scenario::Clean => "clean",
            Scenario::CommonMode => "common_mode",
            Scenario::Seasonal => "seasonal",
            Scenario::Elevation => "elevation",
            Scenario::Step => "step",
            Scenario::SecondSource => "second_source",
            Scenario::Drift => "drift",
            Scenario::SecondSourceNear => "second_source_near",
            Scenario::SecondSourceFar => "second_source_far",
            Scenario::LastingDeflationNear => "lasting_deflation_near",
            Scenario::LastingDeflationFar => "lasting_deflation_far",
            Scenario::LastingDeflationUnderStation => "lasting_deflation_under_station",
            Scenario::StepElevation => "step+elevation",
            Scenario::SecondSourceStep => "second_source+step",
            Scenario::CommonModeSeasonal => "common_mode+seasonal",
            Scenario::TwoSources => "second_source+lasting_source",
            Scenario::TwoSteps => "step+step",
        }
    }

    /// What the scenario injects, in order.
    pub fn injections(self) -> Vec<Injection> {
        let source = |shape, distance| Injection::SecondSource { shape, distance };
        match self {
            Scenario::Clean => vec![],
            Scenario::CommonMode => vec![Injection::CommonMode],
            Scenario::Seasonal => vec![Injection::Seasonal],
            Scenario::Elevation => vec![Injection::Elevation],
            Scenario::Step => vec![Injection::Step],
            Scenario::SecondSource => vec![PULSE],
            Scenario::Drift => vec![Injection::Drift],
            Scenario::SecondSourceNear => vec![source(Shape::Pulse, Distance::Near)],
            Scenario::SecondSourceFar => vec![source(Shape::Pulse, Distance::Far)],
            Scenario::LastingDeflationNear => vec![source(Shape::Lasting, Distance::Near)],
            Scenario::LastingDeflationFar => vec![source(Shape::Lasting, Distance::Far)],
            Scenario::LastingDeflationUnderStation => {
                vec![source(Shape::Lasting, Distance::UnderStation)]
            }
            Scenario::StepElevation => vec![Injection::Step, Injection::Elevation],
            Scenario::SecondSourceStep => vec![PULSE, Injection::Step],
            Scenario::CommonModeSeasonal => vec![Injection::CommonMode, Injection::Seasonal],
            Scenario::TwoSources => vec![PULSE, source(Shape::Lasting, Distance::Far)],
            Scenario::TwoSteps => vec![Injection::Step, Injection::StepElsewhere],
        }
    }

    /// Whether it holds an event, whose period the placement chooses.
    pub fn has_event(self) -> bool {
        self.injections().iter().any(|i| i.is_event())
    }

    /// One line describing the scenario (its documentation).
    pub fn describe(self) -> String {
        use clap::ValueEnum;
        self.to_possible_value()
            .and_then(|v| v.get_help().map(|h| h.to_string()))
            .unwrap_or_default()
    }

    /// Parses a scenario name.
    pub fn parse(name: &str) -> Result<Scenario> {
        Scenario::ALL
            .iter()
            .copied()
            .find(|s| s.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = Scenario::ALL.iter().map(|s| s.name()).collect();
                anyhow::anyhow!(
                    "unknown scenario `{name}` (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// The scenario list as `magic synth --list` prints it: name, families, whether it can be
/// placed, description.
pub fn list() -> String {
    let mut s = String::new();
    for sc in Scenario::ALL {
        let fams: Vec<&str> = sc.injections().iter().map(|i| i.family()).collect();
        s += &format!(
            "{:<29} {:<29} {:<9} {}\n",
            sc.name(),
            if fams.is_empty() {
                "-".to_string()
            } else {
                fams.join(",")
            },
            if sc.has_event() { "placeable" } else { "-" },
            sc.describe().replace('\n', " ")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_match_clap() {
        use clap::ValueEnum;
        for sc in Scenario::ALL {
            assert_eq!(Scenario::parse(sc.name()).unwrap(), sc);
            assert_eq!(Scenario::from_str(sc.name(), false).unwrap(), sc);
            assert!(!sc.describe().is_empty(), "{}", sc.name());
        }
        assert_eq!(Scenario::value_variants().len(), Scenario::ALL.len());
        assert!(Scenario::parse("nope").is_err());
    }

    #[test]
    fn single_family_scenarios_are_named_after_their_family() {
        for sc in &Scenario::ALL[1..7] {
            assert_eq!(sc.injections().len(), 1);
            assert_eq!(sc.injections()[0].family(), sc.name());
        }
        for sc in [
            Scenario::StepElevation,
            Scenario::SecondSourceStep,
            Scenario::CommonModeSeasonal,
            Scenario::TwoSources,
            Scenario::TwoSteps,
        ] {
            let fams: Vec<&str> = sc.injections().iter().map(|i| i.family()).collect();
            assert_eq!(fams.join("+"), sc.name());
        }
    }
}
