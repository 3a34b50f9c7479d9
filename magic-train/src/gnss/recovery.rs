//! Recovery on synthetic data with known injected effects (`magic synth-check`): does the
//! analysis find every injected effect — its family significant and its key parameters
//! recovered — rank a single one first, and add nothing else?
//!
//! The rules, per injected effect (see [`compare`]): a step's station, and its epoch within
//! [`EPOCH_DAYS`]; a second source's horizontal position within [`POSITION_KM`]; the elevation
//! slope, each common-mode RMS and the median of the seasonal annual amplitudes within
//! [`RELATIVE`]; the drifting stations exactly. What the noise itself holds (the truth's
//! `background`: the `red` model's common mode and annual term) is neither counted against the
//! analysis nor in its ranks. A source is found by a significant candidate of either source
//! family ([`same_effect`]): both add the same term to F.

use super::synth::truth::{background, injected, Injected};
use super::synth::{Site, Spec};
use super::GnssResiduals;
use crate::analysis::{analyse, Analysis, AnalysisOptions, Candidate, Rejection};
use crate::numerics::median;
use crate::train::{train_model, ModelKind, TrainConfig};
use anyhow::Result;
use at_truth::AtTruth;
use magic_core::Model;
use serde_json::json;
use std::fmt::Write as _;

/// Largest error (days) of a recovered step epoch.
pub const EPOCH_DAYS: f64 = 10.0;
/// Largest horizontal error (km) of a recovered second source.
pub const POSITION_KM: f64 = 2.0;
/// Largest relative error of a recovered amplitude (elevation slope, common-mode RMS, median
/// seasonal amplitude).
pub const RELATIVE: f64 = 0.3;

/// How one injected effect was recovered.
#[derive(Clone, Debug)]
pub struct Found {
    /// Its family.
    pub family: String,
    /// The family is significant.
    pub significant: bool,
    /// Rank of the family among the candidates of families the noise does not hold (1 = first).
    pub rank: Option<usize>,
    /// Its key parameters are recovered.
    pub params_ok: bool,
    /// What was compared.
    pub detail: String,
    /// Why its family's candidate cannot count as a discovery, if a rule rejected it (e.g. on
    /// the bound of its search grid).
    pub rejected: Option<Rejection>,
    /// A lasting change judged at its truth ([`at_truth`]); `None` for other effects.
    pub at_truth: Option<AtTruth>,
}

impl Found {
    /// Significant with its parameters recovered.
    pub fn found(&self) -> bool {
        self.significant && self.params_ok
    }
}

/// How an analysis of a synthetic dataset compares with its truth.
#[derive(Clone, Debug)]
pub struct Recovery {
    /// Scenario name.
    pub scenario: String,
    /// Noise model.
    pub noise: String,
    /// Placement of its events (`-` when it has none).
    pub placement: String,
    /// Seed.
    pub seed: u64,
    /// The family ranked first among those the noise does not hold.
    pub top: String,
    /// Every injected effect, in the truth's order.
    pub effects: Vec<Found>,
    /// Significant, declarable families neither injected nor held by the noise.
    pub false_additions: Vec<String>,
    /// Families the noise holds that were found significant.
    pub background_found: Vec<String>,
}

impl Recovery {
    /// For a single injected effect, whether its family was ranked first.
    pub fn ranked_first(&self) -> Option<bool> {
        (self.effects.len() == 1).then(|| self.effects[0].rank == Some(1))
    }

    /// Every injected effect found.
    pub fn all_found(&self) -> bool {
        self.effects.iter().all(Found::found)
    }

    /// The verdict: on clean data, nothing added; with one effect, found and ranked first;
    /// with several, all found (in any order).
    pub fn ok(&self) -> bool {
        if self.effects.is_empty() {
            self.false_additions.is_empty()
        } else {
            self.all_found() && self.ranked_first() != Some(false)
        }
    }

    /// One line: verdict and what was compared.
    pub fn detail(&self) -> String {
        let mut parts: Vec<String> = self
            .effects
            .iter()
            .map(|f| {
                format!(
                    "{}: {}{}{}",
                    f.family,
                    if f.significant {
                        ""
                    } else {
                        "not significant; "
                    },
                    f.detail,
                    f.at_truth.as_ref().map_or(String::new(), |t| format!(
                        "; at the truth {:.2} % vs chance {:.2} %{}",
                        100.0 * t.score,
                        100.0 * t.chance,
                        if t.significant { ", significant" } else { "" }
                    ))
                )
            })
            .collect();
        if !self.false_additions.is_empty() {
            parts.push(format!(
                "also significant: {}",
                self.false_additions.join(",")
            ));
        }
        parts.join(" | ")
    }

    /// The comparison as JSON.
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "scenario": self.scenario, "noise": self.noise, "placement": self.placement,
            "seed": self.seed, "ok": self.ok(), "top": self.top,
            "ranked_first": self.ranked_first(), "all_found": self.all_found(),
            "effects": self.effects.iter().map(|f| json!({"family": f.family,
                "significant": f.significant, "rank": f.rank, "params_ok": f.params_ok,
                "found": f.found(), "detail": f.detail,
                "at_truth": f.at_truth.as_ref().map(AtTruth::to_json)})).collect::<Vec<_>>(),
            "false_additions": self.false_additions,
            "background_found": self.background_found,
        })
    }
}

fn num(v: &serde_json::Value, k: &str) -> f64 {
    v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN)
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    core::array::from_fn(|k| v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN))
}

fn step(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let day = |v: &serde_json::Value| v.as_str().and_then(magic_core::time::parse_date);
    let de = match (day(&tp["epoch"]), day(&p["epoch"])) {
        (Some(x), Some(y)) => (y - x) as f64,
        _ => f64::NAN,
    };
    let same = tp["station"] == p["station"];
    let (to, fo) = (vec3(&tp["offset_mm"]), vec3(&p["offset_mm"]));
    (
        same && de.abs() <= EPOCH_DAYS,
        format!(
            "station {} vs {}, epoch {:+} d, offset [{:.1},{:.1},{:.1}] vs [{:.1},{:.1},{:.1}] mm",
            p["station"], tp["station"], de, fo[0], fo[1], fo[2], to[0], to[1], to[2]
        ),
    )
}

fn second_source(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let dh = (num(p, "x_km") - num(tp, "x_km")).hypot(num(p, "y_km") - num(tp, "y_km"));
    let s = |v: &serde_json::Value, k: &str| v[k].as_str().unwrap_or("?").to_string();
    (
        dh <= POSITION_KM,
        format!(
            "horizontal error {dh:.2} km, depth {:.1} vs {:.1} km, window {}..{} vs {}..{}",
            num(p, "depth_km"),
            num(tp, "depth_km"),
            s(p, "start"),
            s(p, "end"),
            s(tp, "start"),
            s(tp, "end")
        ),
    )
}

fn elevation(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let (e, t) = (num(p, "mm_per_km"), num(tp, "mm_per_km"));
    (
        (e - t).abs() <= RELATIVE * t,
        format!("{e:.1} vs {t:.1} mm/km ({:+.0} %)", 100.0 * (e / t - 1.0)),
    )
}

fn common_mode(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let (e, t) = (vec3(&p["rms_mm"]), vec3(&tp["rms_mm"]));
    (
        (0..3).all(|k| (e[k] / t[k] - 1.0).abs() <= RELATIVE),
        format!(
            "rms [{:.2},{:.2},{:.2}] vs [{:.2},{:.2},{:.2}] mm",
            e[0], e[1], e[2], t[0], t[1], t[2]
        ),
    )
}

fn seasonal(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let mut rel = Vec::new();
    if let (Some(em), Some(tm)) = (p["annual_mm"].as_object(), tp["annual_mm"].as_object()) {
        for (sta, tv) in tm {
            let (t, e) = (
                vec3(tv),
                vec3(em.get(sta).unwrap_or(&serde_json::Value::Null)),
            );
            rel.extend((0..3).map(|k| (e[k] / t[k] - 1.0).abs()));
        }
    }
    let m = if rel.is_empty() {
        f64::NAN
    } else {
        median(&mut rel)
    };
    (
        m <= RELATIVE,
        format!(
            "annual amplitudes: median relative error {:.0} %",
            100.0 * m
        ),
    )
}

fn drift(tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    let keys = |v: &serde_json::Value| {
        let mut k: Vec<String> = v["rate_mm_per_yr"]
            .as_object()
            .map_or(vec![], |m| m.keys().cloned().collect());
        k.sort();
        k
    };
    let (e, t) = (keys(p), keys(tp));
    (e == t, format!("stations {e:?} vs {t:?}"))
}

/// Whether a family's fitted parameters `p` recover the true ones `tp`, and what was compared.
pub fn compare(family: &str, tp: &serde_json::Value, p: &serde_json::Value) -> (bool, String) {
    match family {
        "step" => step(tp, p),
        f if crate::gnss::families::is_source(f) => second_source(tp, p),
        "elevation" => elevation(tp, p),
        "common_mode" => common_mode(tp, p),
        "seasonal" => seasonal(tp, p),
        "drift" => drift(tp, p),
        _ => (false, format!("no rule for family {family}")),
    }
}

/// Which candidate of `ranked` (best first) recovers each injected effect: a significant
/// candidate declaring its term ([`same_effect`]: a second source found as a change that stays
/// is the source the loop adds) with its parameters right, each candidate recovering at most
/// one effect — two injected sources within the position tolerance of one candidate are one
/// found, not two. Its own family's candidate first, then one of another family declaring the
/// same term (a pulse found as a change that stays), each in rank order.
fn assign(effects: &[Injected], ranked: &[&Candidate]) -> Vec<Option<usize>> {
    let mut taken = vec![None; effects.len()];
    for own in [true, false] {
        for (i, e) in effects.iter().enumerate() {
            if taken[i].is_some() {
                continue;
            }
            taken[i] = (0..ranked.len()).find(|&k| {
                let c = ranked[k];
                c.significant
                    && same_family(&c.family, &e.family) == own
                    && same_effect(&c.family, &e.family)
                    && !taken.contains(&Some(k))
                    && compare(&e.family, &e.params, &c.params).0
            });
        }
    }
    taken
}

/// How `e` was recovered among `ranked`: by the candidate [`assign`] gave it (`given`), else
/// the first significant one declaring its term, else its own family's candidate is judged —
/// not found, and said so where that candidate recovers another injected effect.
fn found(e: &Injected, ranked: &[&Candidate], given: Option<usize>, taken: &[usize]) -> Found {
    let declares = |c: &&Candidate| c.significant && same_effect(&c.family, &e.family);
    let pos = given
        .or_else(|| ranked.iter().position(declares))
        .or_else(|| {
            ranked
                .iter()
                .position(|c| same_family(&c.family, &e.family))
        });
    let Some(c) = pos.map(|i| ranked[i]) else {
        return Found {
            family: e.family.clone(),
            significant: false,
            rank: None,
            params_ok: false,
            detail: format!("family {} not analysed", e.family),
            rejected: None,
            at_truth: None,
        };
    };
    let (params_ok, mut detail) = compare(&e.family, &e.params, &c.params);
    if given.is_none() && pos.is_some_and(|k| taken.contains(&k)) {
        detail.push_str(" (recovers another injected effect)");
    }
    Found {
        family: e.family.clone(),
        significant: c.significant,
        rank: pos.map(|i| i + 1),
        params_ok: params_ok && (given.is_some() || !c.significant),
        detail: if c.family == e.family {
            detail
        } else {
            format!("as {}: {detail}", c.family)
        },
        rejected: c.rejected.clone(),
        at_truth: None,
    }
}

/// Whether two families declare the same term of F: a second source found as an episode
/// (`second_source`) or as a change that stays (`lasting_source`, `recent_source`) is the same
/// source, so one found beside the other injected is not a false addition.
pub fn same_effect(a: &str, b: &str) -> bool {
    use crate::gnss::families::is_source;
    a == b || (is_source(a) && is_source(b))
}

/// Whether two families are one search: a change that stays, looked for over the whole record
/// (`lasting_source`) or over its last year (`recent_source`), is found by either as its own.
pub fn same_family(a: &str, b: &str) -> bool {
    use crate::gnss::families::is_lasting;
    a == b || (is_lasting(a) && is_lasting(b))
}

/// Compares an analysis's candidates (ranked, as [`Analysis::effects`]) with a truth of
/// `magic synth` (its `effects`, or the single `effect` of older files).
pub fn recovery(truth: &serde_json::Value, candidates: &[Candidate]) -> Recovery {
    let text = |k: &str| truth.get(k).and_then(|v| v.as_str()).unwrap_or("-");
    let effects = injected(truth);
    let bg: Vec<String> = background(truth).into_iter().map(|e| e.family).collect();
    let in_bg = |f: &str| bg.iter().any(|b| b == f);
    let is_injected = |f: &str| effects.iter().any(|e| e.family == f);
    // Ranks among the families the noise does not hold (an injected family of the same kind
    // as the noise's keeps its place).
    let ranked: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| !in_bg(&c.family) || is_injected(&c.family))
        .collect();
    let significant = |keep: &dyn Fn(&Candidate) -> bool| -> Vec<String> {
        candidates
            .iter()
            .filter(|c| c.significant && keep(c))
            .map(|c| c.family.clone())
            .collect()
    };
    Recovery {
        scenario: text("scenario").to_string(),
        noise: truth
            .get("noise")
            .and_then(|v| v.as_str())
            .unwrap_or("paper")
            .to_string(),
        placement: truth
            .get("placement")
            .and_then(|v| v.as_str())
            .unwrap_or("train")
            .to_string(),
        seed: truth.get("seed").and_then(|v| v.as_u64()).unwrap_or(0),
        top: ranked.first().map_or(String::new(), |c| c.family.clone()),
        effects: {
            let given = assign(&effects, &ranked);
            let taken: Vec<usize> = given.iter().flatten().copied().collect();
            effects
                .iter()
                .zip(&given)
                .map(|(e, &pos)| found(e, &ranked, pos, &taken))
                .collect()
        },
        false_additions: significant(&|c| {
            c.effect.is_some()
                && !effects.iter().any(|e| same_effect(&e.family, &c.family))
                && !in_bg(&c.family)
        }),
        background_found: significant(&|c| in_bg(&c.family)),
    }
}

/// One dataset checked: what was injected, what the analysis found, and how they compare.
pub struct Check {
    /// The analysis against the truth.
    pub recovery: Recovery,
    /// The analysis of the trained model's residuals.
    pub analysis: Analysis,
    /// What was injected (`truth.json`).
    pub truth: serde_json::Value,
    /// The residuals analysed.
    pub residuals: GnssResiduals,
}

#[cfg(test)]
impl Recovery {
    /// A run (seed 1) whose one injected effect was recovered as `f`, nothing else found.
    pub(crate) fn single(scenario: &str, noise: &str, placement: &str, f: Found) -> Recovery {
        Recovery {
            scenario: scenario.into(),
            noise: noise.into(),
            placement: placement.into(),
            seed: 1,
            top: f.family.clone(),
            effects: vec![f],
            false_additions: vec![],
            background_found: vec![],
        }
    }
}

/// The epochs B trains for in a recovery check (`magic synth-check`'s default).
pub const BRIEF_EPOCHS: usize = 15;

/// B's training in a recovery check: the volcano recipe for [`BRIEF_EPOCHS`] epochs, every epoch
/// watched as in the paper (the recipe's warm-up waits for a learning-rate step so brief a run
/// never reaches), without a progress bar.
pub fn brief_recipe() -> TrainConfig {
    TrainConfig::gnss()
        .with(BRIEF_EPOCHS, true)
        .with_warmup(Some(0))
}

/// Generates a dataset on `site`, trains a B model on it (seeded with the dataset's seed) and
/// analyses its residuals.
pub fn check_one(
    spec: &Spec,
    site: &Site,
    cfg: &TrainConfig,
    opts: &AnalysisOptions,
) -> Result<Check> {
    let s = spec.generate_on(site)?;
    let (model, _) = train_model(&s.problem, ModelKind::B, &[], cfg, spec.seed)?;
    let bytes = model.encode()?;
    let m = Model::decode(&bytes)?;
    let (analysis, res) = analyse(&s.problem, &m, opts)?;
    let mut recovery = recovery(&s.truth, &analysis.effects);
    for (f, e) in recovery.effects.iter_mut().zip(injected(&s.truth)) {
        f.at_truth = at_truth::lasting(&res, &e, &analysis.effects, opts);
    }
    Ok(Check {
        recovery,
        analysis,
        truth: s.truth,
        residuals: res,
    })
}

/// `k/n`.
fn frac(k: usize, n: usize) -> String {
    format!("{k}/{n}")
}

/// Counts per family name, in first-seen order: `name k/n, …`.
fn tally(lists: &[&Vec<String>], n: usize) -> String {
    let mut names: Vec<&str> = Vec::new();
    for l in lists {
        for f in l.iter() {
            if !names.contains(&f.as_str()) {
                names.push(f);
            }
        }
    }
    names
        .iter()
        .map(|f| {
            let k = lists.iter().filter(|l| l.iter().any(|x| x == f)).count();
            format!("{f} {}", frac(k, n))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The recovery table (Markdown), a line per scenario, placement and noise model, counts out
/// of the seeds: each injected effect found, the single effect ranked first, every effect
/// found, seeds with a false addition (and which families), what the noise holds found, and
/// the verdict of [`Recovery::ok`].
pub fn recovery_table(rows: &[Recovery]) -> String {
    let mut s = String::from(
        "| scenario | placement | noise | seeds | found | ranked 1st | all found | false additions | noise's own found | ok |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut keys: Vec<(&str, &str, &str)> = Vec::new();
    for r in rows {
        let k = (r.scenario.as_str(), r.placement.as_str(), r.noise.as_str());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for (sc, pl, no) in keys {
        let g: Vec<&Recovery> = rows
            .iter()
            .filter(|r| {
                (r.scenario.as_str(), r.placement.as_str(), r.noise.as_str()) == (sc, pl, no)
            })
            .collect();
        let n = g.len();
        let count = |f: &dyn Fn(&Recovery) -> bool| g.iter().filter(|r| f(r)).count();
        let n_eff = g[0].effects.len();
        let found = if n_eff == 0 {
            "-".to_string()
        } else {
            (0..n_eff)
                .map(|i| {
                    let k = count(&|r| r.effects.get(i).is_some_and(Found::found));
                    if n_eff == 1 {
                        frac(k, n)
                    } else {
                        format!("{} {}", g[0].effects[i].family, frac(k, n))
                    }
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        let ranked = if n_eff == 1 {
            frac(count(&|r| r.ranked_first() == Some(true)), n)
        } else {
            "-".into()
        };
        let all = if n_eff == 0 {
            "-".into()
        } else {
            frac(count(&Recovery::all_found), n)
        };
        let fa: Vec<&Vec<String>> = g.iter().map(|r| &r.false_additions).collect();
        let k_fa = count(&|r| !r.false_additions.is_empty());
        let fa_text = if k_fa == 0 {
            frac(0, n)
        } else {
            format!("{} ({})", frac(k_fa, n), tally(&fa, n))
        };
        let bg: Vec<&Vec<String>> = g.iter().map(|r| &r.background_found).collect();
        let bg_text = if bg.iter().all(|l| l.is_empty()) {
            "-".to_string()
        } else {
            tally(&bg, n)
        };
        let _ = writeln!(
            s,
            "| {sc} | {pl} | {no} | {n} | {found} | {ranked} | {all} | {fa_text} | {bg_text} | {} |",
            frac(count(&Recovery::ok), n)
        );
    }
    s
}

pub mod at_truth;
pub mod coverage;
pub mod looped;
pub mod misses;
pub mod pooled;

#[cfg(test)]
mod tests;
