//! Residual analysis, for every problem: which declared effect does F lack?
//!
//! A model's residuals (what F, with the variables the encoder infers, leaves of each
//! observation) are computed by the [`Problem`]; each of its effect [`Family`]s is fitted to them,
//! scored by the share of residual variance it explains on held-out data, and compared with the
//! same score on surrogates that keep the noise's structure but not the family's
//! ([`DynFamily::assess`]); the candidates are ranked, the significant ones first, by their
//! excess over chance ([`Candidate`], [`rank`]). The loop ([`crate::closed_loop`]) adds the top
//! significant, declarable one to F.

mod candidate;
mod family;
mod held_part;
pub mod projection;
mod rejection;
pub mod score;
pub mod surrogate;

pub use candidate::{
    rank, stands_out, stands_out_by, Candidate, ParamSd, MIN_EXCESS, SD_MARGIN, STAT_SD_MARGIN,
};
pub use family::{judge, surrogate_seeds, Chance, DynFamily, Family};
pub use held_part::HeldPart;
pub use rejection::{Rejection, Side};

use crate::data::SplitName;
use crate::model::OwnedEffect;
use crate::problem::Problem;
use anyhow::Result;
use magic_core::{Model, Variant};
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;

/// How the volcano's analysis treats the main source (the forest's ignores it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum MainSource {
    /// Free to move every day, as the encoder moves it: whatever its position, depth or volume
    /// can produce is projected off the residuals. Point sources are located with the main
    /// source held (their field near the main one kept whole, so their depth is fixed) and
    /// scored there too; a candidate whose field is mostly a move of the main source is
    /// rejected.
    #[default]
    Free,
    /// Held in place, its volume changing: only its field's direction is projected off, so a
    /// second source near it stays in the residuals. A main source that does move between its
    /// episodes then shows as a second source beside it.
    Held,
}

/// The volcano: how a change that stays is detected (the forest has none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LastingStatistic {
    /// Located by the network's offsets over 180-day windows, detected by its gain on held-out
    /// stations beyond its surrogates' (the default until the matched filter replaced it; kept
    /// for comparison, docs/matched-filter.md).
    Scan,
    /// Located and detected by a matched filter: the residuals whitened by white plus AR(1)
    /// noise fitted to them, a 90-day ramp at every onset, every station at its own weight; its
    /// z standing out of its surrogates' detects, the held-out gain need only be above 0
    /// (docs/matched-filter.md). The default: it finds more changes at the record's ends.
    #[default]
    Matched,
}

/// Options of [`analyse`], checked once by the problem's residuals.
#[derive(Clone, Debug)]
pub struct AnalysisOptions {
    /// The splits analysed (`None`: the problem's default, [`Problem::default_splits`]). How
    /// they are held out is the problem's: the volcano analyses its whole record and holds out
    /// stations and blocks of days; the forest fits on the first split and scores on the others
    /// (other sites).
    pub splits: Option<Vec<SplitName>>,
    /// Surrogates per family for the chance level.
    pub surrogates: usize,
    /// Quantile of the surrogate scores taken as the chance level.
    pub quantile: f64,
    /// Seed of the surrogates and of the bootstrap.
    pub seed: u64,
    /// Bootstrap draws for the uncertainty of a significant candidate's key parameters (0: none).
    pub bootstrap: usize,
    /// The volcano's main source, free to move or held in place.
    pub main_source: MainSource,
    /// The volcano: the most extra sources F may hold. Where F holds fewer, a new source must
    /// be told from the declared ones and from their trade with the main source
    /// ([`Context::sources_span`](crate::gnss::residuals::Context::sources_span)); the loop
    /// adds none beyond it.
    pub extra_sources: usize,
    /// The volcano: the most steps F may hold, each at its own station and time
    /// ([`OwnedEffect::same_term`]); the loop adds none beyond it.
    pub steps: usize,
    /// The volcano: how a change that stays is detected.
    pub lasting: LastingStatistic,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        AnalysisOptions {
            splits: None,
            surrogates: 20,
            quantile: 0.95,
            seed: 0,
            bootstrap: 20,
            main_source: MainSource::Free,
            extra_sources: 1,
            steps: 1,
            lasting: LastingStatistic::default(),
        }
    }
}

impl AnalysisOptions {
    /// The most terms of `e`'s family F may hold: [`extra_sources`](Self::extra_sources) for
    /// a point source, [`steps`](Self::steps) for a step, one of any other family.
    pub fn most_terms(&self, e: &OwnedEffect) -> usize {
        match e {
            OwnedEffect::SecondSource { .. } => self.extra_sources,
            OwnedEffect::Step { .. } => self.steps,
            _ => 1,
        }
    }

    /// The analysed splits for `problem`, without repeats.
    pub fn splits_for<P: Problem + ?Sized>(&self, problem: &P) -> Vec<SplitName> {
        let mut out: Vec<SplitName> = Vec::new();
        for s in self
            .splits
            .clone()
            .unwrap_or_else(|| problem.default_splits())
        {
            if !out.contains(&s) {
                out.push(s);
            }
        }
        out
    }
}

/// Where an effect stands against F's declared ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Term {
    /// F declares it already ([`OwnedEffect::same_term`]).
    Declared,
    /// Another term of a family F holds as many of as the options allow.
    Beyond,
    /// Another term F may take.
    New,
}

/// Where `e` stands against `declared` under `opts` ([`AnalysisOptions::most_terms`]).
fn term(declared: &[OwnedEffect], e: &OwnedEffect, opts: &AnalysisOptions) -> Term {
    let held = declared.iter().filter(|d| d.family() == e.family()).count();
    if declared.iter().any(|d| d.same_term(e)) {
        Term::Declared
    } else if held >= opts.most_terms(e) {
        Term::Beyond
    } else {
        Term::New
    }
}

/// The result of [`analyse`].
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The problem's name.
    pub problem: &'static str,
    /// Analysed splits.
    pub splits: Vec<SplitName>,
    /// Candidates ranked ([`rank`]): the significant ones first, each group by excess over
    /// chance, descending.
    pub effects: Vec<Candidate>,
    /// What the problem reports about the residuals themselves.
    pub residuals: serde_json::Value,
    /// One line summing the residuals up.
    pub summary: String,
    /// Seconds the analysis took.
    pub seconds: f64,
}

impl Analysis {
    /// The most significant candidate that can be added to F and whose effect F does not
    /// declare yet (`declared`: F's effects). The effect, not the candidate's family, decides
    /// ([`OwnedEffect::same_term`]): two candidate families may declare the same term (a second
    /// source found as an episode or as a change that stays), and a source found again where F
    /// has one would buy the encoder another free variable for whatever the first one left, not
    /// a second effect. A source elsewhere, or a step at another station or time, is another
    /// term, taken while F holds fewer of its family than `opts` allows
    /// ([`AnalysisOptions::most_terms`]). F holds at most
    /// [`MAX_EFFECTS`](magic_core::effects::MAX_EFFECTS) effects.
    pub fn top_declarable(
        &self,
        declared: &[OwnedEffect],
        opts: &AnalysisOptions,
    ) -> Option<&Candidate> {
        self.next_declarable(declared, &[], opts)
    }

    /// As [`top_declarable`](Self::top_declarable), passing over the candidates whose effect is
    /// one of `taken_out` ([`OwnedEffect::same_term`]): added to F and taken out again, the loop
    /// tries the next.
    pub fn next_declarable(
        &self,
        declared: &[OwnedEffect],
        taken_out: &[OwnedEffect],
        opts: &AnalysisOptions,
    ) -> Option<&Candidate> {
        if declared.len() >= magic_core::effects::MAX_EFFECTS {
            return None;
        }
        let new_term = |e: &OwnedEffect| {
            term(declared, e, opts) == Term::New && !taken_out.iter().any(|t| t.same_term(e))
        };
        self.effects
            .iter()
            .find(|c| c.significant && c.effect.as_ref().is_some_and(new_term))
    }

    /// The families of the significant candidates that F does not declare yet but may hold no
    /// more of (`opts`, [`AnalysisOptions::most_terms`]): a source elsewhere with F's extra
    /// sources all taken, a step elsewhere with its steps all taken. The loop's stop says which
    /// option would take them.
    pub fn beyond_capacity(&self, declared: &[OwnedEffect], opts: &AnalysisOptions) -> Vec<String> {
        let beyond = |e: &OwnedEffect| term(declared, e, opts) == Term::Beyond;
        let mut out: Vec<String> = Vec::new();
        for c in &self.effects {
            if c.significant && c.effect.as_ref().is_some_and(beyond) && !out.contains(&c.family) {
                out.push(c.family.clone());
            }
        }
        out
    }

    /// Whether F holds as many effects as a model file carries
    /// ([`MAX_EFFECTS`](magic_core::effects::MAX_EFFECTS)) while a significant candidate is
    /// another term than F's: no option takes it then.
    pub fn beyond_model_file(&self, declared: &[OwnedEffect], opts: &AnalysisOptions) -> bool {
        let other = |e: &OwnedEffect| term(declared, e, opts) != Term::Declared;
        declared.len() >= magic_core::effects::MAX_EFFECTS
            && self
                .effects
                .iter()
                .any(|c| c.significant && c.effect.as_ref().is_some_and(other))
    }

    /// The JSON report (`{"effects": [{"family", "variance_explained", "chance_level",
    /// "significant", "params", …}, …], "residuals": {…}, …}`).
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "problem": self.problem,
            "splits": self.splits,
            "effects": self.effects.iter().map(Candidate::to_json).collect::<Vec<_>>(),
            "residuals": self.residuals,
            "seconds": self.seconds,
        })
    }

    /// A text table of the candidates.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{}", self.summary);
        let _ = writeln!(
            s,
            "{:<14} {:>10} {:>10} {:>10} {:>8}  params",
            "family", "explained", "chance", "excess", "signif."
        );
        for c in &self.effects {
            let _ = writeln!(
                s,
                "{:<14} {:>9.2}% {:>9.2}% {:>9.2}% {:>8}  {}",
                c.family,
                100.0 * c.variance_explained,
                100.0 * c.chance_level,
                100.0 * c.excess(),
                if c.significant { "yes" } else { "no" },
                compact(&c.params)
            );
            for p in &c.uncertainty {
                let _ = writeln!(
                    s,
                    "{:>16} {} = {:.4} ± {:.4} (bootstrap sd)",
                    "", p.name, p.value, p.sd
                );
            }
            if let Some(why) = &c.rejected {
                let _ = writeln!(s, "{:>16} rejected: {why}", "");
            }
        }
        s
    }
}

/// At most 160 characters of a JSON value.
fn compact(v: &serde_json::Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 160 {
        format!("{}…", s.chars().take(157).collect::<String>())
    } else {
        s
    }
}

/// Fits every family of `problem` to the residuals of `model` and ranks them ([`rank`]: the
/// significant ones first, by excess over chance), again after the problem has reconciled them;
/// returns the residuals too (for the problem's figures).
pub fn analyse<P: Problem + ?Sized>(
    problem: &P,
    model: &Model<'_>,
    opts: &AnalysisOptions,
) -> Result<(Analysis, P::Residuals)> {
    let start = std::time::Instant::now();
    if model.variant == Variant::A {
        anyhow::bail!("residual analysis needs a model with physics (variant B or C), not A");
    }
    let res = problem.residuals(model, opts)?;
    let mut effects = problem
        .families(opts)
        .iter()
        .map(|f| f.assess(&res, opts))
        .collect::<Result<Vec<_>>>()?;
    rank(&mut effects);
    problem.reconcile(&res, &mut effects);
    rank(&mut effects);
    let (residuals, summary) = problem.describe_residuals(&res);
    Ok((
        Analysis {
            problem: problem.name(),
            splits: opts.splits_for(problem),
            effects,
            residuals,
            summary,
            seconds: start.elapsed().as_secs_f64(),
        },
        res,
    ))
}

/// A bar per candidate: the share explained (%), a tick at its chance level, `*` when
/// significant.
pub fn effects_chart(path: &Path, title: &str, effects: &[Candidate]) -> Result<()> {
    let labels: Vec<String> = effects
        .iter()
        .map(|c| {
            if c.significant {
                format!("{} *", c.family)
            } else {
                c.family.clone()
            }
        })
        .collect();
    let values: Vec<f64> = effects
        .iter()
        .map(|c| 100.0 * c.variance_explained)
        .collect();
    let chance: Vec<f64> = effects.iter().map(|c| 100.0 * c.chance_level).collect();
    crate::report::plots::bar_chart(path, title, &labels, &values, &chance)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn significant(family: &str, score: f64, effect: OwnedEffect) -> Candidate {
        let noise = vec![0.010, 0.012, 0.008, 0.011, 0.009, 0.010, 0.013, 0.007];
        let mut c = Candidate::from_scores(family, score, noise, 0.95, json!({}), None);
        c.effect = Some(effect);
        c
    }

    /// An analysis holding `effects`, ranked as given.
    fn analysed(effects: Vec<Candidate>) -> Analysis {
        Analysis {
            problem: "mogi",
            splits: vec![],
            effects,
            residuals: json!({}),
            summary: String::new(),
            seconds: 0.0,
        }
    }

    #[test]
    fn a_declared_term_is_not_added_again_but_a_source_elsewhere_is() {
        let source = OwnedEffect::SecondSource {
            x_km: 1.0,
            y_km: -2.0,
            depth_km: 4.0,
        };
        let analysis = analysed(vec![
            significant("lasting_source", 0.3, source.clone()),
            significant("second_source", 0.2, source),
            significant("common_mode", 0.1, OwnedEffect::CommonMode),
        ]);
        let two = AnalysisOptions {
            extra_sources: 2,
            ..AnalysisOptions::default()
        };
        let top = |declared: &[OwnedEffect]| {
            analysis
                .top_declarable(declared, &two)
                .map(|c| c.family.clone())
        };
        let near = OwnedEffect::SecondSource {
            x_km: 2.0,
            y_km: -2.5,
            depth_km: 4.5,
        };
        let far = OwnedEffect::SecondSource {
            x_km: 6.0,
            y_km: 3.0,
            depth_km: 4.0,
        };
        assert_eq!(top(&[]).as_deref(), Some("lasting_source"));
        assert_eq!(
            top(std::slice::from_ref(&near)).as_deref(),
            Some("common_mode")
        );
        assert_eq!(top(&[near.clone(), OwnedEffect::CommonMode]), None);
        // A source 7 km from the declared one is a second term.
        assert_eq!(
            top(std::slice::from_ref(&far)).as_deref(),
            Some("lasting_source")
        );
        // With one extra source allowed, F's one is the only one.
        let one = analysis.top_declarable(std::slice::from_ref(&far), &AnalysisOptions::default());
        assert_eq!(one.map(|c| c.family.as_str()), Some("common_mode"));
        // F is full.
        let full = [far, OwnedEffect::Elevation { z_ref_km: 0.1 }];
        assert_eq!(
            top(&[
                full[0].clone(),
                full[1].clone(),
                full[1].clone(),
                full[1].clone()
            ]),
            None
        );
    }

    #[test]
    fn an_effect_taken_out_is_passed_over_with_its_term() {
        let source = |x_km: f32| OwnedEffect::SecondSource {
            x_km,
            y_km: -2.0,
            depth_km: 4.0,
        };
        let analysis = analysed(vec![
            significant("common_mode", 0.3, OwnedEffect::CommonMode),
            significant("lasting_source", 0.2, source(1.0)),
            significant("second_source", 0.1, source(1.5)),
        ]);
        let opts = AnalysisOptions::default();
        let next = |taken_out: &[OwnedEffect]| {
            analysis
                .next_declarable(&[], taken_out, &opts)
                .map(|c| c.family.as_str())
        };
        assert_eq!(next(&[]), Some("common_mode"));
        assert_eq!(next(&[OwnedEffect::CommonMode]), Some("lasting_source"));
        // A source taken out is the same term as either family's candidate within 2 km.
        assert_eq!(next(&[OwnedEffect::CommonMode, source(1.2)]), None);
        assert_eq!(
            next(&[OwnedEffect::CommonMode, source(9.0)]),
            Some("lasting_source")
        );
    }

    #[test]
    fn a_step_elsewhere_is_another_term_while_f_may_hold_it() {
        let step = |station: u16, epoch_day: f32| OwnedEffect::Step {
            station,
            epoch_day,
            offset_mm: [2.0, -1.0, 8.0],
        };
        let analysis = analysed(vec![
            significant("step", 0.3, step(4, 15_100.0)),
            significant("common_mode", 0.1, OwnedEffect::CommonMode),
        ]);
        let top = |declared: &[OwnedEffect], steps: usize| {
            let opts = AnalysisOptions {
                steps,
                ..AnalysisOptions::default()
            };
            analysis
                .top_declarable(declared, &opts)
                .map(|c| c.family.clone())
        };
        assert_eq!(top(&[], 1).as_deref(), Some("step"));
        // The same station 10 days off: the declared step found again.
        assert_eq!(top(&[step(4, 15_090.0)], 2).as_deref(), Some("common_mode"));
        // Another station, or the same one a year off: another step, if F may hold two.
        assert_eq!(top(&[step(1, 15_100.0)], 2).as_deref(), Some("step"));
        assert_eq!(top(&[step(4, 14_735.0)], 2).as_deref(), Some("step"));
        assert_eq!(top(&[step(1, 15_100.0)], 1).as_deref(), Some("common_mode"));
        let one = AnalysisOptions::default();
        assert_eq!(
            analysis.beyond_capacity(&[step(1, 15_100.0)], &one),
            ["step"]
        );
        assert!(analysis
            .beyond_capacity(&[step(4, 15_090.0)], &one)
            .is_empty());
        // F full: a step elsewhere is beyond the model file, whatever `--steps` allows; one
        // found again is not.
        let four = AnalysisOptions {
            steps: 4,
            ..AnalysisOptions::default()
        };
        let three = [
            step(1, 15_100.0),
            step(2, 15_100.0),
            OwnedEffect::CommonMode,
        ];
        let with = |last: OwnedEffect| [three.as_slice(), &[last]].concat();
        assert!(analysis.beyond_model_file(&with(step(3, 15_100.0)), &four));
        assert!(!analysis.beyond_model_file(&with(step(4, 15_090.0)), &four));
        assert!(!analysis.beyond_model_file(&three, &four));
    }
}
