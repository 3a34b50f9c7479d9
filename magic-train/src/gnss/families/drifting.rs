//! A step at a drifting station: one signal two families see.
//!
//! A linear drift in slow noise peaks the step scan at its station (its scan statistic stands
//! out of surrogates, which turn the trend into a stationary wander), though such a step's
//! held-out score stays below chance: a level that wanders predicts held-out days no better than
//! the surrogates' best steps. A step significant by its statistic alone (score below chance,
//! [`crate::analysis::Family::statistic`]) is taken for a significant `drift` ranked above it at
//! the same station — no longer significant, and the reason said.
//!
//! The other way round, a step mid-record draws a drift at its station (the drift's fit is the
//! step's trend: its rates point along the step's offset), and the drift can rank above it: no
//! surrogate's station stands out, so its chance level is near 0, while the step's pays for
//! every station and epoch scanned; once another effect is declared the trend can even explain
//! more of the held-out days than the step. The step's score tells the two apart: a drift's step
//! stays below chance, a real step's is above. A drift at the station of a significant step whose
//! score is above chance is that step. The loop declares the one kept and judges the other again
//! on what it leaves (a real drift beside a real step is found in the next round).

use crate::analysis::{Candidate, Rejection};
use crate::gnss::Network;
use crate::model::OwnedEffect;

/// Whether the drift `rate` (mm/yr per channel, component-major over `ns` stations) moves
/// `station`.
fn drifts(rate: &[f32], ns: usize, station: usize) -> bool {
    (0..3).any(|k| rate.get(k * ns + station).is_some_and(|r| *r != 0.0))
}

/// Whether `c` is a significant, unrejected `drift` that moves `station`.
fn drift_at(c: &Candidate, ns: usize, station: usize) -> bool {
    c.family == "drift"
        && c.significant
        && c.rejected.is_none()
        && match &c.effect {
            Some(OwnedEffect::Drift { rate, .. }) => drifts(rate, ns, station),
            _ => false,
        }
}

/// Reconciles the significant steps and drifts at one station (`effects` ranked, best first):
/// a step with a score below chance under a drift ranked above it is the drift; a drift at the
/// station of a step whose score is above chance is the step. Each marked one is no longer
/// significant, with the reason.
pub fn mark_drifting(network: &Network, effects: &mut [Candidate]) {
    let ns = network.stations.len();
    for i in 0..effects.len() {
        let c = &effects[i];
        let Some(OwnedEffect::Step { station, .. }) = c.effect else {
            continue;
        };
        if !c.significant || c.rejected.is_some() {
            continue;
        }
        let s = usize::from(station);
        let name = network.names.get(s).map_or("its station", String::as_str);
        let excess = c.excess();
        if excess > 0.0 {
            for d in effects.iter_mut() {
                if drift_at(d, ns, s) {
                    d.significant = false;
                    d.rejected = Some(Rejection::PartOf(format!(
                        "the step at {name}, above chance (a step mid-record fits a trend)"
                    )));
                }
            }
        } else if effects[..i]
            .iter()
            .any(|d| drift_at(d, ns, s) && d.excess() > excess)
        {
            effects[i].significant = false;
            effects[i].rejected = Some(Rejection::PartOf(format!(
                "the drift ranked above it at {name} (a trend peaks the step scan)"
            )));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    use super::super::three_stations as network;

    /// A candidate scoring `score` against the same surrogate scores (chance about 0.002).
    fn candidate(family: &str, score: f64, e: OwnedEffect) -> Candidate {
        let noise = vec![0.001, 0.002, 0.0015, 0.001, 0.002];
        Candidate::from_scores(family, score, noise, 0.95, json!({}), Some(e))
    }

    /// A drift at station B (its up component only).
    fn drift(score: f64) -> Candidate {
        let mut rate = vec![0.0; 9];
        rate[2 * 3 + 1] = 4.0;
        let c = candidate("drift", score, OwnedEffect::Drift { t0_day: 0.0, rate });
        assert!(c.significant);
        c
    }

    /// A step at `station` scoring `score`; significant by its statistic when below chance.
    fn step(score: f64, station: u16) -> Candidate {
        let effect = OwnedEffect::Step {
            station,
            epoch_day: 15_000.0,
            offset_mm: [1.0, 1.0, 5.0],
        };
        let mut c = candidate("step", score, effect);
        c.significant = true;
        c
    }

    #[test]
    fn a_step_below_chance_at_a_drifting_station_is_the_drift() {
        let mut e = vec![drift(0.2), step(0.0015, 1)];
        assert!(e[1].excess() < 0.0);
        mark_drifting(&network(), &mut e);
        assert!(!e[1].significant, "{:?}", e[1]);
        assert!(
            matches!(&e[1].rejected, Some(Rejection::PartOf(w)) if w.contains("drift") && w.contains('B')),
            "{:?}",
            e[1].rejected
        );
        assert!(e[0].significant && e[0].rejected.is_none());
    }

    #[test]
    fn a_drift_at_the_station_of_a_step_above_chance_is_the_step() {
        for mut e in [
            vec![drift(0.2), step(0.03, 1)],
            vec![drift(0.02), step(0.03, 1)],
            vec![step(0.3, 1), drift(0.2)],
        ] {
            mark_drifting(&network(), &mut e);
            let (d, s) = if e[0].family == "drift" {
                (&e[0], &e[1])
            } else {
                (&e[1], &e[0])
            };
            assert!(s.significant && s.rejected.is_none(), "{s:?}");
            assert!(!d.significant, "{d:?}");
            assert!(
                matches!(&d.rejected, Some(Rejection::PartOf(w)) if w.contains("step") && w.contains('B')),
                "{:?}",
                d.rejected
            );
        }
    }

    #[test]
    fn a_step_and_a_drift_at_different_stations_both_stay() {
        for mut e in [
            vec![drift(0.2), step(0.03, 0)],
            vec![drift(0.2), step(0.0015, 0)],
            vec![drift(0.2), step(0.0015, 2)],
            vec![step(0.3, 0), drift(0.2)],
        ] {
            mark_drifting(&network(), &mut e);
            assert!(
                e.iter().all(|c| c.significant && c.rejected.is_none()),
                "{e:?}"
            );
        }
    }
}
