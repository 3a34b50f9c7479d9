//! An effect family: a kind of term F may lack (a network translation, a step, an illumination
//! change, …), typed against its problem's residuals.
//!
//! A family fits itself to the residuals and scores the fit on held-out data (the fitted object
//! carries its score), makes surrogate residuals that keep the noise's structure but not its own
//! (the fit removed, then randomised) for the chance level, and declares a fit as an [`Effect`]
//! of the model file where it can. The chance procedure is written once, in [`DynFamily::assess`]
//! for every family: the same fit-and-score on each surrogate.
//!
//! [`Effect`]: magic_core::effects::Effect

use super::{
    stands_out_by, AnalysisOptions, Candidate, HeldPart, ParamSd, Rejection, MIN_EXCESS, SD_MARGIN,
    STAT_SD_MARGIN,
};
use crate::model::OwnedEffect;
use anyhow::Result;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// An effect family over residuals `R`.
pub trait Family<R>: Sync {
    /// A fit of the family to residuals, with its held-out score.
    type Fit: Send + Sync;

    /// The family's name (reports, `truth.json`, the declared effect's family).
    fn name(&self) -> &'static str;
    /// Fits the family to `res` and scores the fit on data the fit did not use.
    fn fit(&self, res: &R) -> Result<Self::Fit>;
    /// The share of the residual variance a fit explains on held-out data (≥ 0).
    fn score(&self, fit: &Self::Fit) -> f64;
    /// Residuals like `res` without this family's signal: `fit` removed, then randomised so that
    /// the noise's structure is kept and the family's is not.
    fn surrogate(&self, res: &R, fit: &Self::Fit, rng: &mut StdRng) -> Result<R>;
    /// The least excess over chance (share of the residual variance) a fit must reach to count
    /// ([`MIN_EXCESS`] by default). A family scored on the interval where a transient happens
    /// sets it in days' worth of residual variance, so that a transient's floor does not grow
    /// with the record's length.
    fn min_excess(&self, _res: &R) -> f64 {
        MIN_EXCESS
    }
    /// Standard deviations above its surrogates' mean (square-root scale) a fit's score must
    /// reach ([`SD_MARGIN`] by default). A family whose surrogates' spread is measured otherwise
    /// sets its own, on seeds other than the reported ones.
    fn sd_margin(&self) -> f64 {
        SD_MARGIN
    }
    /// The fit's parameters as reported (JSON).
    fn params(&self, res: &R, fit: &Self::Fit) -> serde_json::Value;
    /// The effect that adds the fit to F (`None`: not declarable, or already declared).
    fn declare(&self, res: &R, fit: &Self::Fit) -> Option<OwnedEffect>;
    /// Why the fit cannot count as a discovery whatever its score (a position on the bound of
    /// its search grid is not a discovery), if it cannot.
    fn reject(&self, _res: &R, _fit: &Self::Fit) -> Option<Rejection> {
        None
    }
    /// The part of the data the fit rests on most (a source's station holding most of its field)
    /// and the fit's score with it held out entirely ([`Family::score_without`]), where that
    /// part's share is large enough to ask the rest to confirm the fit ([`HeldPart`]); `None`
    /// for a family without parts, or where no part holds that much.
    fn held_part(&self, _res: &R, _fit: &Self::Fit) -> Option<HeldPart> {
        None
    }
    /// The score of `fit` (any fit: a surrogate's own too) with `part` held out entirely.
    fn score_without(&self, _res: &R, _fit: &Self::Fit, _part: &HeldPart) -> f64 {
        0.0
    }
    /// A surrogate that keeps `part` as `res` holds it and randomises the rest as
    /// [`Family::surrogate`] does: the null under which the fit is that part's own motion
    /// ([`HeldPart`]). [`Family::fit`] on it must search among the fits that part holds most
    /// of, as the data's fit is one.
    fn surrogate_keeping(
        &self,
        res: &R,
        fit: &Self::Fit,
        _part: &HeldPart,
        rng: &mut StdRng,
    ) -> Result<R> {
        self.surrogate(res, fit, rng)
    }
    /// A detection statistic of the fit (larger: stronger) that must also exceed every
    /// surrogate's (unless it only supports: [`statistic_vetoes`](Family::statistic_vetoes)),
    /// where the score alone can be met by structure the surrogates lack (the step scan's peak:
    /// a level that wanders for years explains held-out days like a step, but only a step is
    /// sharper than the noise makes its local jumps); `None` for most families.
    /// A statistic that stands out of the surrogates' by a margin like the score's
    /// ([`stands_out`](super::stands_out)) makes the fit significant once its held-out score is
    /// above 0 (a vetoing or detecting statistic) or above chance (a supporting one): a local
    /// effect (a step in the record's last months) can be clear and still explain little of the
    /// whole network's variance.
    fn statistic(&self, _fit: &Self::Fit) -> Option<f64> {
        None
    }
    /// Whether a [`statistic`](Family::statistic) the surrogates reach rejects the fit (the
    /// step's: its scan is what tells a step from a wandering level). `false`: the statistic
    /// only supports — standing out, it makes a score above chance significant; not standing
    /// out, it takes nothing away (a scan whose chance peaks are as high as a real effect's).
    fn statistic_vetoes(&self) -> bool {
        true
    }
    /// Whether a supporting [`statistic`](Family::statistic) that stands out detects: it makes
    /// the fit significant once its held-out score is above 0, as a vetoing one does, without
    /// vetoing (a statistic that sees more than the score, calibrated on its own surrogates).
    fn statistic_detects(&self) -> bool {
        false
    }
    /// Standard deviations above the surrogates' mean (square-root scale) the
    /// [`statistic`](Family::statistic) must reach to stand out ([`STAT_SD_MARGIN`] unless the
    /// family sets its own).
    fn statistic_sd_margin(&self) -> f64 {
        STAT_SD_MARGIN
    }
    /// The fit's key parameters (name, value), whose uncertainty the bootstrap measures.
    fn key_params(&self, _res: &R, _fit: &Self::Fit) -> Vec<(&'static str, f64)> {
        vec![]
    }
    /// The factor the bootstrap's standard deviation of the key parameter `param` is scaled by:
    /// where the draws are known to be too narrow, the 68.27 % quantile of |estimate − truth| /
    /// sd measured on synthetic seeds other than the reported ones (as the map's standard
    /// deviations are, `raster::calibrate`); 1 by default.
    fn sd_factor(&self, _param: &str) -> f64 {
        1.0
    }
    /// Residuals holding the fitted effect plus fresh noise drawn like the surrogates' (the
    /// parametric bootstrap of the fit's parameters); `None` for a family without one.
    fn resample(&self, _res: &R, _fit: &Self::Fit, _rng: &mut StdRng) -> Option<Result<R>> {
        None
    }
}

/// A family behind a trait object: what the analysis and the registries hold.
pub trait DynFamily<R>: Sync {
    /// The family's name.
    fn name(&self) -> &'static str;
    /// Fits, scores, draws `opts.surrogates` surrogates for the chance level and returns the
    /// candidate.
    fn assess(&self, res: &R, opts: &AnalysisOptions) -> Result<Candidate>;
}

/// Seeds of a family's surrogates: a stream of its own, from the analysis seed and its name, so
/// that adding or reordering families leaves every other family's chance level unchanged.
pub fn surrogate_seeds(seed: u64, family: &str, n: usize) -> Vec<u64> {
    // FNV-1a of the name.
    let h = family.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    });
    let mut rng = StdRng::seed_from_u64(seed ^ h);
    (0..n).map(|_| rng.random()).collect()
}

impl<R: Sync, F: Family<R>> DynFamily<R> for F {
    fn name(&self) -> &'static str {
        Family::name(self)
    }

    fn assess(&self, res: &R, opts: &AnalysisOptions) -> Result<Candidate> {
        let fit = self.fit(res)?;
        let seeds = surrogate_seeds(opts.seed, self.name(), opts.surrogates.max(2));
        let surrogates = seeds
            .par_iter()
            .map(|s| {
                let mut rng = StdRng::seed_from_u64(*s);
                let sur = self.surrogate(res, &fit, &mut rng)?;
                let f = self.fit(&sur)?;
                Ok((self.score(&f), self.statistic(&f)))
            })
            .collect::<Result<Vec<(f64, Option<f64>)>>>()?;
        let mut chance = Chance {
            scores: surrogates.iter().map(|s| s.0).collect(),
            statistics: surrogates.iter().filter_map(|s| s.1).collect(),
            held_part: None,
        };
        let mut c = judge(self, res, &fit, chance.clone(), opts.quantile);
        // A fit one part holds most of, otherwise significant: the rest must confirm it.
        if let Some(part) = self.held_part(res, &fit).filter(|_| c.significant) {
            chance.held_part = Some(held_chance(self, res, &fit, &part, opts)?);
            c = judge(self, res, &fit, chance, opts.quantile);
        }
        if c.significant && opts.bootstrap > 0 {
            c.uncertainty = bootstrap(self, res, &fit, opts)?;
        }
        Ok(c)
    }
}

/// What the surrogates give a family's fit by chance ([`judge`]).
#[derive(Clone, Debug, Default)]
pub struct Chance {
    /// Their scores, each of its own fit.
    pub scores: Vec<f64>,
    /// Their detection statistics ([`Family::statistic`]; empty for a family without one).
    pub statistics: Vec<f64>,
    /// Where the fit has a [`Family::held_part`]: each surrogate's score without that part
    /// ([`Family::surrogate_keeping`], fitted anew among the fits it holds most of), which the
    /// fit's must pass (empty: it cannot be confirmed); `None` where they were not drawn, and
    /// the part is not judged.
    pub held_part: Option<Vec<f64>>,
}

/// A fit of `family` to `res` judged against its surrogates' scores, detection statistics and
/// held-part scores (`chance`) by the family's rules — its score's margin over chance, its
/// rejections, its detection statistic ([`Family::statistic`]), the rest of the data's
/// confirmation where one part holds most of it ([`Family::held_part`]): the candidate
/// [`DynFamily::assess`] returns, before the bootstrap. Any fit can be judged so, a synthetic
/// truth's too (`gnss::recovery::at_truth`).
pub fn judge<R, F: Family<R>>(
    family: &F,
    res: &R,
    fit: &F::Fit,
    chance: Chance,
    quantile: f64,
) -> Candidate {
    let mut c = Candidate::from_scores(
        family.name(),
        family.score(fit),
        chance.scores,
        quantile,
        family.params(res, fit),
        family.declare(res, fit),
    )
    .with_rule(family.min_excess(res), family.sd_margin());
    if let Some(why) = family.reject(res, fit) {
        c.significant = false;
        c.rejected = Some(why);
    }
    if let Some(stat) = family.statistic(fit) {
        let rule = StatisticRule {
            vetoes: family.statistic_vetoes(),
            detects: family.statistic_detects(),
            margin: family.statistic_sd_margin(),
        };
        with_statistic(&mut c, stat, chance.statistics, rule);
    }
    if let Some(held) = family.held_part(res, fit) {
        let margin = family.sd_margin();
        let of_surrogates = chance.held_part.as_deref();
        if let Some(p) = c.params.as_object_mut() {
            p.insert("held_out".into(), held.to_json(of_surrogates, margin));
        }
        let why = of_surrogates.and_then(|v| held.rejection(v, margin));
        if let (None, Some(why)) = (&c.rejected, why) {
            c.significant = false;
            c.rejected = Some(why);
        }
    }
    c
}

/// The chance of a held part's score ([`Chance::held_part`]): `opts.surrogates` surrogates
/// keeping the part ([`Family::surrogate_keeping`]), each fitted anew and scored without it, on
/// a stream of seeds of their own.
fn held_chance<R: Sync, F: Family<R>>(
    family: &F,
    res: &R,
    fit: &F::Fit,
    part: &HeldPart,
    opts: &AnalysisOptions,
) -> Result<Vec<f64>> {
    let name = format!("{}/held_part", family.name());
    surrogate_seeds(opts.seed, &name, opts.surrogates.max(2))
        .par_iter()
        .map(|s| {
            let mut rng = StdRng::seed_from_u64(*s);
            let sur = family.surrogate_keeping(res, fit, part, &mut rng)?;
            let f = family.fit(&sur)?;
            Ok(family.score_without(&sur, &f, part))
        })
        .collect()
}

/// Judges a scored candidate `c` by its family's detection statistic `stat` against the
/// surrogates' (the rule of [`Family::statistic`]: a vetoing statistic the surrogates reach
/// rejects; one that [`stands_out`] makes significant a score the rule lets through), and
/// keeps both on it.
/// How a family's detection statistic judges its fit ([`Family::statistic_vetoes`],
/// [`Family::statistic_detects`], [`Family::statistic_sd_margin`]).
#[derive(Clone, Copy, Debug)]
struct StatisticRule {
    vetoes: bool,
    detects: bool,
    margin: f64,
}

fn with_statistic(c: &mut Candidate, stat: f64, of_surrogates: Vec<f64>, rule: StatisticRule) {
    let top = of_surrogates
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if c.rejected.is_none() {
        if stat <= top && rule.vetoes {
            c.significant = false;
            c.rejected = Some(Rejection::StatisticNotAbove {
                statistic: stat,
                largest: top,
            });
        } else if carries(rule.vetoes || rule.detects, c) {
            c.significant |= stands_out_by(stat, &of_surrogates, rule.margin);
        }
    }
    c.statistic = Some((stat, of_surrogates));
}

/// Whether a candidate's held-out score lets a statistic that [`stands_out`] make it significant.
/// A vetoing or detecting statistic (`any_gain`) is the detection test itself (above every surrogate's, and calibrated on
/// them with the look-elsewhere of its scan): the score need only show that the fit predicts the
/// days it was not fitted on (above 0) — a step in the record's last months explains less of the
/// network's variance than the surrogates' best steps, placed mid-record, do. A supporting
/// statistic carries a score above chance.
fn carries(any_gain: bool, c: &Candidate) -> bool {
    if any_gain {
        c.variance_explained > 0.0
    } else {
        c.excess() > 0.0
    }
}

/// The parametric bootstrap of a fit's key parameters: `opts.bootstrap` residual sets holding the
/// fitted effect plus fresh noise ([`Family::resample`]), each refitted; the standard deviation
/// (scaled by [`Family::sd_factor`]) and the mean of each key parameter over the draws.
fn bootstrap<R: Sync, F: Family<R>>(
    family: &F,
    res: &R,
    fit: &F::Fit,
    opts: &AnalysisOptions,
) -> Result<Vec<ParamSd>> {
    let keys = family.key_params(res, fit);
    if keys.is_empty() {
        return Ok(vec![]);
    }
    let seeds = surrogate_seeds(opts.seed ^ 0xB007, family.name(), opts.bootstrap.max(2));
    let draws = seeds
        .par_iter()
        .filter_map(|s| {
            let mut rng = StdRng::seed_from_u64(*s);
            family.resample(res, fit, &mut rng).map(|r| {
                let r = r?;
                let f = family.fit(&r)?;
                Ok(family.key_params(&r, &f))
            })
        })
        .collect::<Result<Vec<Vec<(&'static str, f64)>>>>()?;
    if draws.len() < 2 {
        return Ok(vec![]);
    }
    Ok(keys
        .iter()
        .enumerate()
        .map(|(k, (name, value))| {
            let v: Vec<f64> = draws.iter().filter_map(|d| d.get(k).map(|x| x.1)).collect();
            let (draws_mean, sd_raw) = crate::numerics::mean_std(&v);
            ParamSd {
                name: name.to_string(),
                value: *value,
                sd: sd_raw * family.sd_factor(name),
                sd_raw,
                draws_mean,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A family whose "residuals" are a number: -1 the data (its fit scores `score` with
    /// statistic `stat`), a surrogate's u in [0, 1) gives score 0.010 + 0.002 u, statistic
    /// 20 + 5 u.
    struct Toy {
        score: f64,
        stat: f64,
        vetoes: bool,
        /// Whether the statistic detects, and its margin (sd).
        detects: Option<f64>,
    }

    impl Family<f64> for Toy {
        type Fit = (f64, f64);
        fn name(&self) -> &'static str {
            "toy"
        }
        fn fit(&self, res: &f64) -> Result<(f64, f64)> {
            Ok(if *res < 0.0 {
                (self.score, self.stat)
            } else {
                (0.010 + 0.002 * res, 20.0 + 5.0 * res)
            })
        }
        fn score(&self, fit: &(f64, f64)) -> f64 {
            fit.0
        }
        fn surrogate(&self, _: &f64, _: &(f64, f64), rng: &mut StdRng) -> Result<f64> {
            Ok(rng.random())
        }
        fn params(&self, _: &f64, _: &(f64, f64)) -> serde_json::Value {
            serde_json::Value::Null
        }
        fn declare(&self, _: &f64, _: &(f64, f64)) -> Option<OwnedEffect> {
            None
        }
        fn statistic(&self, fit: &(f64, f64)) -> Option<f64> {
            Some(fit.1)
        }
        fn statistic_vetoes(&self) -> bool {
            self.vetoes
        }
        fn statistic_detects(&self) -> bool {
            self.detects.is_some()
        }
        fn statistic_sd_margin(&self) -> f64 {
            self.detects.unwrap_or(STAT_SD_MARGIN)
        }
    }

    fn assess_toy(score: f64, stat: f64, vetoes: bool) -> Candidate {
        assess_rule(score, stat, vetoes, None)
    }

    fn assess_rule(score: f64, stat: f64, vetoes: bool, detects: Option<f64>) -> Candidate {
        let opts = AnalysisOptions {
            bootstrap: 0,
            ..AnalysisOptions::default()
        };
        Toy {
            score,
            stat,
            vetoes,
            detects,
        }
        .assess(&-1.0, &opts)
        .unwrap()
    }

    fn assess(score: f64, stat: f64) -> Candidate {
        assess_toy(score, stat, true)
    }

    #[test]
    fn a_statistic_that_stands_out_carries_a_score_just_above_chance() {
        // Just above chance, within the score's margin: significant by the statistic alone.
        let c = assess(0.0125, 90.0);
        assert!(c.excess() > 0.0 && c.excess() < c.margin, "{c:?}");
        assert!(c.significant && c.rejected.is_none(), "{c:?}");
        assert_eq!(c.statistic.as_ref().map(|s| s.1.len()), Some(20));
        // A statistic above the surrogates' largest but not by the margin: not significant.
        assert!(!assess(0.0125, 26.0).significant);
        // Below chance but above 0 (a step in the record's last months): significant by the
        // statistic, which vetoes; at or below 0, however large the statistic: not.
        let c = assess(0.005, 90.0);
        assert!(c.excess() < 0.0 && c.significant, "{c:?}");
        assert!(!assess(0.0, 90.0).significant);
        assert!(!assess(-0.001, 90.0).significant);
        // A score beyond its margin with a statistic the surrogates reach: rejected.
        let c = assess(0.2, 22.0);
        assert!(!c.significant && c.rejected.is_some(), "{c:?}");
        assert!(assess(0.2, 26.0).significant);
    }

    /// A family whose fit is its "residuals" (a number) and whose draws are uniform in [0, 1),
    /// its standard deviation of `a` scaled by `factor`, of `b` not.
    struct Drawn {
        factor: f64,
    }

    impl Family<f64> for Drawn {
        type Fit = f64;
        fn name(&self) -> &'static str {
            "drawn"
        }
        fn fit(&self, res: &f64) -> Result<f64> {
            Ok(*res)
        }
        fn score(&self, _: &f64) -> f64 {
            0.0
        }
        fn surrogate(&self, _: &f64, _: &f64, rng: &mut StdRng) -> Result<f64> {
            Ok(rng.random())
        }
        fn params(&self, _: &f64, _: &f64) -> serde_json::Value {
            serde_json::Value::Null
        }
        fn declare(&self, _: &f64, _: &f64) -> Option<OwnedEffect> {
            None
        }
        fn key_params(&self, _: &f64, fit: &f64) -> Vec<(&'static str, f64)> {
            vec![("a", *fit), ("b", *fit)]
        }
        fn sd_factor(&self, param: &str) -> f64 {
            if param == "a" {
                self.factor
            } else {
                1.0
            }
        }
        fn resample(&self, _: &f64, _: &f64, rng: &mut StdRng) -> Option<Result<f64>> {
            Some(Ok(rng.random()))
        }
    }

    #[test]
    fn the_bootstrap_scales_its_draws_sd_by_the_family_s_factor() {
        let opts = AnalysisOptions {
            bootstrap: 20,
            ..AnalysisOptions::default()
        };
        let u = bootstrap(&Drawn { factor: 1.5 }, &0.5, &0.5, &opts).unwrap();
        let [a, b] = [&u[0], &u[1]];
        assert_eq!((a.name.as_str(), b.name.as_str()), ("a", "b"));
        // The same draws for both; uniform in [0, 1): sd about 0.29.
        assert!(a.sd_raw > 0.15 && a.sd_raw < 0.45, "{a:?}");
        assert_eq!(a.sd_raw, b.sd_raw);
        assert!((a.sd - 1.5 * a.sd_raw).abs() < 1e-15, "{a:?}");
        assert_eq!(b.sd, b.sd_raw);
        assert_eq!((a.value, a.draws_mean), (0.5, b.draws_mean));
    }

    #[test]
    fn a_statistic_that_only_supports_never_rejects() {
        // The same fits with a statistic that does not veto: a score beyond its margin stands
        // whatever the statistic; one just above chance still needs the statistic to stand out,
        // and one below chance is not carried by it.
        let c = assess_toy(0.2, 22.0, false);
        assert!(c.significant && c.rejected.is_none(), "{c:?}");
        assert!(assess_toy(0.0125, 90.0, false).significant);
        assert!(!assess_toy(0.0125, 26.0, false).significant);
        assert!(!assess_toy(0.005, 90.0, false).significant);
    }

    #[test]
    fn a_detecting_statistic_carries_any_gain_and_never_rejects() {
        // Standing out, it carries a score below chance that is above 0, as a vetoing one does.
        let c = assess_rule(0.005, 90.0, false, Some(STAT_SD_MARGIN));
        assert!(c.excess() < 0.0 && c.significant, "{c:?}");
        assert!(!assess_rule(0.0, 90.0, false, Some(STAT_SD_MARGIN)).significant);
        // Not standing out, it takes nothing from a score beyond its margin.
        let c = assess_rule(0.2, 22.0, false, Some(STAT_SD_MARGIN));
        assert!(c.significant && c.rejected.is_none(), "{c:?}");
        // Its own margin: the surrogates' roots are about 4.74 ± 0.30, their largest below 25;
        // 26 stands out by 1 sd, not by the default 5.
        assert!(assess_rule(0.005, 26.0, false, Some(1.0)).significant);
        assert!(!assess_rule(0.005, 26.0, false, Some(STAT_SD_MARGIN)).significant);
    }
}
