//! A fit that one part of the data holds most of — a source whose field one station holds most
//! of — may be that part's own motion (a step, a settling monument) taken for an effect. It
//! counts only where the rest of the data confirm it: scored with that part held out entirely
//! (neither fitted on nor predicted), it must stand out by the family's margin
//! ([`Family::sd_margin`](super::Family::sd_margin), on the square-root scale as the score's
//! rule) of the same score on surrogates that keep the part as the data hold it and randomise
//! the rest ([`Family::surrogate_keeping`](super::Family::surrogate_keeping)), each fitted anew
//! among the fits that part holds most of: the null of the part's own motion, the search's
//! choice of the fit included. (Scored at the data's fit instead, without a search, the
//! surrogates left that choice out: on trial seeds 101–105, 5 of 22 fits one station held
//! passed, none of them a source to find. Searched anywhere, their fits went where the other
//! stations hold more of them, and the score to pass was any fit's chance level.)

use super::candidate::root_threshold;
use super::Rejection;
use serde_json::json;

/// The part of the data a fit rests on most, and the fit's score without it
/// ([`Family::held_part`](super::Family::held_part)).
#[derive(Clone, Debug, PartialEq)]
pub struct HeldPart {
    /// The part (a station's name).
    pub part: String,
    /// Its index (a station's).
    pub index: usize,
    /// Its share of the fit (a source's field energy at that station).
    pub share: f64,
    /// The largest share a fit may hold there without the rest confirming it.
    pub most: f64,
    /// The fit's score with the part held out entirely (share of the residual variance).
    pub score: f64,
}

impl HeldPart {
    /// The score the rest must pass: the surrogates' mean plus `sd_margin` standard deviations
    /// of the square roots of their `chance` scores, squared (`None` with fewer than two).
    ///
    /// ```
    /// use magic_train::analysis::HeldPart;
    /// let h = HeldPart { part: "AV13".into(), index: 3, share: 0.8, most: 0.75, score: 0.01 };
    /// let needed = h.needed(&[0.0004, 0.0009, 0.0001, 0.0004], 4.0).unwrap();
    /// assert!((needed - 0.0026_f64).abs() < 1e-3);
    /// assert_eq!(h.needed(&[0.0004], 4.0), None);
    /// ```
    pub fn needed(&self, chance: &[f64], sd_margin: f64) -> Option<f64> {
        (chance.len() >= 2).then(|| root_threshold(chance, sd_margin).powi(2))
    }

    /// Why the fit is no discovery, if the rest does not confirm it: its share beyond
    /// [`most`](HeldPart::most) and its score without the part not above 0 and
    /// [`needed`](HeldPart::needed) (or no surrogates to judge it by).
    pub fn rejection(&self, chance: &[f64], sd_margin: f64) -> Option<Rejection> {
        if self.share <= self.most {
            return None;
        }
        let needed = self.needed(chance, sd_margin);
        let confirmed = needed.is_some_and(|n| self.score > n.max(0.0));
        (!confirmed).then(|| Rejection::OneStation {
            station: self.part.clone(),
            share: self.share,
            most: self.most,
            without: self.score,
            needed: needed.unwrap_or(f64::NAN),
        })
    }

    /// As reported in the candidate's parameters (`held_out`): the part, its share, the score
    /// without it and what that score had to pass.
    /// `needed` and `surrogate_scores` are null where the surrogates were not drawn (a fit not
    /// otherwise significant).
    pub fn to_json(&self, chance: Option<&[f64]>, sd_margin: f64) -> serde_json::Value {
        json!({
            "part": self.part, "share": self.share, "most": self.most,
            "score_without": self.score,
            "needed": chance.and_then(|c| self.needed(c, sd_margin)),
            "surrogate_scores": chance,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn held(share: f64, score: f64) -> HeldPart {
        HeldPart {
            part: "AV13".into(),
            index: 3,
            share,
            most: 0.75,
            score,
        }
    }

    /// Below the largest share nothing is asked of the rest; beyond it, the rest must stand out
    /// of their chance scores, and without surrogates nothing confirms it.
    #[test]
    fn the_rest_must_confirm_a_fit_one_part_dominates() {
        let chance = [0.0004, 0.0009, 0.0001, 0.0004, 0.0006];
        assert_eq!(held(0.70, 0.0).rejection(&chance, 4.0), None);
        assert_eq!(held(0.80, 0.02).rejection(&chance, 4.0), None);
        let weak = held(0.80, 0.002).rejection(&chance, 4.0);
        assert!(
            matches!(weak, Some(Rejection::OneStation { without, needed, .. }) if without == 0.002 && needed > 0.002),
            "{weak:?}"
        );
        assert!(held(0.80, 0.02).rejection(&[], 4.0).is_some());
        assert!(held(0.80, 0.02).rejection(&[0.0; 8], 4.0).is_none());
        assert!(held(0.80, 0.0).rejection(&[0.0; 8], 4.0).is_some());
    }
}
