//! A candidate effect: one family fitted to the residuals, its held-out score, the chance level
//! of that score from surrogates, and whether the excess is a discovery.
//!
//! **Significance.** A family is significant when its score exceeds the chance level (the
//! [`AnalysisOptions::quantile`](super::AnalysisOptions::quantile) of the surrogate scores,
//! floored at zero) by more than its margin: the score must pass the surrogates' mean plus
//! its family's margin in standard deviations on the square-root scale ([`SD_MARGIN`] unless the
//! family sets its own: [`Family::sd_margin`](super::Family::sd_margin); noise scores are close
//! to Gaussian there, the raw scores χ²-like with a heavy tail), and exceed the chance level by at
//! least [`MIN_EXCESS`] of the residual variance (negligible effects are not worth a model term;
//! a family whose score is a transient's gain sets its floor in days' worth of residual variance
//! instead: [`Family::min_excess`](super::Family::min_excess)).
//! A family with a detection statistic (the step scan's peak) is also significant when the
//! statistic [`stands_out`] of its surrogates' by a like rule and the score is above 0 (a
//! statistic that vetoes, the step's) or above chance (one that only supports): a clear local
//! effect is worth its term though it explains little of the whole network.

use super::Rejection;
use crate::model::OwnedEffect;
use crate::numerics::{quantile, sd};
use serde_json::json;

/// Smallest excess over chance (share of residual variance) that counts as a discovery.
pub const MIN_EXCESS: f64 = 0.005;
/// Standard deviations above the surrogates' mean (square-root scale) a significant score must
/// reach. Red noise makes chance coherence between a dozen stations heavy-tailed: on clean
/// synthetic data scores of 3–4 such deviations occur in a few percent of the families.
pub const SD_MARGIN: f64 = 4.0;

/// One effect family fitted to the residuals.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    /// Family name (`common_mode`, `seasonal`, …, `illumination`, `band_offset`, `species`).
    pub family: String,
    /// Share of the residual variance explained on held-out data.
    pub variance_explained: f64,
    /// Share explained by chance (quantile over surrogates, floored at 0).
    pub chance_level: f64,
    /// Whether the excess over chance is beyond the margin.
    pub significant: bool,
    /// Fitted parameters (for GNSS families, the names of `truth.json` of `magic synth`).
    pub params: serde_json::Value,
    /// The effect that adds this family to F (none when it cannot be declared, or is already).
    pub effect: Option<OwnedEffect>,
    /// Standard deviation of the surrogate scores.
    pub chance_sd: f64,
    /// The margin the excess had to exceed.
    pub margin: f64,
    /// The surrogate scores the chance level comes from.
    pub surrogate_scores: Vec<f64>,
    /// The fit's detection statistic and the surrogates' (families with one,
    /// [`Family::statistic`](super::Family::statistic)).
    pub statistic: Option<(f64, Vec<f64>)>,
    /// Why the fit cannot count as a discovery whatever its score, if it cannot.
    pub rejected: Option<Rejection>,
    /// Standard deviations of the key parameters (parametric bootstrap; significant candidates
    /// only).
    pub uncertainty: Vec<ParamSd>,
}

/// A parameter with its standard deviation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ParamSd {
    /// Name (as in the candidate's `params`).
    pub name: String,
    /// The fitted value.
    pub value: f64,
    /// Its standard deviation: the bootstrap draws' own ([`ParamSd::sd_raw`]) times the factor
    /// that calibrates them on synthetic data ([`Family::sd_factor`](super::Family::sd_factor)).
    pub sd: f64,
    /// The bootstrap draws' own standard deviation.
    pub sd_raw: f64,
    /// The bootstrap draws' mean: `draws_mean − value` is the shift of the estimator that the
    /// bootstrap sees (its estimate of the estimator's bias around `value`).
    pub draws_mean: f64,
}

/// Standard deviations above the surrogates' mean (square-root scale) a detection statistic
/// must reach to make its family significant with a score merely above chance
/// ([`stands_out`]). Set on seeds 101–105 of `magic synth-check`: at [`SD_MARGIN`] the onsets
/// of lasting deflations passed as steps in 4 more of 300 runs, while every step the rule adds
/// stood 6.5 or more deviations out.
pub const STAT_SD_MARGIN: f64 = 5.0;

/// Whether `stat` passes its surrogates' values `of_surrogates`: their mean plus
/// [`STAT_SD_MARGIN`] standard deviations on the square-root scale (as the score's rule:
/// detection statistics such as sums of squared z values are χ²-like too), and their largest.
///
/// ```
/// use magic_train::analysis::stands_out;
/// let noise = [20.0, 24.0, 18.0, 30.0, 22.0, 26.0, 19.0, 25.0];
/// assert!(stands_out(90.0, &noise));
/// assert!(!stands_out(32.0, &noise));
/// assert!(!stands_out(90.0, &[20.0]), "one surrogate has no spread to compare with");
/// ```
pub fn stands_out(stat: f64, of_surrogates: &[f64]) -> bool {
    stands_out_by(stat, of_surrogates, STAT_SD_MARGIN)
}

/// [`stands_out`] by `k` standard deviations instead of [`STAT_SD_MARGIN`].
pub fn stands_out_by(stat: f64, of_surrogates: &[f64], k: f64) -> bool {
    if of_surrogates.len() < 2 || !stat.is_finite() {
        return false;
    }
    let top = of_surrogates.iter().copied().fold(f64::MIN, f64::max);
    stat > top && stat.max(0.0).sqrt() > root_threshold(of_surrogates, k)
}

/// The mean plus `k` standard deviations of the square roots of `values` (negatives as 0): the
/// scale on which chance scores and statistics are close to Gaussian.
pub(super) fn root_threshold(values: &[f64], k: f64) -> f64 {
    let roots: Vec<f64> = values.iter().map(|v| v.max(0.0).sqrt()).collect();
    roots.iter().sum::<f64>() / roots.len().max(1) as f64 + k * sd(&roots)
}

impl Candidate {
    /// A family's candidate from its held-out score and its surrogates' scores (see the module
    /// documentation for the rule).
    pub fn from_scores(
        family: &str,
        score: f64,
        chance: Vec<f64>,
        quantile_level: f64,
        params: serde_json::Value,
        effect: Option<OwnedEffect>,
    ) -> Candidate {
        let chance_level = quantile(&chance, quantile_level).max(0.0);
        let chance_sd = sd(&chance);
        Candidate {
            family: family.into(),
            variance_explained: score,
            chance_level,
            significant: false,
            params,
            effect,
            chance_sd,
            margin: 0.0,
            surrogate_scores: chance,
            statistic: None,
            rejected: None,
            uncertainty: vec![],
        }
        .with_rule(MIN_EXCESS, SD_MARGIN)
    }

    /// The candidate judged with `floor` as the least excess over chance that counts and
    /// `sd_margin` standard deviations as the margin over the surrogates (the module
    /// documentation's rule with them for [`MIN_EXCESS`] and [`SD_MARGIN`]; a family whose score
    /// is a transient's gain sets its own floor, [`Family::min_excess`](super::Family::min_excess),
    /// a family whose surrogates are drawn otherwise its own margin,
    /// [`Family::sd_margin`](super::Family::sd_margin)).
    pub fn with_rule(mut self, floor: f64, sd_margin: f64) -> Candidate {
        let t = root_threshold(&self.surrogate_scores, sd_margin);
        self.margin = floor.max(t * t - self.chance_level);
        self.significant = self.excess() > self.margin;
        self
    }

    /// Score minus chance level (the ranking key within the significant and the other
    /// candidates: see [`rank`]).
    pub fn excess(&self) -> f64 {
        self.variance_explained - self.chance_level
    }

    /// The candidate as reported (`family`, `variance_explained`, `chance_level`, `significant`,
    /// `params`, and `excess`, `margin`, `declarable` — whether it can be added to F — and the
    /// surrogate scores).
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "family": self.family,
            "variance_explained": self.variance_explained,
            "chance_level": self.chance_level,
            "significant": self.significant,
            "params": self.params,
            "excess": self.excess(),
            "margin": self.margin,
            "declarable": self.effect.is_some(),
            "rejected": self.rejected,
            "uncertainty": self.uncertainty,
            "surrogate_scores": self.surrogate_scores,
            "statistic": self.statistic.as_ref().map(|s| s.0),
            "surrogate_statistics": self.statistic.as_ref().map(|s| &s.1),
        })
    }

    /// The first day (days since 1970-01-01) the fitted effect acts on, for a dated one: a step's
    /// epoch (its term is zero before), a source's `start` (the change or pulse found begins
    /// there); `None` for an effect that acts on every row.
    pub fn onset_day(&self) -> Option<f64> {
        self.effect
            .as_ref()
            .and_then(OwnedEffect::onset_day)
            .or_else(|| {
                let start = self.params.get("start")?.as_str()?;
                Some(crate::data::day_number(start)).filter(|d| d.is_finite())
            })
    }

    /// The first and last day (days since 1970-01-01) of the fitted effect, for an episode that
    /// comes back (`shape` `pulse`: a source's volume that rises and returns, found active from
    /// `start` to `end`); `None` for an effect that stays once begun or acts on every row.
    ///
    /// ```
    /// use magic_train::analysis::Candidate;
    /// let c = |params| Candidate::from_scores("second_source", 0.02, vec![0.0; 4], 0.95, params, None);
    /// let pulse = c(serde_json::json!({"shape": "pulse", "start": "2018-01-01", "end": "2018-06-30"}));
    /// assert_eq!(pulse.episode_days(), Some((17532.0, 17712.0)));
    /// let lasting = c(serde_json::json!({"shape": "lasting", "start": "2018-01-01", "end": "2018-06-30"}));
    /// assert_eq!(lasting.episode_days(), None);
    /// ```
    pub fn episode_days(&self) -> Option<(f64, f64)> {
        if self.params.get("shape")?.as_str()? != "pulse" {
            return None;
        }
        let day = |k: &str| {
            let d = crate::data::day_number(self.params.get(k)?.as_str()?);
            d.is_finite().then_some(d)
        };
        let (first, last) = (day("start")?, day("end")?);
        (first <= last).then_some((first, last))
    }

    /// A candidate read back from a report (its serde form, as `magic loop`'s `report.json`
    /// writes it): family, scores, verdict, parameters and effect; the surrogates' scores, the
    /// statistic, the rejection and the standard deviations are not read back. A number written
    /// as `null` (NaN) reads as NaN.
    pub fn from_report(v: &serde_json::Value) -> Result<Candidate, String> {
        use serde_json::Value;
        let num = |k: &str| v.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
        let family = v
            .get("family")
            .and_then(Value::as_str)
            .ok_or("a candidate without a family")?;
        let effect = match v.get("effect") {
            None | Some(Value::Null) => None,
            Some(e) => Some(
                serde_json::from_value(e.clone())
                    .map_err(|err| format!("the effect of a {family} candidate: {err}"))?,
            ),
        };
        Ok(Candidate {
            family: family.into(),
            variance_explained: num("variance_explained"),
            chance_level: num("chance_level"),
            significant: v.get("significant").and_then(Value::as_bool) == Some(true),
            params: v.get("params").cloned().unwrap_or(Value::Null),
            effect,
            chance_sd: num("chance_sd"),
            margin: num("margin"),
            surrogate_scores: vec![],
            statistic: None,
            rejected: None,
            uncertainty: vec![],
        })
    }

    /// `family (explained vs chance)` with three decimals, as the loop tables print it.
    pub fn short(&self) -> String {
        format!(
            "{} ({:.3} vs {:.3})",
            self.family, self.variance_explained, self.chance_level
        )
    }
}

/// Ranks `effects`, best first: the significant candidates (what the loop may add) before the
/// others, each group by excess over chance. A candidate a rule rejected (on the bound of its
/// grid, say) or whose excess is within its margin is no discovery, however large its excess:
/// ranked by excess alone, it would stand above the discovery the loop adds.
pub fn rank(effects: &mut [Candidate]) {
    effects.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(b.excess().total_cmp(&a.excess()))
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_candidate_reads_back_from_its_report() {
        let noise = vec![0.010, 0.012, 0.008, 0.011, 0.009, 0.010, 0.013, 0.007];
        let effect = OwnedEffect::Step {
            station: 3,
            epoch_day: 16_000.0,
            offset_mm: [1.5, -2.0, 8.25],
        };
        let params = json!({"station": "AV13", "epoch": "2013-10-23"});
        let c = Candidate::from_scores("step", 0.2, noise, 0.95, params, Some(effect));
        let back = Candidate::from_report(&serde_json::to_value(&c).unwrap()).unwrap();
        assert_eq!(
            (&back.family, &back.params, &back.effect, back.significant),
            (&c.family, &c.params, &c.effect, c.significant)
        );
        assert_eq!(
            [
                back.variance_explained,
                back.chance_level,
                back.chance_sd,
                back.margin
            ],
            [c.variance_explained, c.chance_level, c.chance_sd, c.margin]
        );
        assert!(Candidate::from_report(&json!({"variance_explained": 0.1})).is_err());
        let bad = json!({"family": "step", "effect": {"family": "step", "station": "AV13"}});
        let err = Candidate::from_report(&bad).unwrap_err();
        assert!(err.contains("the effect of a step candidate"), "{err}");
    }

    #[test]
    fn significance_needs_the_margin_over_chance() {
        let noise = vec![0.010, 0.012, 0.008, 0.011, 0.009, 0.010, 0.013, 0.007];
        let weak = Candidate::from_scores("x", 0.014, noise.clone(), 0.95, json!({}), None);
        assert!(!weak.significant, "{weak:?}");
        let strong = Candidate::from_scores("x", 0.2, noise, 0.95, json!({}), None);
        assert!(strong.significant);
        assert!(strong.margin >= MIN_EXCESS);
        assert!((strong.excess() - (0.2 - strong.chance_level)).abs() < 1e-15);
    }

    #[test]
    fn a_family_s_own_margin_moves_the_threshold_by_its_deviations() {
        // Square roots of the surrogate scores: mean 0.1, sample sd 0.02/√3.
        let noise = vec![
            0.09f64.powi(2),
            0.11f64.powi(2),
            0.09f64.powi(2),
            0.11f64.powi(2),
        ];
        let sd = 0.02 / 3f64.sqrt();
        let at = |k: f64, score: f64| {
            Candidate::from_scores("x", score, noise.clone(), 0.95, json!({}), None)
                .with_rule(0.0, k)
        };
        // A score 3.8 deviations out (square-root scale): beyond a margin of 3.5, short of 4.
        let score = (0.1 + 3.8 * sd).powi(2);
        assert!(at(3.5, score).significant && !at(SD_MARGIN, score).significant);
        let (low, high) = (at(3.5, score).margin, at(SD_MARGIN, score).margin);
        let chance = at(3.5, score).chance_level;
        assert!(
            (low + chance - (0.1 + 3.5 * sd).powi(2)).abs() < 1e-12,
            "{low}"
        );
        assert!(
            (high + chance - (0.1 + 4.0 * sd).powi(2)).abs() < 1e-12,
            "{high}"
        );
    }

    #[test]
    fn significant_candidates_rank_above_larger_excesses_that_are_not() {
        let noise = vec![0.010, 0.012, 0.008, 0.011, 0.009, 0.010, 0.013, 0.007];
        let c = |f: &str, score: f64| {
            Candidate::from_scores(f, score, noise.clone(), 0.95, json!({}), None)
        };
        let mut rejected = c("a", 0.5);
        rejected.significant = false;
        let mut effects = vec![c("weak", 0.014), rejected, c("b", 0.2), c("c", 0.3)];
        rank(&mut effects);
        let order: Vec<&str> = effects.iter().map(|c| c.family.as_str()).collect();
        assert_eq!(order, ["c", "b", "a", "weak"]);
    }

    #[test]
    fn the_onset_is_a_steps_epoch_or_a_sources_start() {
        let c = |params, effect| Candidate::from_scores("x", 0.1, vec![0.0], 0.95, params, effect);
        let step = OwnedEffect::Step {
            station: 3,
            epoch_day: 17_000.0,
            offset_mm: [0.0, 0.0, 9.0],
        };
        let dated = json!({"start": "2019-01-01"});
        assert_eq!(c(json!({}), Some(step.clone())).onset_day(), Some(17_000.0));
        assert_eq!(c(dated.clone(), Some(step)).onset_day(), Some(17_000.0));
        let source = OwnedEffect::SecondSource {
            x_km: 1.0,
            y_km: 2.0,
            depth_km: 3.0,
        };
        let day = crate::data::day_number("2019-01-01");
        assert_eq!(c(dated, Some(source.clone())).onset_day(), Some(day));
        assert_eq!(c(json!({}), Some(source)).onset_day(), None);
        assert_eq!(c(json!({"start": "someday"}), None).onset_day(), None);
    }
}
