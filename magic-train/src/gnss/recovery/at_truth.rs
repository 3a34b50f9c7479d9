//! A lasting change judged at its truth: the lasting-source family's fit at the injected
//! source's position, its onset the best scanned epoch within the true change ([`fit_at`];
//! over the whole record and, for a change in the last year, over that year),
//! judged by the family's rules against the surrogates the analysis drew for its own
//! candidate. A miss is then the data's (not significant at the truth either: no search under
//! this score would find it), the score's (significant there, but another place scores
//! higher) or the search's (the truth scores above the search's best). (Those surrogates were
//! drawn beside the found position, not the true one: close to the test the truth would get,
//! not the same.)

use super::{Found, Recovery};
use crate::analysis::{judge, AnalysisOptions, Candidate, Chance, Family};
use crate::gnss::families::lasting_source::{fit_at, LastingSource};
use crate::gnss::synth::truth::Injected;
use crate::gnss::GnssResiduals;
use serde_json::json;
use std::fmt::Write as _;

/// The family's fit at the truth and its verdict.
#[derive(Clone, Debug, PartialEq)]
pub struct AtTruth {
    /// Share of the residual variance the fit at the truth explains (held-out stations).
    pub score: f64,
    /// The family's chance level in this analysis.
    pub chance: f64,
    /// Significant by the family's rules (a rule rejecting the true position included).
    pub significant: bool,
    /// The score of the family's own fit (its search's best) in the same analysis.
    pub fit_score: f64,
}

impl AtTruth {
    /// As JSON.
    pub fn to_json(&self) -> serde_json::Value {
        json!({"score": self.score, "chance": self.chance, "significant": self.significant,
               "fit_score": self.fit_score})
    }
}

/// The truth of `e`, an injected lasting change (a source of shape `lasting`), judged
/// in the residuals `res` beside the analysis's `candidates`; `None` for any other effect, or
/// when the analysis has no lasting-source candidate to take the surrogates from. Judged by
/// [`LastingSource::WHOLE`] and, when the change lies within the record's last year, by
/// [`LastingSource::RECENT`] too: significant by either (the one that is, else the whole
/// record's verdict).
pub fn lasting(
    res: &GnssResiduals,
    e: &Injected,
    candidates: &[Candidate],
    opts: &AnalysisOptions,
) -> Option<AtTruth> {
    let (pos, from, to) = lasting_truth(e)?;
    let window = (from as f64, to as f64);
    let (whole, recent) = (
        LastingSource::WHOLE.by(opts.lasting),
        LastingSource::RECENT.by(opts.lasting),
    );
    let whole = judged(whole, res, pos, window, candidates, opts);
    let recent = judged(recent, res, pos, window, candidates, opts);
    match (whole, recent) {
        (Some(w), Some(r)) if r.significant && !w.significant => Some(r),
        (None, r) => r,
        (w, _) => w,
    }
}

/// The truth at `pos`, its change between the days of `window`, judged by `family` against the
/// surrogates of that family's candidate; `None` without that candidate, or when the family
/// scans no onset within the window ([`LastingSource::RECENT`] outside the last year).
fn judged(
    family: LastingSource,
    res: &GnssResiduals,
    pos: [f64; 3],
    window: (f64, f64),
    candidates: &[Candidate],
    opts: &AnalysisOptions,
) -> Option<AtTruth> {
    let own = candidates.iter().find(|c| c.family == family.name())?;
    let fit = fit_at(family, res, pos, window)?;
    let statistics = own
        .statistic
        .as_ref()
        .map_or_else(Vec::new, |s| s.1.clone());
    // The candidate's surrogates were not scored at the truth without its dominant station: a
    // truth one station holds most of is not confirmed here.
    let chance = Chance {
        scores: own.surrogate_scores.clone(),
        statistics,
        held_part: Some(Vec::new()),
    };
    let c = judge(&family, res, &fit, chance, opts.quantile);
    Some(AtTruth {
        score: fit.score,
        chance: c.chance_level,
        significant: c.significant,
        fit_score: own.variance_explained,
    })
}

/// Position (km) and the first and last days of `e`'s change, if `e` is a lasting one (a
/// source of either family whose `shape` is `lasting`).
fn lasting_truth(e: &Injected) -> Option<([f64; 3], i64, i64)> {
    let p = &e.params;
    if !super::same_effect(&e.family, "second_source") || p["shape"] != "lasting" {
        return None;
    }
    let num = |k: &str| p[k].as_f64();
    let day = |k: &str| p[k].as_str().and_then(magic_core::time::parse_date);
    Some((
        [num("x_km")?, num("y_km")?, num("depth_km")?],
        day("start")?,
        day("end")?,
    ))
}

/// Why a lasting change was missed, judged at its truth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Not significant at the truth either: the data's (under this score).
    NotThere,
    /// Significant at the truth, but another place scores higher: the score's.
    ElsewhereHigher,
    /// Significant at the truth, which scores above the family's fit: the search's.
    SearchMissed,
}

/// Why `f`, a missed lasting change judged at its truth, was missed; `None` when it was found
/// or not judged.
pub fn verdict(f: &Found) -> Option<Verdict> {
    let t = f.at_truth.as_ref().filter(|_| !f.found())?;
    Some(if !t.significant {
        Verdict::NotThere
    } else if t.score > t.fit_score {
        Verdict::SearchMissed
    } else {
        Verdict::ElsewhereHigher
    })
}

/// Markdown: a line per scenario and noise model whose runs judged a lasting change at its
/// truth — runs, found, missed, and the misses by [`Verdict`].
pub fn truth_table(rows: &[Recovery]) -> String {
    let mut keys: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        let k = (r.scenario.as_str(), r.noise.as_str());
        if r.effects.iter().any(|f| f.at_truth.is_some()) && !keys.contains(&k) {
            keys.push(k);
        }
    }
    if keys.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "| scenario | noise | runs | found | missed | not significant at the truth either | significant there, another place scoring higher | significant there, above the search's best |\n|---|---|---|---|---|---|---|---|\n",
    );
    for (sc, no) in keys {
        let g: Vec<&Found> = rows
            .iter()
            .filter(|r| (r.scenario.as_str(), r.noise.as_str()) == (sc, no))
            .flat_map(|r| r.effects.iter().filter(|f| f.at_truth.is_some()))
            .collect();
        let found = g.iter().filter(|f| f.found()).count();
        let count = |v: Verdict| g.iter().filter(|f| verdict(f) == Some(v)).count();
        let _ = writeln!(
            s,
            "| {sc} | {no} | {} | {found} | {} | {} | {} | {} |",
            g.len(),
            g.len() - found,
            count(Verdict::NotThere),
            count(Verdict::ElsewhereHigher),
            count(Verdict::SearchMissed)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run of a far lasting deflation: found or not, and its truth's verdict (significant,
    /// score against the fit's 0.02) if judged.
    fn run(noise: &str, found: bool, at_truth: Option<(bool, f64)>) -> Recovery {
        let f = Found {
            family: "second_source".into(),
            significant: found,
            rank: Some(1),
            params_ok: true,
            detail: String::new(),
            rejected: None,
            at_truth: at_truth.map(|(significant, score)| AtTruth {
                score,
                chance: 0.01,
                significant,
                fit_score: 0.02,
            }),
        };
        Recovery::single("lasting_deflation_far", noise, "valid", f)
    }

    #[test]
    fn misses_are_told_apart_by_their_truth() {
        let rows = [
            run("paper", true, Some((true, 0.03))),
            run("paper", false, Some((true, 0.03))),
            run("paper", false, Some((true, 0.015))),
            run("paper", false, Some((false, 0.005))),
            run("paper", false, Some((false, 0.03))),
            run("red", true, None),
        ];
        let verdicts: Vec<Option<Verdict>> = rows.iter().map(|r| verdict(&r.effects[0])).collect();
        assert_eq!(
            verdicts,
            [
                None,
                Some(Verdict::SearchMissed),
                Some(Verdict::ElsewhereHigher),
                Some(Verdict::NotThere),
                Some(Verdict::NotThere),
                None
            ]
        );
        let t = truth_table(&rows);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3, "{t}");
        assert_eq!(
            lines[2],
            "| lasting_deflation_far | paper | 5 | 1 | 4 | 2 | 1 | 1 |"
        );
        assert_eq!(truth_table(&rows[5..]), "");
    }

    #[test]
    fn only_a_lasting_change_is_judged_at_its_truth() {
        let source = |shape: &str| {
            Injected::new(
                if shape == "lasting" {
                    "lasting_source"
                } else {
                    "second_source"
                },
                json!({"x_km": 1.0, "y_km": 2.0, "depth_km": 4.0, "start": "2010-01-01",
                       "end": "2010-03-02", "shape": shape}),
            )
        };
        let (pos, from, to) = lasting_truth(&source("lasting")).unwrap();
        assert_eq!(pos, [1.0, 2.0, 4.0]);
        assert_eq!(to - from, 60);
        assert_eq!(lasting_truth(&source("pulse")), None);
        assert_eq!(lasting_truth(&Injected::new("step", json!({}))), None);
    }
}
