//! `magic loop`: close the loop between residuals and physics, for every problem.
//!
//! Round 0 trains B (encoder + F) and C (+ correction) with the problem's plain F. Each round then
//! analyses B's residuals ([`crate::analysis`]: every family scored on held-out data against
//! chance), adds the top significant family whose term can be declared in F and is not yet (one
//! term of each kind, or as many point sources and steps as the options allow:
//! [`Analysis::top_declarable`](crate::analysis::Analysis::top_declarable)), retrains, and repeats.
//! One rule keeps an effect: it must lower B's validation MSE — significance in the residuals is
//! necessary, not sufficient; an effect that does not is taken out again, and the next significant,
//! declarable candidate of the last F kept is tried in its place ([`Analysis::next_declarable`]; an
//! effect of the validation years F lacks can make a true one raise B's validation MSE there), each
//! taken out only once while F stays as it is; the loop stops when none is left or at the round
//! limit, rounds taken out counted. An effect that starts after the training years (a step or a
//! source's change in the validation years) is one retraining on those years cannot learn: a step's
//! term is zero on every training row, a source's volume never moves there. It is judged by B
//! without and with it trained on interleaved blocks of the training and validation rows, in two
//! folds that hold out every day from its onset on once
//! ([`onset_folds`](crate::data::onset_folds)), and scored on those days. An effect that comes back
//! within the training years (a source's pulse) is the mirror case, one the validation years do not
//! hold: judged the same way over its days ([`window_folds`]); a pulse within the test years, which
//! precede them, too, with the test rows dealt out beside the others (the analysis found it on them
//! already). The loop ends with a [`StopReason`] the report prints. Effects the problem names for a
//! direct test ([`Problem::direct_tests`]) and that the loop did not add are then tried on top of
//! the last F kept. Every round is scored the same way: train/valid/test MSE of B and C,
//! physics-only errors, the size of C's correction, the problem's metrics and, where the problem
//! has one, a classical baseline with the same declared effects.

use crate::analysis::{analyse, Analysis, AnalysisOptions, Candidate};
use crate::data::{window_folds, Split};
use crate::eval::{evaluate, evaluate_splits};
use crate::model::OwnedEffect;
use crate::problem::{Metric, Problem};
use crate::report;
use crate::train::{train_model, train_model_on, ModelKind, TrainConfig};
use anyhow::{Context, Result};
use magic_core::Model;
use serde::Serialize;
use std::path::Path;

/// Options of the loop, checked once by [`run`].
#[derive(Clone, Debug)]
pub struct LoopOptions {
    /// Training seed.
    pub seed: u64,
    /// Training recipe.
    pub train: TrainConfig,
    /// Most rounds after the first, each adding one effect (kept, or taken out again).
    pub max_rounds: usize,
    /// Also run the problem's classical baseline each round.
    pub baseline: bool,
    /// The residual analysis.
    pub analysis: AnalysisOptions,
}

/// The scores of one model.
#[derive(Clone, Debug, Serialize)]
pub struct Scores {
    /// Train, valid, test MSE (standardised units).
    pub mse: [f64; 3],
    /// Physics-only MSE (F(E(x))) on train, valid, test.
    pub physics: [f64; 3],
    /// Mean squared correction C(F(E(x))) − F(E(x)) on the test split (0 for B).
    pub correction_ms: f64,
    /// The problem's metrics.
    pub metrics: Vec<Metric>,
    /// The epoch (1-based) whose weights were kept: the lowest validation loss after the
    /// recipe's warm-up (early stopping). Without a warm-up, an effect acting in the
    /// validation years could move it to a lucky early epoch and so decide the keep rule.
    pub best_epoch: usize,
}

/// One round of the loop.
#[derive(Clone, Debug, Serialize)]
pub struct Round {
    /// 0 for the plain F.
    pub round: usize,
    /// Families declared in F this round.
    pub effects: Vec<String>,
    /// The effect added for this round and why (none in round 0).
    pub added: Option<Candidate>,
    /// Encoder + F.
    pub b: Scores,
    /// Encoder + F + correction.
    pub c: Scores,
    /// The classical baseline with the same declared effects, if run.
    pub baseline: Vec<Metric>,
    /// The residual analysis of this round's B model, ranked.
    pub candidates: Vec<Candidate>,
    /// Whether this round's F was kept (false when its added effect was taken out again).
    pub kept: bool,
    /// How the keep rule judged the added effect when it starts after the training years or
    /// comes back before the validation years.
    pub interleaved: Option<Interleaved>,
    /// B's validation MSE without and with the added effect as the keep rule compared them (over
    /// the interleaved blocks' days where [`interleaved`](Self::interleaved) is set); `None` in
    /// round 0.
    pub valid: Option<[f64; 2]>,
}

/// Rows per block when the keep rule deals the training and validation rows out again: two
/// months of daily rows, a whole number of the GNSS recipe's 5-day sequences.
pub const KEEP_BLOCK_ROWS: usize = 60;

/// The keep rule for an effect that starts after the training years or comes back before the
/// validation years: B's validation MSE without and with it, both trained on the same
/// interleaved blocks ([`window_folds`]).
#[derive(Clone, Debug, Serialize)]
pub struct Interleaved {
    /// Rows per block.
    pub block: usize,
    /// B's validation MSE without and with the effect, on the held-out blocks' days from the
    /// effect's onset on — to its end, for an episode — (elsewhere the two differ only by
    /// training), over both folds.
    pub valid: [f64; 2],
    /// How many held-out days that is (every day from the onset on in the training and
    /// validation years, or every day of the episode).
    pub days: usize,
    /// When the effect acts, which decides the days it is judged over and the rows dealt out.
    pub acts: Acting,
}

/// When an effect the keep rule judges on interleaved blocks acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Acting {
    /// From an onset after the training years on: judged from its onset on, on the training
    /// and validation rows.
    AfterTraining,
    /// An episode that comes back within the training years, which the validation years do not
    /// hold: judged over its days, on the training and validation rows.
    WithinTraining,
    /// An episode within the test years, which no training or validation row holds: judged over
    /// its days, the test rows dealt out beside the others.
    WithinTest,
}

impl Acting {
    /// Whether the effect comes back (judged over its days, not from its onset on).
    pub fn is_episode(self) -> bool {
        self != Acting::AfterTraining
    }

    /// When the effect acts, as the report, the stop reason and the loop's progress say it.
    pub fn when(self) -> &'static str {
        match self {
            Acting::AfterTraining => "starts after the training years",
            Acting::WithinTraining => "comes back within the training years",
            Acting::WithinTest => "comes back within the test years",
        }
    }

    /// The held-out days it is scored on, as the report and the stop reason say them.
    pub fn days(self) -> &'static str {
        if self.is_episode() {
            "of the episode"
        } else {
            "from its onset on"
        }
    }

    /// The years whose rows are dealt out into the blocks.
    pub fn years(self) -> &'static str {
        if self == Acting::WithinTest {
            "the test, training and validation years"
        } else {
            "the training and validation years"
        }
    }
}

/// Why the loop stopped.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum StopReason {
    /// No family explained more residual variance than chance.
    NothingBeatChance,
    /// Families beat chance but none can be declared in F (or all are declared already).
    NotDeclarable {
        /// The significant families.
        families: Vec<String>,
        /// Those among them found as another term than F's, of a family F holds as many of as
        /// the options allow ([`Analysis::beyond_capacity`](crate::analysis::Analysis::beyond_capacity)).
        beyond_capacity: Vec<String>,
        /// F holds as many effects as a model file carries and one of them is another term
        /// ([`Analysis::beyond_model_file`](crate::analysis::Analysis::beyond_model_file)).
        full: bool,
    },
    /// The added effect did not lower B's validation MSE and was taken out again, and no other
    /// candidate of the last F kept was left to try (or the round limit was reached).
    NoValidationGain {
        /// The family taken out.
        family: String,
        /// B's validation MSE before and after adding it.
        valid: [f64; 2],
        /// When the effect acts, where B was judged on interleaved blocks rather than on the
        /// validation years (`None`).
        interleaved: Option<Acting>,
    },
    /// The round limit was reached.
    RoundLimit {
        /// The limit.
        rounds: usize,
    },
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::NothingBeatChance => {
                write!(f, "no family explains more residual variance than chance")
            }
            StopReason::NotDeclarable {
                families,
                beyond_capacity,
                full,
            } => {
                write!(
                    f,
                    "significant but not declarable as physics (or declared already): {}",
                    families.join(", ")
                )?;
                if *full {
                    let most = magic_core::effects::MAX_EFFECTS;
                    return write!(
                        f,
                        " (F holds {most} effects, the most a model file carries)"
                    );
                }
                let has = |names: &[&str]| beyond_capacity.iter().any(|x| names.contains(&&**x));
                if has(&crate::gnss::families::SOURCES) {
                    write!(f, " (another point source needs a larger --extra-sources)")?;
                }
                if has(&["step"]) {
                    write!(f, " (another step needs a larger --steps)")?;
                }
                Ok(())
            }
            StopReason::NoValidationGain {
                family,
                valid,
                interleaved,
            } => {
                let on = interleaved.map_or(String::new(), |a| {
                    format!(
                        " on interleaved blocks of {} (the held-out days {}), as it {}",
                        a.years(),
                        a.days(),
                        a.when()
                    )
                });
                write!(
                    f,
                    "{family} did not lower B's validation MSE{on} ({:.4} → {:.4}) and was taken out of F again",
                    valid[0], valid[1]
                )
            }
            StopReason::RoundLimit { rounds } => {
                write!(f, "the round limit ({rounds}) was reached")
            }
        }
    }
}

/// An effect tried directly on top of the last F kept.
#[derive(Clone, Debug, Serialize)]
pub struct DirectTest {
    /// Its family.
    pub family: String,
    /// B's scores with it.
    pub b: Scores,
    /// C's scores with it.
    pub c: Scores,
}

/// What the loop did.
#[derive(Clone, Debug, Serialize)]
pub struct LoopReport {
    /// The problem.
    pub problem: String,
    /// F's name.
    pub physics: String,
    /// Where the data came from.
    pub data: String,
    /// The rounds.
    pub rounds: Vec<Round>,
    /// Why it stopped.
    pub stop: StopReason,
    /// Direct tests of effects the loop did not add.
    pub direct: Vec<DirectTest>,
}

impl LoopReport {
    /// The first round (the plain F).
    pub fn first(&self) -> &Round {
        &self.rounds[0]
    }

    /// The last round whose F was kept.
    pub fn last_kept(&self) -> &Round {
        self.rounds
            .iter()
            .rev()
            .find(|r| r.kept)
            .unwrap_or(&self.rounds[0])
    }

    /// The candidates the loop added and kept, in order.
    pub fn kept_additions(&self) -> Vec<Candidate> {
        self.rounds
            .iter()
            .filter(|r| r.kept)
            .filter_map(|r| r.added.clone())
            .collect()
    }

    /// The effects the loop added and kept, as `family (explained vs chance)`.
    pub fn added(&self) -> Vec<String> {
        self.kept_additions().iter().map(Candidate::short).collect()
    }
}

/// Scores a trained model on the problem's data (`best_epoch`: from its training log).
pub fn scores<P: Problem + ?Sized>(
    problem: &P,
    m: &Model<'_>,
    best_epoch: usize,
) -> Result<Scores> {
    let r = evaluate_splits(m, problem.data())?;
    let phys = |i: usize| r[i].physics_mse.unwrap_or(f64::NAN);
    Ok(Scores {
        mse: [r[0].mse, r[1].mse, r[2].mse],
        physics: [phys(0), phys(1), phys(2)],
        correction_ms: r[2].correction_ms.unwrap_or(0.0),
        metrics: problem.metrics(m)?,
        best_epoch,
    })
}

/// B and C trained with `effects`, their scores and model files (written into `dir` as
/// `<tag>_B.magic`, `<tag>_C.magic`).
fn train_pair<P: Problem + ?Sized>(
    problem: &P,
    effects: &[OwnedEffect],
    opts: &LoopOptions,
    dir: &Path,
    tag: &str,
) -> Result<[(Scores, Vec<u8>); 2]> {
    let one = |kind: ModelKind| -> Result<(Scores, Vec<u8>)> {
        let (m, log) = train_model(problem, kind, effects, &opts.train, opts.seed)?;
        let bytes = m.encode()?;
        std::fs::write(dir.join(format!("{tag}_{kind:?}.magic")), &bytes)?;
        let s = scores(problem, &Model::decode(&bytes)?, log.best_epoch)?;
        Ok((s, bytes))
    };
    Ok([one(ModelKind::B)?, one(ModelKind::C)?])
}

/// The last day (days since 1970-01-01) of a split's rows with a date.
fn last_day(s: &Split) -> f64 {
    s.days()
        .into_iter()
        .filter(|d| d.is_finite())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The days over which the keep rule judges `added` on interleaved blocks instead of on the
/// validation years, whose last training day is `train_end`: from its onset on when that is
/// after the training years ([`Candidate::onset_day`]); its days when it is an episode that comes
/// back by their end, within them or within the test years before them
/// ([`Candidate::episode_days`]); `None` otherwise.
fn keep_window(added: &Candidate, train_end: f64) -> Option<(f64, f64)> {
    if let Some(onset) = added.onset_day().filter(|&d| d > train_end) {
        return Some((onset, f64::INFINITY));
    }
    added.episode_days().filter(|&(_, last)| last <= train_end)
}

/// The keep rule's figures for the last of `effects`, acting from day `window.0` to day
/// `window.1` ([`keep_window`]), when there are two blocks in that window; `None` otherwise. B
/// without and with it is trained on each of the two folds ([`window_folds`]) and scored on the
/// fold's held-out days of the window (elsewhere the two differ only by training); the figures
/// are the means over those days of both folds.
fn judge_interleaved<P: Problem + ?Sized>(
    problem: &P,
    effects: &[OwnedEffect],
    window: Option<(f64, f64)>,
    opts: &LoopOptions,
) -> Result<Option<Interleaved>> {
    let (Some((added, before)), Some((first, last))) = (effects.split_last(), window) else {
        return Ok(None);
    };
    let Some(folds) = window_folds(problem.data(), KEEP_BLOCK_ROWS, first, last) else {
        return Ok(None);
    };
    let data = problem.data();
    let test_rows =
        folds[0].train.len() + folds[0].valid.len() > data.train.len() + data.valid.len();
    let acts = match (last.is_finite(), test_rows) {
        (false, _) => Acting::AfterTraining,
        (true, false) => Acting::WithinTraining,
        (true, true) => Acting::WithinTest,
    };
    eprintln!(
        "{} {}: B without and with it on two folds of blocks of {KEEP_BLOCK_ROWS} rows",
        added.family(),
        acts.when()
    );
    let (mut sums, mut days) = ([0.0; 2], 0);
    for data in &folds {
        let scored = data.valid.within(first, last);
        for (sum, effects) in sums.iter_mut().zip([before, effects]) {
            let (m, _) =
                train_model_on(problem, data, ModelKind::B, effects, &opts.train, opts.seed)?;
            let mse = evaluate(&Model::decode(&m.encode()?)?, &scored, "valid")?.mse;
            *sum += mse * scored.len() as f64;
        }
        days += scored.len();
    }
    let n = days.max(1) as f64;
    Ok(Some(Interleaved {
        block: KEEP_BLOCK_ROWS,
        days,
        valid: [sums[0] / n, sums[1] / n],
        acts,
    }))
}

fn describe_f<P: Problem + ?Sized>(problem: &P, effects: &[OwnedEffect]) -> String {
    std::iter::once(problem.physics_name())
        .chain(effects.iter().map(OwnedEffect::family))
        .collect::<Vec<_>>()
        .join(" + ")
}

/// Runs the loop on `problem` and writes the report (`report.md`, `report.json`, PNG figures,
/// every round's model files) into `dir`.
pub fn run<P: Problem + ?Sized>(problem: &P, opts: &LoopOptions, dir: &Path) -> Result<LoopReport> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut effects: Vec<OwnedEffect> = Vec::new();
    let mut rounds: Vec<Round> = Vec::new();
    let mut added: Option<Candidate> = None;
    let mut models: Vec<Vec<u8>> = Vec::new();
    let train_end = last_day(&problem.data().train);
    // The analysis of the last F kept, and the effects taken out against it: the next
    // candidate is taken from it, none of those again.
    let mut kept_analysis: Option<Analysis> = None;
    let mut taken_out: Vec<OwnedEffect> = Vec::new();
    let stop = loop {
        let round = rounds.len();
        eprintln!("round {round}: F = {}", describe_f(problem, &effects));
        let [(b, bbytes), (c, _)] =
            train_pair(problem, &effects, opts, dir, &format!("round{round}"))?;
        let baseline = if opts.baseline {
            problem.baseline(&effects)?
        } else {
            vec![]
        };
        let analysis = {
            let bm = Model::decode(&bbytes)?;
            let (analysis, res) = analyse(problem, &bm, &opts.analysis)?;
            problem.analysis_plots(&res, &analysis, &dir.join(format!("round{round}")))?;
            analysis
        };
        eprint!("{}", analysis.table());
        let previous_valid = rounds.iter().rev().find(|r| r.kept).map(|r| r.b.mse[1]);
        rounds.push(Round {
            round,
            effects: effects.iter().map(|e| e.family().to_string()).collect(),
            added: added.take(),
            b,
            c,
            baseline,
            candidates: analysis.effects.clone(),
            kept: true,
            interleaved: None,
            valid: None,
        });
        models.push(bbytes);
        let last = rounds.len() - 1;
        if let Some(before) = previous_valid {
            let window = rounds[last]
                .added
                .as_ref()
                .and_then(|a| keep_window(a, train_end));
            let judged = judge_interleaved(problem, &effects, window, opts)?;
            let valid = judged
                .as_ref()
                .map_or([before, rounds[last].b.mse[1]], |j| j.valid);
            let interleaved = judged.as_ref().map(|j| j.acts);
            rounds[last].interleaved = judged;
            rounds[last].valid = Some(valid);
            if valid[1] >= valid[0] {
                let out = effects.pop();
                let family = out.as_ref().map_or("?".into(), |e| e.family().to_string());
                rounds[last].kept = false;
                taken_out.extend(out);
                // Another candidate of the last F kept, tried in its place: an effect of the
                // validation years F lacks can make a true one raise B's validation MSE there.
                let next = kept_analysis
                    .as_ref()
                    .filter(|_| round < opts.max_rounds)
                    .and_then(|a| a.next_declarable(&effects, &taken_out, &opts.analysis));
                let Some(cand) = next else {
                    break StopReason::NoValidationGain {
                        family,
                        valid,
                        interleaved,
                    };
                };
                eprintln!("{family} taken out; next: {}", cand.family);
                effects.extend(cand.effect.clone());
                added = Some(cand.clone());
                continue;
            }
        }
        taken_out.clear();
        if round == opts.max_rounds {
            break StopReason::RoundLimit {
                rounds: opts.max_rounds,
            };
        }
        match analysis.top_declarable(&effects, &opts.analysis) {
            Some(cand) => {
                effects.extend(cand.effect.clone());
                added = Some(cand.clone());
            }
            None => {
                let found: Vec<String> = analysis
                    .effects
                    .iter()
                    .filter(|c| c.significant)
                    .map(|c| c.family.clone())
                    .collect();
                break if found.is_empty() {
                    StopReason::NothingBeatChance
                } else {
                    StopReason::NotDeclarable {
                        families: found,
                        beyond_capacity: analysis.beyond_capacity(&effects, &opts.analysis),
                        full: analysis.beyond_model_file(&effects, &opts.analysis),
                    }
                };
            }
        }
        kept_analysis = Some(analysis);
    };
    let mut direct = Vec::new();
    for e in problem.direct_tests() {
        if effects.iter().any(|d| d.family() == e.family()) {
            continue;
        }
        eprintln!(
            "direct test: F = {} + {}",
            describe_f(problem, &effects),
            e.family()
        );
        let mut with = effects.clone();
        with.push(e.clone());
        let [(b, _), (c, _)] = train_pair(problem, &with, opts, dir, e.family())?;
        direct.push(DirectTest {
            family: e.family().to_string(),
            b,
            c,
        });
    }
    let kept = rounds.iter().rposition(|r| r.kept).unwrap_or(0);
    let plots = problem.loop_plots(
        &Model::decode(&models[0])?,
        &Model::decode(&models[kept])?,
        dir,
    )?;
    let out = LoopReport {
        problem: problem.name().to_string(),
        physics: problem.physics_name().to_string(),
        data: problem.data().source.clone(),
        rounds,
        stop,
        direct,
    };
    report::loop_report::write(&out, &plots, dir)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::synth::{Scenario, Spec};

    #[test]
    fn an_effect_after_the_training_years_is_judged_on_interleaved_blocks() {
        let s = Spec::new(Scenario::Clean, 1).generate();
        let data = s.problem.data();
        let step = |day: f64| OwnedEffect::Step {
            station: 0,
            epoch_day: day as f32,
            offset_mm: [0.0, 0.0, 5.0],
        };
        let opts = LoopOptions {
            seed: 1,
            train: TrainConfig {
                epochs: 2,
                warmup: 0,
                progress: false,
                ..TrainConfig::gnss()
            },
            max_rounds: 1,
            baseline: false,
            analysis: AnalysisOptions::default(),
        };
        let train_end = last_day(&data.train);
        let judge = |effects: &[OwnedEffect]| {
            let window = effects
                .last()
                .and_then(OwnedEffect::onset_day)
                .filter(|&d| d > train_end)
                .map(|d| (d, f64::INFINITY));
            judge_interleaved(&s.problem, effects, window, &opts).unwrap()
        };
        let after = last_day(&data.train) + 30.0;
        let j = judge(&[OwnedEffect::CommonMode, step(after)]).expect("judged on blocks");
        assert_eq!(j.block, KEEP_BLOCK_ROWS);
        assert!(j.valid.iter().all(|v| v.is_finite() && *v > 0.0), "{j:?}");
        // Scored on every day from the onset on (one row a day), each held out by one fold.
        let after_onset = data.valid.since(after).len();
        assert!(after_onset > 2 * KEEP_BLOCK_ROWS);
        assert_eq!(j.days, after_onset, "{j:?}");
        assert_eq!(j.acts, Acting::AfterTraining);
        // Within the training years, without an onset, or after every row: the plain rule.
        assert!(judge(&[step(last_day(&data.train) - 30.0)]).is_none());
        assert!(judge(&[OwnedEffect::CommonMode]).is_none());
        // A source found to start after the training years ([`Candidate::onset_day`]).
        let source = OwnedEffect::SecondSource {
            x_km: 2.0,
            y_km: -1.0,
            depth_km: 4.0,
        };
        let from = |d: f64| Some((d, f64::INFINITY));
        assert!(judge_interleaved(
            &s.problem,
            std::slice::from_ref(&source),
            from(after),
            &opts
        )
        .unwrap()
        .is_some());
        // A pulse within the training years: judged over its days, each held out once.
        let (first, last) = (train_end - 400.0, train_end - 100.0);
        let j = judge_interleaved(
            &s.problem,
            std::slice::from_ref(&source),
            Some((first, last)),
            &opts,
        )
        .unwrap()
        .expect("judged on blocks");
        assert!(
            j.acts == Acting::WithinTraining && j.valid.iter().all(|v| v.is_finite() && *v > 0.0)
        );
        assert_eq!(j.days, data.train.within(first, last).len(), "{j:?}");
        // A pulse within the test years, before the training years: their rows dealt out too.
        let test = data.test.days();
        let (first, last) = (test[100], test[400]);
        let j = judge_interleaved(&s.problem, &[source], Some((first, last)), &opts)
            .unwrap()
            .expect("judged on blocks");
        assert_eq!(j.acts, Acting::WithinTest, "{j:?}");
        assert_eq!(j.days, data.test.within(first, last).len(), "{j:?}");
        assert!(judge(&[step(last_day(&data.valid) + 1.0)]).is_none());
    }

    #[test]
    fn the_keep_window_is_the_onset_after_training_or_an_episode_within_it() {
        let cand = |params: serde_json::Value| {
            Candidate::from_scores("second_source", 0.02, vec![0.0; 4], 0.95, params, None)
        };
        let end = crate::data::day_number("2018-12-31");
        let day = crate::data::day_number;
        let source = |shape: &str, start: &str, last: &str| {
            cand(serde_json::json!({"shape": shape, "start": start, "end": last}))
        };
        // A pulse within the training years, or within the test years before them: its days.
        for (start, last) in [("2018-03-01", "2018-10-01"), ("2007-03-01", "2007-10-01")] {
            assert_eq!(
                keep_window(&source("pulse", start, last), end),
                Some((day(start), day(last)))
            );
        }
        // Beginning after them: from its start on, whatever its shape.
        for shape in ["pulse", "lasting"] {
            assert_eq!(
                keep_window(&source(shape, "2019-03-01", "2019-10-01"), end),
                Some((day("2019-03-01"), f64::INFINITY))
            );
        }
        // A lasting change within them, or a pulse reaching past them: the validation years.
        assert_eq!(
            keep_window(&source("lasting", "2018-03-01", "2018-10-01"), end),
            None
        );
        assert_eq!(
            keep_window(&source("pulse", "2018-09-01", "2019-02-01"), end),
            None
        );
        assert_eq!(keep_window(&cand(serde_json::json!({})), end), None);
    }

    #[test]
    fn an_effect_taken_out_says_which_days_judged_it() {
        let stop = |interleaved: Option<Acting>| {
            StopReason::NoValidationGain {
                family: "second_source".into(),
                valid: [0.75, 0.8],
                interleaved,
            }
            .to_string()
        };
        assert_eq!(
            stop(None),
            "second_source did not lower B's validation MSE (0.7500 → 0.8000) and was taken out of F again"
        );
        let after = stop(Some(Acting::AfterTraining));
        assert!(after.contains("blocks of the training and validation years (the held-out days from its onset on), as it starts after the training years"), "{after}");
        let test = stop(Some(Acting::WithinTest));
        assert!(test.contains("blocks of the test, training and validation years (the held-out days of the episode), as it comes back within the test years"), "{test}");
        assert!(stop(Some(Acting::WithinTraining)).contains("comes back within the training years"));
    }

    #[test]
    fn a_term_left_out_says_how_to_take_it() {
        let stop_full = |f: &[&str], beyond: &[&str], full: bool| {
            let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect();
            StopReason::NotDeclarable {
                families: names(f),
                beyond_capacity: names(beyond),
                full,
            }
            .to_string()
        };
        let stop = |f: &[&str], beyond: &[&str]| stop_full(f, beyond, false);
        assert_eq!(
            stop(&["seasonal"], &[]),
            "significant but not declarable as physics (or declared already): seasonal"
        );
        let source = stop(&["seasonal", "lasting_source"], &["lasting_source"]);
        assert!(source.ends_with("a larger --extra-sources)"), "{source}");
        // A source found again where F has one is not a reason for another.
        assert!(!stop(&["lasting_source"], &[]).contains("--extra-sources"));
        assert!(stop(&["step"], &["step"]).ends_with("a larger --steps)"));
        // With F full no option takes another term: the stop says so, not which option.
        let full = stop_full(&["step"], &["step"], true);
        assert!(
            full.ends_with("(F holds 4 effects, the most a model file carries)"),
            "{full}"
        );
    }
}
